"""Minimal edits of a scene's text at the spans its AST carries.

The studio writes values back into the user's file: a value is replaced
where it is written, an entry is added in its block's own layout (commas or
new lines, the indentation of the entry before it), a declaration goes on a
new line after its neighbour. Comments, spacing and every other character
stay as they were, so a diff of the file shows only what changed.
"""
from __future__ import annotations

import math
import re
from bisect import bisect_right
from dataclasses import dataclass

from .. import ast
from ..errors import LINE_BREAK, Span

# A name a preset may take: the language's names (grammar/frac.lark NAME)
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TRAILING_COMMA = re.compile(r"[ \t]*,")
_INDENT = re.compile(r"[ \t]*")
_COMMENT = re.compile(r"#[^\n\r]*")


@dataclass(frozen=True)
class Edit:
    """Replace the characters [start, end) of the text with `text`."""
    start: int
    end: int
    text: str


def apply(source: str, edits: list[Edit]) -> str:
    """`source` with `edits` (which must not overlap) made."""
    pieces, position = [], 0
    for edit in sorted(edits, key=lambda e: (e.start, e.end)):
        if edit.start < position:
            raise ValueError("overlapping edits")
        pieces += [source[position:edit.start], edit.text]
        position = edit.end
    pieces.append(source[position:])
    return "".join(pieces)


class Text:
    """A scene's text with the offsets of its lines: spans (lines and
    columns, as the parser counts them) to offsets."""

    def __init__(self, source: str):
        self.source = source
        self.line_starts = [0] + [m.end() for m in LINE_BREAK.finditer(source)]

    def offset(self, line: int, column: int) -> int:
        return self.line_starts[line - 1] + column - 1

    def start(self, span: Span) -> int:
        return self.offset(span.line, span.column)

    def end(self, span: Span) -> int:
        return self.offset(span.end_line, span.end_column)

    def line_end(self, offset: int) -> int:
        """The offset of the line break that ends the line at `offset` (the
        text's end on the last line)."""
        found = LINE_BREAK.search(self.source, offset)
        return found.start() if found else len(self.source)

    def indent(self, offset: int) -> str:
        """The leading space of the line at `offset`."""
        start = self.line_starts[bisect_right(self.line_starts, offset) - 1]
        return _INDENT.match(self.source, start).group()


# ---- values as the language writes them ---------------------------------------

def number_text(value: float, low: float | None = None, high: float | None = None) -> str:
    """A finite number as a literal, to 6 significant digits unless that
    would leave [low, high] (then exactly)."""
    if not math.isfinite(value):
        raise ValueError(f"{value!r} is not a finite number")
    text = f"{value:.6g}"
    if (low is not None and float(text) < low) or (high is not None and float(text) > high):
        text = repr(float(value))
    return "0" if float(text) == 0 else text     # never "-0"


def vector_text(values) -> str:
    return "(" + ", ".join(number_text(float(v)) for v in values) + ")"


def entries_text(values: dict[str, str]) -> str:
    """`{ key: value, ... }` on one line."""
    return "{ " + ", ".join(f"{key}: {value}" for key, value in values.items()) + " }"


# ---- edits -------------------------------------------------------------------

def replace(text: Text, span: Span, new: str) -> Edit:
    return Edit(text.start(span), text.end(span), new)


def find_entry(block: ast.Block, key: str) -> ast.Entry | None:
    return next((e for e in block.entries if e.key == key), None)


def set_entry(text: Text, block: ast.Block, path: tuple[str, ...], value: str) -> list[Edit]:
    """Give the key `path` (a key, or a block key's keys: ("fog",
    "density")) the value text `value` in `block`: its value replaced where
    it is written, else a new entry."""
    entry = find_entry(block, path[0])
    if len(path) > 1:
        if entry is not None and isinstance(entry.value, ast.Block):
            return set_entry(text, entry.value, path[1:], value)
        for key in reversed(path[1:]):
            value = entries_text({key: value})
    if entry is not None:
        return [replace(text, entry.value.span, value)]
    return _insert_entry(text, block, f"{path[0]}: {value}")


def _insert_entry(text: Text, block: ast.Block, entry: str) -> list[Edit]:
    """A new entry after the block's last, laid out like the entries
    before it: on a new line with the last one's indentation if they are on
    lines of their own, else after a comma on the same line."""
    source = text.source
    opening, closing = text.start(block.span), text.end(block.span) - 1
    if not block.entries:
        inside = source[opening + 1:closing]
        if LINE_BREAK.search(inside):
            indent = text.indent(closing)
            return [Edit(opening + 1, closing, f"\n{indent}    {entry}\n{indent}")]
        return [Edit(opening + 1, closing, f" {entry} ")]
    entries = block.entries
    last_end = text.end(entries[-1].span)
    trailing = _TRAILING_COMMA.match(source, last_end, closing)
    commas = bool(trailing) or any("," in _COMMENT.sub("", source[text.end(a.span):text.start(b.span)])
                                   for a, b in zip(entries, entries[1:]))
    after = trailing.end() if trailing else last_end
    own_lines = bool(LINE_BREAK.search(source, opening, text.start(entries[-1].span)))
    if not own_lines:
        return [Edit(after, after, ("" if trailing else ",") + f" {entry}" + ("," if trailing else ""))]
    edits = [] if trailing or not commas else [Edit(last_end, last_end, ",")]
    line_end = text.line_end(after)
    # after a comment that ends the line, unless the block closes on it
    at = line_end if line_end < closing else after
    indent = text.indent(text.start(entries[-1].span))
    edits.append(Edit(at, at, f"\n{indent}{entry}" + ("," if trailing else "")))
    return edits


def remove_entry(text: Text, block: ast.Block, key: str) -> list[Edit]:
    """Take the entry of `key` out of `block`, with the separator before it
    (after it, for the first entry)."""
    entries = block.entries
    index = next((i for i, e in enumerate(entries) if e.key == key), None)
    if index is None:
        return []
    if index > 0:
        return [Edit(text.end(entries[index - 1].span), text.end(entries[index].span), "")]
    end = text.start(entries[1].span) if len(entries) > 1 else text.end(entries[0].span)
    return [Edit(text.start(entries[0].span), end, "")]


def add_declaration(text: Text, after: ast.Decl | None, declaration: str) -> Edit:
    """`declaration` on a line of its own: after the line where `after`
    ends, or at the end of the text."""
    if after is not None:
        at = text.line_end(text.end(after.span))
        return Edit(at, at, "\n" + declaration)
    source = text.source
    separator = "" if not source or source.endswith(("\n", "\r")) else "\n"
    return Edit(len(source), len(source), f"{separator}{declaration}\n")


def last_of(program: ast.Program, *kinds: type) -> ast.Decl | None:
    """The last declaration of the first of `kinds` the program has."""
    for kind in kinds:
        found = [d for d in program.decls if isinstance(d, kind)]
        if found:
            return found[-1]
    return None


# ---- what the studio writes back ---------------------------------------------

def param_edits(text: Text, program: ast.Program, values: dict[str, str]) -> list[Edit]:
    """Each param's default (`param NAME = VALUE`) replaced by its value text."""
    declared = {}
    for decl in program.decls:
        if isinstance(decl, ast.ParamDecl):
            declared.setdefault(decl.name, decl)
    return [replace(text, declared[name].default.span, value) for name, value in values.items() if name in declared]


def camera_edits(text: Text, program: ast.Program, values: dict[str, str]) -> list[Edit]:
    """The camera block's keys set to their value texts; a camera block
    after the scene if there is none."""
    if not values:
        return []
    camera = last_of(program, ast.CameraDecl)
    if camera is None:
        return [add_declaration(text, last_of(program, ast.SceneDecl), "camera " + entries_text(values))]
    return [edit for key, value in values.items() for edit in set_entry(text, camera.block, (key,), value)]


def preset_edits(text: Text, program: ast.Program, presets: dict[str, dict[str, str]]) -> list[Edit]:
    """Each preset's values: written into its block where the file has one,
    else a new `preset NAME { ... }` after the last preset (or param)."""
    existing = {d.name: d for d in program.decls if isinstance(d, ast.PresetDecl)}
    edits, new = [], []
    for name, values in presets.items():
        if not NAME.fullmatch(name):
            raise ValueError(f"'{name}' is not a name (letters, digits and _, not starting with a digit)")
        if name in existing:
            block = existing[name].block
            edits += [edit for key, value in values.items() for edit in set_entry(text, block, (key,), value)]
        else:
            new.append(f"preset {name} {entries_text(values)}")
    if new:
        after = last_of(program, ast.PresetDecl, ast.ParamDecl)
        edits.append(add_declaration(text, after, "\n".join(new)) if after else
                     Edit(0, 0, "\n".join(new) + "\n"))
    return edits


def path_text(keyframes: list[tuple[str, dict[str, str]]]) -> str:
    """A `path` block of (time text, values) keyframes, one to a line."""
    lines = [f"    {time}: {entries_text(values)}" for time, values in keyframes]
    return "path {\n" + "\n".join(lines) + "\n}"


def path_edit(text: Text, program: ast.Program, keyframes: list[tuple[str, dict[str, str]]]) -> Edit:
    """The path block replaced by these keyframes, or added after the camera."""
    path = last_of(program, ast.PathDecl)
    if path is not None:
        return replace(text, path.span, path_text(keyframes))
    return add_declaration(text, last_of(program, ast.CameraDecl, ast.SceneDecl), path_text(keyframes))


def remove_declaration(text: Text, decl: ast.Decl) -> Edit:
    """Take a declaration out, with the line break that ends its line."""
    start, end = text.start(decl.span), text.end(decl.span)
    found = LINE_BREAK.match(text.source, end)
    return Edit(start, found.end() if found else end, "")
