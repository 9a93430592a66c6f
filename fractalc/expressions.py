"""What scene checking (fractalc/check_expressions.py) and formula
interpretation (fractalc/formula_interpreter.py) share of an expression:
its mistakes, a vector's size, its components (`v.xy`) and the broadcasting
of numbers over vectors, each with its message, on (type, IR items)."""
from __future__ import annotations

from . import ast
from .errors import Span
from .types import TYPE_WORDS, VECTOR_TYPES, Type

COMPONENTS = "xyzw"


class Mistake(Exception):
    """A mistake in an expression, at its place."""

    def __init__(self, span: Span, message: str):
        super().__init__(message)
        self.span, self.message = span, message


def require_vector_size(e: ast.Vector, size: int) -> None:
    if size > 4:
        raise Mistake(e.span, f"vectors have 2 to 4 components, this one has {size}")


def components(e: ast.Field, type_: Type, items: tuple) -> tuple:
    """The items `e` picks of a vector of `items` (`v.x`, `v.zyx`)."""
    if type_ not in VECTOR_TYPES:
        raise Mistake(e.span, f"'.{e.name}' takes components of a vector, this is {TYPE_WORDS[type_]}")
    names = COMPONENTS[:len(items)]
    if not e.name or len(e.name) > 4 or any(ch not in names for ch in e.name):
        raise Mistake(e.name_span, f"'.{e.name}' is not a component of {TYPE_WORDS[type_]} "
                                   f"(components: {', '.join(names)})")
    return tuple(items[names.index(ch)] for ch in e.name)


def broadcast(operands: list[tuple[Type, tuple]]) -> tuple[int, list[tuple]] | None:
    """Numbers and vectors combined component by component: the result's
    size (1: numbers only) and each operand's items at that size, a number
    repeated; None where vectors of different sizes meet."""
    sizes = {len(items) for type_, items in operands if type_ is not Type.NUMBER}
    if len(sizes) > 1:
        return None
    size = sizes.pop() if sizes else 1
    return size, [items * size if type_ is Type.NUMBER else items for type_, items in operands]
