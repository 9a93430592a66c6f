"""The OpenCL devices (`list_devices`) and the one a render uses
(`open_device`): the one named by `--device`/$FRACTALC_DEVICE, else the
fastest usable one.

The default is the first device, in the speed ranking below, whose driver
passes the lane probe (fractalc/lanes.py; its verdict is cached per driver,
device and CPU, so a choice costs nothing after the first): a GPU before a
CPU; among CPU drivers, Intel's OpenCL CPU runtime before PoCL (newer PoCL
first) before any other. The ranking is measured, not guessed: bulb-640,
examples/benchmark.frac and examples/mandelbulb.frac render 2.2-2.5x faster
on Intel's runtime than on PoCL on the CPUs we meet (Intel Xeon, AMD EPYC
Zen 5), side by side in one process (docs/drivers.md, `python
benchmarks/drivers.py`).
"""
from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass
from functools import lru_cache

from .drivers import SWITCH_ENVIRONMENT, bundled_enabled, bundled_libraries, installed_file, opencl, \
    platform_devices
from .errors import RenderError
from .lanes import LaneChoice, UnusableDevice, choose

DEVICE_ENVIRONMENT = "FRACTALC_DEVICE"
INTEL_RUNTIME_INSTALL = "pip install intel-opencl-rt intel-cmplr-lib-rt"
INSTALL_HINT = ("no OpenCL platform found: install fractalc with pip (it brings PoCL and, on Linux x86-64, "
                f"Intel's OpenCL CPU runtime: {INTEL_RUNTIME_INSTALL}) or your GPU's OpenCL driver")


@dataclass(frozen=True)
class DeviceInfo:
    index: int
    name: str
    platform: str
    kind: str          # CPU | GPU | other
    version: str
    double: bool
    compute_units: int
    driver: str
    platform_version: str = ""

    @property
    def driver_label(self) -> str:
        """The driver in words: "PoCL 3.0-rc2 with LLVM 14.0.6", "Intel(R) OpenCL 2026.22.10.0"."""
        pocl = re.search(r"PoCL (\S+)", self.platform_version)
        if pocl:
            llvm = re.search(r"LLVM (\S+?),?\s", self.platform_version + " ")
            return f"PoCL {pocl.group(1)}" + (f" with LLVM {llvm.group(1)}" if llvm else "")
        return f"{self.platform} {self.driver}"


def describe(index: int, device) -> DeviceInfo:
    cl = opencl()
    kind = ("GPU" if device.type & cl.device_type.GPU else
            "CPU" if device.type & cl.device_type.CPU else "other")
    return DeviceInfo(index, device.name.strip(), device.platform.name.strip(), kind,
                      device.version.strip(), bool(device.double_fp_config),
                      device.max_compute_units, device.driver_version.strip(),
                      device.platform.version.strip())


def list_devices() -> list[DeviceInfo]:
    return [describe(i, d) for i, d in enumerate(platform_devices())]


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in re.findall(r"\d+", text)[:3])


def is_intel_cpu(info: DeviceInfo) -> bool:
    """Intel's OpenCL CPU runtime."""
    return "Intel" in info.platform and info.kind == "CPU"


def refines_rsqrt(info: DeviceInfo) -> bool:
    """Whether float kernels take rsqrt as native_rsqrt and one Newton step
    (emit.Target.refined_rsqrt, REFINED_RSQRT in stdlib_cl/prelude.cl): on
    Intel's CPU runtime, whose exact rsqrt is a library call (bulb-640 4.6%
    faster there; on PoCL, whose rsqrt is inline, the step costs 6% of a
    distance estimate; docs/performance.md)."""
    return is_intel_cpu(info)


def build_options(info: DeviceInfo, double: bool) -> tuple[str, ...]:
    """The OpenCL build options of a render or distance program, chosen by
    measurement with the accuracy tests as the gate (emit.Target.build_options;
    docs/performance.md): `-cl-unsafe-math-optimizations` for float kernels on
    Intel's CPU runtime (bulb-640 about 6% faster; reassociation and fused
    multiply-adds, not approximate functions: `-cl-fast-relaxed-math` is
    10% faster still but fails them), none elsewhere (PoCL gains nothing)."""
    return ("-cl-unsafe-math-optimizations",) if is_intel_cpu(info) and not double else ()


def speed_rank(info: DeviceInfo) -> tuple:
    """Sort key of the default choice (see the module docstring): smaller is
    faster."""
    kind = {"GPU": 0, "CPU": 1}.get(info.kind, 2)
    if is_intel_cpu(info):
        driver = 0
    elif "PoCL" in info.platform_version or "Portable Computing Language" in info.platform:
        driver = 1
    else:
        driver = 2
    newest_first = tuple(-n for n in _version(info.driver_label.split(" with ")[0]))
    return kind, driver, newest_first, info.index


# ---- usable devices and what to do about the others ------------------------------

@lru_cache(maxsize=1)
def host_cpu() -> str:
    """The CPU in words: its model name, family and model (what a driver
    fails to target)."""
    fields = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f.read(1 << 16).splitlines():
                key, _, value = line.partition(":")
                fields.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    name = fields.get("model name") or os.uname().machine
    if "cpu family" in fields:
        return f"{name}, family {fields['cpu family']} model {fields.get('model', '?')}"
    return name


def fix_for(info: DeviceInfo) -> str:
    """What makes fractalc render when `info` cannot: the exact command."""
    others = [d for d in list_devices() if d.index != info.index and usable(d)]
    if others:
        best = min(others, key=speed_rank)
        return (f"use device {best.index} ('{best.name}' on {best.driver_label}): leave --device and "
                f"{DEVICE_ENVIRONMENT} out (the default is the fastest device that builds), or --device {best.index}")
    if bundled_libraries() and not bundled_enabled():
        return f"unset {SWITCH_ENVIRONMENT} (it leaves out Intel's OpenCL CPU runtime, which is installed)"
    if sys.platform.startswith("linux") and os.uname().machine == "x86_64" \
            and installed_file("intel-opencl-rt", "libintelocl.so") is None:
        return f"install Intel's OpenCL CPU runtime: {INTEL_RUNTIME_INSTALL}"
    return "install a newer OpenCL driver for this CPU (Debian: apt install pocl-opencl-icd) or your GPU's"


def cannot_build(info: DeviceInfo, failures: tuple[tuple[int, str], ...], fix: bool = True) -> str:
    """One line: the device, its driver, the CPU it could not target, the
    driver's first error, and (`fix`) the command that fixes it."""
    why = failures[-1][1] if failures else "no verdict"
    target = f" on this CPU ({host_cpu()})" if info.kind == "CPU" else ""
    text = f"the OpenCL device '{info.name}' ({info.driver_label}) cannot build fractalc's kernels{target}: {why}"
    return f"{text}; fix: {fix_for(info)}" if fix else text


def usable(info: DeviceInfo) -> bool:
    try:
        choose(info)
    except UnusableDevice:
        return False
    return True


def lane_choice(info: DeviceInfo) -> LaneChoice:
    """The device's lanes, or the one-line error of a device that cannot build."""
    try:
        return choose(info)
    except UnusableDevice as unusable:
        raise RenderError(cannot_build(info, unusable.failures)) from None


def default_device(infos: list[DeviceInfo]) -> DeviceInfo:
    """The fastest usable device; a note on stderr for each faster one
    found unusable just now (later runs read the verdict from the cache)."""
    skipped = []
    for info in sorted(infos, key=speed_rank):
        try:
            choose(info)
        except UnusableDevice as unusable:
            skipped.append((info, unusable))
            continue
        for other, unusable in skipped:
            if not unusable.remembered:
                print(f"fractalc: note: {cannot_build(other, unusable.failures, fix=False)}; using device {info.index} "
                      f"('{info.name}' on {info.driver_label})", file=sys.stderr)
        return info
    other, unusable = skipped[0]
    raise RenderError(cannot_build(other, unusable.failures))


@lru_cache(maxsize=None)
def _device(spec: str | None):
    devices = platform_devices()
    if not devices:
        raise RenderError(INSTALL_HINT)
    infos = [describe(i, d) for i, d in enumerate(devices)]
    spec = spec if spec is not None else os.environ.get(DEVICE_ENVIRONMENT) or None
    if spec is None:
        return devices[default_device(infos).index]
    if spec.isascii() and spec.isdigit():
        if int(spec) >= len(devices):
            raise RenderError(f"no OpenCL device {spec}: there are {len(devices)} "
                              "(see 'fractalc devices')")
        return devices[int(spec)]
    for info in infos:
        if spec.lower() in f"{info.platform} {info.driver_label} {info.name} {info.kind}".lower():
            return devices[info.index]
    raise RenderError(f"no OpenCL device matches '{spec}' (see 'fractalc devices')")


@dataclass
class Device:
    """A chosen device with its context and queue."""
    device: object
    context: object
    queue: object
    info: DeviceInfo

    @property
    def lane_choice(self) -> LaneChoice:
        return lane_choice(self.info)

    @property
    def lanes(self) -> int:
        """Rays per work-item: vector lanes on CPUs (as many as the driver
        builds and runs, fractalc/lanes.py), one ray per item on GPUs."""
        return self.lane_choice.lanes

    @property
    def work_group(self) -> tuple[int, int] | None:
        """Work-group size of render launches: the driver's choice on GPUs;
        on CPUs small groups of 8 x 1 blocks, which PoCL spreads over its
        threads more evenly than its own choice (docs/performance.md)."""
        return None if self.info.kind == "GPU" else (8, 1)


def open_device(spec: str | None = None) -> Device:
    """The device named by `spec` (index, or a substring of its platform,
    name or kind: "gpu", "cpu", "intel", "pocl"), else $FRACTALC_DEVICE,
    else the fastest usable one. One context per device, however it is
    named."""
    return _open(platform_devices().index(_device(spec)))


@lru_cache(maxsize=None)
def _open(index: int) -> Device:
    cl = opencl()
    device = platform_devices()[index]
    context = cl.Context([device])
    return Device(device, context, cl.CommandQueue(context), describe(index, device))
