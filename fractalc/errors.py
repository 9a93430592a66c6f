"""Source spans and the two errors fractalc raises at users.

Only `parse` and `check` raise `SceneError`; everything after them is either
correct by construction or a `RenderError` (runtime) / compiler bug.
"""
from __future__ import annotations

import enum
import re
import unicodedata
from dataclasses import dataclass
from functools import lru_cache

# The one definition of a line break, shared by the parser and diagnostics:
# "\n", "\r\n" or a lone "\r". Other characters that str.splitlines() breaks
# at (form feed, "\v", "\x1c"-"\x1e", "\x85", U+2028, U+2029) are not.
LINE_BREAK = re.compile(r"\r\n?|\n")

# A long source line is quoted as a window this many characters either side
# of the caret's span (which is itself cut to this length).
_QUOTE_CONTEXT = 60


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


class Severity(str, enum.Enum):
    ERROR = "error"      # the scene is refused
    NOTE = "note"        # the scene is fine; something about it a user should know


@dataclass(frozen=True)
class Diagnostic:
    file: str
    line: int
    column: int
    message: str
    source_line: str = ""
    width: int = 1
    severity: Severity = Severity.ERROR

    def __str__(self) -> str:
        text = f"{visible(self.file)}:{self.line}:{self.column}: {self.severity.value}: {visible(self.message)}"
        if self.source_line:
            text += "\n" + quote(self.source_line, self.column, self.width)
        return text


def visible(text: str) -> str:
    """`text` safe to print on a terminal: a tab becomes a space and any
    other unprintable character (controls such as ESC, line and paragraph
    separators, bidirectional overrides) an escape such as \\x1b."""
    if text.isprintable():
        return text
    return "".join(_visible_char(c) for c in text)


def _visible_char(c: str) -> str:
    if c.isprintable():
        return c
    if c == "\t":
        return " "
    code = ord(c)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}"


def _terminal_columns(shown: str) -> int:
    """Columns `shown` (already visible()) takes: wide East Asian characters
    take two, combining marks none."""
    if shown.isascii():
        return len(shown)
    return sum(0 if unicodedata.combining(c) else 2 if unicodedata.east_asian_width(c) in "WF" else 1
               for c in shown)


def quote(line: str, column: int, width: int) -> str:
    """The source line and a caret under `width` characters from `column`,
    both indented; a long line is cut to a window around the caret."""
    start = max(0, column - 1 - _QUOTE_CONTEXT)
    marked_end = column - 1 + max(1, min(width, _QUOTE_CONTEXT))
    end = min(len(line), marked_end + _QUOTE_CONTEXT)
    before = ("..." if start > 0 else "") + visible(line[start:column - 1])
    marked = visible(line[column - 1:marked_end])
    after = visible(line[marked_end:end]) + ("..." if end < len(line) else "")
    caret = "^" * max(1, _terminal_columns(marked))
    return f"    {before}{marked}{after}\n    {' ' * _terminal_columns(before)}{caret}"


@lru_cache(maxsize=2)
def source_lines(source: str) -> tuple[str, ...]:
    """The lines of `source` (see LINE_BREAK), computed once per source so
    that many diagnostics cost linear time."""
    return tuple(LINE_BREAK.split(source))


def diagnostic(file: str, source: str, span: Span, message: str,
               severity: Severity = Severity.ERROR) -> Diagnostic:
    lines = source_lines(source)
    line_text = lines[span.line - 1] if 0 < span.line <= len(lines) else ""
    width = span.end_column - span.column if span.end_line == span.line else 1
    return Diagnostic(file, span.line, span.column, message, line_text, max(1, width), severity)


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


class NoSceneFile(RenderError):
    """The scene path names no regular file: nothing is there, or it is a
    directory, a FIFO or a device. The command line reports it as a usage
    mistake; other unreadable files stay runtime failures."""
