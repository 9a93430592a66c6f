"""Stage 1: text -> AST (`parse`). Lark LALR, then a non-recursive
Transformer to `ast` nodes, so that no step recurses on the input's depth."""
from __future__ import annotations

import re
from functools import lru_cache

from lark import Lark, Token, Transformer_NonRecursive, Tree, v_args
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken

from . import ast
from .errors import SceneError, Span, diagnostic, source_lines
from .resources import resource_dir
from .source import MAX_FILE_BYTES

MAX_NESTING = 256

_OPENING = {"LPAR": "RPAR", "LSQB": "RSQB", "LBRACE": "RBRACE"}
_CLOSING = set(_OPENING.values())
# Tokens that go on reading the operand of a unary minus (a postfix
# expression); any other token, outside brackets, ends it.
_OPERAND = {"NAME", "NUMBER", "DOT"}
_OPERAND_END = {"NAME", "NUMBER", "RPAR", "RSQB"}   # a '-' after these is binary

# Lark counts lines by "\n" alone; a lone "\r" is a line break too
# (errors.LINE_BREAK), so it reaches Lark as "\n", which keeps every column.
_LONE_CR = re.compile(r"\r(?!\n)")

# Token names as a user would say them, for "expected ..." messages.
_TOKEN_WORDS = {
    "NAME": "a name", "NUMBER": "a number", "LPAR": "'('", "RPAR": "')'",
    "LSQB": "'['", "RSQB": "']'", "LBRACE": "'{'", "RBRACE": "'}'",
    "COMMA": "','", "COLON": "':'", "EQUAL": "'='", "DOT": "'.'",
    "PLUS": "'+'", "MINUS": "'-'", "STAR": "'*'", "SLASH": "'/'",
    "BAR": "'|'", "AMP": "'&'", "_NL": "a new line", "$END": "the end of the file",
}


class _NestingError(Exception):
    def __init__(self, token: Token):
        self.token = token


class _BlockNewlines:
    """Post-lexer: keeps newlines only where they separate block entries
    (directly inside `{ }`), and enforces the nesting limit as the tokens
    arrive, at the token that passes it, before the parser holds them all.
    A level is an open bracket or a unary minus whose operand is still
    being read (the two things the LALR stack grows with)."""

    always_accept = ("_NL",)

    def process(self, stream):
        open_brackets: list[tuple[str, int]] = []   # kind, unary minuses open outside it
        unary = 0        # unary minuses open at the innermost bracket level
        depth = 0
        previous = None
        for token in stream:
            kind = token.type
            if kind == "_NL":
                if open_brackets and open_brackets[-1][0] == "LBRACE" and previous != "_NL":
                    previous = kind
                    yield token
                continue
            if kind in _OPENING or (kind == "MINUS" and previous not in _OPERAND_END):
                if kind == "MINUS":
                    unary += 1
                else:
                    open_brackets.append((kind, unary))
                    unary = 0
                depth += 1
                if depth > MAX_NESTING:
                    raise _NestingError(token)
            elif kind in _CLOSING and open_brackets:
                depth -= 1 + unary
                unary = open_brackets.pop()[1]
            elif kind not in _OPERAND:
                depth -= unary
                unary = 0
            previous = kind
            yield token


def _span(meta_or_token) -> Span:
    m = meta_or_token
    return Span(m.line, m.column, m.end_line, m.end_column)


_EXPRESSIONS = {"vector", "negate", "binary", "call", "method", "named_arg", "positional_arg"}


class _DepthTree(Tree):
    """Parse tree node that holds the depth of expression nodes below it and
    stops the parse the moment it passes the limit (operator chains, which
    the post-lexer does not count), before the rest of the input is read."""
    __slots__ = ("depth",)

    def __init__(self, data, children, meta=None):
        super().__init__(data, children, meta)
        # Only expressions and argument lists look at their children: the
        # helper nodes of `x*` lists grow one child at a time.
        below = max((c.depth for c in children if isinstance(c, _DepthTree)), default=0) \
            if data in _EXPRESSIONS or data == "args" else 0
        self.depth = below + 1 if data in _EXPRESSIONS else below
        if self.depth > MAX_NESTING:
            # A binary node is at its operator; others at their first token.
            where = children[1] if data == "binary" else next(
                (c for c in children if isinstance(c, Token)), children[0])
            raise _NestingError(where)


@v_args(meta=True)
class _ToAst(Transformer_NonRecursive):
    def __default__(self, data, children, meta):
        raise NotImplementedError(f"grammar rule {data!r} has no AST constructor")

    # expressions
    def number(self, meta, c):
        return ast.Number(float(c[0]), _span(meta))

    def name(self, meta, c):
        return ast.Name(str(c[0]), _span(meta))

    def vector(self, meta, c):
        return ast.Vector(tuple(c), _span(meta))

    def negate(self, meta, c):
        return ast.Unary("-", c[1], _span(meta))

    def binary(self, meta, c):
        left, op, right = c
        return ast.Binary(str(op), left, right, _span(meta))

    def call(self, meta, c):
        args = c[1] or ()
        return ast.Call(str(c[0]), _span(c[0]), args, _span(meta))

    def method(self, meta, c):
        receiver, name, args = c[0], c[1], c[2] or ()
        return ast.Method(receiver, str(name), _span(name), args, _span(meta))

    def args(self, meta, c):
        return tuple(c)

    def named_arg(self, meta, c):
        return ast.Arg(str(c[0]), c[1], _span(meta))

    def positional_arg(self, meta, c):
        return ast.Arg(None, c[0], _span(meta))

    # blocks and declarations
    def entry(self, meta, c):
        return ast.Entry(str(c[0]), _span(c[0]), c[1], _span(meta))

    def block(self, meta, c):
        entries = tuple(x for x in c if isinstance(x, ast.Entry))
        return ast.Block(entries, _span(meta))

    def bounds(self, meta, c):
        return (c[0], c[1])

    def param_decl(self, meta, c):
        return ast.ParamDecl(str(c[0]), _span(c[0]), c[1], c[2] if len(c) > 2 else None, _span(meta))

    def let_decl(self, meta, c):
        return ast.LetDecl(str(c[0]), _span(c[0]), c[1], _span(meta))

    def material_decl(self, meta, c):
        return ast.MaterialDecl(str(c[0]), _span(c[0]), c[1], _span(meta))

    def scene_decl(self, meta, c):
        return ast.SceneDecl(c[0], _span(meta))

    def camera_decl(self, meta, c):
        return ast.CameraDecl(c[0], _span(meta))

    def light_decl(self, meta, c):
        return ast.LightDecl(str(c[0]), _span(c[0]), c[1], _span(meta))

    def render_decl(self, meta, c):
        return ast.RenderDecl(c[0], _span(meta))

    def keyframe(self, meta, c):
        return ast.Keyframe(float(c[0]), _span(c[0]), c[1], _span(meta))

    def path_decl(self, meta, c):
        keyframes = tuple(x for x in c if isinstance(x, ast.Keyframe))
        return ast.PathDecl(keyframes, _span(meta))

    def start(self, meta, c):
        return tuple(c)


@lru_cache(maxsize=1)
def _parser() -> Lark:
    grammar = (resource_dir("grammar") / "frac.lark").read_text()
    return Lark(grammar, parser="lalr", lexer="contextual", postlex=_BlockNewlines(),
                propagate_positions=True, maybe_placeholders=True, tree_class=_DepthTree)


def _describe(token: Token) -> str:
    if token.type == "$END":
        return "the end of the file"
    if token.type == "_NL":
        return "a new line"
    return f"'{token}'"


def _expected_words(expected) -> str:
    words = sorted({_TOKEN_WORDS.get(e, f"'{e.lower()}'") for e in expected if not e.startswith("__")})
    if len(words) > 4:
        words = words[:4] + ["..."]
    return ", ".join(words)


def _syntax_message(error: UnexpectedInput) -> str:
    if isinstance(error, UnexpectedCharacters):
        return f"unexpected character '{error.char}'"
    if isinstance(error, UnexpectedEOF):
        return "unexpected end of the file (an unclosed bracket?)"
    assert isinstance(error, UnexpectedToken)
    token, expected = error.token, set(error.expected)
    if token.type == "NAME" and {"COMMA", "_NL"} & expected and "RBRACE" in expected \
            and "NUMBER" not in expected:
        return f"missing ',' or new line before '{token}' (block entries are separated by commas or new lines)"
    if token.type == "$END":
        return f"unexpected end of the file, expected {_expected_words(expected)}"
    return f"unexpected {_describe(token)}, expected {_expected_words(expected)}"


def parse(text: str, path: str = "<string>") -> ast.Program:
    """Parse `.frac` source into an `ast.Program`; raise `SceneError`."""
    def fail(span: Span, message: str):
        raise SceneError([diagnostic(path, text, span, message)])

    if len(text.encode("utf-8", errors="replace")) > MAX_FILE_BYTES:
        fail(Span(1, 1, 1, 2), f"the scene file is larger than {MAX_FILE_BYTES // (1024 * 1024)} MB")
    try:
        decls = _ToAst().transform(_parser().parse(_LONE_CR.sub("\n", text)))
    except UnexpectedInput as error:
        token = getattr(error, "token", None)
        if token is not None and token.type == "$END":
            lines = source_lines(text)
            last = len(lines) - (len(lines) > 1 and lines[-1] == "")   # the line a final break ends
            span = Span(last, len(lines[last - 1]) + 1, last, len(lines[last - 1]) + 2)
        else:
            span = Span(error.line, error.column, error.line, error.column + len(str(token or " ")))
        fail(span, _syntax_message(error))
    except _NestingError as error:
        where = error.token
        fail(_span(where.meta if isinstance(where, Tree) else where), f"nesting deeper than {MAX_NESTING} levels")
    return ast.Program(decls, path, text)
