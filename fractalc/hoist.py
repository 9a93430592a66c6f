"""Uniform values out of the per-ray code (`hoist`): derived params.

A value that depends only on params and constants (a fractal's bound
radius `pow(2, 1 / (power - 1))`, the sine of a param angle, a Julia
constant, a formula param's square) is the same for every ray and every
estimate, yet written inline it is computed in each call of the estimate
(and a library call, like `mandelbulb_bound_radius`, on every vector lane).
`hoist` replaces each largest such subtree by a derived param, a `Param`
after the scene's own: the program's `derived_params` kernel (emit.py)
computes them once per launch into the same params buffer (run.py), and
the estimate reads them like any param.
"""
from __future__ import annotations

from dataclasses import dataclass

from . import ir

# Slots after the scene's params in every program's params buffer; values
# past them stay inline (correct, only slower).
DERIVED_SLOTS = 64


@dataclass(frozen=True)
class Hoisted:
    roots: tuple            # the roots, each hoisted value read as its derived Param
    derived: tuple          # the hoisted values, in slot order (params of the scene only)


def _uniform_nodes(roots) -> set:
    """The nodes under `roots` computed from params and constants alone."""
    uniform: set = set()
    for root in roots:
        for node in ir.walk(root):
            if isinstance(node, (ir.Const, ir.Param)) or (
                    isinstance(node, (ir.Op, ir.Call, ir.Comp, ir.Vec))
                    and all(c in uniform for c in ir.children(node))):
                uniform.add(node)
    return uniform


def hoist(roots: tuple, param_count: int) -> Hoisted:
    """`roots` with each largest uniform real subtree that computes
    something (an operation or a library call) read from a derived param,
    the first at index `param_count`."""
    uniform = _uniform_nodes(roots)
    chosen: dict = {}
    seen: set = set()
    stack = list(reversed(roots))
    while stack:        # from the roots down, so that only the largest are taken
        node = stack.pop()
        if node in seen:
            continue
        seen.add(node)
        if node in uniform and isinstance(node, (ir.Op, ir.Call, ir.Comp)) and node.type == ir.REAL:
            if len(chosen) < DERIVED_SLOTS:
                chosen[node] = ir.Param(param_count + len(chosen), f"derived{len(chosen)}")
                continue
        # a uniform mask (a branch's test) stays in place, its real operands hoisted
        stack.extend(reversed(ir.children(node)))
    return Hoisted(ir.rebuild(tuple(roots), chosen) if chosen else tuple(roots), tuple(chosen))
