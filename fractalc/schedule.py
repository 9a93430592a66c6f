"""IR -> blocks of statements (`schedule`): in what order, and inside which
loop or if block, each value of a function is computed; emit.py renders
the blocks as C.

- Values come in dependency order, each once per block where it is
  visible; what a block computes is out of scope after it.
- A Loop is a `ForBlock`: its start and count before it, then the values
  of its body that do not depend on its States (computed once, before the
  loop, and named), then the body: the statements of its condition and of
  its next values, which see the States.
- A Branch is an `IfBlock`: a uniform condition chooses between its two
  sides; for a per-ray one, `otherwise` is computed before the block and
  the block computes `then` only if some ray needs it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Union

from . import ir


@dataclass(frozen=True)
class Compute:
    """Compute one value (the renderer inlines it or names a temporary)."""
    node: ir.Expr


@dataclass(frozen=True)
class Hoist:
    """A value computed before a loop for its body: give it a name."""
    node: ir.Expr


@dataclass(frozen=True)
class ForBlock:
    loop: ir.Loop
    condition: tuple["Statement", ...]     # computing the condition, at the top of each iteration
    body: tuple["Statement", ...]          # computing the next values


@dataclass(frozen=True)
class IfBlock:
    branch: ir.Branch
    then: tuple["Statement", ...]
    otherwise: tuple["Statement", ...]     # empty where the condition is per ray (computed before)


Statement = Union[Compute, Hoist, ForBlock, IfBlock]


def varying(roots) -> set:
    """The nodes under `roots` that differ from ray to ray: those of the
    point, library calls, and loops and branches (their rays stop or choose
    apart); the rest depend on params and constants only."""
    found: set = set()
    for root in roots:
        for node in ir.walk(root):
            if isinstance(node, (ir.Var, ir.Call, ir.State, ir.Loop, ir.Branch, ir.Out)) \
                    or any(c in found for c in ir.children(node)):
                found.add(node)
    return found


class _Scheduler:
    def __init__(self, roots: tuple, per_ray: set):
        self.levels = ir.state_levels(roots)     # the loop levels whose States a node depends on
        self.varying = per_ray

    def dependencies(self, node) -> tuple:
        """What must be computed before `node` in its own block."""
        if isinstance(node, ir.Loop):
            return (*node.init, node.count)      # its body runs inside the loop
        if isinstance(node, ir.Branch):
            if node.condition in self.varying:
                return (node.condition, *node.otherwise)
            return (node.condition,)
        return ir.children(node)

    def block(self, roots, visible: set) -> list:
        statements: list = []
        for root in roots:
            for node in ir.walk(root, self.dependencies):
                if node in visible:
                    continue
                if isinstance(node, ir.State):
                    raise ValueError(f"{node!r} used outside its loop")
                if isinstance(node, ir.Loop):
                    statements += self.loop(node, visible)
                elif isinstance(node, ir.Branch):
                    statements.append(self.branch(node, visible))
                else:
                    statements.append(Compute(node))
                visible.add(node)
        return statements

    def loop(self, loop: ir.Loop, visible: set) -> list:
        statements: list = []
        body = (*loop.next, *(() if loop.condition is None else (loop.condition,)))
        for inner in (n for root in body for n in ir.walk(root, self.dependencies)):
            if loop.level not in self.levels[inner] and inner not in visible \
                    and not isinstance(inner, (ir.Loop, ir.Branch, ir.Out)):
                statements += self.block((inner,), visible)
                statements.append(Hoist(inner))
        inside = set(visible) | {ir.State(loop.level, i, e.type) for i, e in enumerate(loop.init)}
        condition = () if loop.condition is None else tuple(self.block((loop.condition,), inside))
        statements.append(ForBlock(loop, condition, tuple(self.block(loop.next, inside))))
        return statements

    def branch(self, branch: ir.Branch, visible: set) -> IfBlock:
        then = tuple(self.block(branch.then, set(visible)))
        if branch.condition in self.varying:
            return IfBlock(branch, then, ())
        return IfBlock(branch, then, tuple(self.block(branch.otherwise, set(visible))))


def schedule(roots: tuple, per_ray: set) -> tuple[Statement, ...]:
    """The statements computing `roots`, in order; `per_ray` is
    `varying(roots)` (or a superset), which the caller has already."""
    return tuple(_Scheduler(roots, per_ray).block(roots, set()))
