"""Formulas written in the language (`formula name(...) { ... }`) as IR,
and the orbit of a fractal built from them (docs/formulas.md).

`check` runs a formula's statements once where it is declared (every
mistake is a `Mistake` at its place) and `lower` runs them again for each
use, with that use's arguments: the statements by phase are
formula_statements.py, the values with their derivative forms
formula_values.py, running them formula_interpreter.py. A formula whose
every step keeps z's form (a similarity: Syntopia, "Distance Estimated 3D
Fractals", part VI) gets the cheap scalar running derivative; any other is
differentiated in forward mode (fractalc/derive.py, part VII).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace

import numpy as np

from . import ast, derive, ir
from .errors import Span
from .expressions import Mistake
from .formula_interpreter import Interpreter
from .formula_statements import Formula, nested
from .formula_values import INDEPENDENT, MASK, NUMBER, ONE, ZERO, Value, number, vector, word
from .types import TYPE_WORDS, Type

# A step whose z is beyond this length (or not finite) is not taken: the ray
# stops with its last finite state, so every estimate is finite.
OVERFLOW_LENGTH = 1e18
MAX_DERIVATIVE = 1e30
DEFAULT_BAILOUT = 4.0


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
    z, carried = _initial_state(interpreter, uses, point, julia)
    if julia is not None and len(julia.items) != len(z.items):
        raise Mistake(where or sequence[0].formula.span, f"'julia' must be a {len(z.items)}-vector like z, "
                                                          f"not a {len(julia.items)}-vector")
    c = _constant(julia, z, point)
    dependent, z_forms = _dependent_values(interpreter, uses, carried, z, c)
    own = _require_derivable(sequence, uses, z, z_forms, where)
    conformal = all(v.form is not None for v in z_forms) and not own
    use_scalar = conformal if jacobian is None else (not jacobian and conformal)
    if estimate is None:
        estimate = growth(sequence, julia).estimate
    escape = estimate is Estimate.ESCAPE_TIME
    if bailout is None and escape:
        bailout = ir.const(DEFAULT_BAILOUT)
    loop = _OrbitLoop.of(interpreter, sequence, uses, carried, dependent, z, c, iterations, bailout, use_scalar,
                         trap)
    fields = loop.unpack(ir.loop(loop.pack(loop.start()), loop.count(), loop.round, loop.condition))
    de = _final_estimate(uses[-1], loop, fields, point, own, escape)
    traps = (*fields["trap"], *fields["steps"]) if trap else ()
    inside = None if bailout is None else ir.op("select", _inside(fields["z"], bailout), ir.const(-1.0), ONE)
    return Orbit(de, traps, use_scalar, inside)


def _initial_state(interpreter, uses, point, julia) -> tuple[Value, list[dict[str, Value]]]:
    """z after every formula's `init` (it starts as the point) and each
    formula's carried values, in order."""
    z = vector(point, (ONE, ZERO))
    carried: list[dict[str, Value]] = []
    for use in uses:
        env = {"c": _constant(julia, z, point), **_environment(use), "z": z}
        out = interpreter.run(use.formula.init, env, _readonly(use))
        z = out["z"]
        if z.type not in (Type.VEC3, Type.VEC4):
            assigned = next(s for s in use.formula.init if s.name == "z")
            raise Mistake(assigned.value.span, f"z must be a 3- or 4-vector, this is {word(z)}")
        carried.append({name: out[name] for name in use.formula.carried if name != "z"})
    return z, carried


def _dependent_values(interpreter, uses, carried, z: Value, c: Value) -> tuple[list[set], list[Value]]:
    """Which carried values depend on the point (the scalar derivative then
    cannot follow them), to a fixed point, and each formula's z after a step."""
    dependent: list[set] = [set() for _ in uses]
    for _ in range(8):
        probes = _step_values(interpreter, uses, carried, dependent, z, c)
        grown = [{n for n, v in values.items() if n != "z" and not v.independent} for values in probes]
        if all(g <= d for g, d in zip(grown, dependent)):
            break
        dependent = [d | g for d, g in zip(dependent, grown)]
    return dependent, [values["z"] for values in probes]


def _require_derivable(sequence, uses, z: Value, z_forms: list[Value], where: Span | None) -> list[Use]:
    """The uses that give their own estimate; a Mistake where a step changes
    z's type, an own estimate is in a hybrid, or the compiler's estimate
    would be derived through an operation without a derivative."""
    hybrid_dims = {len(use_z.items) for use_z in z_forms} | {len(z.items)}
    for use, value in zip(uses, z_forms):
        if value.type != z.type and len(uses) > 1 and len(hybrid_dims) > 1:
            raise Mistake(where or use.formula.span, "a hybrid's formulas must all work on 3-vectors "
                                                     "or all on 4-vectors")
        if value.type != z.type:
            assigned = _last_z(use.formula)
            raise Mistake(assigned.span if assigned else use.formula.span,
                          f"z is {word(z)} before the step and {word(value)} after it")
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
    return own


@dataclass(frozen=True, eq=False)
class _OrbitLoop:
    """The orbit's loop: one round takes each step of the sequence in turn
    (a hybrid's round is its whole sequence). Its state is `layout`: z,
    each formula's carried values, dr (the scalar derivative), whether the
    ray stopped, a hybrid's step counter and the orbit trap."""
    interpreter: Interpreter
    steps: tuple                    # (formula index, use) per step of a round
    carried: list                   # each formula's carried values after init
    dependent: list                 # each formula's carried values that depend on the point
    z: Value
    c: Value
    iterations: ir.Expr
    bailout: ir.Expr | None
    use_scalar: bool
    trap: bool
    stops: bool                     # a formula sets `stop`
    # whether a ray can stop before the last step: else nothing reads `stopped`
    # (a ray past the overflow limit keeps its state anyway: the selects in `round`)
    stoppable: bool
    layout: tuple

    @staticmethod
    def of(interpreter, sequence, uses, carried, dependent, z, c, iterations, bailout, use_scalar, trap):
        steps = tuple((k, use) for k, use in enumerate(uses) for _ in range(_count(sequence, use)))
        stops = any(_assignment(use.formula, "stop") for use in uses)
        stoppable = bailout is not None or stops or len(steps) > 1
        layout = [("z", len(z.items)), *(((k, name), len(v.items)) for k, values in enumerate(carried)
                                         for name, v in values.items())]
        layout += ([("dr", 1)] * use_scalar + [("stopped", 1)] * stoppable + [("counter", 1)] * (len(steps) > 1)
                   + [("trap", 4), ("steps", 1)] * trap)
        return _OrbitLoop(interpreter, steps, carried, dependent, z, c, iterations, bailout, use_scalar, trap,
                          stops, stoppable, tuple(layout))

    @property
    def period(self) -> int:
        return len(self.steps)

    def unpack(self, state) -> dict:
        fields, i = {}, 0
        for key, width in self.layout:
            fields[key] = tuple(state[i:i + width])
            i += width
        return fields

    def pack(self, fields: dict) -> tuple:
        return tuple(x for key, _ in self.layout for x in fields[key])

    def start(self) -> dict:
        return {"z": self.z.items, **{(k, name): v.items for k, values in enumerate(self.carried)
                                      for name, v in values.items()},
                "dr": (ONE,), "stopped": (ir.Const(0.0, ir.MASK),), "counter": (ZERO,),
                "trap": (ir.const(1e30),) * 4, "steps": (ZERO,)}

    def count(self) -> ir.Expr:
        """The rounds: the iterations, a hybrid's rounded up to whole rounds."""
        if self.period == 1:
            return self.iterations
        return ir.op("floor", ir.div(ir.add(self.iterations, ir.const(self.period - 1.0)),
                                     ir.const(float(self.period))))

    def formula_values(self, fields: dict, k: int, forms: bool) -> dict:
        return {name: replace(v, items=fields[(k, name)],
                              form=(None if name in self.dependent[k] else INDEPENDENT) if forms else v.form)
                for name, v in self.carried[k].items()}

    def round(self, state):
        fields = self.unpack(state)
        z_now = Value(self.z.type, fields["z"], (ONE, ZERO))
        stopped = fields["stopped"][0] if self.stoppable else None
        for j, (k, use) in enumerate(self.steps):
            # with one step per iteration the loop's condition stops the ray
            going = ir.Const(1.0, ir.MASK)
            if self.period > 1:
                going = ir.op("and", ir.op("not", stopped),
                              ir.op("lt", ir.add(fields["counter"][0], ir.const(float(j))), self.iterations))
                if self.bailout is not None:
                    going = ir.op("and", going, _inside(z_now.items, self.bailout))
            env = {"c": self.c, **_environment(use), **self.formula_values(fields, k, True), "z": z_now}
            out = self.interpreter.run(use.formula.step, env, _readonly(use))
            moved = out["z"]
            ok = ir.op("and", going, ir.op("le", ir.dot(moved.items, moved.items), ir.const(OVERFLOW_LENGTH ** 2)))
            kept = {"z": moved.items, **{(k, name): out[name].items for name in self.carried[k]}}
            if self.use_scalar:
                a, b = moved.form
                kept["dr"] = (ir.op("min", ir.add(ir.mul(a, fields["dr"][0]), b), ir.const(MAX_DERIVATIVE)),)
            if self.trap:   # `trap = point`: where the orbit trap measures (else z)
                kept["trap"] = _trap_added(fields["trap"], out["trap"].items if "trap" in out else moved.items)
                kept["steps"] = (ir.add(fields["steps"][0], ONE),)
            for key, items in kept.items():
                fields[key] = tuple(ir.op("select", ok, a, b) for a, b in zip(items, fields[key]))
            if self.stoppable:
                stopped = ir.op("or", stopped, ir.op("and", going, ir.op("not", ok)))
            if "stop" in out:               # `stop = condition`: these rays iterate no more
                stopped = ir.op("or", stopped, ir.op("and", ok, out["stop"].items[0]))
            z_now = Value(self.z.type, fields["z"], (ONE, ZERO))
        if self.stoppable:
            fields["stopped"] = (stopped,)
        if self.period > 1:
            fields["counter"] = (ir.add(fields["counter"][0], ir.const(float(self.period))),)
        return self.pack(fields)

    def condition(self, state):
        if self.bailout is None and not self.stops:
            return None     # a hybrid's steps check `stopped` themselves
        fields = self.unpack(state)
        going = ir.op("not", fields["stopped"][0])
        return going if self.bailout is None else ir.op("and", going, _inside(fields["z"], self.bailout))


def _final_estimate(last: Use, loop: _OrbitLoop, fields: dict, point, own: list, escape: bool) -> ir.Expr:
    """The distance estimate from the loop's final state: the last formula's
    `final` lines (its own estimate, or one of ESTIMATES), else the
    compiler's of the estimate's kind; from z's Jacobian where the scalar
    derivative cannot follow the steps."""
    dims = len(loop.z.items)
    z_final = fields["z"]
    final_values = loop.formula_values(fields, len(loop.carried) - 1, False)
    dr = fields["dr"][0] if loop.use_scalar else None
    final_z, rows = tuple(z_final), None
    if not loop.use_scalar and not own:
        # z's Jacobian: the final lines read z and the carried values from the
        # loop that carries the tangents too, so the iterations run once
        items = [x for v in final_values.values() for x in v.items]
        rebuilt, all_rows = _jacobian((*final_z, *items), point, _last_z(last.formula).span)
        final_z, rows, values = rebuilt[:dims], all_rows[:dims], iter(rebuilt[dims:])
        final_values = {name: replace(v, items=tuple(next(values) for _ in v.items))
                        for name, v in final_values.items()}
    if not last.formula.final:
        return _estimate(escape, final_z, rows, dr, ZERO)

    def estimate(name: str, args: list[Value], span: Span) -> Value:
        offset = args[0].items[0] if args else ZERO
        if args and (len(args) > 1 or args[0].type != NUMBER):
            raise Mistake(span, f"'{name}' takes at most one number (the linear estimate's offset)")
        return number(_estimate(name == "escape_time_estimate", final_z, rows, dr, offset))

    env = {"c": loop.c, **_environment(last), **final_values, "z": Value(loop.z.type, final_z, None),
           **{name: number(_derivative(name, final_z, rows, dr)) for name in last.formula.derived}}
    out = Interpreter(estimate).run(last.formula.final, env, _readonly(last) | set(last.formula.derived))
    distance = out.get("distance")
    if distance is None:
        raise Mistake(last.formula.final[-1].span, "'final' lines must set 'distance' (the estimate)")
    if distance.type != NUMBER:
        assigned = next(s for s in reversed(last.formula.final) if s.name == "distance")
        raise Mistake(assigned.value.span, f"'distance' must be a number, this is {word(distance)}")
    return derive.finite_distance(distance.items[0])    # the formula's own: guarded as a derived one is


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
    # |z|^2 against bailout^2 (bailout > 0), not |z| against bailout, though
    # formulas compute |z| anyway: the loop's test then waits for no square
    # root, and the iteration that stops computes none (bulb-640 2-3%)
    return ir.op("le", ir.dot(z, z), ir.mul(bailout, bailout))


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
        for inner in (s, *nested(s)):
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
        for name, want in (("stop", MASK), ("trap", Type.VEC3)):
            if name in out and out[name].type != want:
                raise Mistake(_assignment(use.formula, name).span,
                              f"'{name}' must be {TYPE_WORDS[want]}, this is {word(out[name])}")
        for name, v in carried[k].items():
            if name not in out:
                raise Mistake(use.formula.span, f"'{name}' is set on only one side of an 'if'")
            if out[name].type != v.type:
                raise Mistake(use.formula.span, f"'{name}' starts as {word(v)} and becomes {word(out[name])}")
        results.append({"z": out["z"], **{name: out[name] for name in carried[k]}})
    return results
