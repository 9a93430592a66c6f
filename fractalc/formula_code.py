"""Formulas written in the language (`formula name(...) { ... }`) as IR,
and the orbit of a fractal built from them (docs/formulas.md).

`check` runs a formula's statements here once where it is declared (every
mistake is a `Mistake` at its place) and `lower` runs them again for each
use, with that use's arguments. Each value is a `Value`: its type, its IR
components and, for the compiler's derivative, its `form`: lengths of
d value / d point are at most a dr + b, where dr is the running derivative
of z (the point moves, z moves dr times as far), when the value is a
similarity of z (a fold, a rotation, a uniform scale, c added; Syntopia,
"Distance Estimated 3D Fractals", part VI). A formula whose every step
keeps z's form gets the cheap scalar running derivative; any other is
differentiated in forward mode (fractalc/derive.py, part VII).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from . import ast, derive, formulas, ir
from .errors import Span

ZERO, ONE = ir.const(0.0), ir.const(1.0)
INDEPENDENT = (ZERO, ZERO)        # a form: a value that does not depend on the point
# A step whose z is beyond this length (or not finite) is not taken: the ray
# stops with its last finite state, so every estimate is finite.
OVERFLOW_LENGTH = 1e18
MAX_DERIVATIVE = 1e30
DEFAULT_BAILOUT = 4.0
ESTIMATES = ("escape_time_estimate", "linear_estimate")
# What `final` lines may read of the compiler's derivative (docs/formulas.md):
# dr, how fast |z| moves with the point (the running derivative; |grad |z||
# on the Jacobian path), and jacobian_norm, the most z moves when the point
# moves by one (the Jacobian's spectral norm; |dr| for similarities).
DERIVED = ("dr", "jacobian_norm")
VECTOR_TYPES = ("vec2", "vec3", "vec4")
_WORDS = {"num": "a number", "vec2": "a 2-vector", "vec3": "a 3-vector", "vec4": "a 4-vector",
          "mask": "a comparison"}
_COMPONENTS = "xyzw"


class Mistake(Exception):
    def __init__(self, span: Span, message: str):
        super().__init__(message)
        self.span, self.message = span, message


@dataclass(frozen=True)
class Value:
    type: str                                   # num | vec2..vec4 | mask
    items: tuple[ir.Expr, ...]
    form: tuple[ir.Expr, ir.Expr] | None = INDEPENDENT
    underivable: Span | None = None             # an operation on the point without a derivative rule

    @property
    def independent(self) -> bool:
        return self.form is not None and all(ir.is_const(x) and x.value == 0.0 for x in self.form)


def _word(v: Value) -> str:
    return _WORDS[v.type]


def number(x: ir.Expr) -> Value:
    return Value("num", (x,))


def vector(items, form=INDEPENDENT) -> Value:
    return Value(f"vec{len(items)}", tuple(items), form)


def _scaled_form(form, s: ir.Expr):
    return None if form is None else (ir.mul(form[0], s), ir.mul(form[1], s))


def _summed_form(f, g):
    return None if f is None or g is None else (ir.add(f[0], g[0]), ir.add(f[1], g[1]))


def _dependent_scalar(*operands: Value) -> Value:
    """The shared fields of a value computed from `operands` by an
    operation that is not a similarity."""
    independent = all(o.independent for o in operands)
    return Value("num", (), INDEPENDENT if independent else None,
                 next((o.underivable for o in operands if o.underivable), None))


# ---- statements --------------------------------------------------------------

@dataclass(frozen=True)
class Formula:
    """A checked formula: its parameters' names and statements by phase."""
    name: str
    params: tuple[str, ...]
    init: tuple[ast.Statement, ...]
    step: tuple[ast.Statement, ...]
    final: tuple[ast.Statement, ...]
    span: Span
    file: str = "<string>"          # the file it is written in

    @property
    def carried(self) -> tuple[str, ...]:
        """The names set by `init` that the step or the final lines use
        (z among them if it is), in order: the loop carries them."""
        used = _names(self.step + self.final)
        names: list[str] = []
        for s in self.init:
            if s.name not in names and s.name in used:
                names.append(s.name)
        return tuple(names)

    @property
    def derived(self) -> tuple[str, ...]:
        """The compiler's derivatives (DERIVED) the final lines read, those
        the formula does not set itself (its own `init dr = 1`)."""
        own = _names(self.init + self.step) | {s.name for s in self.final if isinstance(s, ast.Assign)}
        read = {e.name for e in _expressions(self.final) if isinstance(e, ast.Name)}
        return tuple(name for name in DERIVED if name in read and name not in own)

    @property
    def sets_distance(self) -> bool:
        """Whether the final lines give the estimate (their own, or one of
        ESTIMATES chosen by name), not the compiler's by its kind."""
        return any(s.name == "distance" for s in self.final)

    @property
    def own_estimate(self) -> bool:
        """Whether `final distance = ...` gives the estimate without asking
        for the compiler's estimates or derivatives."""
        return self.sets_distance and not _calls(self.final, ESTIMATES) and not self.derived


def split(decl: ast.FormulaDecl, file: str = "<string>") -> Formula:
    """The formula's statements by phase; a misplaced one is a Mistake."""
    phases: dict[str, list] = {"init": [], "step": [], "final": []}
    for statement in decl.body:
        phase = statement.phase if isinstance(statement, ast.Assign) else "step"
        phases[phase].append(statement)
        for inner in (statement, *_nested(statement)):
            if not isinstance(inner, ast.Assign):
                continue
            if inner is not statement and inner.phase != "step":
                raise Mistake(inner.span, f"'{inner.phase}' goes at the top of a formula, not inside 'if'")
            own = _RESERVED.get(inner.name)
            if own is not None and inner.phase != own:
                where = {"step": "a step line (no 'init' or 'final')", "final": "a 'final' line"}[own]
                raise Mistake(inner.name_span, f"'{inner.name}' is set in {where}")
    return Formula(decl.name, tuple(p.name for p in decl.params), tuple(phases["init"]),
                   tuple(phases["step"]), tuple(phases["final"]), decl.span, file)


# names with a meaning, and the phase that sets them
_RESERVED = {"stop": "step", "trap": "step", "distance": "final"}


def _nested(statement) -> list:
    """The statements inside `statement` (the sides of an `if`, and theirs)."""
    return [n for n in ast.walk(statement) if n is not statement and isinstance(n, (ast.Assign, ast.If))]


def _expressions(statements) -> list:
    """Every expression node of `statements`, ifs' included."""
    return [n for s in statements for n in ast.walk(s) if not isinstance(n, (ast.Assign, ast.If, ast.Arg))]


def _names(statements) -> set:
    """The names `statements` read or set."""
    assigned = {s.name for s in (*statements, *(n for s in statements for n in _nested(s)))
                if isinstance(s, ast.Assign)}
    return assigned | {e.name for e in _expressions(statements) if isinstance(e, ast.Name)}


def _calls(statements, names) -> bool:
    return any(isinstance(e, ast.Call) and e.name in names for e in _expressions(statements))


class Interpreter:
    """Runs statements on an environment of Values (names -> Value).
    `estimates` gives the compiler's estimates to `final` statements."""

    def __init__(self, estimates: Callable[[str, list[Value], Span], Value] | None = None):
        self.estimates = estimates

    def run(self, statements, env: dict[str, Value], readonly: frozenset = frozenset()) -> dict[str, Value]:
        env = dict(env)
        for s in statements:
            if isinstance(s, ast.Assign):
                if s.name in readonly:
                    raise Mistake(s.name_span, f"'{s.name}' cannot be assigned in a formula"
                                               f"{' (it is a parameter)' if s.name != 'c' else ' (it is the constant)'}")
                env[s.name] = self.expr(s.value, env)
            else:
                env = self.if_(s, env, readonly)
        return env

    def if_(self, s: ast.If, env: dict, readonly) -> dict:
        condition = self.expr(s.condition, env)
        if condition.type != "mask":
            raise Mistake(s.condition.span, f"'if' needs a comparison (such as 'r < 1'), this is {_word(condition)}")
        then, otherwise = self.run(s.then, env, readonly), self.run(s.otherwise, env, readonly)
        merged, differ = dict(env), []
        for name in sorted(set(then) | set(otherwise)):
            if name.startswith("__"):
                continue
            a, b = then.get(name), otherwise.get(name)
            if a is None or b is None:
                merged.pop(name, None)
                merged["__one_sided__"] = {**merged.get("__one_sided__", {}), name: s.span}
            elif a is b:
                merged[name] = a
            elif a.type != b.type:
                raise Mistake(s.span, f"'{name}' is {_word(a)} after 'if' and {_word(b)} after 'else'")
            else:
                differ.append(name)
        # one branch for all the values the sides set differently
        merged.update(zip(differ, _chosen(condition, [then[n] for n in differ], [otherwise[n] for n in differ])))
        return merged

    # ---- expressions ---------------------------------------------------------

    def expr(self, e: ast.Expr, env: dict) -> Value:
        if isinstance(e, ast.Number):
            return number(ir.const(e.value))
        if isinstance(e, ast.Name):
            if e.name in env and not e.name.startswith("__"):
                return env[e.name]
            one_sided = env.get("__one_sided__", {})
            if e.name in one_sided:
                raise Mistake(e.span, f"'{e.name}' is set on only one side of the 'if' at line "
                                      f"{one_sided[e.name].line}: set it on both, or before the 'if'")
            if e.name in FUNCTIONS or e.name in ESTIMATES:
                raise Mistake(e.span, f"'{e.name}' is a function: call it, e.g. '{e.name}(...)'")
            if e.name in DERIVED:
                raise Mistake(e.span, f"'{e.name}' is the compiler's derivative at the orbit's end: only 'final' "
                                      f"lines read it")
            raise Mistake(e.span, f"unknown name '{e.name}' in formula")
        if isinstance(e, ast.Vector):
            parts = [self.expr(x, env) for x in e.items]
            for x, v in zip(e.items, parts):
                if v.type == "mask":
                    raise Mistake(x.span, "a vector's components must be numbers, this is a comparison")
            items = tuple(c for v in parts for c in v.items)
            if len(items) > 4:
                raise Mistake(e.span, f"vectors have 2 to 4 components, this one has {len(items)}")
            return _joined(parts)
        if isinstance(e, ast.Unary):
            v = self.expr(e.operand, env)
            if v.type == "mask":
                raise Mistake(e.span, "a comparison cannot be negated (swap the comparison instead)")
            return replace(v, items=tuple(ir.neg(x) for x in v.items))
        if isinstance(e, ast.Binary):
            left, right = self.expr(e.left, env), self.expr(e.right, env)
            try:
                return _within_float(e, self.binary(e, left, right))
            except (ValueError, ZeroDivisionError, OverflowError):
                raise Mistake(e.span, f"'{e.op}' is undefined for these values") from None
        if isinstance(e, ast.Chain):
            return self.chain(e, [self.expr(x, env) for x in e.operands])
        if isinstance(e, ast.Field):
            return self.field(e, self.expr(e.receiver, env))
        if isinstance(e, ast.Call):
            args = e.args
            for a in args:
                if a.name is not None:
                    raise Mistake(a.span, f"'{e.name}' takes its arguments in order, without names")
            values = [self.expr(a.value, env) for a in args]
            if e.name in ESTIMATES:
                if self.estimates is None:
                    raise Mistake(e.name_span, f"'{e.name}' is the formula's estimate: use it in a 'final' line")
                return self.estimates(e.name, values, e.span)
            function = FUNCTIONS.get(e.name)
            if function is None:
                raise Mistake(e.name_span, f"unknown function '{e.name}' in formula")
            return _within_float(e, function.apply(e, values))
        if isinstance(e, ast.Method):
            raise Mistake(e.name_span, f"'.{e.name}(...)' transforms shapes; in a formula, call "
                                       f"'{e.name}(z, ...)'")
        raise Mistake(e.span, "not an expression a formula can compute")

    def field(self, e: ast.Field, v: Value) -> Value:
        if v.type not in VECTOR_TYPES:
            raise Mistake(e.span, f"'.{e.name}' takes components of a vector, this is {_word(v)}")
        if not e.name or any(ch not in _COMPONENTS[:len(v.items)] for ch in e.name) or len(e.name) > 4:
            raise Mistake(e.name_span, f"'.{e.name}' is not a component of {_word(v)} "
                                       f"(components: {', '.join(_COMPONENTS[:len(v.items)])})")
        items = tuple(v.items[_COMPONENTS.index(ch)] for ch in e.name)
        if len(items) == 1:
            return replace(_dependent_scalar(v), items=items)
        # a projection does not lengthen: the bound a dr + b still holds
        return replace(v, type=f"vec{len(items)}", items=items)

    @staticmethod
    def chain(e: ast.Chain, values: list[Value]) -> Value:
        """Comparisons joined by '&' (and) or '|' (or), as a balanced tree."""
        for operand, v in zip(e.operands, values):
            if v.type != "mask":
                raise Mistake(operand.span, f"'{e.op}' joins comparisons ('{'and' if e.op == '&' else 'or'}'), "
                                            f"this is {_word(v)}")
        joined = ir.pairwise([v.items[0] for v in values], lambda a, b: ir.op("and" if e.op == "&" else "or", a, b))
        return Value("mask", (joined,), INDEPENDENT if all(v.independent for v in values) else None)

    def binary(self, e: ast.Binary, a: Value, b: Value) -> Value:
        op = e.op
        if "mask" in (a.type, b.type):
            raise Mistake(e.span, f"'{op}' needs numbers or vectors, not a comparison")
        if op in ("<", "<=", ">", ">=", "==", "!="):
            if a.type != "num" or b.type != "num":
                raise Mistake(e.span, f"'{op}' compares numbers, not {_word(a) if a.type != 'num' else _word(b)}"
                                      f" (compare components or lengths)")
            x, y = a.items[0], b.items[0]
            test = {"<": ("lt", x, y), "<=": ("le", x, y), ">": ("lt", y, x), ">=": ("le", y, x),
                    "==": ("eq", x, y), "!=": ("eq", x, y)}[op]
            mask = ir.op(*test)
            if op == "!=":
                mask = ir.op("not", mask)
            return Value("mask", (mask,), INDEPENDENT if a.independent and b.independent else None)
        if a.type != "num" and b.type != "num" and a.type != b.type:
            raise Mistake(e.span, f"'{op}' on vectors of different sizes ({len(a.items)} and {len(b.items)})")
        size = max(len(a.items), len(b.items))
        left = a.items * size if a.type == "num" else a.items
        right = b.items * size if b.type == "num" else b.items
        items = tuple(ir.op(op, x, y) for x, y in zip(left, right))
        underivable = a.underivable or b.underivable
        kind = "num" if size == 1 and a.type == "num" and b.type == "num" else f"vec{size}"
        if op in ("+", "-"):
            if kind == "num":
                form = INDEPENDENT if a.independent and b.independent else None
            elif "num" in (a.type, b.type):       # a number added to each component: a translation if constant
                scalar, other = (a, b) if a.type == "num" else (b, a)
                form = other.form if scalar.independent else None
            else:
                form = _summed_form(a.form, b.form)
            return Value(kind, items, form, underivable)
        if op == "/" and any(ir.is_const(x) and x.value == 0.0 for x in b.items):
            raise Mistake(e.span, "division by zero")
        if op == "*" or op == "/":
            if a.independent and b.independent:
                return Value(kind, items, INDEPENDENT, underivable)
            scalar, other = (a, b) if a.type == "num" else (b, a) if b.type == "num" else (None, None)
            form = None
            if kind != "num" and scalar is not None and scalar.independent and (op == "*" or scalar is b):
                size_ = ir.op("abs", scalar.items[0])
                form = _scaled_form(other.form, size_ if op == "*" else ir.div(ONE, size_))
            return Value(kind, items, form, underivable)
        raise Mistake(e.span, f"unknown operator '{op}'")


def _joined(parts: list[Value]) -> Value:
    """A vector from numbers and vectors: (z, w) is a 4-vector."""
    items = tuple(c for v in parts for c in v.items)
    dependent = [v for v in parts if not v.independent]
    form = INDEPENDENT
    if len(dependent) == 1 and dependent[0].type in VECTOR_TYPES:
        form = dependent[0].form         # z with constants beside it: as long as z
    elif dependent:
        form = None
    return Value(f"vec{len(items)}" if len(items) > 1 else "num", items, form,
                 next((v.underivable for v in parts if v.underivable), None))


def _chosen(condition: Value, a: list[Value], b: list[Value]) -> list[Value]:
    """Each of `a` where the condition holds, else of `b`, as one IR branch
    (only the rays that need a side compute it)."""
    then, otherwise, layout = [], [], []
    for x, y in zip(a, b):
        forms = x.form is not None and y.form is not None
        layout.append((len(x.items), forms))
        then += [*x.items, *(x.form if forms else ())]
        otherwise += [*y.items, *(y.form if forms else ())]
    chosen = ir.branch(condition.items[0], tuple(then), tuple(otherwise)) if then else ()
    values, i = [], 0
    for x, y, (n, forms) in zip(a, b, layout):
        items, form = tuple(chosen[i:i + n]), (tuple(chosen[i + n:i + n + 2]) if forms else None)
        i += n + 2 * forms
        if forms and all(ir.is_const(f) and f.value == 0.0 for f in form):
            form = INDEPENDENT
        values.append(Value(x.type, items, form, x.underivable or y.underivable))
    return values


# ---- functions -----------------------------------------------------------------

@dataclass(frozen=True)
class Function:
    """A function formulas can call: its arguments' types (`v` a vector of
    z's size, `n` a number, `3` a 3-vector, `4` a 4-vector, `any` a
    number or vector, `m` a comparison; `?` after a type: optional), and
    how it computes."""
    arguments: tuple[str, ...]
    compute: Callable
    about: str

    def apply(self, e: ast.Call, values: list[Value]) -> Value:
        required = [a for a in self.arguments if not a.endswith("?")]
        if not len(required) <= len(values) <= len(self.arguments):
            count = f"{len(required)}" if len(required) == len(self.arguments) else \
                f"{len(required)} to {len(self.arguments)}"
            raise Mistake(e.span, f"'{e.name}' takes {count} argument{'s' if len(self.arguments) != 1 else ''} "
                                  f"({self.about}), not {len(values)}")
        size = None
        for arg, want, v in zip(e.args, self.arguments, values):
            want = want.rstrip("?")
            ok = {"n": v.type == "num", "3": v.type == "vec3", "4": v.type == "vec4", "m": v.type == "mask",
                  "v": v.type in VECTOR_TYPES, "any": v.type != "mask"}[want]
            if want == "v" and ok:
                if size is not None and len(v.items) != size:
                    raise Mistake(arg.span, f"'{e.name}' needs vectors of one size ({size} and {len(v.items)})")
                size = len(v.items)
            if not ok:
                words = {"n": "a number", "3": "a 3-vector", "4": "a 4-vector", "m": "a comparison",
                         "v": "a vector", "any": "a number or a vector"}
                raise Mistake(arg.span, f"'{e.name}' needs {words[want]} here ({self.about}), this is {_word(v)}")
        try:
            return self.compute(e.span, *values)
        except (ValueError, ZeroDivisionError, OverflowError):
            raise Mistake(e.span, f"'{e.name}' is undefined for these values") from None


def _block(make: Callable):
    """A building block of formulas.py as a function: its result keeps z's
    form times the block's factor where the block has one and its other
    arguments do not depend on the point."""
    def compute(span: Span, z: Value, *rest: Value):
        block = make(z.items, *(r.items if r.type in VECTOR_TYPES else r.items[0] for r in rest))
        others_independent = all(r.independent for r in rest)
        form = _scaled_form(z.form, block.factor) if block.factor is not None and others_independent else None
        if z.independent and others_independent:
            form = INDEPENDENT
        return Value(f"vec{len(block.z)}", tuple(block.z), form,
                     next((v.underivable for v in (z, *rest) if v.underivable), None))
    return compute


def _box_fold(span: Span, z: Value, limit: Value) -> Value:
    if limit.type != "num" and len(limit.items) != len(z.items):
        raise Mistake(span, f"'box_fold' needs one limit or {len(z.items)} (one per axis of z), "
                            f"not {len(limit.items)}")
    return _block(formulas.box_fold)(span, z, limit)


def _map(name: str, derivable: bool = True):
    """A function of numbers applied per component (numbers broadcast)."""
    def compute(span: Span, *values: Value):
        size = max(len(v.items) for v in values)
        lanes = [v.items * size if v.type == "num" else v.items for v in values]
        if any(len(lane) != size for lane in lanes):
            raise Mistake(span, f"'{name}' on vectors of different sizes")
        items = tuple(ir.op(name, *args) for args in zip(*lanes))
        independent = all(v.independent for v in values)
        underivable = next((v.underivable for v in values if v.underivable), None)
        if not derivable and not independent:
            underivable = underivable or span
        form = INDEPENDENT if independent else None
        if name == "abs" and size > 1 and values[0].form is not None:
            form = values[0].form              # the octant fold: lengths kept
        kind = "num" if size == 1 else f"vec{size}"
        return Value(kind, items, form, underivable)
    return compute


def _select(span: Span, condition: Value, a: Value, b: Value) -> Value:
    """Per component, both sides computed (cheap ones; 'if' computes only the side a ray needs)."""
    if a.type != b.type:
        raise Mistake(span, f"'select' chooses between values of one type, not {_word(a)} and {_word(b)}")
    forms = a.form is not None and b.form is not None
    form = tuple(ir.op("select", condition.items[0], x, y) for x, y in zip(a.form, b.form)) if forms else None
    if forms and all(ir.is_const(x) and x.value == 0.0 for x in form):
        form = INDEPENDENT
    return Value(a.type, tuple(ir.op("select", condition.items[0], x, y) for x, y in zip(a.items, b.items)), form,
                 a.underivable or b.underivable)


def _vector_fn(function: Callable, result: str):
    def compute(span: Span, *values: Value):
        items = function(*(v.items for v in values))
        items = items if isinstance(items, tuple) else (items,)
        return replace(_dependent_scalar(*values),
                       type=result if result != "same" else values[0].type, items=items)
    return compute


def _normalize(v):
    inverse = ir.div(ONE, ir.length(v))
    return tuple(ir.mul(x, inverse) for x in v)


def _cross(a, b):
    return (ir.sub(ir.mul(a[1], b[2]), ir.mul(a[2], b[1])), ir.sub(ir.mul(a[2], b[0]), ir.mul(a[0], b[2])),
            ir.sub(ir.mul(a[0], b[1]), ir.mul(a[1], b[0])))


def _quaternion_multiply(span: Span, a: Value, b: Value) -> Value:
    items = formulas.quaternion_multiply(a.items, b.items)
    form = None
    if a.independent and b.independent:
        form = INDEPENDENT
    elif a.independent or b.independent:          # times a constant quaternion: a scale and a rotation
        fixed, moving = (a, b) if a.independent else (b, a)
        form = _scaled_form(moving.form, ir.length(fixed.items))
    return Value("vec4", items, form, a.underivable or b.underivable)


FUNCTIONS: dict[str, Function] = {
    # building blocks (formulas.py), each with its derivative rule
    "box_fold": Function(("v", "any"), _box_fold, "box_fold(z, limit or limits)"),
    "sphere_fold": Function(("v", "n", "n"), _block(formulas.sphere_fold),
                            "sphere_fold(z, min_radius, fixed_radius)"),
    "sphere_invert": Function(("v", "n"), _block(formulas.sphere_invert), "sphere_invert(z, radius)"),
    "reflect": Function(("v", "v", "n?"), _block(formulas.reflect), "reflect(z, normal, offset)"),
    "plane_fold": Function(("v", "v", "n?"), _block(formulas.plane_fold), "plane_fold(z, normal, offset)"),
    "abs_fold": Function(("v",), _block(formulas.abs_fold), "abs_fold(z)"),
    "sort_fold": Function(("3",), _block(formulas.sort_fold), "sort_fold(z)"),
    "rotate": Function(("3", "3", "n"), _block(formulas.rotate), "rotate(z, axis, degrees)"),
    "scale": Function(("v", "n", "v?"), _block(formulas.scale), "scale(z, factor, centre)"),
    "stretch": Function(("v", "v"), _block(formulas.stretch), "stretch(z, factors)"),
    "translate": Function(("v", "v"), _block(formulas.translate), "translate(z, offset)"),
    "triplex_power": Function(("3", "n"), _block(formulas.triplex_power), "triplex_power(z, power)"),
    "quaternion_square": Function(("4",), _block(formulas.quaternion_square), "quaternion_square(q)"),
    "quaternion_multiply": Function(("4", "4"), _quaternion_multiply, "quaternion_multiply(a, b)"),
    # math
    **{name: Function(("any",), _map(name), f"{name}(x)")
       for name in ("sin", "cos", "tan", "asin", "acos", "atan", "sqrt", "rsqrt", "abs", "exp", "log", "radians",
                    "degrees")},
    **{name: Function(("any",), _map(name, derivable=False), f"{name}(x)") for name in ("floor", "round")},
    "atan2": Function(("any", "any"), _map("atan2"), "atan2(y, x)"),
    "min": Function(("any", "any"), _map("min"), "min(a, b)"),
    "max": Function(("any", "any"), _map("max"), "max(a, b)"),
    "pow": Function(("any", "any"), _map("pow"), "pow(x, y)"),
    "clamp": Function(("any", "any", "any"), _map("clamp"), "clamp(x, low, high)"),
    "mix": Function(("any", "any", "any"), _map("mix"), "mix(a, b, t)"),
    "select": Function(("m", "any", "any"), _select, "select(condition, if_true, if_false)"),
    "length": Function(("v",), _vector_fn(ir.length, "num"), "length(v)"),
    "dot": Function(("v", "v"), _vector_fn(ir.dot, "num"), "dot(a, b)"),
    "cross": Function(("3", "3"), _vector_fn(_cross, "vec3"), "cross(a, b)"),
    "normalize": Function(("v",), _vector_fn(_normalize, "same"), "normalize(v)"),
}


# ---- the orbit ------------------------------------------------------------------

@dataclass(frozen=True)
class Use:
    """A formula with its arguments (IR, in its parameters' order), applied
    `count` times in turn in a hybrid."""
    formula: Formula
    args: tuple
    count: int = 1


@dataclass(frozen=True)
class Orbit:
    distance: ir.Expr
    trap: tuple[ir.Expr, ...]       # origin, |x|, |y|, |z|, the steps taken (empty unless asked for)
    scalar: bool                    # the estimate from a scalar running derivative (else the Jacobian or own)
    # -1 where the orbit stays within the bailout for all its iterations (the
    # escape-time set: what the formula means), 1 where it escapes; None without a bailout
    inside: ir.Expr | None = None


def _arg_value(arg) -> Value:
    return vector(arg.items) if isinstance(arg, ir.Vec) else number(arg)


def _environment(use: Use) -> dict[str, Value]:
    return {name: _arg_value(a) for name, a in zip(use.formula.params, use.args)}


def _readonly(use: Use) -> frozenset:
    return frozenset(("c",) + use.formula.params)


# ---- the estimate's kind: |z|'s growth, measured --------------------------------

class Estimate(enum.Enum):
    LINEAR = "linear"               # (r - offset) / |dr|: folds, IFS, boxes
    ESCAPE_TIME = "escape-time"     # 0.5 r ln r / |dr|: z grows faster than linearly (powers)


# A step's growth is the exponent k of |F(z)| ~ |z|^k far out, from |z| at
# these radii (c near the origin), the median over seeded directions; above
# ESCAPE_GROWTH the escape-time estimate (z^2 + c grows as 2, a fold or an
# IFS step as 1, Kaliset's abs(z) / |z|^2 + c as 0).
GROWTH_RADII = (1e2, 1e4)
ESCAPE_GROWTH = 1.5
_GROWTH_DIRECTIONS = 32
_NEAR = (0.1, -0.2, 0.3)            # c while measuring (Mandelbrot mode): a point near the origin
# The sample point as IR, where formulas are checked and measured
POINT = tuple(ir.Comp(ir.Var("p", ir.VEC3), i) for i in range(3))


@dataclass(frozen=True)
class Growth:
    """How fast a fractal's |z| grows per step far out, as measured: the
    largest exponent among its formulas, whose it is, and so its estimate."""
    exponent: float
    formula: str

    @property
    def estimate(self) -> Estimate:
        return Estimate.ESCAPE_TIME if self.exponent > ESCAPE_GROWTH else Estimate.LINEAR

    def reason(self) -> str:
        """Which estimate, and why, in words."""
        grows = "faster than any power" if math.isinf(self.exponent) else f"as |z|^{self.exponent:.2f}"
        low, high = (f"{r:g}" for r in GROWTH_RADII)
        escape = self.estimate is Estimate.ESCAPE_TIME
        return (f"{'the escape-time estimate 0.5 r ln r / dr' if escape else 'the linear estimate r / dr'}: a step "
                f"of '{self.formula}' grows |z| {grows} far out (measured from |z| = {low} to {high}), "
                f"{'' if escape else 'no '}faster than |z|^{ESCAPE_GROWTH:g}")


def growth(sequence: tuple[Use, ...], julia: ir.Vec | None = None,
           param_values: tuple[tuple[float, ...], ...] = ((),)) -> Growth:
    """Measure how each formula of `sequence` grows |z| far out (for each
    set of the scene's param values given: the largest); the estimate's
    kind follows from it, whatever the steps' spelling."""
    directions = np.random.default_rng(0).normal(size=(_GROWTH_DIRECTIONS, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = np.concatenate([GROWTH_RADII[0] * directions, GROWTH_RADII[1] * directions])
    found = []
    for use in _unique(sequence):
        far = _far_step_length(use, julia)
        exponent = 0.0
        for values in param_values:
            near_length, far_length = np.split(ir.evaluate_at((far,), points, values)[0], 2)
            with np.errstate(all="ignore"):
                k = np.log(far_length / near_length) / math.log(GROWTH_RADII[1] / GROWTH_RADII[0])
            k = np.where(np.isfinite(far_length), np.nan_to_num(k, nan=0.0), math.inf)
            exponent = max(exponent, float(np.median(k)))
        found.append(Growth(exponent, use.formula.name))
    return max(found, key=lambda g: g.exponent)


def _far_step_length(use: Use, julia: ir.Vec | None) -> ir.Expr:
    """|z| after one step of the formula from z = the point (taken far
    out), with c near the origin (or the Julia constant)."""
    near = vector(tuple(ir.const(x) for x in _NEAR))
    start = Interpreter().run(use.formula.init, {"c": near, **_environment(use), "z": near}, _readonly(use))
    extra = (ZERO,) * (len(start["z"].items) - 3)
    fits = julia is not None and len(julia.items) == len(start["z"].items)     # else orbit's mistake
    env = {"c": vector(julia.items) if fits else vector((*near.items, *extra)),
           **_environment(use), **{name: start[name] for name in use.formula.carried if name != "z"},
           "z": vector((*POINT, *extra), (ONE, ZERO))}
    return ir.length(Interpreter().run(use.formula.step, env, _readonly(use))["z"].items)


def z_size(use: Use, point: tuple[ir.Expr, ...]) -> int:
    """The components of the formula's z: 4 where its own `init` makes it a
    4-vector (`init z = (z, w)`), else the point's 3."""
    z = vector(point, (ONE, ZERO))
    out = Interpreter().run(use.formula.init, {"c": _constant(None, z, point), **_environment(use), "z": z},
                            _readonly(use))
    return len(out["z"].items)


def orbit(sequence: tuple[Use, ...], point: tuple[ir.Expr, ...], iterations: ir.Expr,
          bailout: ir.Expr | None = None, julia: ir.Vec | None = None, trap: bool = False,
          jacobian: bool | None = None, where: Span | None = None, estimate: Estimate | None = None) -> Orbit:
    """The estimate of the fractal of a formula, or a hybrid of several
    applied in turn (`count` steps each), `iterations` steps in all; a ray
    stops once |z| > bailout or a step would take z beyond OVERFLOW_LENGTH.
    `estimate` is its kind (None: measured now, `growth`, for formulas
    whose arguments are constants); without a bailout, escape-time
    formulas take DEFAULT_BAILOUT and the others none. Raises Mistake (at
    `where`, the use, for the use's own mistakes)."""
    interpreter = Interpreter()
    uses = _unique(sequence)

    # init: each formula's carried values, in order; z starts as the point
    z = vector(point, (ONE, ZERO))
    carried: list[dict[str, Value]] = []
    for use in uses:
        env = {"c": _constant(julia, z, point), **_environment(use), "z": z}
        out = interpreter.run(use.formula.init, env, _readonly(use))
        z = out["z"]
        if z.type not in ("vec3", "vec4"):
            assigned = next(s for s in use.formula.init if s.name == "z")
            raise Mistake(assigned.value.span, f"z must be a 3- or 4-vector, this is {_word(z)}")
        carried.append({name: out[name] for name in use.formula.carried if name != "z"})
    if julia is not None and len(julia.items) != len(z.items):
        raise Mistake(where or sequence[0].formula.span, f"'julia' must be a {len(z.items)}-vector like z, "
                                                          f"not a {len(julia.items)}-vector")
    c = _constant(julia, z, point)

    # which carried values depend on the point (the scalar derivative then cannot follow them)
    dependent: list[set] = [set() for _ in uses]
    for _ in range(8):
        probes = _step_values(interpreter, uses, carried, dependent, z, c)
        grown = [{n for n, v in values.items() if n != "z" and not v.independent} for values in probes]
        if all(g <= d for g, d in zip(grown, dependent)):
            break
        dependent = [d | g for d, g in zip(dependent, grown)]
    z_forms = [values["z"] for values in probes]
    hybrid_dims = {len(use_z.items) for use_z in z_forms} | {len(z.items)}
    for use, value in zip(uses, z_forms):
        if value.type != z.type and len(uses) > 1 and len(hybrid_dims) > 1:
            raise Mistake(where or use.formula.span, "a hybrid's formulas must all work on 3-vectors "
                                                     "or all on 4-vectors")
        if value.type != z.type:
            assigned = _last_z(use.formula)
            raise Mistake(assigned.span if assigned else use.formula.span,
                          f"z is {_word(z)} before the step and {_word(value)} after it")
    own = [u for u in uses if u.formula.own_estimate]
    if own and len(sequence) > 1:
        raise Mistake(where or own[0].formula.span, f"'{own[0].formula.name}' gives its own 'final distance': "
                                           "it cannot be part of a hybrid")
    if not own:
        for use, value in zip(uses, z_forms):
            if value.underivable is not None:
                raise Mistake(value.underivable, "the distance estimate cannot be derived through this "
                                                 "(it has no derivative): give the formula its own "
                                                 "'final distance = ...'")
    conformal = all(v.form is not None for v in z_forms) and not own
    use_scalar = conformal if jacobian is None else (not jacobian and conformal)
    if estimate is None:
        estimate = growth(sequence, julia).estimate
    escape = estimate is Estimate.ESCAPE_TIME
    if bailout is None and escape:
        bailout = ir.const(DEFAULT_BAILOUT)

    steps = [(k, use) for k, use in enumerate(uses) for _ in range(_count(sequence, use))]
    period = len(steps)
    dims = len(z.items)
    stops = any(_assignment(use.formula, "stop") for use in uses)
    # whether a ray can stop before the last step: else nothing reads `stopped`
    # (a ray past the overflow limit keeps its state anyway: the selects below)
    stoppable = bailout is not None or stops or period > 1
    # the loop's carried values, by name: z, each formula's own, dr (the
    # scalar derivative), whether the ray stopped, the step count of a
    # hybrid and the orbit trap
    layout = [("z", dims), *(((k, name), len(v.items)) for k, values in enumerate(carried)
                            for name, v in values.items())]
    layout += ([("dr", 1)] * use_scalar + [("stopped", 1)] * stoppable + [("counter", 1)] * (period > 1)
               + [("trap", 4), ("steps", 1)] * trap)

    def unpack(state) -> dict:
        fields, i = {}, 0
        for key, width in layout:
            fields[key] = tuple(state[i:i + width])
            i += width
        return fields

    def pack(fields: dict) -> tuple:
        return tuple(x for key, _ in layout for x in fields[key])

    def formula_values(fields: dict, k: int, forms: bool) -> dict:
        return {name: replace(v, items=fields[(k, name)],
                              form=(None if name in dependent[k] else INDEPENDENT) if forms else v.form)
                for name, v in carried[k].items()}

    def round_(state):
        fields = unpack(state)
        z_now = Value(z.type, fields["z"], (ONE, ZERO))
        stopped = fields["stopped"][0] if stoppable else None
        for j, (k, use) in enumerate(steps):
            # with one step per iteration the loop's condition stops the ray
            going = ir.Const(1.0, ir.MASK)
            if period > 1:
                going = ir.op("and", ir.op("not", stopped),
                              ir.op("lt", ir.add(fields["counter"][0], ir.const(float(j))), iterations))
                if bailout is not None:
                    going = ir.op("and", going, _inside(z_now.items, bailout))
            env = {"c": c, **_environment(use), **formula_values(fields, k, True), "z": z_now}
            out = interpreter.run(use.formula.step, env, _readonly(use))
            moved = out["z"]
            ok = ir.op("and", going, ir.op("le", ir.dot(moved.items, moved.items), ir.const(OVERFLOW_LENGTH ** 2)))
            kept = {"z": moved.items, **{(k, name): out[name].items for name in carried[k]}}
            if use_scalar:
                a, b = moved.form
                kept["dr"] = (ir.op("min", ir.add(ir.mul(a, fields["dr"][0]), b), ir.const(MAX_DERIVATIVE)),)
            if trap:   # `trap = point`: where the orbit trap measures (else z)
                kept["trap"] = _trap_added(fields["trap"], out["trap"].items if "trap" in out else moved.items)
                kept["steps"] = (ir.add(fields["steps"][0], ONE),)
            for key, items in kept.items():
                fields[key] = tuple(ir.op("select", ok, a, b) for a, b in zip(items, fields[key]))
            if stoppable:
                stopped = ir.op("or", stopped, ir.op("and", going, ir.op("not", ok)))
            if "stop" in out:               # `stop = condition`: these rays iterate no more
                stopped = ir.op("or", stopped, ir.op("and", ok, out["stop"].items[0]))
            z_now = Value(z.type, fields["z"], (ONE, ZERO))
        if stoppable:
            fields["stopped"] = (stopped,)
        if period > 1:
            fields["counter"] = (ir.add(fields["counter"][0], ir.const(float(period))),)
        return pack(fields)

    start = {"z": z.items, **{(k, name): v.items for k, values in enumerate(carried) for name, v in values.items()},
             "dr": (ONE,), "stopped": (ir.Const(0.0, ir.MASK),), "counter": (ZERO,),
             "trap": (ir.const(1e30),) * 4, "steps": (ZERO,)}
    count = iterations if period == 1 else ir.op("floor", ir.div(ir.add(iterations, ir.const(period - 1.0)),
                                                                   ir.const(float(period))))

    def condition(state):
        if bailout is None and not stops:
            return None     # a hybrid's steps check `stopped` themselves
        fields = unpack(state)
        going = ir.op("not", fields["stopped"][0])
        return going if bailout is None else ir.op("and", going, _inside(fields["z"], bailout))

    fields = unpack(ir.loop(pack(start), count, round_, condition))
    z_final = fields["z"]
    finals = [formula_values(fields, k, False) for k in range(len(carried))]
    dr = fields["dr"][0] if use_scalar else None
    traps = (*fields["trap"], *fields["steps"]) if trap else ()

    last = uses[-1]
    final_z, final_values, rows = tuple(z_final), finals[-1], None
    if not use_scalar and not own:
        # z's Jacobian: the final lines read z and the carried values from the
        # loop that carries the tangents too, so the iterations run once
        items = [x for v in final_values.values() for x in v.items]
        rebuilt, all_rows = _jacobian((*final_z, *items), point, _last_z(last.formula).span)
        final_z, rows, values = rebuilt[:dims], all_rows[:dims], iter(rebuilt[dims:])
        final_values = {name: replace(v, items=tuple(next(values) for _ in v.items))
                        for name, v in final_values.items()}

    def estimate(name: str, args: list[Value], span: Span) -> Value:
        offset = args[0].items[0] if args else ZERO
        if args and (len(args) > 1 or args[0].type != "num"):
            raise Mistake(span, f"'{name}' takes at most one number (the linear estimate's offset)")
        return number(_estimate(name == "escape_time_estimate", final_z, rows, dr, offset))

    if last.formula.final:
        env = {"c": c, **_environment(last), **final_values, "z": Value(z.type, final_z, None),
               **{name: number(_derivative(name, final_z, rows, dr)) for name in last.formula.derived}}
        out = Interpreter(estimate).run(last.formula.final, env, _readonly(last) | set(last.formula.derived))
        distance = out.get("distance")
        if distance is None:
            raise Mistake(last.formula.final[-1].span, "'final' lines must set 'distance' (the estimate)")
        if distance.type != "num":
            assigned = next(s for s in reversed(last.formula.final) if s.name == "distance")
            raise Mistake(assigned.value.span, f"'distance' must be a number, this is {_word(distance)}")
        de = derive.finite_distance(distance.items[0])    # the formula's own: guarded as a derived one is
    else:
        de = _estimate(escape, final_z, rows, dr, ZERO)
    inside = None if bailout is None else ir.op("select", _inside(z_final, bailout), ir.const(-1.0), ONE)
    return Orbit(de, traps, use_scalar, inside)


def _within_float(e: ast.Expr, value: Value) -> Value:
    """`value`, where what it computes from constants alone is a number the
    kernel's floats hold, as in a scene's expressions (check.py); a float
    kernel would compute infinity."""
    for item in value.items:
        if ir.is_const(item) and not ir.in_float_range(item.value):
            raise Mistake(e.span, f"this gives {item.value:.3g}, beyond the kernel's floats ({ir.FLOAT_MAX:.3g})")
    return value


def _jacobian(values, point, where: Span):
    """derive.jacobian, its failure a Mistake at `where`."""
    try:
        return derive.jacobian(values, point)
    except (ValueError, ZeroDivisionError, OverflowError):
        # a rule meeting constants outside its domain: 1 / 0 in the derivative of x / 0, of sqrt(0), ...
        raise Mistake(where, "the derivative of this step is undefined for its constants (a division by "
                             "zero, or sqrt, log, asin or acos at the end of their domain)") from None


def _derivative(name: str, z, rows, dr) -> ir.Expr:
    """A DERIVED value at the orbit's end: from the scalar running
    derivative `dr`, or from z's Jacobian `rows` (None on the scalar path)."""
    if rows is None:
        return ir.op("abs", dr)        # a similarity's Jacobian is |dr| times a rotation
    if name == "dr":
        return derive.finite_estimate(derive.gradient_length(z, rows), ir.length(z))
    return derive.spectral_norm(rows)


def _estimate(escape: bool, z, rows, dr, offset: ir.Expr) -> ir.Expr:
    """The escape-time or linear estimate, from z's Jacobian `rows` (the
    Jacobian path) or the scalar running derivative `dr` (rows None)."""
    if rows is not None:
        return derive.escape_time_estimate(z, rows) if escape else derive.linear_estimate(z, rows, offset)
    r = ir.length(z)
    if escape:
        estimate = derive.finite_estimate(ir.mul(ir.mul(ir.const(0.5), ir.op("log", r)), r), ir.op("abs", dr))
        return ir.op("select", ir.op("eq", r, ZERO), ZERO, estimate)
    return derive.finite_estimate(ir.sub(r, offset), ir.op("abs", dr))


def _inside(z, bailout: ir.Expr) -> ir.Expr:
    # |z| itself, not |z|^2 against bailout^2: formulas compute |z| anyway, and it is then computed once
    return ir.op("le", ir.length(z), bailout)


def _trap_added(traps, z) -> tuple:
    return (ir.op("min", traps[0], ir.length(z[:3])), *(ir.op("min", t, ir.op("abs", x)) for t, x in zip(traps[1:], z)))


def _constant(julia, z: Value, point) -> Value:
    """c: the point (beside zeros where z has a fourth component), or the Julia constant."""
    if julia is not None:
        return vector(julia.items)
    extra = (ZERO,) * (len(z.items) - 3)
    return vector((*point, *extra), (ZERO, ONE))


def _unique(sequence) -> list:
    """The uses of a hybrid, each formula with its arguments once (a file's
    formula and the library's of the same name are two)."""
    seen, out = set(), []
    for use in sequence:
        key = (use.formula, use.args)
        if key not in seen:
            seen.add(key)
            out.append(use)
    return out


def _count(sequence, use) -> int:
    return sum(u.count for u in sequence if (u.formula, u.args) == (use.formula, use.args))


def _assignment(formula: Formula, name: str):
    """The last step statement that sets `name`, or None."""
    found = None
    for s in formula.step:
        for inner in (s, *_nested(s)):
            if isinstance(inner, ast.Assign) and inner.name == name:
                found = inner
    return found


def _last_z(formula: Formula):
    return _assignment(formula, "z")


def _step_values(interpreter, uses, carried, dependent, z: Value, c: Value) -> list[dict]:
    """Each formula's values after one step from symbolic state, for
    their forms (which values depend on the point)."""
    results = []
    probe_z = Value(z.type, tuple(ir.Var(f"z.{i}", ir.REAL) for i in range(len(z.items))), (ONE, ZERO))
    for k, use in enumerate(uses):
        env = {"c": c, **_environment(use), "z": probe_z}
        for name, v in carried[k].items():
            env[name] = replace(v, items=tuple(ir.Var(f"{name}.{i}", ir.REAL) for i in range(len(v.items))),
                                form=None if name in dependent[k] else INDEPENDENT)
        out = interpreter.run(use.formula.step, env, _readonly(use))
        if _last_z(use.formula) is None:
            raise Mistake(use.formula.span, f"'{use.formula.name}' never sets z in its step")
        for name, want in (("stop", "mask"), ("trap", "vec3")):
            if name in out and out[name].type != want:
                raise Mistake(_assignment(use.formula, name).span,
                              f"'{name}' must be {_WORDS[want]}, this is {_word(out[name])}")
        for name, v in carried[k].items():
            if name not in out:
                raise Mistake(use.formula.span, f"'{name}' is set on only one side of an 'if'")
            if out[name].type != v.type:
                raise Mistake(use.formula.span, f"'{name}' starts as {_word(v)} and becomes {_word(out[name])}")
        results.append({"z": out["z"], **{name: out[name] for name in carried[k]}})
    return results
