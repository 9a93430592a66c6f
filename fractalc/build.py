"""Stage 5: OpenCL source -> built program (`build`), and device choice.

Programs are cached in-process by (source, options, device), so re-rendering
a scene or changing a param never rebuilds; across processes the driver's
or pyopencl's on-disk binary cache (keyed the same way) skips the compiler.

PoCL's kernel cache is fractalc's own (`<cache>/pocl`, unless
$POCL_CACHE_DIR is set): a process that dies inside the driver (a compiler
crash) leaves a half-built entry there, which makes every later build of
that kernel fail. A marker file lives from a process's first build to its
normal exit; a marker whose process is gone says the cache may hold such
an entry, and it is cleared. Compiler output is kept out of the terminal
unless asked for ($FRACTALC_VERBOSE or `--verbose`).
"""
from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import sys
import tempfile
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache

from .lanes import LaneChoice, cache_dir, choose
from .errors import RenderError

DEVICE_ENVIRONMENT = "FRACTALC_DEVICE"
VERBOSE_ENVIRONMENT = "FRACTALC_VERBOSE"
INSTALL_HINT = ("no OpenCL platform found: install PoCL for your CPU "
                "(pip install pocl-binary-distribution) or your GPU's OpenCL driver")


def _cl():
    _own_driver_cache()
    import pyopencl
    return pyopencl


def driver_cache_dir() -> str:
    return os.environ.get("POCL_CACHE_DIR") or str(cache_dir() / "pocl")


@lru_cache(maxsize=1)
def _own_driver_cache() -> None:
    """Point PoCL at fractalc's kernel cache (before the driver loads) and
    clear it if a process died while using it."""
    os.environ["POCL_CACHE_DIR"] = driver_cache_dir()
    markers = cache_dir() / "building"
    for marker in markers.glob("*") if markers.is_dir() else ():
        if not _alive(marker.name):
            print(f"fractalc: a fractalc process ({marker.name}) died while using the OpenCL driver; "
                  "clearing its kernel cache. If it happens again, set FRACTALC_LANES=8 (or 4, 1), or "
                  "run 'fractalc devices --probe'", file=sys.stderr)
            shutil.rmtree(driver_cache_dir(), ignore_errors=True)
            marker.unlink(missing_ok=True)


def _alive(pid: str) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    return True


@lru_cache(maxsize=1)
def _mark_building() -> None:
    """Leave a marker until this process exits normally (see the module
    docstring)."""
    markers = cache_dir() / "building"
    try:
        markers.mkdir(parents=True, exist_ok=True)
        marker = markers / str(os.getpid())
        marker.write_text(driver_cache_dir())
    except OSError:
        return
    atexit.register(lambda: marker.unlink(missing_ok=True))


def verbose() -> bool:
    return os.environ.get(VERBOSE_ENVIRONMENT, "") not in ("", "0")


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


def all_devices() -> list:
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
                      device.max_compute_units, device.driver_version.strip(),
                      device.platform.version.strip())


def list_devices() -> list[DeviceInfo]:
    return [_describe(i, d) for i, d in enumerate(all_devices())]


@lru_cache(maxsize=None)
def _device(spec: str | None):
    devices = all_devices()
    if not devices:
        raise RenderError(INSTALL_HINT)
    spec = spec if spec is not None else os.environ.get(DEVICE_ENVIRONMENT) or None
    if spec is None:
        # A GPU if there is one: that is what a machine with a GPU driver wants.
        infos = [_describe(i, d) for i, d in enumerate(devices)]
        gpu = next((i for i in infos if i.kind == "GPU"), None)
        return devices[(gpu or infos[0]).index]
    if spec.isascii() and spec.isdigit():
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
    def lane_choice(self) -> LaneChoice:
        return choose(self.info)

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
    name or kind: "gpu", "cpu"), else
    $FRACTALC_DEVICE, else the first GPU, else the first device; one
    context per device, however it is named (built programs are shared
    by device, and belong to a context)."""
    return _opened(_device(spec))


@lru_cache(maxsize=None)
def _opened(device) -> Device:
    cl = _cl()
    context = cl.Context([device])
    index = all_devices().index(device)
    return Device(device, context, cl.CommandQueue(context), _describe(index, device))


@dataclass
class BuildStatistics:
    builds: int = 0     # programs compiled (not found in the in-process cache)


statistics = BuildStatistics()
_programs: dict[str, object] = {}


def source_hash(source: str, options: tuple[str, ...] = ()) -> str:
    return hashlib.sha256("\0".join((source,) + options).encode()).hexdigest()


RENDER_KERNELS = ("render", "distance_at_points")


def build(source: str, device: Device, options: tuple[str, ...] = (), use_cache: bool = True,
          kernels: tuple[str, ...] = RENDER_KERNELS):
    """Build `source` for `device`; reuse a program built before. A cached
    driver binary that lacks the `kernels` (left half-built by a crash) is
    cleared and built again."""
    key = f"{source_hash(source, options)}:{device.info.platform}:{device.info.name}:{device.info.driver}"
    if use_cache and key in _programs:
        return _programs[key]
    _mark_building()
    with _building_alone(key):
        program = _compile(source, device, options)
        if not _has_kernels(program, kernels):
            shutil.rmtree(driver_cache_dir(), ignore_errors=True)
            # a new option is a new cache key for the driver and pyopencl alike
            program = _compile(source, device, options + ("-D FRACTALC_REBUILT=1",))
            if not _has_kernels(program, kernels):
                _build_failed(source, "the built program has no kernels (a driver cache problem?)")
    statistics.builds += 1
    _programs[key] = program
    return program


def build_lock_path(key: str):
    """The lock file of a build key: one of 256 (unrelated kernels rarely
    share one; when they do, they build one after the other)."""
    return cache_dir() / "locks" / hashlib.sha256(key.encode()).hexdigest()[:2]


@contextmanager
def _building_alone(key: str):
    """Hold a lock on `key` (a source and device) across processes while it
    builds: two processes building one kernel at once into the shared
    driver cache (two renders, a render farm's local workers, parallel
    tests) made PoCL fail the build. Kernels of other sources build at the
    same time. (No lock where the platform has no fcntl.)"""
    try:
        import fcntl
    except ImportError:
        yield
        return
    path = build_lock_path(key)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _has_kernels(program, kernels: tuple[str, ...]) -> bool:
    cl = _cl()
    try:
        return set(kernels) <= {k.function_name for k in program.all_kernels()}
    except cl.Error:
        return False


def _compile(source: str, device: Device, options: tuple[str, ...]):
    cl = _cl()
    try:
        with _compiler_output(device):
            return cl.Program(device.context, source).build(options=list(options))
    except cl.Error as error:
        _build_failed(source, str(error))


@contextmanager
def _compiler_output(device: Device):
    """Keep the compiler's warnings (pyopencl's and what the driver prints
    on the process's stderr) out of the terminal unless verbose: then print
    them, with the build log."""
    cl = _cl()
    if verbose():
        os.environ["PYOPENCL_COMPILER_OUTPUT"] = "1"
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with tempfile.TemporaryFile() as sink, warnings.catch_warnings():
            warnings.simplefilter("ignore", cl.CompilerWarning)
            os.dup2(sink.fileno(), 2)
            try:
                yield
            finally:
                os.dup2(saved, 2)
    finally:
        os.close(saved)


def _build_failed(source: str, log: str):
    log_dir = tempfile.mkdtemp(prefix="fractalc-build-")
    source_path, log_path = os.path.join(log_dir, "kernel.cl"), os.path.join(log_dir, "build.log")
    with open(source_path, "w") as f:
        f.write(source)
    with open(log_path, "w") as f:
        f.write(log)
    raise RenderError(f"internal error: the generated kernel failed to build (a fractalc bug; please "
                      f"report it with {source_path} and {log_path})")
