"""The OpenCL library in `stdlib_cl/` and the signatures of the language.

Each library file is split into its functions. A function whose definition
is preceded by a line `//: KIND NAME(ARG, ...)` is callable from the language
under NAME; that line is the one source of its signature:

    //: shape box(size: size = 1 >0)

A `//:` line standing alone (a blank line after it) signs a form whose code
is not the library's: a fractal, whose estimate fractals.py builds as IR
(its file holds the bound radius), carries no function.

ARG is `name: type [= default] [constraint ...]`, with types `num`, `int`,
`vec3`, `vec4` and `size` (a number or a vec3; a number means all three),
and constraints `>X`, `>=X`, `<=X`, `<X`, `A..B` (inclusive), `nonzero`, or
`<=other_arg`. The language-level forms that are not library functions
(combinators, colourings, math) are tabled below; transforms are
fractalc/transforms.py's.

Besides the library: the prelude, the engine (`engine/`, the fixed part of
every render kernel, ENGINE), the kernel of distances at points, and the
templates of what the emitter writes per scene (`shade.cl`, `scene.cl`:
`templates`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, replace
from enum import StrEnum
from functools import lru_cache
from string import Template

from .resources import resource_dir
from .types import Parameter, Type, above, at_least, between, parse_constraint

PRELUDE = "prelude.cl"
DISTANCE_KERNEL = "distance.cl"
COUNTING = "count.cl"
# The engine: the fixed part of every render kernel, one file per concern
# in stdlib_cl/engine/, in the order the kernel holds them (each after what
# it uses); its `#if FEATURE_` blocks hold the optional effects.
ENGINE_DIR = "engine"
BOUND_RADIUS = "_bound_radius"   # the suffix of a shape's bounding radius function (Signature.bound_radius)
ENGINE = (
    "interface",     # what the generated code defines; the camera argument's layout
    "hits",          # Hart's hit threshold; a march's result
    "cone",          # cone marching of a work-item's packet of rays
    "march",         # sphere tracing, over-relaxed, within the scene's bound
    "camera",        # camera rays: projections, stereo, depth of field
    "sky",           # the environment (a sky gradient or map) and the background
    "random",        # per-lane hashes for jitter
    "channels",      # storing a block's pixels into the output's channels
    "normal",        # the normal where a march hit
    "fog",
    "reflections",
    "refraction",    # transparency
    "glow",
    "trace",         # the colour seen along a ray, effects included
    "render",        # the `render` kernel: samples, then the channels and passes
)


@dataclass(frozen=True)
class Signature:
    kind: str                      # shape | fractal | combinator | transform
    name: str
    parameters: tuple[Parameter, ...]
    function: str = ""             # the OpenCL function implementing it
    # the library function `NAME_bound_radius` of its arguments, where the
    # library has one: the radius of a sphere about the origin holding the
    # shape ("": unbounded, or not known)
    bound_radius: str = ""


@dataclass(frozen=True)
class Function:
    name: str
    source: str                    # the definition with its comment lines
    header: str                    # the file's leading comment, emitted once
    file: str
    calls: tuple[str, ...]         # library functions it calls
    parameter_types: tuple[str, ...] = ()   # C types of its parameters


_ANNOTATION = re.compile(r"^//:\s*(\w+)\s+(\w+)\((.*)\)\s*$")
_DEFINITION = re.compile(r"^[A-Za-z_][\w ]*?\b(\w+)\s*\(")
_TYPEDEF = re.compile(r"^typedef struct \{.*\} (\w+);$")
_IDENTIFIER = re.compile(r"\b[A-Za-z_]\w*\b")


def _split_top_level(text: str) -> list[str]:
    parts, depth, current = [], 0, ""
    for ch in text:
        if ch == "," and depth == 0:
            parts.append(current)
            current = ""
            continue
        depth += ch in "(["
        depth -= ch in ")]"
        current += ch
    if current.strip():
        parts.append(current)
    return [p.strip() for p in parts]


def _parse_value(text: str) -> float | tuple:
    text = text.strip()
    if text.startswith("("):
        return tuple(float(x) for x in _split_top_level(text[1:-1]))
    return float(text)


# A `//:` line's type names: `num` is a number
_ANNOTATION_TYPES = {"num": Type.NUMBER, **{t.value: t for t in (Type.WHOLE, Type.VEC3, Type.VEC4, Type.SIZE)}}


def _parse_parameter(text: str) -> Parameter:
    name, rest = (s.strip() for s in text.split(":", 1))
    match = re.match(r"(\w+)\s*(?:=\s*(\([^)]*\)|[-+.\deE]+))?\s*(.*)$", rest)
    type_, default, constraints = match.groups()
    return Parameter(name, _ANNOTATION_TYPES[type_], _parse_value(default) if default else None,
                     tuple(parse_constraint(c) for c in constraints.split()))


def _parameter_types(source: str) -> tuple[str, ...]:
    """C types of a definition's parameters (`real`, `int`, `vec3`, ...)."""
    code = "\n".join(line for line in source.splitlines() if not line.startswith("//"))
    inside = code[code.index("(") + 1:code.index(")")]
    return tuple(" ".join(p.split()[:-1]).replace("__constant ", "").replace("PARAMS_SPACE ", "")
                 for p in inside.split(",") if p.strip())


def _signatures(lines: list[str], function: str) -> dict[str, Signature]:
    """The signatures of the `//:` lines among `lines`, implemented by
    the library's `function` ("" for none)."""
    signatures = {}
    for line in lines:
        annotation = _ANNOTATION.match(line)
        if annotation:
            kind, name, args = annotation.groups()
            signatures[name] = Signature(kind, name, tuple(_parse_parameter(a) for a in _split_top_level(args)),
                                         function)
    return signatures


def _parse_file(path, file_name: str) -> tuple[list[Function], dict[str, Signature]]:
    lines = path.read_text().splitlines()
    header: list[str] = []
    i = 0
    while i < len(lines) and lines[i].startswith("//") and not lines[i].startswith("//:"):
        header.append(lines[i])
        i += 1
    if i < len(lines) and lines[i].strip():
        header = []   # no blank line after it: the comment belongs to the first function
        i = 0
    functions, signatures, pending = [], {}, []
    depth, body, name = 0, [], None
    for line in lines[i:]:
        if name is None:
            if not line.strip():
                signatures.update(_signatures(pending, ""))
                pending = []
                continue
            if line.startswith("//"):
                pending.append(line)
                continue
            typedef = _TYPEDEF.match(line)
            if typedef:   # a one-line struct type: a unit of its own
                functions.append(Function(typedef.group(1), "\n".join(pending + [line]),
                                          "\n".join(header), file_name, ()))
                pending = []
                continue
            match = _DEFINITION.match(line)
            if not match:
                raise ValueError(f"{file_name}: cannot read library line {line!r}")
            name, body = match.group(1), pending + [line]
            pending = []
        else:
            body.append(line)
        depth += line.count("{") - line.count("}")
        if depth == 0 and "}" in line:
            source = "\n".join(body)
            signatures.update(_signatures(body, name))
            functions.append(Function(name, source, "\n".join(header), file_name, (),
                                      _parameter_types(source)))
            name = None
    return functions, signatures


@dataclass(frozen=True)
class Library:
    functions: dict[str, Function]
    signatures: dict[str, Signature]
    prelude: str
    engine: str             # the files of ENGINE, in order
    distance_kernel: str    # `distance_at_points`, for render programs and distance programs alike
    counting: str           # the counting build's hooks (fractalc/count.py), after the prelude in that build alone

    def closure(self, roots) -> list[Function]:
        """The functions `roots` need, each after the ones it calls."""
        order: list[Function] = []
        placed: set[str] = set()

        def visit(name: str, trail: tuple = ()):
            if name in placed or name in trail:
                return
            for callee in self.functions[name].calls:
                visit(callee, trail + (name,))
            placed.add(name)
            order.append(self.functions[name])

        for root in roots:
            visit(root)
        return order


@lru_cache(maxsize=1)
def library() -> Library:
    root = resource_dir("stdlib_cl")
    functions: dict[str, Function] = {}
    signatures: dict[str, Signature] = {}
    for path in sorted(root.glob("*/*.cl")):
        if path.parent.name == ENGINE_DIR:
            continue
        file_name = str(path.relative_to(root))
        found, sigs = _parse_file(path, file_name)
        functions.update((f.name, f) for f in found)
        signatures.update(sigs)
    names = set(functions)
    with_calls = {}
    for f in functions.values():
        body = re.sub(r"//[^\n]*", "", f.source)
        called = {m for m in _IDENTIFIER.findall(body) if m in names and m != f.name}
        with_calls[f.name] = Function(f.name, f.source, f.header, f.file, tuple(sorted(called)),
                                      f.parameter_types)
    # each shape's bounding radius, where the library has one
    signatures = {name: replace(sig, bound_radius=name + BOUND_RADIUS) if name + BOUND_RADIUS in functions else sig
                  for name, sig in signatures.items()}
    engine = "\n\n".join((root / ENGINE_DIR / f"{name}.cl").read_text().rstrip("\n") for name in ENGINE)
    return Library(with_calls, signatures, (root / PRELUDE).read_text(), engine, (root / DISTANCE_KERNEL).read_text(),
                   (root / COUNTING).read_text())


_TEMPLATE_START = "//@ "


@lru_cache(maxsize=None)
def templates(file_name: str) -> dict[str, Template]:
    """The templates of the OpenCL C the emitter writes per scene, from the
    file `stdlib_cl/FILE_NAME`: a line `//@ NAME [what it is]` opens the
    template NAME, which runs to the next such line (its trailing blank
    lines dropped); `$name` in it marks a value the emitter writes there."""
    found: dict[str, list[str]] = {}
    lines = None
    for line in (resource_dir("stdlib_cl") / file_name).read_text().splitlines():
        if line.startswith(_TEMPLATE_START):
            name = line[len(_TEMPLATE_START):].split()[0]
            if name in found:
                raise ValueError(f"{file_name}: a second template {name}")
            lines = found[name] = []
        elif lines is not None:
            lines.append(line)
    return {name: Template("\n".join(lines).rstrip("\n")) for name, lines in found.items()}


# ---- language forms that are not library functions -------------------------

def _p(name, type_, default=None, *constraints, words=()):
    return Parameter(name, type_, default, tuple(constraints), tuple(words))


_SMOOTH = (_p("smooth", Type.NUMBER, 0.0, at_least(0)),)
COMBINATORS = {name: Signature("combinator", name, _SMOOTH) for name in ("union", "intersect", "subtract")}

# `.color(orbit_trap(...))`: a fractal coloured by how near its orbit comes
# to the origin or the coordinate planes (Syntopia part II), from `near`
# (trap distance 0) to `far` (trap distance >= 1 / scale; without a scale,
# spread over the trap's range: fractalc/lower.py); or by the steps
# its orbit took (`iterations`), or where the point is (`radius` |p|,
# `height` p.z).
class TrapKind(StrEnum):
    ORIGIN = "origin"
    X = "x"
    Y = "y"
    Z = "z"
    PLANES = "planes"
    ITERATIONS = "iterations"
    RADIUS = "radius"
    HEIGHT = "height"


TRAP_KINDS = tuple(TrapKind)
# `scale`'s default: spread the trap over its range (fractalc/lower.py, `_trap_parameter`)
AUTO_SCALE = "auto"
_TRAP = _p("trap", Type.WORD, TrapKind.PLANES, words=TrapKind)
_TRAP_SCALE = _p("scale", Type.NUMBER, AUTO_SCALE, above(0))
COLORINGS = {
    "orbit_trap": Signature("coloring", "orbit_trap", (
        _p("near", Type.VEC3, (1.0, 0.85, 0.55), between(0, 1000)),
        _p("far", Type.VEC3, (0.15, 0.25, 0.6), between(0, 1000)), _TRAP, _TRAP_SCALE)),
    # Quilez's cosine palette a + b cos(2 pi (c t + d)) of t = trap * scale
    "palette": Signature("coloring", "palette", (
        _p("a", Type.VEC3, (0.5, 0.5, 0.5)), _p("b", Type.VEC3, (0.5, 0.5, 0.5)), _p("c", Type.VEC3, (1.0, 1.0, 1.0)),
        _p("d", Type.VEC3, (0.0, 0.33, 0.67)), _TRAP, _TRAP_SCALE)),
}


@dataclass(frozen=True)
class MathFunction:
    """A math function of scenes and formulas alike: its arguments' kinds
    (`any` a number or vector, per component with numbers broadcast; `v`
    a vector, all of one size; `3` a 3-vector), what a message shows of
    it, and whether it has a derivative (floor and round have none)."""
    arguments: tuple[str, ...]
    about: str
    derivable: bool = True

    @property
    def per_component(self) -> bool:
        return all(a == "any" for a in self.arguments)


MATH = {
    **{name: MathFunction(("any",), f"{name}(x)") for name in
       ("sin", "cos", "tan", "asin", "acos", "atan", "sqrt", "rsqrt", "abs", "exp", "log", "radians", "degrees")},
    **{name: MathFunction(("any",), f"{name}(x)", derivable=False) for name in ("floor", "round")},
    "atan2": MathFunction(("any", "any"), "atan2(y, x)"),
    "min": MathFunction(("any", "any"), "min(a, b)"),
    "max": MathFunction(("any", "any"), "max(a, b)"),
    "pow": MathFunction(("any", "any"), "pow(x, y)"),
    "clamp": MathFunction(("any", "any", "any"), "clamp(x, low, high)"),
    "mix": MathFunction(("any", "any", "any"), "mix(a, b, t)"),
    "length": MathFunction(("v",), "length(v)"),
    "dot": MathFunction(("v", "v"), "dot(a, b)"),
    "cross": MathFunction(("3", "3"), "cross(a, b)"),
    "normalize": MathFunction(("v",), "normalize(v)"),
}
