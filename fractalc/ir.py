"""The distance IR: a small typed expression DAG.

Every value is a scalar (`real`, an int or a mask), except the results of
library calls that return a `vec3` and the point variable itself; their
components are taken with `Comp`. Vectors of the language are `Vec`
containers of scalar expressions, so vector arithmetic lowers to scalar
arithmetic that a later pass (dual numbers, a running Jacobian) can walk.

Nodes are built through the functions at the bottom (`add`, `call`, ...),
which fold constants: an expression with no `Param` or `Var` in it is a
`Const` by the time it exists.
"""
from __future__ import annotations

import enum
import math
import weakref

import numpy as np
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Callable, Union


class Type(str, enum.Enum):
    """What an IR value is (a str, so that it reads as its name)."""
    REAL = "real"       # a number per ray (or uniform)
    INT = "int"         # a whole number
    MASK = "mask"       # a truth value per ray
    VEC3 = "vec3"       # three reals: the point, a library call's vector


REAL, INT, MASK, VEC3 = Type.REAL, Type.INT, Type.MASK, Type.VEC3

class _Interned(type):
    """Hash-consing: constructing a node equal to a live one returns that
    one. Equal nodes are then the same object, so comparing and hashing
    are by identity and never walk a subtree, however deep the DAG."""

    def __call__(cls, *args, **kwargs):
        made = super().__call__(*args, **kwargs)
        key = (cls,) + tuple(_key(getattr(made, name)) for name in _field_names(cls))
        return _NODES.setdefault(key, made)


@lru_cache(maxsize=None)
def _field_names(cls) -> tuple[str, ...]:
    return tuple(f.name for f in fields(cls))


def _key(value):
    # -0.0 == 0.0 in Python, but they are different constants
    return (value, math.copysign(1.0, value)) if isinstance(value, float) else value


_NODES: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


class _Node(metaclass=_Interned):
    pass


node = dataclass(frozen=True, eq=False)


@node
class Const(_Node):
    value: float
    type: str = REAL


@node
class Param(_Node):
    """A scene `param`: a kernel argument, uniform over all rays."""
    index: int
    name: str
    type: str = REAL


@node
class Var(_Node):
    name: str
    type: str


@node
class Op(_Node):
    """A built-in operation: arithmetic, a math function, a comparison or
    `select(condition, if_true, if_false)`."""
    op: str
    args: tuple["Expr", ...]
    type: str = REAL


@node
class Call(_Node):
    """A call of an OpenCL library function from `stdlib_cl/`."""
    function: str
    args: tuple["Arg", ...]
    type: str


@node
class Comp(_Node):
    """Component `index` (0..2) of a vec3-valued expression."""
    vector: "Expr"
    index: int
    type: str = REAL


@node
class Vec(_Node):
    """A vector of scalar expressions (2 to 4 components)."""
    items: tuple["Expr", ...]

    def __len__(self) -> int:
        return len(self.items)


@node
class State(_Node):
    """Carried value `index` of the loop at nesting `level`, as it is at the
    start of an iteration: a loop's body is written in its States. A
    State is named by position, not by loop, so that equal loops are one
    node (interning) and so are computed once."""
    level: int
    index: int
    type: str = REAL


@node
class Loop(_Node):
    """Up to `count` (uniform) iterations of `next` over the carried values
    that start as `init`. With a `condition` (a mask of the States), a ray
    whose condition fails stops iterating and keeps its values; the loop
    ends when every ray has stopped. Its results are `Out(loop, i)`."""
    level: int
    init: tuple["Expr", ...]
    next: tuple["Expr", ...]
    condition: "Expr | None"
    count: "Expr"


@node
class Branch(_Node):
    """`then` where `condition` holds, else `otherwise` (each a tuple of
    values; results `Out(branch, i)`). Only the rays that need `then`
    compute it: a uniform condition is an if/else, a per-ray one computes
    `otherwise` and then, if any ray needs it, `then`."""
    condition: "Expr"
    then: tuple["Expr", ...]
    otherwise: tuple["Expr", ...]


@node
class Out(_Node):
    """Result `index` of a Loop or a Branch."""
    source: "Loop | Branch"
    index: int
    type: str = REAL


Expr = Union[Const, Param, Var, Op, Call, Comp, State, Out]
Arg = Union[Expr, Vec]


# ---- folding ---------------------------------------------------------------

def _python_round(x: float) -> float:
    # OpenCL `round`: halfway cases away from zero
    return math.copysign(math.floor(abs(x) + 0.5), x)


@dataclass(frozen=True)
class OpRule:
    """One IR operation: how many arguments, its value in float64 (for
    folding constants and for reference evaluation), what it gives, its C
    text from its arguments' texts (None: the C function of that name),
    and its derivative rule: the tangent of the result from the arguments
    and their tangents (forward mode; None for masks, which have none)."""
    arity: int
    value: Callable
    result: Type
    c: Callable[..., str] | None
    derivative: Callable | None


def _d_quotient(a, b, da, db):
    return div(sub(da, mul(div(a, b), db)), b)


def _d_atan2(y, x, dy, dx):
    return div(sub(mul(x, dy), mul(y, dx)), add(mul(x, x), mul(y, y)))


def _d_pow(a, b, da, db):
    # d(a^b) = a^b (db ln a + b da / a)
    return mul(op("pow", a, b), add(mul(db, op("log", a)), div(mul(b, da), a)))


def _d_clamp(x, lo, hi, dx, dlo, dhi):
    return op("select", op("lt", x, lo), dlo, op("select", op("lt", hi, x), dhi, dx))


def _one_over_root(a):
    return div(const(1.0), op("sqrt", sub(const(1.0), mul(a, a))))


# The IR's operations, the one table that folding, evaluating, rendering C
# and differentiating read.
OPS: dict[str, OpRule] = {
    "+": OpRule(2, lambda a, b: a + b, REAL, lambda a, b: f"({a} + {b})", lambda a, b, da, db: add(da, db)),
    "-": OpRule(2, lambda a, b: a - b, REAL, lambda a, b: f"({a} - {b})", lambda a, b, da, db: sub(da, db)),
    "*": OpRule(2, lambda a, b: a * b, REAL, lambda a, b: f"({a} * {b})",
                lambda a, b, da, db: add(mul(da, b), mul(a, db))),
    "/": OpRule(2, lambda a, b: a / b, REAL, lambda a, b: f"({a} / {b})", _d_quotient),
    "neg": OpRule(1, lambda a: -a, REAL, lambda a: f"(-{a})", lambda a, da: neg(da)),
    "sin": OpRule(1, math.sin, REAL, None, lambda a, da: mul(op("cos", a), da)),
    "cos": OpRule(1, math.cos, REAL, None, lambda a, da: neg(mul(op("sin", a), da))),
    "tan": OpRule(1, math.tan, REAL, None, lambda a, da: div(da, mul(op("cos", a), op("cos", a)))),
    "asin": OpRule(1, math.asin, REAL, None, lambda a, da: mul(_one_over_root(a), da)),
    "acos": OpRule(1, math.acos, REAL, None, lambda a, da: neg(mul(_one_over_root(a), da))),
    "atan": OpRule(1, math.atan, REAL, None, lambda a, da: div(da, add(const(1.0), mul(a, a)))),
    "atan2": OpRule(2, math.atan2, REAL, None, _d_atan2),
    "sqrt": OpRule(1, math.sqrt, REAL, None, lambda a, da: div(da, mul(const(2.0), op("sqrt", a)))),
    "rsqrt": OpRule(1, lambda a: 1.0 / math.sqrt(a), REAL, None,
                    lambda a, da: mul(mul(const(-0.5), div(op("rsqrt", a), a)), da)),
    "abs": OpRule(1, abs, REAL, lambda a: f"fabs({a})",
                  lambda a, da: op("select", op("lt", a, const(0.0)), neg(da), da)),
    "min": OpRule(2, min, REAL, lambda a, b: f"fmin({a}, {b})",
                  lambda a, b, da, db: op("select", op("lt", b, a), db, da)),
    "max": OpRule(2, max, REAL, lambda a, b: f"fmax({a}, {b})",
                  lambda a, b, da, db: op("select", op("lt", a, b), db, da)),
    # min and max of operands that cannot be NaN (the range analysis proves
    # it and rewrites min and max into these, fractalc/ranges.py): OpenCL's
    # min and max, which a CPU computes in one instruction where the
    # NaN-aware fmin and fmax take three
    "min_of_numbers": OpRule(2, min, REAL, lambda a, b: f"min({a}, {b})",
                             lambda a, b, da, db: op("select", op("lt", b, a), db, da)),
    "max_of_numbers": OpRule(2, max, REAL, lambda a, b: f"max({a}, {b})",
                             lambda a, b, da, db: op("select", op("lt", a, b), db, da)),
    "pow": OpRule(2, math.pow, REAL, None, _d_pow),
    "exp": OpRule(1, math.exp, REAL, None, lambda a, da: mul(op("exp", a), da)),
    "log": OpRule(1, math.log, REAL, None, lambda a, da: div(da, a)),
    "floor": OpRule(1, math.floor, REAL, None, lambda a, da: const(0.0)),
    "round": OpRule(1, _python_round, REAL, None, lambda a, da: const(0.0)),
    "clamp": OpRule(3, lambda x, lo, hi: min(max(x, lo), hi), REAL, None, _d_clamp),
    "mix": OpRule(3, lambda a, b, t: a + (b - a) * t, REAL, None,
                  lambda a, b, t, da, db, dt: add(add(da, mul(sub(db, da), t)), mul(sub(b, a), dt))),
    "radians": OpRule(1, math.radians, REAL, None, lambda a, da: mul(da, const(math.pi / 180.0))),
    "degrees": OpRule(1, math.degrees, REAL, None, lambda a, da: mul(da, const(180.0 / math.pi))),
    "lt": OpRule(2, lambda a, b: float(a < b), MASK, lambda a, b: f"({a} < {b})", None),
    "le": OpRule(2, lambda a, b: float(a <= b), MASK, lambda a, b: f"({a} <= {b})", None),
    "eq": OpRule(2, lambda a, b: float(a == b), MASK, lambda a, b: f"({a} == {b})", None),
    "and": OpRule(2, lambda a, b: float(bool(a) and bool(b)), MASK, lambda a, b: f"({a} & {b})", None),
    "or": OpRule(2, lambda a, b: float(bool(a) or bool(b)), MASK, lambda a, b: f"({a} | {b})", None),
    "not": OpRule(1, lambda a: float(not a), MASK, lambda a: f"(!{a})", None),
    # a promise, no code: x, which the library knows lies in [low, high]
    # (fractalc/ranges.py reads it where intervals alone are too wide)
    "within": OpRule(3, lambda x, low, high: x, REAL, lambda x, low, high: x,
                     lambda x, low, high, dx, dlow, dhigh: dx),
    # rendered by the emitter: SELECT for a per-ray condition, ?: for a uniform one
    "select": OpRule(3, lambda c, a, b: a if c else b, REAL, None,
                     lambda c, a, b, dc, da, db: op("select", c, da, db)),
}


def is_const(e) -> bool:
    return isinstance(e, Const)


def op(name: str, *args: Expr) -> Expr:
    """Build `Op(name, args)`, folded when every argument is constant.
    Raises ValueError/ZeroDivisionError/OverflowError for a constant
    argument outside the function's domain."""
    rule = OPS[name]
    result_type = rule.result
    assert len(args) == rule.arity, (name, args)
    if all(isinstance(a, Const) for a in args):
        value = float(rule.value(*(a.value for a in args)))
        if math.isnan(value) or math.isinf(value):
            raise ValueError(f"{name} gives a non-finite result")
        return Const(value, INT if result_type == MASK else REAL)
    folded = _simplify(name, args)
    if folded is not None:
        return folded
    if name == "select":
        result_type = args[1].type
    return Op(name, tuple(args), result_type)


def _simplify(name: str, args: tuple) -> Expr | None:
    """Algebraic identities with one constant operand (x+0, x*1, ...)."""
    if name in ("+", "-") and is_const(args[1]) and args[1].value == 0.0:
        return args[0]
    if name == "+" and is_const(args[0]) and args[0].value == 0.0:
        return args[1]
    if name in ("*", "/") and is_const(args[1]) and args[1].value == 1.0:
        return args[0]
    if name == "*" and is_const(args[0]) and args[0].value == 1.0:
        return args[1]
    if name == "*" and any(is_const(a) and a.value == 0.0 for a in args):
        return Const(0.0)   # the point's coordinates are finite
    if name == "-" and is_const(args[0]) and args[0].value == 0.0:
        return op("neg", args[1])
    if name in ("and", "or"):
        # true & x, false | x: x
        for known, other in ((args[0], args[1]), (args[1], args[0])):
            if is_const(known) and bool(known.value) == (name == "and"):
                return other
    if name == "pow" and is_const(args[1]) and args[1].value in _SMALL_POWERS:
        return _power(args[0], int(args[1].value))
    if name == "select" and is_const(args[0]):
        return args[1] if args[0].value else args[2]
    if name == "select" and args[1] == args[2]:
        return args[1]
    return None


# whole exponents that pow(x, n) computes as n's squarings and products
# (pow(x, 32): five squarings, where pow costs ~10x an exp and a log on
# vector lanes); past them pow's one rounding beats log2(n) of them
_SMALL_POWERS = frozenset(float(n) for n in range(1, 33))


def _power(x: Expr, n: int) -> Expr:
    """x^n, n >= 1, by squaring."""
    result, square = None, x
    while n:
        if n & 1:
            result = square if result is None else mul(result, square)
        n >>= 1
        if n:
            square = mul(square, square)
    return result


def const(value: float) -> Const:
    return Const(float(value))


def add(a, b): return op("+", a, b)
def sub(a, b): return op("-", a, b)
def mul(a, b): return op("*", a, b)
def div(a, b): return op("/", a, b)
def neg(a): return op("neg", a)


def call(function: str, args, type: str = REAL) -> Expr:
    return Call(function, tuple(args), type)


def components(e: Expr | Vec) -> tuple[Expr, ...]:
    """The three scalar components of a vec3 value."""
    if isinstance(e, Vec):
        return e.items
    return tuple(Comp(e, i) for i in range(3))


def pairwise(items: list, pair) -> object:
    """Reduce `items` with `pair` as a balanced tree of neighbours (depth
    log2 n, not n), each pair in its original order."""
    while len(items) > 1:
        items = [pair(*items[i:i + 2]) if i + 1 < len(items) else items[i] for i in range(0, len(items), 2)]
    return items[0]


def vec(*items: Expr) -> Vec:
    return Vec(tuple(items))


def dot(a, b) -> Expr:
    """The dot product of two tuples of values."""
    total = mul(a[0], b[0])
    for x, y in zip(a[1:], b[1:]):
        total = add(total, mul(x, y))
    return total


def length(a) -> Expr:
    return op("sqrt", dot(a, a))


# ---- loops and branches --------------------------------------------------------

_loop_level = [0]      # nesting of the loop bodies being built


def loop(init, count: Expr, step: Callable, condition: Callable | None = None) -> tuple[Expr, ...]:
    """The results of a loop carrying `init`: `step(states)` gives the next
    values, `condition(states)` (optional) whether a ray goes on."""
    level = _loop_level[0]
    states = tuple(State(level, i, e.type) for i, e in enumerate(init))
    _loop_level[0] += 1
    try:
        next_values = tuple(step(states))
        test = None if condition is None else condition(states)
    finally:
        _loop_level[0] -= 1
    if test is not None and is_const(test):
        if not test.value:
            return tuple(init)
        test = None
    made = Loop(level, tuple(init), next_values, test, count)
    return tuple(Out(made, i, e.type) for i, e in enumerate(init))


def branch(condition: Expr, then, otherwise) -> tuple[Expr, ...]:
    """`then` where `condition` holds, else `otherwise`: tuples of values,
    or callables giving them (so that a constant condition never builds
    the side it does not take)."""
    if is_const(condition):
        chosen = then if condition.value else otherwise
        return tuple(chosen() if callable(chosen) else chosen)
    then = tuple(then() if callable(then) else then)
    otherwise = tuple(otherwise() if callable(otherwise) else otherwise)
    if then == otherwise:
        return then
    made = Branch(condition, then, otherwise)
    return tuple(Out(made, i, e.type) for i, e in enumerate(then))


# Evaluate a bounded shape within one bound radius of its bounding sphere.
# Beyond, the sphere's distance (>= the radius) stands in; a ray takes that
# for a hit only where the threshold exceeds the radius: a fractal under a pixel.
BOUND_MARGIN = 1.0


def bounded(bound: Expr, inner: Expr, radius: Expr) -> Expr:
    """`inner` within BOUND_MARGIN radii of a bounding sphere of `radius`,
    `bound` (the sphere's distance) beyond: a conservative bounding
    distance that spares evaluating `inner` (a fractal) far from it. Both
    are lower bounds of the true distance, so either is a safe step."""
    return branch(op("lt", bound, mul(radius, const(BOUND_MARGIN))), (inner,), (bound,))[0]


def inside_bound(distance: Expr, point: tuple[Expr, ...], radius: Expr) -> Expr:
    """`distance` where the point is within BOUND_MARGIN radii of the
    sphere of `radius` about the origin: if `distance` is `bounded` by that
    sphere (of `point`), its inner estimate alone, without the test and the
    sphere's distance; else `distance` as it is."""
    if isinstance(distance, Out) and isinstance(distance.source, Branch):
        test, (inner,), otherwise = distance.source.condition, distance.source.then, distance.source.otherwise
        sphere = call("sd_sphere", (Vec(tuple(point)), radius))
        if test == op("lt", sphere, mul(radius, const(BOUND_MARGIN))) and otherwise == (sphere,):
            return inner
    return distance


# ---- walking ---------------------------------------------------------------

def children(e) -> tuple:
    if isinstance(e, (Op, Call)):
        return e.args
    if isinstance(e, Comp):
        return (e.vector,)
    if isinstance(e, Vec):
        return e.items
    if isinstance(e, Out):
        return (e.source,)
    if isinstance(e, Loop):
        return (*e.init, *e.next, *(() if e.condition is None else (e.condition,)), e.count)
    if isinstance(e, Branch):
        return (e.condition, *e.then, *e.otherwise)
    return ()


def walk(root, children=children):
    """Every distinct node reachable from `root` (through `children`),
    children before parents."""
    seen: set = set()
    order: list = []
    stack = [(root, False)]
    while stack:
        node, expanded = stack.pop()
        if expanded:
            order.append(node)
            continue
        if node in seen:
            continue
        seen.add(node)
        stack.append((node, True))
        stack.extend((c, False) for c in reversed(children(node)))
    return order


def _elementwise(rule: OpRule):
    """The rule's float64 value over arrays; NaN outside its domain (as a
    ray computing the side of a select it does not take)."""
    def value(*args):
        try:
            return float(rule.value(*args))
        except (ValueError, ZeroDivisionError, OverflowError):
            return math.nan
    return np.frompyfunc(value, rule.arity, 1)


def evaluate_at(roots: tuple, points, params=()) -> list:
    """The float64 values of `roots` (expressions of the point, loops and
    branches included) at (N, 3) `points`: the IR's meaning, which the
    kernel computes in float or double. Slow; for tests and checks."""
    points = np.asarray(points, dtype=np.float64)
    ones = np.ones(len(points))
    rules = {name: _elementwise(rule) for name, rule in OPS.items()}

    def outside(node):
        return (*node.init, node.count) if isinstance(node, Loop) else children(node)

    def run(roots, memo):
        for root in roots:
            for node in walk(root, outside):
                if node not in memo:
                    memo[node] = compute(node, memo)
        return [memo[r] for r in roots]

    def compute(node, memo):
        if isinstance(node, Const):
            return node.value * ones
        if isinstance(node, Param):
            return float(params[node.index]) * ones
        if isinstance(node, Var):
            return points
        if isinstance(node, Comp) and isinstance(node.vector, Var):
            return points[:, node.index]
        if isinstance(node, Op):
            return rules[node.op](*(memo[a] for a in node.args)).astype(np.float64)
        if isinstance(node, Vec):
            return tuple(memo[c] for c in node.items)
        if isinstance(node, Out):
            return memo[node.source][node.index]
        if isinstance(node, Branch):
            condition = memo[node.condition] != 0
            return [np.where(condition, memo[t], memo[f]) for t, f in zip(node.then, node.otherwise)]
        if isinstance(node, Loop):
            state = [memo[e] for e in node.init]
            active = ones != 0
            for _ in range(int(memo[node.count][0])):
                inner = {k: v for k, v in memo.items() if node.level not in levels[k]}
                inner.update((State(node.level, i, e.type), v) for i, (e, v) in enumerate(zip(node.init, state)))
                if node.condition is not None:
                    active = active & (run((node.condition,), inner)[0] != 0)
                    if not active.any():
                        break
                state = [np.where(active, n, s) for n, s in zip(run(node.next, inner), state)]
            return state
        raise ValueError(f"cannot evaluate {type(node).__name__} here")

    levels = state_levels(roots)
    with np.errstate(all="ignore"):
        return run(tuple(roots), {})


def _with_children(node, new: list):
    """`node` with its children (in `children` order) replaced by `new`."""
    if isinstance(node, Op):
        return Op(node.op, tuple(new), node.type)
    if isinstance(node, Call):
        return Call(node.function, tuple(new), node.type)
    if isinstance(node, Comp):
        return Comp(new[0], node.index, node.type)
    if isinstance(node, Vec):
        return Vec(tuple(new))
    if isinstance(node, Out):
        return Out(new[0], node.index, node.type)
    if isinstance(node, Branch):
        n = len(node.then)
        return Branch(new[0], tuple(new[1:1 + n]), tuple(new[1 + n:]))
    if isinstance(node, Loop):
        n, m = len(node.init), len(node.next)
        condition = None if node.condition is None else new[n + m]
        return Loop(node.level, tuple(new[:n]), tuple(new[n:n + m]), condition, new[-1])
    return node


def rebuild(roots: tuple, replacements: dict) -> tuple:
    """`roots` with each node that is a key of `replacements` replaced by
    its value, and every node above one rebuilt."""
    made: dict = {}
    for root in roots:
        for node in walk(root):
            if node in made:
                continue
            if node in replacements:
                made[node] = replacements[node]
                continue
            old = children(node)
            new = [made[c] for c in old]
            made[node] = node if all(a is b for a, b in zip(old, new)) else _with_children(node, new)
    return tuple(made[r] for r in roots)


def transform(roots: tuple, rewrite: Callable) -> tuple:
    """`roots` rebuilt from the leaves up: each node with its rebuilt
    children, folded as the builders fold (operations through `op`, a
    branch whose condition became constant as the side it takes, a loop
    condition that became true as none), then `rewrite(node, rebuilt)`,
    which gives the node to use in its place."""
    made: dict = {}
    for root in roots:
        for node in walk(root):
            if node in made:
                continue
            old = children(node)
            new = [made[c] for c in old]
            if all(a is b for a, b in zip(old, new)):
                rebuilt = node
            elif isinstance(node, Op):
                try:
                    rebuilt = op(node.op, *new)
                except (ValueError, ZeroDivisionError, OverflowError):   # constants outside the domain
                    rebuilt = _with_children(node, new)
            elif isinstance(node, Out) and isinstance(new[0], Branch) and is_const(new[0].condition):
                side = new[0].then if new[0].condition.value else new[0].otherwise
                rebuilt = side[node.index]
            else:
                rebuilt = _with_children(node, new)
                if isinstance(rebuilt, Loop) and rebuilt.condition is not None and is_const(rebuilt.condition) \
                        and rebuilt.condition.value:
                    rebuilt = Loop(rebuilt.level, rebuilt.init, rebuilt.next, None, rebuilt.count)
            made[node] = rewrite(node, rebuilt)
    return tuple(made[r] for r in roots)


def without_promises(roots: tuple) -> tuple:
    """`roots` with each `within(x, low, high)` as x: once the range analysis
    has read the promise, its bounds would only be computed for nothing."""
    def rewrite(node, rebuilt):
        return rebuilt.args[0] if isinstance(rebuilt, Op) and rebuilt.op == "within" else rebuilt
    return transform(roots, rewrite)


def without_idle_carries(roots: tuple) -> tuple:
    """`roots` with every loop's carried values that never change (the next
    value is the carried one itself, or the constant it starts as) replaced
    by that constant and no longer carried: a carry costs a select per
    iteration, and the guards the range analysis removes leave such carries
    behind (a `stopped` flag that cannot be set, an offset that stays 0)."""
    kept_index: dict = {}       # new loop -> {old index: new index}
    constant: dict = {}         # new loop -> {old index: its constant}

    def idle(loop: Loop, i: int) -> bool:
        start, step = loop.init[i], loop.next[i]
        if not is_const(start):
            return False
        itself = isinstance(step, State) and (step.level, step.index) == (loop.level, i)
        return itself or (is_const(step) and step.value == start.value)

    def rewrite(node, rebuilt):
        if isinstance(rebuilt, Loop):
            still = [i for i in range(len(rebuilt.init)) if not idle(rebuilt, i)]
            if len(still) in (0, len(rebuilt.init)):
                return rebuilt
            renumbered = {old: new for new, old in enumerate(still)}
            fixed = {i: rebuilt.init[i] for i in range(len(rebuilt.init)) if i not in renumbered}

            def in_body(_, body):
                if isinstance(body, State) and body.level == rebuilt.level:
                    return fixed[body.index] if body.index in fixed else \
                        State(body.level, renumbered[body.index], body.type)
                return body
            condition = () if rebuilt.condition is None else (rebuilt.condition,)
            body = transform(tuple(rebuilt.next[i] for i in still) + condition, in_body)
            loop = Loop(rebuilt.level, tuple(rebuilt.init[i] for i in still), body[:len(still)],
                        body[len(still)] if condition else None, rebuilt.count)
            kept_index[loop], constant[loop] = renumbered, fixed
            return loop
        if isinstance(rebuilt, Out) and rebuilt.source in kept_index:
            loop = rebuilt.source
            if rebuilt.index in constant[loop]:
                return constant[loop][rebuilt.index]
            return Out(loop, kept_index[loop][rebuilt.index], rebuilt.type)
        return rebuilt
    return transform(tuple(roots), rewrite)


def state_levels(roots) -> dict:
    """For every node under `roots`, the loop levels whose States it
    depends on (a loop's own level not counted for its results)."""
    levels: dict = {}
    for root in roots:
        for node in walk(root):
            if node in levels:
                continue
            found = frozenset().union(*(levels[c] for c in children(node)))
            if isinstance(node, State):
                found = frozenset((node.level,))
            elif isinstance(node, Loop):
                found = found - {node.level}
            levels[node] = found
    return levels


def evaluate(root: Expr, params) -> float:
    """The value of a point-independent expression for the given param
    values (indexable by `Param.index`), in float64."""
    values: dict = {}
    for node in walk(root):
        if isinstance(node, Const):
            values[node] = node.value
        elif isinstance(node, Param):
            values[node] = float(params[node.index])
        elif isinstance(node, Op):
            values[node] = float(OPS[node.op].value(*(values[a] for a in node.args)))
        else:
            raise ValueError(f"{node!r} depends on the point")
    return values[root]
