"""The built-in fractals: the formulas of LANGUAGE.md, "Fractals", written
in the language (stdlib_frac/builtins.frac: one source of truth, with the
overflow handling that keeps every estimate finite); their signatures are
the `//: fractal` lines of stdlib_cl/fractals/, beside their bound radii.

Each builder takes the point (three IR values) and the fractal's arguments
in its signature's order, and gives the distance estimate and, if asked,
the orbit trap: the smallest distance of the orbit to the origin and to
each coordinate plane (Syntopia, "Distance Estimated 3D Fractals", part
II), carried by the same loop.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from . import formula_code, ir
from .check import library_formulas

Vector = tuple[ir.Expr, ...]


@dataclass(frozen=True)
class Orbit:
    distance: ir.Expr
    trap: tuple[ir.Expr, ...]      # origin, |x|, |y|, |z|, the steps taken (empty: not asked for)
    inside: ir.Expr | None         # -1 in the escape-time set, 1 out of it (formula_code.Orbit); None: no bailout


def _formula(name: str, point: Vector, args: tuple, iterations: ir.Expr, bailout: ir.Expr | None,
             trap: bool) -> Orbit:
    """The library formula NAME_formula as this fractal."""
    formula = dict(library_formulas())[f"{name}_formula"][0]
    # each gives its own estimate and its bailout (the box and the solids none): the kind, which only
    # chooses a default bailout here, is linear
    found = formula_code.orbit((formula_code.Use(formula, args),), point, iterations, bailout, trap=trap,
                               estimate=formula_code.Estimate.LINEAR)
    return Orbit(found.distance, found.trap, found.inside)


def mandelbulb(p: Vector, power: ir.Expr, iterations: ir.Expr, bailout: ir.Expr, trap: bool = False) -> Orbit:
    return _formula("mandelbulb", p, (power,), iterations, bailout, trap)


def julia(p: Vector, c: ir.Vec, slice_: ir.Expr, iterations: ir.Expr, bailout: ir.Expr, trap: bool = False) -> Orbit:
    return _formula("julia", p, (c, slice_), iterations, bailout, trap)


def mandelbox(p: Vector, scale: ir.Expr, min_radius: ir.Expr, fixed_radius: ir.Expr, fold_limit: ir.Expr,
              iterations: ir.Expr, trap: bool = False) -> Orbit:
    return _formula("mandelbox", p, (scale, min_radius, fixed_radius, fold_limit), iterations, None, trap)


def menger(p: Vector, level: ir.Expr, trap: bool = False) -> Orbit:
    return _formula("menger", p, (), level, None, trap)


def sierpinski(p: Vector, level: ir.Expr, trap: bool = False) -> Orbit:
    return _formula("sierpinski", p, (), level, None, trap)


# name -> builder
FRACTALS: dict[str, Callable[..., Orbit]] = {
    "mandelbulb": mandelbulb, "julia": julia, "mandelbox": mandelbox, "menger": menger, "sierpinski": sierpinski,
}


def orbit(name: str, point: Vector, args: tuple, trap: bool = False) -> Orbit:
    """The fractal `name` at `point`; its orbit trap too if `trap` (else
    the loop carries none)."""
    return FRACTALS[name](point, *args, trap=trap)
