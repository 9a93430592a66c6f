"""Lines of OpenCL C inside the string literals of fractalc's Python
modules: what the rule "OpenCL C lives in .cl files" leaves (the `#define`
lines that carry a value, counted apart) and what it does not.

    python benchmarks/c_in_python.py [--list]

An ast walk reads every string literal of fractalc/**/*.py but docstrings
(an f-string's values read as `$`), splits it into lines and takes a line
for C by a heuristic: a preprocessor directive, an OpenCL address space or
`__kernel`, a statement (ending in `;` after a name or a bracket), a block's
brace (`) {`, `} else {`, a line that is `}`), or a `for`/`if`/`while`
head. Not counted: strings that C is read by (a pattern, a separator, a
comparison's words), one-character strings (tokens), strings with no `;`,
directive, OpenCL qualifier or C block head (the scene language's blocks
have braces too), lines quoting with `'` (prose: fractalc writes no
character literals), and expressions (an operator's C spelling in ir.OPS,
`params[i]`): writing those is the emitter's job.
`--list` prints each line counted, with its place.
"""
from __future__ import annotations

import argparse
import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

_DEFINE = re.compile(r"^\s*#\s*define\s+[\w$]+(\(.*?\))?\s+\S")
_DIRECTIVE = re.compile(r"^\s*#\s*(define|undef|if|ifdef|ifndef|elif|else|endif|pragma|include)\b")
_C_LINE = re.compile(
    r"\b__(kernel|constant|global|local|private)\b"       # OpenCL's qualifiers
    r"|[\w)\]}$]\s*;$"                                      # a statement
    r"|\)\s*\{\s*$|^\s*\}|\belse\s*\{"                     # a block's braces
    r"|\b(for|if|while)\s*\(.*\)\s*(\{|break|return|continue)")


# A string holds C only with one of these: the scene language's blocks
# (`camera {`, the studio's edits) have braces but neither
_C_MARK = re.compile(r";|^\s*#\s*\w|\b__(kernel|constant|global)\b|\b(for|if|while)\s*\(|\}\s*else\s*\{", re.M)


def _docstrings(tree) -> set[int]:
    """The ids of the docstring nodes of a module and its classes and functions."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                    and isinstance(first.value.value, str):
                found.add(id(first.value))
    return found


# Strings that C text is read by, not written with: patterns, separators,
# the words of a comparison
_READING = {"startswith", "endswith", "index", "find", "count", "partition", "split", "replace", "compile",
            "match", "search", "sub", "findall"}


def _read_not_written(tree) -> set[int]:
    """The ids of the strings that a program reads C text by (the
    arguments of str's and re's search functions, a comparison's operands)."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _READING:
            found.update(id(a) for a in node.args)
        elif isinstance(node, ast.Compare):
            found.update(id(a) for a in (node.left, *node.comparators))
    return found


def _strings(tree):
    """(line, text) of each string literal written into a program (no
    docstring, no pattern); an f-string's values as $."""
    skip = _docstrings(tree) | _read_not_written(tree)
    inside_fstring = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr) and id(node) not in skip:
            inside_fstring.update(id(v) for v in node.values)
            text = "".join(v.value if isinstance(v, ast.Constant) else "$" for v in node.values)
            yield node.lineno, text
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and id(node) not in skip and id(node) not in inside_fstring:
            yield node.lineno, node.value


def c_lines(path: Path):
    """(kind, line number, text) of each C line in `path`'s strings: kind
    `define` for a #define that carries a value, `c` for any other."""
    tree = ast.parse(path.read_text(), str(path))
    for line_number, text in _strings(tree):
        if len(text) == 1 or not _C_MARK.search(text):
            continue
        for line in text.splitlines():
            if "'" in line:
                continue
            if _DEFINE.match(line):
                yield "define", line_number, line
            elif _DIRECTIVE.match(line) or _C_LINE.search(line):
                yield "c", line_number, line


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="print each line counted")
    args = parser.parse_args(argv)
    totals = {"define": 0, "c": 0}
    for path in sorted((ROOT / "fractalc").rglob("*.py")):
        found = list(c_lines(path))
        counts = {kind: sum(1 for k, _, _ in found if k == kind) for kind in totals}
        for kind in totals:
            totals[kind] += counts[kind]
        if found:
            print(f"{path.relative_to(ROOT)}: {counts['c']} C lines, {counts['define']} #define lines")
        if args.list:
            for kind, line_number, line in found:
                print(f"  {path.relative_to(ROOT)}:{line_number}: [{kind}] {line.strip()}")
    print(f"total: {totals['c']} lines of C beyond #define lines that carry values; "
          f"{totals['define']} such #define lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
