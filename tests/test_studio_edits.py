"""The studio's writing into the scene text (no device needed): values
replaced where they are written, entries added in the block's own layout,
declarations on lines of their own, every comment and space kept; the
key controls' specs come from the checker's tables."""
import difflib
import re
from dataclasses import replace

import pytest

from fractalc.api import Camera
from fractalc.check import check
from fractalc.check_blocks import KeyKind, key_specs
from fractalc.program import CAMERA_KEYS, LIGHT_KEYS, MATERIAL_KEYS, RENDER_KEYS
from fractalc.parse import parse
from fractalc.program import Keyframe
from fractalc.studio import edits
from fractalc.studio.session import Refused, key_edit, text_with_state

pytestmark = pytest.mark.check

SCENE = """\
# A scene as a person writes it: comments, alignment, blocks of each layout.
param blend = 0.25 in [0, 1]     # how far the spheres melt together
param size  = 0.6  in [0.2, 1.5]

material red  { color: (0.8, 0.2, 0.1), specular: 0.3 }
material blue { color: (0.1, 0.2, size), specular: 0.5 }

scene union(sphere(size).material(red), sphere(0.5).translate((1, 0, 0)).material(blue), smooth: blend)

camera {
    position: (0, -4, 1.5)    # in front, a little above
    target: (0, 0, 0)
}

light directional { direction: (-0.4, 0.6, -1), shadows: hard }
light point { position: (2, -2, 3), intensity: 8, }

render { width: 64, height: 48,
         ao: 0.5 }
"""
NUMBER = re.compile(r"-?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def changed_lines(before: str, after: str) -> list[tuple[str, str]]:
    """What a line diff shows: (old lines, new lines) of each change."""
    old, new = before.splitlines(), after.splitlines()
    return [("\n".join(old[i1:i2]), "\n".join(new[j1:j2]))
            for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(None, old, new, autojunk=False).get_opcodes()
            if tag != "equal"]


def state_saved(**changes) -> str:
    checked = check(parse(SCENE, "scene.frac"))
    state = {"params": {p.name: p.default for p in checked.params}, "camera": Camera(**vars(checked.camera)),
             "presets": {}, "keyframes": None}
    state.update(changes)
    return text_with_state(SCENE, "scene.frac", checked, **state)


def test_nothing_changed_writes_the_text_as_it_is():
    assert state_saved() == SCENE


def test_saving_params_and_the_camera_changes_only_their_literals():
    checked = check(parse(SCENE, "scene.frac"))
    camera = Camera(**{**vars(checked.camera), "position": (1.5, -3.25, 2.0), "fov": 30.0})
    saved = state_saved(params={"blend": 0.8, "size": 0.6}, camera=camera)
    pairs = changed_lines(SCENE, saved)
    assert pairs == [("param blend = 0.25 in [0, 1]     # how far the spheres melt together",
                      "param blend = 0.8 in [0, 1]     # how far the spheres melt together"),
                     ("    position: (0, -4, 1.5)    # in front, a little above",
                      "    position: (1.5, -3.25, 2)    # in front, a little above"),
                     ("", "    fov: 30")]
    saved_scene = check(parse(saved))
    assert saved_scene.camera.fov == 30 and saved_scene.params[0].default == 0.8


def test_presets_and_keyframes_become_declarations_of_their_own():
    checked = check(parse(SCENE, "scene.frac"))
    camera = Camera(**vars(checked.camera))
    keyframes = [Keyframe(0.0, camera.position, camera.target, camera.up, 45.0, params=(("blend", 0.1),)),
                 Keyframe(2.5, (3.0, -1.0, 1.0), camera.target, camera.up, 45.0, params=(("blend", 0.9),))]
    saved = state_saved(presets={"melted": {"blend": 1.0, "size": 0.6}}, keyframes=keyframes)
    assert changed_lines(SCENE, saved) == [
        ("", "preset melted { blend: 1, size: 0.6 }"),
        ("", "path {\n    0: { position: (0, -4, 1.5), target: (0, 0, 0), up: (0, 0, 1), fov: 45, blend: 0.1 }\n"
             "    2.5: { position: (3, -1, 1), target: (0, 0, 0), up: (0, 0, 1), fov: 45, blend: 0.9 }\n}")]
    saved_scene = check(parse(saved))
    assert [p.name for p in saved_scene.presets] == ["melted"]
    assert [k.time for k in saved_scene.path.keyframes] == [0.0, 2.5]
    # saved again with other keyframes: the path block is replaced where it is
    again = text_with_state(saved, "scene.frac", saved_scene, {"blend": 0.25, "size": 0.6}, camera,
                            {"melted": {"blend": 0.5}}, keyframes[:1] + [replace(keyframes[1], time=4.0)])
    assert [old.split(":")[0] for old, new in changed_lines(saved, again)] == ["preset melted { blend", "    2.5"]
    assert check(parse(text_with_state(again, "scene.frac", check(parse(again)), {"blend": 0.25, "size": 0.6},
                                       camera, {}, []))).path is None


@pytest.mark.parametrize("block, path, value, old, new", [
    # a value replaced where it is written
    ("{ a: 1, b: 2 }", ("b",), "3", "{ a: 1, b: 2 }", "{ a: 1, b: 3 }"),
    # a new entry: after a comma on one line; on a line of its own below the last
    ("{ a: 1, b: 2 }", ("c",), "3", "{ a: 1, b: 2 }", "{ a: 1, b: 2, c: 3 }"),
    ("{ a: 1, b: 2, }", ("c",), "3", "{ a: 1, b: 2, }", "{ a: 1, b: 2, c: 3, }"),
    ("{\n    a: 1\n    b: 2\n}", ("c",), "3", "    b: 2", "    b: 2\n    c: 3"),
    ("{\n    a: 1,\n    b: 2  # two\n}", ("c",), "3", "    b: 2  # two", "    b: 2,  # two\n    c: 3"),
    ("{ a: 1,\n  b: 2 }", ("c",), "3", "  b: 2 }", "  b: 2,\n  c: 3 }"),
    ("{}", ("a",), "1", "{}", "{ a: 1 }"),
    # a block key's key: inside its block, or a new block entry
    ("{ fog: { density: 0.1 } }", ("fog", "color"), "(1, 1, 1)", "{ fog: { density: 0.1 } }",
     "{ fog: { density: 0.1, color: (1, 1, 1) } }"),
    ("{ a: 1 }", ("fog", "density"), "0.2", "{ a: 1 }", "{ a: 1, fog: { density: 0.2 } }"),
])
def test_entries_are_set_in_the_blocks_own_layout(block, path, value, old, new):
    text = f"render {block}\nscene sphere(1)\n"
    program = parse(text)
    source = edits.Text(text)
    changed = edits.apply(text, edits.set_entry(source, program.decls[0].block, path, value))
    assert changed == text.replace(old, new, 1)
    parse(changed)


@pytest.mark.parametrize("block, key, result", [
    ("{ a: 1, b: 2, c: 3 }", "b", "{ a: 1, c: 3 }"),
    ("{ a: 1, b: 2 }", "a", "{ b: 2 }"),
    ("{\n  a: 1\n  b: 2\n}", "b", "{\n  a: 1\n}"),
    ("{ a: 1 }", "a", "{  }"),
])
def test_an_entry_is_taken_out_with_its_separator(block, key, result):
    text = f"render {block}"
    block_node = parse(text + "\nscene sphere(1)").decls[0].block
    assert edits.apply(text, edits.remove_entry(edits.Text(text), block_node, key)) == f"render {result}"


@pytest.mark.parametrize("value, low, high, text", [
    (0.25, None, None, "0.25"), (-0.0, None, None, "0"), (1 / 3, None, None, "0.333333"),
    (2.0, None, None, "2"), (1e-9, None, None, "1e-09"),
    (0.1234567, 0.0, 0.1234567, "0.1234567"),       # rounded it would leave its range
])
def test_numbers_are_written_short_and_within_their_range(value, low, high, text):
    assert edits.number_text(value, low, high) == text
    parse(f"param p = {text}\nscene sphere(1)")


def test_a_number_that_is_not_finite_is_never_written():
    with pytest.raises(ValueError):
        edits.number_text(float("nan"))


@pytest.mark.parametrize("message, old, new", [
    ({"block": "render", "key": ["ao"], "value": 0.25}, "         ao: 0.5 }", "         ao: 0.25 }"),
    ({"block": "render", "key": ["epsilon"], "value": "pixel"}, "         ao: 0.5 }",
     "         ao: 0.5,\n         epsilon: pixel }"),
    ({"block": "render", "key": ["fog"], "value": {}}, "         ao: 0.5 }", "         ao: 0.5,\n         fog: {} }"),
    ({"block": "render", "key": ["ao"], "value": None}, "render { width: 64, height: 48,\n         ao: 0.5 }",
     "render { width: 64, height: 48 }"),
    ({"block": "light", "index": 1, "key": ["color"], "value": [1, 0.5, 0.25]}, "intensity: 8, }",
     "intensity: 8, color: (1, 0.5, 0.25), }"),
    ({"block": "light", "index": 0, "key": ["shadows"], "value": "soft"}, "shadows: hard", "shadows: soft"),
    ({"block": "material", "name": "red", "key": ["specular"], "value": 0.75}, "specular: 0.3", "specular: 0.75"),
])
def test_key_controls_edit_the_text_at_the_key(message, old, new):
    changed = key_edit(SCENE, "scene.frac", message)
    assert changed == SCENE.replace(old, new, 1)
    check(parse(changed))


def test_a_render_block_is_made_where_there_is_none():
    text = "scene sphere(1)  # a ball\n"
    changed = key_edit(text, "f", {"block": "render", "key": ["fog", "density"], "value": 0.2})
    assert changed == text + "render { fog: { density: 0.2 } }\n"
    assert check(parse(changed)).render.fog.density == 0.2


@pytest.mark.parametrize("message, says", [
    ({"block": "render", "key": ["precision"], "value": "quad"}, "'precision' takes float, double, not 'quad'"),
    ({"block": "render", "key": ["tonemap"], "value": "none\nscene box(1)"}, "takes soft, none, reinhard, aces"),
    ({"block": "render", "key": ["ao"], "value": float("inf")}, "must be a finite number"),
    ({"block": "render", "key": ["nope"], "value": 1}, "no key nope"),
    ({"block": "render", "key": ["environment", "map"], "value": "x.exr"}, "no key environment.map"),
    ({"block": "light", "index": 5, "key": ["color"], "value": [1, 1, 1]}, "no such light"),
    ({"block": "material", "name": "green", "key": ["color"], "value": [1, 1, 1]}, "no such material"),
    ({"block": "camera", "key": ["fov"], "value": 3}, "block must be render, light or material"),
])
def test_key_controls_write_only_values_of_the_keys_type(message, says):
    with pytest.raises(Refused, match=re.escape(says)):
        key_edit(SCENE, "scene.frac", message)


def test_key_specs_are_the_checkers_tables():
    for block, table in (("render", RENDER_KEYS), ("camera", CAMERA_KEYS), ("material", MATERIAL_KEYS),
                         ("light spot", LIGHT_KEYS["spot"])):
        assert [s.name for s in key_specs(block)] == list(table)
    specs = {s.name: s for s in key_specs("render")}
    assert (specs["ao"].kind, specs["ao"].low, specs["ao"].high) == (KeyKind.NUMBER, 0.0, 1.0)
    assert (specs["width"].kind, specs["width"].low, specs["width"].high) == (KeyKind.WHOLE, 1.0, 65536.0)
    assert (specs["epsilon"].words, specs["epsilon"].low, specs["epsilon"].low_excluded) == (("pixel",), 0.0, True)
    assert specs["background"].colour and specs["background"].words == ("transparent",)
    assert specs["tonemap"].kind is KeyKind.WORD and specs["tonemap"].words == ("soft", "none", "reinhard", "aces")
    assert [k.name for k in specs["fog"].keys] == ["color", "density"] and specs["fog"].kind is KeyKind.BLOCK
    fov = next(s for s in key_specs("camera") if s.name == "fov")
    assert (fov.low, fov.high, fov.low_excluded, fov.high_excluded) == (0.0, 180.0, True, True)
    with pytest.raises(ValueError, match="no block 'light laser'"):
        key_specs("light laser")


def test_a_file_with_crlf_line_breaks_is_edited_with_new_lines_and_saved_with_its_own(tmp_path):
    from fractalc.studio.session import read_text
    (tmp_path / "windows.frac").write_bytes(b"param a = 1\r\nscene sphere(a)\r\n")
    (tmp_path / "unix.frac").write_bytes(b"param a = 1\nscene sphere(a)\n")
    assert read_text(str(tmp_path / "windows.frac")) == ("param a = 1\nscene sphere(a)\n", "\r\n")
    assert read_text(str(tmp_path / "unix.frac")) == ("param a = 1\nscene sphere(a)\n", "\n")
