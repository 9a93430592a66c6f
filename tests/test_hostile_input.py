"""Input written to break the compiler: every scene that passes `check`
builds and renders, mistakes are located errors (never a traceback), and
nothing from the file reaches the kernel unescaped (issue 10)."""

import os
import re
import sys

import numpy as np
import pytest

import fractalc

pytestmark = pytest.mark.check

# ---- params in every argument position (uniform and per-ray values mixed) --

# Each shape uses the param `a` (= 1 by default) somewhere; written with `1`
# in its place the scene must give the same distances and the same image.
PARAM_POSITIONS = [
    "sphere({a})", "box({a})", "box(({a}, 1, 1))", "intersect(plane(({a}, 0, 1), 0), sphere(1))",
    "intersect(plane((0, 0, 1), {a} - 1), sphere(1))", "torus({a}, 0.25)", "torus(1, {a} * 0.25)",
    "cylinder({a} * 0.5, 2)", "cylinder(0.5, {a})", "capsule(({a}, 0, 0), (0, 0, 1), 0.25)",
    "capsule((0, 0, 0), (0, {a}, 0), 0.25)", "capsule((0, 0, 0), (0, 0, 1), {a} * 0.25)",
    "mandelbulb(power: {a} * 8)", "mandelbulb(iterations: {a} * 4)", "mandelbulb(bailout: {a} * 2)",
    "julia(c: ({a} * 0.2 - 0.4, 0.6, 0.2, 0))", "julia(slice: {a} - 1)", "julia(iterations: {a} * 4)",
    "julia(bailout: {a} * 4)", "mandelbox(scale: {a} * 2)", "mandelbox(min_radius: {a} * 0.5)",
    "mandelbox(fixed_radius: {a})", "mandelbox(fold_limit: {a})", "mandelbox(iterations: {a} * 4)",
    "menger({a} * 2)", "sierpinski({a} * 2)",
    "sphere(0.5).translate(({a}, 0, 0))", "sphere(0.5).rotate(({a}, 0, 0), 30)",
    "box(0.5).rotate((1, 0, 0), {a} * 30)", "sphere(0.5).scale({a})",
    "intersect(sphere(0.3).repeat(({a}, 0, 0)), box(2))", "intersect(sphere(0.3).repeat({a}), box(2))",
    "intersect(sphere(0.3).repeat((max({a}, 0), 0, 0)), box(2))",
    "box(0.5).round({a} * 0.1)", "box(0.5).onion({a} * 0.1)", "intersect(box(0.5).twist({a}), sphere(1))",
    "intersect(box(0.5).bend({a}), sphere(1))",
    "sphere(0.5).color(({a} * 0.5, 0.2, 0.2))", "mandelbulb().color(orbit_trap(near: ({a}, 0, 0)))",
    "mandelbulb().color(orbit_trap(far: ({a}, 0, 0)))", "mandelbulb().color(orbit_trap(scale: {a}))",
    "sphere(0.5).material(m)",
    "union(sphere(0.5), box(0.4).translate((0, 0, {a} * 0.5)), smooth: {a} * 0.1)",
    "intersect(sphere(0.5), box(0.8), smooth: {a} * 0.1)",
    "subtract(sphere(0.5), box(0.4), smooth: {a} * 0.1)",
    "union(sphere(0.5).color((1, 0, 0)), box(0.4).translate(({a} * 0.5, 0, 0)).color(({a}, 1, 0)))",
    "sphere(0.5).translate((min({a}, 2) - 1, max({a}, 0) - 1, clamp({a}, 0, 1) - 1))",
    "sphere(max({a}, 0.3) * 0.5).translate((mix({a}, 2, 0.5) - 1.5, pow({a}, 2) - 1, atan2({a}, 1) - 0.785))",
]
SPACING = 5.0


def _params_as(value: str) -> str:
    """The scene of PARAM_POSITIONS with the param `a` written as `value`."""
    shapes = ", ".join(f"({s}).translate(({i * SPACING}, 0, 0))" for i, s in enumerate(PARAM_POSITIONS))
    return "\n".join([
        "param a = 1 in [0, 2]",
        "material m { color: ({a} * 0.5, 0.5, 0.5), specular: {a} * 0.5 }",
        f"scene union({shapes})",
        f"camera {{ position: ({SPACING * len(PARAM_POSITIONS) / 2}, -90, 10), "
        f"target: ({SPACING * len(PARAM_POSITIONS) / 2}, 0, 0), fov: 90 }}",
        "light point { position: (100, -40, 40), intensity: 2000 }",
        "render { max_distance: 400 }"]).replace("{a}", value)


@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
def test_params_in_every_argument_position_build_and_match_constants(precision):
    """Item 1: a param where the kernel mixes it with per-ray values (a
    repeat period, select, min/max, an iteration count) builds, and gives
    what the same scene with the value written in gives."""
    points = np.array([[i * SPACING + dx, dy, dz] for i in range(len(PARAM_POSITIONS))
                       for dx, dy, dz in ((0.3, 0.2, 0.1), (-0.6, 0.4, 0.9), (1.1, -0.2, 0.3))])
    with_param = fractalc.loads(_params_as("a"), precision=precision)
    written_in = fractalc.loads(_params_as("1"), precision=precision)
    np.testing.assert_allclose(with_param.distance(points), written_in.distance(points),
                               rtol=1e-5, atol=1e-5)
    image, expected = (s.render(width=16, height=12) for s in (with_param, written_in))
    image_depth, image, expected = image.depth, image.rgba, expected.rgba
    assert np.isfinite(image_depth).sum() > 5     # the shapes are in view
    np.testing.assert_allclose(image, expected, atol=2e-3)


# ---- many shapes, long let chains ------------------------------------------

CENTRES = np.random.default_rng(10).uniform(-2, 2, (300, 3))
RADIUS = 0.1


def _translated_spheres() -> list[str]:
    return [f"sphere({RADIUS}).translate(({x:.17g}, {y:.17g}, {z:.17g}))" for x, y, z in CENTRES]


def _sphere_distances(points) -> np.ndarray:
    """(len(CENTRES), N) distances of each sphere of CENTRES."""
    return np.linalg.norm(points[None, :, :] - CENTRES[:, None, :], axis=2) - RADIUS


POINTS = np.random.default_rng(11).uniform(-2.5, 2.5, (64, 3))


@pytest.mark.opencl
def test_flat_union_past_the_nesting_limit_builds():
    """Item 2: 300 shapes in one union (once more brackets than clang takes)."""
    scene = fractalc.loads(f"scene union({', '.join(_translated_spheres())})")
    np.testing.assert_allclose(scene.distance(POINTS), _sphere_distances(POINTS).min(axis=0), atol=1e-5)
    assert np.isfinite(scene.render(width=16, height=12).depth).any()


@pytest.mark.opencl
def test_smooth_union_of_many_shapes_folds_left_to_right():
    """Item 2: a smooth union stays ordered (LANGUAGE.md), however long."""
    k = 0.3
    scene = fractalc.loads(f"scene union({', '.join(_translated_spheres())}, smooth: {k})")
    expected = _sphere_distances(POINTS)[0]
    for d in _sphere_distances(POINTS)[1:]:
        h = np.maximum(k - np.abs(expected - d), 0) / k
        expected = np.minimum(expected, d) - h * h * k / 4
    np.testing.assert_allclose(scene.distance(POINTS), expected, atol=1e-4)


@pytest.mark.opencl
def test_let_chain_of_unions_with_colours_builds():
    """Item 2: a let chain nests shapes through names, past the parser's
    limit on brackets; each part keeps its own colour."""
    lines = [f"let s0 = {_translated_spheres()[0]}.color((1, 0, 0))"]
    for i, shape in enumerate(_translated_spheres()[1:], 1):
        lines.append(f"let s{i} = union(s{i - 1}, {shape}.color(({i % 2}, 0.5, 0)))")
    scene = fractalc.loads("\n".join(lines) + f"\nscene s{len(CENTRES) - 1}\n")
    np.testing.assert_allclose(scene.distance(POINTS), _sphere_distances(POINTS).min(axis=0), atol=1e-5)
    image = scene.render(width=16, height=12)
    assert np.isfinite(image.depth).any() and np.isfinite(image.rgba).all()


@pytest.mark.opencl
def test_long_chain_of_reverse_references_checks_and_renders():
    """Item 3: lets that each name the next one (defined later), with a
    param: no RecursionError in check or lowering (deeper than Python's
    1000 frames; the kernel's build time grows with n)."""
    n = 1200
    lets = [f"let s{i} = s{i + 1}.translate((p, 0, 0))" for i in range(n)]
    radii = [f"let r{i} = r{i + 1} + p" for i in range(n)]
    text = "\n".join(["param p = 0.0005", *lets, *radii, f"let r{n} = 0.5", f"let s{n} = sphere(r0)",
                      "scene s0"])
    scene = fractalc.loads(text)
    points = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0.5, 0.2]])
    expected = np.linalg.norm(points - [n * 0.0005, 0, 0], axis=1) - (0.5 + n * 0.0005)
    np.testing.assert_allclose(scene.distance(points), expected, atol=1e-4)


def _check_errors(text: str, tmp_path, capsys) -> str:
    """Run `fractalc check` on `text`: it must fail with exit 2 and a
    located error (no traceback); returns what it printed."""
    from fractalc.cli import main
    path = tmp_path / "scene.frac"
    path.write_text(text)
    assert main(["check", str(path)]) == 2
    printed = capsys.readouterr().err
    assert printed.startswith(f"{path}:") and "Traceback" not in printed
    return printed


def test_a_cycle_of_lets_is_a_located_error(tmp_path, capsys):
    text = "let a = b.translate((1, 0, 0))\nlet b = union(c, sphere(1))\nlet c = a\nscene a\n"
    printed = _check_errors(text, tmp_path, capsys)
    assert ":1:5: error: 'a' is defined in terms of itself (a -> b -> c -> a)" in printed


@pytest.mark.parametrize("text, cycle", [
    ("let a = a.x\nscene sphere(1)\n", "a -> a"),                      # through a component (issue 21)
    ("let a = (b.y, 1, 2)\nlet b = a.xy\nscene sphere(1)\n", "a -> b -> a"),
    ("let a = sphere(1).translate(b)\nlet b = (a.x, 0, 0)\nscene a\n", "a -> b -> a"),
])
def test_a_cycle_through_any_kind_of_expression_is_a_located_error(text, cycle, tmp_path, capsys):
    printed = _check_errors(text, tmp_path, capsys)
    assert f":1:5: error: 'a' is defined in terms of itself ({cycle})" in printed


def test_every_pass_walks_every_field_that_holds_nodes():
    """ast.children is the one walk: it finds each node of every kind."""
    from fractalc import ast
    from fractalc.parse import parse
    program = parse("param p = 1 in [0, q]\nlet a = -(p, 2).xy.x | f(k: b.y, r.m(s))\nscene a\n"
                    "camera { position: (t, 0, 0) }\npath { 0: { fov: u }, 1: { fov: 2 } }\n"
                    "formula g(w = v) {\n init k = x\n if y < 1 { z = z } else { z = -z }\n final distance = d\n}\n")
    names = {n.name for n in ast.walk(program) if isinstance(n, ast.Name)}
    assert names == {"p", "q", "a", "b", "r", "s", "t", "u", "v", "x", "y", "z", "d"}
    # nodes inside a node are found once each
    nodes = list(ast.walk(program))
    assert len(nodes) == len({id(n) for n in nodes})


def test_lets_that_double_the_scene_each_time_are_a_located_error(tmp_path, capsys):
    """A let used twice in each of a chain of lets: 2^40 shapes to lower
    and compile. Refused at the let where the scene grows too large."""
    lines = ["let s0 = sphere(0.1)"] + [f"let s{i} = union(s{i - 1}, s{i - 1}.translate((0.1, 0, 0)))"
                                        for i in range(1, 40)]
    printed = _check_errors("\n".join(lines) + "\nscene s39\n", tmp_path, capsys)
    assert ":12:22: error: the scene passes 6000 parts" in printed   # s11's second part: 6142


def test_a_union_too_large_to_compile_is_refused_at_the_shape_that_passes_the_limit(tmp_path, capsys):
    """Item 4: 2999 translated spheres (5999 parts) check; the 3000th is
    refused where it stands, saying why and what to use instead."""
    from fractalc.check_expressions import MAX_SHAPES
    shapes = [f"sphere(0.05).translate(({i}, 0, 0))" for i in range((MAX_SHAPES - 1) // 2 + 1)]
    fractalc.loads(f"scene union({', '.join(shapes[:-1])})")
    text = f"scene union({', '.join(shapes)})\n"
    printed = _check_errors(text, tmp_path, capsys)
    column = text.index(shapes[-1]) + 1
    assert f":1:{column}: error: the scene passes {MAX_SHAPES} parts" in printed
    assert "minutes to compile" in printed and "'.repeat(period)'" in printed


# ---- numbers that overflow -------------------------------------------------

@pytest.mark.parametrize("text, where", [
    ("scene sphere(1e400)", ":1:14:"),
    ("scene sphere(1).rotate((1e308, 0, 0), 30)", ":1:25:"),
    ("scene sphere(radius: 2e38 * 2)", ":1:22:"),
    ("scene sphere(1)\nrender { width: 1e400 }", ":2:17:"),
    ("scene sphere(1)\nmaterial m { color: (1e400, 0, 0) }", ":2:22:"),
    ("param p = 1e400\nscene sphere(1)", ":1:11:"),
    ("scene sphere(1)\nlight point { position: (0, 0, 3), intensity: -1e400 }", ":2:48:"),
])
def test_numbers_beyond_float_are_located_errors(text, where, tmp_path, capsys):
    printed = _check_errors(text + "\n", tmp_path, capsys)
    assert f"{where} error:" in printed and ("too large a number" in printed or "beyond" in printed)


def _usage_error(argv, capsys) -> str:
    """`fractalc ARGV` must stop with exit 2 before rendering."""
    from fractalc.cli import main
    try:
        code = main(argv)
    except SystemExit as stop:      # argparse's own usage errors
        code = stop.code
    assert code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize("option, value", [
    ("--set", "p=inf"), ("--set", "p=nan"), ("--set", "p=-1e39"), ("--seed", "-1"), ("--seed", "4294967296"),
    ("--device", "٣"),
])
def test_command_line_values_out_of_range_are_usage_errors(option, value, tmp_path, capsys):
    scene = tmp_path / "scene.frac"
    scene.write_text("param p = 1\nscene sphere(p)\n")
    output = tmp_path / "out.png"
    printed = _usage_error(["render", str(scene), "-o", str(output), "-q", "--width", "16", "--height", "12",
                            option, value], capsys)
    assert option in printed and "Traceback" not in printed
    assert not output.exists()


def test_python_values_out_of_range_raise_value_errors_naming_the_key():
    scene = fractalc.loads("param x = 1\nscene sphere(x)\n")
    for keys, name in (({"width": float("inf")}, "width"), ({"samples": float("nan")}, "samples"),
                       ({"background": (float("nan"), 0, 0)}, "background"), ({"seed": -1}, "seed")):
        with pytest.raises(ValueError, match=name):
            scene.render(**keys)
    for value in (float("nan"), float("inf"), -1e39):
        with pytest.raises(ValueError, match="'x'"):
            scene.set_params({"x": value})
    assert scene.params == {"x": 1.0}


@pytest.mark.opencl
def test_out_of_memory_is_one_line_with_exit_1(tmp_path, capsys, monkeypatch):
    """The host's image array not fitting in memory (numpy's MemoryError,
    simulated: a size the machine lacks is refused before by its estimate,
    tests/test_runtime_failures.py) is a runtime failure."""
    from fractalc import cli, run

    def no_memory(*args, **kwargs):
        raise MemoryError("Unable to allocate 144. GiB for an array")

    monkeypatch.setattr(run.RenderKernel, "render", no_memory)
    scene = tmp_path / "scene.frac"
    scene.write_text("scene sphere(1)\n")
    assert cli.main(["render", str(scene), "-o", str(tmp_path / "out.exr"), "-q",
                     "--width", "64", "--height", "48"]) == 1
    printed = capsys.readouterr().err
    assert printed.startswith("fractalc: error: out of memory") and printed.count("\n") == 1


@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
def test_lights_bright_enough_to_overflow_give_finite_pixels(precision):
    text = "\n".join(["scene union(sphere(1), plane(offset: -1))",
                      "light point { position: (2, -2, 3), intensity: 1e38, color: (3, 3, 3) }",
                      "light point { position: (-2, -2, 3), intensity: 3e38 }",
                      "light directional { direction: (0, 1, -1), intensity: 3e38, color: (1000, 1, 1) }",
                      "light directional { direction: (1, 1, -1), intensity: 3e38, shadows: soft }",
                      "camera { position: (0, -5, 2), target: (0, 0, 0) }"])
    image = fractalc.loads(text, precision=precision).render(width=16, height=12)
    assert np.isfinite(image.depth).any() and np.isfinite(image.rgba).all()
    assert image.rgba[..., :3].max() > 1e10       # still as bright as it can be


FAR = np.array([[0.0, 0, 0], [0.3, -0.2, 0.5], [1.1, 0, 0], [-2, 3, 1], [50, -40, 30], [1e4, 1e4, -1e4]])


@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("shape", [
    "sphere().scale(1e-30)", "sphere(1e29).scale(1e-30).translate((0, 0, 2))",
    "cylinder().translate((0, 0, 1e20))", "sphere().translate((0, 0, 1e30))",
    "sphere().translate((0, 0, -3e38)).translate((0, 0, 3e38))",
    "julia().scale(1e-30).twist(1.11)", "sphere().twist(3e38)", "box(1).bend(-1e30)",
    "intersect(box(0.5).scale(1e-30).twist(1e30).scale(1e29), sphere(1))",
])
@pytest.mark.opencl
def test_tiny_scales_far_offsets_and_huge_warp_rates_give_finite_distances(shape, precision):
    """Item 1 (fuzz finding 6): a moved point that would pass float's range
    is clamped, a warp's rate too; distances stay finite and images too."""
    scene = fractalc.loads(f"scene {shape}\ncamera {{ position: (0, -6, 2), target: (0, 0, 0) }}",
                           precision=precision)
    assert np.isfinite(scene.distance(FAR)).all()
    image = scene.render(width=16, height=12)
    assert np.isfinite(image.rgba).all() and np.isfinite(image.normal).all()
    assert ((image.depth >= 0) | (image.depth == np.inf)).all()


@pytest.mark.opencl
def test_clamping_a_far_point_keeps_the_estimate_a_lower_bound():
    """Item 1: a sphere 1.2e21 away in double: the clamped estimate (1e18
    at most) is finite and below the true distance; near it, exact."""
    far = 2.0 ** 70          # 1.2e21, and points near it that double holds exactly
    scene = fractalc.loads(f"scene sphere(1).translate((0, 0, {far:.0f}))", precision="double")
    d = scene.distance(np.array([[0.0, 0, 0], [0, 0, far - 2.0 ** 19]]))
    assert 1e17 < d[0] <= far - 1
    assert d[1] == 2.0 ** 19 - 1


@pytest.mark.opencl
def test_epsilon_scale_beyond_its_limit_is_a_located_error(tmp_path, capsys):
    """Item 1 (fuzz finding 7): a threshold of 1e30 pixels gave NaN normals."""
    printed = _check_errors("scene sphere()\nrender { epsilon_scale: 1e30 }\n", tmp_path, capsys)
    assert ":2:25: error: 'epsilon_scale' of 'render' must be at most 1000" in printed
    image = fractalc.loads("scene sphere()\nrender { epsilon_scale: 1000 }").render(width=16, height=12)
    assert np.isfinite(image.normal).all() and np.isfinite(image.depth).any()


@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
def test_huge_glow_fog_and_background_colours_give_finite_pixels(precision):
    """Item 2: colours bounded only below sum past float's range."""
    text = "\n".join(["scene sphere(1)", "render {", "  background: (3e38, 3e38, 0), samples: 4,",
                      "  glow: { color: (3e38, 1, 3e38), strength: 3e38, radius: 1 },",
                      "  fog: { color: (3e38, 3e38, 3e38), density: 0.1 }", "}"])
    image = fractalc.loads(text, precision=precision).render(width=16, height=12)
    assert np.isfinite(image.rgba).all() and np.isfinite(image.depth).any()
    assert image.rgba[..., :3].max() > 1e38       # still as bright as float goes


def test_many_unknown_names_get_few_suggestions(monkeypatch):
    """Item 3: each "did you mean" compares against every known name; only
    the first errors get one, so 1000 unknown names cost linear time."""
    import difflib

    from fractalc import check_base
    calls = []
    original = difflib.get_close_matches
    monkeypatch.setattr(difflib, "get_close_matches", lambda *a, **k: calls.append(a[0]) or original(*a, **k))
    text = "\n".join(f"let value_{i} = 1\nlet x_{i} = valu_{i}" for i in range(1000)) + "\nscene sphere()"
    with pytest.raises(fractalc.SceneError) as error:
        fractalc.loads(text)
    messages = [d.message for d in error.value.errors]
    assert len(messages) == 1000 and len(calls) == check_base.SUGGESTED_ERRORS
    assert messages[0] == "unknown name 'valu_0' (did you mean 'value_0'?)"
    assert messages[-1] == "unknown name 'valu_999'"


# ---- the user's text in generated source and names -------------------------

@pytest.mark.opencl
def test_a_path_with_a_newline_stays_in_the_kernels_comment(tmp_path):
    """Item 5: the path is written into the kernel's header comment; a
    newline in it must not start a line of C (here: one turning the union
    into an intersection)."""
    text = "scene union(sphere(1), sphere(1).translate((1.5, 0, 0)))\n"
    hostile = tmp_path / "a\n#define fmin fmax\n.frac"
    hostile.write_text(text)
    plain = fractalc.loads(text)
    scene = fractalc.load(hostile)
    source = scene.kernel_source()
    assert not any(line.startswith("#define fmin") for line in source.splitlines())
    assert str(hostile).replace("\n", "\\u000a") in source
    points = np.array([[2.5, 0, 0], [-1.0, 0, 0], [0.75, 0, 0], [0, 3, 0]])
    np.testing.assert_array_equal(scene.distance(points), plain.distance(points))


@pytest.mark.opencl
def test_generated_material_names_cannot_be_declared():
    """Item 6: `.color(...)` and the default material make materials of
    their own; a file's materials named like them must not replace them."""
    text = "\n".join([
        "material color0 { color: (0, 0, 1) }", "material default { color: (0, 1, 0) }",
        "scene union(sphere(1).color((1, 0, 0)), sphere(1).translate((0, 0, -2)),",
        "            sphere(0.5).translate((0, 0, 2)).material(color0), box(0.5).translate((0, 0, 3)).material(default))",
        "light directional { direction: (0, 1, 0), shadows: none }",
        "camera { position: (0, -6, 0.5), target: (0, 0, 0.5), fov: 60 }"])
    scene = fractalc.loads(text)
    assert {"color0", "default"} <= set(scene.checked.materials) and len(scene.checked.materials) == 4
    rgba = scene.render(width=16, height=12).rgba
    column = rgba[:, 8, :3]
    red, grey = column[6], column[10]            # the coloured sphere, the one below it
    assert red[0] > 4 * max(red[1], red[2])
    assert np.allclose(grey, grey[0], rtol=0.01)  # the default material: grey, not the file's green


@pytest.mark.opencl
@pytest.mark.parametrize("normals", ["tetrahedral", "central", "forward"])
def test_normals_stay_finite_deep_inside_a_far_plane(normals):
    """Estimates near float's largest (a point 3e38 inside a plane): the
    normal's differences must not overflow (found by the fuzzer)."""
    scene = fractalc.loads(f"scene sphere() | plane(offset: 3e38)\nrender {{ width: 16, height: 12, normals: {normals} }}")
    image = scene.render()
    assert np.isfinite(image.normal).all() and np.isfinite(image.rgba).all()


@pytest.mark.parametrize("text, key", [("scene capsule((-0.6, 2.9, 1e30), (0, 0, 1))", "'a' of 'capsule'"),
                                       ("scene capsule(radius: 1e30)", "'radius' of 'capsule'"),
                                       ("scene torus(1e30)", "'major' of 'torus'")])
@pytest.mark.opencl
def test_shapes_whose_distance_squares_a_huge_size_are_refused_at_the_value(text, key):
    """A capsule end at 1e30 gave distance +inf everywhere (fuzz seed 5 case 3209)."""
    with pytest.raises(fractalc.SceneError, match=key):
        fractalc.loads(text)
    assert np.isfinite(fractalc.loads("scene capsule((0, 0, -1e17), (0, 0, 1e17)) | torus(1e17, 1e17)")
                       .distance([[0, 0, 0], [1, 2, 3]])).all()


# ---- every option and API call answered in words (issue 22) -----------------

HOSTILE_NUMBERS = ("0", "-1", "99999999999999999999", "inf", "nan", "٣")
ALWAYS_REFUSED = ("inf", "nan", "٣")
# options that take text (files, names, lists) rather than a number
TEXT_OPTIONS = {"-o", "--output", "--json", "--csv", "--plot", "--mp4", "--output-dir", "--environment-map",
                "--cluster", "--device", "--precision", "--compression", "--resolution", "--vary", "--aov",
                "--lanes", "--preset", "--host", "--shells"}
# options whose value holds numbers in a form of its own: where a number goes
NUMBER_IN = {"--set": "p={}", "--render": "ao={}", "--camera": "fov={}", "--bounds": "{},-1,-1,1,1,1",
             "--frames": "{}", "--live-size": "{}x12"}
# each command's positional scene and required options ({tmp}: the test's folder)
REQUIRED = {"render": ["-o", "{tmp}/out.png"], "compile": ["-o", "{tmp}/out.cl"], "check": ["--de"],
            "bench": [], "view": [], "animate": ["-o", "{tmp}/f_%03d.png"], "mesh": ["-o", "{tmp}/out.ply"],
            "devices": [], "studio": ["--no-browser"]}
OPTIONS_SCENE = ("param p = 1 in [0, 2]\nscene sphere(p)\nrender { width: 16, height: 12 }\n"
                 "path { 0: { position: (0, -4, 1) }, 1: { position: (4, 0, 1) } }\n")


def _commands():
    from fractalc import cli
    parser = cli._parser()
    commands = next(a for a in parser._actions if a.dest == "command")
    return commands.choices


def _valued_options():
    """(command, option string, how a number is written in it) for every
    option of every command that takes a value, found in the parser itself
    (a new option is covered as it is added)."""
    found = []
    for command, sub in _commands().items():
        for action in sub._actions:
            if not action.option_strings or action.nargs == 0:
                continue
            name = max(action.option_strings, key=len)
            if name not in TEXT_OPTIONS:      # a new option is tried too
                found.append((command, name, NUMBER_IN.get(name, "{}")))
    return found


def test_numeric_options_are_all_checked_types():
    """No option reads its number with plain int or float, which take '٣'
    and give no range: each is a checked type (cli._option), a form of its
    own (NUMBER_IN) or text."""
    for command, sub in _commands().items():
        for action in sub._actions:
            if action.option_strings and action.nargs != 0:
                name = max(action.option_strings, key=len)
                assert getattr(action.type, "argument", None) or name in NUMBER_IN or name in TEXT_OPTIONS, \
                    f"{command} {name}: give it a checked numeric type (cli._option) or list it here"
            assert action.type not in (int, float), f"{command} {action.option_strings}: type={action.type}"
            if action.required and action.option_strings:      # every required option has a value here
                assert set(action.option_strings) & set(REQUIRED[command]), (command, action.option_strings)


class _Accepted(Exception):
    """The options were accepted: the command got as far as loading the scene."""


@pytest.mark.parametrize("command, option, form", _valued_options())
def test_every_numeric_option_answers_every_hostile_number_in_words(command, option, form, tmp_path, capsys,
                                                                    monkeypatch):
    """0, -1, a huge value, inf, nan and a non-ASCII digit for each option:
    a usage error naming the option (one line, exit 2) or accepted; inf,
    nan and '٣' never; no traceback, no work started on a refused value."""
    from fractalc import api, cli

    def accepted(*args, **kwargs):
        raise _Accepted
    monkeypatch.setattr(api, "loads", accepted)
    if command == "studio":       # it serves before it loads
        server = pytest.importorskip("fractalc.studio.server")
        monkeypatch.setattr(server, "serve", accepted)
    scene = tmp_path / "scene.frac"
    scene.write_text(OPTIONS_SCENE)
    required = [part.format(tmp=tmp_path) for part in REQUIRED[command]]
    for value in HOSTILE_NUMBERS:
        argv = [command, str(scene), *required, f"{option}={form.format(value)}"]
        try:
            code = cli.main(argv)
        except _Accepted:
            code = "accepted"
        except SystemExit as stop:       # argparse's own errors
            code = stop.code
        err = capsys.readouterr().err
        assert "Traceback" not in err, (argv, err)
        if code == "accepted":
            assert value not in ALWAYS_REFUSED, f"{argv}: accepted"
            continue
        lines = err.strip().splitlines()
        assert code == 2 and option in lines[-1], (argv, code, err)
        assert lines[-1].startswith(("fractalc", str(scene))) and "error:" in lines[-1], err
        assert not (tmp_path / "out.png").exists()


@pytest.mark.parametrize("argv, refused", [
    (["render", "S", "-o", "O.png", "--workers=0"], "argument --workers: must be between 1 and 1024, not 0"),
    (["render", "S", "-o", "O.png", "--workers=99999999999999999999"], "argument --workers: must be between 1"),
    (["render", "S", "-o", "O.png", "--seed=4294967296"], "argument --seed: must be between 0 and 4294967295"),
    (["render", "S", "-o", "O.png", "--width=70000"], "argument --width: must be at most 65536, not 70000"),
    (["bench", "S", "--frames=1", "--width=70000"], "argument --width: must be at most 65536, not 70000"),
    (["animate", "S", "-o", "f_%d.png", "--fps=inf"], "argument --fps: must be finite"),
    (["animate", "S", "-o", "f_%d.png", "--fps=99999999999999999999"], "argument --fps: must be at most 1000"),
    (["check", "S", "--de", "--rays=100000000"], "argument --rays: must be between 1 and 1000000"),
    (["mesh", "S", "-o", "m.ply", "--resolution=16385"], "argument --resolution: must be between 2 and 16384"),
    (["render", "S", "-o", "O.png", "--bits=٨"], "argument --bits: '٨' is not a number"),
    (["render", "S", "-o", "O.png", "--render", "ao=٣"], "--render ao=٣: 'ao' must be a number, not '٣'"),
    (["render", "S", "-o", "O.png", "--set", "p=٣"], "--set p: '٣' is not a number"),
])
def test_options_out_of_range_as_reported(argv, refused, tmp_path, capsys):
    """The examples of issue 22, each refused before any work, naming the option."""
    scene = tmp_path / "scene.frac"
    scene.write_text(OPTIONS_SCENE)
    argv = [str(scene) if a == "S" else str(tmp_path / a) if "." in a and not a.startswith("-") else a
            for a in argv]
    printed = _usage_error(argv, capsys)
    assert refused in printed and "Traceback" not in printed


def test_a_hybrid_past_its_steps_is_refused_where_it_passes_them():
    """1000 entries with iterations 1000 checked in 0.7 s and then built
    for 84 s: refused at the 257th step, as MAX_SHAPES refuses shapes."""
    from fractalc.check_formulas import MAX_HYBRID_STEPS
    steps = ["bulb()" if i % 2 == 0 else "amazing_box(scale: -1.5)" for i in range(1000)]
    text = f"scene fractal(hybrid({', '.join(steps)}), iterations: 1000, bound: 4)"
    with pytest.raises(fractalc.SceneError) as error:
        fractalc.loads(text)
    assert error.value.column == len("scene fractal(hybrid(") + len(", ".join(steps[:MAX_HYBRID_STEPS])) + 3
    assert f"passes {MAX_HYBRID_STEPS} formula steps per round" in error.value.message
    with pytest.raises(fractalc.SceneError) as error:      # repeat counts count
        fractalc.loads("scene fractal(hybrid(bulb() * 100, amazing_box() * 100) * 2, bound: 4)")
    assert error.value.column == 59
    fractalc.loads("scene fractal(hybrid(bulb() * 100, amazing_box() * 100, bulb(9) * 56), bound: 4)")


FORMULA_WITH = "formula f() {{\n    z = 2 * z + c\n    final distance = {}\n}}\nscene fractal(f(), iterations: 4, bound: 2)\n"


@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("final", ["1e30 * length(z) * 1e30", "sqrt(-length(z))", "exp(1000 * length(z))"])
def test_a_formulas_own_estimate_is_finite_everywhere(final, precision):
    """A formula's own `final distance` gets the guard the derived
    estimates have: +inf and NaN come back within ±1e30."""
    scene = fractalc.loads(FORMULA_WITH.format(final), precision=precision)
    points = np.array([[0.1, 0.2, 0.3], [1.0, 1.0, 1.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    d = scene.distance(points)
    assert np.isfinite(d).all() and np.abs(d).max() <= 1.0001e30, d
    assert np.isfinite(scene.render(width=16, height=12).rgba).all()


@pytest.mark.parametrize("final, column", [("1e30 * 1e30", 22), ("exp(100)", 22), ("length(z) + 1e30 * 1e30", 34)])
def test_a_formula_constant_beyond_float_is_an_error_at_it(final, column):
    with pytest.raises(fractalc.SceneError) as error:
        fractalc.loads(FORMULA_WITH.format(final))
    assert (error.value.line, error.value.column) == (3, column)
    assert "beyond the kernel's floats" in error.value.message


# The API: every public function and method, each argument given None, a
# value of the wrong type and values out of range. An argument's errors are
# SceneError, ValueError or TypeError naming it (RenderError for memory);
# None is accepted only where it is the default; flags take any truth value.

API_SCENE = "param p = 1 in [0, 2]\nscene sphere(p)\nrender { width: 8, height: 6 }\n" \
            "path { 0: { position: (0, -4, 1) }, 1: { position: (4, 0, 1) } }\n"
FLAGS = {"progress", "denoise", "use_cache", "half", "overwrite"}
ERRORS = (fractalc.SceneError, ValueError, TypeError, fractalc.RenderError)


def _api_calls(tmp_path):
    """(name, function, valid keyword arguments) of the public API."""
    import functools

    from fractalc import animate, paths
    scene = fractalc.loads(API_SCENE)
    image = scene.render()
    (tmp_path / "scene.frac").write_text(API_SCENE)
    return [
        ("loads", fractalc.loads, {"text": API_SCENE, "params": {"p": 1.0}, "precision": "float", "device": None,
                                   "path": "scene.frac", "lanes": None}),
        ("load", fractalc.load, {"path": str(tmp_path / "scene.frac"), "params": None, "precision": None,
                                 "device": None, "lanes": None}),
        ("Scene.render", scene.render, {"seed": 0, "progress": False, "camera": None, "cluster": None,
                                        "denoise": False, "width": 8, "height": 6, "samples": 1, "aovs": ()}),
        ("Scene.distance", scene.distance, {"points": [[0.0, 0.0, 0.0]]}),
        ("Scene.set_params", scene.set_params, {"values": {"p": 1.0}}),
        ("Scene.kernel_source", scene.kernel_source, {"lanes": None, "max_steps": 64}),
        ("Scene.compile", scene.compile, {"use_cache": True}),
        ("Scene.set_defaults", scene.set_defaults, {"camera": None, "ao": 0.5}),
        ("Scene.mesh", scene.mesh, {"resolution": 8, "bounds": None, "progress": False}),
        ("Image.save", image.save, {"path": str(tmp_path / "image.png"), "half": False, "compression": "zip",
                                    "bits": 8}),
        ("Camera", fractalc.Camera, {"position": (0, -4, 1), "target": (0, 0, 0), "fov": 40, "aperture": 0,
                                     "focus": None}),
        ("animate.render_frames", functools.partial(animate.render_frames, scene),
         {"pattern": str(tmp_path / "f_%02d.png"), "fps": 2, "seed": 0, "overwrite": False, "frames": (0, 0)}),
        ("paths.frame_times", functools.partial(paths.frame_times, scene.checked.path), {"fps": 2}),
    ]


def _hostile_values(name: str, valid, none_means_default: bool):
    """(value, whether it must be refused) for an argument whose valid value is `valid`."""
    values = [(None, not none_means_default and name not in FLAGS), (object(), name not in FLAGS)]
    if isinstance(valid, (int, float)) and not isinstance(valid, bool):
        values += [(-1, True), (10 ** 400, True), (float("nan"), True), ("3", True)]
    elif isinstance(valid, str):
        values += [(b"bytes", True), (3, name not in ("device",))]
    elif isinstance(valid, (tuple, list)) and name != "aovs":
        values += [((float("inf"),) * len(valid), True), (("x",) * len(valid), True)]
    elif isinstance(valid, dict):
        values += [([1, 2], True), ({"p": 10 ** 400}, True)]
    return values


@pytest.mark.opencl
def test_every_api_function_answers_wrong_arguments_in_words(tmp_path):
    import inspect
    failures = []
    for name, function, valid in _api_calls(tmp_path):
        parameters = inspect.signature(function).parameters
        for argument, good in valid.items():
            parameter = parameters.get(argument)
            # None: the default where it is one; a render key given as None keeps the file's value
            none_means_default = parameter is None or parameter.default is None
            for value, refused in _hostile_values(argument, good, none_means_default):
                call = f"{name}({argument}={value!r:.40})"
                try:
                    function(**{**valid, argument: value})
                except ERRORS as error:
                    said = str(error)
                    key = "points" if argument == "points" else argument
                    if not refused:
                        failures.append(f"{call}: refused: {said}")
                    elif key not in said and not (argument in ("values", "params") and "param" in said) \
                            and not (argument == "pattern" and "%d" in said):
                        failures.append(f"{call}: {type(error).__name__} without the argument's name: {said}")
                except Exception as error:   # noqa: BLE001 -- an internal exception is what this test finds
                    failures.append(f"{call}: {type(error).__name__}: {error}")
                else:
                    if refused:
                        failures.append(f"{call}: accepted")
    assert not failures, "\n".join(failures)


@pytest.mark.opencl
def test_api_examples_of_the_issue():
    """loads(bytes), loads(None), params=[1, 2], device=0 (an index, as
    --device 0), render(camera='x'), render(aovs=3), save(Path), 10**400."""
    import pathlib
    import tempfile
    for call, error, words in [
        (lambda: fractalc.loads(API_SCENE.encode()), TypeError, "text must be"),
        (lambda: fractalc.loads(None), TypeError, "text must be"),
        (lambda: fractalc.loads(API_SCENE, params=[1, 2]), TypeError, "params must be a dict"),
        (lambda: fractalc.loads(API_SCENE).render(camera="x"), TypeError, "camera must be a fractalc.Camera"),
        (lambda: fractalc.loads(API_SCENE).render(aovs=3), TypeError, "aovs must be a list of pass names"),
        (lambda: fractalc.loads(API_SCENE, params={"p": 10 ** 400}), ValueError, "param 'p' must be a finite"),
    ]:
        with pytest.raises(error, match=words):
            call()
    scene = fractalc.loads(API_SCENE, device=0)
    assert scene.device_spec == "0"
    with tempfile.TemporaryDirectory() as folder:
        scene.render().save(pathlib.Path(folder) / "x.exr")
        assert (pathlib.Path(folder) / "x.exr").stat().st_size > 0


@pytest.mark.opencl
def test_one_device_spelled_two_ways_shares_one_context():
    """The default device and device='cpu' (here the same one): a program
    built for one spelling ran with the other's queue (INVALID_CONTEXT)."""
    first = fractalc.loads(API_SCENE)
    first.distance([[0.0, 0.0, 0.0]])
    second = fractalc.loads(API_SCENE, device=first.device.info.kind.lower())
    assert second.device is first.device
    np.testing.assert_array_equal(second.distance([[0.0, 0.0, 0.0]]), [-1.0])


@pytest.mark.opencl
def test_mesh_bounds_that_make_cells_degenerate_are_refused(tmp_path, capsys):
    """--bounds=-1e30,-1,-1,1e30,1,1 at resolution 8 wrote 'v nan ...'."""
    scene_file = tmp_path / "scene.frac"
    scene_file.write_text("scene sphere(1)\n")
    out = tmp_path / "m.obj"
    for bounds, words in [("-1e30,-1,-1,1e30,1,1", "coordinates must lie within"),
                          ("-1e10,-1,-1,1e10,1,1", "the box's y side (2) is shorter than one cell"),
                          ("1000000,-1,-1,1000002,1,1", "cells of 0.25 are too small for float numbers")]:
        printed = _usage_error(["mesh", str(scene_file), "-o", str(out), "--resolution", "8",
                                f"--bounds={bounds}"], capsys)
        assert "--bounds" in printed and words in printed, printed
        assert not out.exists()
    scene = fractalc.loads("scene sphere(1).translate((1000000, 0, 0))\n", precision="double")
    mesh = scene.mesh(resolution=8, bounds=(1e6 - 1.5, -1.5, -1.5, 1e6 + 1.5, 1.5, 1.5))  # double resolves it
    assert np.isfinite(mesh.vertices).all() and np.isfinite(mesh.normals).all()


# ---- environment maps: read in bands, their pixels finite (issue 22) ----------

def _write_map(path, pixels, tile=0):
    import OpenImageIO as oiio
    height, width, channels = pixels.shape
    fmt = oiio.UINT8 if str(path).endswith(".png") else oiio.FLOAT
    spec = oiio.ImageSpec(width, height, channels, fmt)
    if tile:
        spec.tile_width = spec.tile_height = tile
    output = oiio.ImageOutput.create(str(path))
    assert output.open(str(path), spec), oiio.geterror()
    output.write_image(pixels)
    output.close()


def _box_filtered(pixels, rows, columns):
    """The float64 reference: each texel the mean of the pixels whose
    centres fall in it (the nearest pixel where none does), negative
    values taken as 0."""
    pixels = np.maximum(pixels.astype(np.float64), 0.0)
    height, width = pixels.shape[:2]
    table = np.zeros((rows, columns, 3))
    y = (np.arange(height) + 0.5) / height * rows
    x = (np.arange(width) + 0.5) / width * columns
    for r in range(rows):
        for c in range(columns):
            inside = pixels[(y >= r) & (y < r + 1)][:, (x >= c) & (x < c + 1)]
            table[r, c] = inside.reshape(-1, pixels.shape[2])[:, :3].mean(axis=0) if inside.size \
                else pixels[r * height // rows, c * width // columns, :3]
    return table


@pytest.mark.parametrize("size, tile, name", [((37, 203, 4), 0, "a.exr"), ((70, 130, 3), 16, "b.exr"),
                                              ((5, 9, 3), 0, "small.exr")])
def test_an_environment_map_read_in_bands_is_the_box_filtered_map(size, tile, name, tmp_path, monkeypatch):
    """One row read at a time (a scanline file, a tiled one, a map smaller
    than the table): the texels of the whole map's float64 box filter."""
    from fractalc import pathtrace
    monkeypatch.setattr(pathtrace, "MAP_READ_BYTES", 1)
    pixels = np.random.default_rng(22).normal(1.0, 2.0, size).astype(np.float32)
    _write_map(tmp_path / name, pixels, tile)
    texels = pathtrace.environment_map(str(tmp_path / name))
    np.testing.assert_allclose(texels, _box_filtered(pixels, pathtrace.MAP_HEIGHT, pathtrace.MAP_WIDTH),
                               rtol=1e-12, atol=1e-12)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS as Linux counts it")
def test_a_large_environment_map_is_read_in_the_memory_of_its_table(tmp_path):
    """A 4000x2000 PNG was read whole, as float32 then float64 (290 MB;
    an 8000x4000 one peaked at 1.5 GB): read within 96 MB of address space
    more than the reader had before it."""
    import subprocess
    pixels = np.zeros((2000, 4000, 3), np.uint8)
    pixels[..., 0] = (np.arange(2000) * 255 // 2000)[:, None]
    _write_map(tmp_path / "sky.png", pixels)
    code = ("import resource, sys\nfrom fractalc import pathtrace\n"
            "used = int(next(l for l in open('/proc/self/status') if l.startswith('VmSize')).split()[1]) * 1024\n"
            "resource.setrlimit(resource.RLIMIT_AS, (used + 96 * 2 ** 20, resource.RLIM_INFINITY))\n"
            "texels = pathtrace.environment_map(sys.argv[1])\nprint(texels[:, 0, 0].min(), texels[:, 0, 0].max())")
    path = os.pathsep.join([os.path.dirname(os.path.dirname(os.path.abspath(__file__))), os.environ.get("PYTHONPATH", "")])
    result = subprocess.run([sys.executable, "-c", code, str(tmp_path / "sky.png")], capture_output=True, text=True,
                            timeout=120, env={**os.environ, "PYTHONPATH": path})
    assert result.returncode == 0, result.stderr[-2000:]
    low, high = map(float, result.stdout.split())
    assert 0 <= low < 0.05 and 0.9 < high <= 1.0     # the gradient down the rows, averaged into the table


def test_a_map_with_a_nan_pixel_is_an_error_at_what_named_it(tmp_path, capsys):
    """'fractalc: error: non-finite constant nan' came with no place."""
    from fractalc.cli import main
    pixels = np.ones((32, 64, 3), np.float32)
    pixels[5, 7, 1] = np.nan
    _write_map(tmp_path / "nan.exr", pixels)
    text = 'scene sphere(1)\nrender { environment: { map: "nan.exr" } }\n'
    (tmp_path / "scene.frac").write_text(text)
    with pytest.raises(fractalc.SceneError) as error:
        fractalc.load(tmp_path / "scene.frac")
    assert (error.value.line, error.value.column) == (2, text.splitlines()[1].index('"nan.exr"') + 1)
    assert "has a non-finite pixel (1, nan, 1) at x 7, y 5" in error.value.message
    (tmp_path / "plain.frac").write_text("scene sphere(1)\n")
    printed = _usage_error(["render", str(tmp_path / "plain.frac"), "-o", str(tmp_path / "o.png"),
                            "--environment-map", str(tmp_path / "nan.exr")], capsys)
    assert f"--environment-map {tmp_path / 'nan.exr'}: the environment map" in printed and "non-finite" in printed
    with pytest.raises(ValueError, match="non-finite pixel"):
        fractalc.loads("scene sphere(1)").render(environment_map=tmp_path / "nan.exr")
    assert not (tmp_path / "o.png").exists()


# ---- render farms and animations (issue 22) -------------------------------------

@pytest.mark.parametrize("address, words", [
    ("tls://127.0.0.1:1", "not tls://"), ("ucx://127.0.0.1:1", "not ucx://"), ("inproc://x", "not inproc://"),
    ("tcp://localhost", "tcp://HOST:PORT, with a port from 1 to 65535"), ("tcp://host:٣", "a port from 1"),
])
def test_a_cluster_scheme_fractalc_does_not_support_is_refused_in_one_line(address, words, tmp_path, capsys):
    """tls:// and ucx:// were TypeErrors from inside Dask, inproc:// 'not
    enough values to unpack'."""
    pytest.importorskip("distributed")
    scene = tmp_path / "scene.frac"
    scene.write_text("scene sphere(1)\n")
    printed = _usage_error(["render", str(scene), "-o", str(tmp_path / "o.png"), "--cluster", address], capsys)
    assert f"--cluster {address}: " in printed and words in printed and "Traceback" not in printed


def test_a_cluster_that_cannot_be_reached_is_one_line(tmp_path, capsys, monkeypatch):
    distributed = pytest.importorskip("distributed")
    from fractalc.cli import main

    def unreachable(address, timeout):
        raise OSError(f"Timed out trying to connect to {address} after {timeout}\nmore of Dask's words")
    monkeypatch.setattr(distributed, "Client", unreachable)
    scene = tmp_path / "scene.frac"
    scene.write_text("scene sphere(1)\n")
    assert main(["render", str(scene), "-o", str(tmp_path / "o.png"), "--cluster", "farm:8786", "-q"]) == 1
    err = capsys.readouterr().err
    assert err == ("fractalc: error: cannot reach the Dask scheduler at tcp://farm:8786: Timed out trying to "
                   "connect to tcp://farm:8786 after 10s\n")


@pytest.mark.parametrize("pattern, words", [
    ("fr/%4d/x.png", "the frame number goes in the file's name, not a folder's"),
    ("fr/%c.png", "the name must hold the frame number once"),
    ("fr/%d_%d.png", "the name must hold the frame number once"),
    ("fr/100%_%d.png", "the name must hold the frame number once"),
    ("fr/%s.png", "the name must hold the frame number once"),
    ("fr/f\x01%d.png", "a control character"),
    ("fr/%d.jpg", "frames must be .exr or .png"),
])
def test_an_animations_file_pattern_is_checked_whole_before_the_first_frame(pattern, words, tmp_path, capsys):
    """'fr/%4d/x.png' wrote frame 0 and failed at frame 1; 'fr/%c.png' said
    'embedded null byte'."""
    scene = tmp_path / "scene.frac"
    scene.write_text(OPTIONS_SCENE)
    printed = _usage_error(["animate", str(scene), "-o", str(tmp_path / pattern), "-q"], capsys)
    assert words in printed and "Traceback" not in printed
    assert not (tmp_path / "fr").exists()
    from fractalc.animate import render_frames
    with pytest.raises(ValueError, match=re.escape(words)):
        render_frames(fractalc.loads(OPTIONS_SCENE), str(tmp_path / pattern), 2)


def test_a_path_too_long_for_its_fps_is_refused_before_any_frame(tmp_path, capsys):
    scene = tmp_path / "scene.frac"
    scene.write_text("scene sphere(1)\npath { 0: { position: (0, -4, 1) }, 1e30: { position: (4, 0, 1) } }\n")
    printed = _usage_error(["animate", str(scene), "-o", str(tmp_path / "f_%d.png")], capsys)
    assert "fps 30: the path's 1e+30 s would be 3e+31 frames, more than 1000000" in printed
    assert [p.name for p in tmp_path.iterdir()] == ["scene.frac"]


@pytest.mark.parametrize("arguments, error, name", [
    ({"workers": 0}, ValueError, "'workers'"), ({"workers": -1}, ValueError, "'workers'"),
    ({"workers": 10 ** 400}, ValueError, "'workers'"), ({"workers": "2"}, ValueError, "'workers'"),
    ({"workers": object()}, ValueError, "'workers'"), ({"address": 3}, TypeError, "address"),
    ({"address": b"tcp://h:1"}, TypeError, "address"), ({"address": "tls://h:1"}, ValueError, "tls://"),
])
def test_connecting_to_a_cluster_answers_wrong_arguments_before_starting_one(arguments, error, name):
    pytest.importorskip("distributed")
    from fractalc import cluster
    with pytest.raises(error, match=re.escape(name)):
        with cluster.connect(**arguments):
            pytest.fail("a cluster started")


def test_a_local_cluster_that_cannot_start_is_one_line(monkeypatch):
    """Found by the fuzzer (a daemon process may not start workers): Dask's
    'Nanny failed to start' RuntimeError, its cause said in words."""
    distributed = pytest.importorskip("distributed")
    from fractalc import cluster

    def failing(**kwargs):
        try:
            raise AssertionError("daemonic processes are not allowed to have children")
        except AssertionError as cause:
            raise RuntimeError("Nanny failed to start.") from cause
    monkeypatch.setattr(distributed, "LocalCluster", failing)
    with pytest.raises(fractalc.RenderError, match="^cannot start a local Dask cluster of 2 workers: daemonic "
                                                   "processes are not allowed to have children$"):
        with cluster.connect(workers=2):
            pass
