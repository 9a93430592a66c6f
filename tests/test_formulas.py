"""The building blocks of formulas (fractalc/formulas.py) and their
conformal factors; library formulas through the orbit engine
(fractalc/formula_code.py) against the float64 references, hybrids against
numpy and in the kernel."""
from __future__ import annotations

import numpy as np
import pytest

import fractalc
import reference_fractals as ref
from fractalc import derive, formula_code, ir
from fractalc import formulas as F
from kernel_harness import evaluate_in_kernel

pytestmark = pytest.mark.emit

P = ir.components(ir.Var("p", ir.VEC3))
RNG = np.random.default_rng(7)
ITERATIONS = ir.Const(12.0, ir.INT)
FORMULAS = """formula bulb(power = 8) {
    z = triplex_power(z, power) + c
}
formula stretched_box() {
    z = box_fold(z, 1)
    z = sphere_fold(z, 0.5, 1)
    z = stretch(2 * z, (1, 1.3, 0.8)) + c
}
"""


def orbit(use: str, **kwargs) -> formula_code.Orbit:
    """The orbit of a `fractal(...)` use written in the language."""
    shape = fractalc.loads(FORMULAS + f"scene {use}").checked.shape
    return formula_code.orbit(shape.sequence, P, shape.iterations, shape.bailout, shape.julia, **kwargs)


def relative(a, b):
    return np.abs(a - b) / np.maximum(np.abs(b), 1e-3)


def test_the_library_box_is_the_contracts_mandelbox():
    points = RNG.uniform(-2.5, 2.5, (400, 3))
    estimate = orbit("fractal(amazing_box(), iterations: 12)")
    assert estimate.scalar
    got, = ir.evaluate_at((estimate.distance,), points)
    assert np.percentile(relative(got, ref.mandelbox(points)), 99) < 1e-9


def test_a_triplex_power_formula_is_the_contracts_mandelbulb():
    points = RNG.uniform(-1.4, 1.4, (400, 3))
    estimate = orbit("fractal(bulb(), iterations: 12, bailout: 2)")
    assert estimate.scalar     # the contract's scalar rule
    got, = ir.evaluate_at((estimate.distance,), points)
    assert np.percentile(relative(got, ref.mandelbulb(points)), 99) < 1e-9


BLOCKS = {
    "box_fold": lambda z: F.box_fold(z, ir.const(0.8)),
    "sphere_fold": lambda z: F.sphere_fold(z, ir.const(0.4), ir.const(1.1)),
    "sphere_invert": lambda z: F.sphere_invert(z, ir.const(0.9)),
    "reflect": lambda z: F.reflect(z, (ir.const(1.0), ir.const(-2.0), ir.const(0.5)), ir.const(0.3)),
    "plane_fold": lambda z: F.plane_fold(z, (ir.const(0.3), ir.const(1.0), ir.const(-0.4)), ir.const(0.1)),
    "abs_fold": F.abs_fold,
    "sort_fold": F.sort_fold,
    "rotate": lambda z: F.rotate(z, (ir.const(1.0), ir.const(2.0), ir.const(-1.0)), ir.const(37.0)),
    "scale": lambda z: F.scale(z, ir.const(-1.7), (ir.const(0.2), ir.const(0.0), ir.const(1.0))),
    "translate": lambda z: F.translate(z, (ir.const(0.2), ir.const(-0.5), ir.const(1.0))),
}


@pytest.mark.parametrize("name", sorted(BLOCKS))
def test_each_conformal_block_scales_lengths_by_its_factor(name):
    """J^T J = factor^2 I for a similarity: the Jacobian of the block (by
    the derivation pass, checked against finite differences) is its factor
    times an orthogonal matrix, wherever the block is smooth."""
    block = BLOCKS[name](P)
    assert block.factor is not None and not block.approximate
    rebuilt, rows = derive.jacobian(block.z, P)
    points = RNG.uniform(-1.5, 1.5, (200, 3))
    values = ir.evaluate_at((block.factor, *(t for row in rows for t in row)), points)
    factor, jacobian = values[0], np.stack(values[1:], axis=1).reshape(-1, 3, 3)
    gram = np.einsum("nij,nik->njk", jacobian, jacobian)
    assert np.allclose(gram, factor[:, None, None] ** 2 * np.eye(3), rtol=1e-9, atol=1e-9)
    h = 1e-6
    for j in range(3):
        step = np.zeros(3)
        step[j] = h
        up = np.stack(ir.evaluate_at(block.z, points + step), axis=1)
        down = np.stack(ir.evaluate_at(block.z, points - step), axis=1)
        smooth = np.abs(up - down).max(axis=1) < 10 * h * np.abs(factor) + 1e-12
        assert np.allclose(((up - down) / (2 * h))[smooth], jacobian[smooth, :, j], atol=1e-5)


def test_a_non_conformal_formula_uses_the_jacobian():
    assert not orbit("fractal(stretched_box(), bailout: 100)").scalar


def test_on_a_conformal_julia_formula_scalar_and_jacobian_estimates_agree():
    use = "fractal(amazing_box(scale: -1.5), julia: (0.4, -0.3, 0.2))"
    scalar, jacobian = orbit(use), orbit(use, jacobian=True)
    assert scalar.scalar and not jacobian.scalar
    points = RNG.uniform(-2.0, 2.0, (300, 3))
    a, b = ir.evaluate_at((scalar.distance, jacobian.distance), points)
    assert np.allclose(a, b, rtol=1e-8, atol=0)


HYBRID = "fractal(hybrid(bulb() * 2, amazing_box()), iterations: 12)"


def test_a_hybrid_applies_its_formulas_in_turn_with_their_counts():
    """bulb, bulb, amazing box, ... (12 steps), rays stopping between steps
    at |z| > 4, with the scalar running derivative of each: against the
    same steps in numpy."""
    estimate = orbit(HYBRID)
    assert estimate.scalar
    points = RNG.uniform(-1.5, 1.5, (200, 3))
    got, = ir.evaluate_at((estimate.distance,), points)
    z, dr = points.copy(), np.ones(len(points))
    for move in (_numpy_bulb, _numpy_bulb, _numpy_box) * 4:
        going = np.linalg.norm(z, axis=1) <= 4.0
        moved, factor = move(z)
        z = np.where(going[:, None], moved + points, z)
        dr = np.where(going, np.minimum(factor * dr + 1, 1e30), dr)
    r = np.linalg.norm(z, axis=1)
    expected = np.where(r == 0, 0, np.minimum(0.5 * np.log(r) * r / dr, 1e30))
    assert np.percentile(relative(got, expected), 99) < 1e-9
    assert np.isfinite(got).all() and (got[np.linalg.norm(points, axis=1) > 3.0] > 0).all()


def _numpy_bulb(z):
    r = np.linalg.norm(z, axis=1)
    with np.errstate(all="ignore"):
        theta = np.where(r == 0, 0.0, np.arccos(np.clip(z[:, 2] / r, -1, 1))) * 8
    phi = np.arctan2(z[:, 1], z[:, 0]) * 8
    direction = np.stack([np.sin(theta) * np.cos(phi), np.sin(phi) * np.sin(theta), np.cos(theta)], 1)
    return (r ** 8)[:, None] * direction, 8 * r ** 7


def _numpy_box(z):
    z = np.clip(z, -1, 1) * 2 - z
    fold = np.clip(1.0 / np.maximum((z * z).sum(axis=1), 1e-30), 1, 4)
    return z * fold[:, None] * 2, 2 * fold


# p99 measured 4.4e-6 (PoCL) and 5.5e-6 (Intel's runtime) in float, 6.3e-15 in double
@pytest.mark.opencl
@pytest.mark.parametrize("precision, tolerance", [("float", 2e-5), ("double", 1e-9)])
def test_a_hybrid_estimate_in_the_kernel_matches_its_float64_meaning(precision, tolerance):
    estimate = orbit(HYBRID).distance
    points = RNG.uniform(-1.5, 1.5, (256, 3))
    out = evaluate_in_kernel(estimate, points, precision, 8)
    expected, = ir.evaluate_at((estimate,), points)
    assert np.isfinite(out).all() and np.percentile(relative(out, expected), 99) < tolerance
