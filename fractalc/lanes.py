"""Rays per work-item for a device (`choose`): the widest of 16, 8, 4 and 1
lanes that the device's OpenCL compiler builds and runs correctly.

Vector lanes are how a CPU driver runs many rays at once, but not every
driver handles every width: pip's PoCL 3.0 on an AVX-512 CPU crashes the
whole process compiling a float16 `sqrt`. So each width is tried first by a
probe (stdlib_cl/probe.cl: every built-in function the kernels call, at
that width, in float and double) in a child process with a cache folder of
its own, where a crash or a hang costs only the child. The answer is kept on
disk per platform, driver version, device and probe text; `FRACTALC_LANES`
or `--lanes` overrides it; GPUs run one ray per work-item and need no probe.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from .resources import resource_dir

WIDTHS = (16, 8, 4, 1)
CHOICES = (1, 2, 4, 8, 16)
ENVIRONMENT = "FRACTALC_LANES"
CACHE_ENVIRONMENT = "FRACTALC_CACHE_DIR"
PROBE_TIMEOUT = 180.0      # seconds for one width: a compiler that takes longer has failed
PROBE_COUNT = 256          # probe inputs (a multiple of every width)

# The probe's results, row by row (stdlib_cl/probe.cl), with their float64
# references; `steps` may differ by one where an orbit lands on the bailout.
PROBE_FUNCTIONS: tuple[tuple[str, Callable], ...] = (
    ("sqrt", lambda x, y: np.sqrt(x)), ("rsqrt", lambda x, y: 1 / np.sqrt(x)),
    ("sin", lambda x, y: np.sin(x)), ("cos", lambda x, y: np.cos(x)), ("tan", lambda x, y: np.tan(x)),
    ("asin", lambda x, y: np.arcsin(x)), ("acos", lambda x, y: np.arccos(x)), ("atan", lambda x, y: np.arctan(x)),
    ("atan2", lambda x, y: np.arctan2(x, y)), ("exp", lambda x, y: np.exp(x)), ("log", lambda x, y: np.log(y)),
    ("pow", lambda x, y: y ** x), ("fabs", lambda x, y: np.abs(x - 0.5)), ("floor", lambda x, y: np.floor(4 * x)),
    ("round", lambda x, y: np.floor(4 * x + 0.5)), ("fmin", lambda x, y: np.minimum(x, y - 1)),
    ("fmax", lambda x, y: np.maximum(x, y - 1)), ("min", lambda x, y: np.minimum(x, y - 1)),
    ("max", lambda x, y: np.maximum(x, y - 1)), ("clamp", lambda x, y: np.clip(x, 0.25, 0.75)),
    ("mix", lambda x, y: x + (y - x) * 0.25), ("sincos", lambda x, y: np.sin(x) + np.cos(x)),
    ("select", lambda x, y: np.where(x < 0.5, y, x)), ("ceil", lambda x, y: np.ceil(4 * x)),
    ("native_sqrt", lambda x, y: np.sqrt(x)), ("native_rsqrt", lambda x, y: 1 / np.sqrt(x)),
    ("native_sin", lambda x, y: np.sin(x)), ("native_cos", lambda x, y: np.cos(x)),
    ("native_exp", lambda x, y: np.exp(x)), ("native_log", lambda x, y: np.log(y)),
    ("steps", lambda x, y: _escape_steps(y)),
    ("uint", lambda x, y: ((x * 1000).astype(np.uint32) * 3) >> 1),
)
_TOLERANCE = {"steps": 1.0, "floor": 1.0, "round": 1.0, "ceil": 1.0, "uint": 2.0}   # absolute, where exactness is luck


def _escape_steps(y: np.ndarray) -> np.ndarray:
    z, steps = np.zeros_like(y), np.zeros_like(y)
    for _ in range(64):
        active = np.abs(z) <= 2
        z = np.where(active, z * z + y, z)
        steps += active
    return steps


def probe_inputs() -> tuple[np.ndarray, np.ndarray]:
    """The probe's x in (0, 1) and y in (0.5, 2), away from where floor,
    round and ceil jump."""
    t = (np.arange(PROBE_COUNT) + 0.5) / PROBE_COUNT
    return 0.05 + 0.9 * t, 0.5 + 1.5 * t[::-1]


def probe_error(results: np.ndarray, double: bool) -> str | None:
    """Why the probe's (PROBE_RESULTS, count) results are wrong, or None."""
    x, y = probe_inputs()
    for row, (name, reference) in zip(results, PROBE_FUNCTIONS):
        expected = reference(x, y).astype(np.float64)
        tolerance = _TOLERANCE.get(name, 1e-3 * (1 + np.abs(expected)))
        wrong = ~(np.abs(row - expected) <= tolerance)
        if wrong.any():
            k = int(np.argmax(wrong))
            return f"{name} gave {row[k]!r} for {expected[k]!r} ({'double' if double else 'float'})"
    return None


def probe_source(lanes: int, double: bool) -> str:
    root = resource_dir("stdlib_cl")
    text = "\n".join([f"#define LANES {lanes}", f"#define PRECISION_DOUBLE {int(double)}",
                      "#define FAST_MATH 0", (root / "prelude.cl").read_text(), (root / "probe.cl").read_text()])
    if double:
        from .emit import double_literals
        text = double_literals(text)
    return text


# ---- the child process ---------------------------------------------------------

def _probe_in_this_process(device_index: int, lanes: int, double: bool) -> str | None:
    import pyopencl as cl
    from .build import all_devices
    device = all_devices()[device_index]
    context = cl.Context([device])
    queue = cl.CommandQueue(context)
    program = cl.Program(context, probe_source(lanes, double)).build()
    scalar = np.float64 if double else np.float32
    x, y = probe_inputs()
    data = np.concatenate([x, y]).astype(scalar)
    out = np.empty((len(PROBE_FUNCTIONS), PROBE_COUNT), dtype=scalar)
    flags = cl.mem_flags
    in_buffer = cl.Buffer(context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=data)
    out_buffer = cl.Buffer(context, flags.WRITE_ONLY, out.nbytes)
    program.probe(queue, (PROBE_COUNT // lanes,), None, in_buffer, out_buffer, np.int32(PROBE_COUNT))
    cl.enqueue_copy(queue, out, out_buffer)
    return probe_error(out.astype(np.float64), double)


def child_main(argv: list[str]) -> int:
    """The probe child: `DEVICE_INDEX LANES PRECISION...`; prints one JSON
    verdict line per precision (float, double), as each is known."""
    import warnings
    warnings.simplefilter("ignore")     # compiler chatter is not the verdict
    device_index, lanes = int(argv[0]), int(argv[1])
    for precision in argv[2:]:
        error = _probe_in_this_process(device_index, lanes, precision == "double")
        print(json.dumps({"precision": precision, "error": error}), flush=True)
    return 0


def _describe_exit(code: int) -> str:
    if code < 0:
        try:
            import signal
            return f"the OpenCL compiler crashed ({signal.Signals(-code).name})"
        except ValueError:
            return f"the OpenCL compiler crashed (signal {-code})"
    return f"the probe exited with status {code}"


def probe_command(device_index: int, lanes: int, precisions: tuple[str, ...]) -> list[str]:
    return [sys.executable, "-c", "import sys; from fractalc.lanes import child_main; "
            "sys.exit(child_main(sys.argv[1:]))", str(device_index), str(lanes), *precisions]


def run_probe(device_index: int, lanes: int, precisions: tuple[str, ...], command: list[str] | None = None,
              timeout: float = PROBE_TIMEOUT) -> str | None:
    """Run the probe of `lanes` in a child (`command`, by default the real
    one); None if it passed for every precision, else why it failed. The
    child gets a driver cache folder of its own (a crash leaves nothing
    half-built in the user's), and its output never reaches the terminal."""
    command = command or probe_command(device_index, lanes, precisions)
    with tempfile.TemporaryDirectory(prefix="fractalc-probe-") as scratch:
        environment = dict(os.environ, POCL_CACHE_DIR=scratch, PYOPENCL_NO_CACHE="1",
                           PYOPENCL_CACHE_DIR=scratch)
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=timeout,
                                  env=environment, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return f"the OpenCL compiler took over {timeout:.0f} s"
    verdicts = {}
    for line in done.stdout.splitlines():
        try:
            verdict = json.loads(line)
            verdicts[verdict["precision"]] = verdict["error"]
        except (ValueError, KeyError, TypeError):
            continue
    for precision in precisions:
        if precision not in verdicts:
            failure = _describe_exit(done.returncode) if done.returncode else "the probe printed no verdict"
            return f"{failure} ({precision})"
        if verdicts[precision] is not None:
            return verdicts[precision]
    return None


# ---- the choice ----------------------------------------------------------------

@dataclass(frozen=True)
class LaneChoice:
    lanes: int
    reason: str                              # how it was chosen, in words
    failures: tuple[tuple[int, str], ...] = ()   # (width, why) of the wider widths that failed


def cache_dir() -> Path:
    """fractalc's own cache folder: $FRACTALC_CACHE_DIR, else the XDG cache."""
    if os.environ.get(CACHE_ENVIRONMENT):
        return Path(os.environ[CACHE_ENVIRONMENT])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "fractalc"


@lru_cache(maxsize=1)
def _probe_version() -> str:
    root = resource_dir("stdlib_cl")
    text = (root / "prelude.cl").read_text() + (root / "probe.cl").read_text()
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@lru_cache(maxsize=1)
def _host_cpu() -> str:
    """The CPU's model and feature flags: a driver may name different CPUs
    alike (PoCL: "pthread-AMD EPYC" on Zen 3 and on Zen 4, AVX-512 or not)."""
    try:
        with open("/proc/cpuinfo") as f:
            lines = [line for line in f.read(1 << 20).splitlines() if line.startswith(("model name", "flags"))]
    except OSError:
        return ""
    return hashlib.sha256("\n".join(sorted(set(lines))).encode()).hexdigest()[:16]


def device_key(info) -> str:
    host = _host_cpu() if info.kind == "CPU" else ""
    return " | ".join((info.platform, info.platform_version, info.name, info.driver, host, _probe_version()))


def parse_lanes(text: str, where: str) -> int:
    """A lane count given by the user (`where` names the option)."""
    try:
        lanes = int(text) if text.strip().isascii() else None
    except ValueError:
        lanes = None
    if lanes not in CHOICES:
        raise ValueError(f"{where}: lanes must be one of {', '.join(map(str, CHOICES))}, not '{text}'")
    return lanes


def _read_cache(path: Path) -> dict:
    try:
        entries = json.loads(path.read_text())
        return entries if isinstance(entries, dict) else {}
    except (OSError, ValueError):
        return {}


def _write_cache(path: Path, entries: dict) -> None:
    """Atomically (several processes may probe at once); a cache that
    cannot be written only costs a probe next time."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(prefix=".lanes-", dir=path.parent)
        with os.fdopen(handle, "w") as f:
            json.dump(entries, f, indent=1, sort_keys=True)
        os.replace(temporary, path)
    except OSError:
        pass


_chosen: dict = {}     # (cache file, device key) -> the choice made in this process


def choose(info, override: int | None = None, probe: Callable[..., str | None] = run_probe,
           refresh: bool = False) -> LaneChoice:
    """The lanes for device `info` (a build.DeviceInfo): `override`, else
    $FRACTALC_LANES, else 1 on GPUs, else the cached or probed widest
    width that builds and runs (16 -> 8 -> 4 -> 1)."""
    if override is not None:
        return LaneChoice(override, "set by --lanes")
    if os.environ.get(ENVIRONMENT):
        return LaneChoice(parse_lanes(os.environ[ENVIRONMENT], ENVIRONMENT), f"set by {ENVIRONMENT}")
    if info.kind == "GPU":
        return LaneChoice(1, "one ray per work-item on a GPU")
    path = cache_dir() / "lanes.json"
    key = device_key(info)
    if not refresh and (path, key) in _chosen:
        return _chosen[path, key]
    entry = None if refresh else _read_cache(path).get(key)
    if entry and entry.get("lanes") in WIDTHS:
        choice = LaneChoice(entry["lanes"], "probed (cached)", tuple((w, why) for w, why in entry.get("failures", [])))
        _chosen[path, key] = choice
        return choice
    failures = []
    for width in WIDTHS:
        why = probe(info.index, width, ("float", "double") if info.double else ("float",))
        if why is None:
            break
        failures.append((width, why))
    else:
        width = None
    if width is None:
        from .errors import RenderError
        raise RenderError(f"the OpenCL device '{info.name}' failed the lane probe at every width "
                          f"({failures[-1][1]}); try another device (fractalc devices)")
    entries = _read_cache(path)
    entries[key] = {"lanes": width, "failures": failures}
    _write_cache(path, entries)
    _chosen[path, key] = LaneChoice(width, "probed", tuple(failures))
    return _chosen[path, key]


def describe(choice: LaneChoice) -> str:
    text = f"{choice.lanes} lane{'s' if choice.lanes > 1 else ''} ({choice.reason})"
    if choice.failures:
        text += "; " + "; ".join(f"{w} failed: {why}" for w, why in choice.failures)
    return text
