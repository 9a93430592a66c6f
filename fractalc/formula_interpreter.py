"""Runs a formula's statements on Values (fractalc/formula_values.py): the
expressions, `if` with both sides, and the functions formulas call (the
building blocks of fractalc/formulas.py with their derivative rules, and
the math functions scenes have too, stdlib.MATH)."""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

from . import ast, formulas, ir
from .errors import Span
from .expressions import (Mistake, argument_count, beyond_floats, broadcast, component_not_number, components,
                          different_sizes, named_argument, not_numbers, require_vector_size, uncalled_function,
                          undefined, wrong_argument)
from .formula_statements import DERIVED, ESTIMATES
from .formula_values import (INDEPENDENT, MASK, NUMBER, ONE, Value, dependent_scalar,
                             number, scaled_form, summed_form, word)
from .stdlib import MATH
from .types import VECTOR_TYPES, Type, in_float_range, vector_type


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
        if condition.type != MASK:
            raise Mistake(s.condition.span, f"'if' needs a comparison (such as 'r < 1'), this is {word(condition)}")
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
                raise Mistake(s.span, f"'{name}' is {word(a)} after 'if' and {word(b)} after 'else'")
            else:
                differ.append(name)
        # one branch for all the values the sides set differently
        merged.update(zip(differ, chosen(condition, [then[n] for n in differ], [otherwise[n] for n in differ])))
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
                raise Mistake(e.span, uncalled_function(e.name))
            if e.name in DERIVED:
                raise Mistake(e.span, f"'{e.name}' is the compiler's derivative at the orbit's end: only 'final' "
                                      f"lines read it")
            raise Mistake(e.span, f"unknown name '{e.name}' in formula")
        if isinstance(e, ast.Vector):
            parts = [self.expr(x, env) for x in e.items]
            for x, v in zip(e.items, parts):
                if v.type == MASK:
                    raise Mistake(x.span, component_not_number(v.type))
            require_vector_size(e, sum(len(v.items) for v in parts))
            return joined(parts)
        if isinstance(e, ast.Unary):
            v = self.expr(e.operand, env)
            if v.type == MASK:
                raise Mistake(e.span, "a comparison cannot be negated (swap the comparison instead)")
            return replace(v, items=tuple(ir.neg(x) for x in v.items))
        if isinstance(e, ast.Binary):
            left, right = self.expr(e.left, env), self.expr(e.right, env)
            try:
                return within_float(e, self.binary(e, left, right))
            except (ValueError, ZeroDivisionError, OverflowError):
                raise Mistake(e.span, undefined(e.op)) from None
        if isinstance(e, ast.Chain):
            return self.chain(e, [self.expr(x, env) for x in e.operands])
        if isinstance(e, ast.Field):
            return self.field(e, self.expr(e.receiver, env))
        if isinstance(e, ast.Call):
            args = e.args
            for a in args:
                if a.name is not None:
                    raise Mistake(a.span, named_argument(e.name))
            values = [self.expr(a.value, env) for a in args]
            if e.name in ESTIMATES:
                if self.estimates is None:
                    raise Mistake(e.name_span, f"'{e.name}' is the formula's estimate: use it in a 'final' line")
                return self.estimates(e.name, values, e.span)
            function = FUNCTIONS.get(e.name)
            if function is None:
                raise Mistake(e.name_span, f"unknown function '{e.name}' in formula")
            return within_float(e, function.apply(e, values))
        if isinstance(e, ast.Method):
            raise Mistake(e.name_span, f"'.{e.name}(...)' transforms shapes; in a formula, call "
                                       f"'{e.name}(z, ...)'")
        raise Mistake(e.span, "not an expression a formula can compute")

    def field(self, e: ast.Field, v: Value) -> Value:
        items = components(e, v.type, v.items)
        if len(items) == 1:
            return replace(dependent_scalar(v), items=items)
        # a projection does not lengthen: the bound a dr + b still holds
        return replace(v, type=vector_type(len(items)), items=items)

    @staticmethod
    def chain(e: ast.Chain, values: list[Value]) -> Value:
        """Comparisons joined by '&' (and) or '|' (or), as a balanced tree."""
        for operand, v in zip(e.operands, values):
            if v.type != MASK:
                raise Mistake(operand.span, f"'{e.op}' joins comparisons ('{'and' if e.op == '&' else 'or'}'), "
                                            f"this is {word(v)}")
        joined = ir.pairwise([v.items[0] for v in values], lambda a, b: ir.op("and" if e.op == "&" else "or", a, b))
        return Value(MASK, (joined,), INDEPENDENT if all(v.independent for v in values) else None)

    def binary(self, e: ast.Binary, a: Value, b: Value) -> Value:
        op = e.op
        if MASK in (a.type, b.type):
            raise Mistake(e.span, not_numbers(op, MASK))
        if op in ("<", "<=", ">", ">=", "==", "!="):
            if a.type != NUMBER or b.type != NUMBER:
                raise Mistake(e.span, f"'{op}' compares numbers, not {word(a) if a.type != NUMBER else word(b)}"
                                      f" (compare components or lengths)")
            x, y = a.items[0], b.items[0]
            test = {"<": ("lt", x, y), "<=": ("le", x, y), ">": ("lt", y, x), ">=": ("le", y, x),
                    "==": ("eq", x, y), "!=": ("eq", x, y)}[op]
            mask = ir.op(*test)
            if op == "!=":
                mask = ir.op("not", mask)
            return Value(MASK, (mask,), INDEPENDENT if a.independent and b.independent else None)
        combined = broadcast([(a.type, a.items), (b.type, b.items)])
        if combined is None:
            raise Mistake(e.span, different_sizes(op, (len(a.items), len(b.items))))
        size, (left, right) = combined
        items = tuple(ir.op(op, x, y) for x, y in zip(left, right))
        underivable = a.underivable or b.underivable
        kind = NUMBER if size == 1 and a.type == NUMBER and b.type == NUMBER else vector_type(size)
        if op in ("+", "-"):
            if kind == NUMBER:
                form = INDEPENDENT if a.independent and b.independent else None
            elif NUMBER in (a.type, b.type):       # a number added to each component: a translation if constant
                scalar, other = (a, b) if a.type == NUMBER else (b, a)
                form = other.form if scalar.independent else None
            else:
                form = summed_form(a.form, b.form)
            return Value(kind, items, form, underivable)
        if op == "/" and any(ir.is_const(x) and x.value == 0.0 for x in b.items):
            raise Mistake(e.span, "division by zero")
        if op == "*" or op == "/":
            if a.independent and b.independent:
                return Value(kind, items, INDEPENDENT, underivable)
            scalar, other = (a, b) if a.type == NUMBER else (b, a) if b.type == NUMBER else (None, None)
            form = None
            if kind != NUMBER and scalar is not None and scalar.independent and (op == "*" or scalar is b):
                size_ = ir.op("abs", scalar.items[0])
                form = scaled_form(other.form, size_ if op == "*" else ir.div(ONE, size_))
            return Value(kind, items, form, underivable)
        raise Mistake(e.span, f"unknown operator '{op}'")


def joined(parts: list[Value]) -> Value:
    """A vector from numbers and vectors: (z, w) is a 4-vector."""
    items = tuple(c for v in parts for c in v.items)
    dependent = [v for v in parts if not v.independent]
    form = INDEPENDENT
    if len(dependent) == 1 and dependent[0].type in VECTOR_TYPES:
        form = dependent[0].form         # z with constants beside it: as long as z
    elif dependent:
        form = None
    return Value(vector_type(len(items)) if len(items) > 1 else NUMBER, items, form,
                 next((v.underivable for v in parts if v.underivable), None))


def chosen(condition: Value, a: list[Value], b: list[Value]) -> list[Value]:
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
            raise Mistake(e.span, argument_count(e.name, len(required), len(self.arguments), self.about, len(values)))
        size = None
        for arg, want, v in zip(e.args, self.arguments, values):
            want = want.rstrip("?")
            ok = {"n": v.type == NUMBER, "3": v.type == Type.VEC3, "4": v.type == Type.VEC4, "m": v.type == MASK,
                  "v": v.type in VECTOR_TYPES, "any": v.type != MASK}[want]
            if want == "v" and ok:
                if size is not None and len(v.items) != size:
                    raise Mistake(arg.span, different_sizes(e.name, (size, len(v.items))))
                size = len(v.items)
            if not ok:
                words = {"n": "a number", "3": "a 3-vector", "4": "a 4-vector", "m": "a comparison",
                         "v": "a vector", "any": "a number or a vector"}
                raise Mistake(arg.span, wrong_argument(e.name, words[want], self.about, v.type))
        try:
            return self.compute(e.span, *values)
        except (ValueError, ZeroDivisionError, OverflowError):
            raise Mistake(e.span, undefined(e.name)) from None


def _block(make: Callable):
    """A building block of formulas.py as a function: its result keeps z's
    form times the block's factor where the block has one and its other
    arguments do not depend on the point."""
    def compute(span: Span, z: Value, *rest: Value):
        block = make(z.items, *(r.items if r.type in VECTOR_TYPES else r.items[0] for r in rest))
        others_independent = all(r.independent for r in rest)
        form = scaled_form(z.form, block.factor) if block.factor is not None and others_independent else None
        if z.independent and others_independent:
            form = INDEPENDENT
        return Value(vector_type(len(block.z)), tuple(block.z), form,
                     next((v.underivable for v in (z, *rest) if v.underivable), None))
    return compute


def _box_fold(span: Span, z: Value, limit: Value) -> Value:
    if limit.type != NUMBER and len(limit.items) != len(z.items):
        raise Mistake(span, f"'box_fold' needs one limit or {len(z.items)} (one per axis of z), "
                            f"not {len(limit.items)}")
    return _block(formulas.box_fold)(span, z, limit)


def _map(name: str, derivable: bool = True):
    """A function of numbers applied per component (numbers broadcast)."""
    def compute(span: Span, *values: Value):
        combined = broadcast([(v.type, v.items) for v in values])
        if combined is None:
            raise Mistake(span, different_sizes(name, [len(v.items) for v in values if v.type in VECTOR_TYPES]))
        size, lanes = combined
        items = tuple(ir.op(name, *args) for args in zip(*lanes))
        independent = all(v.independent for v in values)
        underivable = next((v.underivable for v in values if v.underivable), None)
        if not derivable and not independent:
            underivable = underivable or span
        form = INDEPENDENT if independent else None
        if name == "abs" and size > 1 and values[0].form is not None:
            form = values[0].form              # the octant fold: lengths kept
        kind = NUMBER if size == 1 else vector_type(size)
        return Value(kind, items, form, underivable)
    return compute


def _select(span: Span, condition: Value, a: Value, b: Value) -> Value:
    """Per component, both sides computed (cheap ones; 'if' computes only the side a ray needs)."""
    if a.type != b.type:
        raise Mistake(span, f"'select' chooses between values of one type, not {word(a)} and {word(b)}")
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
        return replace(dependent_scalar(*values),
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
        form = scaled_form(moving.form, ir.length(fixed.items))
    return Value(Type.VEC4, items, form, a.underivable or b.underivable)


_VECTOR_FUNCTIONS = {"length": _vector_fn(ir.length, NUMBER), "dot": _vector_fn(ir.dot, NUMBER),
                     "cross": _vector_fn(_cross, Type.VEC3), "normalize": _vector_fn(_normalize, "same")}

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
    # math, as scenes have it (stdlib.MATH), and the choice per component
    **{name: Function(f.arguments, _map(name, f.derivable) if f.per_component else _VECTOR_FUNCTIONS[name], f.about)
       for name, f in MATH.items()},
    "select": Function(("m", "any", "any"), _select, "select(condition, if_true, if_false)"),
    # x, promised within [low, high] (no code; fractalc/ranges.py reads it)
    "within": Function(("any", "any", "any"), _map("within"), "within(x, low, high)"),
}


def within_float(e: ast.Binary | ast.Call, value: Value) -> Value:
    """`value`, where what it computes from constants alone is a number the
    kernel's floats hold, as in a scene's expressions (check.py); a float
    kernel would compute infinity."""
    for item in value.items:
        if ir.is_const(item) and not in_float_range(item.value):
            raise Mistake(e.span, beyond_floats(e.op if isinstance(e, ast.Binary) else e.name, item.value))
    return value
