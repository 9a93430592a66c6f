"""Value ranges over the IR (`simplify`): guards only where they can fire.

Interval arithmetic from the params' declared ranges: each value's lowest
and highest value in float (rounding widened outward, past FLOAT_MAX
infinite) and whether it can be NaN; masks are intervals in {0, 1}.
A loop's carried values are iterated to a fixed point (widened to
infinity where they still grow after WIDEN_AFTER iterations), inside its
body refined by its condition, and by that condition at the loop's start
values (a ray whose condition fails there never runs the body); each side
of a branch is refined by its condition. A value's range is the hull over
every place it is computed. Then `simplify` drops what the ranges decide:
a mask known true or false (an overflow test that cannot fail, a `stopped`
flag that cannot be set, a branch that cannot be taken) and a min, max or
clamp whose result is known to be one of its arguments. `within(x, lo,
hi)` is a bound the library promises where intervals alone are too wide.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from . import ir
from .types import FLOAT_MAX

ROUNDING = 1e-5        # relative widening of each computed bound: float's rounding and the library's ulps
TINY = 1e-37           # and absolute, around 0
WIDEN_AFTER = 16       # loop iterations before growing bounds go to infinity
MAX_NODES = 20000      # larger IR is left as it is (the analysis is Python, per node)
WORK_PER_NODE = 200    # and so is IR whose loops and branches take more node computations than this each
INF = math.inf


@dataclass(frozen=True)
class Range:
    low: float
    high: float
    nan: bool = False       # may be NaN

    def hull(self, other: "Range") -> "Range":
        return Range(min(self.low, other.low), max(self.high, other.high), self.nan or other.nan)

    def meet(self, other: "Range") -> "Range":
        """Both hold: the values in both, and NaN only if both allow it."""
        low, high = max(self.low, other.low), min(self.high, other.high)
        if low > high:          # contradictory: the context is never reached; keep it harmless
            return self
        return Range(low, high, self.nan and other.nan)

    def decided(self) -> float | None:
        return self.low if self.low == self.high and not self.nan else None


FULL = Range(-INF, INF, True)
ANY_MASK = Range(0.0, 1.0)
TRUE, FALSE = Range(1.0, 1.0), Range(0.0, 0.0)
FINITE = Range(-FLOAT_MAX, FLOAT_MAX)


def _rounded(low: float, high: float, nan: bool) -> Range:
    if math.isnan(low) or math.isnan(high):
        return FULL
    # rounding never takes a result across 0
    low = max(low - abs(low) * ROUNDING - TINY, 0.0) if low >= 0.0 else low - abs(low) * ROUNDING - TINY
    high = min(high + abs(high) * ROUNDING + TINY, 0.0) if high <= 0.0 else high + abs(high) * ROUNDING + TINY
    return Range(-INF if low < -FLOAT_MAX else low, INF if high > FLOAT_MAX else high, nan)


def _exact(value: float) -> Range:
    return Range(value, value)


def _product(a: float, b: float) -> float:
    return 0.0 if a == 0.0 or b == 0.0 else a * b      # 0 * inf: the NaN is counted apart


def _add(a: Range, b: Range) -> Range:
    nan = a.nan or b.nan or (a.high == INF and b.low == -INF) or (a.low == -INF and b.high == INF)
    low, high = a.low + b.low, a.high + b.high
    return _rounded(-INF if math.isnan(low) else low, INF if math.isnan(high) else high, nan)


def _neg(a: Range) -> Range:
    return Range(-a.high, -a.low, a.nan)


def _mul(a: Range, b: Range, same: bool = False) -> Range:
    if same:
        low = 0.0 if a.low <= 0.0 <= a.high else min(a.low * a.low, a.high * a.high)
        return _rounded(low, max(a.low * a.low, a.high * a.high), a.nan)
    ends = [_product(x, y) for x in (a.low, a.high) for y in (b.low, b.high)]
    infinite = lambda r: math.isinf(r.low) or math.isinf(r.high)  # noqa: E731
    zero = lambda r: r.low <= 0.0 <= r.high                         # noqa: E731
    nan = a.nan or b.nan or (zero(a) and infinite(b)) or (zero(b) and infinite(a))
    return _rounded(min(ends), max(ends), nan)


def _div(a: Range, b: Range) -> Range:
    if b.low <= 0.0 <= b.high:
        return FULL
    inverse = Range(1.0 / b.high, 1.0 / b.low, b.nan)
    nan = (math.isinf(a.low) or math.isinf(a.high)) and (math.isinf(b.low) or math.isinf(b.high))
    product = _mul(a, inverse)
    return Range(product.low, product.high, product.nan or nan)


def _monotone(f, a: Range, low_domain: float = -INF, strict: bool = False) -> Range:
    """f of an increasing function defined from `low_domain` on."""
    nan = a.nan or a.low < low_domain

    def at(x):
        if x <= low_domain:
            return f(low_domain) if not strict else -INF
        try:
            return f(x)
        except OverflowError:
            return INF
    return _rounded(at(max(a.low, low_domain)), at(max(a.high, low_domain)), nan)


def _sqrt(a: Range) -> Range:
    return _monotone(lambda x: math.sqrt(x) if x < INF else INF, a, 0.0)


def _rsqrt(a: Range) -> Range:
    nan = a.nan or a.low < 0.0
    high = INF if a.low <= 0.0 else 1.0 / math.sqrt(a.low)
    low = 0.0 if a.high == INF else 1.0 / math.sqrt(max(a.high, 0.0)) if a.high > 0.0 else INF
    return _rounded(low, high, nan)


def _exp(a: Range) -> Range:
    return _monotone(lambda x: math.exp(x) if x < 710 else INF, a)


def _log(a: Range) -> Range:
    return _monotone(lambda x: math.log(x) if x < INF else INF, a, 0.0, strict=True)


def _bounded(low: float, high: float, domain: float = INF):
    """A function with values in [low, high], NaN outside [-domain, domain]
    (sine and cosine: infinity)."""
    def rule(a: Range) -> Range:
        nan = a.nan or a.low < -domain or a.high > domain or math.isinf(a.low) or math.isinf(a.high)
        return Range(low, high, nan)
    return rule


def _abs(a: Range) -> Range:
    if a.low >= 0.0:
        return a
    if a.high <= 0.0:
        return _neg(a)
    return Range(0.0, max(-a.low, a.high), a.nan)


def _either(base: Range, a: Range, b: Range) -> Range:
    """OpenCL's fmin and fmax of a NaN and a number give the number."""
    if a.nan:
        base = base.hull(Range(b.low, b.high))
    if b.nan:
        base = base.hull(Range(a.low, a.high))
    return Range(base.low, base.high, a.nan and b.nan)


def _min(a: Range, b: Range) -> Range:
    return _either(Range(min(a.low, b.low), min(a.high, b.high)), a, b)


def _max(a: Range, b: Range) -> Range:
    return _either(Range(max(a.low, b.low), max(a.high, b.high)), a, b)


def _compare(strict: bool):
    def rule(a: Range, b: Range) -> Range:
        certain = not (a.nan or b.nan)
        if certain and (a.high < b.low or (not strict and a.high <= b.low)):
            return TRUE
        if a.low > b.high or (strict and a.low >= b.high):
            return FALSE            # a NaN compares false too
        return ANY_MASK
    return rule


def _eq(a: Range, b: Range) -> Range:
    if a.decided() is not None and a.decided() == b.decided() and a.decided() != 0.0:
        return TRUE
    if a.low > b.high or b.low > a.high:
        return FALSE
    return ANY_MASK


def _mask_and(a: Range, b: Range) -> Range:
    return FALSE if FALSE in (a, b) else TRUE if a == b == TRUE else ANY_MASK


def _mask_or(a: Range, b: Range) -> Range:
    return TRUE if TRUE in (a, b) else FALSE if a == b == FALSE else ANY_MASK


def _not(a: Range) -> Range:
    return FALSE if a == TRUE else TRUE if a == FALSE else ANY_MASK


def _select(c: Range, a: Range, b: Range) -> Range:
    return a if c == TRUE else b if c == FALSE else a.hull(b)


def _clamp(x: Range, low: Range, high: Range) -> Range:
    return _min(_max(x, low), high)


def _pow(a: Range, b: Range) -> Range:
    if a.low > 0.0:
        return _exp(_mul(b, _log(a)))
    return FULL


def _floor(a: Range) -> Range:
    return Range(math.floor(a.low) if math.isfinite(a.low) else a.low,
                 math.floor(a.high) if math.isfinite(a.high) else a.high, a.nan)


def _scaled(factor: float):
    return lambda a: _mul(a, _exact(factor))


def _within(x: Range, low: Range, high: Range) -> Range:
    promised = Range(low.low, high.high)
    return x.meet(promised) if x.low <= promised.high and promised.low <= x.high else promised


# the operations that give one of their arguments, by kind
_PICKING = {"min": "min", "min_of_numbers": "min", "max": "max", "max_of_numbers": "max", "clamp": "clamp"}
# min and max of arguments that cannot be NaN: their plain forms (ir.OPS)
_OF_NUMBERS = {"min": "min_of_numbers", "max": "max_of_numbers"}

RULES = {
    "+": _add, "-": lambda a, b: _add(a, _neg(b)), "*": _mul, "/": _div, "neg": _neg,
    "sin": _bounded(-1.0, 1.0), "cos": _bounded(-1.0, 1.0), "tan": lambda a: FULL,
    "asin": _bounded(-math.pi / 2, math.pi / 2, 1.0), "acos": _bounded(0.0, math.pi, 1.0),
    "atan": lambda a: Range(-math.pi / 2, math.pi / 2, a.nan),
    "atan2": lambda a, b: Range(-math.pi, math.pi, a.nan or b.nan),
    "sqrt": _sqrt, "rsqrt": _rsqrt, "abs": _abs, "min": _min, "max": _max, "min_of_numbers": _min,
    "max_of_numbers": _max, "pow": _pow, "exp": _exp,
    "log": _log, "floor": _floor, "round": lambda a: _add(_floor(a), Range(0.0, 1.0)), "clamp": _clamp,
    "mix": lambda a, b, t: _add(a, _mul(_add(b, _neg(a)), t)),
    "radians": _scaled(math.pi / 180.0), "degrees": _scaled(180.0 / math.pi),
    "lt": _compare(True), "le": _compare(False), "eq": _eq,
    "and": _mask_and, "or": _mask_or, "not": _not, "select": _select, "within": _within,
}


class _Scope:
    """Where values are computed: the carried values of the loops around
    (State -> Range) and what the conditions around tell (node -> Range).
    Inside `parent`, what reads none of the `new` States and facts has the
    parent's values."""

    def __init__(self, states: dict, facts: dict, parent: "_Scope | None" = None, new=frozenset()):
        self.states, self.facts, self.memo = states, facts, {}
        self.parent, self.new, self.dirty = parent, new, set(new)


class _TooLarge(Exception):
    """The analysis would take too long: the IR is left as it is."""


def _outside(node) -> tuple:
    """The children computed before a node, in its scope: a loop's body and a
    branch's sides are computed in scopes of their own."""
    if isinstance(node, ir.Loop):
        return (*node.init, node.count)
    if isinstance(node, ir.Branch):
        return (node.condition,)
    return ir.children(node)


class _Analysis:
    def __init__(self, params: dict, budget: int):
        self.params = params
        self.budget = budget        # node computations left
        self.seen: dict = {}        # node -> the hull of its ranges everywhere it is computed
        self.picks: dict = {}       # min/max/clamp node -> the argument positions it gives somewhere
        self.inside: dict = {}      # loop or branch -> every node it reads

    def reads(self, node) -> set:
        if node not in self.inside:
            self.inside[node] = set(ir.walk(node))
        return self.inside[node]

    def inherited(self, node, scope: _Scope) -> bool:
        """Whether `node` has its value of the parent scope: it is there, and
        reads nothing that is new here."""
        parent = scope.parent
        if parent is None or node not in parent.memo or node in scope.new:
            return False
        if isinstance(node, (ir.Loop, ir.Branch)):
            return scope.new.isdisjoint(self.reads(node))
        return not any(c in scope.dirty for c in _outside(node))

    def run(self, roots, scope: _Scope) -> list:
        for root in roots:
            for node in ir.walk(root, _outside):
                if node not in scope.memo:
                    if self.inherited(node, scope):
                        scope.memo[node] = scope.parent.memo[node]
                        continue
                    scope.dirty.add(node)
                    self.budget -= 1
                    if self.budget < 0:
                        raise _TooLarge
                    value = self.compute(node, scope)
                    fact = scope.facts.get(node)
                    if fact is not None and isinstance(value, Range):
                        value = value.meet(fact)
                    scope.memo[node] = value
                    if isinstance(value, Range):
                        known = self.seen.get(node)
                        self.seen[node] = value if known is None else known.hull(value)
        return [scope.memo[r] for r in roots]

    def compute(self, node, scope: _Scope):
        memo = scope.memo
        if isinstance(node, ir.Const):
            return _exact(node.value)
        if isinstance(node, ir.Param):
            return self.params.get(node.index, FINITE)
        if isinstance(node, ir.Comp):
            return FINITE if isinstance(node.vector, ir.Var) else FULL
        if isinstance(node, ir.Call):
            return FULL if node.type != ir.VEC3 else None
        if isinstance(node, (ir.Var, ir.Vec)):
            return None
        if isinstance(node, ir.State):
            return scope.states.get(node, FULL)
        if isinstance(node, ir.Out):
            return memo[node.source][node.index]
        if isinstance(node, ir.Op):
            args = [memo[a] for a in node.args]
            if node.op == "*" and node.args[0] is node.args[1]:
                return _mul(args[0], args[0], same=True)
            if node.op in _PICKING:
                self.pick(node, args)
            return RULES[node.op](*args)
        if isinstance(node, ir.Branch):
            return self.branch(node, scope)
        if isinstance(node, ir.Loop):
            return self.loop(node, scope)
        return FULL

    def pick(self, node, args) -> None:
        """Which argument a min, max or clamp certainly gives here (-1: none)."""
        def below(a: Range, b: Range) -> bool:     # a <= b for sure (a tie only away from +-0)
            return not a.nan and (a.high < b.low or (a.high == b.low and a.high != 0.0))
        if _PICKING[node.op] == "min":
            found = 0 if below(args[0], args[1]) else 1 if below(args[1], args[0]) else -1
        elif _PICKING[node.op] == "max":
            found = 0 if below(args[1], args[0]) else 1 if below(args[0], args[1]) else -1
        else:
            found = 0 if below(args[1], args[0]) and below(args[0], args[2]) else -1
        self.picks.setdefault(node, set()).add(found)

    @staticmethod
    def within(scope: _Scope, facts: dict, states: dict | None = None) -> _Scope:
        """A scope inside `scope` where `facts` hold too (and `states` are the
        innermost loop's carried values)."""
        merged = dict(scope.facts)
        for node, value in facts.items():
            merged[node] = value if node not in merged else merged[node].meet(value)
        return _Scope({**scope.states, **(states or {})}, merged, scope, frozenset(facts) | frozenset(states or ()))

    def branch(self, node: ir.Branch, scope: _Scope):
        condition = scope.memo[node.condition]
        sides = []
        for values, truth in ((node.then, True), (node.otherwise, False)):
            if condition == (FALSE if truth else TRUE):
                continue
            inner = self.within(scope, self.assume(node.condition, truth, scope.memo))
            sides.append(self.run(values, inner))
        if not sides:
            return [FULL] * len(node.then)
        return [a if len(sides) == 1 else a.hull(b) for a, b in zip(sides[0], sides[-1])]

    def loop(self, node: ir.Loop, scope: _Scope):
        states = [scope.memo[e] for e in node.init]
        keys = [ir.State(node.level, i, e.type) for i, e in enumerate(node.init)]
        count = scope.memo[node.count]
        iterations = int(count.high) if math.isfinite(count.high) and not count.nan else 10 ** 9
        facts = {}
        if node.condition is not None:
            # a ray whose condition fails at the start never runs the body
            start = self.within(scope, {}, dict(zip(keys, states)))
            if self.run((node.condition,), start)[0] == FALSE:
                return states
            told = self.assume(node.condition, True, start.memo)
            facts = {init: told[key] for key, init in zip(keys, node.init) if key in told}
            facts.update({n: v for n, v in told.items() if not isinstance(n, ir.State)
                          and not ir.state_levels((n,))[n] & {node.level}})
        for k in range(min(iterations, WIDEN_AFTER + 4)):
            inner = self.within(scope, facts, dict(zip(keys, states)))
            if node.condition is not None:
                test = self.run((node.condition,), inner)[0]
                if test == FALSE:
                    break
                inner = self.within(inner, self.assume(node.condition, True, inner.memo))
            following = [s.hull(n) for s, n in zip(states, self.run(node.next, inner))]
            if following == states:
                return states
            if k >= WIDEN_AFTER:
                following = [Range(-INF if f.low < s.low else s.low, INF if f.high > s.high else s.high, f.nan)
                             for s, f in zip(states, following)]
            states = following
        else:
            if iterations > WIDEN_AFTER + 4:    # not settled: anything
                states = [FULL if s != FALSE and s != TRUE else ANY_MASK for s in states]
                self.run(node.next, self.within(scope, facts, dict(zip(keys, states))))
        return states

    def assume(self, condition, truth: bool, memo: dict) -> dict:
        """What `condition` being `truth` tells of the nodes under it:
        node -> Range, backward through comparisons, sums, differences,
        squares and square roots."""
        told: dict = {}

        def now(node) -> Range | None:
            return told.get(node, memo.get(node))

        def narrow(node, value: Range, depth: int = 0) -> None:
            current = now(node)
            if not isinstance(current, Range):
                return
            narrowed = current.meet(value)
            if narrowed == current:
                return
            told[node] = narrowed
            if depth > 24 or not isinstance(node, ir.Op):
                return
            a = node.args[0]
            b = node.args[1] if len(node.args) > 1 else None
            ra, rb = now(a), (now(b) if b is not None else None)
            if not isinstance(ra, Range) or (b is not None and not isinstance(rb, Range)):
                return
            if node.op == "+":
                narrow(a, _add(narrowed, _neg(rb)), depth + 1)
                narrow(b, _add(narrowed, _neg(ra)), depth + 1)
            elif node.op == "-":
                narrow(a, _add(narrowed, rb), depth + 1)
                narrow(b, _add(ra, _neg(narrowed)), depth + 1)
            elif node.op == "neg":
                narrow(a, _neg(narrowed), depth + 1)
            elif node.op == "*" and a is b and math.isfinite(narrowed.high):
                root = math.sqrt(max(narrowed.high, 0.0)) * (1 + ROUNDING) + TINY
                narrow(a, Range(-root, root), depth + 1)
            elif node.op == "sqrt" and math.isfinite(narrowed.high):
                high = narrowed.high * narrowed.high * (1 + ROUNDING) + TINY
                narrow(a, Range(-INF, high), depth + 1)

        def hold(node, truth: bool) -> None:
            if not isinstance(node, ir.Op):
                if isinstance(node, ir.State):
                    narrow(node, TRUE if truth else FALSE)
                return
            args = node.args
            if node.op == "and" and truth or node.op == "or" and not truth:
                hold(args[0], truth)
                hold(args[1], truth)
            elif node.op == "not":
                hold(args[0], not truth)
            elif node.op in ("lt", "le"):
                a, b = (args[0], args[1]) if truth else (args[1], args[0])
                ra, rb = now(a), now(b)
                if not (isinstance(ra, Range) and isinstance(rb, Range)) or (not truth and (ra.nan or rb.nan)):
                    return
                narrow(a, Range(-INF, rb.high))          # a < b (or b <= a where it fails)
                narrow(b, Range(ra.low, INF))
            elif node.op == "eq" and truth:
                ra, rb = now(args[0]), now(args[1])
                if isinstance(ra, Range) and isinstance(rb, Range):
                    narrow(args[0], rb)
                    narrow(args[1], ra)
        hold(condition, truth)
        return told


def simplify(roots: tuple, params: dict) -> tuple:
    """`roots` without what the ranges decide (the module's doc); `params`:
    param index -> (low, high), the declared ranges."""
    size = len(ir.walk(ir.Vec(tuple(roots)))) if roots else 0
    if size > MAX_NODES:
        return tuple(roots)
    known = {index: Range(low, high) for index, (low, high) in params.items()}
    analysis = _Analysis(known, WORK_PER_NODE * size + 10000)
    try:
        analysis.run(tuple(roots), _Scope({}, {}))
    except _TooLarge:
        return tuple(roots)

    def rewrite(node, rebuilt):
        value = analysis.seen.get(node)
        if value is not None and node.type == ir.MASK and isinstance(node, (ir.Op, ir.State, ir.Out)) \
                and value.decided() is not None:
            return ir.Const(value.decided(), ir.INT)
        picks = analysis.picks.get(node)
        if picks is not None and len(picks) == 1 and -1 not in picks and isinstance(rebuilt, ir.Op) \
                and rebuilt.op == node.op:
            return rebuilt.args[next(iter(picks))]
        if isinstance(node, ir.Op) and isinstance(rebuilt, ir.Op) and rebuilt.op in _OF_NUMBERS and rebuilt.op == node.op \
                and all(analysis.seen.get(a) is not None and not analysis.seen[a].nan for a in node.args):
            return ir.op(_OF_NUMBERS[rebuilt.op], *rebuilt.args)
        return rebuilt
    return ir.transform(tuple(roots), rewrite)
