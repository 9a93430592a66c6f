"""Derivatives of IR values with respect to the point, and the distance
estimates built from them.

Forward mode (dual numbers; Syntopia, "Distance Estimated 3D Fractals",
part VII): every value carries its tangents along the three directions of
the point, computed by each operation's rule in `ir.OPS`. A loop carries the
tangents of its real values as three more carried values each, a branch
chooses them with its values. The result is the Jacobian J = dz/dp of an
iteration's final z, from which the estimates follow:

- escape-time (potential): DE = 0.5 r ln r / |grad r|, grad r = J^T z / r;
- linear (folding, IFS): DE = (r - offset) / |grad r|.

An operation without a rule (a library call) cannot be differentiated:
`NoDerivative` names it.
"""
from __future__ import annotations

from . import ir

Tangent = tuple[ir.Expr, ir.Expr, ir.Expr]
ZERO: Tangent = (ir.const(0.0),) * 3


class NoDerivative(ValueError):
    """An operation on the point that has no derivative rule."""


def _differentiable(node) -> bool:
    return node.type == ir.REAL


class _Tangents:
    """The tangents of IR nodes along the point's three directions; `seeds`
    gives them for the point's own components. Loops and branches get a
    version that carries (or chooses) the tangents of their real results
    too: `carriers` maps each to that version and where each real result's
    three tangents start in it."""

    def __init__(self, seeds: dict, levels: dict, carriers: dict):
        self.memo: dict = dict(seeds)
        self.levels = levels
        self.carriers = carriers

    def of(self, root) -> Tangent | None:
        for node in ir.walk(root, self._needs):
            if node not in self.memo:
                self.memo[node] = self._tangent(node)
        return self.memo[root]

    @staticmethod
    def _needs(node) -> tuple:
        if isinstance(node, ir.Loop):
            return (*node.init, node.count)     # its body is differentiated in `_loop`
        return ir.children(node)

    def _tangent(self, node):
        if isinstance(node, ir.Op):
            rule = ir.OPS[node.op]
            if rule.derivative is None:
                return None
            if node.op == "select":    # the condition has no tangent: choose per direction
                c, a, b = node.args
                return tuple(ir.op("select", c, x, y) for x, y in zip(self.memo[a], self.memo[b]))
            args = [self.memo[a] for a in node.args]
            return tuple(rule.derivative(*node.args, *(t[j] for t in args)) for j in range(3))
        if isinstance(node, ir.Out):
            if not _differentiable(node):
                return None
            carrier, starts = self.carriers[node.source]
            return tuple(ir.Out(carrier, starts[node.index] + j, ir.REAL) for j in range(3))
        if isinstance(node, ir.Loop):
            self.carriers[node] = self._loop(node)
            return None
        if isinstance(node, ir.Branch):
            self.carriers[node] = self._branch(node)
            return None
        if isinstance(node, ir.Call):
            raise NoDerivative(f"'{node.function}' has no derivative rule")
        if isinstance(node, ir.Const):
            return ZERO if _differentiable(node) else None
        if isinstance(node, ir.Param):
            return ZERO
        if isinstance(node, ir.Vec) or not _differentiable(node):
            return None
        raise NoDerivative(f"{node!r} depends on the point other than through the seeds")

    @staticmethod
    def _starts(values) -> dict:
        """Where each real value's three tangents start, after the values."""
        starts = {}
        for i, value in enumerate(values):
            if _differentiable(value):
                starts[i] = len(values) + 3 * len(starts)
        return starts

    def _branch(self, branch: ir.Branch):
        starts = self._starts(branch.then)
        then = [t for i in starts for t in self.memo[branch.then[i]]]
        otherwise = [t for i in starts for t in self.memo[branch.otherwise[i]]]
        return ir.Branch(branch.condition, (*branch.then, *then), (*branch.otherwise, *otherwise)), starts

    def _loop(self, loop: ir.Loop):
        starts = self._starts(loop.init)
        body = _Tangents({}, self.levels, self.carriers)
        # values not depending on this loop's States keep their tangents
        body.memo = {n: t for n, t in self.memo.items() if loop.level not in self.levels.get(n, frozenset())}
        body.memo.update((ir.State(loop.level, i, loop.init[i].type),
                          tuple(ir.State(loop.level, start + j, ir.REAL) for j in range(3)))
                         for i, start in starts.items())
        init = [t for i in starts for t in self.memo[loop.init[i]]]
        following = [t for i in starts for t in body.of(loop.next[i])]
        return ir.Loop(loop.level, (*loop.init, *init), (*loop.next, *following), loop.condition, loop.count), starts


def jacobian(values, point) -> tuple[tuple[ir.Expr, ...], list[Tangent]]:
    """`values` and d value / d point for each (a row of three tangents):
    `point` are the three IR values they are computed from. The values come
    back rebuilt on the loops and branches that carry the tangents, so that
    each iteration runs once."""
    roots = tuple(values)
    seeds = {c: tuple(ir.const(1.0 if j == k else 0.0) for j in range(3)) for k, c in enumerate(point)}
    carriers: dict = {}
    tangents = _Tangents(seeds, ir.state_levels(roots), carriers)
    rows = [tangents.of(v) for v in roots]
    replacements: dict = {}
    for original, (carrier, _) in carriers.items():     # inner ones first: they were made first
        replacements[original] = ir.rebuild((carrier,), replacements)[0]
    flat = ir.rebuild((*roots, *(t for row in rows for t in row)), replacements)
    rebuilt, tangent_values = flat[:len(roots)], flat[len(roots):]
    return rebuilt, [tuple(tangent_values[3 * i:3 * i + 3]) for i in range(len(roots))]


def gradient_length(z, rows) -> ir.Expr:
    """|J^T z|: the length of r's gradient times r."""
    total = None
    for j in range(3):
        component = None
        for value, row in zip(z, rows):
            term = ir.mul(value, row[j])
            component = term if component is None else ir.add(component, term)
        squared = ir.mul(component, component)
        total = squared if total is None else ir.add(total, squared)
    return ir.op("sqrt", total)


def spectral_norm(rows) -> ir.Expr:
    """The largest singular value of the Jacobian `rows` (one row of three
    tangents per component of z): the most z moves when the point moves by
    one. sqrt of the largest eigenvalue of the symmetric A = J^T J, in
    closed form (Smith, "Eigenvalues of a symmetric 3 x 3 matrix", 1961);
    where A is a multiple of the identity (a similarity), that multiple."""
    def entry(i: int, j: int) -> ir.Expr:
        total = None
        for row in rows:
            term = ir.mul(row[i], row[j])
            total = term if total is None else ir.add(total, term)
        return total

    a = [[entry(i, j) for j in range(3)] for i in range(3)]
    off = ir.add(ir.add(ir.mul(a[0][1], a[0][1]), ir.mul(a[0][2], a[0][2])), ir.mul(a[1][2], a[1][2]))
    q = ir.div(ir.add(ir.add(a[0][0], a[1][1]), a[2][2]), ir.const(3.0))
    shifted = [ir.sub(a[i][i], q) for i in range(3)]
    spread = ir.add(ir.add(ir.add(ir.mul(shifted[0], shifted[0]), ir.mul(shifted[1], shifted[1])),
                           ir.mul(shifted[2], shifted[2])), ir.mul(ir.const(2.0), off))
    p = ir.op("sqrt", ir.div(spread, ir.const(6.0)))
    scale = ir.op("max", p, ir.const(1e-30))      # p = 0: the select below takes q
    b = [[ir.div(shifted[i] if i == j else a[i][j], scale) for j in range(3)] for i in range(3)]
    det = ir.sub(ir.add(ir.mul(b[0][0], ir.sub(ir.mul(b[1][1], b[2][2]), ir.mul(b[1][2], b[2][1]))),
                        ir.mul(b[0][2], ir.sub(ir.mul(b[1][0], b[2][1]), ir.mul(b[1][1], b[2][0])))),
                 ir.mul(b[0][1], ir.sub(ir.mul(b[1][0], b[2][2]), ir.mul(b[1][2], b[2][0]))))
    half = ir.op("clamp", ir.mul(det, ir.const(0.5)), ir.const(-1.0), ir.const(1.0))
    largest = ir.add(q, ir.mul(ir.mul(ir.const(2.0), p), ir.op("cos", ir.div(ir.op("acos", half), ir.const(3.0)))))
    largest = ir.op("select", ir.op("le", p, ir.mul(q, ir.const(1e-12))), q, largest)
    return ir.op("sqrt", ir.op("max", largest, ir.const(0.0)))


def finite_distance(distance: ir.Expr) -> ir.Expr:
    """`distance` within +-1e30: every estimate's guard (LANGUAGE.md: an
    estimate is finite everywhere). OpenCL's clamp is fmin(fmax(...)),
    which takes a NaN to the lower end: inside."""
    return ir.op("clamp", distance, ir.const(-1e30), ir.const(1e30))


def finite_estimate(numerator: ir.Expr, denominator: ir.Expr) -> ir.Expr:
    """numerator / denominator within +-1e30, and 0 where the denominator
    is 0 (r = 0, or a point where z does not move with the point: there
    the estimate says nothing, and 0 never oversteps)."""
    de = finite_distance(ir.div(numerator, denominator))
    return ir.op("select", ir.op("eq", denominator, ir.const(0.0)), ir.const(0.0), de)


def _squared_length(z) -> ir.Expr:
    r2 = None
    for value in z:
        r2 = ir.mul(value, value) if r2 is None else ir.add(r2, ir.mul(value, value))
    return r2


def escape_time_estimate(z, rows) -> ir.Expr:
    """0.5 r ln r / |grad r| = 0.5 r^2 ln r / |J^T z|."""
    r2 = _squared_length(z)
    return finite_estimate(ir.mul(ir.mul(ir.const(0.5), r2), ir.op("log", ir.op("sqrt", r2))),
                           gradient_length(z, rows))


def linear_estimate(z, rows, offset: ir.Expr = ir.const(0.0)) -> ir.Expr:
    """(r - offset) / |grad r| = (r - offset) r / |J^T z|."""
    r = ir.op("sqrt", _squared_length(z))
    return finite_estimate(ir.mul(ir.sub(r, offset), r), gradient_length(z, rows))
