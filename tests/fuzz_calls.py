"""Fuzz cases for fractalc's command line and Python API (issue 22):
generated command lines and API calls, each run under an address-space
limit (RLIMIT_AS) and a time limit, so that work beyond the machine's
memory and out-of-memory failures are exercised as well as bad values.

A command line is a command and a few of its options (found in the parser,
so that a new option is fuzzed as it is added), each with a value from a
pool of hostile and plausible text; an API call is one public function
with a few of its arguments from a pool of Python values. Every case is a
pure function of (seed, index): `cli_case`, `api_case`.

The verdict (`judge`): a command answers with exit 0, or exit 1 or 2 and
an error line (`fractalc: error:`, `fractalc COMMAND: error:` or
`FILE:LINE:COL: error:`), never a traceback, a crash, a hang or a
temporary file left behind; an API call returns or raises SceneError,
ValueError, TypeError or RenderError with a message. Each case runs in a
process forked from a server that imported fractalc once (`Runner`): no
interpreter start per case.
"""
from __future__ import annotations

import os
import random
import re
import signal
import sys
import tempfile
import traceback
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# The address space a case may add to its server's (which has imported
# fractalc, numpy, OpenCL and OpenImageIO): out-of-memory paths are reached
# by values that ask for more
HEADROOM_BYTES = 1536 * 2 ** 20
CASE_SECONDS = 60         # a case still running after this is a hang

SCENE = ("param p = 1 in [0, 2]\nscene sphere(p) | box((2, 2, 0.2)).translate((0, 0, -1.2))\n"
         "render { width: 16, height: 12, max_steps: 64 }\n"
         "path { 0: { position: (0, -4, 1), p: 0.5 }, 1: { position: (4, 0, 1) } }\n")

# Option values: hostile numbers and text, and plausible ones (small, so
# that what is accepted renders in moments: `mesh --resolution=1e3` is a
# billion evaluations, minutes of valid work that the time limit took for a hang)
NUMBERS = ("0", "-1", "1", "2", "3", "8", "16", "0.5", "1e-300", "2.5", "65536", "65537", "99999999999999999999",
           "1e308", "inf", "-inf", "nan", "٣", "１", "", " ", "0x10", "1_0", "1e1", "-0", "4294967296")
TEXTS = ("", "x", "%d", "%c", "%4d/x.png", "a\x01b", "\u202e", "..", "/", "/dev/null", "-", "--", "=", ",",
         "tcp://127.0.0.1:1", "inproc://x", "tls://h:1", "p=1", "p=inf", "ao=٣", "fov=0", "fog=off",
         "glow.strength=1e39", "0-1", "5-", "3-1", "-1,-1,-1,1,1,1", "1,1,1,-1,-1,-1", "-1e30,-1,-1,1e30,1,1",
         "cpu", "gpu", "99", "P,diffuse", "nonsense", "float", "double", "zip", "none", "1080p", "epsilon_scale=2")
OUTPUTS = {"render": ("out.png", "out.exr", "out.jpg", "dir/out.png", "out"), "compile": ("out.cl",),
           "animate": ("f/f_%03d.png", "f/f_%03d.exr", "f/%c.png", "f/%4d/x.png", "f_%d.jpg"),
           "mesh": ("m.ply", "m.stl", "m.obj", "m.txt"), "bench": ("b.json",)}
# commands fuzzed: `view` opens a window, `devices` takes no scene
COMMANDS = ("render", "compile", "check", "bench", "animate", "mesh")
SKIPPED_OPTIONS = {"--help", "--no-cache", "--sweep", "--plot", "--csv", "--vary", "--mp4", "--denoise",
                   "--verbose", "--quiet", "--overwrite"}


@dataclass(frozen=True)
class Case:
    kind: str                 # "cli" or "api"
    call: tuple               # argv, or (function name, ((argument, value), ...))

    def __str__(self) -> str:
        if self.kind == "cli":
            return "fractalc " + " ".join(_shell_word(a) for a in self.call)
        name, arguments = self.call
        return f"{name}({', '.join(f'{k}={_shown(v)}' for k, v in arguments)})"


def _shell_word(text: str) -> str:
    return text if re.fullmatch(r"[\w./%=:,+-]+", text) else repr(text)


def _shown(value) -> str:
    text = repr(value) if not isinstance(value, Opaque) else value.name
    return text if len(text) <= 60 else text[:57] + "..."


@dataclass(frozen=True)
class Opaque:
    """A value that is not plain data, made in the child (an object, a path)."""
    name: str


# ---- command lines ---------------------------------------------------------------

def _options(command: str) -> list:
    from fractalc import cli
    parser = cli._parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    return [a for a in sub._actions if a.option_strings and max(a.option_strings, key=len) not in SKIPPED_OPTIONS]


def cli_case(seed: int, index: int) -> Case:
    rng = random.Random(f"cli:{seed}:{index}")
    command = rng.choice(COMMANDS)
    argv = [command, "scene.frac"]
    if command in OUTPUTS:
        argv += ["-o", rng.choice(OUTPUTS[command])] if command != "bench" or rng.random() < 0.3 else []
    if command == "check" and rng.random() < 0.8:
        argv.append("--de")
    options = [a for a in _options(command) if "-o" not in a.option_strings]
    for action in rng.sample(options, min(len(options), rng.choice((1, 1, 2, 3)))):
        name = max(action.option_strings, key=len)
        if action.nargs == 0:
            argv.append(name)
            continue
        numeric = getattr(action.type, "argument", None) or name in ("--seed", "--lanes", "--device")
        value = rng.choice(NUMBERS if numeric and rng.random() < 0.85 else TEXTS)
        if action.choices and rng.random() < 0.6:
            value = str(rng.choice(list(action.choices)))
        argv.append(f"{name}={value}")
    return Case("cli", tuple(argv))


# ---- API calls ---------------------------------------------------------------------

VALUES = (None, True, False, 0, 1, 2, -1, 16, 65536, 2 ** 64, 10 ** 400, 0.5, 1e300, float("nan"), float("inf"),
          -float("inf"), "", "x", "٣", "cpu", "float", "double", b"x", (), [], {}, (1, 2, 3), (float("nan"), 0, 0),
          [[0.0, 0.0, 0.0]], ["P"], ["nonsense"], {"p": 10 ** 400}, {"p": "x"}, {"q": 1}, [1, 2],
          Opaque("object()"), Opaque("Path('out.png')"), Opaque("Path('f_%02d.png')"), "f_%c.png", "out.exr")
# function: the arguments it takes, by name (render keys among a render's)
FUNCTIONS = {
    "loads": ("text", "params", "precision", "device", "path", "lanes"),
    "load": ("path", "params", "precision", "device", "lanes"),
    "Scene.render": ("seed", "camera", "cluster", "width", "height", "samples", "aovs", "environment_map",
                     "max_steps", "ao", "epsilon", "background", "fog", "glow", "precision", "integrator",
                     "bounces", "exposure", "reflections", "nonsense_key"),
    "Scene.distance": ("points",),
    "Scene.set_params": ("values",),
    "Scene.kernel_source": ("lanes", "max_steps", "samples", "fog"),
    "Scene.set_defaults": ("camera", "ao", "width", "background"),
    "Scene.mesh": ("resolution", "bounds"),
    "Image.save": ("path", "half", "compression", "bits"),
    "Camera": ("position", "target", "up", "fov", "aperture", "focus", "projection", "stereo"),
    "animate.render_frames": ("pattern", "fps", "seed", "frames"),
    "paths.frame_times": ("fps",),
    "cluster.connect": ("workers", "address"),
}
REQUIRED = {"loads": {"text": SCENE}, "load": {"path": "scene.frac"}, "Scene.distance": {"points": [[0.0, 0.0, 0.0]]},
            "Scene.set_params": {"values": {"p": 1.0}}, "Image.save": {"path": "image.png"},
            "animate.render_frames": {"pattern": "f_%02d.png", "fps": 2}, "paths.frame_times": {"fps": 2},
            "Scene.mesh": {"resolution": 8}, "cluster.connect": {"workers": 1}}


def api_case(seed: int, index: int) -> Case:
    rng = random.Random(f"api:{seed}:{index}")
    name = rng.choice(sorted(FUNCTIONS))
    arguments = dict(REQUIRED.get(name, {}))
    for argument in rng.sample(FUNCTIONS[name], min(len(FUNCTIONS[name]), rng.choice((1, 1, 2)))):
        arguments[argument] = rng.choice(VALUES)
    return Case("api", (name, tuple(arguments.items())))


def case(seed: int, index: int) -> Case:
    """Command lines and API calls in turn."""
    return cli_case(seed, index // 2) if index % 2 == 0 else api_case(seed, index // 2)


# ---- running and judging --------------------------------------------------------------

@dataclass(frozen=True)
class Verdict:
    outcome: str          # "answered" (a result or an error in words) or "failed"
    failure: str = ""     # what kind of failure
    detail: str = ""


ANSWER = re.compile(r"(fractalc( \w+)?: error: |.*:\d+:\d+: error: )\S")


def _value(value, folder: str):
    if isinstance(value, Opaque):
        return {"object()": object(), "Path('out.png')": Path(folder) / "out.png",
                "Path('f_%02d.png')": Path(folder) / "f_%02d.png"}[value.name]
    return value


def _call(case: Case, folder: str):
    """Run an API case here (in the forked child)."""
    import fractalc
    from fractalc import animate, cluster, paths
    name, arguments = case.call
    kwargs = {k: _value(v, folder) for k, v in arguments}
    if name in ("loads", "load", "Camera"):
        return {"loads": fractalc.loads, "load": fractalc.load, "Camera": fractalc.Camera}[name](**kwargs)
    scene = fractalc.loads(SCENE)
    if name == "Image.save":
        return scene.render().save(**kwargs)
    if name == "animate.render_frames":
        return animate.render_frames(scene, **kwargs)
    if name == "paths.frame_times":
        return paths.frame_times(scene.checked.path, **kwargs)
    if name == "cluster.connect":
        with cluster.connect(**kwargs):
            return None
    return getattr(scene, name.split(".")[1])(**kwargs)


def _child(case: Case, folder: str, limit: int) -> None:
    """The forked child: limits, then the case; exits with what happened."""
    import resource
    os.chdir(folder)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    signal.alarm(CASE_SECONDS)        # a hang is reported by the parent, which sees SIGALRM
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    err = os.open("stderr.txt", os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(err, 2)
    sys.stderr = os.fdopen(2, "w", buffering=1)
    code = 0
    try:
        if case.kind == "cli":
            from fractalc.cli import main
            code = main(list(case.call))
        else:
            import fractalc
            try:
                _call(case, folder)
            except (fractalc.SceneError, ValueError, TypeError, fractalc.RenderError) as error:
                print(f"refused: {type(error).__name__}: {error}", file=sys.stderr)
                code = 0 if str(error).strip() else 3
    except SystemExit as stop:            # argparse's usage errors
        code = stop.code if isinstance(stop.code, int) else 2
    except BaseException:                 # noqa: BLE001 -- what the fuzzer looks for
        traceback.print_exc()
        code = 4
    sys.stderr.flush()
    os._exit(code)


def run(case: Case, limit: int) -> Verdict:
    """Run `case` in a forked child under `limit` bytes of address space."""
    with tempfile.TemporaryDirectory() as folder:
        Path(folder, "scene.frac").write_text(SCENE)
        pid = os.fork()
        if pid == 0:
            try:
                _child(case, folder, limit)
            finally:
                os._exit(5)
        _, status = os.waitpid(pid, 0)
        err = Path(folder, "stderr.txt").read_text(errors="replace") if Path(folder, "stderr.txt").exists() else ""
        left = [p.name for p in Path(folder).rglob("*") if ".tmp" in p.name or p.name.startswith(".fractalc")]
        return _verdict(case, status, err, left)


def _verdict(case: Case, status: int, err: str, left: list) -> Verdict:
    if os.WIFSIGNALED(status):
        number = os.WTERMSIG(status)
        kind = "hang" if number == signal.SIGALRM else f"killed by {signal.Signals(number).name}"
        return Verdict("failed", kind, err[-2000:])
    code = os.WEXITSTATUS(status)
    if "Traceback" in err or code in (3, 4, 5):
        last = err.strip().splitlines()[-1] if err.strip() else ""
        return Verdict("failed", f"traceback: {last.split(':')[0]}" if code != 3 else "error without words",
                       err[-3000:])
    if left:
        return Verdict("failed", "temporary file left", ", ".join(left))
    if case.kind == "cli" and code != 0:
        lines = [line for line in err.strip().splitlines() if not line.startswith(("usage:", " "))]
        if code not in (1, 2) or not lines or not any(ANSWER.match(line) for line in lines):
            return Verdict("failed", f"exit {code} without an error line", err[-2000:])
    return Verdict("answered", detail=err[-300:])


class Runner:
    """Runs cases in a server process (spawned: a fresh interpreter that
    imports fractalc once and never touches OpenCL), which forks a child
    per case with HEADROOM_BYTES of address space beyond its own; forks
    from a process whose OpenCL driver has threads (a test process) would
    not be safe. Use as a context manager."""

    def __init__(self, headroom: int = HEADROOM_BYTES):
        import multiprocessing
        context = multiprocessing.get_context("spawn")
        self.connection, theirs = context.Pipe()
        # not a daemon: a daemon process may not start processes (a case's local cluster)
        self.server = context.Process(target=_serve, args=(theirs, headroom))

    def __enter__(self):
        self.server.start()
        return self

    def __exit__(self, *exc):
        self.connection.send(None)
        self.server.join(timeout=30)
        if self.server.is_alive():
            self.server.kill()

    def judge(self, case: Case) -> Verdict:
        self.connection.send(case)
        return self.connection.recv()


def _serve(connection, headroom: int) -> None:
    import fractalc  # noqa: F401 -- imported once, for every child
    import fractalc.cli  # noqa: F401
    import numpy  # noqa: F401
    import OpenImageIO  # noqa: F401
    import pyopencl  # noqa: F401
    used = int(next(line for line in open("/proc/self/status") if line.startswith("VmSize")).split()[1]) * 1024
    while True:
        case = connection.recv()
        if case is None:
            return
        connection.send(run(case, used + headroom))


def signature(case: Case, verdict: Verdict) -> str:
    """A failure's kind, for counting: the failure and what was called."""
    where = case.call[0] if case.kind == "cli" else case.call[0]
    return f"{verdict.failure} in {case.kind} {where}"
