"""Stage 3: checked scene -> distance IR (`lower`).

A shape becomes IR expressions of the point variable `p`: its distance
estimate, and the surface (colour and finish) of the part nearest to `p`.
Point transforms (translate, rotate, repeat, scale) are scalar IR arithmetic
on the point's components; library shapes and warps are `ir.Call`s.
Constants fold as the IR is built; params stay symbolic.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

from . import ir
from .program import (DEFAULT_MATERIAL, CheckedScene, Coloring, Combination, Fractal, Material, Primitive,
                      Shape, Transformed, WithMaterial, cosine_palette, fold_shape)
from . import formula_code
from .fractals import orbit
from .transforms import TRANSFORMS, Bound, Point, squared_length

POINT = ir.Var("p", ir.VEC3)


@dataclass(frozen=True)
class Surface:
    """The surface properties at a point, each an IR expression."""
    red: ir.Expr
    green: ir.Expr
    blue: ir.Expr
    specular: ir.Expr
    shininess: ir.Expr
    reflectivity: ir.Expr
    transparency: ir.Expr
    ior: ir.Expr
    material: ir.Expr      # the material's index among the scene's (the `material` pass)

    @staticmethod
    def of(material: Material, index: int) -> "Surface":
        return Surface(*material.color.items, material.specular, material.shininess,
                       material.reflectivity, material.transparency, material.ior, ir.const(float(index)))

    def items(self) -> tuple[ir.Expr, ...]:
        return tuple(getattr(self, f.name) for f in fields(self))


def _chosen(condition: ir.Expr, if_true: Surface, if_false: Surface) -> Surface:
    """Field-wise select (folded where both sides agree)."""
    return Surface(*(ir.op("select", condition, a, b) for a, b in zip(if_true.items(), if_false.items())))


@dataclass(frozen=True)
class SceneIR:
    scene: CheckedScene
    distance: ir.Expr            # real, of POINT
    surface: Surface             # of POINT
    bound: Bound | None = None   # where the whole scene can be (uniform)


# The default (`auto`) scale of an orbit trap's distance: t = 1 + ln(trap) /
# TRAP_DECADES, so traps from e^-5 (0.0067) to 1 span the palette. Measured
# on the surfaces of the library's fractals, the `planes` trap runs from
# 0.004-0.024 (5th percentile) to 0.15-0.71 (95th): linear in the trap, no
# one scale suits them all (scale 1 left most of the Mandelbulb's surface
# at `far`).
TRAP_DECADES = 5.0


def _trap_parameter(coloring: Coloring, trap: ir.Expr, iterations: ir.Expr, radius: ir.Expr | None) -> ir.Expr:
    """t, where the trap falls on the colouring's palette: trap * scale, or
    with the `auto` scale (None) spread over the trap's range: a distance's
    logarithm (TRAP_DECADES), the steps over the iterations, the radius
    over the fractal's bound and the height across it (-bound to bound)."""
    if coloring.scale is not None:
        return ir.mul(trap, coloring.scale)
    if coloring.trap == "iterations":
        return ir.div(trap, ir.op("max", iterations, ir.const(1.0)))
    if coloring.trap in ("radius", "height"):
        across = radius if radius is not None else ir.const(1.0)
        if coloring.trap == "radius":
            return ir.div(trap, across)
        return ir.add(ir.const(0.5), ir.div(trap, ir.mul(across, ir.const(2.0))))
    logarithm = ir.op("log", ir.op("max", trap, ir.const(1e-30)))
    return ir.add(ir.const(1.0), ir.div(logarithm, ir.const(TRAP_DECADES)))


def _trap_colored(surface: Surface, coloring: Coloring, traps, point: Point, iterations: ir.Expr,
                  radius: ir.Expr | None) -> Surface:
    """Orbit-trap colour: mix(near, far, clamp(t, 0, 1)), or a cosine palette
    of t, with t the trap on the palette (`_trap_parameter`)."""
    trap = {"planes": lambda: ir.op("min", traps[1], ir.op("min", traps[2], traps[3])),
            "radius": lambda: ir.length(point), "height": lambda: point[2]}.get(
        coloring.trap, lambda: traps[("origin", "x", "y", "z", "iterations").index(coloring.trap)])()
    t = _trap_parameter(coloring, trap, iterations, radius)
    if coloring.palette is not None:
        rgb = cosine_palette(coloring.palette, t).items
    else:
        t = ir.op("clamp", t, ir.const(0.0), ir.const(1.0))
        rgb = tuple(ir.op("mix", a, b, t) for a, b in zip(coloring.near.items, coloring.far.items))
    items = surface.items()
    return Surface(*rgb, *items[3:])



def _smooth_or_plain(plain: str, smooth_function: str, a, b, k: ir.Expr) -> ir.Expr:
    if ir.is_const(k) and k.value == 0.0:
        return ir.op(plain, a, b)
    return ir.call(smooth_function, (a, b, k))


def _plain(s: Combination) -> bool:
    """A union or intersection without smoothing: min or max of its parts,
    which may be grouped in any order."""
    return s.kind != "subtract" and ir.is_const(s.smooth) and s.smooth.value == 0.0


def _operands(s: Combination) -> tuple[Shape, ...]:
    """A combination's parts, with plain parts of the same kind inside a
    plain one opened up (a union of unions is one union), in order."""
    if not _plain(s):
        return s.shapes
    found, stack = [], list(reversed(s.shapes))
    while stack:
        part = stack.pop()
        if isinstance(part, Combination) and part.kind == s.kind and _plain(part):
            stack.extend(reversed(part.shapes))
        else:
            found.append(part)
    return tuple(found)


def _nearer(a, b):
    """Union of (distance, surface) pairs: on a tie the first part's surface."""
    (da, sa), (db, sb) = a, b
    return ir.op("min", da, db), _chosen(ir.op("lt", db, da), sb, sa)


def _farther(a, b):
    (da, sa), (db, sb) = a, b
    return ir.op("max", da, db), _chosen(ir.op("lt", da, db), sb, sa)


class _Lowerer:
    def __init__(self, scene: CheckedScene, escape_time_sets: bool = False):
        self.materials = scene.materials
        self.escape_time_sets = escape_time_sets

    def surface_of(self, name: str) -> Surface:
        """The surface of material `name`; its index counts the scene's
        materials in order (0 the default, then those the file declares, then
        those `.color(...)` makes)."""
        return Surface.of(self.materials[name], list(self.materials).index(name))

    def shape(self, s: Shape, point: Point, look: tuple[Surface, Coloring | None]):
        """(distance, surface) of shape `s` at `point`; `look` is the
        innermost enclosing material (and orbit-trap colouring)."""
        return fold_shape(s, (point, look), self.parts, self.combine)

    def parts(self, s: Shape, context) -> tuple:
        point, look = context
        if isinstance(s, (Primitive, Fractal)):
            return ()
        if isinstance(s, WithMaterial):
            return ((s.shape, (point, (self.surface_of(s.material), s.coloring))),)
        if isinstance(s, Combination):
            return tuple((part, context) for part in _operands(s))
        return ((s.shape, (self.moved(s, point), look)),)

    def combine(self, s: Shape, context, values: list):
        point, look = context
        if isinstance(s, Primitive):
            return self.primitive(s, point), self.primitive_surface(s, point, look)
        if isinstance(s, Fractal):
            return self.fractal(s, point), self.fractal_surface(s, point, look)
        if isinstance(s, WithMaterial):
            return values[0]
        if isinstance(s, Combination):
            return self.combination(s, values)
        return self.transformed(s, point, *values[0])

    def primitive(self, s: Primitive, point: Point) -> ir.Expr:
        if s.signature.kind != "fractal":
            return ir.call(s.signature.function, (ir.Vec(point),) + s.args)
        distance = self.estimate_or_set(orbit(s.signature.name, point, s.args))
        # A fractal: far from its bounding sphere, the sphere's distance is
        # a safe step and the fractal is not evaluated (Hart et al. 1989).
        radius = ir.call(s.signature.bound_radius, s.args)
        bound = ir.call("sd_sphere", (ir.Vec(point), radius))
        return ir.bounded(bound, distance, radius)

    def primitive_surface(self, s: Primitive, point: Point, look) -> Surface:
        surface, coloring = look
        if coloring is None or s.signature.kind != "fractal":
            return surface
        args = dict(zip((p.name for p in s.signature.parameters), s.args))
        iterations = args.get("iterations", args.get("level"))
        radius = ir.call(s.signature.bound_radius, s.args)
        return _trap_colored(surface, coloring, orbit(s.signature.name, point, s.args, trap=True).trap, point,
                             iterations, radius)

    def estimate_or_set(self, found) -> ir.Expr:
        """A fractal's estimate, or (escape_time_sets) its escape-time set's -1 / 1 where it has a bailout."""
        return found.inside if self.escape_time_sets and found.inside is not None else found.distance

    def fractal(self, s: Fractal, point: Point) -> ir.Expr:
        distance = ir.mul(self.estimate_or_set(formula_code.orbit(s.sequence, point, s.iterations, s.bailout,
                                                                  s.julia, estimate=s.growth.estimate)), s.step)
        if s.bound is None:
            return distance
        bound = ir.call("sd_sphere", (ir.Vec(point), s.bound))
        return ir.bounded(bound, distance, s.bound)

    @staticmethod
    def fractal_surface(s: Fractal, point: Point, look) -> Surface:
        surface, coloring = look
        if coloring is None:
            return surface
        return _trap_colored(surface, coloring, formula_code.orbit(s.sequence, point, s.iterations, s.bailout,
                                                                   s.julia, trap=True,
                                                                   estimate=s.growth.estimate).trap, point,
                             s.iterations, s.bound)

    @staticmethod
    def combination(s: Combination, lowered: list):
        if _plain(s):   # min / max: a balanced tree, the same result as folding left
            return ir.pairwise(lowered, _nearer if s.kind == "union" else _farther)
        # smooth ones fold left to right (LANGUAGE.md)
        distance, surface = lowered[0]
        for d, other in lowered[1:]:
            if s.kind == "union":
                surface = _chosen(ir.op("lt", d, distance), other, surface)
                distance = _smooth_or_plain("min", "smooth_min", distance, d, s.smooth)
            elif s.kind == "intersect":
                surface = _chosen(ir.op("lt", distance, d), other, surface)
                distance = _smooth_or_plain("max", "smooth_max", distance, d, s.smooth)
            else:   # subtract: the cut face keeps the first shape's surface
                distance = _smooth_or_plain("max", "smooth_max", distance, ir.neg(d), s.smooth)
        return distance, surface

    @staticmethod
    def moved(s: Transformed, point: Point) -> Point:
        """The point at which the transformed shape's field is read."""
        return TRANSFORMS[s.kind].point(point, s.args)

    @staticmethod
    def transformed(s: Transformed, point: Point, d: ir.Expr, surface: Surface):
        """The transformed shape's (distance, surface) from its inner
        shape's at the moved point."""
        return TRANSFORMS[s.kind].distance(d, s.args, point, lambda: _Bounds().of(s.shape)), surface


class _Bounds:
    """The Bound of a shape, or None where it is unbounded (repetition, a
    warp); unions take a sphere around their parts' spheres and all their
    half-spaces."""

    def of(self, s: Shape) -> Bound | None:
        return fold_shape(s, None, self._parts, self._combine)

    @staticmethod
    def _parts(s: Shape, context) -> tuple:
        if isinstance(s, (Primitive, Fractal)):
            return ()
        if isinstance(s, Combination):
            return tuple((part, context) for part in s.shapes)
        return ((s.shape, context),)

    def _combine(self, s: Shape, context, bounds: list) -> Bound | None:
        if isinstance(s, Primitive):
            return self._primitive(s)
        if isinstance(s, Fractal):
            return None if s.bound is None else Bound(((ir.const(0.0),) * 3, s.bound))
        if isinstance(s, WithMaterial):
            return bounds[0]
        if isinstance(s, Combination):
            return self._combination(s, bounds)
        inner = bounds[0]
        return None if inner is None else TRANSFORMS[s.kind].bound(inner, s.args)

    def _primitive(self, s: Primitive) -> Bound | None:
        if s.signature.name == "plane":
            normal, offset = s.args
            length = ir.op("sqrt", squared_length(*normal.items))
            return Bound(None, ((tuple(ir.div(c, length) for c in normal.items), offset),))
        if not s.signature.bound_radius:
            return None
        return Bound(((ir.const(0.0),) * 3, ir.call(s.signature.bound_radius, s.args)))

    @staticmethod
    def _combination(s: Combination, bounds: list) -> Bound | None:
        if s.kind == "subtract":             # only ever smaller than the first shape
            return bounds[0]
        if s.kind == "intersect":            # within each part: the tightest one known
            known = [b for b in bounds if b is not None]
            bounded = [b for b in known if b.sphere is not None and not b.half_spaces]
            return (bounded or known or [None])[0]
        if any(b is None for b in bounds):
            return None
        spheres = [b.sphere for b in bounds if b.sphere is not None]
        sphere = None
        if spheres:
            centre, radius = spheres[0]
            for other_centre, other_radius in spheres[1:]:
                gap = ir.op("sqrt", squared_length(*(ir.sub(a, b) for a, b in zip(other_centre, centre))))
                radius = ir.op("max", radius, ir.add(gap, other_radius))
            sphere = centre, radius
        # a smooth union bulges by at most k / 4 beyond both shapes
        bulge = ir.mul(s.smooth, ir.const(0.25))
        if sphere is not None:
            sphere = sphere[0], ir.add(sphere[1], bulge)
        half_spaces = tuple((n, ir.add(offset, bulge)) for b in bounds for n, offset in b.half_spaces)
        return Bound(sphere, half_spaces)


def marched_distance(scene_ir: SceneIR, bound_marched: bool) -> ir.Expr:
    """The distance as a render samples it. Where its march keeps to the
    scene's bounding sphere (`bound_marched`: the camera's rays from where
    they enter it to where they leave, the shadow rays to where they leave
    it, the normals' and the occlusion's samples near a surface), a scene
    that is one shape bounded by that sphere needs no test of the sphere
    in each estimate, whose far side would never be taken: the shape's own
    estimate (bulb-640 1.5% faster on Intel's runtime, 3% on PoCL). A
    point beyond it still gets an estimate, the shape's own (its program's
    `distance_at_points` too); the distance program keeps the test."""
    bound = scene_ir.bound
    if not bound_marched or bound is None or bound.sphere is None or bound.half_spaces:
        return scene_ir.distance
    centre, radius = bound.sphere
    if not all(ir.is_const(c) and c.value == 0 for c in centre):
        return scene_ir.distance
    return ir.inside_bound(scene_ir.distance, ir.components(POINT), radius)


def lower(scene: CheckedScene, escape_time_sets: bool = False) -> SceneIR:
    """Lower the scene's shape to its distance and surface expressions; with
    `escape_time_sets`, each fractal that has a bailout as its escape-time
    set instead (-1 inside, 1 outside: what `check --de` marches to)."""
    lowerer = _Lowerer(scene, escape_time_sets)
    point = ir.components(POINT)
    default = (lowerer.surface_of(DEFAULT_MATERIAL), None)
    distance, surface = lowerer.shape(scene.shape, point, default)
    cut = scene.render.slice
    if cut is not None:
        # Slicing (the blog post "Rendering Julia sets and the Mandelbulb"):
        # intersect with the half-space behind the plane; the cut face is
        # part of the plane, so its normal is the plane's.
        length = math.sqrt(sum(c * c for c in cut.normal))
        plane = ir.const(-cut.offset)
        for p, c in zip(point, cut.normal):
            plane = ir.add(plane, ir.mul(p, ir.const(c / length)))
        distance = ir.op("max", distance, plane)
    try:
        bound = _Bounds().of(scene.shape)
    except (ValueError, ZeroDivisionError, OverflowError):
        bound = None       # a bound past double's range (scales of scales): march unbounded
    if bound is not None and bound.sphere is None:
        bound = None       # half-spaces alone (a ground plane): march as unbounded
    return SceneIR(scene, distance, surface, bound)
