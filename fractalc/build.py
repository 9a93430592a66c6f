"""Stage 5: OpenCL source -> built program (`build`) on a device
(fractalc/devices.py).

Programs are cached in-process by (source, options, device), so re-rendering
a scene or changing a param never rebuilds; across processes the driver's
or pyopencl's on-disk binary cache (keyed the same way) skips the compiler.
A build marks the process as using the driver's kernel cache
(fractalc/drivers.py clears a cache whose user died). Compiler output is
kept out of the terminal unless asked for ($FRACTALC_VERBOSE or
`--verbose`).
"""
from __future__ import annotations

import hashlib
import os
import sys
import tempfile
import warnings
from contextlib import contextmanager
from dataclasses import dataclass

from .cache import cache_dir
from .devices import Device
from .drivers import clear_driver_cache, mark_building, opencl
from .errors import RenderError

VERBOSE_ENVIRONMENT = "FRACTALC_VERBOSE"


def verbose() -> bool:
    return os.environ.get(VERBOSE_ENVIRONMENT, "") not in ("", "0")


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
    mark_building()
    with _building_alone(key):
        program = _compile(source, device, options)
        if not _has_kernels(program, kernels):
            clear_driver_cache()
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
    cl = opencl()
    try:
        return set(kernels) <= {k.function_name for k in program.all_kernels()}
    except cl.Error:
        return False


def _compile(source: str, device: Device, options: tuple[str, ...]):
    cl = opencl()
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
    cl = opencl()
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
