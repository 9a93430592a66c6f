"""The OpenCL library in `stdlib_cl/` and the signatures of the language.

Each library file is split into its functions. A function whose definition
is preceded by a line `//: KIND NAME(ARG, ...)` is callable from the language
under NAME; that line is the one source of its signature:

    //: shape box(size: size = 1 >0)

ARG is `name: type [= default] [constraint ...]`, with types `num`, `int`,
`vec3`, `vec4` and `size` (a number or a vec3; a number means all three),
and constraints `>X`, `>=X`, `<=X`, `<X`, `A..B` (inclusive), `nonzero`, or
`<=other_arg`. The language-level forms that are not library functions
(combinators, transforms, math) are tabled below.

Besides the library: the prelude, the engine (`engine/`, the fixed part of
every render kernel, ENGINE), the kernel of distances at points, and the
templates of what the emitter writes per scene (`shade.cl`, `scene.cl`:
`templates`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, replace
from functools import lru_cache
from string import Template

from .resources import resource_dir

PRELUDE = "prelude.cl"
DISTANCE_KERNEL = "distance.cl"
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
class Parameter:
    name: str
    type: str                      # num | int | vec3 | vec4 | size | shape | material | rgb
    default: float | tuple | None  # None: required
    constraints: tuple[str, ...] = ()


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


def _parse_parameter(text: str) -> Parameter:
    name, rest = (s.strip() for s in text.split(":", 1))
    match = re.match(r"(\w+)\s*(?:=\s*(\([^)]*\)|[-+.\deE]+))?\s*(.*)$", rest)
    type_, default, constraints = match.groups()
    return Parameter(name, type_, _parse_value(default) if default else None,
                     tuple(constraints.split()))


def _parameter_types(source: str) -> tuple[str, ...]:
    """C types of a definition's parameters (`real`, `int`, `vec3`, ...)."""
    code = "\n".join(line for line in source.splitlines() if not line.startswith("//"))
    inside = code[code.index("(") + 1:code.index(")")]
    return tuple(" ".join(p.split()[:-1]).replace("__constant ", "") for p in inside.split(",") if p.strip())


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
            for comment in body:
                annotation = _ANNOTATION.match(comment)
                if annotation:
                    kind, lang_name, args = annotation.groups()
                    params = tuple(_parse_parameter(a) for a in _split_top_level(args))
                    signatures[lang_name] = Signature(kind, lang_name, params, name)
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
    from .fractals import FRACTALS    # the fractals are IR, their signatures beside them
    for name, (parameters, _) in FRACTALS.items():
        signatures[name] = Signature("fractal", name, tuple(_parse_parameter(a) for a in _split_top_level(parameters)))
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
    return Library(with_calls, signatures, (root / PRELUDE).read_text(), engine, (root / DISTANCE_KERNEL).read_text())


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

def _p(name, type_, default=None, *constraints):
    return Parameter(name, type_, default, tuple(constraints))


COMBINATORS = {
    "union": Signature("combinator", "union", (_p("smooth", "num", 0.0, ">=0"),)),
    "intersect": Signature("combinator", "intersect", (_p("smooth", "num", 0.0, ">=0"),)),
    "subtract": Signature("combinator", "subtract", (_p("smooth", "num", 0.0, ">=0"),)),
}

TRANSFORMS = {
    "translate": Signature("transform", "translate", (_p("offset", "vec3"),)),
    "rotate": Signature("transform", "rotate", (_p("axis", "vec3", None, "nonzero"), _p("degrees", "num"))),
    "scale": Signature("transform", "scale", (_p("factor", "num", None, ">0"),)),
    "repeat": Signature("transform", "repeat", (_p("period", "size", None, ">=0"),)),
    "round": Signature("transform", "round", (_p("radius", "num", None, ">=0"),)),
    "onion": Signature("transform", "onion", (_p("thickness", "num", None, ">0"),)),
    "twist": Signature("transform", "twist", (_p("rate", "num"),)),
    "bend": Signature("transform", "bend", (_p("rate", "num"),)),
    "material": Signature("transform", "material", (_p("material", "material"),)),
    "color": Signature("transform", "color", (_p("rgb", "color", None, "0..1000"),)),
}

# `.color(orbit_trap(...))`: a fractal coloured by how near its orbit comes
# to the origin or the coordinate planes (Syntopia part II), from `near`
# (trap distance 0) to `far` (trap distance >= 1 / scale; without a scale,
# spread over the trap's range: fractalc/lower.py); or by the steps
# its orbit took (`iterations`), or where the point is (`radius` |p|,
# `height` p.z).
TRAP_KINDS = ("origin", "x", "y", "z", "planes", "iterations", "radius", "height")
_TRAP_WORDS = "word:" + "|".join(TRAP_KINDS)
# `scale`'s default: spread the trap over its range (fractalc/lower.py, `_trap_parameter`)
AUTO_SCALE = "auto"
COLORINGS = {
    "orbit_trap": Signature("coloring", "orbit_trap", (
        _p("near", "vec3", (1.0, 0.85, 0.55), "0..1000"), _p("far", "vec3", (0.15, 0.25, 0.6), "0..1000"),
        _p("trap", _TRAP_WORDS, "planes"), _p("scale", "num", AUTO_SCALE, ">0"))),
    # Quilez's cosine palette a + b cos(2 pi (c t + d)) of t = trap * scale
    "palette": Signature("coloring", "palette", (
        _p("a", "vec3", (0.5, 0.5, 0.5)), _p("b", "vec3", (0.5, 0.5, 0.5)), _p("c", "vec3", (1.0, 1.0, 1.0)),
        _p("d", "vec3", (0.0, 0.33, 0.67)), _p("trap", _TRAP_WORDS, "planes"),
        _p("scale", "num", AUTO_SCALE, ">0"))),
}

# math function -> (arity, how arguments combine): "map" applies per
# component (numbers broadcast), the others take and give what they say.
MATH = {
    **{name: (1, "map") for name in
       ("sin", "cos", "tan", "asin", "acos", "atan", "sqrt", "abs", "exp", "log",
        "floor", "radians", "degrees")},
    "atan2": (2, "map"), "min": (2, "map"), "max": (2, "map"), "pow": (2, "map"),
    "clamp": (3, "map"), "mix": (3, "map"),
    "length": (1, "vector->num"), "normalize": (1, "vector->vector"),
    "dot": (2, "vector,vector->num"), "cross": (2, "vec3,vec3->vec3"),
}
