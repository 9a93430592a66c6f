"""The language's value types, and the parameters that take them: a
function's arguments (the `//:` lines, fractalc/stdlib.py) and a block's
keys (declared beside their fields in fractalc/program.py), each with its
constraints as typed values, parsed once and checked without a checker
(`violation`)."""
from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields
from enum import Enum, StrEnum
from functools import lru_cache
from typing import Callable

# The largest float: a number beyond it is infinite in a float kernel
FLOAT_MAX = 3.4028234663852886e38


def in_float_range(x: float) -> bool:
    return math.isfinite(x) and abs(x) <= FLOAT_MAX


class Type(StrEnum):
    """A value's type in a scene or a formula, and what a parameter takes."""
    NUMBER = "number"
    WHOLE = "int"           # a number that is a whole number
    VEC2 = "vec2"
    VEC3 = "vec3"
    VEC4 = "vec4"
    SIZE = "size"           # a number or a 3-vector (a number: all three)
    COLOR = "color"         # a 3-vector or a colouring
    SHAPE = "shape"
    MATERIAL = "material"
    WORD = "word"           # a bare name: one of a parameter's words
    COLORING = "coloring"
    FORMULA = "formula"
    MASK = "mask"           # a comparison, in a formula
    FILE = "file"           # a file name in quotes
    BLOCK = "block"         # a block of keys of its own
    ERROR = "error"         # an expression that failed (already reported)


VECTOR_TYPES = (Type.VEC2, Type.VEC3, Type.VEC4)
NUMBER_TYPES = (Type.NUMBER, *VECTOR_TYPES)     # what arithmetic takes


def vector_type(size: int) -> Type:
    return Type(f"vec{size}")


TYPE_WORDS = {Type.NUMBER: "a number", Type.SHAPE: "a shape", Type.MATERIAL: "a material", Type.WORD: "a name",
              Type.FORMULA: "a formula", Type.COLORING: "a colouring (orbit_trap)",
              Type.COLOR: "a colour (r, g, b) or orbit_trap(...)", Type.VEC2: "a 2-vector",
              Type.VEC3: "a 3-vector", Type.VEC4: "a 4-vector", Type.SIZE: "a number or a 3-vector",
              Type.WHOLE: "a whole number", Type.MASK: "a comparison"}


def number_text(number: float) -> str:
    """A number in a message: whole numbers in full (4294967295, not 4.29497e+09)."""
    return str(int(number)) if number.is_integer() and abs(number) < 1e16 else f"{number:g}"


# ---- constraints ---------------------------------------------------------------

class Comparison(Enum):
    """`value OP limit`: its sign in a `//:` line, its words in a message, its test."""
    ABOVE = (">", "greater than", float.__gt__)
    AT_LEAST = (">=", "at least", float.__ge__)
    BELOW = ("<", "less than", float.__lt__)
    AT_MOST = ("<=", "at most", float.__le__)

    @property
    def sign(self) -> str:
        return self.value[0]


@dataclass(frozen=True)
class Bound:
    """Every component OP `limit`: a number, or the name of another
    argument of the same call (`min_radius: num <=fixed_radius`)."""
    comparison: Comparison
    limit: float | str

    @property
    def relative(self) -> bool:
        return isinstance(self.limit, str)

    def violation(self, values, others: dict | None) -> str | None:
        if self.relative:
            if not others or self.limit not in others:
                return None
            limit, text = others[self.limit], f"'{self.limit}' ({others[self.limit]:g})"
        else:
            limit, text = self.limit, number_text(self.limit)
        test = self.comparison.value[2]
        return None if all(test(v, limit) for v in values) else f"must be {self.comparison.value[1]} {text}"


@dataclass(frozen=True)
class Between:
    """Every component within [low, high]."""
    low: float
    high: float

    def violation(self, values, others: dict | None) -> str | None:
        if all(self.low <= v <= self.high for v in values):
            return None
        return f"must be between {number_text(self.low)} and {number_text(self.high)}"


@dataclass(frozen=True)
class NonZero:
    """Not every component zero (a direction)."""

    def violation(self, values, others: dict | None) -> str | None:
        return None if any(v != 0 for v in values) else "must not be zero"


Constraint = Bound | Between | NonZero
NONZERO = NonZero()


def above(x: float) -> Bound:
    return Bound(Comparison.ABOVE, float(x))


def at_least(x: float) -> Bound:
    return Bound(Comparison.AT_LEAST, float(x))


def below(x: float) -> Bound:
    return Bound(Comparison.BELOW, float(x))


def at_most(x: float) -> Bound:
    return Bound(Comparison.AT_MOST, float(x))


def between(low: float, high: float) -> Between:
    return Between(float(low), float(high))


def parse_constraint(text: str) -> Constraint:
    """A constraint as a `//:` line writes it: `>X`, `>=X`, `<X`, `<=X`,
    `A..B` (inclusive), `nonzero`, or a bound by another argument `<=name`."""
    if text == "nonzero":
        return NONZERO
    if ".." in text:
        low, high = text.split("..")
        return between(float(low), float(high))
    comparison = next(c for c in sorted(Comparison, key=lambda c: -len(c.sign)) if text.startswith(c.sign))
    limit = text[len(comparison.sign):]
    return Bound(comparison, limit if limit[:1].isalpha() else float(limit))


# ---- what the kernel reads of a key ----------------------------------------------

@dataclass(frozen=True)
class Feature:
    """The kernel's `#if FEATURE_<name>` blocks (stdlib_cl/engine/) that a
    key turns on where `on(value)` holds (emit.features). `alters_march`:
    with it on, the march no longer takes each plain step (longer steps, a
    packet's cone), which what reads the plain march (glow, step-count AO)
    rules out."""
    name: str
    on: Callable[[object], bool]
    alters_march: bool = False


@dataclass(frozen=True)
class Constant:
    """The `#define` lines the kernel reads a key's value by (emit): `name`
    with the value (of a number, whole number or 3-vector key; a 3-vector
    as NAME_R, NAME_G, NAME_B), or those `values(value)` gives as
    {name: value} (numbers, truths, 3-vectors); written where the feature
    `when` is on (None: the key's own feature, or its block's; a key with
    neither, or `always`: in every kernel)."""
    name: str = ""
    values: Callable[[object], dict] | None = None
    when: Feature | None = None
    always: bool = False


# ---- parameters ------------------------------------------------------------------

@dataclass(frozen=True)
class Parameter:
    """What an argument or a block key takes: its type (with `words`, one
    of these words or a value of the type; type WORD: a word only), its
    default (None: required, for an argument), its constraints, and for
    a BLOCK the dataclass whose keys it holds."""
    name: str
    type: Type
    default: object = None
    constraints: tuple[Constraint, ...] = ()
    words: tuple[str, ...] = ()
    block: type | None = None
    runtime: bool = False          # a render key the kernel takes as an argument: no rebuild
    feature: Feature | None = None     # the kernel's blocks the key turns on
    constant: Constant | None = None   # the #defines the kernel reads its value by

    def __post_init__(self):
        # a type or constraint still spelt as text ("num", ">0") fails where it is declared, not in a check
        if not isinstance(self.type, Type) or not all(isinstance(c, Constraint) for c in self.constraints):
            raise TypeError(f"parameter '{self.name}': a Type and typed constraints (types.parse_constraint), "
                            f"not {self.type!r} {self.constraints!r}")

    @property
    def range(self) -> tuple[float | None, float | None, bool, bool]:
        """(low, high, low excluded, high excluded) of its numeric bounds,
        None: open on that side."""
        low = high = None
        low_excluded = high_excluded = False
        for c in self.constraints:
            if isinstance(c, Between):
                low, high = c.low, c.high
            elif isinstance(c, Bound) and not c.relative:
                excluded = c.comparison in (Comparison.ABOVE, Comparison.BELOW)
                if c.comparison in (Comparison.ABOVE, Comparison.AT_LEAST):
                    low, low_excluded = c.limit, excluded
                else:
                    high, high_excluded = c.limit, excluded
        return low, high, low_excluded, high_excluded

    def word(self, value):
        """The word `value` names among the parameter's words (its enum
        member where they are one), or None."""
        return self.words[self.words.index(value)] if isinstance(value, str) and value in self.words else None

    def violation(self, values, others: dict | None = None) -> str | None:
        """What is wrong with these constant components (None: nothing),
        as "must be ..., not X"; a bound by another argument is checked
        where `others` gives that argument's value."""
        shown = number_text(values[0]) if len(values) == 1 else "(" + ", ".join(f"{v:g}" for v in values) + ")"
        if self.type is Type.WHOLE and any(v != math.floor(v) for v in values):
            return f"must be a whole number, not {shown}"
        for c in self.constraints:
            says = c.violation(values, others)
            if says:
                return f"{says}, not {shown}"
        return None


def empty_range(low: float, high: float) -> str:
    """The message of a declared range [low, high] with low > high."""
    return f"the range [{low:g}, {high:g}] is empty"


def range_violation(name: str, value: float, low: float | None, high: float | None) -> str | None:
    """A declared param's (or formula parameter's) value outside its range [low, high]."""
    if (low is not None and value < low) or (high is not None and value > high):
        return f"'{name}' = {value:g} is outside its range [{low:g}, {high:g}]"
    return None


# ---- keys declared beside their fields --------------------------------------------

def key(default, type_: Type, *constraints: Constraint, words=(), block: type | None = None,
        runtime: bool = False, field_default: bool = True, feature: Feature | None = None,
        constant: str | Constant | None = None):
    """A dataclass field that is a block's key: the Parameter a file's,
    the command line's and the API's values of it are checked against
    (`keys_of`), and what the kernel reads of it: the `feature` its value
    turns on, the `constant` (a name, or a Constant) it is read by.
    `field_default=False`: the default is the key's only (the field holds
    another form of it, as a material's IR)."""
    spec = dict(type=type_, default=default, constraints=constraints, words=tuple(words), block=block,
                runtime=runtime, feature=feature,
                constant=Constant(constant) if isinstance(constant, str) else constant)
    return field(default=default if field_default else MISSING, metadata={"key": spec})


@lru_cache(maxsize=None)
def keys_of(cls, *extra: Parameter) -> dict[str, Parameter]:
    """The keys a dataclass declares (`key`) in field order, and `extra`."""
    found = {f.name: Parameter(f.name, **f.metadata["key"]) for f in fields(cls) if "key" in f.metadata}
    found.update((p.name, p) for p in extra)
    return found
