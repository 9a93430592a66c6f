"""The formula engine (fractalc/formulas.py): building blocks and their
conformal factors, formulas and hybrids with a scalar running derivative
or the Jacobian, against the float64 references and in the kernel."""
from __future__ import annotations

import numpy as np
import pytest

import reference_fractals as ref
from fractalc import derive, ir
from fractalc import formulas as F
from kernel_harness import evaluate_in_kernel

P = ir.components(ir.Var("p", ir.VEC3))
RNG = np.random.default_rng(7)
ITERATIONS = ir.Const(12.0, ir.INT)


def amazing_box(scale=2.0, fold=1.0, min_radius=0.5, fixed_radius=1.0):
    def step(z, c):
        folded = F.box_fold(z, ir.const(fold))
        inverted = F.sphere_fold(folded.z, ir.const(min_radius), ir.const(fixed_radius))
        return [folded, inverted, F.scale(inverted.z, ir.const(scale))]
    return F.Formula("amazing_box", step)


MANDELBULB = F.Formula("mandelbulb", lambda z, c: [F.triplex_power(z, ir.const(8.0))])


def relative(a, b):
    return np.abs(a - b) / np.maximum(np.abs(b), 1e-3)


def test_a_mandelbox_from_blocks_is_the_contracts_mandelbox():
    points = RNG.uniform(-2.5, 2.5, (400, 3))
    estimate = F.orbit(P, [(amazing_box(), 1)], ITERATIONS, ir.const(1e30), kind="linear")
    assert estimate.scalar
    got, = ir.evaluate_at((estimate.distance,), points)
    assert np.percentile(relative(got, ref.mandelbox(points)), 99) < 1e-9


def test_a_mandelbulb_from_blocks_is_the_contracts_mandelbulb():
    points = RNG.uniform(-1.4, 1.4, (400, 3))
    estimate = F.orbit(P, [(MANDELBULB, 1)], ITERATIONS, ir.const(2.0))
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
    stretched = F.Formula("stretched_box", lambda z, c: [*amazing_box().step(z, c),
                                                         F.stretch(z, (ir.const(1.0), ir.const(1.3), ir.const(0.8)))])
    assert not F.orbit(P, [(stretched, 1)], ITERATIONS, ir.const(100.0), kind="linear").scalar


def test_on_a_conformal_julia_formula_scalar_and_jacobian_estimates_agree():
    julia = (ir.const(0.4), ir.const(-0.3), ir.const(0.2))
    args = dict(kind="linear", julia=julia)
    scalar = F.orbit(P, [(amazing_box(scale=-1.5), 1)], ITERATIONS, ir.const(1e30), **args)
    jacobian = F.orbit(P, [(amazing_box(scale=-1.5), 1)], ITERATIONS, ir.const(1e30), jacobian=True, **args)
    assert scalar.scalar and not jacobian.scalar
    points = RNG.uniform(-2.0, 2.0, (300, 3))
    a, b = ir.evaluate_at((scalar.distance, jacobian.distance), points)
    assert np.allclose(a, b, rtol=1e-8, atol=0)


def test_a_hybrid_applies_its_formulas_in_turn_with_their_counts():
    """mandelbulb x 2 then amazing box per round, rays stopping between
    steps: the orbit against the same rounds in numpy."""
    hybrid = F.orbit(P, [(MANDELBULB, 2), (amazing_box(), 1)], ir.Const(4.0, ir.INT), ir.const(4.0),
                     jacobian=True)
    points = RNG.uniform(-1.5, 1.5, (200, 3))
    values = ir.evaluate_at((hybrid.distance, *hybrid.z), points)
    z = points.copy()
    stopped = np.zeros(len(points), bool)
    for _ in range(4):
        for move in (_numpy_bulb, _numpy_bulb, _numpy_box):
            going = ~stopped & (np.linalg.norm(z, axis=1) <= 4.0)
            z = np.where(going[:, None], move(z) + points, z)
            stopped = ~going
    assert np.allclose(np.stack(values[1:], axis=1), z, rtol=1e-9, atol=1e-9)
    distance = values[0]
    assert np.isfinite(distance).all() and (distance[np.linalg.norm(points, axis=1) > 3.0] > 0).all()


def _numpy_bulb(z):
    r = np.linalg.norm(z, axis=1)
    with np.errstate(all="ignore"):
        theta = np.where(r == 0, 0.0, np.arccos(np.clip(z[:, 2] / r, -1, 1))) * 8
    phi = np.arctan2(z[:, 1], z[:, 0]) * 8
    return (r ** 8)[:, None] * np.stack([np.sin(theta) * np.cos(phi), np.sin(phi) * np.sin(theta), np.cos(theta)], 1)


def _numpy_box(z):
    z = np.clip(z, -1, 1) * 2 - z
    r2 = np.maximum((z * z).sum(axis=1), 1e-30)
    return z * np.clip(1.0 / r2, 1, 4)[:, None] * 2


@pytest.mark.parametrize("precision, tolerance", [("float", 1e-3), ("double", 1e-9)])
def test_a_hybrid_estimate_in_the_kernel_matches_its_float64_meaning(precision, tolerance):
    estimate = F.orbit(P, [(MANDELBULB, 2), (amazing_box(), 1)], ir.Const(4.0, ir.INT), ir.const(4.0)).distance
    points = RNG.uniform(-1.5, 1.5, (256, 3))
    out = evaluate_in_kernel(estimate, points, precision, 8)
    expected, = ir.evaluate_at((estimate,), points)
    assert np.isfinite(out).all() and np.percentile(relative(out, expected), 99) < tolerance
