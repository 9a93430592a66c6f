"""Formulas written in the language (docs/formulas.md): every kind of
mistake is a located error; the derived estimates against float64 numpy
references written here (finite differences where the map is not a
similarity); scalar and Jacobian derivatives agree on a conformal map;
hybrids step in Mandelbulber's order; the kernel agrees with the IR's
float64 meaning in float and double and stays finite at the hard cases;
formula arguments are params (no rebuild)."""
import subprocess
import sys

import numpy as np
import pytest

import fractalc
from fractalc import build as build_module, formula_code, formula_statements, ir
from fractalc.check import library_formulas
from fractalc.errors import SceneError
from fractalc.parse import parse

pytestmark = pytest.mark.check

POINT = tuple(ir.Comp(ir.Var("p", ir.VEC3), i) for i in range(3))


def _error(source: str) -> str:
    with pytest.raises(SceneError) as caught:
        fractalc.loads(source, path="t.frac")
    return str(caught.value).splitlines()[0]


DOUBLE = "formula f() {\n    z = z * 2 + c\n}\n"
MISTAKES = [
    ("formula f() {\n    z = z * q + c\n}\nscene fractal(f())", "2:13", "unknown name 'q' in formula"),
    ("formula f() {\n    z = boxfold(z, 1) + c\n}\nscene fractal(f())", "2:9", "unknown function 'boxfold'"),
    ("formula f() {\n    z = box_fold(z) + c\n}\nscene fractal(f())", "2:9", "'box_fold' takes 2 arguments"),
    ("formula f() {\n    z = sphere_fold(z, (1, 2, 3), 1) + c\n}\nscene fractal(f())", "2:24", "needs a number here"),
    ("formula f() {\n    w = z + c\n}\nscene fractal(f())", "1:1", "'f' never sets z"),
    ("formula f() {\n    z = length(z)\n}\nscene fractal(f())", "2:5", "z is a 3-vector before the step and a number"),
    ("formula f() {\n    if z.x { z = z * 2 }\n    z = z + c\n}\nscene fractal(f())", "2:8", "'if' needs a comparison"),
    ("formula f() {\n    if z.x < 0 { k = 2 }\n    z = z * k + c\n}\nscene fractal(f())", "3:13",
     "'k' is set on only one side of the 'if' at line 2"),
    ("formula f() {\n    if z.x < 0 { init k = 2 }\n    z = z + c\n}\nscene fractal(f())", "2:18",
     "'init' goes at the top of a formula"),
    ("formula f(s = 2) {\n    s = 3\n    z = z * s + c\n}\nscene fractal(f())", "2:5", "(it is a parameter)"),
    ("formula f() {\n    c = z\n    z = z + c\n}\nscene fractal(f())", "2:5", "(it is the constant)"),
    ("param t = 1\nformula f(s = t) {\n    z = z * s + c\n}\nscene fractal(f())", "2:15", "default must be a constant"),
    ("formula f(s = 2 in [3, 1]) {\n    z = z * s + c\n}\nscene fractal(f())", "1:21", "the range [3, 1] is empty"),
    ("formula f(s = 5 in [0, 1]) {\n    z = z * s + c\n}\nscene fractal(f())", "1:15", "outside its range [0, 1]"),
    ("formula f(s = 0.5 in [0, 1]) {\n    z = z * s + c\n}\nscene fractal(f(s: 3))", "4:20",
     "'s' of 'f' must be between 0 and 1, not 3"),
    (DOUBLE + "scene fractal(hybrid(f() * 1.5))", "4:28", "repeat count must be a constant whole number"),
    (DOUBLE + "scene fractal(hybrid(f(), sphere(1)))", "4:27", "'hybrid' takes formulas"),
    ("scene fractal(sphere(1))", "1:15", "'fractal' needs a formula"),
    (DOUBLE + "scene fractal(f(), julia: (1, 2, 3, 4))", "4:7", "'julia' must be a 3-vector like z"),
    ("formula f() {\n    z = z * 2 + c\n    final distance = length(z)\n}\nformula g() {\n    z = z * 3 + c\n}\n"
     "scene fractal(hybrid(f(), g()))", "8:7", "gives its own 'final distance': it cannot be part of a hybrid"),
    ("formula q() {\n    init z = (z, 0)\n    z = quaternion_square(z) + c\n}\n" + DOUBLE.replace("f()", "g()")
     + "scene fractal(hybrid(q(), g()), iterations: 8)", "8:15",
     "a hybrid's formulas must all work on 3-vectors or all on 4-vectors: 'q' makes z a 4-vector"),
    ("formula f() {\n    z = z * 2 / dr + c\n}\nscene fractal(f())", "2:17",
     "'dr' is the compiler's derivative at the orbit's end: only 'final' lines read it"),
    ("formula f() {\n    z = floor(z) * 2 + c\n}\nscene fractal(f())", "2:9",
     "the distance estimate cannot be derived through this"),
    ("formula f() {\n    z = z * 2 + c\n    final distance = z\n}\nscene fractal(f())", "3:22",
     "'distance' must be a number, this is a 3-vector"),
    ("formula f() {\n    z = z * 2 + c\n    final r = length(z)\n}\nscene fractal(f())", "3:5",
     "'final' lines must set 'distance'"),
    ("formula f() {\n    z = z * 2 + c\n    stop = 1\n}\nscene fractal(f())", "3:5", "'stop' must be a comparison"),
    ("formula f(s = 1, s = 2) {\n    z = z * s + c\n}\nscene fractal(f())", "1:18", "'s' is already a parameter"),
    ("formula f(z = 1) {\n    z = z + c\n}\nscene fractal(f())", "1:11", "'z' is the formula's own"),
    ("formula sphere() {\n    z = z + c\n}\nscene sphere(1)", "1:9", "'sphere' is a built-in name"),
    ("formula f() {\n    if z < 1 { z = z * 2 }\n    z = z + c\n}\nscene fractal(f())", "2:8", "'<' compares numbers"),
    ("scene sphere(1 < 2)", "1:14", "a scene has no comparisons"),
    ("formula f() {\n    z = z * 2 + c\n    d = linear_estimate()\n}\nscene fractal(f())", "3:9",
     "use it in a 'final' line"),
    ("formula f() {\n    z = z.xyq + c\n}\nscene fractal(f())", "2:11", "'.xyq' is not a component of a 3-vector"),
    ("formula f() {\n    z = (z, 1) + c\n}\nscene fractal(f())", "2:9", "'+' on vectors of different sizes (3 and 4)"),
    ("formula f() {\n    z = z.scale(2) + c\n}\nscene fractal(f())", "2:11", "transforms shapes; in a formula"),
    ("formula f() {\n    z = z * log(0) + c\n}\nscene fractal(f())", "2:13", "'log' is undefined for these values"),
    (DOUBLE + "scene f() | sphere(1)", "4:7", "this is a formula: make it a shape with 'fractal("),
    (DOUBLE + "scene f()", "4:7", "'scene' needs a shape, this is a formula"),
    ("formula f() {\n    if z.x < 0 { z = z }\n    else { z = -z }\n    z = z + c\n}\nscene fractal(f())", "3:10",
     "'else' goes on the line of the '}' that ends its 'if'"),
    ("formula f() {\n    stop = z.x < 1 < 2\n    z = z + c\n}\nscene fractal(f())", "2:20",
     "comparisons do not chain"),
    ("formula f() {\n    init stop = (z, 1)\n    z = z + c\n    final d = stop\n}\nscene fractal(f())", "2:10",
     "'stop' is set in a step line"),
    ("formula f() {\n    distance = 1\n    z = z + c\n}\nscene fractal(f())", "2:5", "'distance' is set in a 'final' line"),
    ("formula f() {\n    z = z / 0 + c\n}\nscene fractal(f())", "2:9", "division by zero"),
    ("formula f() {\n    z = z * pow(0, z.x) + c\n}\nscene fractal(f())", "2:5",
     "the derivative of this step is undefined for its constants"),
]


@pytest.mark.parametrize("source, place, message", MISTAKES, ids=[m[2][:40] for m in MISTAKES])
def test_each_formula_mistake_is_a_located_error(source, place, message):
    first = _error(source)
    assert first.startswith(f"t.frac:{place}: error: "), first
    assert message in first, first


def test_formula_mistakes_exit_2_with_a_caret_and_no_traceback(tmp_path):
    scene = tmp_path / "bad.frac"
    scene.write_text("formula f() {\n    z = boxfold(z, 1) + c\n}\nscene fractal(f())\n")
    result = subprocess.run([sys.executable, "-m", "fractalc", "check", str(scene)], capture_output=True, text=True)
    assert result.returncode == 2
    assert "bad.frac:2:9: error: unknown function 'boxfold'" in result.stderr
    assert "^^^^^^^" in result.stderr and "Traceback" not in result.stderr


def test_statements_parse_by_phase_with_else_if():
    program = parse("formula f(s = 2 in [1, 3]) {\n    init k = 1\n    if z.x < 0 { z = -z } else if z.y < 0 {\n"
                    "        z = z * s\n    } else { k = k * 2 }\n    z = z + c\n    final distance = length(z) / k\n}\n"
                    "scene fractal(f())")
    formula = formula_statements.split(program.decls[0])
    assert [s.name for s in formula.init] == ["k"] and [s.name for s in formula.final] == ["distance"]
    branch = formula.step[0]
    assert branch.otherwise[0].then[0].name == "z" and branch.otherwise[0].otherwise[0].name == "k"
    assert formula.carried == ("k",)


# ---- derived estimates against numpy -------------------------------------------

def _numpy_box(points, scale, julia, iterations):
    """The amazing box iteration in float64: box fold at 1, sphere fold
    (min radius 0.5, fixed 1), z -> scale z + c, with the scalar running
    derivative (dr -> |scale| fold dr, + 1 when c is the point)."""
    z, dr = points.copy(), np.ones(len(points))
    c = points if julia is None else np.broadcast_to(julia, points.shape)
    for _ in range(iterations):
        z = np.clip(z, -1, 1) * 2 - z
        r2 = np.maximum(np.sum(z * z, axis=1), 1e-30)
        fold = np.clip(1 / r2, 1, 4)
        z = scale * z * fold[:, None] + c
        dr = abs(scale) * fold * dr + (1 if julia is None else 0)
    return np.linalg.norm(z, axis=1) / dr


def _orbit(name, args, julia=None, iterations=6, jacobian=None, bailout=None):
    formula = dict(library_formulas())[name][0]
    return formula_code.orbit((formula_code.Use(formula, tuple(ir.const(a) for a in args)),), POINT,
                              ir.const(float(iterations)), bailout, julia, jacobian=jacobian)


def test_library_box_gets_the_scalar_derivative_and_matches_numpy():
    points = np.random.default_rng(4).uniform(-3, 3, (400, 3))
    found = _orbit("amazing_box", (2.0, 1.0, 0.5, 1.0))
    assert found.scalar
    de = ir.evaluate_at((found.distance,), points)[0]
    np.testing.assert_allclose(de, _numpy_box(points, 2.0, None, 6), rtol=1e-12)


def test_scalar_and_jacobian_derivatives_agree_on_a_conformal_map():
    """In Julia mode z -> s fold(z) + c is a similarity at every point, so
    the Jacobian's estimate is the scalar one (Syntopia part VII)."""
    julia = ir.vec(ir.const(0.3), ir.const(-0.2), ir.const(0.1))
    points = np.random.default_rng(5).uniform(-2, 2, (300, 3))
    scalar = _orbit("amazing_box", (-1.5, 1.0, 0.5, 1.0), julia, jacobian=False)
    full = _orbit("amazing_box", (-1.5, 1.0, 0.5, 1.0), julia, jacobian=True)
    assert scalar.scalar and not full.scalar
    a = ir.evaluate_at((scalar.distance,), points)[0]
    b = ir.evaluate_at((full.distance,), points)[0]
    np.testing.assert_allclose(b, a, rtol=1e-9)
    np.testing.assert_allclose(a, _numpy_box(points, -1.5, np.array([0.3, -0.2, 0.1]), 6), rtol=1e-12)


STRETCHED = """formula stretched(k = 1.3) {
    z = (z.x * z.x - z.y * z.y, 2 * z.x * z.y, k * z.z) + c
}
scene fractal(stretched(), iterations: 4, bailout: 1000000)
"""


def _numpy_stretched(points, k, iterations):
    z = points.copy()
    for _ in range(iterations):
        z = np.stack([z[:, 0] ** 2 - z[:, 1] ** 2, 2 * z[:, 0] * z[:, 1], k * z[:, 2]], axis=1) + points
    return z


def test_jacobian_estimate_against_finite_differences_of_numpy():
    """Not a similarity (a complex square beside a stretch): the compiler
    carries the Jacobian; its escape-time estimate 0.5 r^2 ln r / |J^T z|
    against the same from a central-difference Jacobian of the numpy map."""
    scene = fractalc.loads(STRETCHED)
    (use,) = scene.checked.shape.sequence
    found = formula_code.orbit((use,), POINT, ir.const(4.0), ir.const(1e6))
    assert not found.scalar
    points = np.random.default_rng(6).uniform(-0.8, 0.8, (200, 3))
    de = ir.evaluate_at((found.distance,), points)[0]
    z = _numpy_stretched(points, 1.3, 4)
    h = 1e-5
    jacobian = np.stack([(_numpy_stretched(points + h * e, 1.3, 4) - _numpy_stretched(points - h * e, 1.3, 4)) / (2 * h)
                         for e in np.eye(3)], axis=2)           # (N, 3 rows of z, 3 directions)
    r = np.linalg.norm(z, axis=1)
    expected = 0.5 * r ** 2 * np.log(r) / np.linalg.norm(np.einsum("nij,ni->nj", jacobian, z), axis=1)
    smooth = r > 1.5        # away from r = 1, where ln r and the estimate vanish
    assert smooth.sum() > 50
    np.testing.assert_allclose(de[smooth], expected[smooth], rtol=1e-6)


def test_hybrid_steps_in_turn_counting_each_step():
    """hybrid(f * 2, g): f, f, g, f, f, g, ...; with f adding (1, 0, 0) and g
    doubling, the linear estimate |z| / dr is known in closed form."""
    text = ("formula shift() {\n    z = z + (1, 0, 0)\n}\nformula double() {\n    z = 2 * z\n}\n"
            "scene fractal(hybrid(shift() * 2, double()), iterations: {n})")
    points = np.random.default_rng(7).uniform(-1, 1, (50, 3))
    shifted = points + [2, 0, 0]
    for n, expected in ((3, np.linalg.norm(shifted * 2, axis=1) / 2),
                        (4, np.linalg.norm(shifted * 2 + [1, 0, 0], axis=1) / 2),
                        (6, np.linalg.norm((shifted * 2 + [2, 0, 0]) * 2, axis=1) / 4)):
        shape = fractalc.loads(text.replace("{n}", str(n))).checked.shape
        found = formula_code.orbit(shape.sequence, POINT, shape.iterations, shape.bailout)
        np.testing.assert_allclose(ir.evaluate_at((found.distance,), points)[0], expected, rtol=1e-12)


# ---- in the kernel ------------------------------------------------------------------

HYBRID = """formula bulb8(power = 8 in [2, 12]) {
    z = triplex_power(z, power) + c
}
scene fractal(hybrid(bulb8() * 2, amazing_box(scale: -1.5)), iterations: 9, bailout: 4)
"""
QUATERNION = """formula quaternion(w = 0 in [-1, 1]) {
    init z = (z, w)
    z = quaternion_square(z) + c
}
scene fractal(quaternion(), iterations: 10, bailout: 4)
"""
HARD_POINTS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1], [2, 0, 0], [0, 4, 0], [1e6, 0, 0],
                        [0, -1e6, 3], [1e18, 1e18, 1e18], [1e-30, 0, 0], [4 / 3 ** 0.5] * 3], dtype=float)


@pytest.mark.opencl
@pytest.mark.parametrize("text", [HYBRID, QUATERNION], ids=["hybrid", "quaternion"])
@pytest.mark.parametrize("precision, tolerance", [("float", 1e-3), ("double", 1e-9)])
def test_kernel_matches_the_float64_meaning_and_is_finite_at_hard_cases(text, precision, tolerance):
    scene = fractalc.loads(text, precision=precision)
    shape = scene.checked.shape
    expected_de = formula_code.orbit(shape.sequence, POINT, shape.iterations, shape.bailout).distance
    points = np.random.default_rng(8).uniform(-1.5, 1.5, (2000, 3))
    got = scene.distance(points)
    expected = ir.evaluate_at((expected_de,), points)[0]
    relative = np.abs(got - expected) / np.maximum(np.abs(expected), 1e-3)
    assert np.percentile(relative, 99) < tolerance
    hard = scene.distance(HARD_POINTS)
    assert np.all(np.isfinite(hard)), hard
    assert hard[7] > 1e3 and hard[9] > 1e3      # far away, the estimate says so


@pytest.mark.opencl
def test_formula_arguments_are_params_without_a_rebuild():
    text = ("param s = 2 in [1.5, 3]\n" + f"# {np.random.default_rng().integers(1 << 40)}\n"
            "camera { position: (0, -14, 6), target: (0, 0, 0) }\n"
            "scene fractal(amazing_box(scale: s), iterations: 8, bound: 7)")
    scene = fractalc.loads(text)
    first = scene.render(width=32, height=24)
    builds = build_module.statistics.builds
    scene.set_params({"s": 2.8})
    second = scene.render(width=32, height=24)
    assert build_module.statistics.builds == builds
    assert not np.array_equal(first.depth, second.depth)


@pytest.mark.opencl
def test_a_files_formula_replaces_the_librarys():
    text = "formula amazing_box() {\n    z = 3 * z + c\n}\nscene fractal(amazing_box(), iterations: 2)"
    scene = fractalc.loads(text)
    # z = 3 (3p + p) + p = 13 p; dr = 3 (3 + 1) + 1 = 13: the linear estimate is |p|
    np.testing.assert_allclose(scene.distance(np.array([[0.5, 0.2, 0.1]])), [np.linalg.norm([0.5, 0.2, 0.1])],
                               rtol=1e-5)


def test_a_formula_that_hides_the_librarys_says_so_once_and_the_librarys_is_still_reachable(tmp_path, capsys):
    """A file's formula replaced the library's of its name silently (issue
    21): a note names the hidden one, and `library.NAME(...)` still calls it."""
    from fractalc import cli
    text = ("formula amazing_box(scale = 3) {\n    z = scale * z + c\n}\n"
            "scene fractal(hybrid(amazing_box(), amazing_box(2), library.amazing_box(scale: 2)), iterations: 3)\n")
    checked = fractalc.loads(text, path="t.frac").checked
    uses = checked.shape.sequence
    assert [u.formula.file for u in uses[:2]] == ["t.frac"] * 2 and uses[2].formula.file.endswith("formulas.frac")
    # the library's and the file's, with the same arguments, are two formulas of a hybrid
    mine = "formula bulb(power = 8) {\n    z = triplex_power(z, power) * 0.5 + c\n}\n"
    both, twice = (fractalc.loads(f"{mine}scene fractal(hybrid({hybrid}), iterations: 4)").checked.shape
                   for hybrid in ("bulb(8), library.bulb(8)", "bulb(8) * 2"))
    assert formula_code.orbit(both.sequence, POINT, both.iterations, both.bailout).distance is not \
        formula_code.orbit(twice.sequence, POINT, twice.iterations, twice.bailout).distance
    (note,) = checked.notes
    assert str(note).startswith("t.frac:1:9: note: 'amazing_box' hides the library formula of that name "
                                "(stdlib_frac/formulas.frac:")
    assert "the library's is still 'library.amazing_box(...)'" in note.message
    (tmp_path / "t.frac").write_text(text)
    assert cli.main(["check", str(tmp_path / "t.frac")]) == 0
    assert capsys.readouterr().err.count("note: 'amazing_box' hides") == 1
    assert "the library has no formula 'amazng_box' (did you mean 'amazing_box'?)" in \
        _error("scene fractal(library.amazng_box())")


def _final_estimate(step: str, final: str, iterations: int, points):
    text = f"formula f() {{\n    {step}\n    final distance = {final}\n}}\nscene fractal(f(), iterations: {iterations})"
    shape = fractalc.loads(text).checked.shape
    found = formula_code.orbit(shape.sequence, POINT, shape.iterations, shape.bailout)
    return ir.evaluate_at((found.distance,), points)[0], found.scalar


def test_final_lines_read_the_running_derivative_as_dr():
    """`final distance = (length(z) - 1) / dr` was "unknown name 'dr'" (issue
    21). Scalar path: a box fold then 2 z + c, dr = 2^(n+1) - 1; Jacobian
    path: a stretch S then + c, J_n = I + S + ... + S^n and dr = |J^T z| / |z|."""
    points = np.random.default_rng(12).uniform(-1.5, 1.5, (64, 3))
    got, scalar = _final_estimate("z = box_fold(z, 1) * 2 + c", "(length(z) - 1) / dr", 4, points)
    z = points.copy()
    for _ in range(4):
        z = 2 * (np.clip(z, -1, 1) * 2 - z) + points
    assert scalar
    np.testing.assert_allclose(got, (np.linalg.norm(z, axis=1) - 1) / (2 ** 5 - 1), rtol=1e-12)
    stretch = np.array([1.0, 2.0, 1.5])
    got, scalar = _final_estimate("z = stretch(z, (1, 2, 1.5)) + c", "(length(z) - 1) / dr", 3, points)
    z, jacobian = points.copy(), np.ones(3)
    for _ in range(3):
        z, jacobian = z * stretch + points, jacobian * stretch + 1
    r = np.linalg.norm(z, axis=1)
    assert not scalar
    np.testing.assert_allclose(got, (r - 1) * r / np.linalg.norm(z * jacobian, axis=1), rtol=1e-12)


def test_final_lines_read_the_jacobians_spectral_norm_as_jacobian_norm():
    """A shear then + c: J_n = I + M + ... + M^n, not a similarity; its
    spectral norm (numpy's largest singular value), and |dr| on the scalar
    path, where a similarity's Jacobian is dr times a rotation."""
    points = np.random.default_rng(13).uniform(-1, 1, (64, 3))
    got, scalar = _final_estimate("z = (z.x + 0.5 * z.y, z.y, 1.2 * z.z - 0.3 * z.x) + c",
                                  "length(z) / jacobian_norm", 3, points)
    m = np.array([[1, 0.5, 0], [0, 1, 0], [-0.3, 0, 1.2]])
    jacobian = sum(np.linalg.matrix_power(m, k) for k in range(4))
    z = points.copy()
    for _ in range(3):
        z = z @ m.T + points
    assert not scalar
    np.testing.assert_allclose(got, np.linalg.norm(z, axis=1) / np.linalg.norm(jacobian, 2), rtol=1e-9)
    got, scalar = _final_estimate("z = box_fold(z, 1) * 2 + c", "length(z) / jacobian_norm", 4, points)
    assert scalar
    np.testing.assert_allclose(got, _final_estimate("z = box_fold(z, 1) * 2 + c", "length(z) / dr", 4, points)[0],
                               rtol=1e-15)


# The two pairs (issue 21): one map, two spellings each.
ROTATED_FOLD = {
    "by hand": "    a = radians(40 * z.z)\n    z = (cos(a) * z.x - sin(a) * z.y, sin(a) * z.x + cos(a) * z.y, z.z)\n"
               "    z = clamp(z, -1, 1) * 2 - z\n    z = 2 * z + c\n",
    "blocks": "    z = rotate(z, (0, 0, 1), 40 * z.z)\n    z = box_fold(z, 1)\n    z = 2 * z + c\n",
}
SQUARED = {"scaled": "    z = scale(z, length(z)) + c\n", "multiplied": "    z = z * length(z) + c\n"}
ROTATED_FOLD_USE = "iterations: 6, bailout: 100, julia: (0.3, -0.2, 0.1), bound: 12"
SQUARED_USE = "iterations: 8, bound: 2"


def pair_scene(body: str, use: str) -> str:
    return f"formula f() {{\n{body}}}\nscene fractal(f(), {use})\n"


@pytest.mark.parametrize("spellings, use, estimate", [
    (ROTATED_FOLD, ROTATED_FOLD_USE, formula_code.Estimate.LINEAR),
    (SQUARED, SQUARED_USE, formula_code.Estimate.ESCAPE_TIME)], ids=["rotated fold", "squared"])
def test_the_estimates_kind_is_the_maps_growth_whatever_its_spelling(spellings, use, estimate):
    """A hand-written rotation and clamp fold got the escape-time estimate,
    `scale(z, length(z))` the linear one (issue 21): the kind is measured
    from how |z| grows, so each spelling gets the same, right kind, the
    same estimate, and a note that says why."""
    points = np.random.default_rng(14).uniform(-3, 3, (200, 3))
    found = []
    for body in spellings.values():
        shape = fractalc.loads(pair_scene(body, use)).checked.shape
        assert shape.growth.estimate is estimate
        assert shape.estimate_reason.startswith(f"the {estimate.value} estimate")
        orbit = formula_code.orbit(shape.sequence, POINT, shape.iterations, shape.bailout, shape.julia,
                                   estimate=shape.growth.estimate)
        found.append(ir.evaluate_at((orbit.distance,), points)[0])
    np.testing.assert_allclose(found[0], found[1], rtol=1e-9, atol=1e-12)


def test_a_formula_that_gives_its_own_estimate_gets_no_note_of_the_kind():
    text = "formula f() {\n    z = z * length(z) + c\n    final distance = linear_estimate()\n}\nscene fractal(f())"
    assert fractalc.loads(text).checked.shape.estimate_reason is None


@pytest.mark.opencl
def test_an_underivable_step_is_allowed_with_the_formulas_own_estimate():
    text = ("formula cells() {\n    z = (z - floor(z)) * 2 + c\n    final distance = length(z) - 1\n}\n"
            "scene fractal(cells(), iterations: 1)")
    p = np.array([[0.25, 1.5, -0.75]])
    z = (p - np.floor(p)) * 2 + p
    np.testing.assert_allclose(fractalc.loads(text).distance(p), np.linalg.norm(z, axis=1) - 1, rtol=1e-5)


def test_a_box_fold_with_a_limit_per_axis_keeps_the_scalar_derivative():
    """box_fold(z, (1, 0.5, 1e6)): x folded at 1, y at 0.5, z never (Amazing
    Surf's fold), still a similarity: against numpy."""
    text = ("formula surf() {\n    z = box_fold(z, (1, 0.5, 1000000))\n    z = 2 * z + c\n}\n"
            "scene fractal(surf(), iterations: 4)")
    shape = fractalc.loads(text).checked.shape
    found = formula_code.orbit(shape.sequence, POINT, shape.iterations, shape.bailout)
    assert found.scalar
    points = np.random.default_rng(9).uniform(-2, 2, (100, 3))
    z, limits = points.copy(), np.array([1, 0.5, 1e6])
    for _ in range(4):
        z = 2 * (np.clip(z, -limits, limits) * 2 - z) + points
    dr = 2 ** 5 - 1                 # dr -> 2 dr + 1, four times from 1
    np.testing.assert_allclose(ir.evaluate_at((found.distance,), points)[0], np.linalg.norm(z, axis=1) / dr,
                               rtol=1e-12)


@pytest.mark.opencl
def test_step_scales_the_estimate_to_its_safe_factor(tmp_path):
    """`step: F` multiplies the estimate (check --de's safe step factor for a
    formula that oversteps); outside (0, 1] it is a located error."""
    text = "scene fractal(bulb(), iterations: 8, bailout: 2, bound: 1.2{step})"
    points = np.random.default_rng(10).uniform(-1.2, 1.2, (64, 3))
    plain = fractalc.loads(text.format(step="")).distance(points)
    halved = fractalc.loads(text.format(step=", step: 0.5")).distance(points)
    np.testing.assert_allclose(halved, plain * 0.5, rtol=1e-6)
    assert "'step' of 'fractal' must be at most 1, not 1.5" in _error(text.format(step=", step: 1.5"))


@pytest.mark.opencl
def test_an_estimate_where_z_does_not_move_with_the_point_is_zero_not_infinite():
    """At the origin z * z.x has a zero Jacobian (Julia mode: c does not
    move either): 0.5 r^2 ln r / 0 would be -inf; the estimate is 0 there
    and finite everywhere."""
    scene = fractalc.loads("formula f() {\n    z = z * z.x + c\n}\nscene fractal(f(), julia: (0.1, 0.2, 0.3))")
    d = scene.distance(np.array([[0, 0, 0], [0.1, 0.2, 0.3], [1e6, 0, 0]]))
    assert d[0] == 0 and np.all(np.isfinite(d)) and d[2] > 1e3
