"""The OpenCL drivers: the ones fractalc brings, registered with the ICD
loader before it starts (`opencl`), their kernel caches, and every device of
every driver (`platform_devices`).

pip installs two CPU drivers with fractalc on Linux x86-64: PoCL
(`pocl-binary-distribution`, which pyopencl's own loader finds) and Intel's
OpenCL CPU runtime (`intel-opencl-rt`, with `intel-cmplr-lib-rt` and `tbb`).
The Intel wheel's `.icd` file names a placeholder path
(/opt/anaconda1anaconda2anaconda3/...), so the loader would skip it. Before
the loader starts, `register` writes a vendors folder in fractalc's cache
holding the .icd files the loader would read anyway (the system's folder, or
what a user's $OCL_ICD_VENDORS names) plus one naming the runtime's real
library, and points $OCL_ICD_VENDORS at it, for this process and the
processes it starts. $FRACTALC_BUNDLED_DRIVERS=0 leaves the bundled drivers
out: the loader then sees exactly what it would without fractalc.

PoCL's kernel cache is fractalc's own (`<cache>/pocl`, unless
$POCL_CACHE_DIR is set): a process that dies inside the driver (a compiler
crash) leaves a half-built entry there, which makes every later build of
that kernel fail. A marker file lives from a process's first build to its
normal exit; a marker whose process is gone says the cache may hold such an
entry, and the cache is cleared, but only while no other process is using
it (clearing it under another's build made PoCL abort that build).
"""
from __future__ import annotations

import atexit
import ctypes
import hashlib
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from .cache import cache_dir

SWITCH_ENVIRONMENT = "FRACTALC_BUNDLED_DRIVERS"     # "0": register none
VENDORS_ENVIRONMENT = "OCL_ICD_VENDORS"             # read by ocl-icd and the Khronos loader
SYSTEM_VENDORS = Path("/etc/OpenCL/vendors")
REGISTERED_ENVIRONMENT = "FRACTALC_ICD_FOLDER"      # the folder this process pointed the loader at


@dataclass(frozen=True)
class BundledDriver:
    """A driver that a pip package installs without a usable .icd file."""
    distribution: str           # the package that holds the library
    library: str                # the ICD library's file name
    icd_name: str               # the .icd file fractalc writes for it
    companions: tuple[tuple[str, str], ...]   # (package, library) it links against, in load order


BUNDLED = (
    BundledDriver("intel-opencl-rt", "libintelocl.so", "fractalc-intel-cpu.icd",
                  (("intel-cmplr-lib-rt", "libintlc.so.5"), ("intel-cmplr-lib-rt", "libimf.so"),
                   ("intel-cmplr-lib-rt", "libsvml.so"), ("intel-cmplr-lib-rt", "libirng.so"),
                   ("tbb", "libtbb.so.12"))),
)


def installed_file(distribution: str, name: str) -> Path | None:
    """Where package `distribution` installed a file called `name`, if it did."""
    try:
        files = metadata.distribution(distribution).files or ()
    except metadata.PackageNotFoundError:
        return None
    for file in files:
        if file.name == name:
            path = Path(file.locate()).resolve()
            if path.is_file():
                return path
    return None


def bundled_libraries() -> list[tuple[BundledDriver, Path]]:
    """The bundled drivers installed here, with their libraries."""
    found = []
    for driver in BUNDLED:
        library = installed_file(driver.distribution, driver.library)
        if library is not None:
            found.append((driver, library))
    return found


def loader_entries(environment) -> dict[str, str]:
    """The .icd files the loader reads without fractalc, as {file name:
    contents}: $OCL_ICD_VENDORS (a folder, one .icd file or a library
    name), else $OPENCL_VENDOR_PATH's folder, else /etc/OpenCL/vendors."""
    named = environment.get(VENDORS_ENVIRONMENT) or ""
    folder = Path(named or environment.get("OPENCL_VENDOR_PATH") or SYSTEM_VENDORS)
    if named and not folder.is_dir():
        if folder.is_file():
            return {_icd_name(folder.name): _read(folder)}
        return {"user-library.icd": named}
    try:
        files = sorted(folder.glob("*.icd"))
    except OSError:
        return {}
    return {f.name: _read(f) for f in files if f.is_file()}


def _icd_name(name: str) -> str:
    return name if name.endswith(".icd") else name + ".icd"


def _read(path: Path) -> str:
    try:
        return path.read_text(errors="replace").strip()
    except OSError:
        return ""


def vendors_folder(environment, bundled: list[tuple[BundledDriver, Path]]) -> dict[str, str]:
    """What the loader should read: every entry it reads already, and each
    bundled driver whose library none of them names already."""
    entries = loader_entries(environment)
    listed = {os.path.basename(text.splitlines()[0]) for text in entries.values() if text}
    for driver, library in bundled:
        if driver.library not in listed and library.name not in listed:
            entries[driver.icd_name] = str(library)
    return entries


def _write_folder(entries: dict[str, str]) -> Path:
    """The vendors folder holding `entries`, named by its contents (so
    processes that register alike share one, written atomically)."""
    digest = hashlib.sha256(repr(sorted(entries.items())).encode()).hexdigest()[:16]
    folder = cache_dir() / "icd" / digest
    if folder.is_dir():
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=".icd-", dir=folder.parent))
    for name, text in entries.items():
        (scratch / name).write_text(text + "\n")
    try:
        os.rename(scratch, folder)
    except OSError:         # another process wrote the same folder first
        shutil.rmtree(scratch, ignore_errors=True)
    return folder


def _load_companions(driver: BundledDriver, library: Path) -> None:
    """Load the libraries `library` links against that its own folder
    lacks (its RUNPATH is $ORIGIN; a layout where pip put the packages in
    different folders would make the loader skip it)."""
    for distribution, name in driver.companions:
        if (library.parent / name).exists():
            continue
        companion = installed_file(distribution, name)
        if companion is not None:
            try:
                ctypes.CDLL(str(companion), mode=ctypes.RTLD_GLOBAL)
            except OSError:
                pass        # the loader then skips the driver, as without fractalc


def bundled_enabled() -> bool:
    return os.environ.get(SWITCH_ENVIRONMENT, "1").strip() not in ("0", "no", "off", "false")


@lru_cache(maxsize=1)
def register() -> None:
    """Register the bundled drivers with the ICD loader of this process
    (before it starts) and of its children; see the module docstring."""
    if not bundled_enabled():
        return
    if os.environ.get(VENDORS_ENVIRONMENT) and os.environ.get(VENDORS_ENVIRONMENT) == os.environ.get(
            REGISTERED_ENVIRONMENT):
        return      # a parent fractalc process registered them
    bundled = bundled_libraries()
    if not bundled:
        return
    entries = vendors_folder(os.environ, bundled)
    if entries == loader_entries(os.environ):
        return      # the system lists them already
    try:
        folder = str(_write_folder(entries))
    except OSError:
        return      # no cache folder: the loader sees what it would without fractalc
    for driver, library in bundled:
        _load_companions(driver, library)
    os.environ[VENDORS_ENVIRONMENT] = os.environ[REGISTERED_ENVIRONMENT] = folder


def opencl():
    """pyopencl, with the bundled drivers registered and PoCL's kernel cache
    fractalc's own (both must happen before the loader starts)."""
    register()
    _own_driver_cache()
    import pyopencl
    return pyopencl


def platform_devices(cl=None) -> list:
    """Every device of every OpenCL platform, in the loader's order (the
    index `--device N` names); `cl`: pyopencl as loaded already (the lane
    probe's child, which leaves the kernel cache's markers alone)."""
    cl = cl or opencl()
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


# ---- the drivers' kernel caches ----------------------------------------------

def driver_cache_dir() -> str:
    return os.environ.get("POCL_CACHE_DIR") or str(cache_dir() / "pocl")


def building_markers() -> Path:
    """The folder of the markers of the processes that use the driver's
    kernel cache (see the module docstring), a file per process id."""
    return cache_dir() / "building"


def building_marker(pid: int) -> Path:
    return building_markers() / str(pid)


@lru_cache(maxsize=1)
def _own_driver_cache() -> None:
    """Point PoCL at fractalc's kernel cache (before the driver loads) and
    clear it if a process died while using it."""
    os.environ["POCL_CACHE_DIR"] = driver_cache_dir()
    markers = building_markers()
    found = list(markers.glob("*")) if markers.is_dir() else []
    dead = [marker for marker in found if not _alive(marker.name)]
    if not dead or len(dead) < len(found):
        return      # nothing to clear, or another process builds into the cache now: the last one out clears it
    print(f"fractalc: a fractalc process ({dead[0].name}) died while using the OpenCL driver; "
          "clearing its kernel cache. If it happens again, set FRACTALC_LANES=8 (or 4, 1), or "
          "run 'fractalc devices --probe'", file=sys.stderr)
    clear_driver_cache()
    for marker in dead:
        marker.unlink(missing_ok=True)


def clear_driver_cache() -> None:
    shutil.rmtree(driver_cache_dir(), ignore_errors=True)


def _alive(pid: str) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ValueError, ProcessLookupError):
        return False
    except PermissionError:
        return True
    return True


@lru_cache(maxsize=1)
def mark_building() -> None:
    """Leave a marker until this process exits normally (see the module
    docstring)."""
    marker = building_marker(os.getpid())
    try:
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(driver_cache_dir())
    except OSError:
        return
    atexit.register(lambda: marker.unlink(missing_ok=True))
