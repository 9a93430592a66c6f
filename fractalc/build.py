"""Stage 5: OpenCL source -> built program (`build`), and device choice.

Programs are cached in-process by (source, options, device), so re-rendering
a scene or changing a param never rebuilds; across processes the driver's
or pyopencl's on-disk binary cache (keyed the same way) skips the compiler.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from dataclasses import dataclass
from functools import lru_cache

from .errors import RenderError

DEVICE_ENVIRONMENT = "FRACTALC_DEVICE"
INSTALL_HINT = ("no OpenCL platform found: install PoCL for your CPU "
                "(pip install pocl-binary-distribution) or your GPU's OpenCL driver")


def _cl():
    import pyopencl
    return pyopencl


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


def _all_devices() -> list:
    cl = _cl()
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        platforms = []
    devices = []
    for platform in platforms:
        try:
            devices.extend(platform.get_devices())
        except cl.Error:
            continue
    return devices


def _describe(index: int, device) -> DeviceInfo:
    cl = _cl()
    kind = ("GPU" if device.type & cl.device_type.GPU else
            "CPU" if device.type & cl.device_type.CPU else "other")
    return DeviceInfo(index, device.name.strip(), device.platform.name.strip(), kind,
                      device.version.strip(), bool(device.double_fp_config),
                      device.max_compute_units, device.driver_version.strip())


def list_devices() -> list[DeviceInfo]:
    return [_describe(i, d) for i, d in enumerate(_all_devices())]


@lru_cache(maxsize=None)
def _device(spec: str | None):
    devices = _all_devices()
    if not devices:
        raise RenderError(INSTALL_HINT)
    spec = spec if spec is not None else os.environ.get(DEVICE_ENVIRONMENT) or None
    if spec is None:
        # A GPU if there is one: that is what a machine with a GPU driver wants.
        infos = [_describe(i, d) for i, d in enumerate(devices)]
        gpu = next((i for i in infos if i.kind == "GPU"), None)
        return devices[(gpu or infos[0]).index]
    if spec.isdigit():
        if int(spec) >= len(devices):
            raise RenderError(f"no OpenCL device {spec}: there are {len(devices)} "
                              "(see 'fractalc devices')")
        return devices[int(spec)]
    for index, device in enumerate(devices):
        if spec.lower() in f"{device.platform.name} {device.name} {_describe(index, device).kind}".lower():
            return device
    raise RenderError(f"no OpenCL device matches '{spec}' (see 'fractalc devices')")


@dataclass
class Device:
    """A chosen device with its context and queue."""
    device: object
    context: object
    queue: object
    info: DeviceInfo

    @property
    def lanes(self) -> int:
        """Rays per work-item: vector lanes on CPUs, one ray per item on GPUs."""
        return 1 if self.info.kind == "GPU" else 16

    @property
    def work_group(self) -> tuple[int, int] | None:
        """Work-group size of render launches: the driver's choice on GPUs;
        on CPUs small groups of 8 x 1 blocks, which PoCL spreads over its
        threads more evenly than its own choice (docs/performance.md)."""
        return None if self.info.kind == "GPU" else (8, 1)


@lru_cache(maxsize=None)
def open_device(spec: str | None = None) -> Device:
    """The device named by `spec` (index, or a substring of its platform,
    name or kind: "gpu", "cpu"), else
    $FRACTALC_DEVICE, else the first GPU, else the first device."""
    cl = _cl()
    device = _device(spec)
    context = cl.Context([device])
    index = _all_devices().index(device)
    return Device(device, context, cl.CommandQueue(context), _describe(index, device))


@dataclass
class BuildStatistics:
    builds: int = 0     # programs compiled (not found in the in-process cache)


statistics = BuildStatistics()
_programs: dict[str, object] = {}


def source_hash(source: str, options: tuple[str, ...] = ()) -> str:
    return hashlib.sha256("\0".join((source,) + options).encode()).hexdigest()


def build(source: str, device: Device, options: tuple[str, ...] = (), use_cache: bool = True):
    """Build `source` for `device`; reuse a program built before."""
    cl = _cl()
    key = f"{source_hash(source, options)}:{device.info.platform}:{device.info.name}:{device.info.driver}"
    if use_cache and key in _programs:
        return _programs[key]
    program = cl.Program(device.context, source)
    try:
        program = program.build(options=list(options))
    except cl.Error as error:
        log_dir = tempfile.mkdtemp(prefix="fractalc-build-")
        with open(os.path.join(log_dir, "kernel.cl"), "w") as f:
            f.write(source)
        with open(os.path.join(log_dir, "build.log"), "w") as f:
            f.write(str(error))
        raise RenderError(f"internal error: the generated kernel failed to build (a fractalc bug); "
                          f"source and build log saved in {log_dir}") from None
    statistics.builds += 1
    _programs[key] = program
    return program
