"""The fractal distance estimators (the IR loops of `fractalc/fractals.py`,
emitted on their own, with every argument a kernel param) and their bound
radii (`stdlib_cl/fractals/`), against the float64 numpy reference in
`reference_fractals.py`: accuracy, lower bounds for the exact solids,
finiteness in the hard cases, and the bound radii."""

from functools import lru_cache

import numpy as np
import pytest

import reference_fractals as ref
from fractalc import ir
from fractalc.emit import _library_text, double_literals, function_source
from fractalc.fractals import orbit
from fractalc.stdlib import library

pytestmark = pytest.mark.opencl

LANES = (1, 8)
PRECISIONS = ("float", "double")
# The 99th percentile of the relative error a fractal's estimate may have:
# in float, three times the largest measured over its cases here and in
# test_fractals.py, with pip's PoCL and with Intel's CPU runtime
# (mandelbulb 1.9e-4: power 16 with 8 lanes on Intel, 1.2e-4 on PoCL;
# mandelbox 1.7e-4; menger 3.0e-5; julia 1.9e-5; sierpinski 2.1e-6), so
# that an estimate 0.08% off (0.5004 for the Mandelbulb's 0.5) fails; in
# double 1e-9 (measured at most 5.5e-13).
FLOAT_TOLERANCE = {"mandelbulb": 6e-4, "mandelbox": 6e-4, "menger": 1e-4, "julia": 6e-5, "sierpinski": 1e-5}
DOUBLE_TOLERANCE = 1e-9
FLOOR = 1e-3                                   # relative to max(|reference|, FLOOR)
SLACK = {"float": 1e-5, "double": 1e-12}       # lower bounds may exceed the truth by this

_KERNELS = """
__kernel VECTOR_LANES_HINT void evaluate(__global const scalar *x, __global const scalar *y, __global const scalar *z,
                       __constant scalar *params, __global scalar *out) {{
    int i = get_global_id(0);
    vec3 p = v3(LOAD_LANES(i, x), LOAD_LANES(i, y), LOAD_LANES(i, z));
    STORE_LANES(fractal_distance(p, params), i, out);
}}

__kernel void bound(__constant scalar *params, __global scalar *out) {{
    real r = {name}_bound_radius({bound_args});
    STORE_LANES(r, 0, out);
}}
"""


# ---------------------------------------------------------------- the harness

def _arguments(name):
    """The fractal's arguments as IR params, one per number (vec4 as four),
    in the order `_c_arguments` lists their values."""
    args, index = [], 0
    for parameter in library().signatures[name].parameters:
        width = 4 if parameter.type == "vec4" else 1
        params = [ir.Param(index + k, f"{parameter.name}{k}") for k in range(width)]
        args.append(ir.Vec(tuple(params)) if width == 4 else params[0])
        index += width
    return tuple(args)


@lru_cache(maxsize=None)
def _program(name, lanes, precision):
    """The built program of NAME's DE (emitted from its IR) and its bound,
    with kernels `evaluate` (the DE at points) and `bound` (the radius)."""
    import pyopencl as cl
    from fractalc.devices import open_device
    lib = library()
    args = _arguments(name)
    point = ir.components(ir.Var("p", ir.VEC3))
    distance = function_source(orbit(name, point, args).distance,
                               "real fractal_distance(vec3 p, __constant scalar *params)")
    bound = f"{name}_bound_radius"
    bound_args = [f"(int)params[{k}]" if t == "int" else f"(real)params[{k}]"
                  for k, t in enumerate(lib.functions[bound].parameter_types)]
    kernels = _KERNELS.format(name=name, bound_args=", ".join(bound_args))
    source = "\n".join([f"#define LANES {lanes}", f"#define PRECISION_DOUBLE {int(precision == 'double')}",
                        "#define FAST_MATH 0", lib.prelude, _library_text(lib.closure([bound])), distance, kernels])
    if precision == "double":
        source = double_literals(source)
    device = open_device()
    try:
        program = cl.Program(device.context, source).build()
    except cl.RuntimeError as error:   # keep the build log in the failure
        raise AssertionError(f"{name} does not build ({lanes} lanes, {precision}):\n{error}") from None
    return device, cl.Kernel(program, "evaluate"), cl.Kernel(program, "bound")


def _c_arguments(name, kwargs):
    """The C argument values (vec4 as four) from language-level keyword
    arguments, the signature's defaults for the others."""
    values = []
    for parameter in library().signatures[name].parameters:
        value = kwargs.pop(parameter.name, parameter.default)
        values.extend(value if parameter.type == "vec4" else [value])
    assert not kwargs, f"unknown arguments {kwargs}"
    return values


def _params(device, values, dtype):
    import pyopencl as cl
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    return cl.Buffer(device.context, flags, hostbuf=np.asarray(values, dtype=dtype))


def evaluate(name, points, lanes=1, precision="float", **kwargs):
    """The DE of fractal NAME at `points` (N, 3), as float64."""
    import pyopencl as cl
    device, kernel, _ = _program(name, lanes, precision)
    dtype = np.float64 if precision == "double" else np.float32
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    count = -(-len(points) // lanes) * lanes
    padded = np.zeros((count, 3), dtype=dtype)
    padded[:len(points)] = points
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    xyz = [cl.Buffer(device.context, flags, hostbuf=np.ascontiguousarray(padded[:, i])) for i in range(3)]
    out = np.empty(count, dtype=dtype)
    out_buffer = cl.Buffer(device.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    params = _params(device, _c_arguments(name, dict(kwargs)), dtype)
    kernel(device.queue, (count // lanes,), None, *xyz, params, out_buffer)
    cl.enqueue_copy(device.queue, out, out_buffer)
    return out[:len(points)].astype(np.float64)


def bound_radius(name, lanes=1, precision="float", **kwargs):
    import pyopencl as cl
    device, _, kernel = _program(name, lanes, precision)
    dtype = np.float64 if precision == "double" else np.float32
    out = np.empty(lanes, dtype=dtype)
    out_buffer = cl.Buffer(device.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    params = _params(device, _c_arguments(name, dict(kwargs)), dtype)
    kernel(device.queue, (1,), None, params, out_buffer)
    cl.enqueue_copy(device.queue, out, out_buffer)
    return float(out[0])


def tolerance(name: str, precision: str) -> float:
    return FLOAT_TOLERANCE[name] if precision == "float" else DOUBLE_TOLERANCE


def ball(count, radius, seed=20240607):
    """`count` seeded points uniform in the ball of `radius`."""
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return directions * radius * rng.uniform(0, 1, (count, 1)) ** (1 / 3)


def shell(count, inner, outer, seed=7):
    """`count` seeded points with inner < |p| <= outer, random directions."""
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return directions * rng.uniform(inner, outer, (count, 1))


def relative_error(d, expected):
    return np.abs(d - expected) / np.maximum(np.abs(expected), FLOOR)


def both():
    """Parametrise a test over lanes and precisions."""
    return pytest.mark.parametrize("lanes, precision", [(n, p) for n in LANES for p in PRECISIONS])


# ---------------------------------------------------------------- escape-time fractals vs the reference

ESCAPE_TIME = [
    ("mandelbulb", {}),
    ("mandelbulb", dict(power=2.0, iterations=8)),
    ("mandelbulb", dict(power=16.0, iterations=20, bailout=4.0)),
    ("mandelbulb", dict(power=5.5, iterations=12, bailout=1e6)),     # past the overflow guard
    ("mandelbulb", dict(power=12.0, iterations=10, bailout=1e6)),
    ("julia", {}),
    ("julia", dict(c=(0.3, -0.5, 0.4, 0.2), slice=0.3, iterations=20, bailout=16.0)),
    ("julia", dict(c=(-0.8, 0.15, 0.0, 0.1), slice=-0.2, iterations=10, bailout=1e8)),  # past it
    ("mandelbox", {}),
    ("mandelbox", dict(scale=-1.5, iterations=16)),
    ("mandelbox", dict(scale=3.0, min_radius=0.3, fixed_radius=1.2, fold_limit=0.8, iterations=8)),
    ("mandelbox", dict(scale=2.0, iterations=40)),                   # renormalised z and dr
]


def _region(name, kwargs):
    """10k points in the bound sphere (a finite one) and a little beyond."""
    radius = bound_radius(name, precision="double", **kwargs)
    return ball(10_000, 1.1 * min(radius, 20.0))


@pytest.mark.parametrize("name, kwargs", ESCAPE_TIME, ids=lambda v: str(v))
@both()
def test_escape_time_fractal_matches_reference(name, kwargs, lanes, precision):
    points = _region(name, kwargs)
    expected = getattr(ref, name)(points, **kwargs)
    d = evaluate(name, points, lanes, precision, **kwargs)
    assert np.isfinite(d).all()
    error = np.percentile(relative_error(d, expected), 99)
    assert error < tolerance(name, precision), f"99th percentile relative error {error:.3g}"


# ---------------------------------------------------------------- exact solids: lower bounds

def _solid_cases():
    return [("menger", level) for level in range(4)] + [("sierpinski", level) for level in range(5)]


def _near_and_far(count=10_000, seed=3):
    """Points near the solids (most within 0.3 of the cube) and some far."""
    rng = np.random.default_rng(seed)
    near = rng.uniform(-1.3, 1.3, (count * 4 // 5, 3))
    return np.concatenate([near, ball(count - len(near), 4.0, seed)])


@lru_cache(maxsize=None)
def _solid_truth(name, level):
    """Sample points and the exact distances to the level-N solid there."""
    points = _near_and_far()
    return points, getattr(ref, f"{name}_distance")(points, level)


@pytest.mark.parametrize("name, level", _solid_cases(), ids=lambda v: str(v))
@both()
def test_solid_estimate_is_a_useful_lower_bound(name, level, lanes, precision):
    points, truth = _solid_truth(name, level)
    d = evaluate(name, points, lanes, precision, level=level)
    assert np.isfinite(d).all()
    excess = d - truth
    assert excess.max() <= SLACK[precision], f"exceeds the true distance by {excess.max():.3g}"
    outside = truth > 1e-3
    assert np.mean(d[outside] / truth[outside]) >= 0.1


def _members(name, level, count=2000, seed=5):
    """Points inside the level-N solid: in random ones of its boxes /
    tetrahedra, each found by a random path down the levels."""
    rng = np.random.default_rng(seed)
    if name == "menger":
        centres, half = np.zeros((count, 3)), 1.0
        for _ in range(level):
            half /= 3
            centres += 2 * half * ref.MENGER_OFFSETS[rng.integers(20, size=count)]
        return centres + rng.uniform(-half, half, (count, 3)) * 0.999
    tetrahedra = np.broadcast_to(ref.TETRAHEDRON, (count, 4, 3))
    for _ in range(level):
        vertex = tetrahedra[np.arange(count), rng.integers(4, size=count)]
        tetrahedra = (tetrahedra + vertex[:, None, :]) / 2
    weights = rng.dirichlet(np.ones(4), size=count)
    return (weights[:, :, None] * tetrahedra).sum(axis=1)


@pytest.mark.parametrize("name, level", [("menger", n) for n in (0, 1, 3, 6, 10)] +
                         [("sierpinski", n) for n in (0, 1, 4, 8, 10)], ids=lambda v: str(v))
@both()
def test_solid_estimate_is_not_positive_inside(name, level, lanes, precision):
    points = _members(name, level)
    if level <= 3:
        assert (getattr(ref, f"{name}_distance")(points, level) == 0).all()
    d = evaluate(name, points, lanes, precision, level=level)
    assert np.isfinite(d).all()
    assert d.max() <= SLACK[precision]


def test_sierpinski_estimate_is_the_exact_distance():
    for level in (0, 2, 4):
        points, truth = _solid_truth("sierpinski", level)
        d = evaluate("sierpinski", points, 8, "double", level=level)
        assert np.allclose(np.maximum(d, 0), truth, rtol=0, atol=1e-12)


# ---------------------------------------------------------------- finite everywhere

HARD_POINTS = np.array(
    [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (0, 0, -1), (-1, 0, 0), (0, 0, 0.5), (0, 0, -0.5),
     (0.3, 0, 0), (0, 0, 1e-30), (1e-30, 0, 0), (1e-20, 1e-20, 1e-20), (2, 0, 0), (0, 0, 2), (0, -2, 0),
     (4, 0, 0), (0, 0, -4), (2 / 3 ** 0.5,) * 3, (1e6, 0, 0), (0, 0, 1e6), (0, 0, -1e6), (-5.8e5, 5.8e5, 5.8e5),
     (1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1), (1, 1, 0), (6, 6, 6), (-6, 0, 6), (1e-6, 0, 0),
     (0.5, 0.5, 0.5), (0.1, -0.2, 0.3)], dtype=np.float64)

HARD = [
    ("mandelbulb", {}), ("mandelbulb", dict(power=2.0)), ("mandelbulb", dict(power=16.0)),
    ("mandelbulb", dict(power=32.0)), ("mandelbulb", dict(power=1.0)),
    ("mandelbulb", dict(iterations=64)), ("mandelbulb", dict(power=32.0, iterations=64)),
    ("mandelbulb", dict(bailout=1e6)), ("mandelbulb", dict(power=32.0, bailout=1e6, iterations=64)),
    ("mandelbulb", dict(power=16.0, bailout=1e30, iterations=1000)),
    ("mandelbulb", dict(bailout=1e-3)),
    ("julia", {}), ("julia", dict(iterations=64)), ("julia", dict(iterations=1000)),
    ("julia", dict(bailout=1e6)), ("julia", dict(bailout=1e30, iterations=1000)),
    ("julia", dict(c=(0, 0, 0, 0))), ("julia", dict(c=(0, 0, 0, 0), iterations=1000)),
    ("julia", dict(slice=1.0)), ("julia", dict(bailout=1e-3)),
    ("mandelbox", {}), ("mandelbox", dict(scale=-1.5)), ("mandelbox", dict(scale=3.0)),
    ("mandelbox", dict(iterations=64)), ("mandelbox", dict(scale=3.0, iterations=1000)),
    ("mandelbox", dict(scale=-1.5, iterations=1000)), ("mandelbox", dict(scale=0.9, iterations=1000)),
    ("mandelbox", dict(scale=0.0)), ("mandelbox", dict(scale=1.0, iterations=1000)),
    ("mandelbox", dict(scale=2.0, min_radius=0.01, fixed_radius=2.0, iterations=1000)),
    ("menger", dict(level=0)), ("menger", dict(level=10)),
    ("sierpinski", dict(level=0)), ("sierpinski", dict(level=10)),
]


@pytest.mark.parametrize("name, kwargs", HARD, ids=lambda v: str(v))
@both()
def test_estimate_is_finite_in_hard_cases(name, kwargs, lanes, precision):
    radius = bound_radius(name, lanes, precision, **kwargs)
    finite_radius = radius if np.isfinite(radius) else 10.0
    points = np.concatenate([HARD_POINTS, ball(500, 1.2 * finite_radius),
                             HARD_POINTS * finite_radius / 2 ** 0.5])
    d = evaluate(name, points, lanes, precision, **kwargs)
    bad = points[~np.isfinite(d)]
    assert len(bad) == 0, f"not finite at {bad[:5]}"


@pytest.mark.parametrize("kwargs", [{}, dict(power=2.0), dict(power=16.0), dict(power=32.0),
                                    dict(iterations=64), dict(bailout=1e6)], ids=str)
@both()
def test_mandelbulb_signs(kwargs, lanes, precision):
    # the origin is a fixed point: r = 0, DE = 0; a point of the set's inner
    # region (its orbit stays small) is <= 0; far points are positive
    inside = np.array([(0, 0, 0), (0, 0, 1e-3), (0.1, 0.1, 0.1)])
    d = evaluate("mandelbulb", inside, lanes, precision, **kwargs)
    assert d[0] == 0 and (d <= 1e-6).all()
    far = evaluate("mandelbulb", [(1e6, 0, 0), (0, 0, -1e6), (3, 3, 3)], lanes, precision, **kwargs)
    assert (far > 0).all()
    assert far[0] == pytest.approx(ref.mandelbulb(np.array([(1e6, 0, 0)]), **kwargs)[0], rel=1e-5)


@both()
def test_julia_signs(lanes, precision):
    # default c: the origin's orbit 0 -> c -> ... stays bounded (|q| < 0.71):
    # the origin is in the set; dr = 0 after the first step: DE = 0 by the
    # contract
    q, c = np.zeros(4), np.array([-0.2, 0.6, 0.2, 0.0])
    for _ in range(1000):
        q = np.concatenate([[q[0] ** 2 - q[1:] @ q[1:]], 2 * q[0] * q[1:]]) + c
        assert np.linalg.norm(q) < 1
    d = evaluate("julia", [(0, 0, 0)], lanes, precision, iterations=1000)
    assert d[0] == 0
    # a point of the filled set (c = 0: the unit ball) is <= 0
    inner = evaluate("julia", [(0.5, 0.1, 0.2)], lanes, precision, c=(0, 0, 0, 0), iterations=64)
    assert inner[0] <= 0


@both()
def test_mandelbox_is_positive_and_small_inside(lanes, precision):
    # DE = |z| / |dr| >= 0; the origin is in the set: tiny after 64 iterations
    d = evaluate("mandelbox", [(0, 0, 0), (0.5, 0.5, 0.5), (1e6, 0, 0)], lanes, precision, iterations=64)
    assert (d >= 0).all() and d[0] < 1e-12 and d[2] > 1e5


# ---------------------------------------------------------------- bound radii

BOUNDED = [
    ("mandelbulb", {}), ("mandelbulb", dict(power=2.0)), ("mandelbulb", dict(power=16.0)),
    ("mandelbulb", dict(power=32.0, iterations=64)), ("mandelbulb", dict(power=1.0)),
    ("mandelbulb", dict(power=3.0, bailout=1e6)), ("mandelbulb", dict(power=1.5, iterations=30)),
    ("julia", {}), ("julia", dict(c=(0, 0, 0, 0))), ("julia", dict(slice=1.2, iterations=64)),
    ("julia", dict(slice=3.0)), ("julia", dict(c=(-1.2, 0.3, 0.2, -0.4), iterations=100)),
    ("mandelbox", {}), ("mandelbox", dict(scale=-1.5)), ("mandelbox", dict(scale=3.0, fold_limit=0.7)),
    ("mandelbox", dict(scale=-2.5, iterations=40)), ("mandelbox", dict(scale=1.2, iterations=30)),
    ("mandelbox", dict(scale=-0.5, iterations=30)),
    ("menger", dict(level=0)), ("menger", dict(level=4)),
    ("sierpinski", dict(level=0)), ("sierpinski", dict(level=6)),
]


@pytest.mark.parametrize("name, kwargs", BOUNDED, ids=lambda v: str(v))
@both()
def test_estimate_is_positive_outside_the_bound(name, kwargs, lanes, precision):
    radius = bound_radius(name, lanes, precision, **kwargs)
    assert radius < np.inf
    radius = max(radius, 0.0)    # -1: an empty julia slice, positive everywhere
    points = np.concatenate([shell(5000, radius * (1 + 1e-6), radius * 1.2),
                             shell(1000, radius * 1.2, radius * 10 + 1),
                             np.eye(3) * radius * (1 + 1e-5), -np.eye(3) * radius * (1 + 1e-5)])
    points = points[np.linalg.norm(points, axis=1) > radius]
    d = evaluate(name, points, lanes, precision, **kwargs)
    assert (d > 0).all(), f"DE <= 0 outside the bound radius {radius} at {points[d <= 0][:3]}"


def test_bound_radius_formulas():
    assert bound_radius("mandelbulb", precision="double") == pytest.approx(2 ** (1 / 7))
    assert bound_radius("mandelbulb", precision="double", power=1.0) == 1.0
    assert bound_radius("julia", precision="double") == pytest.approx(
        (1 + np.sqrt(1 + 4 * np.linalg.norm((-0.2, 0.6, 0.2, 0)))) / 2)
    assert bound_radius("julia", precision="double", slice=5.0) == -1.0   # an empty slice
    assert bound_radius("mandelbox", precision="double") == pytest.approx(6 * np.sqrt(3))
    assert bound_radius("mandelbox", precision="double", scale=-1.5) == pytest.approx(2 * np.sqrt(3))
    assert bound_radius("mandelbox", precision="double", scale=0.5) == np.inf
    assert bound_radius("menger", level=3) == pytest.approx(np.sqrt(3))
    assert bound_radius("sierpinski", level=3) == pytest.approx(np.sqrt(3))


@pytest.mark.parametrize("kwargs, half", [
    (dict(scale=2.0), 6.0), (dict(scale=3.0, fold_limit=0.5), 2.0), (dict(scale=1.5, min_radius=0.2), 10.0),
    (dict(scale=-1.5), 2.0), (dict(scale=-2.0, fold_limit=1.5), 3.0)], ids=str)
def test_mandelbox_orbits_escape_outside_the_bound_cube(kwargs, half):
    # The bound's argument: outside the cube [-B, B]^3, B = 2 L (s+1)/(s-1)
    # (2 L for s < 0), z never reaches 0 and, for |s| > 1, escapes.
    points = shell(5000, half * 1.001, half * 3)
    points = points[np.abs(points).max(axis=1) > half * 1.001]
    assert bound_radius("mandelbox", precision="double", **kwargs) == pytest.approx(half * np.sqrt(3))
    z, _ = ref.mandelbox_orbit(points, iterations=40, **kwargs)
    assert (np.linalg.norm(z, axis=1) > 100 * np.linalg.norm(points, axis=1)).all()
