"""The language's transforms, `.NAME(args)` on a shape: each one entry of
TRANSFORMS holding its signature (the checker binds its arguments by it)
and how it lowers (fractalc/lower.py reads the point, the distance and the
bound there); a warp's library functions are in stdlib_cl/ops/warp.cl.
`.material(...)` and `.color(...)` change the surface, not the shape: the
checker makes them a WithMaterial (SURFACE_TRANSFORMS: signatures only).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from . import ir
from .stdlib import Signature
from .types import NONZERO, Parameter, Type, above, at_least, between

# Where a transform can carry a point past float's range (a translate by
# more than this, a scale by a factor below 1, either by a param), the moved
# point's coordinates are clamped to +-MAX_COORDINATE: beyond ~1.8e19 a
# shape's squared length overflows to +inf, and a warp's angle to NaN.
# Projecting onto a box that holds the shape moves no point farther from it,
# so the estimate stays a lower bound, finite (issue 10).
MAX_COORDINATE = 1e18
# Twist and bend rates act as at most this many radians per unit: at unit
# distance float resolves such an angle to 0.06 rad, and beyond it rate x
# coordinate overflows to an infinite angle (a NaN point).
MAX_WARP_RATE = 1e6

Point = tuple[ir.Expr, ir.Expr, ir.Expr]
Sphere = tuple[Point, ir.Expr]      # centre and radius
HalfSpace = tuple[Point, ir.Expr]   # unit normal n and offset: the points with n.p <= offset


@dataclass(frozen=True)
class Bound:
    """Where a shape can be: within `sphere` (None: nowhere) or in one of
    the `half_spaces` (ground planes). A ray that has left the sphere and
    moves away from every half-space it is outside of meets nothing more."""
    sphere: Sphere | None
    half_spaces: tuple[HalfSpace, ...] = ()


@dataclass(frozen=True)
class Transform:
    """A transform: its `signature` and how it lowers, in three parts, none
    with a default: `point(point, args)`: where the inner shape's field is
    read; `distance(d, args, point, inner_bound)`: the transformed shape's
    distance from the inner one's `d` there (`inner_bound()`: the inner
    shape's Bound or None, for a distance that needs it); `bound(inner
    bound, args)`: where the transformed shape can be (None: anywhere)."""
    signature: Signature
    point: Callable[[Point, tuple], Point]
    distance: Callable[[ir.Expr, tuple, Point, Callable[[], "Bound | None"]], ir.Expr]
    bound: Callable[[Bound, tuple], "Bound | None"]


def dot3(a: Point, b: Point) -> ir.Expr:
    return ir.add(ir.add(ir.mul(a[0], b[0]), ir.mul(a[1], b[1])), ir.mul(a[2], b[2]))


def squared_length(x, y, z) -> ir.Expr:
    return ir.add(ir.add(ir.mul(x, x), ir.mul(y, y)), ir.mul(z, z))


def _rotated(point: Point, axis: ir.Vec, degrees: ir.Expr) -> Point:
    """R^T p for R the right-handed rotation about `axis` by `degrees`
    (Rodrigues): the shape turns by R, so its field is read at R^T p."""
    length = ir.op("sqrt", ir.add(ir.add(ir.mul(axis.items[0], axis.items[0]),
                                         ir.mul(axis.items[1], axis.items[1])),
                                  ir.mul(axis.items[2], axis.items[2])))
    kx, ky, kz = (ir.div(a, length) for a in axis.items)
    angle = ir.mul(degrees, ir.const(math.pi / 180.0))
    c, s = ir.op("cos", angle), ir.op("sin", angle)
    t = ir.sub(ir.const(1.0), c)
    x, y, z = point
    k_dot_p = ir.add(ir.add(ir.mul(kx, x), ir.mul(ky, y)), ir.mul(kz, z))
    k_cross_p = (ir.sub(ir.mul(ky, z), ir.mul(kz, y)),
                 ir.sub(ir.mul(kz, x), ir.mul(kx, z)),
                 ir.sub(ir.mul(kx, y), ir.mul(ky, x)))
    # rotation by -angle: p cos - (k x p) sin + k (k.p)(1 - cos)
    return tuple(ir.add(ir.sub(ir.mul(pi, c), ir.mul(cross, s)), ir.mul(ki, ir.mul(k_dot_p, t)))
                 for pi, cross, ki in zip(point, k_cross_p, (kx, ky, kz)))


def _repeated(point: Point, period: ir.Vec) -> Point:
    """p - c round(p / c) on each axis whose period c is not 0 (a period
    that is a param may become 0 at render time: then p)."""
    def axis(p, c):
        if ir.is_const(c) and c.value == 0.0:
            return p
        wrapped = ir.sub(p, ir.mul(c, ir.op("round", ir.div(p, c))))
        return ir.op("select", ir.op("lt", ir.const(0.0), c), wrapped, p)
    return tuple(axis(p, c) for p, c in zip(point, period.items))


def _clamped(point: Point) -> Point:
    return tuple(ir.op("clamp", c, ir.const(-MAX_COORDINATE), ir.const(MAX_COORDINATE)) for c in point)


def _warp_rate(rate: ir.Expr) -> ir.Expr:
    return ir.op("clamp", rate, ir.const(-MAX_WARP_RATE), ir.const(MAX_WARP_RATE))


def _warped_sphere(kind: str, sphere: Sphere) -> Sphere:
    """A sphere that holds a twisted (bent) shape, from one that holds the
    shape: a twist turns each point about the z axis (a bend, about the y
    axis), which keeps its distance to every point of that axis, so the
    sphere about the axis point nearest the centre that holds the first
    sphere holds the warped shape."""
    (x, y, z), radius = sphere
    zero = ir.const(0.0)
    if kind == "twist":
        centre, off_axis = (zero, zero, z), (x, y)
    else:
        centre, off_axis = (zero, y, zero), (x, z)
    across = ir.op("sqrt", ir.add(ir.mul(off_axis[0], off_axis[0]), ir.mul(off_axis[1], off_axis[1])))
    return centre, ir.add(radius, across)


def _read_at(point: Point, args: tuple) -> Point:
    """The point itself: the transform changes the distance, not where it is read."""
    return point


def _same_distance(d: ir.Expr, args: tuple, point: Point, inner_bound) -> ir.Expr:
    return d


def _same_bound(inner: Bound, args: tuple) -> Bound:
    """Within the inner shape: as bounded as it."""
    return inner


def _unbounded(inner: Bound, args: tuple) -> None:
    return None


def _moving(sphere: Callable[[Sphere, tuple], Sphere],
            half_space: Callable[[HalfSpace, tuple], HalfSpace]) -> Callable[[Bound, tuple], Bound]:
    """A bound update that moves the inner bound's sphere and each of its half-spaces."""
    def bound(inner: Bound, args: tuple) -> Bound:
        return Bound(None if inner.sphere is None else sphere(inner.sphere, args),
                     tuple(half_space(h, args) for h in inner.half_spaces))
    return bound


def _translated(point: Point, args: tuple) -> Point:
    moved = tuple(ir.sub(p, v) for p, v in zip(point, args[0].items))
    far = any(not ir.is_const(v) or abs(v.value) > MAX_COORDINATE for v in args[0].items)
    return _clamped(moved) if far else moved


def _scaled(point: Point, args: tuple) -> Point:
    moved = tuple(ir.div(p, args[0]) for p in point)
    return moved if ir.is_const(args[0]) and args[0].value >= 1.0 else _clamped(moved)


def _onion(d: ir.Expr, args: tuple, point: Point, inner_bound) -> ir.Expr:
    # a shell of thickness t inside the surface: |d + t/2| - t/2
    half = ir.mul(args[0], ir.const(0.5))
    return ir.sub(ir.op("abs", ir.add(d, half)), half)


def _signature(name: str, *parameters: Parameter) -> Signature:
    return Signature("transform", name, parameters)


def _warp(signature: Signature, point_function: str, lipschitz_function: str) -> Transform:
    """A warp (twist, bend): the point moved by the library's
    `point_function`, the distance divided by its Lipschitz factor
    (`lipschitz_function`), and a sphere about the warp's axis for a bound."""
    kind = signature.name

    def point(p: Point, args: tuple) -> Point:
        return ir.components(ir.call(point_function, (ir.Vec(p), _warp_rate(args[0])), ir.VEC3))

    def distance(d: ir.Expr, args: tuple, p: Point, inner_bound) -> ir.Expr:
        warped = ir.div(d, ir.call(lipschitz_function, (ir.Vec(p), _warp_rate(args[0]))))
        inner = inner_bound()
        if inner is None or inner.sphere is None or inner.half_spaces:
            return warped
        # Dividing by the warp's Lipschitz factor, which grows with the
        # distance from the axis, caps the estimate near 1 / rate however
        # far the point is: the march crawls and a soft shadow's k d / t
        # reads the cap as a near miss (rings on a floor). The warp keeps
        # the sphere about its axis that holds the shape, and that
        # sphere's distance is a lower bound too: the larger of the two,
        # and the sphere's alone far from it (as a fractal's bound).
        centre, radius = _warped_sphere(kind, inner.sphere)
        bound = ir.call("sd_sphere", (ir.Vec(tuple(ir.sub(c, o) for c, o in zip(p, centre))), radius))
        return ir.bounded(bound, ir.op("max", warped, bound), radius)

    def bound(inner: Bound, args: tuple) -> Bound | None:
        # a warped half-space is no half-space
        return None if inner.sphere is None or inner.half_spaces else Bound(_warped_sphere(kind, inner.sphere))
    return Transform(signature, point, distance, bound)


TRANSFORMS = {
    "translate": Transform(
        _signature("translate", Parameter("offset", Type.VEC3)),
        _translated, _same_distance,
        _moving(lambda sphere, args: (tuple(ir.add(c, v) for c, v in zip(sphere[0], args[0].items)), sphere[1]),
                lambda half_space, args: (half_space[0], ir.add(half_space[1], dot3(half_space[0], args[0].items))))),
    "rotate": Transform(
        _signature("rotate", Parameter("axis", Type.VEC3, None, (NONZERO,)), Parameter("degrees", Type.NUMBER)),
        lambda point, args: _rotated(point, args[0], args[1]), _same_distance,
        _moving(lambda sphere, args: (_rotated(sphere[0], args[0], ir.neg(args[1])), sphere[1]),
                lambda half_space, args: (_rotated(half_space[0], args[0], ir.neg(args[1])), half_space[1]))),
    "scale": Transform(
        _signature("scale", Parameter("factor", Type.NUMBER, None, (above(0),))),
        _scaled, lambda d, args, point, inner_bound: ir.mul(d, args[0]),
        _moving(lambda sphere, args: (tuple(ir.mul(c, args[0]) for c in sphere[0]), ir.mul(sphere[1], args[0])),
                lambda half_space, args: (half_space[0], ir.mul(half_space[1], args[0])))),
    "repeat": Transform(
        _signature("repeat", Parameter("period", Type.SIZE, None, (at_least(0),))),
        lambda point, args: _repeated(point, args[0]), _same_distance, _unbounded),
    "round": Transform(
        _signature("round", Parameter("radius", Type.NUMBER, None, (at_least(0),))),
        _read_at, lambda d, args, point, inner_bound: ir.sub(d, args[0]),
        _moving(lambda sphere, args: (sphere[0], ir.add(sphere[1], args[0])),
                lambda half_space, args: (half_space[0], ir.add(half_space[1], args[0])))),
    "onion": Transform(
        _signature("onion", Parameter("thickness", Type.NUMBER, None, (above(0),))),
        _read_at, _onion, _same_bound),
    "twist": _warp(_signature("twist", Parameter("rate", Type.NUMBER)), "twist_point", "twist_lipschitz"),
    "bend": _warp(_signature("bend", Parameter("rate", Type.NUMBER)), "bend_point", "bend_lipschitz"),
}

SURFACE_TRANSFORMS = {
    "material": _signature("material", Parameter("material", Type.MATERIAL)),
    "color": _signature("color", Parameter("rgb", Type.COLOR, None, (between(0, 1000),))),
}

# What the checker binds `.NAME(...)` by, in the order its messages list them
SIGNATURES = {**{name: t.signature for name, t in TRANSFORMS.items()}, **SURFACE_TRANSFORMS}
