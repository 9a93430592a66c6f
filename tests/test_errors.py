"""Scene errors: each check-error class at the right line and column, all
independent errors at once, the printed form, and the `check` command."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import fractalc

pytestmark = pytest.mark.check

REPO = Path(__file__).resolve().parents[1]
MARK = "»"  # in a test scene, marks where an error must be reported
CAMERA = "camera { position: (0, 0, 5), target: (0, 0, 0) }"


def locate(marked):
    """The scene without its marks, and the 1-based (line, column) of each mark."""
    text, positions = "", []
    for i, piece in enumerate(marked.split(MARK)):
        if i:
            line_start = text.rfind("\n") + 1
            positions.append((text.count("\n") + 1, len(text) - line_start + 1))
        text += piece
    return text, positions


def scene_error(text, **kwargs):
    with pytest.raises(fractalc.SceneError) as info:
        fractalc.loads(text, path="scene.frac", **kwargs)
    return info.value


def case(name, marked, mentions=None):
    return pytest.param(marked, mentions, id=name)


CASES = [
    # ---- syntax
    case("unclosed paren", f"scene union(sphere(1), box(2) »render {{ width: 64 }}"),
    case("unclosed paren, next line", f"scene sphere(1.5»\n{CAMERA}", "unclosed '(' opened at 1:13"),
    case("missing comma in block",
         "scene sphere()\ncamera { position: (0, 0, 5) »target: (0, 0, 0) }"),
    case("missing value", "scene sphere()\nrender { width: »}"),
    case("bad character", "scene sphere(»$1)"),
    # ---- unknown names
    case("unknown shape", "scene »sphre(1)", "sphre"),
    case("unknown variable", "scene sphere(»rad)", "rad"),
    case("unknown method", "scene sphere(1).»translat((1, 0, 0))", "translat"),
    case("unknown material", "scene sphere().material(»gold)", "gold"),
    case("unknown block key", "scene sphere()\nrender { »widht: 10 }", "widht"),
    # ---- wrong types
    case("shape for a number", "scene sphere(radius: »box())"),
    case("vector for a number", "scene sphere(»(1, 2, 3))"),
    case("shape for a vector", "scene sphere(1).translate(»box())"),
    case("let of the wrong type", "let r = box(1)\nscene sphere(»r)"),
    case("scene not a shape", "scene »1.5"),
    case("vector for fov",
         "scene sphere()\ncamera { position: (0, 0, 5), target: (0, 0, 0), fov: »(1, 2, 3) }"),
    # ---- arity
    case("too many positional", "scene sphere(1, »2)"),
    case("too many for a method", "scene sphere(1).translate((1, 0, 0), »(0, 1, 0))"),
    case("unknown named", "scene sphere(»radios: 1)", "radios"),
    case("positional then named", "scene sphere(1, »radius: 2)"),
    case("named twice", "scene sphere(radius: 1, »radius: 2)"),
    case("missing argument", "scene sphere(»sqrt())"),
    # ---- ranges
    case("negative radius", "scene sphere(»-1)"),
    case("zero box side", "scene box(»0)"),
    case("zero scale", "scene sphere(1).scale(»0)"),
    case("fov", "scene sphere()\ncamera { position: (0, 0, 5), target: (0, 0, 0), fov: »190 }"),
    case("up parallel to view",
         "scene sphere()\ncamera { position: (0, 0, 5), target: (0, 0, 0), up: »(0, 0, 2) }"),
    case("param default outside its range", "param x = »5 in [0.5, 1]\nscene sphere(x)"),
    case("zero width", "scene sphere()\nrender { width: »0 }"),
    case("fractional max_steps", "scene sphere()\nrender { max_steps: »1.5 }"),
    case("specular", "scene sphere()\nmaterial m { color: (1, 0, 0), specular: »2 }"),
    case("spot light aimed twice", "scene sphere()\nlight spot { position: (0, 0, 3), direction: (0, 0, -1), "
                                   "»target: (0, 0, 0) }", "'direction' or 'target', not both"),
    case("spot light aimed at itself", "scene sphere()\nlight spot { position: (0, 0, 3), target: »(0, 0, 3) }",
         "target is its position"),
    case("spot light aimed nowhere", "scene sphere()\n»light spot { position: (0, 0, 3) }", "or 'target'"),
    # ---- duplicates and missing declarations
    case("duplicate camera", f"scene sphere()\n{CAMERA}\n»{CAMERA}"),
    case("duplicate scene", "scene sphere()\n»scene box()"),
    case("duplicate block key", "scene sphere()\nrender { width: 10, »width: 20 }"),
    # A file without a scene has nowhere better to point than its start.
    case("missing scene", f"»{CAMERA}\n"),
    case("empty file", "»"),
]


@pytest.mark.parametrize("marked, mentions", CASES)
def test_error_is_reported_at_its_span(marked, mentions):
    text, [(line, column)] = locate(marked)
    err = scene_error(text)
    assert (err.file, err.line, err.column) == ("scene.frac", line, column), err.message
    first = err.errors[0]
    assert (first.file, first.line, first.column, first.message) == (
        err.file, err.line, err.column, err.message)
    if mentions:
        assert mentions in err.message


MANY = (
    "scene »sphre(1)\n"
    "camera { position: (0, 0, 5), target: (0, 0, 0), fov: »190 }\n"
    f"»{CAMERA}\n"
    "render { width: »0 }\n"
)


def test_independent_errors_are_all_reported_in_source_order():
    text, positions = locate(MANY)
    err = scene_error(text)
    assert [(e.line, e.column) for e in err.errors] == positions
    assert all(e.file == "scene.frac" for e in err.errors)
    assert (err.line, err.column, err.message) == (
        err.errors[0].line, err.errors[0].column, err.errors[0].message)


def test_str_shows_each_error_with_its_source_line_and_caret():
    text, _ = locate(MANY)
    err = scene_error(text)
    printed = str(err).splitlines()
    for e in err.errors:
        at = printed.index(f"scene.frac:{e.line}:{e.column}: error: {e.message}")
        source = text.splitlines()[e.line - 1]
        shown, caret = printed[at + 1], printed[at + 2]
        assert shown.endswith(source)
        gutter = len(shown) - len(source)  # e.g. "  3 | ", if any
        assert caret.index("^") == gutter + e.column - 1


def test_param_override_outside_its_range():
    scene_error("param r = 0.7 in [0.1, 2]\nscene sphere(r)", params={"r": 5})


def test_an_unknown_param_is_the_callers_mistake_naming_the_closest():
    """Was a SceneError at the file's 1:1 (issue 21): nothing in the file is wrong."""
    with pytest.raises(ValueError, match=r"^the scene has no param 'radus'; did you mean 'radius'\?$"):
        fractalc.loads("param radius = 0.7 in [0.1, 2]\nscene sphere(radius)", params={"radus": 1})


@pytest.mark.parametrize("kind, size", [("spot", ""), ("rectangle", ", width: 2")])
def test_a_spot_or_rectangle_light_faces_its_target(kind, size):
    """As a camera does: `target` stands for `direction: target - position`."""
    def light(aim):
        return fractalc.loads(f"scene sphere()\nlight {kind} {{ position: (1, -2, 3), {aim}{size} }}").checked.lights[0]
    aimed = light("target: (0.5, 0, 1)")
    assert aimed == light("direction: (-0.5, 2, -2)") and aimed.direction == (-0.5, 2.0, -2.0)


# -------------------------------------------------------------- command line

def check(tmp_path, text, name="bad.frac"):
    """Run `python -m fractalc check NAME` in tmp_path on `text`."""
    path = tmp_path / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    pythonpath = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONPATH": pythonpath}
    return subprocess.run(
        [sys.executable, "-m", "fractalc", "check", name],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )


def assert_scene_error(result, prefix):
    assert result.returncode == 2, result.stderr
    assert prefix in result.stderr
    assert "Traceback" not in result.stderr + result.stdout


def test_check_accepts_a_good_scene(tmp_path):
    result = check(tmp_path, f"scene sphere()\n{CAMERA}\n", name="good.frac")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("good.frac: ok: 1 part (1 shape);")


def test_check_says_in_one_line_what_it_checked(tmp_path):
    """A silent `check` left a user unsure anything ran (issue 21)."""
    text = ("param power = 8 in [2, 16]\nformula twice() {\n    z = 2 * z + c\n}\n"
            "scene union(mandelbulb(power), fractal(twice(), bound: 2).translate((3, 0, 0)), plane(offset: -2))\n"
            f"{CAMERA}\nlight point {{ position: (1, 2, 3) }}\nrender {{ fog: {{ density: 0.1 }} }}\n")
    result = check(tmp_path, text, name="good.frac")
    assert result.returncode == 0 and result.stderr.startswith("good.frac:5:32: note: the fractal gets the linear")
    assert result.stdout.count("\n") == 1
    assert result.stdout.startswith("good.frac: ok: 5 parts (1 shape, 2 fractals, 1 combination, 1 transform); "
                                    "formulas: mandelbulb, twice; 1 param (power); 1 light; kernel features: fog")


@pytest.mark.parametrize("name", ["bad.frac", "scenes/bad.frac"])
@pytest.mark.parametrize("marked", [
    "# a comment\nscene union(sphere(), »sphre(1))",
    "scene sphere(1»\nrender { width: 64 }",
])
def test_check_reports_errors_with_the_given_path(tmp_path, marked, name):
    text, [(line, column)] = locate(marked)
    assert_scene_error(check(tmp_path, text, name), f"{name}:{line}:{column}: error:")


def test_check_rejects_a_file_over_8mb(tmp_path):
    padding = ("#" + "x" * 1023 + "\n") * (9 * 1024)
    assert_scene_error(check(tmp_path, "scene sphere()\n" + padding), "bad.frac:")


def nested(depth):
    return "scene sphere(" + "(" * depth + "1" + ")" * depth + ")"


@pytest.mark.parametrize("depth", [300, 100_000])
def test_check_rejects_deep_nesting_where_the_limit_is_passed(tmp_path, depth):
    result = check(tmp_path, nested(depth))
    assert_scene_error(result, "bad.frac:1:")
    # Level 257 opens around column 13 + 256; the error points thereabouts.
    column = int(re.search(r"bad\.frac:1:(\d+): error:", result.stderr)[1])
    assert 250 <= column <= 275


def test_check_accepts_nesting_within_the_limit(tmp_path):
    result = check(tmp_path, nested(250))
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("chain", [
    "scene " + " | ".join(["sphere()"] * 5000),
    "scene sphere()" + ".translate((0, 0, 0))" * 5000,
], ids=["operators", "methods"])
def test_long_chains_do_not_crash(tmp_path, chain):
    result = check(tmp_path, chain)
    assert result.returncode in (0, 2), result.stderr
    assert "Traceback" not in result.stderr + result.stdout
