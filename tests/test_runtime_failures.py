"""Runtime failures: exit 1 with one line, no traceback, no output file;
Ctrl-C stops cleanly."""
import os
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
    result = _fractalc(*command, cwd=tmp_path, env={"OCL_ICD_VENDORS": str(tmp_path / "no-vendors"),
                                                    "FRACTALC_BUNDLED_DRIVERS": "0"})
    assert result.returncode == 1
    assert "pocl" in result.stderr.lower() and "Traceback" not in result.stderr
    assert "pip install intel-opencl-rt intel-cmplr-lib-rt" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out.png").exists()


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


def test_ctrl_c_stops_cleanly_without_output(tmp_path, monkeypatch, capsys):
    (tmp_path / "scene.frac").write_text(SCENE)
    out = tmp_path / "out.png"
    out.write_bytes(b"previous image")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "render", interrupted)
    status = cli.main(["render", str(tmp_path / "scene.frac"), "-o", str(out), "-q"])
    err = capsys.readouterr().err
    assert status == 130 and "interrupted" in err and "Traceback" not in err
    assert out.read_bytes() == b"previous image"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png", "scene.frac"]   # no temporary left


def test_an_interrupted_render_waits_for_the_tiles_it_queued():
    """The kernel writes into the array the render returns; when Ctrl-C
    stops a render between tiles, no queued tile may still be writing once
    the array is gone: the render finishes the queue before it lets go."""
    import dataclasses

    import fractalc
    import pyopencl as cl

    scene = fractalc.loads(SCENE)
    program, target = scene._program(scene.checked.render)
    device = scene.device

    class RecordingQueue(cl.CommandQueue):
        finished = 0

        def finish(self):
            RecordingQueue.finished += 1
            return super().finish()

    queue = RecordingQueue(device.context)
    watched = dataclasses.replace(device, queue=queue)
    frame = run.Frame(64, 8 * run.TILE_HEIGHT, 1, 0, run.camera_block(scene.checked.camera))

    def interrupt(pixels):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run.render(program, watched, frame, [], target.lanes, target.double, interrupt)
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
