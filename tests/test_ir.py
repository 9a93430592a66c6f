"""The IR's loops, branches and op table: derivative rules against finite
differences, loops and branches as the emitter schedules them, and their
values in the compiled kernel against the same iteration in numpy."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import fractalc
from fractalc import ir
from fractalc.emit import function_source

pytestmark = pytest.mark.emit

X, Y, Z = ir.Param(0, "x"), ir.Param(1, "y"), ir.Param(2, "z")

# a point inside each op's domain (x, y, z), away from kinks
DOMAIN = {"asin": (0.3, 0.0, 0.0), "acos": (-0.4, 0.0, 0.0), "sqrt": (1.7, 0.0, 0.0), "rsqrt": (1.7, 0.0, 0.0),
          "log": (1.3, 0.0, 0.0), "pow": (1.4, 0.7, 0.0), "clamp": (0.5, 0.2, 0.9), "mix": (0.3, 1.9, 0.4),
          "abs": (-0.8, 0.0, 0.0), "min": (0.3, 0.9, 0.0), "max": (0.3, 0.9, 0.0), "floor": (1.3, 0.0, 0.0),
          "round": (1.3, 0.0, 0.0), "select": (1.0, 0.6, -0.2)}


def _tangent(name: str, wrt: int) -> ir.Expr:
    """d op(x, y, z) / d(argument `wrt`), by the op's rule."""
    rule = ir.OPS[name]
    args = (X, Y, Z)[:rule.arity]
    if name == "select":
        args = (ir.op("lt", ir.const(0.0), X), Y, Z)
    tangents = tuple(ir.const(1.0 if i == wrt else 0.0) for i in range(rule.arity))
    return rule.derivative(*args, *tangents)


def _value(name: str, point) -> float:
    rule = ir.OPS[name]
    if name == "select":
        return point[1] if point[0] > 0 else point[2]
    return rule.value(*point[:rule.arity])


@pytest.mark.parametrize("name", sorted(n for n, rule in ir.OPS.items() if rule.derivative is not None))
def test_every_derivative_rule_matches_finite_differences(name):
    rule = ir.OPS[name]
    point = DOMAIN.get(name, (0.4, 0.7, 0.0))
    first = 1 if name == "select" else 0     # the condition has no tangent
    for wrt in range(first, rule.arity):
        h = 1e-6
        up, down = list(point), list(point)
        up[wrt] += h
        down[wrt] -= h
        expected = (_value(name, up) - _value(name, down)) / (2 * h)
        got = ir.evaluate(_tangent(name, wrt), point)
        assert math.isclose(got, expected, rel_tol=1e-6, abs_tol=1e-7), (name, wrt, got, expected)


def test_exactly_the_masks_have_no_derivative():
    for name, rule in ir.OPS.items():
        assert (rule.derivative is None) == (rule.result == ir.MASK), name


# ---- loops and branches --------------------------------------------------------

def _escape_loop(point, limit):
    """z -> z^2 + c on the x coordinate until |z| > limit: (z, steps)."""
    c = point[0]

    def step(state):
        z, steps = state
        return ir.add(ir.mul(z, z), c), ir.add(steps, ir.const(1.0))

    def going_on(state):
        return ir.op("le", ir.op("abs", state[0]), limit)

    return ir.loop((ir.const(0.0), ir.const(0.0)), ir.Const(40.0, ir.INT), step, going_on)


def test_equal_loops_are_one_node():
    point = ir.components(ir.Var("p", ir.VEC3))
    first, second = _escape_loop(point, ir.const(2.0)), _escape_loop(point, ir.const(2.0))
    assert first[0].source is second[0].source
    assert _escape_loop(point, ir.const(3.0))[0].source is not first[0].source


def test_a_loop_is_a_for_block_with_its_invariants_computed_once_before_it():
    point = ir.components(ir.Var("p", ir.VEC3))
    limit = ir.op("sqrt", ir.add(ir.mul(point[1], point[1]), ir.const(4.0)))   # depends on p, not on the loop
    z, steps = _escape_loop(point, limit)
    source = function_source(ir.add(z, steps), "real f(vec3 p, __constant scalar *params)")
    before, loop = source.split("for (", 1)
    assert "sqrt(" in before and "sqrt(" not in loop
    assert re.search(r"\bif \(!ANY\(a0\)\) break;", loop)
    assert source.count("for (") == 1


def test_a_constant_condition_builds_one_side_only():
    built = []

    def side(value):
        built.append(value)
        return (ir.const(value),)

    assert ir.branch(ir.op("lt", ir.const(1.0), ir.const(2.0)), lambda: side(1.0), lambda: side(2.0)) \
        == (ir.const(1.0),)
    assert built == [1.0]


def test_uniform_branches_are_if_else_and_per_ray_ones_compute_their_side_where_needed():
    point = ir.components(ir.Var("p", ir.VEC3))
    uniform, = ir.branch(ir.op("lt", X, ir.const(1.0)), (ir.op("sin", point[0]),), (ir.op("cos", point[0]),))
    source = function_source(uniform, "real f(vec3 p, __constant scalar *params)")
    assert re.search(r"if \(\(params\[0\] < 1\.0f\)\) \{\n.*sin.*\n.*\} else \{\n.*cos", source, re.S)
    varying, = ir.branch(ir.op("lt", point[0], ir.const(1.0)), (ir.op("sin", point[0]),), (ir.op("cos", point[0]),))
    source = function_source(varying, "real f(vec3 p, __constant scalar *params)")
    before, inside = source.split("if (ANY(", 1)
    assert "cos(" in before and "sin(" in inside and "else" not in source


@pytest.mark.opencl
@pytest.mark.parametrize("precision", ["float", "double"])
@pytest.mark.parametrize("lanes", [1, 8])
def test_a_fractal_loop_in_the_kernel_matches_its_numpy_iteration(precision, lanes):
    """The Mandelbulb at power 2, whose rays stop at different steps (the
    loop's per-ray condition), against the float64 reference."""
    scene = fractalc.loads("scene mandelbulb(power: 2, iterations: 7, bailout: 3)", precision=precision, lanes=lanes)
    rng = np.random.default_rng(3)
    points = rng.uniform(-1.6, 1.6, (256, 3))
    from reference_fractals import mandelbulb
    expected = mandelbulb(points, power=2.0, iterations=7, bailout=3.0)
    got = scene.distance(points)
    inside = np.linalg.norm(points, axis=1) < 2.0       # within the bound: the loop's value
    error = np.abs(got - expected)[inside] / np.maximum(np.abs(expected[inside]), 1e-3)
    assert np.percentile(error, 99) < (1e-3 if precision == "float" else 1e-9)
