"""What every part of the checker shares (fractalc/check.py): a checked
expression's `Value`, the error value that later checks accept silently
(one mistake, one message), and the diagnostics."""
from __future__ import annotations

import difflib
import itertools
from dataclasses import dataclass

from . import ast, ir
from .errors import Diagnostic, Severity, Span, diagnostic
from .expressions import Mistake
from .formula_statements import Formula
from .program import Material, ParamCheck, ParamInfo, Shape, constant
from .stdlib import Signature, library
from .types import Parameter, Type

NUMBER, SHAPE, MATERIAL, WORD = Type.NUMBER, Type.SHAPE, Type.MATERIAL, Type.WORD
COLORING, FORMULA = Type.COLORING, Type.FORMULA


@dataclass(frozen=True)
class Value:
    type: Type
    data: object       # ir.Expr | ir.Vec | Shape | material name | word


ERROR = Value(Type.ERROR, None)


# Errors that get a "did you mean" (each costs time in the number of known names)
SUGGESTED_ERRORS = 10


class Failed(Exception):
    """Raised to abandon the current expression after recording an error."""


class CheckerBase:
    """The state of one check: the program, its declarations as far as
    they are known, and the diagnostics found."""

    def __init__(self, program: ast.Program, library_formulas=()):
        self.program = program
        self.errors: list[Diagnostic] = []
        self.library = library()
        self.params: dict[str, ParamInfo] = {}
        self.lets: dict[str, ast.LetDecl] = {}
        self.let_values: dict[str, Value] = {}
        self.material_decls: dict[str, ast.MaterialDecl] = {}
        self.materials: dict[str, Material] = {}
        self.colors: dict[tuple, str] = {}
        self.param_checks: list[ParamCheck] = []
        self.shape_sizes: dict[int, tuple[Shape, int]] = {}
        # the library's formulas, and those a scene can call by name: the library's and the file's own
        self.library_formulas: dict[str, tuple[Formula, Signature]] = dict(library_formulas)
        self.formulas: dict[str, tuple[Formula, Signature] | None] = dict(self.library_formulas)
        self.notes: list[Diagnostic] = []

    def error(self, span: Span, message: str) -> None:
        self.errors.append(diagnostic(self.program.file, self.program.source, span, message))

    def fail(self, span: Span, message: str):
        self.error(span, message)
        raise Failed

    def shared(self, compute, *args):
        """`compute(*args)` of the expression core (fractalc/expressions.py),
        its Mistake this checker's error."""
        try:
            return compute(*args)
        except Mistake as mistake:
            self.fail(mistake.span, mistake.message)

    def note(self, span: Span, message: str) -> None:
        self.notes.append(diagnostic(self.program.file, self.program.source, span, message, Severity.NOTE))

    def did_you_mean(self, name: str, *known) -> str:
        """' (did you mean 'x'?)' naming the name in `known` (collections
        of names) closest to `name`, or ''. Its cost grows with the known
        names, so only the first SUGGESTED_ERRORS errors get one: a file of
        thousands of unknown names stays linear."""
        if len(self.errors) >= SUGGESTED_ERRORS:
            return ""
        close = closest_name(name, itertools.chain(*known))
        return f" (did you mean '{close}'?)" if close else ""


def closest_name(name: str, known) -> str | None:
    """The name among `known` closest to a misspelt `name`, if one is close."""
    close = difflib.get_close_matches(name, known, n=1)
    return close[0] if close else None


def source_text(program: ast.Program, span: Span) -> str:
    """The text of a one-line span (a number as the user wrote it)."""
    lines = program.source.splitlines()
    if span.line != span.end_line or not 0 < span.line <= len(lines):
        return "this"
    return lines[span.line - 1][span.column - 1:span.end_column - 1]


def default_value(p: Parameter):
    """An argument's default as its value: a word, or IR constants (a size's
    number on all three axes)."""
    if isinstance(p.default, str):
        return p.default
    if p.type is Type.SIZE and not isinstance(p.default, tuple):
        return ir.vec(*(ir.const(p.default),) * 3)
    return constant(p.default)
