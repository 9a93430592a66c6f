"""Immutable AST nodes produced by `parse`, each carrying its source span.

Nodes compare by identity (`eq=False`): two `sphere(1)` calls at different
places are different nodes, and hashing never walks a subtree.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Union

from .errors import Span

node = dataclass(frozen=True, eq=False, slots=True)


# ---- expressions -----------------------------------------------------------

@node
class Number:
    value: float
    span: Span


@node
class Name:
    name: str
    span: Span


@node
class Vector:
    items: tuple["Expr", ...]
    span: Span


@node
class Unary:
    op: str            # "-"
    operand: "Expr"
    span: Span


@node
class Binary:
    op: str            # + - * / | & and, in formulas, < <= > >= == !=
    left: "Expr"
    right: "Expr"
    span: Span


@node
class Arg:
    name: str | None   # None for a positional argument
    value: "Expr"
    span: Span


@node
class Call:
    name: str
    name_span: Span
    args: tuple[Arg, ...]
    span: Span


@node
class Method:
    """`receiver.name(args)`: a transform of a shape."""
    receiver: "Expr"
    name: str
    name_span: Span
    args: tuple[Arg, ...]
    span: Span


@node
class Field:
    """`receiver.x`: components of a vector (x, y, z, w, or several: xyz)."""
    receiver: "Expr"
    name: str
    name_span: Span
    span: Span


Expr = Union[Number, Name, Vector, Unary, Binary, Call, Method, Field]


@node
class String:
    """A string literal: a file name, only ever a block entry's value."""
    value: str         # the text between the quotes, as written (no escapes)
    span: Span         # quotes included


# ---- blocks and declarations -----------------------------------------------

@node
class Entry:
    key: str
    key_span: Span
    value: Union[Expr, "Block", String]
    span: Span


@node
class Block:
    entries: tuple[Entry, ...]
    span: Span


@node
class ParamDecl:
    name: str
    name_span: Span
    default: Expr
    bounds: tuple[Expr, Expr] | None
    span: Span


@node
class LetDecl:
    name: str
    name_span: Span
    value: Expr
    span: Span


@node
class MaterialDecl:
    name: str
    name_span: Span
    block: Block
    span: Span


@node
class SceneDecl:
    shape: Expr
    span: Span


@node
class CameraDecl:
    block: Block
    span: Span


@node
class LightDecl:
    kind: str
    kind_span: Span
    block: Block
    span: Span


@node
class RenderDecl:
    block: Block
    span: Span


@node
class Keyframe:
    """`TIME: { ... }` in a path: camera keys and param values at that time."""
    time: float
    time_span: Span
    block: Block
    span: Span


@node
class PathDecl:
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
class Assign:
    """`name = value` in a formula: `phase` says when it runs: "init" once
    before the iterations, "step" in each, "final" once after them."""
    name: str
    name_span: Span
    value: Expr
    phase: str
    span: Span


@node
class If:
    """`if condition { ... } else { ... }` among a formula's steps."""
    condition: Expr
    then: tuple["Statement", ...]
    otherwise: tuple["Statement", ...]
    span: Span


Statement = Union[Assign, If]


@node
class FormulaDecl:
    name: str
    name_span: Span
    params: tuple[ParamDecl, ...]
    body: tuple[Statement, ...]
    span: Span


Decl = Union[ParamDecl, LetDecl, MaterialDecl, SceneDecl, CameraDecl, LightDecl, RenderDecl, PathDecl,
             PresetDecl, FormulaDecl]


@node
class Program:
    decls: tuple[Decl, ...]
    file: str
    source: str
