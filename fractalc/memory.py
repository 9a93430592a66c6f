"""Memory: what this process may still take, work refused before it starts
when its estimate is more, and out-of-memory failures recognised wherever
they happen (numpy's MemoryError, OpenCL's allocation failures), so that
every command answers them in one line (LANGUAGE.md: a runtime failure,
exit 1)."""
from __future__ import annotations

import os

from .errors import RenderError

# Less than any machine that runs fractalc has free: not worth reading the
# system's figure for (0.1 ms, a third of a 640x480 frame's host time)
ALWAYS_GRANTED = 16 * 2 ** 20
# OpenCL's error codes for memory it could not allocate
_OPENCL_CODES = {-4: "MEM_OBJECT_ALLOCATION_FAILURE", -5: "OUT_OF_RESOURCES", -6: "OUT_OF_HOST_MEMORY"}


def _proc_kib(path: str, field: str) -> int | None:
    try:
        with open(path) as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def available() -> int | None:
    """Bytes this process can still allocate: the memory the system has
    available (/proc/meminfo's MemAvailable, else the free pages), and
    within an address-space limit (RLIMIT_AS) what is left of it; None
    where neither can be read."""
    have = _proc_kib("/proc/meminfo", "MemAvailable")
    if have is None:
        try:
            have = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            have = None
    try:
        import resource
        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
    except (ImportError, OSError, ValueError):
        limit = -1
    if limit not in (-1, getattr(resource, "RLIM_INFINITY", -1)):
        used = _proc_kib("/proc/self/status", "VmSize") or 0
        left = max(0, limit - used)
        have = left if have is None else min(have, left)
    return have


def size_text(count: float) -> str:
    """Bytes in words: 1.5 GiB, 300 MiB."""
    for unit, scale in (("TiB", 2 ** 40), ("GiB", 2 ** 30), ("MiB", 2 ** 20)):
        if count >= scale:
            return f"{count / scale:.3g} {unit}"
    return f"{count / 1024:.3g} KiB"


def require_memory(needed: float, what: str) -> None:
    """Refuse work estimated to need `needed` bytes, more than this process
    can have: a RenderError, 'out of memory: WHAT needs ...'. Work under
    ALWAYS_GRANTED bytes goes ahead unasked."""
    if needed < ALWAYS_GRANTED:
        return
    have = available()
    if have is not None and needed > have:
        raise RenderError(f"out of memory: {what} would take about {size_text(needed)}, "
                          f"more than the {size_text(have)} available")


def is_out_of_memory(error: BaseException) -> bool:
    """Whether `error` says memory ran out: MemoryError, or an OpenCL error
    whose code is an allocation failure."""
    if isinstance(error, MemoryError):
        return True
    import sys
    cl = sys.modules.get("pyopencl")     # never imported here just to ask
    if cl is None or not isinstance(error, cl.Error):
        return False
    if isinstance(error, cl.MemoryError):
        return True
    try:
        code = error.code
    except AttributeError:     # an Error made from a message alone
        code = None
    return code in _OPENCL_CODES or any(name in str(error) for name in _OPENCL_CODES.values())
