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
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from .cache import cache_dir
from .drivers import platform_devices, register
from .emit import double_literals
from .errors import RenderError
from .resources import resource_dir

WIDTHS = (16, 8, 4, 1)
CHOICES = (1, 2, 4, 8, 16)
ENVIRONMENT = "FRACTALC_LANES"
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


def native_error(results: np.ndarray, double: bool) -> float | None:
    """The worst relative error of the probe's `native_` rows, or None in
    double (where they are the exact functions)."""
    if double:
        return None
    x, y = (v.astype(np.float32).astype(np.float64) for v in probe_inputs())
    worst = 0.0
    for row, (name, reference) in zip(results, PROBE_FUNCTIONS):
        if name.startswith("native_"):
            expected = reference(x, y)
            worst = max(worst, float(np.max(np.abs(row - expected) / np.maximum(np.abs(expected), 1e-30))))
    return worst


def probe_source(lanes: int, double: bool) -> str:
    root = resource_dir("stdlib_cl")
    text = "\n".join([f"#define LANES {lanes}", f"#define PRECISION_DOUBLE {int(double)}",
                      "#define FAST_MATH 0", (root / "prelude.cl").read_text(), (root / "probe.cl").read_text()])
    if double:
        text = double_literals(text)
    return text


# ---- the child process ---------------------------------------------------------

def _probe_in_this_process(device_index: int, lanes: int, double: bool) -> dict:
    """The verdict: `error` (None if the probe passed) and `native_error`."""
    register()      # before the loader starts; the driver cache is the child's own (run_probe)
    import pyopencl as cl
    device = platform_devices(cl)[device_index]
    try:
        context = cl.Context([device])
    except cl.Error as error:
        raise ProbeBuildFailed(first_error_line(str(error)), anything=False) from None
    queue = cl.CommandQueue(context)
    try:
        program = cl.Program(context, probe_source(lanes, double)).build()
    except cl.Error as error:
        raise ProbeBuildFailed(first_error_line(str(error)), _builds_anything(context)) from None
    scalar = np.float64 if double else np.float32
    x, y = probe_inputs()
    data = np.concatenate([x, y]).astype(scalar)
    out = np.empty((len(PROBE_FUNCTIONS), PROBE_COUNT), dtype=scalar)
    flags = cl.mem_flags
    in_buffer = cl.Buffer(context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=data)
    out_buffer = cl.Buffer(context, flags.WRITE_ONLY, out.nbytes)
    program.probe(queue, (PROBE_COUNT // lanes,), None, in_buffer, out_buffer, np.int32(PROBE_COUNT))
    cl.enqueue_copy(queue, out, out_buffer)
    results = out.astype(np.float64)
    return {"error": probe_error(results, double), "native_error": native_error(results, double)}


class ProbeBuildFailed(Exception):
    """The probe did not build (or the device gave no context);
    `anything`: whether the driver builds a trivial kernel (if not, no
    width will do)."""

    def __init__(self, line: str, anything: bool):
        super().__init__(line)
        self.line, self.anything = line, anything


def _builds_anything(context) -> bool:
    import pyopencl as cl
    try:
        cl.Program(context, (resource_dir("stdlib_cl") / "trivial.cl").read_text()).build()
    except cl.Error:
        return False
    return True


def first_error_line(log: str) -> str:
    """The driver's own first error line in a build failure's text: the
    first `error:` line (clang's), else the build log's first line."""
    lines = [line.strip() for line in log.splitlines() if line.strip()]
    marked = [line for line in lines if re.search(r"\berror\b\s*:", line, re.IGNORECASE)
              and not line.startswith("clBuildProgram failed")]
    if marked:
        return marked[0][:300]
    after_header = [i for i, line in enumerate(lines) if line.startswith("Build on")]
    if after_header and after_header[0] + 1 < len(lines):
        return lines[after_header[0] + 1][:300]
    return (lines[0] if lines else "no build log")[:300]


def child_main(argv: list[str]) -> int:
    """The probe child: `DEVICE_INDEX LANES PRECISION...`; prints one JSON
    verdict line per precision (float, double), as each is known."""
    import warnings
    warnings.simplefilter("ignore")     # compiler chatter is not the verdict
    device_index, lanes = int(argv[0]), int(argv[1])
    for precision in argv[2:]:
        try:
            verdict = _probe_in_this_process(device_index, lanes, precision == "double")
        except ProbeBuildFailed as failed:
            verdict = {"error": failed.line, "builds": failed.anything}
        print(json.dumps({"precision": precision, **verdict}), flush=True)
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


@dataclass(frozen=True)
class ProbeFailure:
    why: str                # in words, with the driver's own first error line where it gave one
    hopeless: bool = False  # the driver builds no kernel at all: no narrower width will do


@dataclass(frozen=True)
class ProbePassed:
    native_error: float | None = None   # the worst relative error of the float native_ functions


def run_probe(device_index: int, lanes: int, precisions: tuple[str, ...], command: list[str] | None = None,
              timeout: float = PROBE_TIMEOUT) -> ProbeFailure | ProbePassed:
    """Run the probe of `lanes` in a child (`command`, by default the real
    one): passed for every precision, or why it failed. The child gets a
    driver cache folder of its own (a crash leaves nothing half-built in
    the user's), and its output never reaches the terminal."""
    command = command or probe_command(device_index, lanes, precisions)
    with tempfile.TemporaryDirectory(prefix="fractalc-probe-") as scratch:
        environment = dict(os.environ, POCL_CACHE_DIR=scratch, PYOPENCL_NO_CACHE="1")
        try:
            done = subprocess.run(command, capture_output=True, text=True, timeout=timeout,
                                  env=environment, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return ProbeFailure(f"the OpenCL compiler took over {timeout:.0f} s")
    verdicts = {}
    for line in done.stdout.splitlines():
        try:
            verdict = json.loads(line)
            verdicts[verdict["precision"]] = verdict
        except (ValueError, KeyError, TypeError):
            continue
    for precision in precisions:
        if precision not in verdicts:
            failure = _describe_exit(done.returncode) if done.returncode else "the probe printed no verdict"
            return ProbeFailure(f"{failure} ({precision})")
        if verdicts[precision].get("error") is not None:
            return ProbeFailure(f"{verdicts[precision]['error']} ({precision})",
                                hopeless=verdicts[precision].get("builds") is False)
    return ProbePassed(verdicts.get("float", {}).get("native_error"))


# ---- the choice ----------------------------------------------------------------

NATIVE_EXACT = 1e-6    # relative error of native_ functions that counts as exact (a few float ulps)


@dataclass(frozen=True)
class LaneChoice:
    lanes: int
    reason: str                              # how it was chosen, in words
    failures: tuple[tuple[int, str], ...] = ()   # (width, why) of the wider widths that failed
    native_error: float | None = None        # the probe's measure of the driver's float native_ functions

    @property
    def native_exact(self) -> bool:
        """Whether `fast_math: auto` may use the native_ functions: the
        probe measured them within a few ulps (PoCL's are the exact
        functions; Intel's native_exp is off by 2e-4)."""
        return self.native_error is not None and self.native_error <= NATIVE_EXACT


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


class UnusableDevice(RenderError):
    """A CPU device whose driver passed the probe at no width: `failures`
    are (width, why), `remembered` says the verdict came from the cache."""

    def __init__(self, info, failures: tuple[tuple[int, str], ...], remembered: bool):
        super().__init__(f"the OpenCL device '{info.name}' failed the lane probe at every width "
                         f"({failures[-1][1]}); try another device (fractalc devices)")
        self.info, self.failures, self.remembered = info, failures, remembered


def choose(info, override: int | None = None, probe: Callable[..., ProbeFailure | ProbePassed] = run_probe,
           refresh: bool = False) -> LaneChoice:
    """The lanes for device `info` (a devices.DeviceInfo): `override`, else
    $FRACTALC_LANES, else 1 on GPUs, else the cached or probed widest
    width that builds and runs (16 -> 8 -> 4 -> 1). A device that passes
    at no width raises UnusableDevice; that verdict is cached too. An
    override knows the driver's native_ functions only from an earlier
    probe (else they count as inexact)."""
    path = cache_dir() / "lanes.json"
    key = device_key(info)
    if override is not None or os.environ.get(ENVIRONMENT):
        lanes, reason = ((override, "set by --lanes") if override is not None else
                         (parse_lanes(os.environ[ENVIRONMENT], ENVIRONMENT), f"set by {ENVIRONMENT}"))
        return LaneChoice(lanes, reason, native_error=(_read_cache(path).get(key) or {}).get("native_error"))
    if info.kind == "GPU":
        return LaneChoice(1, "one ray per work-item on a GPU")
    if not refresh and (path, key) in _chosen:
        return _chosen[path, key]
    entry = None if refresh else _read_cache(path).get(key)
    if entry and (entry.get("lanes") in WIDTHS or entry.get("lanes") is None and entry.get("failures")):
        failures = tuple((w, why) for w, why in entry.get("failures", []))
        if entry["lanes"] is None:
            raise UnusableDevice(info, failures, remembered=True)
        choice = LaneChoice(entry["lanes"], "probed (cached)", failures, entry.get("native_error"))
        _chosen[path, key] = choice
        return choice
    failures, width, native = [], None, None
    for candidate in WIDTHS:
        verdict = probe(info.index, candidate, ("float", "double") if info.double else ("float",))
        if isinstance(verdict, ProbePassed):
            width, native = candidate, verdict.native_error
            break
        failures.append((candidate, verdict.why))
        if verdict.hopeless:
            break
    entries = _read_cache(path)
    entries[key] = {"lanes": width, "failures": failures, "native_error": native}
    _write_cache(path, entries)
    if width is None:
        raise UnusableDevice(info, tuple(failures), remembered=False)
    _chosen[path, key] = LaneChoice(width, "probed", tuple(failures), native)
    return _chosen[path, key]


def describe(choice: LaneChoice) -> str:
    text = f"{choice.lanes} lane{'s' if choice.lanes > 1 else ''} ({choice.reason})"
    if choice.failures:
        text += "; " + "; ".join(f"{w} failed: {why}" for w, why in choice.failures)
    return text
