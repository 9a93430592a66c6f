"""What scene checking (fractalc/check_expressions.py) and formula
interpretation (fractalc/formula_interpreter.py) share of an expression:
its mistakes, a vector's size, its components (`v.xy`) and the broadcasting
of numbers over vectors, each with its message, on (type, IR items); and
the messages of the mistakes both find, in one wording."""
from __future__ import annotations

from . import ast
from .errors import Span
from .types import FLOAT_MAX, TYPE_WORDS, VECTOR_TYPES, Type

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


# ---- the messages of mistakes scenes and formulas share ------------------------

def different_sizes(name: str, sizes) -> str:
    """`name` (an operator or a function) given vectors of these different sizes."""
    shown = sorted(set(sizes))
    return f"'{name}' on vectors of different sizes ({', '.join(map(str, shown[:-1]))} and {shown[-1]})"


def not_numbers(name: str, this: Type) -> str:
    return f"'{name}' needs numbers or vectors, not {TYPE_WORDS[this]}"


def component_not_number(this: Type) -> str:
    return f"a vector's components must be numbers, this is {TYPE_WORDS[this]}"


def undefined(name: str) -> str:
    """`name`'s constants have no value (log(0), a division by zero in a function)."""
    return f"'{name}' is undefined for these values"


def beyond_floats(name: str, value: float) -> str:
    """A constant `name` computes past what the kernel's floats hold (it would compute infinity)."""
    return f"'{name}' gives {value:.3g}, beyond the kernel's floats ({FLOAT_MAX:.3g})"


def uncalled_function(name: str) -> str:
    return f"'{name}' is a function: call it, e.g. '{name}(...)'"


def named_argument(name: str) -> str:
    """A named argument to a function that takes its arguments by position."""
    return f"'{name}' takes its arguments in order, without names"


def argument_count(name: str, low: int, high: int, about: str, given: int) -> str:
    """`name` takes `low` to `high` arguments (`about` shows them), not `given`."""
    count = f"{low}" if low == high else f"{low} to {high}"
    return f"'{name}' takes {count} argument{'s' if high != 1 else ''} ({about}), not {given}"


def wrong_argument(name: str, wanted: str, about: str, this: Type) -> str:
    """An argument of `name` that is `this`, where `wanted` (words: "a vector") goes."""
    return f"'{name}' needs {wanted} here ({about}), this is {TYPE_WORDS[this]}"
