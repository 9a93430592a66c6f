"""Runtime failures: exit 1 with one line, no traceback, no output file;
Ctrl-C stops cleanly."""
import os
import signal
import subprocess
import sys

import pytest

from fractalc import build, cli, run

SCENE = "scene sphere(1)\nrender { width: 32, height: 24 }\n"


REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _fractalc(*args, cwd, env=None):
    path = os.pathsep.join([REPO, os.environ.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-m", "fractalc", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONPATH": path, **(env or {})})


@pytest.mark.parametrize("command", [["devices"], ["render", "scene.frac", "-o", "out.png"]])
def test_no_opencl_platform_says_how_to_install_pocl(tmp_path, command):
    (tmp_path / "scene.frac").write_text(SCENE)
    # a cache of its own: a process that another test killed while it used
    # the shared one would add a line here (drivers.py clears the cache then)
    result = _fractalc(*command, cwd=tmp_path, env={"OCL_ICD_VENDORS": str(tmp_path / "no-vendors"),
                                                    "FRACTALC_BUNDLED_DRIVERS": "0",
                                                    "FRACTALC_CACHE_DIR": str(tmp_path / "cache")})
    assert result.returncode == 1
    assert "pocl" in result.stderr.lower() and "Traceback" not in result.stderr
    assert "pip install intel-opencl-rt intel-cmplr-lib-rt" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out.png").exists()


@pytest.mark.opencl
def test_a_kernel_that_fails_to_build_is_reported_with_its_log(tmp_path, monkeypatch, capsys):
    (tmp_path / "scene.frac").write_text(SCENE)
    real_build = build.build

    def broken(source, device, *args, **kwargs):
        return real_build(source + "\nthis is not OpenCL;\n", device, *args, **kwargs)

    monkeypatch.setattr("fractalc.api.build", broken)
    status = cli.main(["render", str(tmp_path / "scene.frac"), "-o", str(tmp_path / "out.png"), "-q"])
    err = capsys.readouterr().err
    assert status == 1 and "failed to build" in err and "Traceback" not in err
    source, log = (word.rstrip(")") for word in err.split() if word.startswith("/"))
    assert os.path.basename(source) == "kernel.cl" and os.path.basename(log) == "build.log"
    assert "this is not OpenCL" in open(source).read() and "error" in open(log).read()
    assert not (tmp_path / "out.png").exists()


@pytest.mark.opencl
def test_ctrl_c_stops_cleanly_without_output(tmp_path, monkeypatch, capsys):
    (tmp_path / "scene.frac").write_text(SCENE)
    out = tmp_path / "out.png"
    out.write_bytes(b"previous image")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(run.RenderKernel, "render", interrupted)
    status = cli.main(["render", str(tmp_path / "scene.frac"), "-o", str(out), "-q"])
    err = capsys.readouterr().err
    assert status == 130 and "interrupted" in err and "Traceback" not in err
    assert out.read_bytes() == b"previous image"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png", "scene.frac"]   # no temporary left


@pytest.mark.opencl
def test_an_interrupted_render_waits_for_the_tiles_it_queued():
    """The kernel writes into the array the render returns; when Ctrl-C
    stops a render between tiles, no queued tile may still be writing once
    the array is gone: the render finishes the queue before it lets go."""
    import dataclasses

    import fractalc
    import pyopencl as cl

    scene = fractalc.loads(SCENE)
    renderer = scene.renderer()
    device = scene.device

    class RecordingQueue(cl.CommandQueue):
        finished = 0

        def finish(self):
            RecordingQueue.finished += 1
            return super().finish()

    queue = RecordingQueue(device.context)
    watched = dataclasses.replace(device, queue=queue)
    frame = run.Frame(64, 8 * run.tile_size(device)[1], 1, 0, run.camera_block(scene.checked.camera))

    def interrupt(pixels):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run.RenderKernel(renderer.kernel.program, watched, renderer.target.lanes, renderer.target.double).render(
            frame, [], interrupt)
    assert RecordingQueue.finished == 1


def test_a_kernel_builds_in_one_process_at_a_time(tmp_path, monkeypatch):
    """Two processes building one kernel at once into the shared driver
    cache made PoCL fail the build (seen with two test processes): a build
    holds its key's lock, which another process cannot take meanwhile; a
    different key's lock it can."""
    monkeypatch.setenv("FRACTALC_CACHE_DIR", str(tmp_path))
    try_lock = ("import fcntl, sys\n"
                "with open(sys.argv[1], 'a') as f:\n"
                "    try:\n        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)\n"
                "    except BlockingIOError:\n        sys.exit(3)\n")
    key = "kernel source hash:PoCL:cpu:3.0"
    other = next(k for k in (f"other kernel {i}" for i in range(100))
                 if build.build_lock_path(k) != build.build_lock_path(key))
    with build._building_alone(key):
        taken = [subprocess.run([sys.executable, "-c", try_lock, str(build.build_lock_path(k))]).returncode
                 for k in (key, other)]
    assert taken == [3, 0]
    after = subprocess.run([sys.executable, "-c", try_lock, str(build.build_lock_path(key))]).returncode
    assert after == 0, "the lock is released when the build ends"


# ---- the launcher and its worker (issues 21 and 22) ---------------------------

# A render of many small tiles (256 x 4096 in 64 tiles; 8 s on Intel's
# runtime on a Zen 5): long enough to be stopped in the middle, each tile
# short, so that it stops soon after
LONG_RENDER = "scene sphere(1)\nrender { width: 256, height: 4096, samples: 1024 }\n"
LONG_ANIMATION = ("scene sphere(1)\nrender { width: 64, height: 48, samples: 64 }\n"
                  "path { 0: { position: (0, -4, 1) }, 100: { position: (4, 0, 1) } }\n")


def _launch(tmp_path, command):
    """`python -m fractalc COMMAND` (the launcher and its worker) with a
    previous output in place; returns (launcher, the worker's pid)."""
    import time
    (tmp_path / "scene.frac").write_text(LONG_RENDER if command == "render" else LONG_ANIMATION)
    (tmp_path / "out.png").write_bytes(b"previous image")
    argv = ["render", "scene.frac", "-o", "out.png", "-q"] if command == "render" else \
        ["animate", "scene.frac", "-o", "frames/f_%04d.png", "-q"]
    path = os.pathsep.join([REPO, os.environ.get("PYTHONPATH", "")])
    # started as a shell starts a command in the foreground: SIGINT at its
    # default even where the suite itself runs with it ignored (a background
    # job's), which fractalc keeps ignored, as under nohup
    launcher = subprocess.Popen([sys.executable, "-m", "fractalc", *argv], cwd=tmp_path, stderr=subprocess.PIPE,
                                text=True, env={**os.environ, "PYTHONPATH": path},
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    children = f"/proc/{launcher.pid}/task/{launcher.pid}/children"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not open(children).read().split():
        time.sleep(0.05)
    worker = int(open(children).read().split()[0])
    time.sleep(1.5)     # into its work (building or rendering: either must stop)
    return launcher, worker


def _gone(pid: int, seconds: float) -> bool:
    import time
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().split(") ")[1].startswith("Z"):    # exited, not yet reaped by its new parent
                    return True
        except FileNotFoundError:
            return True
        time.sleep(0.1)
    return False


def _nothing_half_written(tmp_path) -> None:
    assert (tmp_path / "out.png").read_bytes() == b"previous image"
    left = [p.name for p in tmp_path.rglob("*") if p.name not in ("scene.frac", "out.png", "frames")]
    assert all(name.startswith("f_") and name.endswith(".png") for name in left), left   # whole frames only


@pytest.mark.opencl
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the worker's pid in /proc")
@pytest.mark.parametrize("command", ["render", "animate"])
def test_sigint_sent_to_the_launcher_stops_the_work_as_ctrl_c_does(tmp_path, command):
    """`kill -INT PID` from a script or a process manager: the launcher
    ignored it; now the work stops, exit 130, nothing half-written."""
    launcher, worker = _launch(tmp_path, command)
    launcher.send_signal(signal.SIGINT)
    _, err = launcher.communicate(timeout=120)
    assert launcher.returncode == 130, err
    assert err.strip().splitlines()[-1] == "fractalc: interrupted" and "Traceback" not in err
    assert _gone(worker, 10)
    _nothing_half_written(tmp_path)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the worker's pid in /proc")
def test_the_worker_exits_when_its_launcher_is_killed(tmp_path):
    """kill -9 of the launcher left its worker running (holding 21 GB in
    issue 22's case): the worker is sent SIGTERM as its parent dies, and
    unwinds through its cleanup."""
    launcher, worker = _launch(tmp_path, "render")
    launcher.send_signal(signal.SIGKILL)
    launcher.wait(timeout=30)
    assert _gone(worker, 60), "the worker outlived its launcher"
    _nothing_half_written(tmp_path)


def test_a_launcher_watchdog_stops_the_worker_where_prctl_is_missing(monkeypatch):
    """Without PR_SET_PDEATHSIG, a thread polls the parent's pid and
    sends the worker SIGTERM when it changes."""
    monkeypatch.setenv(cli.LAUNCHER_ENVIRONMENT, str(os.getppid() + 1_000_000))   # not this process's parent
    monkeypatch.setattr(cli, "_parent_death_signal", lambda number: False)
    monkeypatch.setattr(cli, "PARENT_POLL_SECONDS", 0.01)
    sent = []
    monkeypatch.setattr(os, "kill", lambda pid, number: sent.append((pid, number)))
    cli._exit_with_launcher()
    import time
    deadline = time.monotonic() + 5
    while not sent and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sent == [(os.getpid(), signal.SIGTERM)]


# ---- out of memory, in every command (issue 22) ----------------------------------

def _in_address_space(limit_bytes: int, *argv, cwd):
    """`fractalc ARGV` (main, in this interpreter's child) under RLIMIT_AS."""
    code = ("import resource, sys\n"
            f"resource.setrlimit(resource.RLIMIT_AS, ({limit_bytes}, {limit_bytes}))\n"
            "from fractalc.cli import main\nsys.exit(main(sys.argv[1:]))")
    path = os.pathsep.join([REPO, os.environ.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-c", code, *argv], cwd=cwd, capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": path})


def _one_line_out_of_memory(result, *names) -> None:
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith("fractalc: error: out of memory"), result.stderr
    assert all(name in result.stderr for name in names), result.stderr


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS as Linux counts it")
@pytest.mark.parametrize("argv, names", [
    (["check", "scene.frac", "--de", "--rays", "1000000"], ["1000000 rays"]),
    (["mesh", "scene.frac", "-o", "m.ply", "--resolution", "16384"], ["resolution 16384"]),
    (["render", "scene.frac", "-o", "o.exr", "--width", "65536", "--height", "65536"], ["width 65536"]),
])
@pytest.mark.opencl
def test_work_beyond_an_address_space_limit_is_refused_in_one_line(argv, names, tmp_path):
    """Under a 2 GB limit: check --de --rays and mesh --resolution 16384 (the
    documented maximum) were MemoryError tracebacks; each is refused before
    it starts, naming what it would take."""
    (tmp_path / "scene.frac").write_text(SCENE)
    result = _in_address_space(2 * 2 ** 30, *argv, cwd=tmp_path)
    _one_line_out_of_memory(result, *names)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.frac"]


@pytest.mark.parametrize("command", ["check", "mesh", "bench", "compile"])
def test_a_memory_error_anywhere_is_one_line_with_exit_1(command, tmp_path, capsys, monkeypatch):
    """A MemoryError, or OpenCL's allocation failure, in any command (not
    only render's image) is the contract's one-line error."""
    import pyopencl as cl
    from fractalc import api

    failures = {"check": MemoryError("Unable to allocate 11.2 GiB for an array"),
                "mesh": cl.MemoryError("clEnqueueNDRangeKernel failed: MEM_OBJECT_ALLOCATION_FAILURE"),
                "bench": cl.RuntimeError("clBuildProgram failed: OUT_OF_HOST_MEMORY"),
                "compile": MemoryError()}

    def fail(*args, **kwargs):
        raise failures[command]
    monkeypatch.setattr(api, "loads", fail)
    (tmp_path / "scene.frac").write_text(SCENE)
    argv = {"check": ["--de"], "mesh": ["-o", str(tmp_path / "m.ply")], "bench": [],
            "compile": ["-o", str(tmp_path / "k.cl")]}[command]
    assert cli.main([command, str(tmp_path / "scene.frac"), *argv]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"fractalc: error: out of memory in 'fractalc {command}'") and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.frac"]


@pytest.mark.opencl
def test_memory_estimates_refuse_before_any_work(monkeypatch, capsys, tmp_path):
    """With 64 MiB available: a render's image, a local cluster's workers,
    check --de's rays and a mesh's slabs are refused, naming each, before
    anything is allocated or started."""
    import fractalc
    from fractalc import api, cluster, memory, overstep
    from fractalc import mesh as meshing
    monkeypatch.setattr(memory, "available", lambda: 64 * 2 ** 20)
    started = []
    monkeypatch.setattr(run.RenderKernel, "render", lambda *a, **k: started.append("render"))
    scene = fractalc.loads(SCENE)
    with pytest.raises(fractalc.RenderError, match=r"out of memory: an image of width 4096 and height 4096 \(9 "):
        scene.render(width=4096, height=4096)
    with pytest.raises(fractalc.RenderError, match="out of memory: a local cluster of 2 workers would take about 420 MiB"):
        with cluster.connect(workers=2):
            started.append("cluster")
    with pytest.raises(fractalc.RenderError, match="out of memory: measuring along 10000 rays"):
        overstep.measure(scene, rays=10000)
    with pytest.raises(fractalc.RenderError, match="out of memory: meshing at resolution 4096"):
        meshing.mesh(scene, 4096)
    assert not started
    (tmp_path / "scene.frac").write_text(SCENE)
    assert cli.main(["render", str(tmp_path / "scene.frac"), "-o", str(tmp_path / "o.png"), "--workers", "2"]) == 1
    assert capsys.readouterr().err.startswith("fractalc: error: out of memory: a local cluster of 2 workers")
    assert api.require_image_memory(64, 48, 9, False) is None       # what fits goes ahead
