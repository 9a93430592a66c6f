"""Stage 1: text -> AST (`parse`). Lark LALR, then a non-recursive
Transformer to `ast` nodes, so that no step recurses on the input's depth."""
from __future__ import annotations

import gc
import re
from array import array
from dataclasses import dataclass, replace
from functools import lru_cache
from itertools import islice
from sys import intern

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

# Lark counts lines by "\n" alone; "\r\n" and a lone "\r" are line breaks
# too (errors.LINE_BREAK), so each reaches the parsers as "\n": every column
# is kept, and an unexpected line break is placed just after its line.
_LINE_BREAK = re.compile(r"\r\n?")

# Token names as a user would say them, for "expected ..." messages.
_TOKEN_WORDS = {
    "NAME": "a name", "NUMBER": "a number", "LPAR": "'('", "RPAR": "')'",
    "LSQB": "'['", "RSQB": "']'", "LBRACE": "'{'", "RBRACE": "'}'",
    "COMMA": "','", "COLON": "':'", "EQUAL": "'='", "DOT": "'.'",
    "PLUS": "'+'", "MINUS": "'-'", "STAR": "'*'", "SLASH": "'/'",
    "BAR": "'|'", "AMP": "'&'", "COMPARE": "a comparison", "_NL": "a new line", "$END": "the end of the file",
    "STRING": "a string",
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


_EXPRESSIONS = {"vector", "negate", "binary", "call", "method", "field", "named_arg", "positional_arg"}
_CHAINS = {"union_chain", "intersection_chain"}


class _DepthTree(Tree):
    """Parse tree node that holds the depth of expression nodes below it and
    stops the parse the moment it passes the limit (operator chains, which
    the post-lexer does not count), before the rest of the input is read."""
    __slots__ = ("depth",)

    def __init__(self, data, children, meta=None):
        super().__init__(data, children, meta)
        if data in _CHAINS:      # a chain is one level above its deepest operand, however long
            first, last = children[0], children[2]
            so_far = first.depth - 1 if isinstance(first, _DepthTree) and first.data == data else _depth(first)
            self.depth = max(so_far, _depth(last)) + 1
        else:
            # Only expressions and argument lists look at their children: the
            # helper nodes of `x*` lists grow one child at a time.
            below = max((c.depth for c in children if isinstance(c, _DepthTree)), default=0) \
                if data in _EXPRESSIONS or data in ("args", "chain") else 0
            self.depth = below + 1 if data in _EXPRESSIONS else below
        if self.depth > MAX_NESTING:
            # A binary node or chain is at its operator; others at their first token.
            where = children[1] if data == "binary" or data in _CHAINS else next(
                (c for c in children if isinstance(c, Token)), children[0])
            raise _NestingError(where)


def _depth(child) -> int:
    return child.depth if isinstance(child, _DepthTree) else 0


class _Operands:
    """A chain's operator and operands, while Lark reads it."""
    __slots__ = ("op", "items")

    def __init__(self, op: str, items: list):
        self.op, self.items = op, items


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

    def union_chain(self, meta, c):
        """The operands so far (one list, grown in place: linear time)."""
        operands, op, right = c
        if not isinstance(operands, _Operands):
            operands = _Operands(str(op), [operands])
        operands.items.append(right)
        return operands

    intersection_chain = union_chain

    def chain(self, meta, c):
        return ast.Chain(c[0].op, tuple(c[0].items), _span(meta))

    def call(self, meta, c):
        args = c[1] or ()
        return ast.Call(str(c[0]), _span(c[0]), args, _span(meta))

    def method(self, meta, c):
        receiver, name, args = c[0], c[1], c[2] or ()
        return ast.Method(receiver, str(name), _span(name), args, _span(meta))

    def field(self, meta, c):
        return ast.Field(c[0], str(c[1]), _span(c[1]), _span(meta))

    def args(self, meta, c):
        return tuple(c)

    def named_arg(self, meta, c):
        return ast.Arg(str(c[0]), c[1], _span(meta))

    def positional_arg(self, meta, c):
        return ast.Arg(None, c[0], _span(meta))

    # blocks and declarations
    def entry(self, meta, c):
        value = c[1]
        if isinstance(value, Token):     # a STRING
            value = ast.String(value[1:-1], _span(value))
        return ast.Entry(str(c[0]), _span(c[0]), value, _span(meta))

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

    def preset_decl(self, meta, c):
        return ast.PresetDecl(str(c[0]), _span(c[0]), c[1], _span(meta))

    def render_decl(self, meta, c):
        return ast.RenderDecl(c[0], _span(meta))

    def keyframe(self, meta, c):
        return ast.Keyframe(float(c[0]), _span(c[0]), c[1], _span(meta))

    def path_decl(self, meta, c):
        keyframes = tuple(x for x in c if isinstance(x, ast.Keyframe))
        return ast.PathDecl(keyframes, _span(meta))

    # formulas
    def formula_decl(self, meta, c):
        return ast.FormulaDecl(str(c[0]), _span(c[0]), c[1] or (), c[2], _span(meta))

    def formula_params(self, meta, c):
        return tuple(c)

    def formula_param(self, meta, c):
        return ast.ParamDecl(str(c[0]), _span(c[0]), c[1], c[2] if len(c) > 2 else None, _span(meta))

    def statements(self, meta, c):
        return tuple(x for x in c if isinstance(x, (ast.Assign, ast.If)))

    def _assign(self, meta, c, phase):
        return ast.Assign(str(c[0]), _span(c[0]), c[1], phase, _span(meta))

    def assign(self, meta, c):
        return self._assign(meta, c, "step")

    def init_assign(self, meta, c):
        return self._assign(meta, c, "init")

    def final_assign(self, meta, c):
        return self._assign(meta, c, "final")

    def if_statement(self, meta, c):
        otherwise = c[2] if len(c) > 2 and c[2] is not None else ()
        if isinstance(otherwise, ast.If):
            otherwise = (otherwise,)
        return ast.If(c[0], c[1], otherwise, _span(meta))

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
    words = sorted({_TOKEN_WORDS.get(e, f"'{e.lstrip('_').lower()}'") for e in expected if not e.startswith("__")})
    if len(words) > 4:
        words = words[:4] + ["..."]
    return ", ".join(words)


def _syntax_message(error: UnexpectedInput, before: str = "", bracket: str | None = None) -> str:
    """What went wrong; `before` is the text of the error's line before it,
    `bracket` the innermost one open there."""
    if isinstance(error, UnexpectedCharacters):
        if error.char == '"':
            return "unterminated string: a string ends with '\"' on the line it starts"
        return f"unexpected character '{error.char}'"
    if isinstance(error, UnexpectedEOF):
        return "unexpected end of the file (an unclosed bracket?)"
    assert isinstance(error, UnexpectedToken)
    token, expected = error.token, set(error.expected)
    if token.type == "NAME" and {"COMMA", "_NL"} & expected and "NUMBER" not in expected:
        if bracket == "{" and "RBRACE" in expected:
            return f"missing ',' or new line before '{token}' (block entries are separated by commas or new lines)"
        if bracket in ("(", "[") and "COMMA" in expected:
            return f"missing ',' before '{token}' (arguments and components are separated by commas)"
    if token.type == "$END":
        return f"unexpected end of the file, expected {_expected_words(expected)}"
    if token.type == "STRING":
        return f"unexpected string {token}: a string is a file name, only ever a block entry's value"
    if token.type == "COMPARE":
        return f"unexpected '{token}': comparisons do not chain (join them with '&': 'a < b & b < c')"
    if token.type == "LBRACE" and re.search(r"(^|\W)else\s*$", before):
        return "'else' goes on the line of the '}' that ends its 'if' ('} else {')"
    return f"unexpected {_describe(token)}, expected {_expected_words(expected)}"


# ---- the fast parser ---------------------------------------------------------

class _Stop(Exception):
    """The fast parser met a token it does not take: Lark decides."""


# Lark's tokens (see grammar/frac.lark): skipped space and comments, then a
# name, a number, a punctuation mark or a new line; group 4 is the end of the
# text, group 5 a string and group 6 any other character (an error).
_FAST_TOKEN = re.compile(r"(?:[ \t\r\f]+|#[^\n]*)*(?:([A-Za-z_][A-Za-z0-9_]*)|((?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)"
                         r"|(<=|>=|==|!=|[-+*/|&(){}\[\],:=.<>\n])|(\Z)|(\"[^\"\n]*\")|(.))", re.S)
_DECL_WORDS = frozenset({"param", "let", "material", "scene", "camera", "light", "render", "path", "preset",
                         "formula"})
# Declarations of a name and a block: `material NAME { ... }`
_NAMED_BLOCKS = {"material": ast.MaterialDecl, "light": ast.LightDecl, "preset": ast.PresetDecl}
_COMPARISONS = frozenset({"<", "<=", ">", ">=", "==", "!="})
# of the operators `arithmetic` reads; `|` and `&` chains are `expr`'s
_PRECEDENCE = {**{c: 2.5 for c in _COMPARISONS}, "+": 3, "-": 3, "*": 4, "/": 4}
_STATEMENT_WORDS = frozenset({"init", "final", "if", "else"})     # keywords where a statement starts
_SEPARATORS = frozenset({",", "\n"})
# The fast parser hands anything this deep to Lark, which reports the
# nesting limit exactly where it is passed.
_FAST_DEPTH = MAX_NESTING - 8
_FIRST_TOKENS = 1 << 12


def _tokens(source: str, most: int | None) -> tuple[list, list, list, list]:
    """Kinds ("name", "number", "string", the punctuation itself, "\n", "" at
    the end, "?" for a character no token starts with, "..." where `most` tokens
    were read), texts, lines and columns of the tokens of `source`. New
    lines are kept only directly inside `{ }` and once, as `_BlockNewlines`
    does."""
    # Lines and columns as machine integers: at 8 MB, Python ints would take
    # a few hundred MB.
    kinds, texts, lines, columns, open_brackets = [], [], array("q"), array("q"), []
    add_kind, add_text, add_line, add_column = kinds.append, texts.append, lines.append, columns.append
    line, line_start = 1, 0
    for match in islice(_FAST_TOKEN.finditer(source), most):
        group = match.lastindex
        kind = text = match.group(group)
        if group == 3:
            if kind == "\n":
                line, line_start = line + 1, match.end()
                if not open_brackets or open_brackets[-1] != "{" or kinds[-1] == "\n":
                    continue
            elif kind in "([{":
                open_brackets.append(kind)
            elif kind in ")]}" and open_brackets:
                open_brackets.pop()
        elif group == 1:
            kind, text = "name", intern(text)     # one string for all the `sphere`s
        elif group == 2:
            kind = "number"
        elif group == 5:
            kind = "string"     # its text with the quotes
        else:
            kind, text = ("" if group == 4 else "?"), ""
        add_kind(kind)
        add_text(text)
        add_line(line)
        add_column(match.start(group) - line_start + 1)
        if group in (4, 6):
            break
    else:
        add_kind("...")
        add_text("")
        add_line(line)
        add_column(0)
    return kinds, texts, lines, columns


class _FastParser:
    """A recursive-descent parser of the grammar in grammar/frac.lark that
    builds the AST as it reads, with Lark's spans (a node's span runs from
    its first to its last token, brackets around a whole operand left out).
    It takes only input Lark takes, and stops (`_Stop`) at anything else:
    a mistake or nesting near the limit."""

    def __init__(self, source: str):
        self.source = source
        self.decl_starts: list[tuple[int, int]] = []   # lines and columns of the declarations begun
        self.level = 0                     # open brackets and unary minuses, as _BlockNewlines counts
        self.depth = 0                     # of the expression read last, as _DepthTree counts
        self.outer = Span(1, 1, 1, 1)      # the span of the expression read last, with its brackets

    def program(self) -> tuple:
        # The first tokens alone first: a hostile file (nesting past the
        # limit) stops there without reading the rest.
        for most in (_FIRST_TOKENS, None):
            self.kinds, self.texts, self.lines, self.columns = _tokens(self.source, most)
            self.i, self.level, self.decl_starts = 0, 0, []
            try:
                decls = []
                while self.kinds[self.i]:
                    decls.append(self.decl())
                return tuple(decls)
            except RecursionError:
                raise _Stop from None
            except _Stop:
                # Stopped by the end of the tokens read so far (a look-ahead
                # sees one token past self.i): read them all.
                if self.kinds[-1] != "..." or self.i < len(self.kinds) - 3:
                    raise

    # tokens
    def span(self, j: int) -> Span:
        line, column = self.lines[j], self.columns[j]
        return Span(line, column, line, column + len(self.texts[j]))

    def name(self) -> tuple[str, Span]:
        i = self.i
        if self.kinds[i] != "name":     # keywords too: Lark's contextual lexer reads them as names here
            raise _Stop
        self.i = i + 1
        return self.texts[i], self.span(i)

    def expect(self, kind: str) -> Span:
        i = self.i
        if self.kinds[i] != kind:
            raise _Stop
        self.i = i + 1
        return self.span(i)

    def open(self, kind: str) -> Span:
        self.level += 1
        if self.level > _FAST_DEPTH:
            raise _Stop
        return self.expect(kind)

    def close(self, kind: str) -> Span:
        self.level -= 1
        return self.expect(kind)

    # declarations
    def decl(self):
        i = self.i
        self.decl_starts.append((self.lines[i], self.columns[i]))
        word = self.texts[i]
        if self.kinds[i] != "name" or word not in _DECL_WORDS:
            raise _Stop
        keyword = self.span(i)
        self.i = i + 1
        if word == "let":
            name, name_span = self.name()
            self.expect("=")
            value = self.expr()
            return ast.LetDecl(name, name_span, value, keyword.to(self.outer))
        if word == "scene":
            shape = self.expr()
            return ast.SceneDecl(shape, keyword.to(self.outer))
        if word == "param":
            param = self.param()
            return replace(param, span=keyword.to(param.span))
        if word == "formula":
            name, name_span = self.name()
            self.open("(")
            params = []
            while self.kinds[self.i] != ")":
                params.append(self.param())
                if self.kinds[self.i] != ",":
                    break
                self.i += 1
            self.close(")")
            body, end = self.separated(self.statement)
            return ast.FormulaDecl(name, name_span, tuple(params), body, keyword.to(end))
        if word in _NAMED_BLOCKS:
            name, name_span = self.name()
            block = self.block()
            return _NAMED_BLOCKS[word](name, name_span, block, keyword.to(block.span))
        if word == "path":
            keyframes, end = self.separated(self.keyframe)
            return ast.PathDecl(keyframes, keyword.to(end))
        block = self.block()
        node = ast.CameraDecl if word == "camera" else ast.RenderDecl
        return node(block, keyword.to(block.span))

    def param(self) -> ast.ParamDecl:
        """`NAME = EXPR [in [LOW, HIGH]]`, spanning from the name."""
        name, name_span = self.name()
        self.expect("=")
        default = self.expr()
        end, bounds = self.outer, None
        if self.kinds[self.i] == "name" and self.texts[self.i] == "in":
            self.i += 1
            self.open("[")
            low = self.expr()
            self.expect(",")
            high = self.expr()
            end, bounds = self.close("]"), (low, high)
        return ast.ParamDecl(name, name_span, default, bounds, name_span.to(end))

    def statement(self):
        """A formula's statement: `[init|final] NAME = EXPR` or an `if`."""
        word = self.texts[self.i] if self.kinds[self.i] == "name" else None
        if word == "if":
            return self.if_statement()
        phase, start = "step", None
        if word in ("init", "final"):
            phase, start = word, self.span(self.i)
            self.i += 1
        elif word in _STATEMENT_WORDS:
            raise _Stop
        name, name_span = self.name()
        self.expect("=")
        value = self.expr()
        return ast.Assign(name, name_span, value, phase, (start or name_span).to(self.outer))

    def if_statement(self) -> ast.If:
        start = self.span(self.i)
        self.i += 1
        condition = self.expr()
        then, end = self.separated(self.statement)
        otherwise = ()
        if self.kinds[self.i] == "name" and self.texts[self.i] == "else":
            self.i += 1
            if self.kinds[self.i] == "name" and self.texts[self.i] == "if":
                nested = self.if_statement()
                otherwise, end = (nested,), nested.span
            else:
                otherwise, end = self.separated(self.statement)
        return ast.If(condition, then, otherwise, start.to(end))

    def separated(self, item) -> tuple[tuple, Span]:
        """`{ item, item ... }`, items separated by commas or new lines: the
        items and the span of the braces."""
        start = self.open("{")
        kinds, items = self.kinds, []
        while kinds[self.i] in _SEPARATORS:
            self.i += 1
        while kinds[self.i] != "}":
            items.append(item())
            if kinds[self.i] == "}":
                break
            if kinds[self.i] not in _SEPARATORS:
                raise _Stop
            while kinds[self.i] in _SEPARATORS:
                self.i += 1
        return tuple(items), start.to(self.close("}"))

    def block(self) -> ast.Block:
        entries, span = self.separated(self.entry)
        return ast.Block(entries, span)

    def entry(self) -> ast.Entry:
        key, key_span = self.name()
        self.expect(":")
        if self.kinds[self.i] == "string":
            value = ast.String(self.texts[self.i][1:-1], self.span(self.i))
            self.i += 1
            return ast.Entry(key, key_span, value, key_span.to(value.span))
        if self.kinds[self.i] == "{":
            value = self.block()
            return ast.Entry(key, key_span, value, key_span.to(value.span))
        value = self.expr()
        return ast.Entry(key, key_span, value, key_span.to(self.outer))

    def keyframe(self) -> ast.Keyframe:
        time = self.texts[self.i]
        time_span = self.expect("number")
        self.expect(":")
        block = self.block()
        return ast.Keyframe(float(time), time_span, block, time_span.to(block.span))

    # expressions
    def expr(self):
        """A '|' chain of '&' chains of arithmetic (a chain of one operand is
        that operand), in one frame: a bracket costs the stack two more."""
        kinds = self.kinds
        chains = (("&", [], []), ("|", [], []))   # each chain being read: its operands and their depths
        starts = {}
        while True:
            node = self.arithmetic()
            for op, operands, depths in chains:
                if not operands and kinds[self.i] != op:
                    continue                      # no chain of this operator here
                if not operands:
                    starts[op] = self.outer
                operands.append(node)
                depths.append(self.depth)
                if kinds[self.i] == op:
                    break                         # the chain goes on
                node = ast.Chain(op, tuple(operands), starts[op].to(self.outer))
                self.depth, self.outer = max(depths) + 1, node.span
                if self.depth > _FAST_DEPTH:
                    raise _Stop
                operands.clear()
                depths.clear()
            else:
                return node
            self.i += 1

    def arithmetic(self):
        """Comparisons and + - * /, left to right by precedence, without recursion."""
        node = self.operand()
        kinds, texts = self.kinds, self.texts
        precedence = _PRECEDENCE.get(kinds[self.i])
        if precedence is None:
            return node
        operands, outers, depths, operators = [node], [self.outer], [self.depth], []
        bare = [False]        # whether each operand is a comparison not in brackets (they do not chain)
        while True:
            while operators and (precedence is None or operators[-1][0] >= precedence):
                right, left, op = operands.pop(), operands.pop(), operators.pop()[1]
                right_outer = outers.pop()
                span = outers.pop().to(right_outer)
                depth = max(depths.pop(), depths.pop()) + 1
                left_bare = bare.pop(-2)
                bare.pop()
                if depth > _FAST_DEPTH or (op in _COMPARISONS and left_bare):
                    raise _Stop
                operands.append(ast.Binary(op, left, right, span))
                outers.append(span)
                depths.append(depth)
                bare.append(op in _COMPARISONS)
            if precedence is None:
                self.depth, self.outer = depths[0], outers[0]
                return operands[0]
            operators.append((precedence, texts[self.i]))
            self.i += 1
            operands.append(self.operand())
            outers.append(self.outer)
            depths.append(self.depth)
            bare.append(False)
            precedence = _PRECEDENCE.get(kinds[self.i])

    def operand(self):
        """Unary minuses, an atom and its method calls."""
        kinds, texts, i = self.kinds, self.texts, self.i
        minuses = []
        while kinds[i] == "-":
            minuses.append(i)
            i += 1
        self.i = i
        self.level += len(minuses)
        if self.level > _FAST_DEPTH:
            raise _Stop
        kind = kinds[i]
        if kind == "number":
            self.i, depth = i + 1, 0
            node = ast.Number(float(texts[i]), self.span(i))
            outer = node.span
        elif kind == "name" and kinds[i + 1] == "(":
            name, name_span = self.name()
            self.open("(")
            args = self.arguments()
            node, depth = ast.Call(name, name_span, args, name_span.to(self.close(")"))), self.depth + 1
            outer = node.span
        elif kind == "name":
            name, name_span = self.name()
            node, depth, outer = ast.Name(name, name_span), 0, name_span
        elif kind == "(":
            start = self.open("(")
            node = self.expr()
            depth = self.depth
            if kinds[self.i] == ",":
                items = [node]
                while kinds[self.i] == "," and (len(items) == 1 or kinds[self.i + 1] != ")"):
                    self.i += 1
                    items.append(self.expr())
                    depth = max(depth, self.depth)
                if kinds[self.i] == ",":
                    self.i += 1
                node, depth = ast.Vector(tuple(items), start.to(self.close(")"))), depth + 1
                outer = node.span
            else:
                # Lark's span of a bracketed operand leaves the brackets out,
                # but the spans of the nodes around it take them in.
                outer = start.to(self.close(")"))
        else:
            raise _Stop
        while kinds[self.i] == ".":
            self.i += 1
            name, name_span = self.name()
            if kinds[self.i] != "(":          # a component: v.x
                node, depth = ast.Field(node, name, name_span, outer.to(name_span)), depth + 1
                outer = node.span
                continue
            self.open("(")
            args = self.arguments()
            node = ast.Method(node, name, name_span, args, outer.to(self.close(")")))
            depth = max(depth, self.depth) + 1
            outer = node.span
        self.level -= len(minuses)
        for j in reversed(minuses):
            node = ast.Unary("-", node, self.span(j).to(outer))
            outer = node.span
        depth += len(minuses)
        if depth > _FAST_DEPTH:
            raise _Stop
        self.depth, self.outer = depth, outer
        return node

    def arguments(self) -> tuple[ast.Arg, ...]:
        """A call's arguments, up to its ')'; self.depth is the deepest."""
        kinds = self.kinds
        args, depth = [], 0
        while kinds[self.i] != ")":
            i = self.i
            if kinds[i] == "name" and kinds[i + 1] == ":":
                name, name_span = self.name()
                self.i += 1
                value = self.expr()
                args.append(ast.Arg(name, value, name_span.to(self.outer)))
            else:
                value = self.expr()
                args.append(ast.Arg(None, value, self.outer))
            depth = max(depth, self.depth + 1)
            if kinds[self.i] != ",":
                break
            self.i += 1
        self.depth = depth
        return tuple(args)


def parse(text: str, path: str = "<string>") -> ast.Program:
    """Parse `.frac` source into an `ast.Program`; raise `SceneError`.

    The hand-written parser below reads valid files (fast: large scenes
    parse in seconds); wherever it stops, Lark reads the file from the
    declaration before, so that errors and their places are Lark's."""
    if len(text.encode("utf-8", errors="replace")) > MAX_FILE_BYTES:
        raise SceneError([diagnostic(path, text, Span(1, 1, 1, 2),
                                     f"the scene file is larger than {MAX_FILE_BYTES // (1024 * 1024)} MB")])
    source = _LINE_BREAK.sub("\n", text)
    reader = _FastParser(source)
    collecting = gc.isenabled()
    gc.disable()     # millions of new nodes, none of them garbage: collections only cost time
    try:
        decls = reader.program()
    except _Stop:
        decls = None
    finally:
        if collecting:
            gc.enable()
    if decls is None:
        line, column = reader.decl_starts[-2] if len(reader.decl_starts) > 1 else (1, 1)
        _lark_parse(source, text, path, _offset(source, line, column))   # raises the error it meets first
        decls = _lark_parse(source, text, path, 0)    # a valid file the fast parser stops on
    return ast.Program(decls, path, text)


def _offset(source: str, line: int, column: int) -> int:
    start = 0
    for _ in range(line - 1):
        start = source.index("\n", start) + 1
    return start + column - 1


def _lark_parse(source: str, text: str, path: str, start: int) -> tuple:
    """Lark's parse of `source` from offset `start` (the start of a
    declaration); errors are placed in the whole file."""
    line_offset = source.count("\n", 0, start)
    column_offset = start - (source.rfind("\n", 0, start) + 1)

    def fail(span: Span, message: str):
        def column(line: int, col: int) -> int:
            return col + column_offset if line == 1 else col
        span = Span(span.line + line_offset, column(span.line, span.column),
                    span.end_line + line_offset, column(span.end_line, span.end_column))
        raise SceneError([diagnostic(path, text, span, message)])

    try:
        return _ToAst().transform(_parser().parse(source[start:]))
    except UnexpectedInput as error:
        token = getattr(error, "token", None)
        at_end = isinstance(error, UnexpectedEOF) or (token is not None and token.type == "$END")
        scan = None
        if not isinstance(error, UnexpectedCharacters):
            scan = _scan(source, start, len(source) if at_end else _offset(
                source, error.line + line_offset, error.column + (column_offset if error.line == 1 else 0)),
                line_offset, column_offset)
            unclosed = _unclosed(scan, error, at_end, Span(
                error.line + line_offset, error.column + (column_offset if error.line == 1 else 0),
                error.line + line_offset, error.column + (column_offset if error.line == 1 else 0)
                + len(str(token or " "))) if not at_end else None)
            if unclosed:
                raise SceneError([diagnostic(path, text, *unclosed)])
        bracket = scan.opened[-1].text if scan and scan.opened else None
        if at_end:
            lines = source_lines(text)
            last = len(lines) - (len(lines) > 1 and lines[-1] == "")   # the line a final break ends
            raise SceneError([diagnostic(path, text, Span(last, len(lines[last - 1]) + 1, last,
                                                          len(lines[last - 1]) + 2), _syntax_message(error))])
        line = source[start:].split("\n")[error.line - 1]
        fail(Span(error.line, error.column, error.line, error.column + len(str(token or " "))),
             _syntax_message(error, line[:error.column - 1], bracket))
    except _NestingError as error:
        where = error.token
        fail(_span(where.meta if isinstance(where, Tree) else where), f"nesting deeper than {MAX_NESTING} levels")


_CLOSERS = {"(": ")", "[": "]", "{": "}"}
_CLOSER_TOKENS = {"(": "RPAR", "[": "RSQB", "{": "RBRACE"}


@dataclass(frozen=True)
class _Read:
    """A token read before an error: its text and where it starts and ends."""
    text: str
    line: int
    column: int
    end: int              # the column after it


@dataclass(frozen=True)
class _Scan:
    """What came before an error: the brackets still open (innermost last),
    the last token, the first token of the last token's line and the token
    before that one."""
    opened: tuple[_Read, ...]
    last: _Read | None
    first: _Read | None
    before: _Read | None


def _scan(source: str, start: int, stop: int, line_offset: int, column_offset: int) -> _Scan:
    """The tokens of `source` from offset `start` (a declaration's start:
    no bracket open) to offset `stop` (an error's token)."""
    opened: list[_Read] = []
    before = last = first = None
    line, line_start = line_offset + 1, start - column_offset
    for match in _FAST_TOKEN.finditer(source, start):
        group = match.lastindex
        if match.start(group) >= stop or group in (4, 6):
            break
        text = match.group(group)
        if text == "\n":
            line, line_start = line + 1, match.end()
            continue
        read = _Read(text, line, match.start(group) - line_start + 1, match.end(group) - line_start + 1)
        if last is None or last.line != line:
            before, first = last, read
        last = read
        if text in _CLOSERS:
            opened.append(read)
        elif text in ")]}" and opened:
            opened.pop()
    return _Scan(tuple(opened), last, first, before)


def _unclosed(scan: _Scan, error: UnexpectedInput, at_end: bool, place: Span | None) -> tuple[Span, str] | None:
    """Where and why, when Lark's error is a bracket left open: just after
    the last token that should have closed it (or at the error, on the
    bracket's line) and "unclosed '(' opened at L:C". That is so at the end
    of the file; where a line after the bracket's starts a declaration
    (or, inside '(' or '[', a block entry's 'key:'); where the error
    follows a line break inside '(' or '[' and a closer could come there;
    and where a declaration's keyword comes inside a bracket."""
    if not scan.opened:
        return None
    bracket, last, first = scan.opened[-1], scan.last, scan.first
    error_line = place.line if place else 0
    message = f"unclosed '{bracket.text}' opened at {bracket.line}:{bracket.column}"
    if at_end:
        return Span(last.line, last.end, last.line, last.end + 1), f"unexpected end of the file: {message}"
    token, expected = str(error.token), set(error.expected)
    closer = _CLOSERS[bracket.text]
    round_ = bracket.text in "(["                   # newlines inside are space, not separators
    if first.line > bracket.line and first.line == error_line \
            and (first.text in _DECL_WORDS or (round_ and token == ":" and last is first)):
        where, next_text = scan.before, first.text     # a declaration (or a block entry) on a line of its own
    elif last.line < error_line and round_ and _CLOSER_TOKENS[bracket.text] in expected:
        where, next_text = last, token
    elif token in _DECL_WORDS:
        return place, f"{message}: '{closer}' expected before '{token}'"
    else:
        return None
    if where is None or where.line < bracket.line:
        return None
    also = " or ','" if "COMMA" in expected and where is last else ""
    return Span(where.line, where.end, where.line, where.end + 1), \
        f"{message}: '{closer}'{also} expected before '{next_text}'"
