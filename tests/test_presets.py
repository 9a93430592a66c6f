"""`preset NAME { param: value, ... }`: param values saved under a name
(docs/language.md#preset), read by both parsers alike, checked like a
path's param values, and chosen with `--preset` or `Scene.apply_preset`."""
import subprocess
import sys

import pytest

import fractalc
from fractalc import parse as parse_module
from fractalc.check import check
from fractalc.parse import parse
from test_large_input import as_data, lark_decls

pytestmark = pytest.mark.check

SCENE = """\
param blend = 0.25 in [0, 1]
param size = 1
preset soft { blend: 0.9 }
preset big {
    size: 3     # a comment
    blend: 0
}
scene sphere(size) | sphere(1).translate((blend, 0, 0))
"""


def test_presets_hold_their_values_in_the_order_written():
    checked = check(parse(SCENE))
    assert [(p.name, p.params) for p in checked.presets] == [
        ("soft", (("blend", 0.9),)), ("big", (("size", 3.0), ("blend", 0.0)))]
    assert checked.presets[1].span.line == 4


@pytest.mark.parametrize("text", [SCENE, "param p = 1 preset preset { p: 2, } preset x {}\nscene sphere(p)",
                                  "let preset = 1\nscene sphere(preset)"])
def test_both_parsers_read_presets_alike(text):
    reader = parse_module._FastParser(text)
    assert as_data(reader.program()) == as_data(lark_decls(text))


@pytest.mark.parametrize("text, where, says", [
    ("param a = 1 in [0, 2]\npreset x { a: 3 }\nscene sphere(1)", (2, 15), "'a' of 'preset' must be between 0 and 2"),
    ("param alpha = 1\npreset x { alpah: 3 }\nscene sphere(1)", (2, 12), "did you mean 'alpha'"),
    ("param a = 1\npreset x { a: 1 }\npreset x { a: 2 }\nscene sphere(1)", (3, 8), "a second preset 'x' (the first is at line 2)"),
    ("param a = 1\npreset x { a: a }\nscene sphere(1)", (2, 15), "must be a constant"),
    ("param a = 1\npreset x { a: 1, a: 2 }\nscene sphere(1)", (2, 18), "'a' is given twice"),
    ("param a = 1\npreset { a: 1 }\nscene sphere(1)", (2, 8), "unexpected '{'"),
])
def test_preset_mistakes_are_errors_at_their_place(text, where, says):
    with pytest.raises(fractalc.SceneError) as error:
        check(parse(text))
    assert (error.value.line, error.value.column) == where
    assert says in error.value.message


def test_a_preset_sets_the_params_it_gives_and_keeps_the_others():
    scene = fractalc.loads(SCENE, params={"size": 2})
    scene.apply_preset("soft")
    assert scene.params == {"blend": 0.9, "size": 2}
    with pytest.raises(ValueError, match="no preset 'hard' .its presets: soft, big"):
        scene.apply_preset("hard")


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "fractalc", *args], capture_output=True, text=True, cwd=cwd)


@pytest.mark.opencl
def test_render_takes_a_preset_and_set_wins_over_it(tmp_path):
    (tmp_path / "scene.frac").write_text(SCENE)
    done = _cli("render", "scene.frac", "-o", "out.exr", "--width", "4", "--height", "4", "--preset", "big",
                "--set", "blend=0.5", "-q", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    import OpenImageIO as oiio
    image = oiio.ImageInput.open(str(tmp_path / "out.exr"))
    params = image.spec().get_string_attribute("fractalc:params")
    image.close()
    assert params == "blend=0.5 size=3"


def test_an_unknown_preset_is_a_usage_error(tmp_path):
    (tmp_path / "scene.frac").write_text(SCENE)
    done = _cli("render", "scene.frac", "-o", "out.png", "--preset", "hard", cwd=tmp_path)
    assert done.returncode == 2
    assert "--preset hard: the scene has no preset 'hard' (its presets: soft, big)" in done.stderr
    assert not (tmp_path / "out.png").exists()
