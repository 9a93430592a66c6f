"""Output files on any machine: outputs that cannot be written fail before
rendering, SIGTERM and SIGHUP leave no temporary file, a replaced file keeps
its permissions, a render's memory is the image plus a little, and
`fractalc animate` resumes only frames of the same scene and settings."""

import os
import signal
import stat
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc import cli
from fractalc.animate import render_frames
from fractalc.run import _without_padding
from fractalc.write import EXR_CHANNELS, TEMPORARY_PREFIX, output_problem

oiio = pytest.importorskip("OpenImageIO")

REPO = Path(__file__).resolve().parents[1]

# 16 march steps, no AO, no shadows: a large frame renders in a second or two
CHEAP = textwrap.dedent("""\
    scene sphere(1) | box((3, 3, 0.2)).translate((0, 0, -1.2))
    camera { position: (2, -3, 1.5), target: (0, 0, 0), fov: 50 }
    light directional { direction: (-0.4, 0.7, -1), shadows: none }
    render { width: 16, height: 12, max_steps: 16, ao: 0 }
    """)
ANIMATED = CHEAP + textwrap.dedent("""\
    path {
        0: { position: (2, -3, 1.5) }
        1: { position: (3, 2, 1.5) }
    }
    """)
FRAMES = 5          # 1 second at 4 frames per second, both ends included


def environment():
    env = {k: v for k, v in os.environ.items() if k != "FRACTALC_DEVICE"}
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    return env


def command(*args):
    return [sys.executable, "-m", "fractalc", *map(str, args)]


def fractalc_cli(*args, cwd):
    return subprocess.run(command(*args), cwd=cwd, env=environment(), capture_output=True, text=True,
                          timeout=300)


def temporaries(folder):
    return sorted(p.name for p in Path(folder).rglob(f"{TEMPORARY_PREFIX}*"))


@pytest.fixture
def work(tmp_path):
    (tmp_path / "cheap.frac").write_text(CHEAP)
    (tmp_path / "fly.frac").write_text(ANIMATED)
    (tmp_path / "folder.png").mkdir()
    (tmp_path / "locked").mkdir()
    return tmp_path


# ---- outputs checked before rendering ----------------------------------

BAD_OUTPUTS = [
    (["render", "cheap.frac", "-o", "nodir/out.png"], "-o nodir/out.png: the folder 'nodir' does not exist"),
    (["render", "cheap.frac", "-o", "folder.png"], "-o folder.png: 'folder.png' is a folder"),
    (["render", "cheap.frac", "-o", "cheap.frac/out.exr"], "-o cheap.frac/out.exr: 'cheap.frac' is not a folder"),
    (["compile", "cheap.frac", "-o", "nodir/scene.cl"], "-o nodir/scene.cl: the folder 'nodir' does not exist"),
    (["bench", "cheap.frac", "--json", "nodir/b.json"], "--json nodir/b.json: the folder 'nodir' does not exist"),
    (["bench", "cheap.frac", "--sweep", "--csv", "nodir/rows.csv"], "--csv nodir/rows.csv: the folder"),
    (["bench", "cheap.frac", "--sweep", "--plot", "folder.png"], "--plot folder.png: 'folder.png' is a folder"),
    (["animate", "fly.frac", "-o", "cheap.frac/f_%d.png"], "-o cheap.frac/f_%d.png: 'cheap.frac' is not a folder"),
    (["animate", "fly.frac", "-o", "f_%d.png", "--mp4", "nodir/fly.mp4"], "--mp4 nodir/fly.mp4: the folder"),
]


@pytest.mark.parametrize("args, message", BAD_OUTPUTS, ids=[" ".join(a) for a, _ in BAD_OUTPUTS])
def test_an_output_that_cannot_be_written_fails_at_once(work, monkeypatch, capsys, args, message):
    monkeypatch.chdir(work)
    before = sorted(p.name for p in work.rglob("*"))
    assert cli.main(args) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"fractalc: error: {message}"), lines
    assert sorted(p.name for p in work.rglob("*")) == before


def test_the_output_is_checked_before_the_scene(work):
    (work / "broken.frac").write_text("scene sphere(\n")
    result = fractalc_cli("render", "broken.frac", "-o", "nodir/out.png", cwd=work)
    assert result.returncode == 1, result.stderr
    assert "nodir/out.png" in result.stderr and "broken.frac:" not in result.stderr


def can_create_in(folder):
    import tempfile
    try:
        tempfile.TemporaryFile(dir=folder).close()
        return True
    except OSError:
        return False


def test_an_unwritable_folder_is_reported_by_its_name(work):
    locked = work / "locked"
    locked.chmod(0o555)
    try:
        # root may write in a locked folder, but not in /sys
        folder = next((str(f) for f in (locked, Path("/sys")) if f.is_dir() and not can_create_in(f)), None)
        if folder is None:
            pytest.skip("no folder here that this user cannot write in")
        result = fractalc_cli("render", "cheap.frac", "-o", f"{folder}/out.png", cwd=work)
        assert result.returncode == 1
        assert result.stderr.startswith(f"fractalc: error: -o {folder}/out.png: cannot write in '{folder}': ")
        assert len(result.stderr.strip().splitlines()) == 1
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o755)


def test_output_problem_on_the_file_system(tmp_path):
    (tmp_path / "file").write_text("x")
    deep = str(tmp_path / "a" / "b" / "out.png")
    assert output_problem(str(tmp_path / "out.png")) is None
    assert output_problem(deep) == f"the folder '{tmp_path / 'a' / 'b'}' does not exist"
    assert output_problem(deep, folders_made=True) is None
    assert output_problem(str(tmp_path / "file" / "b" / "out.png"), folders_made=True) == \
        f"'{tmp_path / 'file'}' is not a folder"
    assert output_problem(str(tmp_path)) == f"'{tmp_path}' is a folder"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]      # the probe left nothing


# ---- SIGTERM and SIGHUP ------------------------------------------------

def wait_for(condition, process, timeout=120):
    start = time.monotonic()
    while not condition():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() - start < timeout
        time.sleep(0.005)


POSIX_ONLY = pytest.mark.skipif(sys.platform == "win32", reason="SIGTERM and SIGHUP are POSIX signals")


@pytest.mark.opencl
@POSIX_ONLY
def test_sigterm_while_writing_leaves_no_temporary_file(work):
    (work / "out.exr").write_bytes(b"the previous image")
    process = subprocess.Popen(command("render", "cheap.frac", "-o", "out.exr", "--width", 1920, "--height", 1080,
                                       "-q"), cwd=work, env=environment(), stderr=subprocess.PIPE, text=True)
    # the image file's temporary name appears when the render is done and its write begins
    wait_for(lambda: any(name.endswith(".exr") for name in temporaries(work)), process)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 128 + signal.SIGTERM, stderr
    assert stderr.strip().splitlines()[-1] == "fractalc: stopped by SIGTERM" and "Traceback" not in stderr
    assert temporaries(work) == []
    assert (work / "out.exr").read_bytes() == b"the previous image"


@POSIX_ONLY
def test_ctrl_c_in_the_image_writer_waits_for_a_whole_file_then_removes_it(tmp_path, monkeypatch, capfd):
    # Ctrl-C that arrived between the PNG writer's opening and closing made
    # libpng print "No IDATs written into file" after fractalc's message
    import OpenImageIO
    from fractalc import write
    real = OpenImageIO.ImageOutput

    class Interrupted:
        """The real image writer, Ctrl-C arriving as it starts writing."""
        @staticmethod
        def create(name):
            output = real.create(name)

            class Output:
                def open(self, *args):
                    return output.open(*args)

                def write_image(self, pixels):
                    signal.raise_signal(signal.SIGINT)
                    return output.write_image(pixels)

                def close(self):
                    return output.close()

                def geterror(self):
                    return output.geterror()
            return Output()

    monkeypatch.setattr(OpenImageIO, "ImageOutput", Interrupted)
    (tmp_path / "out.png").write_bytes(b"the previous image")
    planes = {name: np.zeros((24, 32), np.float32) for name in EXR_CHANNELS}
    with pytest.raises(KeyboardInterrupt):
        write.write(str(tmp_path / "out.png"), planes, {})
    assert "libpng" not in capfd.readouterr().err
    assert (tmp_path / "out.png").read_bytes() == b"the previous image"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png"]


@pytest.mark.opencl
@POSIX_ONLY
def test_sighup_while_rendering_frames_leaves_whole_frames_only(work):
    process = subprocess.Popen(command("animate", "fly.frac", "-o", "frames/f_%02d.png", "--fps", 4,
                                       "--width", 640, "--height", 480, "--samples", 8, "-q"),
                               cwd=work, env=environment(), stderr=subprocess.PIPE, text=True)
    wait_for(lambda: (work / "frames" / "f_00.png").exists(), process)
    process.send_signal(signal.SIGHUP)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 128 + signal.SIGHUP, stderr
    assert stderr.strip().splitlines()[-1] == "fractalc: stopped by SIGHUP"
    frames = sorted(p.name for p in (work / "frames").iterdir())
    assert temporaries(work) == [] and "f_00.png" in frames and len(frames) < FRAMES
    for frame in frames:                      # every frame there is whole
        assert oiio.ImageInput.open(str(work / "frames" / frame)).read_image().shape == (480, 640, 4)


# ---- permissions -------------------------------------------------------

def save_image(path):
    fractalc.loads(CHEAP).render().save(str(path))


def save_text(path):
    cli._write_text_atomically(str(path), "kernel source\n")


@pytest.mark.opencl
@pytest.mark.parametrize("save", [save_image, save_text])
def test_a_replaced_file_keeps_its_mode_and_a_new_one_gets_the_umask(tmp_path, save):
    output = tmp_path / "out.png"
    output.write_text("old")
    output.chmod(0o640)
    save(output)
    assert stat.S_IMODE(output.stat().st_mode) == 0o640 and output.read_bytes() != b"old"
    output.unlink()
    umask = os.umask(0o002)
    try:
        save(output)
    finally:
        os.umask(umask)
    assert stat.S_IMODE(output.stat().st_mode) == 0o664          # not mkstemp's 0o600
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png"]


# ---- memory ------------------------------------------------------------

def test_the_kernels_array_is_the_image_without_a_copy():
    padded = np.arange(8 * 12 * 9, dtype=np.float32).reshape(8, 12, 9)
    expected = padded[:6, :10].copy()
    image = _without_padding(padded, 6, 10)
    assert image.flags.c_contiguous and np.shares_memory(image, padded)
    assert np.array_equal(image, expected)


@pytest.mark.opencl
def test_an_odd_sized_render_writes_the_right_pixels(tmp_path):
    # 61 columns: the kernel's rows are padded, so the image is compacted in place
    image = fractalc.loads(CHEAP).render(width=61, height=13)
    assert image.rgba.shape == (13, 61, 4)
    image.save(str(tmp_path / "odd.exr"))
    file = oiio.ImageInput.open(str(tmp_path / "odd.exr"))
    names, pixels = list(file.spec().channelnames), np.asarray(file.read_image(oiio.FLOAT))
    file.close()
    planes = image.planes()
    for name in EXR_CHANNELS:
        assert np.array_equal(pixels[..., names.index(name)], planes[name]), name


# The child's own peak (VmHWM): getrusage's ru_maxrss keeps the peak of the
# process it was forked from across exec, which is the test runner's.
PEAK_RSS = """
import sys, fractalc
def peak():
    return next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM:"))
scene = fractalc.loads(sys.argv[1])
scene.render(width=16, height=12).save(sys.argv[2])
before = peak()
scene.render(width=1920, height=1080).save(sys.argv[2])
print(before, peak())
"""


@pytest.mark.opencl
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="peak RSS from /proc/self/status")
@pytest.mark.parametrize("name", ["out.png", "out.exr"])
def test_a_renders_memory_is_the_image_plus_a_little(tmp_path, name):
    """Peak RSS beyond a tiny render's stays under 1.5 times the image's
    9 float32 channels (it was about 3 times, three copies, before the
    writer took the kernel's array as it is)."""
    result = subprocess.run([sys.executable, "-c", PEAK_RSS, CHEAP, str(tmp_path / name)], env=environment(),
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    before, after = (int(kib) * 1024 for kib in result.stdout.split())     # Linux: KiB
    assert after - before < 1.5 * 1920 * 1080 * 9 * 4, (before, after)


# ---- resuming animations -----------------------------------------------

def stamps(folder):
    return {p.name: p.stat().st_mtime_ns for p in sorted(Path(folder).iterdir())}


@pytest.mark.opencl
def test_a_rerun_with_the_same_settings_keeps_every_frame(tmp_path):
    scene = fractalc.loads(ANIMATED)
    pattern = str(tmp_path / "f_%d.png")
    assert render_frames(scene, pattern, fps=4)[1] == FRAMES
    before = stamps(tmp_path)
    assert render_frames(fractalc.loads(ANIMATED), pattern, fps=4)[1] == 0
    assert stamps(tmp_path) == before


@pytest.mark.opencl
@pytest.mark.parametrize("change", ["size", "samples", "fps", "seed", "text", "params", "precision"])
def test_a_rerun_with_other_settings_renders_the_stale_frames(tmp_path, change):
    text = ANIMATED.replace("path {", "param r = 1 in [0.5, 2]\npath {").replace("sphere(1)", "sphere(r)")
    pattern = str(tmp_path / "f_%d.exr")
    first = dict(fps=4, seed=0, width=16, height=12, samples=1)
    assert render_frames(fractalc.loads(text), pattern, **first)[1] == FRAMES
    again = dict(first)
    scene = fractalc.loads(text)
    if change == "size":
        again["width"] = 20
    elif change == "samples":
        again["samples"] = 2
    elif change == "fps":
        again["fps"] = 5         # 6 frames: the first five are on disk, all stale
    elif change == "seed":
        again["seed"] = 1
    elif change == "text":
        scene = fractalc.loads(text.replace("fov: 50", "fov: 45"))
    elif change == "params":
        scene = fractalc.loads(text, params={"r": 1.5})
    elif change == "precision":
        scene = fractalc.loads(text, precision="double")
    files, rendered = render_frames(scene, pattern, **again)
    assert rendered == len(files) >= FRAMES
    # and the frames now on disk are this run's
    assert render_frames(scene, pattern, **again)[1] == 0


@pytest.mark.opencl
def test_frames_from_elsewhere_are_rendered_again(tmp_path):
    (tmp_path / "f_1.png").write_bytes(b"not a frame")
    oiio.ImageBuf(oiio.ImageSpec(16, 12, 4, oiio.UINT8)).write(str(tmp_path / "f_2.png"))  # no stamp
    files, rendered = render_frames(fractalc.loads(ANIMATED), str(tmp_path / "f_%d.png"), fps=4)
    assert rendered == FRAMES
    assert oiio.ImageInput.open(files[1]).spec().width == 16


@pytest.mark.opencl
def test_the_cli_rerenders_frames_after_the_size_changes(tmp_path):
    (tmp_path / "fly.frac").write_text(ANIMATED)
    args = ("animate", "fly.frac", "-o", "frames/f_%d.png", "--fps", 4)
    assert fractalc_cli(*args, cwd=tmp_path).returncode == 0
    result = fractalc_cli(*args, "--width", 20, cwd=tmp_path)
    assert result.returncode == 0 and f"wrote {FRAMES} of {FRAMES} frames (0 already there)" in result.stderr
    widths = {oiio.ImageInput.open(str(f)).spec().width for f in (tmp_path / "frames").iterdir()}
    assert widths == {20}
