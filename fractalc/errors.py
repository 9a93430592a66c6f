"""Source spans and the two errors fractalc raises at users.

Only `parse` and `check` raise `SceneError`; everything after them is either
correct by construction or a `RenderError` (runtime) / compiler bug.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Span:
    """A half-open region of the source: 1-based line/column of its first
    and one past its last character."""
    line: int
    column: int
    end_line: int
    end_column: int

    def to(self, other: "Span") -> "Span":
        return Span(self.line, self.column, other.end_line, other.end_column)


@dataclass(frozen=True)
class Diagnostic:
    file: str
    line: int
    column: int
    message: str
    source_line: str = ""
    width: int = 1

    def __str__(self) -> str:
        text = f"{self.file}:{self.line}:{self.column}: error: {self.message}"
        if self.source_line:
            line = self.source_line.expandtabs(1).rstrip("\n")
            width = max(1, min(self.width, len(line) - self.column + 1))
            text += f"\n    {line}\n    {' ' * (self.column - 1)}{'^' * width}"
        return text


def diagnostic(file: str, source: str, span: Span, message: str) -> Diagnostic:
    lines = source.splitlines()
    line_text = lines[span.line - 1] if 0 < span.line <= len(lines) else ""
    width = span.end_column - span.column if span.end_line == span.line else 1
    return Diagnostic(file, span.line, span.column, message, line_text, max(1, width))


class SceneError(Exception):
    """One or more errors in a scene. `file`, `line`, `column`, `message`
    describe the first; `errors` holds all of them in source order."""

    def __init__(self, errors: list[Diagnostic]):
        self.errors = sorted(errors, key=lambda d: (d.line, d.column))
        first = self.errors[0]
        self.file, self.line, self.column, self.message = (
            first.file, first.line, first.column, first.message)
        super().__init__(str(self))

    def __str__(self) -> str:
        return "\n".join(str(e) for e in self.errors)


class RenderError(Exception):
    """A runtime failure: no OpenCL device, out of memory, a kernel that
    failed to build (a compiler bug), an unsupported precision."""
