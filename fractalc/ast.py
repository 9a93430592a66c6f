"""Immutable AST nodes produced by `parse`, each carrying its source span.

Nodes compare by identity (`eq=False`): two `sphere(1)` calls at different
places are different nodes, and hashing never walks a subtree.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cache
from typing import Iterator, Union

from .errors import Span


class Node:
    """What every AST node is: `children` and `walk` find the nodes inside
    one by this base, whatever its kind."""
    __slots__ = ()


node = dataclass(frozen=True, eq=False, slots=True)


# ---- expressions -----------------------------------------------------------

@node
class Number(Node):
    value: float
    span: Span


@node
class Name(Node):
    name: str
    span: Span


@node
class Vector(Node):
    items: tuple["Expr", ...]
    span: Span


@node
class Unary(Node):
    op: str            # "-"
    operand: "Expr"
    span: Span


@node
class Binary(Node):
    op: str            # + - * / and, in formulas, < <= > >= == != (| and & make a Chain)
    left: "Expr"
    right: "Expr"
    span: Span


@node
class Chain(Node):
    """`a | b | c ...` or `a & b & c ...`: operands joined by one operator
    (both associative), one node however many: a chain of 300 is as deep as
    `union(...)` of 300."""
    op: str            # | or &
    operands: tuple["Expr", ...]
    span: Span


@node
class Arg(Node):
    name: str | None   # None for a positional argument
    value: "Expr"
    span: Span


@node
class Call(Node):
    name: str
    name_span: Span
    args: tuple[Arg, ...]
    span: Span


@node
class Method(Node):
    """`receiver.name(args)`: a transform of a shape."""
    receiver: "Expr"
    name: str
    name_span: Span
    args: tuple[Arg, ...]
    span: Span


@node
class Field(Node):
    """`receiver.x`: components of a vector (x, y, z, w, or several: xyz)."""
    receiver: "Expr"
    name: str
    name_span: Span
    span: Span


Expr = Union[Number, Name, Vector, Unary, Binary, Chain, Call, Method, Field]


@node
class String(Node):
    """A string literal: a file name, only ever a block entry's value."""
    value: str         # the text between the quotes, as written (no escapes)
    span: Span         # quotes included


# ---- blocks and declarations -----------------------------------------------

@node
class Entry(Node):
    key: str
    key_span: Span
    value: Union[Expr, "Block", String]
    span: Span


@node
class Block(Node):
    entries: tuple[Entry, ...]
    span: Span


@node
class ParamDecl(Node):
    name: str
    name_span: Span
    default: Expr
    bounds: tuple[Expr, Expr] | None
    span: Span


@node
class LetDecl(Node):
    name: str
    name_span: Span
    value: Expr
    span: Span


@node
class MaterialDecl(Node):
    name: str
    name_span: Span
    block: Block
    span: Span


@node
class SceneDecl(Node):
    shape: Expr
    span: Span


@node
class CameraDecl(Node):
    block: Block
    span: Span


@node
class LightDecl(Node):
    kind: str
    kind_span: Span
    block: Block
    span: Span


@node
class RenderDecl(Node):
    block: Block
    span: Span


@node
class Keyframe(Node):
    """`TIME: { ... }` in a path: camera keys and param values at that time."""
    time: float
    time_span: Span
    block: Block
    span: Span


@node
class PathDecl(Node):
    keyframes: tuple[Keyframe, ...]
    span: Span


@node
class PresetDecl:
    """`preset NAME { param: value, ... }`: param values saved under a name."""
    name: str
    name_span: Span
    block: Block
    span: Span


# ---- formulas ----------------------------------------------------------------

@node
class Assign(Node):
    """`name = value` in a formula: `phase` says when it runs: "init" once
    before the iterations, "step" in each, "final" once after them."""
    name: str
    name_span: Span
    value: Expr
    phase: str
    span: Span


@node
class If(Node):
    """`if condition { ... } else { ... }` among a formula's steps."""
    condition: Expr
    then: tuple["Statement", ...]
    otherwise: tuple["Statement", ...]
    span: Span


Statement = Union[Assign, If]


@node
class FormulaDecl(Node):
    name: str
    name_span: Span
    params: tuple[ParamDecl, ...]
    body: tuple[Statement, ...]
    span: Span


Decl = Union[ParamDecl, LetDecl, MaterialDecl, SceneDecl, CameraDecl, LightDecl, RenderDecl, PathDecl,
             PresetDecl, FormulaDecl]


@node
class Program(Node):
    decls: tuple[Decl, ...]
    file: str
    source: str


# ---- walking -------------------------------------------------------------------

# Field types that never hold a node (annotations are strings here)
_PLAIN = frozenset({"str", "str | None", "float", "Span"})


@cache
def _field_names(kind: type) -> tuple[str, ...]:
    """The fields of a node kind that may hold nodes."""
    return tuple(f.name for f in fields(kind) if f.type not in _PLAIN)


def children(parent: Node) -> tuple[Node, ...]:
    """The nodes directly inside `parent`, in source order: its fields that
    are nodes or tuples of nodes (arguments, items, statements, a param's
    bounds). Every pass that walks the AST walks it through this, so no
    pass can miss a kind of node."""
    found: list[Node] = []
    for name in _field_names(type(parent)):
        value = getattr(parent, name)
        if isinstance(value, Node):
            found.append(value)
        elif isinstance(value, tuple):
            found.extend(x for x in value if isinstance(x, Node))
    return tuple(found)


def walk(root: Node) -> Iterator[Node]:
    """`root` and every node inside it, each before the nodes inside it and
    in source order (the order evaluation meets them), on an explicit
    stack: any depth costs no Python recursion."""
    stack = [root]
    while stack:
        here = stack.pop()
        yield here
        stack.extend(reversed(children(here)))
