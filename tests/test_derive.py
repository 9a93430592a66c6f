"""Forward-mode derivatives through IR loops and branches (fractalc/derive.py):
the Jacobian of an iteration against finite differences of the same
iteration in float64, the estimates built from it against the built-in
fractals' hand-derived running derivatives, and the same in the kernel."""
from __future__ import annotations

import numpy as np
import pytest

from fractalc import derive, formulas, fractals, ir
from fractalc.emit import function_source
from kernel_harness import evaluate_in_kernel

pytestmark = pytest.mark.emit

P = ir.components(ir.Var("p", ir.VEC3))
RNG = np.random.default_rng(20261127)


def triplex_power(z, power):
    """z^power of the Mandelbulb, its running derivative left to the
    compiler."""
    return formulas.triplex_power(z, power).z


def mandelbulb_z(power: float, iterations: int, bailout: float):
    def step(state):
        return tuple(ir.add(c, q) for c, q in zip(triplex_power(state, ir.const(power)), P))
    return ir.loop(tuple(P), ir.Const(float(iterations), ir.INT), step,
                   lambda state: ir.op("le", ir.length(state), ir.const(bailout)))


def mandelbox_z(scale: float, iterations: int, julia: tuple | None = None):
    """Box fold, sphere fold (min radius 0.5, fixed 1), scale and translate
    by p (or by a constant, `julia`): the contract's Mandelbox, with its
    running scalar derivative carried beside as the contract writes it
    (no `+ 1` in Julia mode, where nothing but the folds depends on p)."""
    added = P if julia is None else tuple(ir.const(c) for c in julia)

    def step(state):
        z, dr = state[:3], state[3]
        z = tuple(ir.sub(ir.mul(ir.op("clamp", c, ir.const(-1.0), ir.const(1.0)), ir.const(2.0)), c) for c in z)
        r2 = ir.dot(z, z)
        factor = ir.op("select", ir.op("lt", r2, ir.const(0.25)), ir.const(4.0),
                       ir.op("select", ir.op("lt", r2, ir.const(1.0)), ir.div(ir.const(1.0), r2), ir.const(1.0)))
        z = tuple(ir.add(ir.mul(ir.mul(c, factor), ir.const(scale)), q) for c, q in zip(z, added))
        return (*z, ir.add(ir.mul(ir.mul(dr, factor), ir.const(abs(scale))), ir.const(1.0 if julia is None else 0.0)))
    return ir.loop((*P, ir.const(1.0)), ir.Const(float(iterations), ir.INT), step)


def julia_q(iterations: int):
    c = (-0.2, 0.6, 0.2, 0.1)

    def step(q):
        x, rest = q[0], q[1:]
        square = (ir.sub(ir.mul(x, x), ir.dot(rest, rest)), *(ir.mul(ir.mul(ir.const(2.0), x), v) for v in rest))
        return tuple(ir.add(s, ir.const(k)) for s, k in zip(square, c))
    return ir.loop((*P, ir.const(0.0)), ir.Const(float(iterations), ir.INT), step,
                   lambda q: ir.op("le", ir.length(q), ir.const(4.0)))


def finite_differences(values, points, h=1e-6):
    """d values / d p by central differences of the float64 evaluation:
    (N, len(values), 3)."""
    columns = []
    for j in range(3):
        step = np.zeros(3)
        step[j] = h
        up = np.stack(ir.evaluate_at(values, points + step), axis=1)
        down = np.stack(ir.evaluate_at(values, points - step), axis=1)
        columns.append((up - down) / (2 * h))
    return np.stack(columns, axis=2)


def derived(values, points):
    rebuilt, rows = derive.jacobian(values, P)
    out = ir.evaluate_at((*rebuilt, *(t for row in rows for t in row)), points)
    count = len(values)
    return np.stack(out[:count], axis=1), np.stack(out[count:], axis=1).reshape(len(points), count, 3)


@pytest.mark.parametrize("case, values", [
    ("mandelbulb power 8", lambda: mandelbulb_z(8.0, 3, 1e6)),
    ("mandelbulb power 3", lambda: mandelbulb_z(3.0, 4, 1e6)),
    ("mandelbox", lambda: mandelbox_z(2.0, 4)[:3]),
    ("julia", lambda: julia_q(4)),
])
def test_the_jacobian_through_a_loop_matches_finite_differences(case, values):
    values = values()
    points = RNG.uniform(-1.2, 1.2, (60, 3))
    _, jacobian = derived(values, points)
    expected = finite_differences(values, points)
    scale = np.abs(expected).max(axis=(1, 2))
    error = np.abs(jacobian - expected).max(axis=(1, 2)) / scale
    # the map is smooth at almost every point: folds and clamps have kinks
    assert np.median(error) < 1e-6 and np.percentile(error, 90) < 1e-5, (case, np.percentile(error, [50, 90]))


def test_per_ray_stopping_freezes_the_tangents_with_the_values():
    values = mandelbulb_z(8.0, 8, 2.0)
    points = RNG.uniform(-1.3, 1.3, (80, 3))
    z, jacobian = derived(values, points)
    expected = finite_differences(values, points)
    error = np.abs(jacobian - expected).max(axis=(1, 2)) / np.abs(expected).max(axis=(1, 2))
    # rays whose neighbours stop at the same step are smooth there
    assert np.median(error) < 1e-5
    assert np.isfinite(z).all() and np.isfinite(jacobian).all()


def test_on_a_conformal_formula_the_jacobian_estimate_is_the_scalar_one():
    """A Julia-mode Mandelbox is a similarity at every step (folds,
    inversion, scale, a constant added), so J = dr Q with Q orthogonal and
    r / |grad r| = r / dr exactly."""
    loop = mandelbox_z(2.0, 6, julia=(0.3, -0.2, 0.1))
    z, dr = loop[:3], loop[3]
    rebuilt, rows = derive.jacobian(z, P)
    jacobian_estimate = derive.linear_estimate(rebuilt, rows)
    scalar_estimate = ir.div(ir.length(z), dr)
    points = RNG.uniform(-2.0, 2.0, (200, 3))
    a, b = ir.evaluate_at((jacobian_estimate, scalar_estimate), points)
    assert np.allclose(a, b, rtol=1e-9, atol=0)


def test_the_derived_mandelbulb_estimate_is_near_the_hand_derived_one():
    """Syntopia (part V): the scalar running derivative approximates |J|;
    the two estimates agree within a few percent at most points."""
    rebuilt, rows = derive.jacobian(mandelbulb_z(8.0, 12, 2.0), P)
    estimate = derive.escape_time_estimate(rebuilt, rows)
    builtin = fractals.orbit("mandelbulb", P, (ir.const(8.0), ir.Const(12.0, ir.INT), ir.const(2.0))).distance
    points = RNG.uniform(-1.3, 1.3, (1500, 3))
    a, b = ir.evaluate_at((estimate, builtin), points)
    assert np.isfinite(a).all()
    outside = b > 1e-3
    ratio = a[outside] / b[outside]
    assert 0.97 < np.median(ratio) < 1.05 and np.percentile(ratio, 5) > 0.9


def test_each_iteration_runs_once_with_its_tangents():
    rebuilt, rows = derive.jacobian(mandelbulb_z(8.0, 12, 2.0), P)
    source = function_source(derive.escape_time_estimate(rebuilt, rows), "real f(vec3 p, __constant scalar *params)")
    assert source.count("for (") == 1


def test_a_library_call_has_no_derivative():
    shape = ir.call("sd_sphere", (ir.Vec(P), ir.const(1.0)))
    with pytest.raises(derive.NoDerivative, match="'sd_sphere' has no derivative rule"):
        derive.jacobian((shape,), P)


@pytest.mark.opencl
@pytest.mark.parametrize("precision, tolerance", [("float", 2e-4), ("double", 1e-10)])
@pytest.mark.parametrize("lanes", [1, 8])
def test_the_derived_estimate_in_the_kernel_matches_its_float64_meaning(precision, tolerance, lanes):
    rebuilt, rows = derive.jacobian(mandelbulb_z(8.0, 8, 2.0), P)
    estimate = derive.escape_time_estimate(rebuilt, rows)
    points = RNG.uniform(-1.3, 1.3, (256, 3))
    out = evaluate_in_kernel(estimate, points, precision, lanes)
    expected, = ir.evaluate_at((estimate,), points)
    error = np.abs(out - expected) / np.maximum(np.abs(expected), 1e-3)
    assert np.isfinite(out).all() and np.percentile(error, 99) < tolerance, np.percentile(error, [50, 99])
