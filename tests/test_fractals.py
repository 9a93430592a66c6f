"""The five fractals through the language (`fractalc.loads` -> compiled
kernel): distances against the float64 numpy reference of
`reference_fractals.py` at the defaults and at param-driven settings (params
changed without rebuilding), hard cases, the bounding sphere `lower` wraps
every fractal in (and how it moves with transforms), depth maps against a
numpy sphere tracer, orbit-trap colouring and double precision.

`test_fractal_library.py` tests the .cl files on their own (accuracy over
many settings, lower bounds, finiteness, the bound radii): this file tests
what the language adds on top of them and reuses that file's sampling
helpers."""

import dataclasses
import re
from functools import lru_cache

import numpy as np
import pytest

import fractalc
import reference_fractals as ref
from fractalc import build as build_module
from fractalc import emit as emit_module
from fractalc.emit import Target, emit_distance
from fractalc.lower import lower
from test_fractal_library import ball, relative_error, shell, tolerance

PRECISIONS = ("float", "double")
SQRT3 = np.sqrt(3.0)
from fractalc.ir import BOUND_MARGIN as MARGIN   # evaluated within (1 + MARGIN) R

pytestmark = pytest.mark.emit
ULP = {"float": np.finfo(np.float32).eps, "double": np.finfo(np.float64).eps}

DEFAULTS = {
    "mandelbulb": dict(power=8.0, iterations=12, bailout=2.0),
    "julia": dict(c=(-0.2, 0.6, 0.2, 0.0), slice=0.0, iterations=12, bailout=4.0),
    "mandelbox": dict(scale=2.0, min_radius=0.5, fixed_radius=1.0, fold_limit=1.0, iterations=12),
    "menger": dict(level=4),
    "sierpinski": dict(level=6),
}
FRACTALS = tuple(DEFAULTS)


def builds():
    return build_module.statistics.builds


@lru_cache(maxsize=None)
def scene(text, precision="float", device=None):
    """A loaded scene, shared by the tests (params are mutable: a test sets
    every param it relies on)."""
    return fractalc.loads(text, precision=precision, device=device)


# ---------------------------------------------------------------- numpy references

def menger_de(p, level):
    """The Menger estimator of stdlib_cl/fractals/menger.cl in float64: the
    largest of the signed distances to the cube and to the outside of each
    level's bars. The contract only asks for a lower bound of the true
    distance; `test_solid_references_against_the_exact_distances` checks that
    this one is (so the kernel, agreeing with it, is too)."""
    p = np.clip(np.asarray(p, dtype=np.float64), -1e15, 1e15)
    q = np.abs(p) - 1
    d = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
    a, size = p.copy(), 1.0
    for _ in range(level):
        a = np.abs(a)
        ordered = np.sort(a, axis=1)
        u, v = ordered[:, 1] - 1 / 3, ordered[:, 0] - 1 / 3
        bar = np.hypot(np.maximum(u, 0), np.maximum(v, 0)) + np.minimum(np.maximum(u, v), 0)
        d = np.maximum(d, -bar * size)
        a = np.where(a > 1 / 3, 3 * a - 2, 3 * a)
        size /= 3
    return d


def tetrahedron_sd(p):
    """Exact signed distance to the level-0 tetrahedron: the largest face
    plane distance inside (a convex solid), the exact distance of
    reference_fractals outside."""
    planes = (-(p @ ref.TETRAHEDRON.T) - 1) / SQRT3        # face opposite vertex i: a_i . p = -1
    inside = planes.max(axis=1)
    out = inside > 0
    result = inside.copy()
    if out.any():
        result[out] = ref.tetrahedron_distance(p[out], ref.TETRAHEDRON[None])[:, 0]
    return result


def sierpinski_de(p, level):
    """The exact signed distance to the level-N solid, by folding: the
    reflections swapping (1,1,1) with another vertex map the solid to itself,
    and dist(p) = dist(2p - (1,1,1)) / 2 on (1,1,1)'s side of them."""
    p = np.clip(np.asarray(p, dtype=np.float64), -1e15, 1e15).copy()
    for _ in range(level):
        for i, j in ((0, 1), (0, 2), (1, 2)):
            flip = p[:, i] + p[:, j] < 0
            p[flip, i], p[flip, j] = -p[flip, j], -p[flip, i]
        p = 2 * p - 1
    return tetrahedron_sd(p) / 2 ** level


def reference_de(name, points, **kwargs):
    """The float64 distance estimate of fractal NAME (defaults for the
    arguments not given)."""
    args = {**DEFAULTS[name], **kwargs}
    points = np.asarray(points, dtype=np.float64)
    if name == "menger":
        return menger_de(points, int(args["level"]))
    if name == "sierpinski":
        return sierpinski_de(points, int(args["level"]))
    if "iterations" in args:
        args["iterations"] = int(args["iterations"])
    return getattr(ref, name)(points, **args)


def bound_radius(name, **kwargs):
    """R of `<name>_bound_radius` in the .cl files, in numpy."""
    args = {**DEFAULTS[name], **kwargs}
    if name == "mandelbulb":
        power = args["power"]
        return 1.0 if power <= 1 else 2.0 ** (1 / (power - 1))
    if name == "julia":
        radius = (1 + np.sqrt(1 + 4 * np.linalg.norm(args["c"]))) / 2
        return float(np.sqrt(max(radius ** 2 - args["slice"] ** 2, 0.0)))
    if name == "mandelbox":
        s, limit = args["scale"], args["fold_limit"]
        if 0 < s <= 1:
            return np.inf
        return float(SQRT3 * (2 * limit if s <= 0 else 2 * limit * (s + 1) / (s - 1)))
    return float(SQRT3)


def bounded_reference_de(name, points, **kwargs):
    """What the scene computes: the DE within (1 + MARGIN) R of the origin,
    the bounding sphere's distance |p| - R beyond."""
    radius = bound_radius(name, **kwargs)
    sphere = np.linalg.norm(points, axis=1) - radius
    near = sphere < MARGIN * radius
    result = sphere.copy()
    if near.any():
        result[near] = reference_de(name, points[near], **kwargs)
    return result


def rotated_back(points, axis, degrees):
    """R^T p for R the right-handed rotation about `axis` (LANGUAGE.md)."""
    k = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    angle = np.radians(-degrees)
    return (points * np.cos(angle) + np.cross(k, points) * np.sin(angle)
            + np.outer(points @ k, k) * (1 - np.cos(angle)))


def p99(d, expected):
    return float(np.percentile(relative_error(d, expected), 99))


def test_solid_references_against_the_exact_distances():
    # The numpy estimators above stand for the kernel's in this file: they
    # must be lower bounds of the exact distances (sierpinski: equal to it),
    # and <= 0 exactly on the solid.
    points = np.concatenate([np.random.default_rng(11).uniform(-1.2, 1.2, (600, 3)), ball(200, 3.0, 12)])
    for level in (0, 1, 2):
        truth = ref.menger_distance(points, level)
        d = menger_de(points, level)
        assert (d <= truth + 1e-12).all()
        assert ((d <= 1e-12) == (truth == 0)).mean() > 0.99
        assert np.mean(d[truth > 1e-3] / truth[truth > 1e-3]) > 0.5
    for level in (0, 1, 3, 6):
        sample = points if level < 6 else points[:150]
        truth = ref.sierpinski_distance(sample, level)
        assert np.allclose(np.maximum(sierpinski_de(sample, level), 0), truth, rtol=0, atol=1e-12)


# ---------------------------------------------------------------- 1. distances through the language

def _region(name, kwargs, count=10_000, seed=20240607):
    """Seeded points inside the bound radius (a finite one): the DE itself."""
    return ball(count, min(bound_radius(name, **kwargs), 20.0), seed)


@pytest.mark.opencl
@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("name", FRACTALS)
def test_default_fractal_matches_reference(name, precision, driver):
    points = _region(name, {})
    d = scene(f"scene {name}()", precision, driver).distance(points)
    assert np.isfinite(d).all()
    error = p99(d, reference_de(name, points))
    print(f"\nFIGURE default {name} {precision}: p99 relative error {error:.3g}")
    assert error < tolerance(name, precision)


# (fractal, argument, three settings: the file's param value, one given by
# set_params, one by loads(params=)); julia's c is four params, one a component
C_PARAMS = ("c0", "c1", "c2", "c3")
PARAM_CASES = [
    ("mandelbulb", "power", (6.0, 3.0, 12.0)),
    ("mandelbulb", "iterations", (20, 5, 16)),
    ("mandelbulb", "bailout", (4.0, 1.0, 50.0)),
    ("julia", "c", ((0.3, -0.5, 0.4, 0.2), (-0.8, 0.15, 0.0, 0.1), (-0.2, 0.6, 0.2, 0.0))),
    ("julia", "slice", (0.3, -0.2, 0.9)),
    ("julia", "iterations", (20, 6, 64)),
    ("julia", "bailout", (16.0, 2.0, 1e6)),
    ("mandelbox", "scale", (-1.5, 3.0, 2.5)),
    ("mandelbox", "min_radius", (0.3, 0.1, 0.8)),
    ("mandelbox", "fixed_radius", (1.2, 0.8, 2.0)),
    ("mandelbox", "fold_limit", (0.8, 1.5, 0.5)),
    ("mandelbox", "iterations", (8, 20, 40)),
    ("menger", "level", (2, 0, 5)),
    ("sierpinski", "level", (3, 0, 8)),
]
RANGES = {"power": (1, 32), "iterations": (1, 1000), "bailout": (0.01, 1e7), "slice": (-3, 3),
          "scale": (-4, 4), "min_radius": (0.01, 1), "fixed_radius": (0.5, 3), "fold_limit": (0.1, 3),
          "level": (0, 10), "c": (-2, 2)}


def param_scene_text(name, argument, value):
    """`param NAME = value in [lo, hi]` (one per component for c) and the
    fractal called with the param."""
    lo, hi = RANGES[argument]
    if argument == "c":
        lines = [f"param {p} = {v!r} in [{lo}, {hi}]" for p, v in zip(C_PARAMS, value)]
        call = f"julia(c: ({', '.join(C_PARAMS)}))"
    else:
        lines = [f"param {argument} = {value!r} in [{lo}, {hi}]"]
        call = f"{name}({argument}: {argument})"
    return "\n".join(lines + [f"scene {call}"])


def param_values(argument, value):
    return dict(zip(C_PARAMS, value)) if argument == "c" else {argument: value}


def _check_against_reference(name, argument, value, distance, precision, label):
    kwargs = {argument: value}
    points = _region(name, kwargs)
    d = distance(points)
    assert np.isfinite(d).all()
    error = p99(d, reference_de(name, points, **kwargs))
    print(f"\nFIGURE {name} {argument}={value} ({label}) {precision}: p99 relative error {error:.3g}")
    assert error < tolerance(name, precision), f"{argument} = {value} ({label}): p99 relative error {error:.3g}"


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("name, argument, values", PARAM_CASES,
                         ids=[f"{c[0]}-{c[1]}" for c in PARAM_CASES])
@pytest.mark.opencl
def test_param_driven_fractal_matches_reference(name, argument, values, precision):
    in_file, set_later, given_to_loads = values
    text = param_scene_text(name, argument, in_file)
    s = scene(text, precision)
    s.set_params(param_values(argument, in_file))   # the file's value (the scene is shared)
    _check_against_reference(name, argument, in_file, s.distance, precision, "file")
    before = builds()
    s.set_params(param_values(argument, set_later))
    _check_against_reference(name, argument, set_later, s.distance, precision, "set_params")
    other = fractalc.loads(text, params=param_values(argument, given_to_loads), precision=precision)
    _check_against_reference(name, argument, given_to_loads, other.distance, precision, "params=")
    assert builds() == before, "changing a param rebuilt the kernel"


@pytest.mark.parametrize("call, bad", [
    ("mandelbulb(iterations: v)", 12.5), ("mandelbulb(iterations: v)", 0), ("mandelbulb(iterations: v)", 1001),
    ("mandelbulb(power: v)", 0.5), ("mandelbulb(power: v)", 33), ("mandelbulb(bailout: v)", 0),
    ("julia(bailout: v)", -1), ("julia(iterations: v)", 2.5), ("mandelbox(min_radius: v)", 0),
    ("mandelbox(fixed_radius: v)", -1), ("mandelbox(iterations: v)", 0.5),
    ("menger(level: v)", 11), ("menger(level: v)", 1.5), ("sierpinski(level: v)", -1)], ids=str)
def test_param_values_outside_the_valid_values_are_check_errors(call, bad):
    text = f"param v = 1 in [-10, 2000]\nscene {call}"
    s = fractalc.loads(text)
    with pytest.raises(fractalc.SceneError) as error:
        s.set_params({"v": bad})
    assert (error.value.line, error.value.column) == _position(text, "v)")
    with pytest.raises(fractalc.SceneError):
        fractalc.loads(text, params={"v": bad})


@pytest.mark.opencl
def test_a_rejected_param_value_leaves_the_scene_unchanged():
    # set_params stores each value before checking the values that depend on
    # it: after the SceneError the scene renders with the rejected value
    # (here a negative fixed_radius), and a dict with one bad entry applies
    # the good ones before it.
    text = "param v = 1 in [-10, 10]\nparam w = 2 in [-10, 10]\nscene mandelbox(fixed_radius: v, fold_limit: w)"
    s = fractalc.loads(text)
    points = ball(50, 3.0, 17)
    before = s.distance(points)
    with pytest.raises(fractalc.SceneError):
        s.set_params({"v": -1})
    with pytest.raises(fractalc.SceneError):
        s.set_params({"w": 1.5, "v": 0})
    assert s.params == {"v": 1, "w": 2}, f"the scene kept rejected values: {s.params}"
    assert np.array_equal(s.distance(points), before)


# ---------------------------------------------------------------- 2. hard cases

SPECIAL = np.array([(0, 0, 0), (0.1, 0.1, 0.1), (0, 0, 1e-3), (1 - 1e-6, 1 - 1e-6, 1 - 1e-6)])
ORIGIN, INNER, VERTEX = 0, slice(1, 3), 3      # rows of SPECIAL: the origin, the inner bulb, a solid's vertex


def hard_points(name, kwargs):
    """SPECIAL, then points on the axes, on the bailout sphere, with tiny
    and huge coordinates."""
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    radius = bound_radius(name, **kwargs)
    radii = [1e-30, 1e-6, 0.1, 0.5, 1.0, 2.0, 1e6]
    if np.isfinite(radius):
        radii += [radius, radius * (1 + MARGIN), radius * (1 + MARGIN) * (1 + 1e-6)]
    points = [SPECIAL, *(axes * r for r in radii), shell(50, 1e6, 1e6, 2),
              np.array([(1e-20, 1e-20, 1e-20), (0.5, 0.5, 0.5), (1, 1, 1), (-1, -1, 1), (-5.8e5, 5.8e5, 5.8e5)])]
    bailout = kwargs.get("bailout", DEFAULTS[name].get("bailout"))
    if bailout is not None:
        points += [axes * bailout, shell(100, bailout, bailout, 3),
                   axes * np.nextafter(bailout, np.inf), axes * np.nextafter(bailout, 0)]
    return np.concatenate(points)


HARD = [
    ("mandelbulb", {}), ("mandelbulb", dict(power=2.0)), ("mandelbulb", dict(power=16.0)),
    ("mandelbulb", dict(iterations=64)), ("mandelbulb", dict(bailout=1e6)),
    ("mandelbulb", dict(bailout=1.0)),       # the bailout sphere inside the bound
    ("julia", {}), ("julia", dict(iterations=64)), ("julia", dict(bailout=1e6)), ("julia", dict(bailout=1.0)),
    ("mandelbox", {}), ("mandelbox", dict(scale=-1.5)), ("mandelbox", dict(scale=3.0)),
    ("mandelbox", dict(scale=0.5)),          # no bound: the DE is evaluated everywhere, 1e6 included
    ("mandelbox", dict(iterations=64)),
    ("menger", dict(level=0)), ("menger", {}), ("menger", dict(level=10)),
    ("sierpinski", dict(level=0)), ("sierpinski", {}), ("sierpinski", dict(level=10)),
]


def _param_scene_for(name, kwargs, precision):
    """A cached param scene of PARAM_CASES set to `kwargs` (one argument)."""
    if not kwargs:
        return scene(f"scene {name}()", precision)
    (argument, value), = kwargs.items()
    case = next(c for c in PARAM_CASES if c[0] == name and c[1] == argument)
    s = scene(param_scene_text(name, argument, case[2][0]), precision)
    s.set_params(param_values(argument, value))
    return s


@pytest.mark.opencl
@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("name, kwargs", HARD, ids=[f"{n}-{k}" for n, k in HARD])
def test_hard_cases_are_finite_with_the_right_sign(name, kwargs, precision):
    points = hard_points(name, kwargs)
    s = _param_scene_for(name, kwargs, precision)
    d = s.distance(points)
    bad = points[~np.isfinite(d)]
    assert len(bad) == 0, f"not finite at {bad[:5]}"
    norm = np.linalg.norm(points, axis=1)
    radius = bound_radius(name, **kwargs)
    if np.isfinite(radius):
        # far away: the bounding sphere, positive
        far = norm > 1e5
        assert (d[far] > 0).all()
        assert np.allclose(d[far], norm[far] - radius, rtol=8 * ULP[precision], atol=0)
    else:
        assert (d[norm > 1e5] > 1e5).all()      # the DE at 1e6 (the bound is infinite)
    origin = d[ORIGIN]
    if name in ("mandelbulb", "mandelbox", "julia"):
        # the origin is in these sets: mandelbulb and mandelbox keep z = 0
        # (DE = 0); julia's default orbit of 0 stays bounded with dr = 0 (DE = 0)
        assert origin == 0
    if name == "mandelbulb":
        assert (d[INNER] <= 1e-6).all(), "points of the set's inner region are not inside"
    if name == "mandelbox":
        assert (d >= 0).all(), "the Mandelbox DE |z| / |dr| is never negative"
    if name in ("menger", "sierpinski"):
        level = kwargs.get("level", DEFAULTS[name]["level"])
        # a vertex of the cube / tetrahedron is in every level
        assert d[VERTEX] <= 1e-5
        if level >= 1 and name == "menger":
            # the centre is cut away; its nearest points, the edge midpoints
            # of the kept cubes around it, stay in every level
            assert 0 < origin <= np.sqrt(2) / 3 + 1e-6
        elif level >= 1:
            assert origin == pytest.approx(sierpinski_de(np.zeros((1, 3)), level)[0], rel=1e-5)
            assert origin > 0


# ---------------------------------------------------------------- 3. bounding

BOUND_SETTINGS = [("mandelbulb", {}), ("mandelbulb", dict(power=3.0)), ("julia", {}),
                  ("julia", dict(slice=0.9)), ("mandelbox", {}), ("mandelbox", dict(scale=-1.5)),
                  ("mandelbox", dict(fold_limit=0.5)), ("menger", {}), ("sierpinski", {})]


@pytest.mark.opencl
@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("name, kwargs", BOUND_SETTINGS, ids=[f"{n}-{k}" for n, k in BOUND_SETTINGS])
def test_outside_the_bound_is_the_bounding_sphere_distance(name, kwargs, precision):
    s = _param_scene_for(name, kwargs, precision)
    radius = bound_radius(name, **kwargs)
    limit = (1 + MARGIN) * radius
    far = np.concatenate([shell(3000, limit * (1 + 1e-5), 10 * limit, 4), shell(500, 10, 1e6, 5),
                          np.eye(3) * limit * (1 + 1e-5), -np.eye(3) * 1e3])
    d = s.distance(far)
    expected = np.linalg.norm(far, axis=1) - radius
    error = np.abs(d - expected) / np.linalg.norm(far, axis=1)
    assert error.max() <= 8 * ULP[precision], f"not |p| - R: relative error {error.max():.3g}"
    # within the margin (and inside the sphere), the fractal's own estimate
    near = shell(3000, radius * 0.5, limit * (1 - 1e-5), 6)
    d = s.distance(near)
    expected = reference_de(name, near, **kwargs)
    assert p99(d, expected) < tolerance(name, precision)
    sphere = np.linalg.norm(near, axis=1) - radius
    differs = np.abs(expected - sphere) > 1e-2 * np.maximum(np.abs(sphere), 1e-3)
    assert differs.mean() > 0.5, "the DE looks like the bounding sphere's distance in the margin"


TRANSFORM_CASES = [
    # (text after the fractal, point -> local point, distance scale)
    (".translate((1, -2, 0.5))", lambda p: p - (1, -2, 0.5), 1.0),
    (".rotate((1, 2, 3), 40)", lambda p: rotated_back(p, (1, 2, 3), 40), 1.0),
    (".scale(0.25)", lambda p: p / 0.25, 0.25),
    (".scale(3).translate((4, 0, -1))", lambda p: (p - (4, 0, -1)) / 3, 3.0),
    (".rotate((0, 0, 1), 90).scale(0.5).translate((0, 1, 0))",
     lambda p: rotated_back((p - (0, 1, 0)) / 0.5, (0, 0, 1), 90), 0.5),
]


@pytest.mark.opencl
@pytest.mark.parametrize("name", ["mandelbulb", "mandelbox"])
@pytest.mark.parametrize("transform, local, factor", TRANSFORM_CASES, ids=[c[0] for c in TRANSFORM_CASES])
def test_the_bound_moves_and_scales_with_the_shape(name, transform, local, factor):
    s = scene(f"scene {name}(){transform}")
    radius = bound_radius(name)
    # far points (in the local frame, beyond the margin): factor * (|p_local| - R)
    local_far = shell(2000, (1 + MARGIN) * radius * (1 + 1e-4), 20 * radius, 8)
    world_far = _to_world(local, local_far)
    d = s.distance(world_far)
    expected = factor * (np.linalg.norm(local(world_far), axis=1) - radius)
    assert np.allclose(d, expected, rtol=1e-5, atol=1e-5 * factor * radius)
    # near points: factor * DE(p_local), the fractal where the shape is
    local_near = ball(3000, radius, 9)
    world_near = _to_world(local, local_near)
    d = s.distance(world_near)
    assert p99(d / factor, reference_de(name, local(world_near))) < tolerance(name, "float")


def _to_world(local, points):
    """Invert the affine map `local` (row vectors: local(p) = p M + b)."""
    b = local(np.zeros((1, 3)))
    return (points - b) @ np.linalg.inv(local(np.eye(3)) - b)


@pytest.mark.opencl
def test_a_scale_param_moves_the_bound_without_rebuilding():
    s = scene("param k = 2 in [0.1, 10]\nscene mandelbulb().scale(k).translate((1, 0, 0))")
    s.set_params({"k": 2})
    s.distance(np.zeros((1, 3)))
    before = builds()
    radius = bound_radius("mandelbulb")
    for k in (2.0, 0.3, 7.0):
        s.set_params({"k": k})
        points = np.array([(1, 0, 0)]) + shell(500, (1 + MARGIN) * radius * k * 1.001, 30 * k, 10)
        expected = k * (np.linalg.norm((points - (1, 0, 0)) / k, axis=1) - radius)
        assert np.allclose(s.distance(points), expected, rtol=1e-5, atol=1e-6 * k)
    assert builds() == before


def _function_body(source, signature):
    start = source.index(signature)
    depth, i = 0, source.index("{", start)
    for j in range(i, len(source)):
        depth += {"{": 1, "}": -1}.get(source[j], 0)
        if depth == 0:
            return source[i + 1:j]
    raise AssertionError("unbalanced braces")


# the margin R * MARGIN, or R itself where MARGIN is 1 (folded)
# (R: a temporary, or a derived param computed once per launch)
_RADIUS = r"(\w+|params\[\d+\])"
_MARGIN = _RADIUS if MARGIN == 1 else rf"\({_RADIUS} \* {MARGIN}f?\)"
BOUND_TEST = re.compile(rf"^\((\w+) < {_MARGIN}\)$")
BOUND_IF = re.compile(r"^(\s*)if \(ANY\((\w+)\)\) \{")


def _check_bounded_structure(source, names):
    """Each fractal's loop sits in an `if (ANY(m))` block, m = (b < R *
    MARGIN), b = sd_sphere(point, R) and R = <name>_bound_radius(...),
    assigned before (or a derived param that the derived_params kernel
    computes so), and the block ends by selecting the fractal's value
    where m holds."""
    body = _function_body(source, "real distance_estimate(")
    lines = body.splitlines()
    assigned = {}
    for line in lines:
        m = re.match(r"\s*(?:real|mask) (\w+) = (.*);$", line)
        if m:
            assigned[m.group(1)] = m.group(2)
    derived = _function_body(source, "__kernel void derived_params(")
    computed = dict(re.findall(r"scalar (\w+) = uniform_(.*);", derived))
    for slot, value in re.findall(r"(params\[\d+\]) = \(scalar\)(\w+);", derived):
        assigned[slot] = computed.get(value, value)
    found = []
    for n, line in enumerate(lines):
        if not re.match(r"\s*for \(int ", line):
            continue
        # the innermost enclosing if: the nearest line above with less indentation
        indent = len(line) - len(line.lstrip())
        header = next(lines[k] for k in range(n - 1, -1, -1)
                      if len(lines[k]) - len(lines[k].lstrip()) < indent)
        m = BOUND_IF.match(header)
        assert m, f"a fractal's loop is not inside an `if (ANY(...))` block:\n{body}"
        near = m.group(2)
        test = BOUND_TEST.match(assigned[near])
        assert test, assigned[near]
        bound_var, radius_var = test.group(1), test.group(2)
        bound_text = assigned[bound_var]
        assert re.fullmatch(rf"sd_sphere\(.*, (\(real\))?{re.escape(radius_var)}\)", bound_text), bound_text
        name = re.match(r"(\w+)_bound_radius\(", assigned[radius_var]).group(1)
        found.append(name)
        value = next(v for v, text in assigned.items() if text == bound_var)   # the block's result
        assert re.search(rf"{value} = SELECT\({value}, .*, {near}\);", body), body
    assert sorted(found) == sorted(names), f"fractal loops {found}, expected {names}"


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("name", FRACTALS)
def test_the_fractal_is_evaluated_only_inside_the_bound_block(name, precision):
    # the estimate of the distance program (Scene.distance samples any
    # point); a render whose march keeps to the bound needs no block
    # (test_a_render_marching_within_the_bound_takes_the_fractal_s_own_estimate)
    checked = scene(f"scene {name}()", precision).checked
    _check_bounded_structure(emit_distance(lower(checked), Target(double=precision == "double")), [name])


@pytest.mark.opencl
def test_a_render_marching_within_the_bound_takes_the_fractal_s_own_estimate(monkeypatch):
    """A scene that is one fractal, bounded by the scene's sphere: its
    render marches within that sphere (camera rays, shadow rays, normals and
    occlusion near a surface), where the bound block's far side is never
    taken, so the render program's estimate is the fractal's own: the same
    image, bit for bit, as with the block. Where the march leaves the
    sphere (glow), or the sphere is not the scene's whole bound (a ground
    plane), the block stays."""
    text = ("scene mandelbulb()\ncamera { position: (0, -2.8, 1), target: (0, 0, 0), fov: 40 }\n"
            "light directional { direction: (-0.5, 0.4, -1), shadows: hard }\n"
            "render { width: 64, height: 48, ao: 0.7 }\n")
    marched = scene(text)
    assert "sd_sphere(" not in _function_body(marched.kernel_source(), "real distance_estimate(")
    for other in (text.replace("ao: 0.7", "ao: 0.7, glow: { strength: 0.5, radius: 0.1 }"),
                  text.replace("scene mandelbulb()", "scene mandelbulb() | plane(offset: -1.5)")):
        assert "sd_sphere(" in _function_body(scene(other).kernel_source(), "real distance_estimate(")
    image = marched.render()
    monkeypatch.setattr(emit_module, "marched_distance", lambda scene_ir, bound_marched: scene_ir.distance)
    blocked = fractalc.loads(text + "# with the bound block\n")
    assert "sd_sphere(" in _function_body(blocked.kernel_source(), "real distance_estimate(")
    with_block = blocked.render()
    assert 0.2 < np.isfinite(image.depth).mean() < 0.8
    np.testing.assert_array_equal(image.rgba, with_block.rgba)
    np.testing.assert_array_equal(image.depth, with_block.depth)


@pytest.mark.opencl
def test_each_fractal_of_a_scene_gets_its_own_bound_block():
    text = ("param k = 1 in [0.5, 2]\n"
            "scene union(mandelbulb().scale(k), menger(2).translate((3, 0, 0)), julia().rotate((0, 0, 1), 30))")
    _check_bounded_structure(scene(text).kernel_source(), ["mandelbulb", "menger", "julia"])


@pytest.mark.opencl
@pytest.mark.parametrize("name, level", [("menger", 2), ("menger", 3), ("sierpinski", 2), ("sierpinski", 4)])
def test_bounded_estimate_never_exceeds_the_exact_distance(name, level):
    # Where the reference is a valid bound (the exact solids): neither the
    # bounding sphere nor the DE overestimates, near or far.
    s = _param_scene_for(name, dict(level=level), "double")
    rng = np.random.default_rng(13)
    points = np.concatenate([rng.uniform(-1.5, 1.5, (1500, 3)), shell(500, 1.9, 50, 14),
                             shell(50, 1e3, 1e5, 15)])
    truth = getattr(ref, f"{name}_distance")(points, level)
    d = s.distance(points)
    excess = (d - truth).max()
    far = np.linalg.norm(points, axis=1) > (1 + MARGIN) * SQRT3
    print(f"\nFIGURE bounded {name}({level}) vs exact: max excess {excess:.3g}; "
          f"far: mean d / truth {np.mean(d[far] / truth[far]):.3f}")
    assert excess <= 1e-12


# ---------------------------------------------------------------- 4. depth maps

TRACE = dict(epsilon=1e-3, max_steps=200)
CAMERAS = {
    "mandelbulb": dict(position=(0.0, -2.6, 1.2), fov=40, max_distance=10),
    "julia": dict(position=(0.4, -2.8, 1.0), fov=40, max_distance=10),
    "mandelbox": dict(position=(13.0, -19.0, 10.0), fov=40, max_distance=50),
    "menger": dict(position=(2.6, -3.4, 2.2), fov=40, max_distance=12),
    "sierpinski": dict(position=(1.8, -3.0, 1.3), fov=40, max_distance=12),
}
W, H = 64, 48


def primary_rays(position, target=(0, 0, 0), up=(0, 0, 1), fov=40, width=W, height=H):
    """LANGUAGE.md's camera model: origin and unit directions (H, W, 3)."""
    position = np.asarray(position, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    up_ = np.cross(right, forward)
    tan_half = np.tan(np.radians(fov) / 2)
    x = (2 * (np.arange(width) + 0.5) / width - 1) * (width / height) * tan_half
    y = (1 - 2 * (np.arange(height) + 0.5) / height) * tan_half
    dirs = forward + x[None, :, None] * right + y[:, None, None] * up_
    return position, dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)


def sphere_trace(de, origin, dirs, epsilon, max_steps, max_distance):
    """Sphere tracing as LANGUAGE.md's "Marching": a hit where the DE is below
    epsilon (a number, or a function of t) or <= 0, a miss past max_distance
    or after max_steps. Returns the ray distance of the hits (+inf on
    misses) and the steps taken."""
    shape = dirs.shape[:-1]
    dirs = dirs.reshape(-1, 3)
    t = np.zeros(len(dirs))
    steps = np.zeros(len(dirs))
    hit = np.zeros(len(dirs), dtype=bool)
    active = np.ones(len(dirs), dtype=bool)
    for _ in range(max_steps):
        index = np.flatnonzero(active)
        if not len(index):
            break
        d = de(origin + dirs[index] * t[index, None])
        steps[index] += 1
        close = (d < (epsilon(t[index]) if callable(epsilon) else epsilon)) | (d <= 0)
        hit[index[close]] = True
        active[index[close]] = False
        go = index[~close]
        t[go] += d[~close]
        active[go] = t[go] < max_distance
    return np.where(hit, t, np.inf).reshape(shape), steps.reshape(shape)


def camera_scene(body, camera, precision="float", extra=""):
    position = ", ".join(repr(float(c)) for c in camera["position"])
    return (f"{body}\ncamera {{ position: ({position}), target: (0, 0, 0), up: (0, 0, 1), fov: {camera['fov']} }}\n"
            f"render {{ epsilon: {TRACE['epsilon']}, max_steps: {TRACE['max_steps']}, "
            f"max_distance: {camera['max_distance']}, dither: 0{extra} }}")


@lru_cache(maxsize=None)
def reference_depth(name):
    camera = CAMERAS[name]
    origin, dirs = primary_rays(camera["position"], fov=camera["fov"])
    return sphere_trace(lambda p: bounded_reference_de(name, p), origin, dirs,
                        TRACE["epsilon"], TRACE["max_steps"], camera["max_distance"])


@pytest.mark.opencl
@pytest.mark.parametrize("name", FRACTALS)
def test_depth_map_matches_a_numpy_sphere_tracer(name, driver):
    image = scene(camera_scene(f"scene {name}()", CAMERAS[name]), device=driver).render(width=W, height=H)
    expected, _ = reference_depth(name)
    hit, expected_hit = np.isfinite(image.depth), np.isfinite(expected)
    agreement = np.mean(hit == expected_hit)
    both = hit & expected_hit
    difference = np.abs(image.depth[both] - expected[both])
    print(f"\nFIGURE depth {name}: {expected_hit.mean():.1%} hits, hit/miss agreement {agreement:.2%} "
          f"({np.sum(hit != expected_hit)} of {hit.size} pixels differ); |dZ| on common hits: "
          f"median {np.median(difference):.2g}, p99 {np.percentile(difference, 99):.2g}, "
          f"max {difference.max():.2g}")
    assert 0.1 < expected_hit.mean() < 0.9, "the camera should see the fractal and the background"
    assert agreement >= 0.99
    # both stop within epsilon of the surface, on the same side of it
    # (measured: medians 0.12-0.52 epsilon, 99th percentiles 0.9-1.7, on
    # PoCL and Intel's runtime; where a march stops is no test of an
    # estimate's last digits: the distance tests above are)
    assert np.median(difference) < TRACE["epsilon"]
    assert np.percentile(difference, 99) < 3.5 * TRACE["epsilon"]


# ---------------------------------------------------------------- 5. orbit traps

AMBIENT = 0.25      # emit.AMBIENT: with one light of intensity 0, colour = AMBIENT * albedo
DARK = "light directional { direction: (0, 0, -1), intensity: 0, shadows: none }"
NEAR, FAR = np.array([1.0, 0.8, 0.2]), np.array([0.1, 0.3, 0.9])
TRAP_CAMERA = CAMERAS["mandelbulb"]


def trap_scene(shape, trap="origin", colours="params", scale="ts", precision="float"):
    if colours == "params":
        params = "\n".join(f"param {p}{c} = {float(v)!r} in [0, 1]" for p, values in (("n", NEAR), ("f", FAR))
                           for c, v in zip("rgb", values))
        near, far = "(nr, ng, nb)", "(fr, fg, fb)"
    else:
        params, (near, far) = "", colours
    text = (f"{params}\nparam ts = 1.5 in [0.01, 100]\n"
            f"scene {shape}.color(orbit_trap(near: {near}, far: {far}, trap: {trap}, scale: {scale}))\n{DARK}")
    return scene(camera_scene(text, TRAP_CAMERA, extra=", background: (0, 0, 0)"), precision)


def _colour_params(near, far):
    return {**{f"n{c}": v for c, v in zip("rgb", near)}, **{f"f{c}": v for c, v in zip("rgb", far)}}


def _albedo(image):
    hit = np.isfinite(image.depth)
    return hit, image.rgba[..., :3][hit].astype(np.float64) / AMBIENT


def mandelbulb_trap(points, kind, power=8.0, iterations=12, bailout=2.0):
    """The orbit trap of the reference iteration: the smallest distance of
    the iterates z_1, z_2, ... (each z computed from a |z| <= bailout) to the
    origin / the planes x, y, z = 0 / the nearest plane."""
    z = np.asarray(points, dtype=np.float64).copy()
    p = z.copy()
    trap = np.full((len(z), 4), np.inf)
    active = np.ones(len(z), dtype=bool)
    for _ in range(iterations):
        r = np.linalg.norm(z, axis=1)
        active &= r <= bailout
        if not active.any():
            break
        za, ra = z[active], r[active]
        theta = np.arccos(np.clip(np.where(ra > 0, za[:, 2] / np.where(ra > 0, ra, 1), 1), -1, 1)) * power
        phi = np.arctan2(za[:, 1], za[:, 0]) * power
        z[active] = ra[:, None] ** power * np.stack(
            [np.sin(theta) * np.cos(phi), np.sin(phi) * np.sin(theta), np.cos(theta)], axis=1) + p[active]
        values = np.concatenate([np.linalg.norm(z[active], axis=1)[:, None], np.abs(z[active])], axis=1)
        trap[active] = np.minimum(trap[active], values)
    if kind == "planes":
        return trap[:, 1:].min(axis=1)
    return trap[:, ("origin", "x", "y", "z").index(kind)]


@pytest.mark.opencl
def test_orbit_trap_colour_lies_between_near_and_far_and_follows_the_trap():
    s = trap_scene("mandelbulb()")
    s.set_params({**_colour_params(NEAR, FAR), "ts": 0.8})    # origin traps are 0.6 .. 1.1 here
    image = s.render(width=W, height=H)
    hit, albedo = _albedo(image)
    assert hit.mean() > 0.1
    low, high = np.minimum(NEAR, FAR), np.maximum(NEAR, FAR)
    assert ((albedo >= low - 1e-5) & (albedo <= high + 1e-5)).all()
    # one mix weight t for the three channels: mix(near, far, t)
    t = (albedo - NEAR) / (FAR - NEAR)
    assert np.abs(t - t.mean(axis=1, keepdims=True)).max() < 1e-4
    t = t.mean(axis=1)
    assert t.std() > 0.05, "the colour does not vary over the fractal"
    # t = clamp(trap * scale, 0, 1), the trap of the orbit at the hit point
    origin, dirs = primary_rays(TRAP_CAMERA["position"], fov=TRAP_CAMERA["fov"])
    points = origin + dirs[hit] * image.depth[hit][:, None]
    expected = np.clip(mandelbulb_trap(points, "origin") * 0.8, 0, 1)
    difference = np.abs(t - expected)
    print(f"\nFIGURE orbit trap: mix weight vs numpy trap at the hit points: median {np.median(difference):.2g}, "
          f"p90 {np.percentile(difference, 90):.2g}")
    assert np.median(difference) < 1e-2 and np.percentile(difference, 90) < 0.1


@pytest.mark.opencl
def test_orbit_trap_defaults_spread_the_colour_over_the_fractal():
    # trap and scale left to their defaults: the nearest plane's distance,
    # t = 1 + ln(trap) / 5 (lower.TRAP_DECADES). The default was once the
    # origin trap at scale 1: t = 1 (all `far`) on every Mandelbulb and
    # Mandelbox pixel.
    weights = {}
    for name in ("mandelbulb", "mandelbox"):
        camera = CAMERAS[name]
        near, far = (f"({', '.join(map(str, colour))})" for colour in (NEAR, FAR))
        text = camera_scene(f"scene {name}().color(orbit_trap(near: {near}, far: {far}))\n{DARK}",
                            camera, extra=", background: (0, 0, 0)")
        image = scene(text).render(width=W, height=H)
        hit, albedo = _albedo(image)
        weights[name] = ((albedo - NEAR) / (FAR - NEAR)).mean(axis=1)
        assert hit.mean() > 0.1
        low, high = np.percentile(weights[name], [5, 95])
        assert high - low > 0.5, (name, low, high)
        if name == "mandelbulb":
            origin, dirs = primary_rays(camera["position"], fov=camera["fov"])
            points = origin + dirs[hit] * image.depth[hit][:, None]
            expected = np.clip(1 + np.log(mandelbulb_trap(points, "planes")) / 5, 0, 1)
            difference = np.abs(weights[name] - expected)
            assert np.median(difference) < 1e-2 and np.percentile(difference, 90) < 0.1


@pytest.mark.opencl
def test_orbit_trap_colours_and_scale_change_the_image_as_predicted_without_rebuilding():
    s = trap_scene("mandelbulb()")
    s.set_params({**_colour_params(NEAR, FAR), "ts": 0.8})
    first = s.render(width=W, height=H)
    before = builds()
    s.set_params(_colour_params(FAR, NEAR))          # swapped: mix(far, near, t) = near + far - mix(near, far, t)
    swapped = s.render(width=W, height=H)
    hit, a = _albedo(first)
    _, b = _albedo(swapped)
    assert np.array_equal(first.depth, swapped.depth)
    assert np.abs(a + b - (NEAR + FAR)).max() < 1e-5
    s.set_params({**_colour_params(NEAR, FAR), "ts": 100.0})   # trap * 100 >= 1 almost everywhere: far
    _, c = _albedo(s.render(width=W, height=H))
    assert np.mean(np.abs(c - FAR).max(axis=1) < 1e-5) > 0.9
    s.set_params({**_colour_params(NEAR, FAR), "ts": 0.01})    # trap * 0.01 ~ 0: near
    _, c = _albedo(s.render(width=W, height=H))
    assert np.abs(c - NEAR).max() < 0.05
    assert builds() == before


@pytest.mark.opencl
def test_trap_kinds_give_different_images():
    # in double: each kind is its own kernel, and a float build on Intel's
    # runtime (-cl-unsafe-math-optimizations) may round the orbit apart in
    # two of them, which the orbit at the set's edge magnifies past 1e-4
    renders = {}
    for kind in ("origin", "x", "y", "z", "planes"):
        s = trap_scene("mandelbulb()", trap=kind, precision="double")
        s.set_params({**_colour_params(NEAR, FAR), "ts": 1.5})
        renders[kind] = s.render(width=32, height=24)
    images = {k: r.rgba for k, r in renders.items()}
    kinds = list(images)
    for i, a in enumerate(kinds):
        for b in kinds[i + 1:]:
            assert np.abs(images[a] - images[b]).max() > 0.02, f"trap {a} and {b} give the same image"
    # the nearest plane is never farther than each plane: weight (and colour, near -> far) below each
    hit = np.isfinite(renders["planes"].depth)
    weight = {k: ((images[k][..., 0] / AMBIENT - NEAR[0]) / (FAR[0] - NEAR[0]))[hit] for k in kinds}
    for axis in "xyz":
        assert (weight["planes"] <= weight[axis] + 1e-4).all()


@pytest.mark.opencl
def test_orbit_trap_on_a_shape_without_an_orbit_uses_near():
    s = trap_scene("sphere(0.8)", colours=("(0.9, 0.3, 0.1)", "(0.1, 0.2, 0.7)"), scale="3")
    hit, albedo = _albedo(s.render(width=32, height=24))
    assert hit.mean() > 0.1
    assert np.allclose(albedo, (0.9, 0.3, 0.1), atol=1e-5)
    points = ball(100, 2.0, 16)
    assert np.allclose(s.distance(points), np.linalg.norm(points, axis=1) - 0.8, atol=1e-5)


def _position(text, snippet):
    """1-based (line, column) of `snippet` in `text`."""
    offset = text.index(snippet)
    line = text.count("\n", 0, offset) + 1
    return line, offset - (text.rfind("\n", 0, offset) + 1) + 1


@pytest.mark.parametrize("argument, snippet", [
    ("trap: diagonal", "diagonal"), ("trap: corner", "corner"), ("trap: 2", "2"),
    ("scale: 0", "0"), ("scale: -1.5", "-1.5")])
def test_bad_orbit_trap_arguments_are_check_errors_at_the_value(argument, snippet):
    prefix = "let bulb = mandelbulb(power: 6)\nscene bulb.color(orbit_trap(near: (1, 1, 1), "
    text = prefix + argument + "))\n"
    with pytest.raises(fractalc.SceneError) as error:
        fractalc.loads(text)
    line, column = _position(text, argument)
    assert (error.value.line, error.value.column) == (line, column + len(argument) - len(snippet))
    assert "trap" in error.value.message or "scale" in error.value.message


def test_orbit_trap_scale_param_must_stay_positive():
    text = "param s = 1 in [-1, 1]\nscene mandelbulb().color(orbit_trap(scale: s))"
    s = fractalc.loads(text)
    for bad in (0.0, -0.5):
        with pytest.raises(fractalc.SceneError) as error:
            s.set_params({"s": bad})
        assert (error.value.line, error.value.column) == _position(text, "s))")
        with pytest.raises(fractalc.SceneError):
            fractalc.loads(text, params={"s": bad})


# ---------------------------------------------------------------- 6. precision

F_LITERAL = re.compile(r"(?<![\w.])(\d+\.\d*|\.\d+|\d+(?=[eE]))([eE][+-]?\d+)?[fF]\b")


@pytest.mark.opencl
@pytest.mark.parametrize("name", FRACTALS)
def test_double_kernel_has_no_float_literals(name):
    text = f"param k = 1 in [0.5, 2]\nscene {name}().scale(k).color(orbit_trap())"
    source = fractalc.loads(text, precision="double").kernel_source()
    assert F_LITERAL.findall(source) == []
    assert "#define PRECISION_DOUBLE 1" in source
    assert F_LITERAL.findall(fractalc.loads(text).kernel_source()), "the float kernel has f literals"
    source = fractalc.loads(text + "\nrender { precision: double }").kernel_source()
    assert F_LITERAL.findall(source) == []


@pytest.fixture
def no_double(monkeypatch):
    """The chosen device, claiming not to support double precision."""
    device = fractalc.loads("scene sphere()").device
    monkeypatch.setattr(device, "info", dataclasses.replace(device.info, double=False))
    return device


@pytest.mark.opencl
@pytest.mark.parametrize("how", ["loads", "render block"])
def test_double_on_a_device_without_double_is_a_clear_render_error(no_double, how):
    if how == "loads":
        s = fractalc.loads("scene mandelbulb()", precision="double")
    else:
        s = fractalc.loads("scene mandelbulb()\nrender { precision: double }")
    for action in (lambda: s.distance(np.zeros((4, 3))), lambda: s.render(width=8, height=6)):
        with pytest.raises(fractalc.RenderError) as error:
            action()
        assert "double" in str(error.value) and no_double.info.name in str(error.value)
    # float still works there, and an explicit lane count needs no device
    assert np.isfinite(fractalc.loads("scene mandelbulb()").distance(np.zeros((4, 3)))).all()
    assert "PRECISION_DOUBLE 1" in s.kernel_source(lanes=8)


# ---------------------------------------------------------------- bugs found

@pytest.mark.opencl
def test_an_empty_julia_slice_renders_nothing():
    # |slice| >= R: the slice misses the set (julia.cl: the DE is > 0
    # everywhere) and julia_bound_radius is 0. The bounding sphere of radius
    # 0 then has distance |p|, 0 at the origin: rays passing within the hit
    # threshold of the origin hit a point that is not in the set.
    assert bound_radius("julia", slice=3.0) == 0
    text = "scene julia(slice: 3)\ncamera { position: (0, -3, 0), target: (0, 0, 0) }"
    s = scene(text)
    assert reference_de("julia", np.zeros((1, 3)), slice=3.0)[0] > 0.1
    assert s.distance(np.zeros((1, 3)))[0] > 0, "the scene's distance at the origin is 0"
    image = s.render(width=64, height=48)
    assert not np.isfinite(image.depth).any(), f"{np.isfinite(image.depth).sum()} pixels hit an empty set"


def test_mandelbox_radius_order_is_checked_for_param_values():
    # LANGUAGE.md "Valid values": 0 < min_radius <= fixed_radius, a check
    # error at the value's span; params are checked whenever they change.
    text = "param mr = 0.5 in [0.1, 2]\nscene mandelbox(min_radius: mr)"
    s = fractalc.loads(text)
    with pytest.raises(fractalc.SceneError) as error:
        s.set_params({"mr": 1.5})
    assert (error.value.line, error.value.column) == _position(text, "mr)")
    text = "param fr = 1 in [0.1, 2]\nscene mandelbox(min_radius: 0.8, fixed_radius: fr)"
    with pytest.raises(fractalc.SceneError):
        fractalc.loads(text, params={"fr": 0.5})


@pytest.mark.opencl
def test_the_bounding_sphere_never_shows_in_the_image():
    # Beyond 1.1 R the scene's distance is the bounding sphere's, |p| - R, and
    # nothing stops that value from falling below the hit threshold when the
    # threshold exceeds the margin 0.1 R: with `epsilon: pixel`, for a fractal
    # a few tens of pixels across. Rays then hit the bounding sphere (a
    # speckled ring around the fractal) where the fractal's own estimate is
    # far above the threshold. menger(1), a cube 4 pixels wide at 30 units:
    # the kernel's hits against a numpy tracer of the unbounded estimate
    # (the threshold of `epsilon: pixel` is max(t * pixel angle, 1e-6)).
    position, fov = (0.3, -30.0, 0.2), 40
    text = (f"scene menger(1)\ncamera {{ position: {position}, target: (0, 0, 0), fov: {fov} }}\n"
            "render { dither: 0, max_distance: 100 }")
    image = scene(text).render(width=W, height=H)
    origin, dirs = primary_rays(position, fov=fov)
    pixel_angle = 2 * np.tan(np.radians(fov) / 2) / H
    expected, _ = sphere_trace(lambda p: menger_de(p, 1), origin, dirs,
                               lambda t: np.maximum(t * pixel_angle, 1e-6), 256, 100)
    hit, expected_hit = np.isfinite(image.depth), np.isfinite(expected)
    assert expected_hit.sum() > 10
    extra = hit & ~expected_hit
    assert extra.sum() <= 2, (f"{extra.sum()} pixels hit the bounding sphere ({hit.sum()} hits, "
                              f"{expected_hit.sum()} from the fractal's estimate)")
