"""The building blocks of fractal formulas (the functions formulas call in
the language: fractalc/formula_code.py).

Each is an IR expression of z with, where it has one, its conformal factor:
the scalar by which it scales lengths around z (a similarity at every
point: folds, reflections, rotations, uniform scales, sphere folds and
inversions). When every block of a formula has one, the running
derivative is the scalar dr -> factor dr (+ 1 where c is the point), exact
and cheap (Syntopia, "Distance Estimated 3D Fractals", part VI); otherwise
the compiler carries the Jacobian (fractalc/derive.py, part VII). The
triplex power of the Mandelbulb is not conformal; its standard scalar rule
n r^(n-1) is the `approximate` factor the contract defines (part V).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from . import ir

Vector = tuple[ir.Expr, ...]


@dataclass(frozen=True)
class Block:
    """A building block's result: the new z, and the factor by which it
    scales lengths (None: not conformal; `approximate`: a standard scalar
    rule that is not exact)."""
    z: Vector
    factor: ir.Expr | None
    approximate: bool = False


def _c(value: float) -> ir.Expr:
    return ir.const(value)


def _scaled(z: Vector, s: ir.Expr) -> Vector:
    return tuple(ir.mul(c, s) for c in z)


# ---- building blocks ------------------------------------------------------------

def box_fold(z: Vector, limit: ir.Expr | Vector) -> Block:
    """Each coordinate beyond +-limit reflected back inside (Tom Lowe); a
    vector of limits folds each axis at its own."""
    limits = limit if isinstance(limit, tuple) else (limit,) * len(z)
    return Block(tuple(ir.sub(ir.mul(ir.op("clamp", c, ir.neg(k), k), _c(2.0)), c) for c, k in zip(z, limits)),
                 _c(1.0))


def sphere_fold(z: Vector, min_radius: ir.Expr, fixed_radius: ir.Expr) -> Block:
    """Inversion in the sphere of `fixed_radius` inside it, a uniform scale
    inside `min_radius`: the factor fixed^2 / r^2 clamped to [1, fixed^2 / min^2]."""
    fixed2 = ir.mul(fixed_radius, fixed_radius)
    r2 = ir.op("max", ir.dot(z, z), _c(1e-30))
    factor = ir.op("clamp", ir.div(fixed2, r2), _c(1.0), ir.div(fixed2, ir.mul(min_radius, min_radius)))
    return Block(_scaled(z, factor), factor)


def sphere_invert(z: Vector, radius: ir.Expr) -> Block:
    """z R^2 / |z|^2: inversion in the sphere of radius R."""
    factor = ir.div(ir.mul(radius, radius), ir.op("max", ir.dot(z, z), _c(1e-30)))
    return Block(_scaled(z, factor), factor)


def reflect(z: Vector, normal: Vector, offset: ir.Expr = _c(0.0)) -> Block:
    """Mirror image in the plane n.z = offset (n normalised here)."""
    n = _scaled(normal, ir.div(_c(1.0), ir.length(normal)))
    side = ir.sub(ir.dot(n, z), offset)
    return Block(tuple(ir.sub(c, ir.mul(ir.mul(_c(2.0), side), k)) for c, k in zip(z, n)), _c(1.0))


def plane_fold(z: Vector, normal: Vector, offset: ir.Expr = _c(0.0)) -> Block:
    """z moved to the side of the plane n.z = offset that n points to
    (reflected where it is behind): kaleidoscopic IFS folds."""
    n = _scaled(normal, ir.div(_c(1.0), ir.length(normal)))
    behind = ir.op("min", ir.sub(ir.dot(n, z), offset), _c(0.0))
    return Block(tuple(ir.sub(c, ir.mul(ir.mul(_c(2.0), behind), k)) for c, k in zip(z, n)), _c(1.0))


def abs_fold(z: Vector) -> Block:
    """Every coordinate made positive: the octant fold."""
    return Block(tuple(ir.op("abs", c) for c in z), _c(1.0))


def sort_fold(z: Vector) -> Block:
    """Coordinates sorted largest first: the Menger sponge's folds about
    the planes x = y, x = z, y = z."""
    x, y, w = z
    for a, b in ((0, 1), (0, 2), (1, 2)):
        point = [x, y, w]
        point[a], point[b] = ir.op("max", point[a], point[b]), ir.op("min", point[a], point[b])
        x, y, w = point
    return Block((x, y, w), _c(1.0))


def rotate(z: Vector, axis: Vector, degrees: ir.Expr) -> Block:
    """Right-handed rotation about `axis` (Rodrigues)."""
    k = _scaled(axis, ir.div(_c(1.0), ir.length(axis)))
    angle = ir.mul(degrees, _c(math.pi / 180.0))
    cos, sin = ir.op("cos", angle), ir.op("sin", angle)
    k_dot_z = ir.dot(k, z)
    cross = (ir.sub(ir.mul(k[1], z[2]), ir.mul(k[2], z[1])), ir.sub(ir.mul(k[2], z[0]), ir.mul(k[0], z[2])),
             ir.sub(ir.mul(k[0], z[1]), ir.mul(k[1], z[0])))
    turned = tuple(ir.add(ir.add(ir.mul(c, cos), ir.mul(x, sin)), ir.mul(ki, ir.mul(k_dot_z, ir.sub(_c(1.0), cos))))
                   for c, x, ki in zip(z, cross, k))
    return Block(turned, _c(1.0))


def scale(z: Vector, factor: ir.Expr, centre: Vector | None = None) -> Block:
    """s (z - centre) + centre: a uniform scale, |s| on lengths."""
    if centre is None:
        return Block(_scaled(z, factor), ir.op("abs", factor))
    return Block(tuple(ir.add(ir.mul(factor, ir.sub(c, o)), o) for c, o in zip(z, centre)), ir.op("abs", factor))


def stretch(z: Vector, factors: Vector) -> Block:
    """A different scale on each axis: not conformal."""
    return Block(tuple(ir.mul(c, f) for c, f in zip(z, factors)), None)


def translate(z: Vector, offset: Vector) -> Block:
    return Block(tuple(ir.add(c, o) for c, o in zip(z, offset)), _c(1.0))


def triplex_direction(z: Vector, r: ir.Expr, power: ir.Expr) -> Vector:
    """The direction of the triplex power z^power: z's spherical angles
    (theta from the z axis, 0 at r = 0; phi about it) times the power."""
    polar = ir.op("acos", ir.op("clamp", ir.div(z[2], r), _c(-1.0), _c(1.0)))
    theta = ir.mul(ir.op("select", ir.op("eq", r, _c(0.0)), _c(0.0), polar), power)
    phi = ir.mul(ir.op("atan2", z[1], z[0]), power)
    sin_theta = ir.op("sin", theta)
    return ir.mul(sin_theta, ir.op("cos", phi)), ir.mul(ir.op("sin", phi), sin_theta), ir.op("cos", theta)


def triplex_power(z: Vector, power: ir.Expr) -> Block:
    """White and Nylander's z^n, r^n times `triplex_direction`, with the
    Mandelbulb's standard scalar rule n r^(n-1) as its approximate factor."""
    r = ir.length(z)
    log_r = ir.op("log", r)
    factor = ir.mul(power, ir.op("exp", ir.mul(ir.sub(power, _c(1.0)), log_r)))
    return Block(_scaled(triplex_direction(z, r, power), ir.op("exp", ir.mul(power, log_r))), factor,
                 approximate=True)


def quaternion_square(q: Vector) -> Block:
    """q^2 = (x^2 - |v|^2, 2 x v) for q = (x, v): conformal, factor 2|q|."""
    x, rest = q[0], q[1:]
    square = (ir.sub(ir.mul(x, x), ir.dot(rest, rest)), *(ir.mul(ir.mul(_c(2.0), x), v) for v in rest))
    return Block(square, ir.mul(_c(2.0), ir.length(q)))


def quaternion_multiply(a: Vector, b: Vector) -> Vector:
    """The Hamilton product a b (real part first); a tool for formulas,
    not a step of its own."""
    (a0, a1, a2, a3), (b0, b1, b2, b3) = a, b
    m, s, p = ir.mul, ir.sub, ir.add
    return (s(s(s(m(a0, b0), m(a1, b1)), m(a2, b2)), m(a3, b3)),
            s(p(p(m(a0, b1), m(a1, b0)), m(a2, b3)), m(a3, b2)),
            p(s(p(m(a0, b2), m(a1, b3)), m(a2, b0)), m(a3, b1)),
            p(p(s(m(a0, b3), m(a1, b2)), m(a2, b1)), m(a3, b0)))
