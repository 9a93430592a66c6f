"""Block keys declared beside their fields (fractalc/program.py) and the
typed constraints of fractalc/types.py: what the checker, the command line
and the API derive from them. No OpenCL."""
from dataclasses import fields

import pytest

from fractalc.check import check, check_value
from fractalc.errors import SceneError
from fractalc.parse import parse
from fractalc.program import (CAMERA_KEYS, LIGHT_KEYS, RENDER_KEYS, Camera, LightKind, Normals, Projection,
                              RenderSettings, Shadows)
from fractalc.types import Comparison, Parameter, Type, at_most, between, parse_constraint

pytestmark = pytest.mark.check


def _checked(text: str):
    return check(parse(text, "scene.frac"))


def test_the_render_keys_are_the_settings_fields_that_declare_a_key():
    declared = [f.name for f in fields(RenderSettings) if "key" in f.metadata]
    assert list(RENDER_KEYS) == declared
    assert "environment_map" not in RENDER_KEYS and "aovs" not in RENDER_KEYS
    assert {name for name, key in RENDER_KEYS.items() if key.runtime} == \
        {"width", "height", "samples", "exposure", "tonemap"}
    assert all(RENDER_KEYS[f.name].default == f.default for f in fields(RenderSettings) if f.name in RENDER_KEYS)


def test_a_word_key_checks_to_its_enum_member():
    scene = _checked("scene sphere(1)\nrender { normals: central }\ncamera { projection: fisheye }\n"
                     "light point { position: (1, 2, 3), shadows: soft }")
    assert scene.render.normals is Normals.CENTRAL
    assert scene.camera.projection is Projection.FISHEYE
    assert scene.lights[0].kind is LightKind.POINT and scene.lights[0].shadows is Shadows.SOFT


def test_a_value_from_python_is_refused_in_the_words_a_file_gets():
    with pytest.raises(SceneError) as raised:
        _checked("scene sphere(1)\nrender { ao: 2 }")
    in_file = raised.value.message
    with pytest.raises(ValueError) as from_python:
        check_value(RENDER_KEYS["ao"], "ao", 2)
    assert str(from_python.value) == in_file == "'ao' of 'render' must be between 0 and 1, not 2"
    assert check_value(RENDER_KEYS["normals"], "normals", "forward") is Normals.FORWARD


def test_constraints_are_parsed_once_into_values_that_check_themselves():
    relative = parse_constraint("<=fixed_radius")
    assert relative.comparison is Comparison.AT_MOST and relative.limit == "fixed_radius" and relative.relative
    assert parse_constraint("1..10") == between(1, 10) and parse_constraint("<=1") == at_most(1)
    radius = Parameter("min_radius", Type.NUMBER, None, (relative,))
    assert radius.violation([2.0]) is None                      # the other argument not known: not checked
    assert radius.violation([2.0], {"fixed_radius": 1.0}) == "must be at most 'fixed_radius' (1), not 2"
    assert CAMERA_KEYS["fov"].range == (0.0, 180.0, True, True)


def test_the_light_kinds_keys_keep_their_order():
    assert list(LIGHT_KEYS[LightKind.SPOT]) == ["position", "direction", "target", "color", "intensity", "shadows",
                                               "softness", "angle", "falloff"]


def test_round_is_a_scene_math_function_as_in_formulas():
    scene = _checked("let r = round(1.6) + rsqrt(4)\nscene sphere(r)")
    assert scene.shape.args[0].value == 2.5


def test_the_camera_checks_its_aim_in_one_place():
    with pytest.raises(ValueError, match="'target' is its 'position'"):
        Camera(position=(1, 1, 1), target=(1, 1, 1)).aimed(up_given=False, keys_quoted=True)
    assert Camera(position=(0, 0, 5)).aimed(up_given=False).up == (0.0, 1.0, 0.0)
    with pytest.raises(SceneError, match="the camera's target is its position"):
        _checked("scene sphere(1)\ncamera { position: (1, 1, 1), target: (1, 1, 1) }")


def test_a_parameter_spelt_as_text_fails_where_it_is_declared():
    with pytest.raises(TypeError, match="parameter 'radius'"):
        Parameter("radius", "num", None, (">0",))


def test_a_setting_given_as_it_stands_is_kept_and_any_other_value_checked():
    """A frame given the settings it has (the same width and height each
    frame) keeps the settings as they are, with no check and no copy; a
    value that only equals it (a float for a whole number, a bool) or
    differs is checked as ever."""
    import fractalc
    scene = fractalc.loads("scene sphere(1)\nrender { width: 64, height: 48, epsilon: pixel }")
    settings = scene.checked.render
    assert scene.render_settings(width=64, height=48, epsilon="pixel") is settings
    assert scene.render_settings(width=64.0) == settings and type(scene.render_settings(width=64.0).width) is int
    with pytest.raises(ValueError, match="'width' must be a number, not True"):
        scene.render_settings(width=True)
    with pytest.raises(ValueError, match="whole number"):
        scene.render_settings(height=48.5)
    assert scene.render_settings(width=32, height=48).width == 32
