"""The values formulas compute (fractalc/formula_code.py): each `Value`
has its type, its IR components and, for the compiler's derivative, its
`form`: lengths of d value / d point are at most a dr + b, where dr is the
running derivative of z (the point moves, z moves dr times as far), when
the value is a similarity of z (a fold, a rotation, a uniform scale, c
added; Syntopia, "Distance Estimated 3D Fractals", part VI). A mistake in a
formula is an expressions.Mistake at its place.
"""
from __future__ import annotations

from dataclasses import dataclass

from . import ir
from .errors import Span
from .types import TYPE_WORDS, Type, vector_type

ZERO, ONE = ir.const(0.0), ir.const(1.0)
INDEPENDENT = (ZERO, ZERO)        # a form: a value that does not depend on the point
NUMBER, MASK = Type.NUMBER, Type.MASK


@dataclass(frozen=True)
class Value:
    type: Type                                  # a number, vector or comparison (MASK)
    items: tuple[ir.Expr, ...]
    form: tuple[ir.Expr, ir.Expr] | None = INDEPENDENT
    underivable: Span | None = None             # an operation on the point without a derivative rule

    @property
    def independent(self) -> bool:
        return self.form is not None and all(ir.is_const(x) and x.value == 0.0 for x in self.form)


def word(v: Value) -> str:
    return TYPE_WORDS[v.type]


def number(x: ir.Expr) -> Value:
    return Value(NUMBER, (x,))


def vector(items, form=INDEPENDENT) -> Value:
    return Value(vector_type(len(items)), tuple(items), form)


def scaled_form(form, s: ir.Expr):
    return None if form is None else (ir.mul(form[0], s), ir.mul(form[1], s))


def summed_form(f, g):
    return None if f is None or g is None else (ir.add(f[0], g[0]), ir.add(f[1], g[1]))


def dependent_scalar(*operands: Value) -> Value:
    """The shared fields of a value computed from `operands` by an
    operation that is not a similarity."""
    independent = all(o.independent for o in operands)
    return Value(NUMBER, (), INDEPENDENT if independent else None,
                 next((o.underivable for o in operands if o.underivable), None))
