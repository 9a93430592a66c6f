"""A formula's statements by phase (`init`, step, `final`) as a checked
`Formula`, and what they read and set (docs/formulas.md)."""
from __future__ import annotations

from dataclasses import dataclass

from . import ast
from .errors import Span
from .expressions import Mistake

ESTIMATES = ("escape_time_estimate", "linear_estimate")
# What `final` lines may read of the compiler's derivative (docs/formulas.md):
# dr, how fast |z| moves with the point (the running derivative; |grad |z||
# on the Jacobian path), and jacobian_norm, the most z moves when the point
# moves by one (the Jacobian's spectral norm; |dr| for similarities).
DERIVED = ("dr", "jacobian_norm")


@dataclass(frozen=True)
class Formula:
    """A checked formula: its parameters' names and statements by phase."""
    name: str
    params: tuple[str, ...]
    init: tuple[ast.Statement, ...]
    step: tuple[ast.Statement, ...]
    final: tuple[ast.Statement, ...]
    span: Span
    file: str = "<string>"          # the file it is written in

    @property
    def carried(self) -> tuple[str, ...]:
        """The names set by `init` that the step or the final lines use
        (z among them if it is), in order: the loop carries them."""
        used = names_of(self.step + self.final)
        names: list[str] = []
        for s in self.init:
            if s.name not in names and s.name in used:
                names.append(s.name)
        return tuple(names)

    @property
    def derived(self) -> tuple[str, ...]:
        """The compiler's derivatives (DERIVED) the final lines read, those
        the formula does not set itself (its own `init dr = 1`)."""
        own = names_of(self.init + self.step) | {s.name for s in self.final if isinstance(s, ast.Assign)}
        read = {e.name for e in expressions(self.final) if isinstance(e, ast.Name)}
        return tuple(name for name in DERIVED if name in read and name not in own)

    @property
    def sets_distance(self) -> bool:
        """Whether the final lines give the estimate (their own, or one of
        ESTIMATES chosen by name), not the compiler's by its kind."""
        return any(s.name == "distance" for s in self.final)

    @property
    def own_estimate(self) -> bool:
        """Whether `final distance = ...` gives the estimate without asking
        for the compiler's estimates or derivatives."""
        return self.sets_distance and not calls(self.final, ESTIMATES) and not self.derived


def split(decl: ast.FormulaDecl, file: str = "<string>") -> Formula:
    """The formula's statements by phase; a misplaced one is a Mistake."""
    phases: dict[str, list] = {"init": [], "step": [], "final": []}
    for statement in decl.body:
        phase = statement.phase if isinstance(statement, ast.Assign) else "step"
        phases[phase].append(statement)
        for inner in (statement, *nested(statement)):
            if not isinstance(inner, ast.Assign):
                continue
            if inner is not statement and inner.phase != "step":
                raise Mistake(inner.span, f"'{inner.phase}' goes at the top of a formula, not inside 'if'")
            own = RESERVED.get(inner.name)
            if own is not None and inner.phase != own:
                where = {"step": "a step line (no 'init' or 'final')", "final": "a 'final' line"}[own]
                raise Mistake(inner.name_span, f"'{inner.name}' is set in {where}")
    return Formula(decl.name, tuple(p.name for p in decl.params), tuple(phases["init"]),
                   tuple(phases["step"]), tuple(phases["final"]), decl.span, file)


# names with a meaning, and the phase that sets them
RESERVED = {"stop": "step", "trap": "step", "distance": "final"}


def nested(statement) -> list:
    """The statements inside `statement` (the sides of an `if`, and theirs)."""
    return [n for n in ast.walk(statement) if n is not statement and isinstance(n, (ast.Assign, ast.If))]


def expressions(statements) -> list:
    """Every expression node of `statements`, ifs' included."""
    return [n for s in statements for n in ast.walk(s) if not isinstance(n, (ast.Assign, ast.If, ast.Arg))]


def names_of(statements) -> set:
    """The names `statements` read or set."""
    assigned = {s.name for s in (*statements, *(n for s in statements for n in nested(s)))
                if isinstance(s, ast.Assign)}
    return assigned | {e.name for e in expressions(statements) if isinstance(e, ast.Name)}


def calls(statements, names) -> bool:
    return any(isinstance(e, ast.Call) and e.name in names for e in expressions(statements))
