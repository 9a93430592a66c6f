"""The drivers fractalc brings (fractalc/drivers.py) and the default device
(fractalc/devices.py): the bundled Intel runtime registered beside whatever
the system or the user lists, a switch that leaves it out, the fastest
usable device chosen, and a driver that cannot build on this CPU (as pip's
PoCL 3.0 on a Zen 5) skipped or reported in one line with its fix.

A driver that cannot build is made for real, through the driver's own
settings: PoCL refuses every build with POCL_EXTRA_BUILD_FLAGS=-Xclang
("Invalid build option"), Intel's runtime offers no device for an unknown
CL_CONFIG_CPU_TARGET_ARCH, so no Zen 5 is needed."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fractalc import drivers
from fractalc.cache import CACHE_ENVIRONMENT
from fractalc.devices import DeviceInfo, speed_rank

ROOT = Path(__file__).resolve().parent.parent
INTEL = drivers.installed_file("intel-opencl-rt", "libintelocl.so")
needs_intel = pytest.mark.skipif(INTEL is None, reason="Intel's OpenCL CPU runtime is not installed here")
BROKEN_POCL = {"POCL_EXTRA_BUILD_FLAGS": "-Xclang"}
BROKEN_INTEL = {"CL_CONFIG_CPU_TARGET_ARCH": "zen9"}


# ---- registration (no OpenCL needed) -----------------------------------------

def fake_bundled(tmp_path):
    library = tmp_path / "lib" / "libintelocl.so"
    library.parent.mkdir(parents=True, exist_ok=True)
    library.write_text("")
    return [(drivers.BUNDLED[0], library)]


def test_the_bundled_driver_is_added_to_the_system_s_drivers(tmp_path, monkeypatch):
    system = tmp_path / "vendors"
    system.mkdir()
    (system / "nvidia.icd").write_text("libnvidia-opencl.so.1\n")
    (system / "pocl.icd").write_text("/usr/lib/x86_64-linux-gnu/libpocl.so.2\n")
    monkeypatch.setattr(drivers, "SYSTEM_VENDORS", system)
    entries = drivers.vendors_folder({}, fake_bundled(tmp_path))
    assert entries == {"nvidia.icd": "libnvidia-opencl.so.1", "pocl.icd": "/usr/lib/x86_64-linux-gnu/libpocl.so.2",
                       "fractalc-intel-cpu.icd": str(tmp_path / "lib" / "libintelocl.so")}


@pytest.mark.parametrize("given", ["folder", "file", "library"])
def test_a_user_s_ocl_icd_vendors_is_kept(given, tmp_path):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "a.icd").write_text("/opt/a/liba.so\n")
    value = {"folder": str(folder), "file": str(folder / "a.icd"), "library": "/opt/b/libb.so"}[given]
    entries = drivers.vendors_folder({"OCL_ICD_VENDORS": value}, fake_bundled(tmp_path))
    kept = {"folder": {"a.icd": "/opt/a/liba.so"}, "file": {"a.icd": "/opt/a/liba.so"},
            "library": {"user-library.icd": "/opt/b/libb.so"}}[given]
    assert entries == {**kept, "fractalc-intel-cpu.icd": str(tmp_path / "lib" / "libintelocl.so")}


def test_a_driver_the_system_lists_already_is_not_listed_twice(tmp_path, monkeypatch):
    system = tmp_path / "vendors"
    system.mkdir()
    (system / "intel64.icd").write_text("/opt/intel/oclcpuexp/x64/libintelocl.so\n")
    monkeypatch.setattr(drivers, "SYSTEM_VENDORS", system)
    assert drivers.vendors_folder({}, fake_bundled(tmp_path)) == {
        "intel64.icd": "/opt/intel/oclcpuexp/x64/libintelocl.so"}


def run_python(code: str, tmp_path, **environment) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in (
        "OCL_ICD_VENDORS", drivers.REGISTERED_ENVIRONMENT, drivers.SWITCH_ENVIRONMENT, "FRACTALC_DEVICE")}
    env.update({CACHE_ENVIRONMENT: str(tmp_path / "cache")}, **environment)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)


PLATFORMS = ("import json, os; from fractalc.devices import list_devices; platforms = [d.platform for d in "
             "list_devices()]; print(json.dumps([os.environ.get('OCL_ICD_VENDORS'), platforms]))")


@pytest.mark.opencl
@needs_intel
def test_registered_drivers_reach_the_loader_and_the_switch_leaves_them_out(tmp_path):
    done = run_python(PLATFORMS, tmp_path)
    assert done.returncode == 0, done.stderr
    folder, platforms = json.loads(done.stdout)
    assert "Intel(R) OpenCL" in platforms and "Portable Computing Language" in platforms
    assert Path(folder, "fractalc-intel-cpu.icd").read_text().strip() == str(INTEL)
    off = run_python(PLATFORMS, tmp_path, FRACTALC_BUNDLED_DRIVERS="0")
    assert off.returncode == 0, off.stderr
    folder, platforms = json.loads(off.stdout)
    assert folder is None and "Intel(R) OpenCL" not in platforms
    # a user's own list is read too, and its driver not listed twice
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "intel.icd").write_text(f"{INTEL}\n")
    own = run_python(PLATFORMS, tmp_path, OCL_ICD_VENDORS=str(mine))
    folder, platforms = json.loads(own.stdout)
    assert folder == str(mine) and platforms.count("Intel(R) OpenCL") == 1


# ---- the default device --------------------------------------------------------

def info(index, kind, platform, version="", driver="1.0"):
    return DeviceInfo(index, f"device {index}", platform, kind, "OpenCL 3.0", True, 2, driver, version)


def test_the_ranking_puts_gpus_then_intel_s_cpu_runtime_then_the_newest_pocl_first():
    pocl_30 = info(0, "CPU", "Portable Computing Language", "OpenCL 3.0 PoCL 3.0-rc2  Linux, LLVM 14.0.6, SLEEF")
    pocl_31 = info(1, "CPU", "Portable Computing Language", "OpenCL 3.0 PoCL 3.1+debian  Linux, LLVM 15.0.6")
    intel = info(2, "CPU", "Intel(R) OpenCL", "OpenCL 3.1 LINUX", "2026.22.10.0.01_160000")
    other = info(3, "CPU", "Some Vendor CPU")
    gpu = info(4, "GPU", "NVIDIA CUDA", "OpenCL 3.0 CUDA 13.0", "580.1")
    ranked = sorted([pocl_30, pocl_31, intel, other, gpu], key=speed_rank)
    assert [d.index for d in ranked] == [4, 2, 1, 0, 3]
    assert pocl_30.driver_label == "PoCL 3.0-rc2 with LLVM 14.0.6"


def fractalc_command(args, tmp_path, **environment) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in (
        "OCL_ICD_VENDORS", drivers.REGISTERED_ENVIRONMENT, drivers.SWITCH_ENVIRONMENT, "FRACTALC_DEVICE",
        "FRACTALC_LANES", "POCL_CACHE_DIR")}
    env.update({CACHE_ENVIRONMENT: str(tmp_path / "cache"), "XDG_CACHE_HOME": str(tmp_path / "xdg")},
               **environment)
    return subprocess.run([sys.executable, "-m", "fractalc", *args], cwd=ROOT, capture_output=True, text=True,
                          env=env, timeout=600)


RENDER = ["render", "examples/primitives.frac", "--width", "32", "--height", "24", "-o"]


@pytest.mark.opencl
@needs_intel
def test_a_pocl_that_cannot_build_here_is_reported_and_intel_renders(tmp_path):
    """pip's PoCL 3.0 on a Zen 5: the first command still works, `devices`
    says why PoCL cannot build, and asking for PoCL is one line with the
    fix, exit 1."""
    done = fractalc_command(RENDER + [str(tmp_path / "a.png")], tmp_path, **BROKEN_POCL)
    assert done.returncode == 0 and (tmp_path / "a.png").is_file(), done.stderr
    listed = fractalc_command(["devices"], tmp_path, **BROKEN_POCL)
    assert listed.returncode == 0, listed.stderr
    pocl = next(line for line in listed.stdout.splitlines() if "PoCL 3" in line)
    assert "builds: no" in pocl and "Invalid build option: -Xclang" in pocl, pocl
    intel = next(line for line in listed.stdout.splitlines() if "Intel(R) OpenCL" in line)
    assert intel.startswith("*") and "builds: yes" in intel and "16 lanes" in intel
    asked = fractalc_command(RENDER + [str(tmp_path / "b.png"), "--device", "pocl"], tmp_path, **BROKEN_POCL)
    assert asked.returncode == 1 and not (tmp_path / "b.png").exists()
    assert len(asked.stderr.splitlines()) == 1, asked.stderr
    line = asked.stderr.strip()
    assert line.startswith("fractalc: error: the OpenCL device 'pthread-") and "(PoCL 3." in line
    assert "cannot build fractalc's kernels on this CPU (" in line and "family" in line
    assert "Invalid build option: -Xclang" in line and "fix: use device" in line
    # a driver that builds nothing is probed once, at one width, and remembered
    entries = json.loads((tmp_path / "cache" / "lanes.json").read_text())
    unusable = [e for key, e in entries.items() if "PoCL" in key]      # pip's, and a system's PoCL if any
    assert unusable and all((e["lanes"], [w for w, _ in e["failures"]]) == (None, [16]) for e in unusable)


def pocl_builds_here() -> bool:
    from fractalc.devices import list_devices, usable
    return any(usable(d) for d in list_devices() if "PoCL" in d.driver_label)


@pytest.mark.opencl
@needs_intel
def test_the_default_falls_to_the_next_driver_with_a_note(tmp_path):
    if not pocl_builds_here():
        pytest.skip("PoCL cannot build on this CPU (as on a Zen 5): no next driver to fall to")
    first = fractalc_command(RENDER + [str(tmp_path / "a.png")], tmp_path, **BROKEN_INTEL)
    assert first.returncode == 0, first.stderr
    note = next(line for line in first.stderr.splitlines() if line.startswith("fractalc: note:"))
    # Intel's runtime names the device after the CPU ('AMD EPYC' on an AMD machine)
    assert "(Intel(R) OpenCL" in note and "cannot build fractalc's kernels on this CPU" in note
    assert "using device" in note and "PoCL" in note
    again = fractalc_command(RENDER + [str(tmp_path / "b.png")], tmp_path, **BROKEN_INTEL)
    assert again.returncode == 0 and "note:" not in again.stderr, "the verdict is remembered"


@pytest.mark.opencl
@needs_intel
def test_no_driver_that_builds_is_one_line_with_the_fix(tmp_path):
    done = fractalc_command(RENDER + [str(tmp_path / "a.png")], tmp_path, **BROKEN_INTEL, **BROKEN_POCL)
    assert done.returncode == 1 and not (tmp_path / "a.png").exists()
    assert len(done.stderr.splitlines()) == 1, done.stderr
    assert "cannot build fractalc's kernels on this CPU" in done.stderr and "fix: " in done.stderr
    off = fractalc_command(RENDER + [str(tmp_path / "a.png")], tmp_path, FRACTALC_BUNDLED_DRIVERS="0",
                           **BROKEN_POCL)
    assert off.returncode == 1 and "fix: unset FRACTALC_BUNDLED_DRIVERS" in off.stderr, off.stderr
