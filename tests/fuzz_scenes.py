"""Fuzz cases for fractalc: generated scenes and mutated example files.

The generator knows the language from its documentation (LANGUAGE.md,
docs/language.md, docs/effects.md), not from fractalc's own tables, so a
checker that drifts from the documents shows up as a failure. Every case is
a pure function of (seed, index): `case(seed, index)`.

A generated scene is valid by construction, or carries exactly one
deliberate defect whose place is marked, so the judge can also ask that the
error is reported there. Mutations of the example files have no expected
outcome: they only have to check cleanly or fail cleanly.

`judge` (the end of this file) runs a case through fractalc and says what,
if anything, went wrong.
"""
from __future__ import annotations

import math
import os
import random
import re
import signal
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# Marks (private-use characters) around a deliberate defect while it is generated.
START, END = "\ue000", "\ue001"


@dataclass(frozen=True)
class Case:
    source: str | bytes      # bytes: not valid UTF-8 (read through a file)
    origin: str              # how it was made, for the report
    expect: str              # "valid", "invalid" or "unknown"
    where: tuple | None = None   # (line, first column, end column) of the defect


# ---- the language, from the documents ------------------------------------

@dataclass(frozen=True)
class Range:
    """Valid numbers: lo/hi (None: unbounded), open or closed ends, whole or not."""
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    whole: bool = False
    nonzero: bool = False    # vectors: not all components zero
    limit: "Range | None" = None   # what the checker allows, where values are drawn from less


ANY = Range()
POSITIVE = Range(0, None, lo_open=True)
# sizes a distance squares (docs/language.md, "Limits")
COORDINATE = Range(-1e18, 1e18)
SIZE = Range(0, 1e18, lo_open=True)
NON_NEGATIVE = Range(0, None)
UNIT = Range(0, 1)
COLOR = Range(0, 1000)
ITERATIONS = Range(1, 30, whole=True, limit=Range(1, 1000, whole=True))   # few: cheap renders

# argument: (name, type, range); types num | int | vec3 | vec4 | size
PRIMITIVES = {
    "sphere": (("radius", "num", POSITIVE),),
    "box": (("size", "size", POSITIVE),),
    "plane": (("normal", "vec3", Range(nonzero=True)), ("offset", "num", ANY)),
    "torus": (("major", "num", SIZE), ("minor", "num", SIZE)),
    "cylinder": (("radius", "num", POSITIVE), ("height", "num", POSITIVE)),
    "capsule": (("a", "vec3", COORDINATE), ("b", "vec3", COORDINATE), ("radius", "num", SIZE)),
}
FRACTALS = {
    "mandelbulb": (("power", "num", Range(1, 32)), ("iterations", "int", ITERATIONS),
                   ("bailout", "num", POSITIVE)),
    "julia": (("c", "vec4", ANY), ("slice", "num", ANY), ("iterations", "int", ITERATIONS),
              ("bailout", "num", POSITIVE)),
    "mandelbox": (("scale", "num", ANY), ("min_radius", "num", POSITIVE), ("fixed_radius", "num", POSITIVE),
                  ("fold_limit", "num", POSITIVE), ("iterations", "int", ITERATIONS)),
    "menger": (("level", "int", Range(0, 10, whole=True)),),
    "sierpinski": (("level", "int", Range(0, 10, whole=True)),),
}
TRANSFORMS = {
    "translate": (("offset", "vec3", ANY),),
    "rotate": (("axis", "vec3", Range(nonzero=True)), ("degrees", "num", ANY)),
    "scale": (("factor", "num", POSITIVE),),
    "repeat": (("period", "size", NON_NEGATIVE),),
    "round": (("radius", "num", NON_NEGATIVE),),
    "onion": (("thickness", "num", POSITIVE),),
    "twist": (("rate", "num", ANY),),
    "bend": (("rate", "num", ANY),),
}
MATERIAL_KEYS = {"color": ("vec3", COLOR), "specular": ("num", UNIT), "shininess": ("num", POSITIVE),
                 "reflectivity": ("num", UNIT), "transparency": ("num", UNIT), "ior": ("num", Range(1, 10))}
CAMERA_KEYS = {"fov": ("num", Range(0, 180, True, True)), "aperture": ("num", NON_NEGATIVE),
               "focus": ("num", POSITIVE)}
LIGHT_KEYS = {"color": ("vec3", NON_NEGATIVE), "intensity": ("num", NON_NEGATIVE),
              "softness": ("num", POSITIVE)}

def _cheap(lo: int, hi: int, limit: int) -> Range:
    return Range(lo, hi, whole=True, limit=Range(lo, limit, whole=True))


# render keys kept cheap enough for a 16x12 render (the checker's limits are wider)
RENDER_KEYS = {
    "width": ("int", _cheap(1, 64, 65536)), "height": ("int", _cheap(1, 48, 65536)),
    "max_steps": ("int", _cheap(1, 200, 100000)), "max_distance": ("num", POSITIVE),
    "ao": ("num", UNIT), "samples": ("int", _cheap(1, 4, 4096)), "background": ("vec3", NON_NEGATIVE),
    "reflections": ("int", _cheap(0, 2, 16)), "dither": ("num", UNIT),
    "overrelax": ("num", Range(1, 1.99)), "epsilon_scale": ("num", Range(0, 1000, lo_open=True)),
}
RENDER_WORDS = {"precision": ("float", "double"), "ao_method": ("normal", "steps"),
                "normals": ("tetrahedral", "central", "forward"), "fast_math": ("auto", "on", "off"),
                "cone_marching": ("on", "off")}
EFFECT_BLOCKS = {
    "glow": {"color": ("vec3", NON_NEGATIVE), "strength": ("num", NON_NEGATIVE), "radius": ("num", POSITIVE)},
    "fog": {"color": ("vec3", NON_NEGATIVE), "density": ("num", NON_NEGATIVE)},
    "slice": {"normal": ("vec3", Range(nonzero=True)), "offset": ("num", ANY)},
}
TRAPS = ("origin", "x", "y", "z", "planes", "iterations", "radius", "height")
WORDS = ("param", "let", "material", "scene", "camera", "light", "render", "path", "in", "union", "intersect",
         "subtract", "smooth", "orbit_trap", "pixel", "directional", "point", "shadows", "soft", "hard",
         "none", *PRIMITIVES, *FRACTALS, *TRANSFORMS, "material", "color", *MATERIAL_KEYS, *RENDER_KEYS,
         *RENDER_WORDS, *EFFECT_BLOCKS, "sin", "sqrt", "pow", "clamp", "normalize", "cross", "length")


# ---- numbers ---------------------------------------------------------------

def _spell(rng: random.Random, v: float) -> str:
    """A number literal for v >= 0 in one of the documented spellings."""
    if v == int(v) and abs(v) < 1e15:
        return rng.choice([str(int(v)), f"{int(v)}.", f"{int(v)}.0", f"{v:e}"])
    text = repr(v)
    if "e" in text:
        return rng.choice([text, text.replace("e", "E")])
    if text.startswith("0."):
        return rng.choice([text, text[1:]])
    return text


def literal(rng: random.Random, v: float) -> str:
    if v < 0 or (v == 0 and math.copysign(1, v) < 0):
        return "-" + _spell(rng, -v)
    return _spell(rng, v)


def inside(rng: random.Random, r: Range, extreme: float = 0.03) -> float:
    """A value in r: usually an ordinary one, sometimes at a bound or huge/tiny."""
    roll = rng.random()
    if roll < extreme:
        choices = [x for x in (1e-30, 1e-7, 1e6, 1e30, 3e38, -1e6, -1e30) if _contains(r, x)]
        if choices:
            return rng.choice(choices)
    if roll < 0.15:
        ends = [x for x, is_open in ((r.lo, r.lo_open), (r.hi, r.hi_open)) if x is not None and not is_open]
        if ends:
            return rng.choice(ends)
    lo = r.lo if r.lo is not None else -3.0
    hi = min(r.hi, lo + 3) if r.hi is not None and r.hi - lo > 10 else r.hi if r.hi is not None else max(lo, 0) + 3
    if r.whole:
        v = float(rng.randint(math.ceil(lo), math.floor(hi)))
    else:
        v = round(rng.uniform(lo, hi), rng.choice([1, 2, 3, 6]))
    return v if _contains(r, v) else (lo + hi) / 2


def _contains(r: Range, v: float) -> bool:
    if r.whole and v != int(v):
        return False
    if r.lo is not None and (v < r.lo or (r.lo_open and v == r.lo)):
        return False
    return not (r.hi is not None and (v > r.hi or (r.hi_open and v == r.hi)))


def outside(rng: random.Random, r: Range) -> float | None:
    """A value just or far outside r (None if r is everything)."""
    r = r.limit or r
    choices = []
    if r.lo is not None:
        choices += [r.lo if r.lo_open else r.lo - rng.choice([1, 0.5, 1e-3]), r.lo - 1e6]
    if r.hi is not None:
        choices += [r.hi if r.hi_open else r.hi + rng.choice([1, 0.5, 1e-3]) * max(1.0, abs(r.hi) * 1e-6), r.hi * 10 + 1]
    if r.whole:
        choices.append(((r.lo or 0) + (r.hi if r.hi is not None else 2)) / 2 + 0.5)
    choices = [c for c in choices if not _contains(r, c)]
    return rng.choice(choices) if choices else None


# ---- generated scenes --------------------------------------------------------

class _Generator:
    """One scene. `defect` is the kind of mistake still to be made (None: none);
    sites take it with some probability, the end of the file takes it last."""

    def __init__(self, rng: random.Random, defect: bool):
        self.rng = rng
        self.pending = defect
        self.made = ""
        self.params: list[tuple[str, float, float, float]] = []   # name, default, lo, hi
        self.decls: list[str] = []
        self.numbers: dict[str, float] = {}                       # let name -> value
        self.shapes: list[str] = []                                # let names of shapes
        self.materials: list[str] = []
        self.counter = 0
        self.depth = rng.choice([1, 2, 2, 3])     # of nested combinations: small scenes build faster

    def fresh(self, stem: str) -> str:
        self.counter += 1
        return f"{stem}{self.counter}"

    def take_defect(self, odds: float = 0.12) -> bool:
        if self.pending and self.rng.random() < odds:
            self.pending = False
            return True
        return False

    @staticmethod
    def mark(text: str) -> str:
        return START + text + END

    # numbers and vectors (valid unless a defect is taken here)

    def number(self, r: Range, kind: str = "num", params_ok: bool = True, defects: bool = True) -> str:
        """kind: num, int, or size (where a 3-vector is fine too)."""
        rng = self.rng
        if defects and self.take_defect(0.04):
            bad = outside(rng, r)
            wrong = [literal(rng, bad)] if bad is not None else []
            wrong += ["sphere()", "undefined_name", "(1, 2)"] + (["1.5"] if kind == "int" else [])
            wrong += [] if kind == "size" else ["(1, 2, 3)"]
            self.made = "value out of range or of the wrong type"
            return self.mark(rng.choice(wrong))
        roll = rng.random()
        if params_ok and roll < 0.12:
            return self.param_for(r)
        if roll < 0.2:
            return self.let_number(r)
        v = inside(rng, r)
        return self.dress(literal(rng, v), v)

    def dress(self, text: str, v: float) -> str:
        """Wrap a literal in value-preserving arithmetic, sometimes."""
        rng = self.rng
        if rng.random() > 0.25:
            return text
        forms = [f"({text})", f"{text} * 1", f"{text} / 1", f"{text} + 0", f"max({text}, {text})",
                 f"min({text}, {text})", f"clamp({text}, {text}, {text})", f"mix({text}, {text}, 0.3)",
                 f"pow({text}, 1)", f"- -{text}" if not text.startswith("-") else f"-({text[1:]})"]
        if v >= 0:
            forms.append(f"abs({text})")
        if v == int(v) and abs(v) < 1e15:
            forms.append(f"floor({text})")
        return rng.choice(forms)

    def let_number(self, r: Range) -> str:
        v = inside(self.rng, r)
        name = self.fresh("n")
        self.decls.append(f"let {name} = {literal(self.rng, v)}")
        self.numbers[name] = v
        return name

    def param_for(self, r: Range) -> str:
        """A param whose whole range is valid here (ends strictly inside open bounds)."""
        rng = self.rng
        lo = r.lo if r.lo is not None else -5.0
        hi = r.hi if r.hi is not None else lo + 5.0
        if r.lo_open:
            lo = lo + min(0.1, (hi - lo) / 4)
        if r.hi_open:
            hi = hi - min(0.1, (hi - lo) / 4)
        if r.whole:
            lo, hi = float(math.ceil(lo)), float(math.floor(hi))
        if lo > hi:
            return literal(rng, inside(rng, r))
        default = float(rng.randint(int(lo), int(hi))) if r.whole else round(rng.uniform(lo, hi), 3)
        if not lo <= default <= hi:
            default = lo
        name = self.fresh("p")
        self.params.append((name, default, lo, hi))
        if self.take_defect(0.05):
            self.made = "param's default outside its range"
            self.decls.append(f"param {name} = {self.mark(literal(rng, hi + max(1.0, abs(hi) * 1e-6)))} in [{lo!r}, {hi!r}]")
        else:
            self.decls.append(f"param {name} = {literal(rng, default)} in [{literal(rng, lo)}, {literal(rng, hi)}]")
        return rng.choice([name, f"({name})", f"{name} * 1", f"max({name}, {name})"])

    def vector(self, r: Range, size: int = 3, params_ok: bool = True, number_ok: bool = False) -> str:
        rng = self.rng
        if self.take_defect(0.04):
            self.made = "vector of the wrong size or type"
            wrong = ["(1, 2)", "(1, 2, 3, 4, 5)", "box(1)"] if size == 3 else ["(1, 2, 3)", "1"]
            if r.nonzero:
                wrong.append("(0, 0, 0)")
            if not number_ok:
                wrong.append("1")
            return self.mark(rng.choice(wrong))
        while True:
            items = [self.number(Range(r.lo, r.hi, r.lo_open, r.hi_open), params_ok=params_ok, defects=False)
                     if rng.random() < 0.3 else literal(rng, inside(rng, r, 0.01)) for _ in range(size)]
            if not r.nonzero or any(_plain_nonzero(x) for x in items):
                break
        text = "(" + ", ".join(items) + ("," if rng.random() < 0.05 else "") + ")"
        if rng.random() < 0.1 and all(_is_plain(x) for x in items):
            name = self.fresh("v")
            self.decls.append(f"let {name} = {text}")
            return name
        if rng.random() < 0.08:
            return f"{text} * 1"
        return text

    def value(self, kind: str, r: Range, params_ok: bool = True) -> str:
        if kind in ("num", "int"):
            return self.number(r, kind, params_ok)
        if kind == "size" and self.rng.random() < 0.5:
            return self.number(r, "size", params_ok)
        return self.vector(r, 4 if kind == "vec4" else 3, params_ok, number_ok=kind == "size")

    # shapes

    def arguments(self, spec, owner: str) -> str:
        """Some positional, then some named in any order; defects in the list itself."""
        rng = self.rng
        if owner == "mandelbox":
            return self.mandelbox_arguments()
        given = [(name, self.value(kind, r)) for name, kind, r in spec if rng.random() < 0.6]
        positional = 0
        while positional < len(given) and given[positional][0] == spec[positional][0] and rng.random() < 0.5:
            positional += 1
        named = given[positional:]
        rng.shuffle(named)
        parts = [v for _, v in given[:positional]] + [f"{n}: {v}" for n, v in named]
        if self.take_defect(0.08):
            name, kind, r = rng.choice(spec)
            extra = self.value(kind, r)
            choices = [(f"radiusss: {extra}", "unknown argument")]
            if given:
                choices.append((f"{rng.choice(given)[0]}: {extra}", "argument given twice"))
            if positional == len(spec):
                choices.append((extra, "one argument too many"))
            text, self.made = rng.choice(choices)
            parts.append(self.mark(text))
        return ", ".join(parts)

    def mandelbox_arguments(self) -> str:
        rng = self.rng
        fixed = inside(rng, POSITIVE)
        fixed = fixed if 1e-6 < fixed < 1e6 else 1.0
        low = fixed * rng.choice([1, 0.5, 0.25, rng.random()]) or fixed
        parts = [f"scale: {self.number(ANY)}", f"fixed_radius: {literal(rng, fixed)}",
                 f"iterations: {self.number(ITERATIONS)}", f"fold_limit: {self.number(POSITIVE)}"]
        parts = [p for p in parts if rng.random() < 0.7 or p.startswith("fixed") or START in p]
        if self.take_defect(0.1):
            self.made = "min_radius above fixed_radius"
            parts.append(f"min_radius: {self.mark(literal(rng, fixed * 2 + 1))}")
        else:
            parts.append(f"min_radius: {literal(rng, low)}")
        rng.shuffle(parts)
        return ", ".join(parts)

    def primitive(self) -> str:
        rng = self.rng
        table = FRACTALS if rng.random() < 0.35 else PRIMITIVES
        name = rng.choice(list(table))
        spec = table[name]
        if self.take_defect(0.03):
            self.made = "unknown function"
            return f"{self.mark(name + 'z')}({self.arguments(spec, name)})"
        return f"{name}({self.arguments(spec, name)})"

    def shape(self, depth: int = 0) -> str:
        rng = self.rng
        roll = rng.random()
        if depth >= self.depth or roll < 0.3:
            text = self.primitive()
        elif roll < 0.4 and self.shapes:
            text = rng.choice(self.shapes)
        elif roll < 0.7:
            kind = rng.choice(["union", "intersect", "subtract"])
            count = 2 if kind == "subtract" else rng.randint(2, 4)
            parts = [self.shape(depth + 1) for _ in range(count)]
            if rng.random() < 0.5:
                parts.append(f"smooth: {self.smooth()}")
            text = f"{kind}({', '.join(parts)})"
        elif roll < 0.85:
            op = rng.choice(["|", "&", "-"])
            text = f"({self.shape(depth + 1)}) {op} ({self.shape(depth + 1)})"
        else:
            text = self.shape(depth + 1)
        for _ in range(rng.choice([0, 0, 1, 1, 2, 3])):
            text = self.transform(text)
        if rng.random() < 0.15:
            name = self.fresh("s")
            self.decls.append(f"let {name} = {text}")
            self.shapes.append(name)
            return name
        return text

    def smooth(self) -> str:
        if self.rng.random() < 0.2:
            return self.param_for(Range(0.01, 1))
        return self.number(Range(0, 2, limit=NON_NEGATIVE), params_ok=False)

    def transform(self, text: str) -> str:
        rng = self.rng
        name = rng.choice(list(TRANSFORMS) + ["material", "color", "color"])
        if self.take_defect(0.03):
            self.made = "unknown transform"
            return f"({text}).{self.mark(name + 'd')}()"
        if name == "material":
            return f"({text}).material({self.material_name()})"
        if name == "color":
            if rng.random() < 0.4:
                return f"({text}).color({self.orbit_trap()})"
            return f"({text}).color({self.vector(COLOR)})"
        spec = TRANSFORMS[name]
        # a param as a repeat period must not reach 0 (docs): literals only there
        if name == "repeat" and rng.random() < 0.5:
            args = rng.choice(["(2, 0, 0)", "(0, 3, 0)", "(1.5, 1.5, 0)", "4"])
        else:
            args = ", ".join(self.value(kind, r, params_ok=name != "repeat") for _, kind, r in spec)
        if self.take_defect(0.05):
            self.made = "transform without its argument"
            return f"{self.mark('(' + text + ')')}.{name}()"
        return f"({text}).{name}({args})"

    def orbit_trap(self) -> str:
        rng = self.rng
        parts = []
        if rng.random() < 0.6:
            parts.append(f"near: {self.vector(COLOR)}")
        if rng.random() < 0.6:
            parts.append(f"far: {self.vector(COLOR)}")
        if rng.random() < 0.6:
            trap = rng.choice(TRAPS)
            if self.take_defect(0.1):
                self.made = "unknown trap"
                trap = self.mark("corner")
            parts.append(f"trap: {trap}")
        if rng.random() < 0.5:
            parts.append(f"scale: {self.number(POSITIVE)}")
        rng.shuffle(parts)
        return f"orbit_trap({', '.join(parts)})"

    def material_name(self) -> str:
        if self.materials and self.rng.random() < 0.6:
            return self.rng.choice(self.materials)
        name = self.fresh("m")
        self.materials.append(name)
        self.decls.append(f"material {name} {self.block(MATERIAL_KEYS, params_ok=True)}")
        return name

    # blocks

    def block(self, keys: dict, params_ok: bool = False, required: tuple = (), words: dict | None = None) -> str:
        rng = self.rng
        entries = list(required)
        taken = {e.split(":")[0].strip(START + END) for e in required}
        for key, (kind, r) in keys.items():
            if key not in taken and rng.random() < 0.5:
                entries.append(f"{key}: {self.value(kind, r, params_ok)}")
        for key, choices in (words or {}).items():
            if rng.random() < 0.4:
                entries.append(f"{key}: {rng.choice(choices)}")
        rng.shuffle(entries)
        if keys and self.take_defect(0.08):
            key = rng.choice(list(keys))
            entries.append(self.mark(rng.choice([f"{key}x", "wibble"])) + ": 1")
            self.made = "unknown key"
        elif entries and self.take_defect(0.05):
            first = entries[0].split(":")[0]
            entries.append(self.mark(first) + ": " + entries[0].split(":", 1)[1].strip())
            self.made = "key given twice"
        numeric = [key for key, (kind, _) in keys.items() if kind == "num"]
        if not params_ok and self.params and numeric and self.take_defect(0.05):
            key = rng.choice(numeric)
            entries = [e for e in entries if not e.startswith(key + ":") or START in e]
            entries.append(f"{key}: {self.mark(self.params[0][0])}")
            self.made = "param in a constant block"
        separator = rng.choice([", ", ",\n    ", "\n    ", ",\n    "])
        trailing = "," if rng.random() < 0.2 else ""
        if not entries:
            return "{}" if rng.random() < 0.5 else "{\n}"
        return "{ " + separator.join(entries) + trailing + " }"

    def camera(self) -> str:
        rng = self.rng
        while True:
            position = tuple(round(rng.uniform(-6, 6), 2) for _ in range(3))
            if math.dist(position, (0, 0, 0)) > 2.5:
                break
        entries = [f"position: {_vec(position)}"]
        if rng.random() < 0.5:
            target = tuple(round(rng.uniform(-0.5, 0.5), 2) for _ in range(3))
            entries.append(f"target: {_vec(target)}")
        else:
            target = (0.0, 0.0, 0.0)
        if rng.random() < 0.3:
            entries.append("up: " + rng.choice(["(0, 0, 1)", "(0, 1, 0)", "(1, 0, 0)"]))
            forward = [t - p for t, p in zip(target, position)]
            up = eval(entries[-1][4:])  # noqa: S307 - one of the three literals above
            if _parallel(forward, up):
                entries.pop()
        if self.take_defect(0.15):
            if rng.random() < 0.5:
                entries = [e for e in entries if not e.startswith("target")]
                entries.append(f"target: {self.mark(_vec(position))}")
                self.made = "camera target at its position"
            else:
                entries = [e for e in entries if not e.startswith("up")]
                forward = tuple(t - p for t, p in zip(target, position))
                entries.append(f"up: {self.mark(_vec(tuple(2 * f for f in forward)))}")
                self.made = "camera up parallel to the view"
        return "camera " + self.block(CAMERA_KEYS, required=tuple(entries))

    def light(self) -> str:
        rng = self.rng
        kind = rng.choice(["directional", "point"])
        if kind == "directional":
            need = f"direction: {self.vector(Range(nonzero=True), params_ok=False)}"
        else:
            need = f"position: {_vec(tuple(round(rng.uniform(-5, 5), 1) for _ in range(3)))}"
        words = {"shadows": ("none", "hard", "soft")}
        if self.take_defect(0.06):
            self.made = "unknown light kind"
            return f"light {self.mark('laser')} " + self.block(LIGHT_KEYS, required=(need,), words=words)
        return f"light {kind} " + self.block(LIGHT_KEYS, required=(need,), words=words)

    def render(self) -> str:
        rng = self.rng
        entries = []
        if rng.random() < 0.5:
            entries.append("epsilon: " + (rng.choice(["pixel", "0.001", "1e-4", "0.01"])))
        for name, keys in EFFECT_BLOCKS.items():
            if rng.random() < 0.2:
                entries.append(f"{name}: {self.block(keys)}")
        if self.take_defect(0.1):
            key = rng.choice([k for k, (_, r) in RENDER_KEYS.items() if r.limit])
            entries.append(f"{key}: {self.mark(literal(rng, outside(rng, RENDER_KEYS[key][1])))}")
            self.made = "render value out of range"
        return "render " + self.block(RENDER_KEYS, required=tuple(entries), words=RENDER_WORDS)

    def path(self) -> str:
        rng = self.rng
        times = sorted(rng.sample(range(0, 20), rng.randint(2, 4)))
        frames = []
        for t in times:
            entries = [f"position: {_vec(tuple(round(rng.uniform(-6, 6), 1) + (5 if i == 1 else 0) for i in range(3)))}"]
            if rng.random() < 0.4:
                entries.append(f"fov: {literal(rng, inside(rng, Range(10, 90)))}")
            for name, default, lo, hi in self.params:
                if rng.random() < 0.4:
                    entries.append(f"{name}: {literal(rng, rng.choice([lo, hi, default]))}")
            frames.append((t, entries))
        if self.take_defect(0.2):
            if rng.random() < 0.5:
                frames[-1] = (self.mark(str(frames[-2][0])), frames[-1][1])
                self.made = "keyframe times not increasing"
            else:
                frames[0] = (self.mark(str(frames[0][0])), [e for e in frames[0][1] if not e.startswith("position")])
                self.made = "keyframe without a position"
        body = "\n".join(f"    {t}: {{ {', '.join(entries)} }}" for t, entries in frames)
        return "path {\n" + body + "\n}"

    def scene(self) -> str:
        rng = self.rng
        shape = self.shape()
        main = [f"scene {shape}"]
        if rng.random() < 0.6:
            main.append(self.camera())
        main += [self.light() for _ in range(rng.choice([0, 1, 1, 2, 3]))]
        if rng.random() < 0.7:
            main.append(self.render())
        if rng.random() < 0.1:
            main.append(self.path())
        decls = self.decls + main
        if self.pending:
            decls = self.declaration_defect(decls)
        elif rng.random() < 0.3:
            rng.shuffle(decls)   # declarations may come in any order
        comment = "# generated scene\n" if rng.random() < 0.3 else ""
        return comment + "\n".join(decls) + ("\n" if rng.random() < 0.8 else "")

    def declaration_defect(self, decls: list[str]) -> list[str]:
        rng = self.rng
        kind = rng.choice(["duplicate", "second scene", "no scene", "cycle", "empty range", "stray character",
                           "missing comma", "unclosed block", "division by zero", "sqrt of negative",
                           "path with one keyframe", "light without direction", "keyword glued to a name"])
        self.made = kind
        if kind == "duplicate":
            return decls + [f"let {self.mark('taken')} = 2", "let taken = 1"][::-1]
        if kind == "second scene":
            return decls + [self.mark("scene") + " sphere(1)"]
        if kind == "no scene":
            return [d for d in decls if not d.startswith("scene")]
        if kind == "cycle":
            return decls + [f"let {self.mark('ping')} = pong + 1", "let pong = ping * 2"]
        if kind == "empty range":
            return decls + [f"param bad = 1 in [{self.mark('3')}, 2]"]
        if kind == "stray character":
            return decls + [f"let stray = 1 {self.mark(rng.choice('$@!?;~`^'))} 2"]
        if kind == "missing comma":
            return decls + [f"material gap {{ specular: 0.5 {self.mark('shininess')}: 3 }}"]
        if kind == "unclosed block":
            return decls + ["material open { color: (1, 0, 0)"]
        if kind == "division by zero":
            return decls + [f"let ratio = {self.mark('1 / 0')}"]
        if kind == "sqrt of negative":
            return decls + [f"let root = {self.mark(rng.choice(['sqrt(-1)', 'log(0)', 'acos(2)']))}"]
        if kind == "path with one keyframe":
            return [d for d in decls if not d.startswith("path")] + [self.mark("path") + " { 0: { position: (0, -5, 1) } }"]
        if kind == "keyword glued to a name":
            return decls + [self.mark(rng.choice(["letglued", "paramglued", "scenesphere"])) + " = 1"]
        return decls + [self.mark("light") + " directional { intensity: 2 }"]


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:g}" for x in v) + ")"


def _parallel(a, b) -> bool:
    cross = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    return math.hypot(*cross) <= 1e-6 * math.hypot(*a) * math.hypot(*b)


def _is_plain(text: str) -> bool:
    return re.fullmatch(r"-?[\d.eE+-]+", text) is not None


def _plain_nonzero(text: str) -> bool:
    try:
        return float(text) != 0
    except ValueError:
        return False


def _unmark(text: str) -> tuple[str, tuple | None]:
    """The text without marks, and the (line, first column, end column) marked."""
    start = text.find(START)
    if start < 0:
        return text, None
    end = text.index(END)
    before = text[:start]
    line = before.count("\n") + 1
    column = start - (before.rfind("\n") + 1) + 1
    plain = text.replace(START, "").replace(END, "")
    return plain, (line, column, column + (end - start - 1))


def generated(rng: random.Random) -> Case:
    defect = rng.random() < 0.3
    generator = _Generator(rng, defect)
    text, where = _unmark(generator.scene())
    if not defect:
        return Case(text, "generated", "valid")
    return Case(text, f"generated, defect: {generator.made}", "invalid", where)


# ---- mutations of the example files -----------------------------------------------

TOKEN = re.compile(r"\s+|#[^\n]*|(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[A-Za-z_]\w*|.", re.S)
EXTREMES = ("0", "-0", "0.0", "1e-40", "1e-400", "1e38", "3.5e38", "1e39", "1e308", "1e400", "nan", "NaN", "inf",
            "-inf", "1e", "1.2.3", "99999999999999999999999999999999", "4294967297", "2147483648", "-1",
            "1e-7", "0x10", "1_000", "٣")
NOISE = ("\x00", "\x01", "\x07", "\x0b", "\x0c", "\x1b", "\x7f", "\x85", "\u2028", "\ufeff", "\t", "\r", "\r\n",
         "é", "∞", "\U0001f600", "{", "}", "(", ")", "[", "]", ",", ":", "|", "&", "-", ".", "#", "\"", "'", "\\")


def corpus() -> list[tuple[str, str]]:
    """(name, text) of every example file, hard test scene and documented example."""
    files = sorted(REPO.glob("examples/*.frac")) + sorted(REPO.glob("tests/hard/*.frac"))
    texts = [(str(p.relative_to(REPO)), p.read_text()) for p in files]
    for page in sorted(REPO.glob("docs/*.md")):
        for i, block in enumerate(re.findall(r"```frac\n(.*?)```", page.read_text(), re.S)):
            texts.append((f"{page.relative_to(REPO)}#{i + 1}", block))
    return texts


_CORPUS: list[tuple[str, str]] = []


def mutated(rng: random.Random) -> Case:
    if not _CORPUS:
        _CORPUS.extend(corpus())
    name, text = rng.choice(_CORPUS)
    tokens = TOKEN.findall(text)
    data: bytes | None = None
    ops = []
    for _ in range(rng.choice([1, 1, 1, 2, 3, 5])):
        op = rng.choice(["delete", "duplicate", "swap", "number", "number", "name", "noise", "truncate",
                         "splice", "nest", "bytes", "newline"])
        ops.append(op)
        if not tokens:
            tokens = [""]
        i = rng.randrange(len(tokens))
        if op == "delete":
            del tokens[i:i + rng.choice([1, 1, 2, 5])]
        elif op == "duplicate":
            tokens[i:i] = tokens[i:i + rng.choice([1, 2, 4])]
        elif op == "swap":
            j = rng.randrange(len(tokens))
            tokens[i], tokens[j] = tokens[j], tokens[i]
        elif op == "number":
            numbers = [k for k, t in enumerate(tokens) if t[:1].isdigit() or t[:1] == "."]
            if numbers:
                tokens[rng.choice(numbers)] = rng.choice(EXTREMES)
        elif op == "name":
            names = [k for k, t in enumerate(tokens) if t[:1].isalpha() or t[:1] == "_"]
            if names:
                tokens[rng.choice(names)] = rng.choice(WORDS)
        elif op == "noise":
            tokens.insert(i, "".join(rng.choice(NOISE) for _ in range(rng.choice([1, 1, 3]))))
        elif op == "truncate":
            tokens = tokens[:i]
        elif op == "splice":
            other = TOKEN.findall(rng.choice(_CORPUS)[1])
            j = rng.randrange(len(other) or 1)
            tokens[i:i] = other[j:j + rng.randint(1, 30)]
        elif op == "nest":
            depth = rng.choice([100, 255, 256, 257, 300, 2000])
            form = rng.choice(["paren", "minus", "chain", "union"])
            tokens.insert(i, {"paren": "(" * depth + "1" + ")" * depth,
                              "minus": "-" * depth + "1",
                              "chain": "sphere()" + ".scale(1)" * depth,
                              "union": " | ".join(["sphere()"] * depth)}[form])
        elif op == "newline":
            spaces = [k for k, t in enumerate(tokens) if t in (" ", ", ", "\n", ",")]
            if spaces:
                tokens[rng.choice(spaces)] = rng.choice(["\n", ",", " ", "\n\n", ",,"])
        else:   # bytes: the file is not valid UTF-8 (or has a BOM)
            raw = "".join(tokens).encode()
            at = rng.randrange(len(raw) + 1)
            junk = rng.choice([b"\xff", b"\xc3", b"\xe2\x82", b"\xed\xa0\x80", b"\x80\x80", bytes([rng.randrange(256)])])
            data = (b"\xef\xbb\xbf" + raw) if rng.random() < 0.2 else raw[:at] + junk + raw[at:]
            tokens = None
            break
    origin = f"mutation of {name}: {', '.join(ops)}"
    if data is not None:
        try:
            return Case(data.decode("utf-8"), origin, "unknown")
        except UnicodeDecodeError:
            return Case(data, origin, "unknown")
    return Case("".join(tokens), origin, "unknown")


def case(seed: int, index: int) -> Case:
    rng = random.Random(f"{seed}:{index}")
    return generated(rng) if rng.random() < 0.6 else mutated(rng)


# ---- the judge ----------------------------------------------------------------------

FILE = "fuzz.frac"
WIDTH, HEIGHT = 16, 12
HANG_SECONDS = 20
POINTS = ((0, 0, 0), (0.3, -0.2, 0.5), (1.1, 0, 0), (-2, 3, 1), (50, -40, 30), (1e4, 1e4, -1e4))


@dataclass(frozen=True)
class Verdict:
    outcome: str             # "rejected", "checked", "rendered" or "failed"
    failure: str = ""        # category: what went wrong (empty unless failed)
    detail: str = ""


class CaseTimeout(Exception):
    pass


@contextmanager
def time_limit(seconds: float):
    """Raise CaseTimeout in this (main) thread after `seconds`."""
    def expire(signum, frame):
        raise CaseTimeout
    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def text_of(source: str | bytes) -> str:
    """What fractalc quotes: a file's bytes as UTF-8 (bad bytes escaped), less a byte order mark."""
    if isinstance(source, str):
        return source
    return source.removeprefix(b"\xef\xbb\xbf").decode("utf-8", errors="backslashreplace")


# Line breaks: "\r\n", "\r" or "\n" (as editors count lines); other separators
# such as "\x0c" or "\u2028" are characters of a line.
LINE_BREAK = re.compile(r"\r\n?|\n")


def load(source: str | bytes):
    """Text through `loads`, bytes through a file named FILE in the working folder."""
    import fractalc
    if isinstance(source, str):
        return fractalc.loads(source, path=FILE)
    with tempfile.TemporaryDirectory() as folder:
        Path(folder, FILE).write_bytes(source)
        with _working_folder(folder):
            return fractalc.load(FILE)


@contextmanager
def _working_folder(folder):
    before = os.getcwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(before)


def location_problem(error, text: str, where: tuple | None) -> str:
    """Why the SceneError's places are wrong, or ''."""
    lines = LINE_BREAK.split(text)
    for d in error.errors:
        if d.file != FILE:
            return f"error names the file {d.file!r}"
        if not (1 <= d.line <= len(lines)) or not (1 <= d.column <= len(lines[d.line - 1]) + 1):
            return f"error at {d.line}:{d.column}, outside the text"
        if d.source_line != lines[d.line - 1]:
            return f"error at line {d.line} quotes another line: {d.source_line!r}"
        if not d.message.strip():
            return "error without a message"
    if not str(error).startswith(f"{FILE}:{error.line}:{error.column}: error: "):
        return "printed error does not start with FILE:LINE:COL: error:"
    if where:
        line, first, end = where
        if not any(d.line == line and first <= d.column <= max(first, end - 1) for d in error.errors):
            found = "; ".join(f"{d.line}:{d.column} {d.message}" for d in error.errors)
            return f"defect at {line}:{first}-{end} not reported there (reported: {found})"
    return ""


def judge(case: Case, build: bool) -> Verdict:
    """Check the case; if it checks and `build`, render it 16x12 and probe distances."""
    import numpy as np

    import fractalc
    text = text_of(case.source)
    try:
        with time_limit(HANG_SECONDS):
            scene = load(case.source)
    except CaseTimeout:
        return Verdict("failed", "hang while checking", f"over {HANG_SECONDS} s")
    except fractalc.SceneError as error:
        problem = location_problem(error, text, case.where)
        if problem:
            return Verdict("failed", "misplaced error", problem + "\n" + str(error))
        if case.expect == "valid":
            return Verdict("failed", "valid scene rejected", str(error))
        return Verdict("rejected")
    except RecursionError as error:
        return Verdict("failed", "traceback while checking", f"RecursionError: {error}")
    except Exception as error:  # noqa: BLE001 - any other exception is the failure being looked for
        return Verdict("failed", "traceback while checking", f"{type(error).__name__}: {error}")
    if case.expect == "invalid":
        return Verdict("failed", "defect not reported", case.origin)
    if not build:
        return Verdict("checked")
    keys = {"width": WIDTH, "height": HEIGHT}
    if scene.checked.render.samples > 4:
        keys["samples"] = 4
    if scene.checked.render.max_steps > 256:
        keys["max_steps"] = 256
    try:
        with time_limit(HANG_SECONDS * 3):
            image = scene.render(**keys)
            distances = scene.distance(np.array(POINTS, dtype=np.float64))
            problems = _non_finite(image, distances)
            for end in ("low", "high"):   # params at the ends of their ranges: no rebuild
                values = {p.name: getattr(p, end) for p in scene.checked.params if getattr(p, end) is not None}
                if values and not problems and _accepts(scene, values):
                    problems = [f"with params {values}: {p}" for p in
                                _non_finite(scene.render(**keys), scene.distance(np.array(POINTS)))]
    except CaseTimeout:
        return Verdict("failed", "hang while building or rendering", f"over {HANG_SECONDS * 3} s")
    except fractalc.RenderError as error:
        return Verdict("failed", "render error", str(error).splitlines()[0])
    except Exception as error:  # noqa: BLE001
        return Verdict("failed", "traceback while rendering", f"{type(error).__name__}: {error}")
    if problems:
        return Verdict("failed", "non-finite output", "; ".join(problems))
    return Verdict("rendered")


def _accepts(scene, values: dict) -> bool:
    """Set the params if these values are valid together (each alone is in range)."""
    import fractalc
    try:
        scene.set_params(values)
    except fractalc.SceneError:
        return False
    return True


def _non_finite(image, distances) -> list[str]:
    """What is not finite in a render and the distances at POINTS (Z may be +inf)."""
    import numpy as np
    problems = []
    for what, values in (("rgba", image.rgba), ("normal", image.normal), ("steps", image.steps)):
        bad = ~np.isfinite(values)
        if bad.any():
            problems.append(f"{what}: {int(bad.sum())} non-finite values, e.g. {values[bad][:3]}")
    depth = image.depth
    bad = ~(np.isfinite(depth) | (depth == np.inf)) | (depth < 0)
    if bad.any():
        problems.append(f"Z: {int(bad.sum())} values neither >= 0 nor +inf, e.g. {depth[bad][:3]}")
    if not np.isfinite(distances).all():
        problems.append(f"distance() at {POINTS}: {distances}")
    return problems


# ---- shrinking a failing case -------------------------------------------------------

def signature(verdict: Verdict) -> str:
    """What makes two failures the same: the category and the gist of the detail."""
    gist = verdict.detail.splitlines()[0] if verdict.detail else ""
    gist = re.sub(r"^\S*:\d+:\d+: error: ", "", gist)
    gist = re.sub(r"'[^']*'|\"[^\"]*\"|\[[^\]]*\]|[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|nan|inf", "_", gist)
    return f"{verdict.failure}: {gist[:90]}"


_PIECES = {str: re.compile(r"\s+|#[^\n]*|[\w.]+|.", re.S), bytes: re.compile(rb"\s+|[\w.]+|.", re.S)}


def shrink(failing: Case, verdict: Verdict, build: bool, tries: int = 300) -> Case:
    """A smaller case with the same failure signature: whole lines, then tokens,
    are dropped while the failure stays (delta debugging, Zeller)."""
    want = signature(verdict)
    source = failing.source
    newline = "\n" if isinstance(source, str) else b"\n"

    def still_fails(candidate) -> bool:
        nonlocal tries
        tries -= 1
        return signature(judge(Case(candidate, failing.origin, failing.expect), build)) == want

    empty = source[:0]
    for split, joiner in ((lambda s: s.split(newline), newline), (_PIECES[type(source)].findall, empty)):
        units = split(source)
        chunk = max(1, len(units) // 2)
        while chunk >= 1 and tries > 0:
            i, removed = 0, False
            while i < len(units) and tries > 0:
                candidate = units[:i] + units[i + chunk:]
                if candidate and still_fails(joiner.join(candidate)):
                    units, removed = candidate, True
                else:
                    i += chunk
            if not removed:
                chunk //= 2
        source = joiner.join(units)
    return Case(source, failing.origin, failing.expect)
