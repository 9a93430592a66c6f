"""`fractalc animate`: the frames of a scene's path (count, camera and
params per frame), resuming after frames were deleted, MP4 output, and
usage errors."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc.animate import render_frames
from fractalc.cli import main

oiio = pytest.importorskip("OpenImageIO")

REPO = Path(__file__).resolve().parents[1]

SCENE = textwrap.dedent("""\
    param r = 1 in [0.5, 1.5]
    scene sphere(r) | box((2, 2, 0.4)).translate((0, 0, -1.2))
    camera { target: (0, 0, -0.2), fov: 40 }
    render { width: 32, height: 24, background: (0.1, 0.1, 0.2) }
    path {
        0: { position: (0.5, -4, 1.5), r: 0.6 }
        0.5: { position: (4, 0.5, 1.5) }
        1: { position: (0.5, 4, 2), r: 1.4 }
    }
    """)
FRAMES = 5          # 1 second at 4 frames per second, both ends included


def fractalc_cli(*args, cwd):
    environment = {k: v for k, v in os.environ.items() if k != "FRACTALC_DEVICE"}
    environment["PYTHONPATH"] = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-m", "fractalc", *map(str, args)], cwd=cwd, env=environment,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "fly.frac"
    path.write_text(SCENE)
    return path


def metadata(path):
    image = oiio.ImageInput.open(str(path))
    spec = image.spec()
    image.close()
    return {a.name.removeprefix("fractalc:"): a.value for a in spec.extra_attribs if a.name.startswith("fractalc:")}


@pytest.mark.opencl
def test_animate_renders_every_frame_and_resumes_after_deletions(scene_file, tmp_path):
    result = fractalc_cli("animate", scene_file, "-o", "frames/frame_%04d.png", "--fps", 4, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    frames = sorted((tmp_path / "frames").iterdir())
    assert [f.name for f in frames] == [f"frame_{i:04d}.png" for i in range(FRAMES)]
    assert f"wrote {FRAMES} of {FRAMES} frames (0 already there)" in result.stderr
    stamps = {f.name: f.stat().st_mtime_ns for f in frames}
    for name in ("frame_0001.png", "frame_0003.png"):
        (tmp_path / "frames" / name).unlink()
    again = fractalc_cli("animate", scene_file, "-o", "frames/frame_%04d.png", "--fps", 4, cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert f"wrote 2 of {FRAMES} frames ({FRAMES - 2} already there)" in again.stderr
    for name, stamp in stamps.items():
        now = (tmp_path / "frames" / name).stat().st_mtime_ns
        assert (now == stamp) == (name not in ("frame_0001.png", "frame_0003.png")), name


@pytest.mark.opencl
def test_each_frame_has_the_path_camera_and_params(scene_file, tmp_path):
    scene = fractalc.load(scene_file, params={"r": 0.8})
    files, rendered = render_frames(scene, str(tmp_path / "f_%02d.exr"), fps=4)
    assert rendered == FRAMES and len(files) == FRAMES
    first, middle, last = metadata(files[0]), metadata(files[2]), metadata(files[-1])
    assert first["camera.position"] == "0.5 -4 1.5" and first["params"] == "r=0.6"
    assert middle["camera.position"] == "4 0.5 1.5" and middle["path.time"] == "0.5"
    assert last["camera.position"] == "0.5 4 2" and last["params"] == "r=1.4"
    assert last["path.frame"] == str(FRAMES - 1)
    assert scene.params == {"r": 0.8}                         # the scene's own params are back
    assert render_frames(scene, str(tmp_path / "f_%02d.exr"), fps=4)[1] == 0
    assert render_frames(scene, str(tmp_path / "f_%02d.exr"), fps=4, overwrite=True)[1] == FRAMES


def frame_pixels(file):
    return oiio.ImageBuf(str(file)).get_pixels(oiio.FLOAT)


@pytest.mark.opencl
def test_frame_ranges_share_an_animation(scene_file, tmp_path):
    # two machines, one folder: 0-1 and 2- make the frames one run makes
    scene = fractalc.load(scene_file)
    pattern = str(tmp_path / "shared" / "f_%02d.exr")
    files, rendered = render_frames(scene, pattern, fps=4, frames=(0, 1))
    assert rendered == 2 and files == [pattern % 0, pattern % 1]
    assert sorted(os.listdir(tmp_path / "shared")) == ["f_00.exr", "f_01.exr"]
    files, rendered = render_frames(scene, pattern, fps=4, frames=(2, None))
    assert rendered == FRAMES - 2 and files == [pattern % i for i in range(2, FRAMES)]
    whole = str(tmp_path / "whole" / "f_%02d.exr")
    render_frames(scene, whole, fps=4)
    for index in range(FRAMES):
        assert np.array_equal(frame_pixels(pattern % index), frame_pixels(whole % index))
        assert metadata(pattern % index)["path.frame"] == str(index)
    # a run over every frame finds them all done: a range's frames carry the whole run's stamp
    assert render_frames(scene, pattern, fps=4)[1] == 0


@pytest.mark.opencl
def test_animate_frames_option_renders_one_frame_or_a_clamped_range(scene_file, tmp_path, capsys):
    pattern = str(tmp_path / "f_%d.png")
    assert main(["animate", str(scene_file), "-o", pattern, "--fps", "4", "--frames", "3"]) == 0
    assert sorted(os.listdir(tmp_path)) == sorted([scene_file.name, "f_3.png"])
    assert "wrote 1 of 1 frames (0 already there)" in capsys.readouterr().err
    # a range past the end stops at the last frame, so ranges need not know the count
    assert main(["animate", str(scene_file), "-o", pattern, "--fps", "4", "--frames", "3-99"]) == 0
    assert "wrote 1 of 2 frames (1 already there)" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == sorted([scene_file.name, "f_3.png", "f_4.png"])


@pytest.mark.opencl
def test_animate_writes_an_mp4_of_the_frames(scene_file, tmp_path):
    # both in the test extra: a missing one fails here, it does not skip
    import imageio.v2 as imageio
    import imageio_ffmpeg  # noqa: F401
    result = fractalc_cli("animate", scene_file, "-o", "f%d.exr", "--fps", 4, "--mp4", "fly.mp4", "-q",
                          cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    reader = imageio.get_reader(str(tmp_path / "fly.mp4"), format="FFMPEG")
    video = np.stack([frame for frame in reader])      # list(reader) asks its length: infinite
    reader.close()
    assert video.shape == (FRAMES, 24, 32, 3)
    assert np.abs(video[0].astype(int) - video[-1].astype(int)).mean() > 5      # the camera moved


@pytest.mark.parametrize("args, message", [
    (["-o", "frames/frame.png"], "the name must hold the frame number"),
    (["-o", "frame_%d.jpg"], "frames must be .exr or .png"),
    (["-o", "frame_%d.png", "--fps", "0"], "argument --fps: must be greater than 0, not 0"),
    (["-o", "frame_%d.png", "--mp4", "out.avi"], "the name must end in .mp4"),
    (["-o", "frame_%d.png", "--frames", "3-1"], "argument --frames: '3-1' is not a frame range"),
    (["-o", "frame_%d.png", "--frames", "one"], "argument --frames: 'one' is not a frame range"),
    (["-o", "frame_%d.png", "--fps", "4", "--frames", "5-"], f"--frames 5-: the path has {FRAMES} frames at 4 fps, 0 to 4"),
    (["-o", "frame_%d.png", "--frames", "0-1", "--mp4", "fly.mp4"], "--mp4 needs every frame"),
])
def test_animate_usage_errors(scene_file, tmp_path, args, message):
    result = fractalc_cli("animate", scene_file, *args, cwd=tmp_path)
    assert result.returncode == 2 and message in result.stderr
    assert "Traceback" not in result.stderr
    assert list(tmp_path.iterdir()) == [scene_file]


def test_a_scene_without_a_path_cannot_be_animated(tmp_path):
    still = tmp_path / "still.frac"
    still.write_text("scene sphere()\n")
    result = fractalc_cli("animate", still, "-o", "f_%d.png", cwd=tmp_path)
    assert result.returncode == 2
    assert f"{still} has no 'path' to animate" in result.stderr
