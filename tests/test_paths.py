"""Camera paths: the `path` declaration (parse and check, errors at their
spans) and the interpolation of fractalc.paths (pure numpy, no OpenCL):
through every keyframe exactly, C1-continuous, no overshoot."""

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc.check import check
from fractalc.errors import SceneError
from fractalc.parse import parse
from fractalc.paths import camera_at, frame_times, interpolate, params_at, tangents
from fractalc.program import Camera

pytestmark = pytest.mark.check

REPO = Path(__file__).resolve().parents[1]

TIMES = np.array([0.0, 1.0, 1.5, 4.0, 4.2])
POINTS = np.array([[0.0, -4.0, 1.0], [3.0, -2.0, 1.5], [4.0, 0.0, 0.5], [0.0, 4.0, 2.0], [-0.5, 3.0, 2.0]])

SCENE = textwrap.dedent("""\
    param power = 8 in [2, 16]
    param blend = 0.2
    scene mandelbulb(power: power) | sphere(blend)
    camera { position: (0, -3, 1), target: (0, 0, 0.5), fov: 40 }
    path {
        0: { position: (0, -4, 1), target: (0, 0, 0), power: 6 }
        2: { position: (4, 0, 1), fov: 30 }
        5: { position: (0, 4, 2), power: 9, blend: 0.5 }
    }
    """)


def checked(text, file="path.frac"):
    return check(parse(text, file))


def errors_of(text):
    with pytest.raises(SceneError) as caught:
        checked(text)
    return [(e.line, e.column, e.message) for e in caught.value.errors]


# ---- interpolation ----------------------------------------------------------

def test_the_curve_passes_through_every_keyframe_exactly():
    assert np.array_equal(interpolate(TIMES, POINTS, TIMES), POINTS)
    for time, point in zip(TIMES, POINTS):
        assert np.array_equal(interpolate(TIMES, POINTS, time), point)
    assert np.array_equal(interpolate(TIMES, POINTS[:, 0], TIMES), POINTS[:, 0])


def test_the_curve_is_c1_at_every_keyframe():
    h = 1e-6
    for k in range(1, len(TIMES) - 1):
        t = TIMES[k]
        left = (interpolate(TIMES, POINTS, t) - interpolate(TIMES, POINTS, t - h)) / h
        right = (interpolate(TIMES, POINTS, t + h) - interpolate(TIMES, POINTS, t)) / h
        np.testing.assert_allclose(left, right, atol=1e-4)
        np.testing.assert_allclose(right, tangents(TIMES, POINTS)[k], atol=1e-4)


def test_tangents_are_catmull_rom_where_nothing_turns():
    times, values = np.array([0.0, 1.0, 3.0]), np.array([0.0, 1.0, 2.0])
    assert tangents(times, values)[1, 0] == pytest.approx((2.0 - 0.0) / (3.0 - 0.0))


def test_no_component_overshoots_its_keyframes():
    t = np.linspace(TIMES[0], TIMES[-1], 2001)
    curve = interpolate(TIMES, POINTS, t)
    segment = np.clip(np.searchsorted(TIMES, t, side="right") - 1, 0, len(TIMES) - 2)
    low = np.minimum(POINTS[segment], POINTS[segment + 1])
    high = np.maximum(POINTS[segment], POINTS[segment + 1])
    assert np.all(curve >= low - 1e-12) and np.all(curve <= high + 1e-12)
    # a held value stays held: keys 9, 9 after a rise
    held = interpolate([0.0, 5.0, 10.0], [6.0, 9.0, 9.0], np.linspace(5.0, 10.0, 50))
    np.testing.assert_allclose(held, 9.0, rtol=0, atol=1e-12)


def test_values_hold_outside_the_keyframes():
    assert np.array_equal(interpolate(TIMES, POINTS, -3.0), POINTS[0])
    assert np.array_equal(interpolate(TIMES, POINTS, 99.0), POINTS[-1])


# ---- the checked path and what it gives --------------------------------------

def test_a_path_gives_the_camera_and_params_at_each_time():
    scene = checked(SCENE)
    path = scene.path
    assert [k.time for k in path.keyframes] == [0.0, 2.0, 5.0]
    start = camera_at(path, scene.camera, 0.0)
    assert start == Camera(position=(0.0, -4.0, 1.0), target=(0.0, 0.0, 0.0), fov=30.0)
    middle = camera_at(path, scene.camera, 2.0)
    assert middle.position == (4.0, 0.0, 1.0) and middle.target == (0.0, 0.0, 0.0)
    assert params_at(path, 0.0) == {"power": 6.0, "blend": 0.5}
    assert params_at(path, 5.0) == {"power": 9.0, "blend": 0.5}
    assert 6.0 < params_at(path, 2.5)["power"] < 9.0


def test_channels_no_keyframe_gives_come_from_the_scene_camera():
    scene = checked(SCENE.replace("target: (0, 0, 0), ", ""))
    assert camera_at(scene.path, scene.camera, 3.0).target == (0.0, 0.0, 0.5)


def test_frame_times_run_from_the_first_keyframe_to_the_last():
    path = checked(SCENE).path
    assert np.allclose(frame_times(path, 2), np.arange(11) / 2)
    assert len(frame_times(path, 30)) == 151
    assert frame_times(path, 0.3)[-1] <= path.end


def test_path_is_still_a_name_elsewhere():
    assert checked("let path = sphere(1)\nscene path").path is None


@pytest.mark.parametrize("keyframes, expected", [
    ("0: { position: (0, -4, 1), powr: 7 }\n1: { position: (1, 1, 1) }",
     (6, 32, "'path' has no key 'powr' (did you mean 'power'?)")),
    ("0: { position: (0, -4, 1) }\n0: { position: (1, 1, 1) }",
     (7, 5, "keyframe times must increase: 0 does not come after 0 (line 6)")),
    ("0: { position: (0, -4, 1) }\n1: { target: (1, 1, 1) }",
     (7, 5, "the keyframe at 1 needs a 'position'")),
    ("0: { position: (0, -4, 1), power: 20 }\n1: { position: (1, 1, 1) }",
     (6, 39, "'power' of 'path' must be between 2 and 16, not 20")),
    ("0: { position: (0, -4, 1), fov: power }\n1: { position: (1, 1, 1) }",
     (6, 37, "'fov' must be a constant (it depends on a param)")),
    ("0: { position: (1, 1, 1), target: (1, 1, 1) }\n1: { position: (1, 2, 1) }",
     (6, 39, "the keyframe's target is its position: it looks nowhere")),
    ("0: { position: (0, -4, 1) }",
     (5, 1, "a path needs at least two keyframes, this one has 1")),
])
def test_path_errors_point_at_their_place(keyframes, expected):
    text = SCENE[:SCENE.index("path {")] + "path {\n" + textwrap.indent(keyframes, "    ") + "\n}\n"
    assert expected in errors_of(text)


def test_a_second_path_is_an_error():
    errors = errors_of(SCENE + "path { 0: { position: (1, 1, 1) }, 1: { position: (2, 1, 1) } }\n")
    assert (10, 1, "a second 'path' declaration (the first is at line 5)") in errors


def test_every_example_in_the_animation_page_checks():
    blocks = re.findall(r"```frac\n(.*?)```", (REPO / "docs" / "animation.md").read_text(), re.S)
    assert blocks
    for block in blocks:
        assert checked(block, "docs/animation.md").path is not None


def test_the_flythrough_example_animates_the_mandelbulb_power_from_6_to_9():
    scene = fractalc.load(REPO / "examples" / "flythrough.frac")
    path = scene.checked.path
    assert params_at(path, path.start) == {"power": 6.0} and params_at(path, path.end) == {"power": 9.0}
    assert camera_at(path, scene.checked.camera, path.start) == scene.checked.camera
