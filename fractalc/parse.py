"""Stage 1: text -> AST (`parse`). Lark LALR, then a non-recursive
Transformer to `ast` nodes, so that no step recurses on the input's depth."""
from __future__ import annotations

from functools import lru_cache

from lark import Lark, Token, Transformer_NonRecursive, v_args
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken, VisitError

from . import ast
from .errors import SceneError, Span, diagnostic
from .resources import resource_dir

MAX_FILE_BYTES = 8 * 1024 * 1024
MAX_NESTING = 256

_OPENING = {"LPAR": "RPAR", "LSQB": "RSQB", "LBRACE": "RBRACE"}
_CLOSING = set(_OPENING.values())

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
    (directly inside `{ }`), and enforces the nesting limit."""

    always_accept = ("_NL",)

    def process(self, stream):
        open_brackets: list[str] = []
        previous_newline = True
        for token in stream:
            kind = token.type
            if kind == "_NL":
                if open_brackets and open_brackets[-1] == "LBRACE" and not previous_newline:
                    previous_newline = True
                    yield token
                continue
            previous_newline = False
            if kind in _OPENING:
                open_brackets.append(kind)
                if len(open_brackets) > MAX_NESTING:
                    raise _NestingError(token)
            elif kind in _CLOSING and open_brackets:
                open_brackets.pop()
            yield token


def _span(meta_or_token) -> Span:
    m = meta_or_token
    return Span(m.line, m.column, m.end_line, m.end_column)


def _depth_checked(node, *children):
    """AST depth limit for operator chains (brackets are limited earlier)."""
    depth = 1 + max((getattr(c, "_depth", 0) for c in children), default=0)
    if depth > MAX_NESTING:
        raise _NestingError(node.span)
    object.__setattr__(node, "_depth", depth)
    return node


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
        return _depth_checked(ast.Vector(tuple(c), _span(meta)), *c)

    def negate(self, meta, c):
        return _depth_checked(ast.Unary("-", c[1], _span(meta)), c[1])

    def binary(self, meta, c):
        left, op, right = c
        return _depth_checked(ast.Binary(str(op), left, right, _span(meta)), left, right)

    def call(self, meta, c):
        args = c[1] or ()
        return _depth_checked(ast.Call(str(c[0]), _span(c[0]), args, _span(meta)), *args)

    def method(self, meta, c):
        receiver, name, args = c[0], c[1], c[2] or ()
        return _depth_checked(
            ast.Method(receiver, str(name), _span(name), args, _span(meta)), receiver, *args)

    def args(self, meta, c):
        return tuple(c)

    def named_arg(self, meta, c):
        return _depth_checked(ast.Arg(str(c[0]), c[1], _span(meta)), c[1])

    def positional_arg(self, meta, c):
        return _depth_checked(ast.Arg(None, c[0], _span(meta)), c[0])

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
                propagate_positions=True, maybe_placeholders=True)


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
        decls = _ToAst().transform(_parser().parse(text))
    except UnexpectedInput as error:
        token = getattr(error, "token", None)
        if token is not None and token.type == "$END":
            lines = text.splitlines() or [""]
            span = Span(len(lines), len(lines[-1]) + 1, len(lines), len(lines[-1]) + 2)
        else:
            span = Span(error.line, error.column, error.line, error.column + len(str(token or " ")))
        fail(span, _syntax_message(error))
    except (_NestingError, VisitError) as error:
        nesting = error if isinstance(error, _NestingError) else error.orig_exc
        if not isinstance(nesting, _NestingError):
            raise
        where = nesting.token
        span = where if isinstance(where, Span) else _span(where)
        fail(span, f"nesting deeper than {MAX_NESTING} levels")
    return ast.Program(decls, path, text)
