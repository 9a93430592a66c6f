"""Input written to break the compiler: every scene that passes `check`
builds and renders, mistakes are located errors (never a traceback), and
nothing from the file reaches the kernel unescaped (issue 10)."""

import numpy as np
import pytest

import fractalc

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


def test_flat_union_past_the_nesting_limit_builds():
    """Item 2: 300 shapes in one union (once more brackets than clang takes)."""
    scene = fractalc.loads(f"scene union({', '.join(_translated_spheres())})")
    np.testing.assert_allclose(scene.distance(POINTS), _sphere_distances(POINTS).min(axis=0), atol=1e-5)
    assert np.isfinite(scene.render(width=16, height=12).depth).any()


def test_smooth_union_of_many_shapes_folds_left_to_right():
    """Item 2: a smooth union stays ordered (LANGUAGE.md), however long."""
    k = 0.3
    scene = fractalc.loads(f"scene union({', '.join(_translated_spheres())}, smooth: {k})")
    expected = _sphere_distances(POINTS)[0]
    for d in _sphere_distances(POINTS)[1:]:
        h = np.maximum(k - np.abs(expected - d), 0) / k
        expected = np.minimum(expected, d) - h * h * k / 4
    np.testing.assert_allclose(scene.distance(POINTS), expected, atol=1e-4)


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
    from fractalc.check import MAX_SHAPES
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


def test_out_of_memory_is_one_line_with_exit_1(tmp_path, capsys, monkeypatch):
    """The host's image array not fitting in memory (numpy's MemoryError;
    simulated: a real one needs a 144 GiB array) is a runtime failure."""
    from fractalc import cli, run

    def no_memory(*args, **kwargs):
        raise MemoryError("Unable to allocate 144. GiB for an array")

    monkeypatch.setattr(run, "render", no_memory)
    scene = tmp_path / "scene.frac"
    scene.write_text("scene sphere(1)\n")
    assert cli.main(["render", str(scene), "-o", str(tmp_path / "out.exr"), "-q",
                     "--width", "65536", "--height", "65536"]) == 1
    printed = capsys.readouterr().err
    assert printed.startswith("fractalc: error: out of memory") and printed.count("\n") == 1


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
def test_tiny_scales_far_offsets_and_huge_warp_rates_give_finite_distances(shape, precision):
    """Item 1 (fuzz finding 6): a moved point that would pass float's range
    is clamped, a warp's rate too; distances stay finite and images too."""
    scene = fractalc.loads(f"scene {shape}\ncamera {{ position: (0, -6, 2), target: (0, 0, 0) }}",
                           precision=precision)
    assert np.isfinite(scene.distance(FAR)).all()
    image = scene.render(width=16, height=12)
    assert np.isfinite(image.rgba).all() and np.isfinite(image.normal).all()
    assert ((image.depth >= 0) | (image.depth == np.inf)).all()


def test_clamping_a_far_point_keeps_the_estimate_a_lower_bound():
    """Item 1: a sphere 1.2e21 away in double: the clamped estimate (1e18
    at most) is finite and below the true distance; near it, exact."""
    far = 2.0 ** 70          # 1.2e21, and points near it that double holds exactly
    scene = fractalc.loads(f"scene sphere(1).translate((0, 0, {far:.0f}))", precision="double")
    d = scene.distance(np.array([[0.0, 0, 0], [0, 0, far - 2.0 ** 19]]))
    assert 1e17 < d[0] <= far - 1
    assert d[1] == 2.0 ** 19 - 1


def test_epsilon_scale_beyond_its_limit_is_a_located_error(tmp_path, capsys):
    """Item 1 (fuzz finding 7): a threshold of 1e30 pixels gave NaN normals."""
    printed = _check_errors("scene sphere()\nrender { epsilon_scale: 1e30 }\n", tmp_path, capsys)
    assert ":2:25: error: 'epsilon_scale' of 'render' must be at most 1000" in printed
    image = fractalc.loads("scene sphere()\nrender { epsilon_scale: 1000 }").render(width=16, height=12)
    assert np.isfinite(image.normal).all() and np.isfinite(image.depth).any()


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

    from fractalc import check
    calls = []
    original = difflib.get_close_matches
    monkeypatch.setattr(difflib, "get_close_matches", lambda *a, **k: calls.append(a[0]) or original(*a, **k))
    text = "\n".join(f"let value_{i} = 1\nlet x_{i} = valu_{i}" for i in range(1000)) + "\nscene sphere()"
    with pytest.raises(fractalc.SceneError) as error:
        fractalc.loads(text)
    messages = [d.message for d in error.value.errors]
    assert len(messages) == 1000 and len(calls) == check.SUGGESTED_ERRORS
    assert messages[0] == "unknown name 'valu_0' (did you mean 'value_0'?)"
    assert messages[-1] == "unknown name 'valu_999'"


# ---- the user's text in generated source and names -------------------------

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
def test_shapes_whose_distance_squares_a_huge_size_are_refused_at_the_value(text, key):
    """A capsule end at 1e30 gave distance +inf everywhere (fuzz seed 5 case 3209)."""
    with pytest.raises(fractalc.SceneError, match=key):
        fractalc.loads(text)
    assert np.isfinite(fractalc.loads("scene capsule((0, 0, -1e17), (0, 0, 1e17)) | torus(1e17, 1e17)")
                       .distance([[0, 0, 0], [1, 2, 3]])).all()
