"""Rays per work-item chosen by a probe in a child process (fractalc/lanes.py),
the driver's kernel cache guarded against crashes, quiet builds, and the
`fractalc` command's one-line error when the driver crashes."""
from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc import build as build_module
from fractalc import cli, lanes
from fractalc.cache import CACHE_ENVIRONMENT
from fractalc.devices import list_devices, usable
from fractalc.errors import RenderError

ROOT = Path(__file__).resolve().parent.parent
SEGFAULT = [sys.executable, "-c", "import os, signal; os.kill(os.getpid(), signal.SIGSEGV)"]
HANG = [sys.executable, "-c", "import time; time.sleep(60)"]


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh fractalc cache folder and no lane override."""
    monkeypatch.setenv(CACHE_ENVIRONMENT, str(tmp_path / "cache"))
    monkeypatch.delenv(lanes.ENVIRONMENT, raising=False)
    return tmp_path / "cache"


@pytest.fixture(scope="module")
def cpu():
    """The first CPU device whose driver builds here (pip's PoCL does not
    on a Zen 5)."""
    info = next((d for d in list_devices() if d.kind == "CPU" and usable(d)), None)
    if info is None:
        pytest.skip("no CPU OpenCL device that builds")
    return info


class Probes:
    """A probe that fails at the widths given (by really crashing a child,
    or hanging one), and passes, for real, at the others."""

    def __init__(self, failing: dict[int, list[str]], timeout: float = 120.0):
        self.failing, self.timeout, self.widths = failing, timeout, []

    def __call__(self, device_index, width, precisions):
        self.widths.append(width)
        if width in self.failing:
            return lanes.run_probe(device_index, width, precisions, command=self.failing[width],
                                   timeout=self.timeout)
        return lanes.run_probe(device_index, width, precisions)


@pytest.mark.opencl
def test_the_probe_passes_at_a_width_this_driver_runs(cpu, cache):
    passed = lanes.run_probe(cpu.index, 4, ("float", "double") if cpu.double else ("float",))
    assert isinstance(passed, lanes.ProbePassed) and 0 <= passed.native_error < 1e-2


@pytest.mark.opencl
def test_a_crashing_probe_falls_back_to_the_next_width_and_is_remembered(cpu, cache):
    probe = Probes({16: SEGFAULT, 8: SEGFAULT})
    choice = lanes.choose(cpu, probe=probe)
    assert choice.lanes == 4 and probe.widths == [16, 8, 4]
    assert [w for w, _ in choice.failures] == [16, 8]
    assert all("crashed (SIGSEGV)" in why for _, why in choice.failures)
    # remembered on disk: no probe next time, in this process or another
    again = Probes({})
    assert lanes.choose(cpu, probe=again).lanes == 4 and again.widths == []
    entries = json.loads((cache / "lanes.json").read_text())
    assert [e["lanes"] for e in entries.values()] == [4]
    assert "16 failed: the OpenCL compiler crashed (SIGSEGV)" in lanes.describe(lanes.choose(cpu, probe=again))


@pytest.mark.opencl
def test_a_hanging_probe_times_out_and_falls_back(cpu, cache):
    probe = Probes({16: HANG}, timeout=3.0)
    choice = lanes.choose(cpu, probe=probe)
    assert choice.lanes == 8 and choice.failures == ((16, "the OpenCL compiler took over 3 s"),)


@pytest.mark.opencl
def test_a_device_that_fails_at_every_width_is_a_clear_error(cpu, cache):
    probe = Probes({w: SEGFAULT for w in lanes.WIDTHS})
    with pytest.raises(RenderError, match="failed the lane probe at every width"):
        lanes.choose(cpu, probe=probe)


@pytest.mark.opencl
def test_the_probe_checks_double_too_where_the_device_has_it(cpu, cache):
    asked = []

    def probe(index, width, precisions):
        asked.append(precisions)
        return lanes.ProbePassed()
    lanes.choose(cpu, probe=probe)
    assert asked == [("float", "double") if cpu.double else ("float",)]


DOUBLE_FAILS = [sys.executable, "-c", "print('{\"precision\": \"float\", \"error\": null}'); "
                "print('{\"precision\": \"double\", \"error\": \"sqrt gave 0.5 for 0.7\"}')"]


@pytest.mark.opencl
def test_a_failure_in_double_alone_fails_the_width(cpu, cache):
    failure = lanes.run_probe(cpu.index, 16, ("float", "double"), command=DOUBLE_FAILS)
    assert failure == lanes.ProbeFailure("sqrt gave 0.5 for 0.7 (double)")
    if cpu.double:
        probe = Probes({16: DOUBLE_FAILS})
        choice = lanes.choose(cpu, probe=probe)
        assert choice.lanes == 8 and choice.failures == ((16, "sqrt gave 0.5 for 0.7 (double)"),)


def test_wrong_results_fail_the_probe():
    x, y = lanes.probe_inputs()
    right = np.array([reference(x, y) for _, reference in lanes.PROBE_FUNCTIONS], dtype=np.float64)
    assert lanes.probe_error(right, double=False) is None
    wrong = right.copy()
    wrong[0, 5] *= 1.01          # sqrt off by 1%
    assert lanes.probe_error(wrong, double=False).startswith("sqrt gave")


def test_native_functions_count_as_exact_only_within_a_few_ulps():
    x, y = (v.astype(np.float32).astype(np.float64) for v in lanes.probe_inputs())
    right = np.array([reference(x, y) for _, reference in lanes.PROBE_FUNCTIONS], dtype=np.float64)
    assert lanes.native_error(right, double=False) == 0 and lanes.native_error(right, double=True) is None
    assert lanes.LaneChoice(16, "probed", native_error=lanes.native_error(right, False)).native_exact
    row = [name for name, _ in lanes.PROBE_FUNCTIONS].index("native_exp")
    approximate = right.copy()
    approximate[row] *= 1 + 2.3e-4     # Intel's native_exp, measured
    assert lanes.native_error(approximate, double=False) == pytest.approx(2.3e-4, rel=1e-3)
    assert not lanes.LaneChoice(16, "probed", native_error=2.3e-4).native_exact
    assert not lanes.LaneChoice(16, "set by --lanes").native_exact, "unmeasured counts as inexact"


@pytest.mark.opencl
def test_overrides_and_gpus_need_no_probe(cpu, cache, monkeypatch):
    never = Probes({})
    assert lanes.choose(cpu, override=2, probe=never).lanes == 2
    monkeypatch.setenv(lanes.ENVIRONMENT, "4")
    assert lanes.choose(cpu, probe=never) == lanes.LaneChoice(4, "set by FRACTALC_LANES")
    monkeypatch.delenv(lanes.ENVIRONMENT)
    gpu = dataclasses.replace(cpu, kind="GPU")
    assert lanes.choose(gpu, probe=never).lanes == 1
    assert never.widths == []


@pytest.mark.parametrize("text", ["3", "x", "", "٣", "16.0", "-8"])
def test_a_lane_count_outside_the_choices_is_refused(text):
    with pytest.raises(ValueError, match="lanes must be one of 1, 2, 4, 8, 16"):
        lanes.parse_lanes(text, "--lanes")


def test_the_command_line_checks_lanes_before_any_work(capsys, monkeypatch):
    monkeypatch.delenv(lanes.ENVIRONMENT, raising=False)
    assert cli.main(["render", str(ROOT / "examples/primitives.frac"), "-o", "never.png", "--lanes", "3"]) == 2
    assert "--lanes: lanes must be one of 1, 2, 4, 8, 16, not '3'" in capsys.readouterr().err
    monkeypatch.setenv(lanes.ENVIRONMENT, "12")
    assert cli.main(["check", str(ROOT / "examples/primitives.frac")]) == 2
    assert "FRACTALC_LANES: lanes must be one of" in capsys.readouterr().err
    assert not Path("never.png").exists()


@pytest.mark.opencl
def test_the_lane_override_reaches_the_kernel(monkeypatch):
    scene = fractalc.loads("scene sphere(1)", lanes=4)
    assert "#define LANES 4" in scene.kernel_source()
    assert abs(scene.distance([[0, 0, 3]])[0] - 2.0) < 1e-6
    monkeypatch.setenv(lanes.ENVIRONMENT, "2")
    assert "#define LANES 2" in fractalc.loads("scene sphere(1)").kernel_source()
    with pytest.raises(ValueError, match="lanes must be one of"):
        fractalc.loads("scene sphere(1)", lanes=3)


@pytest.mark.opencl
def test_devices_shows_the_rays_per_work_item(capsys, monkeypatch):
    monkeypatch.setenv(lanes.ENVIRONMENT, "8")
    assert cli.main(["devices"]) == 0
    out = capsys.readouterr().out
    assert "rays per work-item: 8 lanes (set by FRACTALC_LANES)" in out


# ---- the driver's kernel cache and crashes ------------------------------------

def test_a_marker_left_by_a_dead_process_clears_the_driver_cache(tmp_path):
    cache = tmp_path / "cache"
    (cache / "pocl" / "half-built").mkdir(parents=True)
    (cache / "building").mkdir()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (cache / "building" / dead.stdout.strip()).write_text("")
    environment = {k: v for k, v in os.environ.items() if k != "POCL_CACHE_DIR"}
    environment[CACHE_ENVIRONMENT] = str(cache)
    done = subprocess.run([sys.executable, "-c", "from fractalc import drivers; drivers.opencl(); "
                           "import os; print(os.environ['POCL_CACHE_DIR'])"],
                          capture_output=True, text=True, env=environment)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(cache / "pocl")
    assert not (cache / "pocl" / "half-built").exists()
    assert list((cache / "building").iterdir()) == []
    assert "died while using the OpenCL driver; clearing its kernel cache" in done.stderr


def test_a_dead_marker_waits_while_another_process_builds(tmp_path):
    """Clearing the cache under a live process's build made PoCL abort it:
    while one is alive, the dead marker stays for the last one out."""
    cache = tmp_path / "cache"
    (cache / "pocl" / "entry").mkdir(parents=True)
    (cache / "building").mkdir()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (cache / "building" / dead.stdout.strip()).write_text("")
    (cache / "building" / str(os.getpid())).write_text("")       # this test's process: alive
    environment = {k: v for k, v in os.environ.items() if k != "POCL_CACHE_DIR"}
    environment[CACHE_ENVIRONMENT] = str(cache)
    done = subprocess.run([sys.executable, "-c", "from fractalc import drivers; drivers.opencl()"],
                          capture_output=True, text=True, env=environment)
    assert done.returncode == 0, done.stderr
    assert (cache / "pocl" / "entry").exists() and "clearing" not in done.stderr
    assert sorted(p.name for p in (cache / "building").iterdir()) == sorted([dead.stdout.strip(), str(os.getpid())])


@pytest.mark.opencl
def test_a_program_without_its_kernels_is_cleared_and_built_again(monkeypatch, tmp_path):
    """As PoCL answers after a crash left a half-built cache entry: the
    program builds but has no `render` kernel."""
    monkeypatch.setenv("POCL_CACHE_DIR", str(tmp_path / "pocl"))
    (tmp_path / "pocl").mkdir()
    scene = fractalc.loads("scene sphere(1.25)", lanes=1)
    device = scene.device
    real_compile = build_module._compile
    compiled_with = []

    def half_built_first(source, device, options):
        compiled_with.append(options)
        if not options:
            return real_compile("__kernel void other(__global float *x) { }", device, ())
        return real_compile(source, device, options)

    monkeypatch.setattr(build_module, "_compile", half_built_first)
    program = build_module.build(scene.kernel_source(), device, use_cache=False)
    assert compiled_with == [(), ("-D FRACTALC_REBUILT=1",)]
    assert not (tmp_path / "pocl").exists()
    assert {k.function_name for k in program.all_kernels()} >= {"render", "distance_at_points"}


def test_a_driver_crash_is_one_line_that_says_what_to_do(monkeypatch, capsys):
    monkeypatch.delenv(cli.SUPERVISED_ENVIRONMENT, raising=False)
    monkeypatch.setattr(cli, "_child_command", lambda argv: SEGFAULT)
    monkeypatch.setattr(sys, "argv", ["fractalc", "render", "scene.frac", "-o", "out.png"])
    assert cli.entry() == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("fractalc: error: the OpenCL driver crashed (SIGSEGV); run 'fractalc devices --probe'")


def test_the_command_passes_on_its_child_exit_code(monkeypatch):
    monkeypatch.delenv(cli.SUPERVISED_ENVIRONMENT, raising=False)
    monkeypatch.setattr(cli, "_child_command", lambda argv: [sys.executable, "-c", "raise SystemExit(2)"])
    monkeypatch.setattr(sys, "argv", ["fractalc", "check", "scene.frac"])
    assert cli.entry() == 2


# ---- quiet builds ------------------------------------------------------------------

@pytest.mark.opencl
@pytest.mark.parametrize("verbose", [False, True])
def test_compiler_chatter_reaches_the_terminal_only_when_verbose(verbose, monkeypatch, capfd):
    import pyopencl as cl
    monkeypatch.setenv(build_module.VERBOSE_ENVIRONMENT, "1" if verbose else "0")
    monkeypatch.delenv("PYOPENCL_COMPILER_OUTPUT", raising=False)
    device = fractalc.loads("scene sphere(1)").device
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with build_module._compiler_output(device):
            os.write(2, b"1 warning generated.\n")     # as the driver prints it
            warnings.warn("Non-empty compiler output", cl.CompilerWarning)
    shown = capfd.readouterr().err
    assert ("1 warning generated." in shown) == verbose
    assert any(issubclass(w.category, cl.CompilerWarning) for w in caught) == verbose


@pytest.mark.opencl
def test_a_failed_build_names_the_saved_source_and_log(monkeypatch):
    device = fractalc.loads("scene sphere(1)").device
    with pytest.raises(RenderError) as error:
        build_module.build("__kernel void broken( {", device, use_cache=False)
    message = str(error.value)
    source, log = (word.rstrip(")") for word in message.split() if word.startswith("/"))
    assert Path(source).read_text() == "__kernel void broken( {"
    assert Path(log).read_text().strip()


@pytest.mark.opencl
def test_first_render_on_a_cold_machine(tmp_path):
    """The README's first command with every cache empty: the lane probe
    runs, the kernel is compiled from nothing, and the terminal sees one
    line."""
    environment = {k: v for k, v in os.environ.items()
                   if k not in ("POCL_CACHE_DIR", lanes.ENVIRONMENT, build_module.VERBOSE_ENVIRONMENT)}
    environment.update({CACHE_ENVIRONMENT: str(tmp_path / "cache"),
                        "XDG_CACHE_HOME": str(tmp_path / "xdg")})
    out = tmp_path / "out.png"
    done = subprocess.run([sys.executable, "-m", "fractalc", "render", "examples/primitives.frac", "-o", str(out),
                           "--width", "64", "--height", "48"], cwd=ROOT, env=environment,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines() == [line for line in done.stderr.splitlines() if line.startswith("wrote ")]
    assert len(done.stderr.splitlines()) == 1
    import OpenImageIO as oiio
    image = oiio.ImageBuf(str(out))
    assert (image.spec().width, image.spec().height) == (64, 48)
    choice = json.loads((tmp_path / "cache" / "lanes.json").read_text())
    assert [entry["lanes"] for entry in choice.values()][0] in lanes.WIDTHS
    assert (tmp_path / "cache" / "pocl").is_dir()
