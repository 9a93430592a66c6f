"""`fractalc view`: the Viewer driven by synthetic pygame events under
SDL_VIDEODRIVER=dummy (moving, looking, refining a still view toward
`Scene.render`, reloading the file, params, printing and saving the view,
playing the path), and the command without a display."""

import io
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
pygame = pytest.importorskip("pygame")

import fractalc  # noqa: E402
from fractalc.build import statistics  # noqa: E402
from fractalc.paths import camera_at  # noqa: E402
from fractalc.view import PASS_SAMPLES, Viewer  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
W, H = 64, 48

SCENE = textwrap.dedent("""\
    param r = 1 in [0.5, 1.5]
    material red { color: (0.9, 0.2, 0.1), specular: 0.5, shininess: 20 }
    scene sphere(r).material(red) | box((2, 2, 0.4)).translate((0, 0, -1.2))
    camera { position: (0.5, -4, 1.5), target: (0, 0, -0.2), fov: 40 }
    light directional { direction: (-0.4, 0.7, -1), shadows: soft }
    render { width: 64, height: 48, max_steps: 300, ao: 0.5, background: (0.1, 0.1, 0.2) }
    path {
        0: { position: (0.5, -4, 1.5), r: 0.6 }
        1: { position: (4, 0.5, 1.5), r: 1.4 }
    }
    """)


def save(path, text):
    """Write the file as an editor would, its modification time moved on."""
    before = path.stat().st_mtime_ns if path.exists() else 0
    path.write_text(text)
    os.utime(path, ns=(before + 10**9, before + 10**9))


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "ball.frac"
    save(path, SCENE)
    return path


def viewer_of(path, **options):
    options.setdefault("out", io.StringIO())
    options.setdefault("err", io.StringIO())
    return Viewer(str(path), output_dir=str(path.parent), **options)


def key(kind, code, mod=0):
    return pygame.event.Event(kind, key=code, mod=mod)


def press(viewer, code, mod=0):
    viewer.handle(key(pygame.KEYDOWN, code, mod))
    viewer.handle(key(pygame.KEYUP, code, mod))


def settle(viewer, samples):
    """Step a still viewer until its image has `samples` samples (one step
    at least: a change shows at the next step)."""
    for _ in range(samples + 2):
        viewer.step(0.05)
        if viewer.samples >= samples and viewer.linear.shape[:2] == (viewer.height, viewer.width):
            return
    raise AssertionError(f"no {samples} samples: {viewer.status()}")


def reference(viewer, samples):
    return viewer.scene.render(camera=viewer.camera, width=W, height=H, samples=samples).rgba[..., :3]


# ---- moving -----------------------------------------------------------------

@pytest.mark.parametrize("code, axis, sign", [
    (pygame.K_w, "forward", 1), (pygame.K_s, "forward", -1), (pygame.K_d, "right", 1),
    (pygame.K_a, "right", -1), (pygame.K_e, "up", 1), (pygame.K_q, "up", -1)])
@pytest.mark.opencl
def test_a_held_key_moves_the_camera_by_speed_times_time(scene_file, code, axis, sign):
    viewer = viewer_of(scene_file)
    start = np.array(viewer.camera.position)
    forward = np.subtract((0, 0, -0.2), start)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, (0, 0, 1))
    right /= np.linalg.norm(right)
    direction = {"forward": forward, "right": right, "up": np.array([0.0, 0.0, 1.0])}[axis] * sign
    viewer.handle(key(pygame.KEYDOWN, code))
    viewer.step(0.5)
    viewer.step(0.25)
    viewer.handle(key(pygame.KEYUP, code))
    viewer.step(1.0)
    expected = start + direction * viewer.speed * 0.75
    np.testing.assert_allclose(viewer.camera.position, expected, atol=1e-9)
    # moving: the frame was a preview at half the size
    viewer.handle(key(pygame.KEYDOWN, code))
    viewer.step(0.1)
    assert viewer.linear.shape == (H // 2, W // 2, 3)


def test_the_wheel_and_plus_minus_change_the_speed(scene_file):
    viewer = viewer_of(scene_file)
    speed = viewer.speed
    viewer.handle(pygame.event.Event(pygame.MOUSEWHEEL, x=0, y=2))
    assert viewer.speed == pytest.approx(speed * 1.25 ** 2)
    press(viewer, pygame.K_MINUS)
    press(viewer, pygame.K_MINUS)
    press(viewer, pygame.K_MINUS)
    assert viewer.speed == pytest.approx(speed / 1.25)


def test_dragging_turns_the_view_and_never_flips_it(scene_file):
    viewer = viewer_of(scene_file)
    position, forward = viewer.camera.position, viewer.forward.copy()
    viewer.handle(pygame.event.Event(pygame.MOUSEMOTION, rel=(50, 0), buttons=(0, 0, 0)))
    assert np.array_equal(viewer.forward, forward)           # no button held: no turn
    viewer.handle(pygame.event.Event(pygame.MOUSEBUTTONDOWN, button=1, pos=(10, 10)))
    viewer.handle(pygame.event.Event(pygame.MOUSEMOTION, rel=(50, 0), buttons=(1, 0, 0)))
    turned = viewer.forward
    assert np.cross(forward, turned)[2] < 0                  # dragged right: turned right (clockwise from above)
    assert turned[2] == pytest.approx(forward[2])            # about the up axis only
    for _ in range(100):
        viewer.handle(pygame.event.Event(pygame.MOUSEMOTION, rel=(0, -40), buttons=(1, 0, 0)))
    assert viewer.forward[2] == pytest.approx(np.sin(np.radians(88)))    # up to 88 degrees, no further
    np.testing.assert_allclose(np.linalg.norm(viewer.forward), 1.0)
    assert viewer.camera.position == position


# ---- refining a still view ----------------------------------------------------

@pytest.mark.opencl
def test_a_still_view_refines_toward_the_render_of_the_same_camera(scene_file):
    viewer = viewer_of(scene_file, max_samples=32)
    viewer.step(0.05)                                        # the first frame: a preview
    assert viewer.linear.shape == (H // 2, W // 2, 3)
    viewer.step(0.05)                                        # still: the full-size pinhole image
    assert viewer.samples == 1
    assert np.array_equal(viewer.linear, reference(viewer, 1))
    converged = reference(viewer, 64)
    pinhole_error = np.abs(viewer.linear - converged).mean()
    settle(viewer, 32)
    assert viewer.samples == 32 and "32 samples" in viewer.status()
    error = np.abs(viewer.linear - converged).mean()
    assert error < 0.004 and error < 0.6 * pinhole_error
    assert viewer.step(0.05) is False                        # max_samples reached: nothing more to do


@pytest.mark.opencl
def test_moving_starts_the_refinement_again(scene_file):
    viewer = viewer_of(scene_file)
    settle(viewer, 2 * PASS_SAMPLES)
    viewer.handle(key(pygame.KEYDOWN, pygame.K_w))
    viewer.step(0.1)
    assert viewer.samples == 1 and viewer.linear.shape == (H // 2, W // 2, 3)


# ---- the scene file -----------------------------------------------------------

@pytest.mark.opencl
def test_saving_the_file_recompiles_and_keeps_the_camera(scene_file):
    viewer = viewer_of(scene_file, max_samples=1)
    viewer.handle(key(pygame.KEYDOWN, pygame.K_d))
    viewer.step(0.3)
    viewer.handle(key(pygame.KEYUP, pygame.K_d))
    settle(viewer, 1)
    camera, before, builds = viewer.camera, viewer.linear.copy(), statistics.builds
    save(scene_file, SCENE.replace("(0.9, 0.2, 0.1)", "(0.123, 0.75, 0.321)"))
    assert viewer.step(0.05) is True
    assert statistics.builds == builds + 1
    assert viewer.camera == camera
    changed = np.abs(viewer.linear - before).max(axis=-1) > 0.05
    assert changed.mean() > 0.05
    assert np.array_equal(viewer.linear, reference(viewer, 1))


@pytest.mark.opencl
def test_a_scene_error_keeps_the_last_image_and_is_reported(scene_file):
    err = io.StringIO()
    viewer = viewer_of(scene_file, max_samples=PASS_SAMPLES, err=err)
    settle(viewer, PASS_SAMPLES)
    image, scene = viewer.linear.copy(), viewer.scene
    save(scene_file, SCENE.replace("sphere(r)", "sphere(radius: q)"))
    assert viewer.step(0.05) is False
    message = f"{scene_file}:3:22: error: unknown name 'q'"
    assert viewer.error.startswith(message)
    assert err.getvalue().startswith(message)
    assert np.array_equal(viewer.linear, image) and viewer.scene is scene
    save(scene_file, SCENE)
    viewer.step(0.05)
    assert viewer.error is None and viewer.scene is not scene


def _words(lines) -> str:
    """The text of lines, wrapped or not: without its white space."""
    return "".join("".join(lines).split())


@pytest.mark.opencl
@pytest.mark.parametrize("size", [(320, 240), (160, 100)])
def test_the_status_help_and_error_fit_a_small_window(scene_file, size):
    from fractalc.view import HELP, Panel, overlay, overlay_font
    viewer = viewer_of(scene_file, width=size[0], height=size[1])
    viewer.step(0.0)
    save(scene_file, SCENE.replace("sphere(r)", "sphere(radius: q)"))
    viewer.step(0.05)
    viewer.show_help = True
    viewer.message = f"saved {scene_file.parent}/ball-view-1.png and {scene_file.parent}/ball-view-1.exr"
    pygame.font.init()
    font = overlay_font(size)
    blocks = overlay(viewer, size, font)
    for block in blocks.values():      # every panel inside the window
        (x, y), (w, h) = block.topleft, block.size(font)
        assert x >= 0 and y >= 0 and x + w <= size[0] and y + h <= size[1], (block, w, h)
    # the status line is wrapped, never cut; the error's message comes first
    assert _words(blocks[Panel.STATUS].lines) == _words([viewer.status()])
    message, source, carets = viewer.error.splitlines()[:3]
    shown = blocks[Panel.ERROR].lines
    assert _words(shown).startswith(_words([message]))
    if size == (320, 240):    # room for all: the whole message and help
        assert _words(blocks[Panel.MESSAGE].lines) == _words([viewer.message])
        assert _words(blocks[Panel.HELP].lines) == _words(HELP)
    else:                     # what does not fit is said to be cut
        lines = blocks[Panel.HELP].lines
        assert lines[-1].startswith("...") and "more line" in lines[-1], lines
    # the source line, cut to the panel, still has the carets under their place
    line, caret = next((a, b) for a, b in zip(shown, shown[1:]) if b.strip() and set(b.strip()) == {"^"})
    assert line[caret.index("^"):].startswith("q"), (line, caret)
    assert source.strip()[:12] in line


@pytest.mark.opencl
def test_params_change_from_the_keyboard_without_recompiling(scene_file):
    viewer = viewer_of(scene_file, max_samples=1)
    settle(viewer, 1)
    before, builds = viewer.linear.copy(), statistics.builds
    for _ in range(5):
        press(viewer, pygame.K_LEFTBRACKET)
    assert viewer.scene.params["r"] == pytest.approx(1 - 5 * (1.5 - 0.5) / 50)
    assert viewer.param_lines() == ["> r = 0.9"]
    for _ in range(40):
        press(viewer, pygame.K_LEFTBRACKET)
    assert viewer.scene.params["r"] == 0.5                   # held at the range's end
    settle(viewer, 1)
    assert statistics.builds == builds
    assert np.abs(viewer.linear - before).max() > 0.1
    # a param set here outlives a reload
    save(scene_file, SCENE.replace("shininess: 20", "shininess: 21"))
    viewer.step(0.05)
    assert viewer.scene.params["r"] == 0.5


# ---- printing, saving, playing --------------------------------------------------

@pytest.mark.opencl
def test_c_prints_the_camera_as_a_block_that_reproduces_it(scene_file):
    viewer = viewer_of(scene_file)
    viewer.handle(key(pygame.KEYDOWN, pygame.K_w))
    viewer.step(0.4)
    press(viewer, pygame.K_c)
    block = viewer.out.getvalue()
    assert block.startswith("camera {\n    position: (") and block.endswith("}\n")
    text = SCENE.replace("camera { position: (0.5, -4, 1.5), target: (0, 0, -0.2), fov: 40 }", block)
    camera = fractalc.loads(text).checked.camera
    np.testing.assert_allclose(camera.position, viewer.camera.position, atol=1e-4)
    np.testing.assert_allclose(camera.target, viewer.camera.target, atol=1e-4)
    assert camera.fov == viewer.camera.fov


def test_c_keeps_the_cameras_projection_and_stereo_keys(scene_file):
    scene_file.write_text(scene_file.read_text().replace(
        "fov: 40 }", "fov: 40, projection: fisheye, fisheye_fov: 200, stereo: side_by_side }"))
    viewer = viewer_of(scene_file)
    press(viewer, pygame.K_c)
    block = viewer.out.getvalue()
    text = SCENE.replace("camera { position: (0.5, -4, 1.5), target: (0, 0, -0.2), fov: 40 }", block)
    camera = fractalc.loads(text).checked.camera
    assert (camera.projection, camera.fisheye_fov, camera.stereo) == ("fisheye", 200.0, "side_by_side")
    assert "eye_separation" not in block        # at its default: left out


@pytest.mark.opencl
def test_p_saves_the_view_as_png_and_exr_with_metadata(scene_file):
    oiio = pytest.importorskip("OpenImageIO")
    viewer = viewer_of(scene_file, max_samples=PASS_SAMPLES)
    settle(viewer, PASS_SAMPLES)
    press(viewer, pygame.K_p)
    png, exr = (scene_file.parent / f"ball-view-1{ext}" for ext in (".png", ".exr"))
    assert png.exists() and exr.exists()
    assert viewer.message == f"saved {png} and {exr}"
    image = oiio.ImageInput.open(str(exr))
    spec, pixels = image.spec(), image.read_image(oiio.FLOAT)
    image.close()
    assert spec.getattribute("fractalc:camera.position") == " ".join(f"{x:g}" for x in viewer.camera.position)
    assert spec.getattribute("fractalc:render.samples") == str(PASS_SAMPLES)
    np.testing.assert_allclose(pixels[..., :3], viewer.linear, atol=1e-6)
    press(viewer, pygame.K_p)
    assert (scene_file.parent / "ball-view-2.png").exists()


@pytest.mark.opencl
def test_space_plays_the_path(scene_file):
    viewer = viewer_of(scene_file)
    press(viewer, pygame.K_SPACE)
    viewer.step(0.5)
    path = viewer.scene.checked.path
    expected = camera_at(path, viewer.scene.checked.camera, 0.5)
    np.testing.assert_allclose(viewer.camera.position, expected.position, atol=1e-9)
    assert viewer.scene.params["r"] == pytest.approx(1.0)
    viewer.step(0.7)                                         # past the end: stops there
    assert viewer.play_time is None and viewer.scene.params["r"] == pytest.approx(1.4)
    np.testing.assert_allclose(viewer.camera.position, (4, 0.5, 1.5), atol=1e-9)


def test_escape_and_closing_the_window_stop_the_viewer(scene_file):
    for event in (key(pygame.KEYDOWN, pygame.K_ESCAPE), pygame.event.Event(pygame.QUIT)):
        viewer = viewer_of(scene_file)
        viewer.handle(event)
        assert viewer.running is False


# ---- the command ------------------------------------------------------------------

def fractalc_view(*args, env):
    environment = {k: v for k, v in os.environ.items()
                   if k not in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER")}
    environment["PYTHONPATH"] = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    environment.update(env)
    return subprocess.run([sys.executable, "-m", "fractalc", "view", *map(str, args)],
                          env=environment, capture_output=True, text=True, timeout=300)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="DISPLAY decides only on Linux")
def test_without_a_display_view_exits_1_with_one_line(scene_file):
    result = fractalc_view(scene_file, env={})
    assert result.returncode == 1
    assert result.stderr == "fractalc: error: cannot open a window: no display " \
                            "(DISPLAY and WAYLAND_DISPLAY are not set)\n"
    assert result.stdout == ""


def test_benchmark_runs_the_window_loop_and_prints_the_frame_rate(scene_file):
    result = fractalc_view(scene_file, "--benchmark", 4, "--width", 40, "--height", 30,
                           env={"SDL_VIDEODRIVER": "dummy"})
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"{scene_file}: ")
    assert result.stdout.rstrip().endswith("FPS while moving (4 frames at 20x15 in a 40x30 window)")
