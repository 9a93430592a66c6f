"""The built-in fractals as IR loops: the formulas of LANGUAGE.md,
"Fractals", with the overflow handling that keeps every estimate finite.

Each builder takes the point (three IR values) and the fractal's arguments
in its signature's order, and gives the distance estimate and the orbit
trap: the smallest distance of the orbit to the origin and to each
coordinate plane (Syntopia, "Distance Estimated 3D Fractals", part II),
carried by the same loop. The signature of each fractal is written beside
its builder (the `//:` syntax of stdlib.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from . import ir
from .formulas import quaternion_square, triplex_direction

Vector = tuple[ir.Expr, ...]
TRAP_START = 1e30           # a trap distance no orbit point is farther than
FLT_MIN = 1.1754943508222875e-38
NO_ESCAPE = ir.Const(0.0, ir.MASK)


@dataclass(frozen=True)
class Orbit:
    distance: ir.Expr
    trap: tuple[ir.Expr, ...]      # origin, |x|, |y|, |z| (empty: not asked for)


def _c(value: float) -> ir.Expr:
    return ir.const(value)


def _add(a: Vector, b: Vector) -> Vector:
    return tuple(ir.add(x, y) for x, y in zip(a, b))


def _scale(a: Vector, s: ir.Expr) -> Vector:
    return tuple(ir.mul(x, s) for x in a)


def _select(condition: ir.Expr, if_true: Vector, if_false: Vector) -> Vector:
    return tuple(ir.op("select", condition, t, f) for t, f in zip(if_true, if_false))


def _trap_start(trap: bool) -> Vector:
    return (_c(TRAP_START),) * 4 if trap else ()


def _trap_add(trap: Vector, z: Vector, keep: ir.Expr | None = None) -> Vector:
    """The trap with orbit point z added (unless `keep`, a mask, holds); no
    trap carried, none added."""
    if not trap:
        return ()
    added = (ir.op("min", trap[0], ir.length(z)),
             *(ir.op("min", t, ir.op("abs", c)) for t, c in zip(trap[1:], z)))
    return added if keep is None else _select(keep, trap, added)


def _clamped(p: Vector) -> Vector:
    """p clamped to a box holding the solid: only brings it closer to the
    solid (so the estimate stays a lower bound) and keeps |p|^2 finite."""
    return tuple(ir.op("clamp", c, _c(-1e15), _c(1e15)) for c in p)


# ---- the Mandelbulb ----------------------------------------------------------------

MANDELBULB = "power: num = 8 1..32, iterations: int = 12 1..1000, bailout: num = 2 >0"


def _mandelbulb_power8(z: Vector) -> Vector:
    """z^8 without trigonometry, after Quilez ("Mandelbulb", 2009), with his
    polar axis y turned to our z: r^8 times the direction at power 8 (to
    rounding). On the z axis (x = y = 0) the polynomial is 0 / 0; there
    z^8 = (0, 0, z^8)."""
    x, y, w = z[1], z[2], z[0]                      # Quilez's x, y, z
    m, a, s = ir.mul, ir.add, ir.sub
    x2, y2, w2 = m(x, x), m(y, y), m(w, w)
    x4, y4, w4 = m(x2, x2), m(y2, y2), m(w2, w2)
    k3 = a(x2, w2)
    k3_2 = m(k3, k3)
    k2 = ir.op("rsqrt", m(m(m(k3_2, k3_2), k3_2), k3))
    k1 = s(a(a(a(x4, y4), w4), m(_c(2.0), m(w2, x2))), a(m(_c(6.0), m(y2, w2)), m(_c(6.0), m(x2, y2))))
    k4 = a(s(x2, y2), w2)
    k12 = m(k1, k2)
    x8 = a(s(a(s(m(x4, x4), m(_c(28.0), m(m(x4, x2), w2))), m(_c(70.0), m(x4, w4))),
             m(_c(28.0), m(m(x2, w2), w4))), m(w4, w4))
    power8 = (m(m(m(_c(-8.0), y), m(k4, x8)), k12),
              m(m(m(m(_c(64.0), x), m(y, w)), m(m(s(x2, w2), k4), a(s(x4, m(_c(6.0), m(x2, w2))), w4))), k12),
              a(m(m(_c(-16.0), y2), m(k3, m(k4, k4))), m(k1, k1)))
    on_axis = ir.op("eq", k3, _c(0.0))
    return _select(on_axis, (_c(0.0), _c(0.0), m(y4, y4)), power8)


def mandelbulb(p: Vector, power: ir.Expr, iterations: ir.Expr, bailout: ir.Expr, trap: bool = False) -> Orbit:
    """White and Nylander's power-n triplex z -> z^n + p, DE = 0.5 ln(r) r / dr
    with dr -> n r^(n-1) dr + 1 (Syntopia, parts IV and V).

    Overflow: r^power is at most 1e12 on a step that keeps iterating; a step
    past that escapes, its z and dr stored divided by r^power, whose log
    goes to `log_scale` (the final DE is the same number). dr is capped at
    1e24 (only bounded orbits get there, whose DE is below 1e-20 either
    way), so n r^(n-1) dr stays below 1e38."""
    def radius(state):
        return ir.length(state[:3])

    def step(state):
        z, dr, log_scale, trap = state[:3], state[3], state[4], state[6:]
        r = radius(state)
        # the triplex power z^power as r^power times a direction, and r^(power-1)
        r2 = ir.mul(r, r)
        *z_power, r_power1 = ir.branch(
            ir.op("eq", power, _c(8.0)),
            lambda: (*_mandelbulb_power8(z), ir.mul(ir.mul(ir.mul(r2, r2), r2), r)),
            # r^power as exp(power ln r): pow costs ~10x exp + log on vector
            # lanes (PoCL); 0^0 = 1 at power 1
            lambda: (*_scale(triplex_direction(z, r, power), ir.op("exp", ir.mul(power, ir.op("log", r)))),
                     ir.op("select", ir.op("eq", power, _c(1.0)), _c(1.0),
                           ir.op("exp", ir.mul(ir.sub(power, _c(1.0)), ir.op("log", r))))))
        r_power = ir.mul(r_power1, r)
        z_next = _add(tuple(z_power), p)
        dr_next = ir.op("min", ir.add(ir.mul(ir.mul(power, r_power1), dr), _c(1.0)), _c(1e24))
        escapes = ir.op("lt", _c(1e12), r_power)

        def rescaled():
            log_power = ir.mul(power, ir.op("log", r))
            inverse = ir.op("exp", ir.neg(log_power))
            direction = triplex_direction(z, r, power)
            return (*_add(direction, _scale(p, inverse)), ir.add(ir.div(ir.mul(power, dr), r), inverse), log_power)

        *z_new, dr_new, log_new = ir.branch(escapes, rescaled, (*z_next, dr_next, log_scale))
        return (*z_new, dr_new, log_new, escapes, *_trap_add(trap, tuple(z_new), escapes))

    def going_on(state):
        return ir.op("and", ir.op("le", radius(state), bailout), ir.op("not", state[5]))

    final = ir.loop((*p, _c(1.0), _c(0.0), NO_ESCAPE, *_trap_start(trap)), iterations, step, going_on)
    z, dr, log_scale = final[:3], final[3], final[4]
    r = ir.length(z)
    de = ir.div(ir.mul(ir.mul(_c(0.5), ir.add(ir.op("log", r), log_scale)), r), dr)
    # DE = 0 at r = 0; min() keeps it finite where |p| overflows (> 1e19 in float)
    return Orbit(ir.op("select", ir.op("eq", r, _c(0.0)), _c(0.0), ir.op("min", de, _c(1e30))), final[6:])


# ---- quaternion Julia sets ---------------------------------------------------------

JULIA = "c: vec4 = (-0.2, 0.6, 0.2, 0), slice: num = 0, iterations: int = 12 1..1000, bailout: num = 4 >0"


def julia(p: Vector, c: ir.Vec, slice_: ir.Expr, iterations: ir.Expr, bailout: ir.Expr, trap: bool = False) -> Orbit:
    """q -> q^2 + c sliced at a fixed k component, DE = 0.5 ln(r) r / dr,
    dr -> 2 |q| dr (Hart, Sandin and Kauffman 1989; Syntopia, part IV).

    Overflow: |q|^2 is at most 1e12 on a step that keeps iterating; a step
    from a larger |q| escapes, q and dr stored divided by |q|^2, whose log
    goes to `log_scale`. dr is capped at 1e30."""
    def squared(state):
        return ir.dot(state[:4], state[:4])

    def step(state):
        q, dr, log_scale, trap = state[:4], state[4], state[5], state[7:]
        r2 = squared(state)
        r = ir.op("sqrt", r2)
        square = quaternion_square(q).z
        escapes = ir.op("lt", _c(1e12), r2)
        scale, log_new = ir.branch(escapes, lambda: (ir.div(_c(1.0), r2), ir.op("log", r2)), (_c(1.0), log_scale))
        q_new = tuple(ir.mul(ir.add(s, k), scale) for s, k in zip(square, c.items))
        dr_new = ir.mul(ir.op("min", ir.mul(ir.mul(_c(2.0), r), dr), _c(1e30)), scale)
        return (*q_new, dr_new, log_new, escapes, *_trap_add(trap, q_new[:3], escapes))

    def going_on(state):
        return ir.op("and", ir.op("le", ir.op("sqrt", squared(state)), bailout), ir.op("not", state[6]))

    final = ir.loop((*p, slice_, _c(1.0), _c(0.0), NO_ESCAPE, *_trap_start(trap)), iterations, step, going_on)
    q, dr, log_scale = final[:4], final[4], final[5]
    r = ir.length(q)
    de = ir.div(ir.mul(ir.mul(_c(0.5), ir.add(ir.op("log", r), log_scale)), r), dr)
    # DE = 0 at r = 0 or dr = 0; min() keeps it finite where |p| overflows
    degenerate = ir.op("or", ir.op("eq", r, _c(0.0)), ir.op("eq", dr, _c(0.0)))
    return Orbit(ir.op("select", degenerate, _c(0.0), ir.op("min", de, _c(1e30))), final[7:])


# ---- the Mandelbox -----------------------------------------------------------------

MANDELBOX = ("scale: num = 2, min_radius: num = 0.5 >0 <=fixed_radius, fixed_radius: num = 1 >0, "
             "fold_limit: num = 1 >0, iterations: int = 12 1..1000")


def mandelbox(p: Vector, scale: ir.Expr, min_radius: ir.Expr, fixed_radius: ir.Expr, fold_limit: ir.Expr,
              iterations: ir.Expr, trap: bool = False) -> Orbit:
    """Tom Lowe's z -> scale * spherefold(boxfold(z)) + p, dr -> |scale| fold
    dr + 1, DE = |z| / |dr| (Syntopia, part VI).

    There is no bailout, so z and dr grow like |scale|^n outside the set,
    and dr also grows inside it. Both are kept multiplied by a per-ray
    factor k (z_true = z / k, dr_true = dr / k), and k shrinks whenever z or
    dr passes 1e6: in the scaled values the folds compare with fold_limit k
    and radius^2 k^2, the translation adds p k and the derivative k; the DE
    does not depend on k."""
    min2, fixed2 = ir.mul(min_radius, min_radius), ir.mul(fixed_radius, fixed_radius)

    def step(state):
        z, dr, k, trap = state[:3], state[3], state[4], state[5:]
        # box fold: reflect each coordinate beyond +-fold_limit back inside
        limit = ir.mul(fold_limit, k)
        z = tuple(ir.sub(ir.mul(ir.op("clamp", c, ir.neg(limit), limit), _c(2.0)), c) for c in z)
        # sphere fold: the factor fixed^2 / r^2 clamped to [1, fixed^2 / min^2]
        # (the floor on r^2 keeps 0 / 0 out once k^2 has underflowed)
        r2 = ir.op("max", ir.dot(z, z), _c(FLT_MIN))
        fold = ir.op("clamp", ir.div(ir.mul(fixed2, ir.mul(k, k)), r2), _c(1.0), ir.div(fixed2, min2))
        z = _add(_scale(z, ir.mul(fold, scale)), _scale(p, k))
        dr = ir.add(ir.mul(ir.mul(dr, fold), ir.op("abs", scale)), k)
        trap = _trap_add(trap, _scale(z, ir.div(_c(1.0), ir.op("max", k, _c(1e-30)))))
        # renormalise rays whose z or dr got large
        largest = ir.op("max", ir.op("max", ir.op("abs", z[0]), ir.op("abs", z[1])),
                        ir.op("max", ir.op("abs", z[2]), dr))

        def shrunk():
            shrink = ir.div(_c(1.0), largest)
            return (*_scale(z, shrink), ir.mul(dr, shrink), ir.mul(k, shrink))

        return (*ir.branch(ir.op("lt", _c(1e6), largest), shrunk, (*z, dr, k)), *trap)

    final = ir.loop((*p, _c(1.0), _c(1.0), *_trap_start(trap)), iterations, step)
    # dr > 0; the floor only matters once k has underflowed to 0 inside the set
    return Orbit(ir.div(ir.length(final[:3]), ir.op("max", final[3], _c(1e-30))), final[5:])


# ---- the Menger sponge -------------------------------------------------------------

MENGER = "level: int = 4 0..10"


def menger(p: Vector, level: ir.Expr, trap: bool = False) -> Orbit:
    """The level-N sponge filling [-1,1]^3 (Syntopia, part III; Quilez,
    "Menger fractal"): the largest of the exact signed distances to the
    cube and to the outside of each level's bars, each a set holding the
    sponge, so never more than the distance to it (exact inside). abs()
    folds the point into one octant of its cell, the bars' cross section
    there is [0, 1/3]^2 of the two smallest coordinates, and a = 3a or
    3a - 2 enters the next level's cell (cells 3^-n the cube's size)."""
    p = _clamped(p)
    q = tuple(ir.sub(ir.op("abs", c), _c(1.0)) for c in p)
    outside = ir.length(tuple(ir.op("max", c, _c(0.0)) for c in q))
    cube = ir.add(outside, ir.op("min", ir.op("max", q[0], ir.op("max", q[1], q[2])), _c(0.0)))
    third = 1.0 / 3.0

    def step(state):
        a, d, size, trap = tuple(ir.op("abs", c) for c in state[:3]), state[3], state[4], state[5:]
        lowest = ir.op("min", a[0], ir.op("min", a[1], a[2]))
        middle = ir.op("max", ir.op("min", a[0], a[1]), ir.op("min", ir.op("max", a[0], a[1]), a[2]))
        # signed distance to the nearest bar, the one along the largest axis
        u, v = ir.sub(middle, _c(third)), ir.sub(lowest, _c(third))
        bar = ir.add(ir.length((ir.op("max", u, _c(0.0)), ir.op("max", v, _c(0.0)))),
                     ir.op("min", ir.op("max", u, v), _c(0.0)))
        d = ir.op("max", d, ir.neg(ir.mul(bar, size)))
        # each coordinate as the coordinate of the third it falls in
        a = tuple(ir.op("select", ir.op("lt", _c(third), c), ir.sub(ir.mul(_c(3.0), c), _c(2.0)),
                        ir.mul(_c(3.0), c)) for c in a)
        return (*a, d, ir.mul(size, _c(third)), *_trap_add(trap, a))

    final = ir.loop((*p, cube, _c(1.0), *_trap_start(trap)), level, step)
    return Orbit(final[3], final[5:])


# ---- the Sierpinski tetrahedron -----------------------------------------------------

SIERPINSKI = "level: int = 6 0..10"


def _sierpinski_fold(p: Vector, side: float) -> Vector:
    """Folds p by the three reflections swapping a1 with a2, a4, a3, each
    when a1 . p is below (side 1) or above (side -1) the other vertex's: a
    reflection leaves the dot products of the vertices it does not swap as
    they were, so afterwards a1 . p is the largest (smallest)."""
    x, y, z = p
    for first, second in ((0, 1), (0, 2), (1, 2)):
        point = [x, y, z]
        swap = ir.op("lt", ir.mul(_c(side), ir.add(point[first], point[second])), _c(0.0))
        point[first], point[second] = (ir.op("select", swap, ir.neg(point[second]), point[first]),
                                       ir.op("select", swap, ir.neg(point[first]), point[second]))
        x, y, z = point
    return x, y, z


def _sierpinski_tetrahedron(p: Vector) -> ir.Expr:
    """Exact signed distance to T. Folded so that the face a2 a3 a4
    (x + y + z = -1) is the one whose plane is farthest out, the point is
    inside T if inside that plane, else nearest to that face; sorting
    x >= y >= z makes a3 its nearest vertex: the point is nearest to the
    face's inside or, past the edge a3 a4, to that edge."""
    p = _sierpinski_fold(p, -1.0)
    plane = ir.mul(ir.sub(ir.neg(ir.add(ir.add(p[0], p[1]), p[2])), _c(1.0)), _c(1.0 / 3.0 ** 0.5))
    x = ir.op("max", p[0], ir.op("max", p[1], p[2]))
    z = ir.op("min", p[0], ir.op("min", p[1], p[2]))
    y = ir.op("max", ir.op("min", p[0], p[1]), ir.op("min", ir.op("max", p[0], p[1]), p[2]))
    t = ir.op("min", ir.mul(_c(0.5), ir.sub(x, y)), _c(1.0))
    edge = ir.length((ir.sub(x, t), ir.add(y, t), ir.add(z, _c(1.0))))
    past_edge = ir.op("lt", _c(0.0), ir.sub(ir.sub(ir.add(x, y), ir.mul(_c(2.0), z)), _c(2.0)))
    outside = ir.op("select", past_edge, edge, plane)
    return ir.op("select", ir.op("le", plane, _c(0.0)), plane, outside)


def sierpinski(p: Vector, level: ir.Expr, trap: bool = False) -> Orbit:
    """The level-N solid tetrahedron with vertices a1 = (1,1,1), (-1,-1,1),
    (1,-1,-1), (-1,1,-1) (Syntopia, part III). Exact: the reflection
    swapping a1 and ai maps the solid to itself and the copy scaled about
    a1 lies on a1's side of each of those planes, so the folds keep the
    distance and dist(p) = dist(2p - a1) / 2, down to T itself."""
    def step(state):
        folded, size, trap = _sierpinski_fold(state[:3], 1.0), state[3], state[4:]
        point = tuple(ir.sub(ir.mul(_c(2.0), c), _c(1.0)) for c in folded)
        return (*point, ir.mul(size, _c(0.5)), *_trap_add(trap, point))

    final = ir.loop((*_clamped(p), _c(1.0), *_trap_start(trap)), level, step)
    return Orbit(ir.mul(_sierpinski_tetrahedron(final[:3]), final[3]), final[4:])


# name -> (signature text, builder)
FRACTALS: dict[str, tuple[str, Callable[..., Orbit]]] = {
    "mandelbulb": (MANDELBULB, mandelbulb),
    "julia": (JULIA, julia),
    "mandelbox": (MANDELBOX, mandelbox),
    "menger": (MENGER, menger),
    "sierpinski": (SIERPINSKI, sierpinski),
}


def orbit(name: str, point: Vector, args: tuple, trap: bool = False) -> Orbit:
    """The fractal `name` at `point`; its orbit trap too if `trap` (else
    the loop carries none)."""
    return FRACTALS[name][1](point, *args, trap=trap)
