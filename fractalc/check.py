"""Stage 2: AST -> checked scene (`check`).

Resolves names, types and arguments, folds constants (through `ir`), checks
ranges, and collects every error with its span before raising one
`SceneError`. An expression that failed evaluates to `_ERROR`, which later
checks accept silently, so one mistake gives one message.
"""
from __future__ import annotations

import difflib
from functools import lru_cache
import itertools
import math
import os
from dataclasses import dataclass, replace
from enum import Enum

from . import ast, formula_code, ir, pathtrace
from .errors import Diagnostic, SceneError, Severity, Span, diagnostic
from .ir import FLOAT_MAX, in_float_range
from .program import (DEFAULT_MATERIAL, PROJECTIONS, STEREO_LAYOUTS, Camera, CameraPath, CheckedScene, Coloring,
                      Combination, Environment, Fog, Fractal, Glow, Keyframe, Light, Material, ParamCheck, ParamInfo,
                      Preset, Primitive, RenderSettings, Shape, Slice, Transformed, WithMaterial, cosine_palette,
                      light_vector_key)
from .parse import parse
from .resources import resource_dir
from .stdlib import AUTO_SCALE, COLORINGS, COMBINATORS, MATH, TRANSFORMS, Parameter, Signature, library
from .write import TONE_CURVES

# The language's value types.
NUM, SHAPE, MATERIAL, WORD, COLORING, FORMULA = "number", "shape", "material", "word", "coloring", "formula"
def vec_type(n: int) -> str:
    return f"vec{n}"


@dataclass(frozen=True)
class Value:
    type: str          # number | vec2..vec4 | shape | material | word | error
    data: object       # ir.Expr | ir.Vec | Shape | material name | word


_ERROR = Value("error", None)

# Parts (primitives, transforms, combinations) a scene may have, counting a
# let each time it is used. The kernel's build time grows faster than its
# size: on 2 cores, a union of 1000 translated spheres (2001 parts) takes
# 11 s to build and render once, 2000 spheres 30 s, 4000 spheres 73 s
# (benchmarks/scene_size.py; 10000 spheres took 17 minutes).
MAX_SHAPES = 6000
# Formula steps in one round of a hybrid (each `f() * n` counts n): a round
# is written out whole in the orbit loop, so the kernel grows with it. On 2
# cores (load 5), hybrids of bulb and amazing_box steps, iterations 1000,
# check in 0.3-1.7 s and then build and render once in 7 s (100 steps),
# 26 s (200), 64 s (400; benchmarks/hybrid_size.py); 1000 steps built for 84 s.
MAX_HYBRID_STEPS = 256
# The hit threshold's largest multiple: normals are differences over that
# step, which beyond it can pass float's range on the scene (NaN normals).
MAX_EPSILON_SCALE = 1000
# Errors that get a "did you mean" (each costs time in the number of known names)
SUGGESTED_ERRORS = 10
_TYPE_WORDS = {NUM: "a number", SHAPE: "a shape", MATERIAL: "a material", WORD: "a name", FORMULA: "a formula",
               COLORING: "a colouring (orbit_trap)", "color": "a colour (r, g, b) or orbit_trap(...)",
               "vec2": "a 2-vector", "vec3": "a 3-vector", "vec4": "a 4-vector",
               "size": "a number or a 3-vector", "int": "a whole number", "rgb": "a colour (r, g, b)"}


class _Failed(Exception):
    """Raised to abandon the current expression after recording an error."""


class _Checker:
    def __init__(self, program: ast.Program, with_library: bool = True):
        self.program = program
        self.errors: list[Diagnostic] = []
        self.library = library()
        self.params: dict[str, ParamInfo] = {}
        self.lets: dict[str, ast.LetDecl] = {}
        self.let_values: dict[str, Value] = {}
        self.material_decls: dict[str, ast.MaterialDecl] = {}
        self.materials: dict[str, Material] = {}
        self.colors: dict[tuple, str] = {}
        self.param_checks: list[ParamCheck] = []
        self.shape_sizes: dict[int, tuple[Shape, int]] = {}
        # the library's formulas, and those a scene can call by name: the library's and the file's own
        self.library_formulas: dict[str, tuple[formula_code.Formula, Signature]] = \
            dict(library_formulas() if with_library else ())
        self.formulas: dict[str, tuple[formula_code.Formula, Signature] | None] = dict(self.library_formulas)
        self.notes: list[Diagnostic] = []

    # ---- diagnostics -------------------------------------------------------

    def error(self, span: Span, message: str) -> None:
        self.errors.append(diagnostic(self.program.file, self.program.source, span, message))

    def fail(self, span: Span, message: str):
        self.error(span, message)
        raise _Failed

    def note(self, span: Span, message: str) -> None:
        self.notes.append(diagnostic(self.program.file, self.program.source, span, message, Severity.NOTE))

    # ---- declarations ------------------------------------------------------

    def run(self) -> CheckedScene:
        decls = self.program.decls
        names: dict[str, Span] = {}
        singles: dict[type, ast.Decl] = {}
        for decl in decls:
            if isinstance(decl, (ast.ParamDecl, ast.LetDecl, ast.MaterialDecl, ast.FormulaDecl)):
                if decl.name in names:
                    first = names[decl.name]
                    self.error(decl.name_span, f"'{decl.name}' is already declared (line {first.line})")
                    continue
                names[decl.name] = decl.name_span
            if isinstance(decl, (ast.SceneDecl, ast.CameraDecl, ast.RenderDecl, ast.PathDecl)):
                kind = type(decl).__name__.removesuffix("Decl").lower()
                if type(decl) in singles:
                    first = singles[type(decl)].span
                    self.error(decl.span, f"a second '{kind}' declaration (the first is at line {first.line})")
                    continue
                singles[type(decl)] = decl
            if isinstance(decl, ast.LetDecl):
                self.lets[decl.name] = decl
            elif isinstance(decl, ast.MaterialDecl):
                self.material_decls[decl.name] = decl

        for decl in decls:
            if isinstance(decl, ast.ParamDecl) and decl.name not in self.params:
                self.declare_param(decl)
        for decl in decls:
            if isinstance(decl, ast.FormulaDecl) and names.get(decl.name) is decl.name_span:
                self.declare_formula(decl)     # a file's formula replaces the library's of its name
        self.materials[DEFAULT_MATERIAL] = Material(
            DEFAULT_MATERIAL, ir.vec(*(ir.const(0.8) for _ in range(3))),
            ir.const(0.3), ir.const(32.0), ir.const(0.0), ir.const(0.0), ir.const(1.5))
        for name, decl in self.material_decls.items():
            self.materials[name] = self.material(decl)
        for name in self.lets:
            self.let_value(name)

        shape = None
        scene = singles.get(ast.SceneDecl)
        if scene is None:
            end = len(self.program.source.splitlines()) or 1
            self.error(Span(end, 1, end, 2), "the file has no 'scene' declaration (add e.g. 'scene sphere(1)')")
        else:
            value = self.evaluate(scene.shape)
            if value.type not in (SHAPE, "error"):
                hint = " (make it one with 'fractal(formula(...), iterations: N)')" if value.type == FORMULA else ""
                self.error(scene.shape.span, f"'scene' needs a shape, this is {_TYPE_WORDS[value.type]}{hint}")
            shape = value.data
        camera = self.camera(singles.get(ast.CameraDecl))
        lights = tuple(self.light(d) for d in decls if isinstance(d, ast.LightDecl))
        render = self.render(singles.get(ast.RenderDecl))
        path = self.path(singles.get(ast.PathDecl))
        presets = self.presets([d for d in decls if isinstance(d, ast.PresetDecl)])
        if self.errors:
            raise SceneError(self.errors)
        scene = CheckedScene(self.program.file, self.program.source, tuple(self.params.values()),
                             self.materials, shape, camera, tuple(l for l in lights if l), render,
                             tuple(self.param_checks), path, presets,
                             tuple(sorted(self.notes, key=lambda d: (d.line, d.column))))
        check_param_values(scene, [p.default for p in scene.params])
        return scene

    def declare_param(self, decl: ast.ParamDecl) -> None:
        default = self.constant_number(decl.default, "a param's value")
        low = high = None
        if decl.bounds:
            low = self.constant_number(decl.bounds[0], "a param's bound")
            high = self.constant_number(decl.bounds[1], "a param's bound")
            if None not in (low, high, default):
                if low > high:
                    self.error(decl.bounds[0].span, f"the range [{low:g}, {high:g}] is empty")
                elif not low <= default <= high:
                    self.error(decl.default.span,
                               f"'{decl.name}' = {default:g} is outside its range [{low:g}, {high:g}]")
        self.params[decl.name] = ParamInfo(decl.name, len(self.params), default or 0.0, low, high, decl.span)

    # ---- formulas ------------------------------------------------------------

    def declare_formula(self, decl: ast.FormulaDecl) -> None:
        """A formula's parameters (constant defaults, ranges) and its
        statements, run once with the defaults: each mistake at its place."""
        self.formulas[decl.name] = None
        if decl.name in self.library.signatures or decl.name in FORMULA_FORMS or decl.name in MATH \
                or decl.name in COMBINATORS or decl.name in COLORINGS:
            self.error(decl.name_span, f"'{decl.name}' is a built-in name: give the formula another")
            return
        parameters, defaults, seen = [], [], set()
        for param in decl.params:
            if param.name in seen or param.name in ("z", "distance"):
                self.error(param.name_span, f"'{param.name}' is already a parameter of '{decl.name}'"
                           if param.name in seen else
                           f"'{param.name}' is the formula's own: name the parameter otherwise")
                return
            seen.add(param.name)
            value = self.evaluate(param.default)
            items = value.data.items if isinstance(value.data, ir.Vec) else (value.data,)
            if value.type not in (NUM, "vec3", "vec4") or not all(ir.is_const(x) for x in items):
                if value.type != "error":
                    self.error(param.default.span, "a formula parameter's default must be a constant number "
                                                   "or a 3- or 4-vector")
                return
            constraints = ()
            if param.bounds:
                low = self.constant_number(param.bounds[0], "a parameter's bound")
                high = self.constant_number(param.bounds[1], "a parameter's bound")
                if low is None or high is None:
                    return
                if low > high:
                    self.error(param.bounds[0].span, f"the range [{low:g}, {high:g}] is empty")
                    return
                if value.type != NUM:
                    self.error(param.bounds[0].span, "a range is for a number parameter")
                    return
                if not low <= items[0].value <= high:
                    self.error(param.default.span, f"'{param.name}' = {items[0].value:g} is outside its range "
                                                   f"[{low:g}, {high:g}]")
                    return
                constraints = (f"{low!r}..{high!r}",)
            default = items[0].value if value.type == NUM else tuple(x.value for x in items)
            parameters.append(Parameter(param.name, "num" if value.type == NUM else value.type, default,
                                        constraints))
            defaults.append(value.data)
        try:
            formula = formula_code.split(decl, self.program.file)
            formula_code.orbit((formula_code.Use(formula, tuple(defaults)),), formula_code.POINT, ir.const(2.0))
        except formula_code.Mistake as mistake:
            self.error(mistake.span, mistake.message)
            return
        self.formulas[decl.name] = (formula, Signature("formula", decl.name, tuple(parameters)))
        hidden = self.library_formulas.get(decl.name)
        if hidden is not None:
            where = f"{os.path.basename(os.path.dirname(hidden[0].file))}/{os.path.basename(hidden[0].file)}"
            self.note(decl.name_span, f"'{decl.name}' hides the library formula of that name ({where}:"
                                      f"{hidden[0].span.line}); the library's is still "
                                      f"'{LIBRARY}.{decl.name}(...)'")

    def formula_use(self, e: ast.Call | ast.Method, known) -> Value:
        """A formula with its arguments; `known` is its declaration (None: one that had a mistake)."""
        if known is None:
            raise _Failed              # its declaration had a mistake, already reported
        formula, signature = known
        return Value(FORMULA, (formula_code.Use(formula, self.bound_args(e, signature, e.args)),))

    def library_formula(self, e: ast.Method) -> Value:
        """`library.NAME(...)`: the library's formula NAME, even where the file's hides it."""
        known = self.library_formulas.get(e.name)
        if known is None:
            self.fail(e.name_span, f"the library has no formula '{e.name}'"
                                   f"{self.did_you_mean(e.name, self.library_formulas)}")
        return self.formula_use(e, known)

    def hybrid(self, e: ast.Call) -> Value:
        sequence = []
        for arg in e.args:
            if arg.name is not None:
                self.fail(arg.span, "'hybrid' takes formulas in order, without names")
            value = self.value_of(arg.value)
            if value.type == "error":
                raise _Failed
            if value.type != FORMULA:
                self.fail(arg.span, f"'hybrid' takes formulas (e.g. hybrid(bulb(8) * 2, amazing_box())), "
                                    f"this is {_TYPE_WORDS[value.type]}")
            sequence.extend(value.data)
            self.require_hybrid_steps(sequence, arg.span)
        if not sequence:
            self.fail(e.span, "'hybrid' needs at least one formula")
        sizes = {}                     # 3 or 4 -> the first formula whose z has that many components
        for use in sequence:
            try:
                size = formula_code.z_size(use, formula_code.POINT)
            except formula_code.Mistake:
                continue               # the formula's own mistake, reported where it is used
            if size in (3, 4):
                sizes.setdefault(size, use.formula.name)
        if len(sizes) > 1:
            self.fail(e.span, f"a hybrid's formulas must all work on 3-vectors or all on 4-vectors: "
                              f"'{sizes[4]}' makes z a 4-vector in its 'init', '{sizes[3]}' works on the "
                              f"point's 3")
        return Value(FORMULA, tuple(sequence))

    def repeated(self, e: ast.Binary, formula: Value, count: Value) -> Value:
        """`formula * n`: n steps of it in turn in a hybrid."""
        if count.type == SHAPE:
            self.fail(e.left.span, "this is a formula: make it a shape with 'fractal(formula(...), iterations: N)'")
        if e.op != "*" or count.type != NUM:
            self.fail(e.span, f"a formula can only be repeated: 'formula * count', not '{e.op}' "
                              f"with {_TYPE_WORDS[count.type]}")
        n = count.data.value if ir.is_const(count.data) else None
        if n is None or n != math.floor(n) or not 1 <= n <= 100:
            self.fail(e.right.span, "a formula's repeat count must be a constant whole number from 1 to 100")
        repeated = tuple(replace(use, count=use.count * int(n)) for use in formula.data)
        self.require_hybrid_steps(repeated, e.right.span)
        return Value(FORMULA, repeated)

    def require_hybrid_steps(self, sequence, span: Span) -> None:
        """A hybrid's round of at most MAX_HYBRID_STEPS steps, refused where it passes them."""
        steps = sum(use.count for use in sequence)
        if steps > MAX_HYBRID_STEPS:
            self.fail(span, f"the hybrid passes {MAX_HYBRID_STEPS} formula steps per round here ({steps}): "
                            f"each is written out in the kernel, which would take minutes to compile. "
                            f"Use fewer steps (a formula's repeat count, e.g. 'bulb() * 4', counts as 4)")

    def fractal(self, e: ast.Call) -> Value:
        bound = self.bind(e, FORMULA_FORMS["fractal"], e.args)
        formula = bound["formula"][1]
        if formula.type == "error":
            raise _Failed
        if formula.type != FORMULA:
            if formula.type == WORD:
                self.unknown_name(bound["formula"][0].value.span, formula.data)
            self.fail(bound["formula"][0].value.span, f"'fractal' needs a formula (declared with 'formula "
                                                      f"name(...) {{ ... }}'), this is {_TYPE_WORDS[formula.type]}")
        values = {}
        for p in FORMULA_FORMS["fractal"].parameters[1:]:
            if p.name not in bound:
                values[p.name] = _default(p) if p.name in ("iterations", "step") else None
                continue
            arg, value = bound[p.name]
            if p.name == "julia" and value.type == "vec4":
                p = replace(p, type="vec4")
            values[p.name] = self.convert(arg.value.span, value, p, "fractal")
        # the estimate's kind from |z|'s growth at the params' defaults and range ends
        params = tuple(self.params.values())
        param_values = tuple(tuple(p.default if value is None else value for p, value in zip(params, chosen))
                             for chosen in ([None] * len(params), [p.low for p in params], [p.high for p in params]))
        try:
            growth = formula_code.growth(formula.data, values["julia"], param_values)
            formula_code.orbit(formula.data, formula_code.POINT, ir.const(2.0), values["bailout"], values["julia"],
                               where=e.span, estimate=growth.estimate)
        except formula_code.Mistake as mistake:
            inside = next((u.formula for u in formula.data if u.formula.file != self.program.file), None)
            if inside is None or mistake.span == e.span:
                self.fail(mistake.span, mistake.message)
            self.fail(e.span, f"{mistake.message} (in the library's '{inside.name}', "
                              f"{inside.file}:{mistake.span.line})")
        reason = None if formula.data[-1].formula.sets_distance else growth.reason()
        return self.shape(Fractal(formula.data, values["iterations"], values["bailout"], values["julia"],
                                  values["bound"], values["step"], e.span, growth, reason))

    def constant_number(self, expr: ast.Expr, what: str) -> float | None:
        value = self.evaluate(expr)
        if value.type == "error":
            return None
        if value.type != NUM or not ir.is_const(value.data):
            self.error(expr.span, f"{what} must be a constant number")
            return None
        return value.data.value

    def let_value(self, name: str) -> Value:
        if name not in self.let_values:
            for ready in self.let_order(name):
                value = self.let_expression(ready)
                self.let_values.setdefault(ready, value)   # a let in a cycle stays an error
        return self.let_values[name]

    def let_expression(self, name: str) -> Value:
        try:
            return self.value_of(self.lets[name].value)
        except _Failed:
            return _ERROR

    def let_order(self, name: str) -> list[str]:
        """`name` and the lets without a value that it uses, each after the
        lets it uses. Depth-first on an explicit stack: a chain of lets of
        any length costs no Python recursion. A let met again on its own
        chain is a cycle: reported, and its value is an error."""
        order: list[str] = []
        path, stack, placed = [name], [iter(self.let_uses(name))], set()
        on_path = {name}
        while stack:
            used = next(stack[-1], None)
            if used is None:
                order.append(path.pop())
                on_path.discard(order[-1])
                placed.add(order[-1])
                stack.pop()
            elif used in on_path:
                cycle = " -> ".join(path[path.index(used):] + [used])
                self.error(self.lets[used].name_span, f"'{used}' is defined in terms of itself ({cycle})")
                self.let_values[used] = _ERROR
            elif used not in self.let_values and used not in placed:
                path.append(used)
                on_path.add(used)
                stack.append(iter(self.let_uses(used)))
        return order

    def let_uses(self, name: str) -> list[str]:
        """The lets named in a let's expression, in the order evaluation
        meets them."""
        return [e.name for e in ast.walk(self.lets[name].value)
                if isinstance(e, ast.Name) and e.name in self.lets and e.name not in self.params]

    # ---- expressions -------------------------------------------------------

    def evaluate(self, expr: ast.Expr) -> Value:
        try:
            return self._evaluate(expr)
        except _Failed:
            return _ERROR

    def _evaluate(self, e: ast.Expr) -> Value:
        if isinstance(e, ast.Number):
            if not in_float_range(e.value):
                self.fail(e.span, f"{_source_text(self.program, e.span)} is too large a number "
                                  f"(the kernel's floats reach {FLOAT_MAX:.3g})")
            return Value(NUM, ir.const(e.value))
        if isinstance(e, ast.Name):
            return self.name(e)
        if isinstance(e, ast.Vector):
            items = [self._evaluate(x) for x in e.items]
            if any(v.type == "error" for v in items):
                return _ERROR
            for item, v in zip(e.items, items):
                if v.type != NUM:
                    self.fail(item.span, f"a vector's components must be numbers, this is {_TYPE_WORDS[v.type]}")
            if len(items) > 4:
                self.fail(e.span, f"vectors have 2 to 4 components, this one has {len(items)}")
            return Value(vec_type(len(items)), ir.Vec(tuple(v.data for v in items)))
        if isinstance(e, ast.Unary):
            operand = self._evaluate(e.operand)
            if operand.type == "error":
                return _ERROR
            if operand.type == SHAPE:
                self.fail(e.span, "a shape cannot be negated (to cut one shape from another use 'a - b')")
            return self.arithmetic(e, "neg", [operand])
        if isinstance(e, ast.Binary):
            return self.binary(e)
        if isinstance(e, ast.Chain):
            return self.chain(e)
        if isinstance(e, ast.Call):
            return self.call(e)
        if isinstance(e, ast.Method):
            return self.method(e)
        if isinstance(e, ast.Field):
            return self.field(e)
        raise TypeError(f"unexpected AST node {e!r}")

    def name(self, e: ast.Name) -> Value:
        if e.name in self.params:
            info = self.params[e.name]
            return Value(NUM, ir.Param(info.index, info.name))
        if e.name in self.lets:
            return self.let_value(e.name)
        if e.name in self.material_decls:
            return Value(MATERIAL, e.name)
        if e.name in self.library.signatures or e.name in COMBINATORS or e.name in MATH \
                or e.name in COLORINGS or e.name in self.formulas or e.name in FORMULA_FORMS:
            self.fail(e.span, f"'{e.name}' is a function: call it, e.g. '{e.name}()'")
        return Value(WORD, e.name)

    def unknown_name(self, span: Span, name: str) -> None:
        hint = self.did_you_mean(name, self.params, self.lets, self.material_decls)
        self.fail(span, f"unknown name '{name}'{hint}")

    def did_you_mean(self, name: str, *known) -> str:
        """' (did you mean 'x'?)' naming the name in `known` (collections
        of names) closest to `name`, or ''. Its cost grows with the known
        names, so only the first SUGGESTED_ERRORS errors get one: a file of
        thousands of unknown names stays linear."""
        if len(self.errors) >= SUGGESTED_ERRORS:
            return ""
        close = closest_name(name, itertools.chain(*known))
        return f" (did you mean '{close}'?)" if close else ""

    def value_of(self, e: ast.Expr) -> Value:
        """Evaluate an expression that must be a value (not a bare word)."""
        value = self._evaluate(e)
        if value.type == WORD:
            self.unknown_name(e.span, value.data)
        return value

    def binary(self, e: ast.Binary) -> Value:
        left, right = self.value_of(e.left), self.value_of(e.right)
        if "error" in (left.type, right.type):
            return _ERROR
        if left.type == FORMULA:
            return self.repeated(e, left, right)
        if right.type == FORMULA:
            self.fail(e.right.span if left.type == SHAPE else e.span,
                      "this is a formula: make it a shape with 'fractal(formula(...), iterations: N)'"
                      if left.type == SHAPE else "a formula's repeat count goes after it: 'formula * count'")
        if e.op not in "+-*/":
            self.fail(e.span, f"'{e.op}' compares numbers in a formula; a scene has no comparisons")
        if left.type == SHAPE and right.type == SHAPE:
            if e.op != "-":
                self.fail(e.span, f"'{e.op}' does not combine shapes: use '|' (union), '&' (intersect) or '-' (subtract)")
            return self.shape(Combination("subtract", (left.data, right.data), ir.const(0.0), e.span))
        if SHAPE in (left.type, right.type):
            other = right if left.type == SHAPE else left
            self.fail(e.span, f"'{e.op}' needs two shapes or two numbers/vectors, not a shape and {_TYPE_WORDS[other.type]}")
        return self.arithmetic(e, e.op, [left, right])

    def chain(self, e: ast.Chain) -> Value:
        """`a | b | ...` (a union) or `a & b & ...` (an intersection) of shapes:
        one combination of them all, as union(...) and intersect(...) are."""
        shapes = []
        for operand in e.operands:
            value = self.value_of(operand)
            if value.type == "error":
                raise _Failed
            if value.type != SHAPE:
                self.fail(operand.span, "this is a formula: make it a shape with 'fractal(formula(...), iterations: N)'"
                          if value.type == FORMULA else
                          f"'{e.op}' combines shapes ({'union' if e.op == '|' else 'intersection'}), "
                          f"this is {_TYPE_WORDS[value.type]}")
            shapes.append(value.data)
        return self.shape(Combination("union" if e.op == "|" else "intersect", tuple(shapes), ir.const(0.0), e.span))

    def arithmetic(self, e, op: str, operands: list[Value], mode: str = "map") -> Value:
        """Component-wise arithmetic on numbers and vectors; numbers broadcast."""
        for operand in operands:
            if operand.type not in (NUM, "vec2", "vec3", "vec4"):
                self.fail(e.span, f"'{op}' needs numbers or vectors, not {_TYPE_WORDS[operand.type]}")
        sizes = {len(o.data) for o in operands if o.type != NUM}
        if len(sizes) > 1:
            self.fail(e.span, f"'{op}' on vectors of different sizes ({', '.join(map(str, sorted(sizes)))})")
        size = sizes.pop() if sizes else 0
        lanes = [o.data.items if o.type != NUM else (o.data,) * max(size, 1) for o in operands]
        try:
            items = tuple(ir.op(op, *args) for args in zip(*lanes))
        except (ValueError, ZeroDivisionError, OverflowError):
            self.fail(e.span, f"'{op}' is undefined for these values")
        for item in items:
            if ir.is_const(item) and not in_float_range(item.value):
                self.fail(e.span, f"'{op}' gives {item.value:.3g}, beyond the kernel's floats ({FLOAT_MAX:.3g})")
        if size == 0:
            return Value(NUM, items[0])
        return Value(vec_type(size), ir.Vec(items))

    # ---- calls -------------------------------------------------------------

    def bind(self, e, signature: Signature, args: tuple[ast.Arg, ...]) -> dict[str, tuple[ast.Arg, Value]]:
        """Match arguments to parameters; report unknown, duplicate, extra
        and missing arguments."""
        params = signature.parameters
        bound: dict[str, tuple[ast.Arg, Value]] = {}
        positional = 0
        for arg in args:
            if arg.name is None:
                if positional >= len(params):
                    self.fail(arg.span, f"'{signature.name}' takes at most {len(params)} "
                                        f"argument{'s' if len(params) != 1 else ''}, this is one more")
                name = params[positional].name
                positional += 1
            else:
                name = arg.name
                if name not in {p.name for p in params}:
                    names = ", ".join(p.name for p in params) or "none"
                    self.fail(arg.span, f"'{signature.name}' has no argument '{name}' (its arguments: {names})")
            if name in bound:
                self.fail(arg.span, f"argument '{name}' is given twice")
            bound[name] = (arg, self._evaluate(arg.value))
        for p in params:
            if p.name not in bound and p.default is None:
                self.fail(e.span, f"'{signature.name}' needs the argument '{p.name}'")
        return bound

    def convert(self, span: Span, value: Value, param: Parameter, owner: str):
        """An argument value as the parameter's type (ir.Expr or ir.Vec)."""
        if value.type == "error":
            raise _Failed
        want = param.type
        if want.startswith("word:"):
            choices = want[5:].split("|")
            if value.type == WORD and value.data in choices:
                return value.data
            self.fail(span, f"'{param.name}' of '{owner}' must be one of {', '.join(choices)}")
        if want == "color" and value.type == COLORING:
            return value.data
        ok = {"num": (NUM,), "int": (NUM,), "vec3": ("vec3",), "vec4": ("vec4",), "color": ("vec3",),
              "size": (NUM, "vec3"), "material": (MATERIAL,), "shape": (SHAPE,)}[want]
        if value.type not in ok:
            word = _TYPE_WORDS.get(want if want != "num" else NUM)
            if value.type == WORD and want != "material":
                self.unknown_name(span, value.data)
            if value.type == WORD:
                hint = self.did_you_mean(value.data, self.material_decls)
                self.fail(span, f"unknown material '{value.data}'{hint}")
            self.fail(span, f"'{param.name}' of '{owner}' needs {word}, this is {_TYPE_WORDS[value.type]}")
        data = value.data
        if want == "size" and value.type == NUM:
            data = ir.vec(data, data, data)
        self.check_constraints(span, data, param, owner)
        return data

    def check_constraints(self, span: Span, data, param: Parameter, owner: str,
                          others: dict | None = None, subject: str | None = None) -> None:
        """`subject`: who the message speaks of, if not `'name' of 'owner'`
        (an API argument; '': none, where the caller names the option)."""
        subject = f"'{param.name}' of '{owner}'" if subject is None else subject
        items = data.items if isinstance(data, ir.Vec) else (data,)
        if not all(isinstance(x, ir.Const) for x in items):
            if (param.constraints or param.type == "int") and others is None:
                self.param_checks.append(ParamCheck(span, data, param, owner))
            return   # depends on a param: checked for each set of param values
        values = [x.value for x in items]
        shown = _number_text(values[0]) if len(values) == 1 else "(" + ", ".join(f"{v:g}" for v in values) + ")"
        if param.type == "int" and any(v != math.floor(v) for v in values):
            self.fail(span, f"{subject} must be a whole number, not {shown}".lstrip())
        for c in param.constraints:
            if c == "nonzero":
                ok, says = any(v != 0 for v in values), "must not be zero"
            elif ".." in c:
                lo, hi = (float(x) for x in c.split(".."))
                ok, says = all(lo <= v <= hi for v in values), f"must be between {_number_text(lo)} and {_number_text(hi)}"
            else:
                opname, bound = c[:2] if c[1] == "=" else c[0], c[2:] if c[1] == "=" else c[1:]
                if bound[0].isalpha():
                    if not others or bound not in others:
                        continue
                    limit, bound_text = others[bound], f"'{bound}' ({others[bound]:g})"
                else:
                    limit, bound_text = float(bound), _number_text(float(bound))
                test = {">": float.__gt__, ">=": float.__ge__, "<": float.__lt__, "<=": float.__le__}[opname]
                ok = all(test(v, limit) for v in values)
                says = f"must be {'greater than' if opname == '>' else 'at least' if opname == '>=' else 'less than' if opname == '<' else 'at most'} {bound_text}"
            if not ok:
                self.fail(span, f"{subject} {says}, not {shown}".lstrip())

    def bound_args(self, e, signature: Signature, args) -> tuple:
        bound = self.bind(e, signature, args)
        converted: dict[str, object] = {}
        failed = False
        for p in signature.parameters:
            try:
                if p.name in bound:
                    arg, value = bound[p.name]
                    converted[p.name] = self.convert(arg.value.span, value, p, signature.name)
                else:
                    converted[p.name] = _default(p)
            except _Failed:
                failed = True
        if failed:
            raise _Failed
        scalars = {k: v for k, v in converted.items() if isinstance(v, (ir.Const, ir.Param, ir.Op))}
        for p in signature.parameters:
            # constraints between arguments, e.g. min_radius <= fixed_radius
            related = tuple(c for c in p.constraints if c[:2] in ("<=", ">=") and c[2:3].isalpha())
            if not related or p.name not in scalars:
                continue
            between = replace(p, constraints=related)
            span = bound[p.name][0].value.span if p.name in bound else e.span
            others = {c[2:]: scalars[c[2:]] for c in related if c[2:] in scalars}
            if all(ir.is_const(x) for x in (scalars[p.name], *others.values())):
                self.check_constraints(span, scalars[p.name], between, signature.name,
                                       {k: v.value for k, v in others.items()})
            else:
                self.param_checks.append(ParamCheck(span, scalars[p.name], between, signature.name, others))
        return tuple(converted[p.name] for p in signature.parameters)

    def call(self, e: ast.Call) -> Value:
        name = e.name
        if name in self.formulas:
            return self.formula_use(e, self.formulas[name])
        if name == "fractal":
            return self.fractal(e)
        if name == "hybrid":
            return self.hybrid(e)
        if name in MATH:
            return self.math(e)
        if name in COMBINATORS:
            return self.combinator(e)
        if name == "palette":
            *palette, trap, scale = self.bound_args(e, COLORINGS[name], e.args)
            start = cosine_palette(tuple(palette), ir.const(0.0))
            return Value(COLORING, Coloring(start, start, trap, _given_scale(scale), tuple(palette)))
        if name in COLORINGS:
            near, far, trap, scale = self.bound_args(e, COLORINGS[name], e.args)
            return Value(COLORING, Coloring(near, far, trap, _given_scale(scale)))
        signature = self.library.signatures.get(name)
        if signature is None:
            hint = self.did_you_mean(name, self.library.signatures, COMBINATORS, MATH, COLORINGS, self.formulas)
            self.fail(e.name_span, f"unknown function '{name}'{hint}")
        return self.shape(Primitive(signature, self.bound_args(e, signature, e.args), e.span))

    def combinator(self, e: ast.Call) -> Value:
        signature = COMBINATORS[e.name]
        shapes = [a for a in e.args if a.name is None]
        options = tuple(a for a in e.args if a.name is not None)
        values = [self.value_of(a.value) for a in shapes]
        for arg, value in zip(shapes, values):
            if value.type not in (SHAPE, "error"):
                self.fail(arg.span, f"'{e.name}' combines shapes, this is {_TYPE_WORDS[value.type]}")
        if any(v.type == "error" for v in values):
            raise _Failed
        need = 2
        if len(values) < need:
            self.fail(e.span, f"'{e.name}' needs at least {need} shapes")
        if e.name == "subtract" and len(values) != 2:
            self.fail(e.span, f"'subtract' takes exactly 2 shapes (a with b cut away), not {len(values)}")
        (smooth,) = self.bound_args(e, signature, options)
        return self.shape(Combination(e.name, tuple(v.data for v in values), smooth, e.span))

    def math(self, e: ast.Call) -> Value:
        arity, mode = MATH[e.name]
        if any(a.name is not None for a in e.args):
            named = next(a for a in e.args if a.name is not None)
            self.fail(named.span, f"'{e.name}' takes positional arguments only")
        if len(e.args) != arity:
            self.fail(e.span, f"'{e.name}' takes {arity} argument{'s' if arity > 1 else ''}, not {len(e.args)}")
        values = [self.value_of(a.value) for a in e.args]
        if any(v.type == "error" for v in values):
            raise _Failed
        if mode == "map":
            return self.arithmetic(e, e.name, values)
        for arg, v in zip(e.args, values):
            if v.type not in ("vec2", "vec3", "vec4") or (mode.startswith("vec3") and v.type != "vec3"):
                want = "a 3-vector" if mode.startswith("vec3") else "a vector"
                self.fail(arg.span, f"'{e.name}' needs {want}, this is {_TYPE_WORDS[v.type]}")
        if len(values) == 2 and len(values[0].data) != len(values[1].data):
            self.fail(e.span, f"'{e.name}' on vectors of different sizes")
        try:
            return _vector_math(e.name, [v.data for v in values])
        except (ValueError, ZeroDivisionError):
            self.fail(e.span, f"'{e.name}' is undefined here (a zero vector?)")

    def field(self, e: ast.Field) -> Value:
        """`v.x`, `v.xy`: components of a vector."""
        receiver = self.value_of(e.receiver)
        if receiver.type == "error":
            raise _Failed
        if receiver.type not in ("vec2", "vec3", "vec4"):
            self.fail(e.span, f"'.{e.name}' takes components of a vector, this is {_TYPE_WORDS[receiver.type]}")
        names = "xyzw"[:len(receiver.data)]
        if len(e.name) > 4 or any(ch not in names for ch in e.name):
            self.fail(e.name_span, f"'.{e.name}' is not a component of {_TYPE_WORDS[receiver.type]} "
                                   f"(components: {', '.join(names)})")
        items = tuple(receiver.data.items[names.index(ch)] for ch in e.name)
        return Value(NUM, items[0]) if len(items) == 1 else Value(vec_type(len(items)), ir.Vec(items))

    def method(self, e: ast.Method) -> Value:
        if isinstance(e.receiver, ast.Name) and e.receiver.name == LIBRARY and not any(
                LIBRARY in names for names in (self.params, self.lets, self.material_decls)):
            return self.library_formula(e)
        receiver = self.value_of(e.receiver)
        if receiver.type == "error":
            raise _Failed
        signature = TRANSFORMS.get(e.name)
        if signature is None:
            self.fail(e.name_span, f"unknown transform '.{e.name}'{self.did_you_mean(e.name, TRANSFORMS)}")
        if receiver.type != SHAPE:
            self.fail(e.name_span, f"'.{e.name}' transforms a shape, this is {_TYPE_WORDS[receiver.type]}")
        args = self.bound_args(e, signature, e.args)
        if e.name == "material":
            return self.shape(WithMaterial(receiver.data, args[0], e.span))
        if e.name == "color" and isinstance(args[0], Coloring):
            coloring = args[0]
            return self.shape(WithMaterial(receiver.data, self.color_material(coloring.near), e.span,
                                             coloring))
        if e.name == "color":
            return self.shape(WithMaterial(receiver.data, self.color_material(args[0]), e.span))
        return self.shape(Transformed(e.name, receiver.data, args, e.span))

    def shape(self, shape: Shape) -> Value:
        """A shape value, counted: the kernel computes every part of the
        shape with each let expanded where it is used, so a let used twice
        in each of a chain of lets doubles it each time. Too many parts is
        an error at the part that passes the limit."""
        parts = shape.shapes if isinstance(shape, Combination) else \
            () if isinstance(shape, (Primitive, Fractal)) else (shape.shape,)
        size = 1
        for part in parts:
            size += self.shape_sizes[id(part)][1]
            if size > MAX_SHAPES:
                self.fail(part.span if len(parts) > 1 else shape.span,
                          f"the scene passes {MAX_SHAPES} parts (primitives, transforms, combinations, "
                          f"with each let counted where it is used) here: it would take minutes to compile. "
                          f"Repeat a regular array of copies with '.repeat(period)', or use fewer shapes")
        self.shape_sizes[id(shape)] = (shape, size)   # the shape kept alive: ids stay unique
        return Value(SHAPE, shape)

    def color_material(self, rgb: ir.Vec) -> str:
        """`.color(rgb)`: a material with the default's finish in that colour."""
        key = rgb.items
        if key not in self.colors:
            name = f"(color {len(self.colors)})"   # not a name a file can declare
            self.colors[key] = name
            self.materials[name] = replace(self.materials[DEFAULT_MATERIAL], name=name, color=rgb)
        return self.colors[key]

    # ---- blocks ------------------------------------------------------------

    def entries(self, block: ast.Block | None, keys: dict[str, Parameter], owner: str) -> dict:
        """Check a block's entries against `keys` (with types, defaults and
        constraints); unknown and duplicate keys are errors."""
        found: dict[str, object] = {}
        spans: dict[str, Span] = {}
        for entry in block.entries if block else ():
            if entry.key in spans:
                self.error(entry.key_span, f"'{entry.key}' is given twice in '{owner}'")
                continue
            spans[entry.key] = entry.key_span
            param = keys.get(entry.key)
            if param is None:
                hint = self.did_you_mean(entry.key, keys) or \
                    (f" (known: {', '.join(keys)})" if len(keys) <= len(RENDER_KEYS) else "")
                self.error(entry.key_span, f"'{owner}' has no key '{entry.key}'{hint}")
                continue
            nested = BLOCK_KEYS.get(param.type)
            if isinstance(entry.value, ast.Block) != bool(nested):
                self.error(entry.value.span, f"'{entry.key}' takes a block {{ ... }}" if nested
                           else f"'{entry.key}' takes a value, not a block")
                continue
            if nested:
                keys_type, defaults = nested
                values = self.entries(entry.value, keys_type, entry.key)
                found[entry.key] = replace(defaults, **values)
                continue
            if isinstance(entry.value, ast.String) != (param.type == "file"):
                self.error(entry.value.span, f"'{entry.key}' takes a file name in quotes, such as \"sky.exr\""
                           if param.type == "file" else f"'{entry.key}' takes a value, not a string "
                                                        f"(strings are file names: environment's 'map')")
                continue
            try:
                found[entry.key] = self.file(entry.value) if param.type == "file" \
                    else self.entry_value(entry, param, owner)
            except _Failed:
                pass
        return found

    def file(self, name: ast.String) -> str:
        """The absolute path of the image file a string names, relative to
        the scene file's folder, once it reads (it is read on the host: the
        path never reaches the kernel's source)."""
        for index, character in enumerate(name.value):
            if ord(character) < 32 or ord(character) == 127:
                column = name.span.column + 1 + index
                self.fail(Span(name.span.line, column, name.span.line, column + 1),
                          f"a control character (code {ord(character)}) in a string")
        if not name.value:
            self.fail(name.span, "an empty file name")
        path = os.path.abspath(os.path.join(os.path.dirname(self.program.file), name.value))
        try:
            pathtrace.environment_map(path)
        except ValueError as error:
            self.fail(name.span, str(error))
        return path

    def entry_value(self, entry: ast.Entry, param: Parameter, owner: str):
        value = self._evaluate(entry.value)
        if param.type.startswith("word:"):
            choices = param.type[5:].split("|")
            other = _word_alternative(choices)     # a number or a vector where no word is given
            if value.type == WORD and value.data in choices:
                return value.data
            if not (other and value.type == _WORD_ALTERNATIVES[other]):
                listed = " or ".join(f"'{c}'" if c not in _WORD_ALTERNATIVES
                                     else _TYPE_WORDS[_WORD_ALTERNATIVES[c]] for c in choices)
                self.fail(entry.value.span, f"'{entry.key}' must be {listed}")
            param = _P(param.name, other, None, *param.constraints)
        data = self.convert(entry.value.span, value, param, owner)
        if owner == "material":
            return data
        items = data.items if isinstance(data, ir.Vec) else (data,)
        if not all(isinstance(x, ir.Const) for x in items):
            self.fail(entry.value.span, f"'{entry.key}' must be a constant (it depends on a param)")
        values = tuple(x.value for x in items)
        return values if isinstance(data, ir.Vec) else (int(values[0]) if param.type == "int" else values[0])

    def material(self, decl: ast.MaterialDecl) -> Material:
        found = self.entries(decl.block, MATERIAL_KEYS, "material")
        default = self.materials[DEFAULT_MATERIAL]
        return Material(decl.name, found.get("color", default.color),
                        found.get("specular", default.specular),
                        found.get("shininess", default.shininess),
                        found.get("reflectivity", default.reflectivity),
                        found.get("transparency", default.transparency),
                        found.get("ior", default.ior))

    def camera(self, decl: ast.CameraDecl | None) -> Camera:
        errors_before = len(self.errors)
        found = self.entries(decl.block if decl else None, CAMERA_KEYS, "camera")
        camera = Camera(**found)
        forward = [t - p for t, p in zip(camera.target, camera.position)]
        if len(self.errors) > errors_before:
            return camera
        if _norm(forward) == 0:
            where = next((x.value.span for x in decl.block.entries if x.key == "target"), decl.span)
            self.error(where, "the camera's target is its position: it looks nowhere")
        elif _norm(_cross(forward, camera.up)) <= 1e-9 * _norm(forward) * _norm(camera.up):
            entry = next((x for x in decl.block.entries if x.key == "up"), None)
            if entry is None:   # looking straight along the default up: y is up instead
                return replace(camera, up=(0.0, 1.0, 0.0))
            self.error(entry.value.span, "the camera's 'up' is parallel to its view direction (target - position)")
        return camera

    def light(self, decl: ast.LightDecl) -> Light | None:
        keys = LIGHT_KEYS.get(decl.kind)
        if keys is None:
            self.error(decl.kind_span, f"unknown light kind '{decl.kind}' (known: {', '.join(LIGHT_KEYS)})")
            return None
        errors_before = len(self.errors)
        found = self.entries(decl.block, keys, "light")
        vector_key = light_vector_key(decl.kind)
        given = {e.key: e for e in decl.block.entries}
        aimed = "target" in keys         # a spot or rectangle light: `direction` or `target`, as a camera
        if aimed and "direction" in given and "target" in given:
            second = max(given["direction"], given["target"], key=lambda e: (e.span.line, e.span.column))
            self.error(second.key_span, f"a {decl.kind} light takes 'direction' or 'target', not both")
        needed = (vector_key, "direction") if aimed else (vector_key,)
        for key in needed:
            if key not in given and not (key == "direction" and "target" in given):
                self.error(decl.span, f"a {decl.kind} light needs '{key}'"
                                      + (" (or 'target', the point it faces)" if key == "direction" else ""))
        if len(self.errors) > errors_before:
            return None
        vector = found.pop(vector_key)
        if aimed and "target" in found:
            target = found.pop("target")
            found["direction"] = tuple(t - p for t, p in zip(target, vector))
            if not any(found["direction"]):
                self.error(given["target"].value.span, f"the {decl.kind} light's target is its position: "
                                                        f"it faces nowhere")
                return None
        if decl.kind in ("sphere", "rectangle"):    # the direct renderer's stand-in for their soft shadows
            found.setdefault("shadows", "soft")
        return Light(decl.kind, vector, **found)

    def render(self, decl: ast.RenderDecl | None) -> RenderSettings:
        found = self.entries(decl.block if decl else None, RENDER_KEYS, "render")
        environment = found.get("environment")
        if environment is not None and environment.map is not None:   # the one place a map is kept
            found.update(environment=replace(environment, map=None), environment_map=environment.map)
        return RenderSettings(**found)

    def path(self, decl: ast.PathDecl | None) -> CameraPath | None:
        """Keyframes take the camera's keys (constants, checked the same way)
        and values of params (in the params' ranges); a camera key wins over
        a param of the same name."""
        if decl is None:
            return None
        # the camera keys a path animates (a projection and stereo layout are the block's)
        animated = [key for key in CAMERA_KEYS if key in Keyframe.__dataclass_fields__]
        keys = {key: CAMERA_KEYS[key] for key in animated}
        for name, key in self.param_keys().items():
            keys.setdefault(name, key)
        keyframes = []
        for before, frame in zip((None,) + decl.keyframes, decl.keyframes):
            if not in_float_range(frame.time):
                self.error(frame.time_span, f"{_source_text(self.program, frame.time_span)} is too large a time")
            elif before is not None and frame.time <= before.time:
                self.error(frame.time_span, f"keyframe times must increase: {frame.time:g} does not come after "
                                            f"{before.time:g} (line {before.span.line})")
            found = self.entries(frame.block, keys, "path")
            camera = {key: found.pop(key) for key in animated if key in found}
            if "position" not in camera:
                if not any(e.key == "position" for e in frame.block.entries):
                    self.error(frame.time_span, f"the keyframe at {frame.time:g} needs a 'position'")
                continue
            if camera.get("target") == camera["position"]:
                where = next(e.value.span for e in frame.block.entries if e.key == "target")
                self.error(where, "the keyframe's target is its position: it looks nowhere")
            keyframes.append(Keyframe(frame.time, **camera, params=tuple(found.items())))
        if len(decl.keyframes) < 2:
            self.error(decl.span, f"a path needs at least two keyframes, this one has {len(decl.keyframes)}")
        return CameraPath(tuple(keyframes), decl.span)

    def param_keys(self) -> dict[str, Parameter]:
        """The params as block keys (a path's keyframes, presets): a
        constant number in the param's range."""
        keys = {}
        for name, info in self.params.items():
            in_range = (f"{info.low!r}..{info.high!r}",) if None not in (info.low, info.high) else ()
            keys[name] = _P(name, "num", None, *in_range)
        return keys

    def presets(self, decls: list[ast.PresetDecl]) -> tuple[Preset, ...]:
        """Each `preset NAME { param: value, ... }`: constant values of
        params, in their ranges; one preset of each name."""
        keys, found = self.param_keys(), {}
        for decl in decls:
            if decl.name in found:
                first = found[decl.name].span
                self.error(decl.name_span, f"a second preset '{decl.name}' (the first is at line {first.line})")
                continue
            values = self.entries(decl.block, keys, "preset")
            found[decl.name] = Preset(decl.name, tuple(values.items()), decl.span)
        return tuple(found.values())


def _source_text(program: ast.Program, span: Span) -> str:
    """The text of a one-line span (a number as the user wrote it)."""
    lines = program.source.splitlines()
    if span.line != span.end_line or not 0 < span.line <= len(lines):
        return "this"
    return lines[span.line - 1][span.column - 1:span.end_column - 1]


def _given_scale(scale):
    """An orbit trap's scale, or None for the default: spread over the trap's range."""
    return None if scale == AUTO_SCALE else scale


def _default(p: Parameter):
    if isinstance(p.default, str):
        return p.default
    if isinstance(p.default, tuple):
        return ir.Vec(tuple(ir.const(x) for x in p.default))
    if p.type == "size":
        return ir.vec(*(ir.const(p.default),) * 3)
    return ir.const(p.default)


def _norm(v) -> float:
    return math.sqrt(sum(x * x for x in v))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _vector_math(name: str, vectors: list[ir.Vec]) -> Value:
    a = vectors[0].items

    def dot(u, v):
        total = ir.mul(u[0], v[0])
        for x, y in zip(u[1:], v[1:]):
            total = ir.add(total, ir.mul(x, y))
        return total

    if name == "length":
        return Value(NUM, ir.op("sqrt", dot(a, a)))
    if name == "dot":
        return Value(NUM, dot(a, vectors[1].items))
    if name == "normalize":
        length = ir.op("sqrt", dot(a, a))
        return Value(vec_type(len(a)), ir.Vec(tuple(ir.div(x, length) for x in a)))
    b = vectors[1].items
    return Value("vec3", ir.vec(ir.sub(ir.mul(a[1], b[2]), ir.mul(a[2], b[1])),
                                ir.sub(ir.mul(a[2], b[0]), ir.mul(a[0], b[2])),
                                ir.sub(ir.mul(a[0], b[1]), ir.mul(a[1], b[0]))))


_WORD_ALTERNATIVES = {"num": NUM, "vec3": "vec3"}   # parameter type: its values' type


def _word_alternative(choices) -> str | None:
    """The type a `word:...|num` or `word:...|vec3` key takes besides its words."""
    return next((c for c in choices if c in _WORD_ALTERNATIVES), None)


def _keys(*params: Parameter) -> dict[str, Parameter]:
    return {p.name: p for p in params}


def _P(name: str, type_: str, default=None, *constraints: str) -> Parameter:
    return Parameter(name, type_, default, constraints)


MATERIAL_KEYS = _keys(_P("color", "vec3", None, "0..1000"), _P("specular", "num", None, "0..1"),
                      _P("shininess", "num", None, ">0"), _P("reflectivity", "num", None, "0..1"),
                      _P("transparency", "num", None, "0..1"), _P("ior", "num", None, "1..10"))
CAMERA_KEYS = _keys(_P("position", "vec3"), _P("target", "vec3"), _P("up", "vec3", None, "nonzero"),
                    _P("fov", "num", None, ">0", "<180"), _P("aperture", "num", None, ">=0"),
                    _P("focus", "num", None, ">0"), _P("projection", f"word:{'|'.join(PROJECTIONS)}"),
                    _P("fisheye_fov", "num", None, ">0", "<=360"),
                    _P("stereo", f"word:{'|'.join(STEREO_LAYOUTS)}"), _P("eye_separation", "num", None, ">=0"))
_LIGHT_COMMON = (_P("color", "vec3", None, ">=0"), _P("intensity", "num", None, ">=0"),
                 _P("shadows", "word:none|hard|soft"), _P("softness", "num", None, ">0"))
LIGHT_KEYS = {"directional": _keys(_P("direction", "vec3", None, "nonzero"), *_LIGHT_COMMON),
              "point": _keys(_P("position", "vec3"), *_LIGHT_COMMON),
              "spot": _keys(_P("position", "vec3"), _P("direction", "vec3", None, "nonzero"), _P("target", "vec3"),
                            *_LIGHT_COMMON, _P("angle", "num", None, ">0", "<180"),
                            _P("falloff", "num", None, ">=0", "<=180")),
              "sphere": _keys(_P("position", "vec3"), _P("radius", "num", None, ">0"), *_LIGHT_COMMON),
              "rectangle": _keys(_P("position", "vec3"), _P("direction", "vec3", None, "nonzero"),
                                 _P("target", "vec3"), _P("width", "num", None, ">0"), _P("height", "num", None, ">0"),
                                 *_LIGHT_COMMON)}
BLOCK_KEYS = {
    "block:glow": (_keys(_P("color", "vec3", None, ">=0"), _P("strength", "num", None, ">=0"),
                         _P("radius", "num", None, ">0")), Glow()),
    "block:fog": (_keys(_P("color", "vec3", None, ">=0"), _P("density", "num", None, ">=0")), Fog()),
    "block:slice": (_keys(_P("normal", "vec3", None, "nonzero"), _P("offset", "num")), Slice()),
    "block:environment": (_keys(_P("zenith", "vec3", None, ">=0"), _P("horizon", "vec3", None, ">=0"),
                                _P("ground", "vec3", None, ">=0"), _P("intensity", "num", None, ">=0"),
                                _P("map", "file")),
                          Environment()),
}
RENDER_KEYS = _keys(
    _P("width", "int", None, ">=1", "<=65536"), _P("height", "int", None, ">=1", "<=65536"),
    _P("max_steps", "int", None, "1..100000"), _P("max_distance", "num", None, ">0"),
    _P("epsilon", "word:pixel|num", None, ">0"), _P("ao", "num", None, "0..1"),
    _P("samples", "int", None, ">=1", "<=4096"), _P("background", "word:transparent|vec3", None, ">=0"),
    _P("precision", "word:float|double"), _P("reflections", "int", None, "0..16"),
    _P("glow", "block:glow"), _P("fog", "block:fog"), _P("slice", "block:slice"),
    _P("ao_method", "word:normal|steps"), _P("dither", "num", None, "0..1"),
    _P("overrelax", "num", None, "1..1.99"), _P("cone_marching", "word:on|off"),
    _P("epsilon_scale", "num", None, ">0", f"<={MAX_EPSILON_SCALE:g}"),
    _P("normals", "word:tetrahedral|central|forward"), _P("fast_math", "word:auto|on|off"),
    _P("exposure", "num", None, "-20..20"), _P("tonemap", "word:" + "|".join(TONE_CURVES)),
    _P("integrator", "word:direct|path"), _P("bounces", "int", None, "1..64"),
    _P("environment", "block:environment"))


# The vector keys that are colours (r, g, b): what a colour picker sets.
COLOUR_KEYS = frozenset({"color", "background", "zenith", "horizon", "ground"})


class KeyKind(Enum):
    """What a block key takes (besides the words it names)."""
    NUMBER = "number"
    WHOLE = "whole number"
    VECTOR = "3-vector"
    WORD = "word"           # one of its words only
    BLOCK = "block"         # a block of keys of its own
    FILE = "file"           # a file name in quotes


@dataclass(frozen=True)
class KeySpec:
    """A key of a block as an editor's control sees it (`key_specs`)."""
    name: str
    kind: KeyKind
    words: tuple[str, ...] = ()     # the words it takes
    low: float | None = None        # its range, None: open on that side
    high: float | None = None
    low_excluded: bool = False      # `> low` rather than `>= low`
    high_excluded: bool = False
    colour: bool = False            # an (r, g, b) colour
    keys: tuple["KeySpec", ...] = ()   # a block's keys


def key_specs(block: str) -> tuple[KeySpec, ...]:
    """The keys of a block, their types and ranges from the checker's own
    tables: `block` is "render", "camera", "material" or "light KIND"."""
    kind, _, light = block.partition(" ")
    tables = {"render": RENDER_KEYS, "camera": CAMERA_KEYS, "material": MATERIAL_KEYS}
    keys = LIGHT_KEYS.get(light) if kind == "light" else tables.get(block)
    if keys is None:
        raise ValueError(f"no block '{block}' (blocks: {', '.join(tables)}, light {'|'.join(LIGHT_KEYS)})")
    return tuple(_key_spec(parameter) for parameter in keys.values())


def _key_spec(parameter: Parameter) -> KeySpec:
    if parameter.type in BLOCK_KEYS:
        nested = BLOCK_KEYS[parameter.type][0]
        return KeySpec(parameter.name, KeyKind.BLOCK, keys=tuple(_key_spec(p) for p in nested.values()))
    if parameter.type == "file":
        return KeySpec(parameter.name, KeyKind.FILE)
    words, other = (), parameter.type
    if parameter.type.startswith("word:"):
        words = tuple(c for c in parameter.type[5:].split("|") if c not in _WORD_ALTERNATIVES)
        other = _word_alternative(parameter.type[5:].split("|"))
    kind = {None: KeyKind.WORD, "int": KeyKind.WHOLE, "vec3": KeyKind.VECTOR}.get(other, KeyKind.NUMBER)
    bounds: dict = {}
    for c in parameter.constraints:
        if ".." in c:
            bounds["low"], bounds["high"] = (float(x) for x in c.split(".."))
        elif c[0] in "<>" and not c.lstrip("<>=")[:1].isalpha():    # not a bound by another argument
            side = "low" if c[0] == ">" else "high"
            bounds[side] = float(c.lstrip("<>="))
            bounds[f"{side}_excluded"] = c[1] != "="
    return KeySpec(parameter.name, kind, words, colour=kind is KeyKind.VECTOR and parameter.name in COLOUR_KEYS,
                   **bounds)


# `fractal(formula, ...)`: the shape of a formula (docs/formulas.md). The
# bailout, julia and bound are optional (the bailout's default depends on
# the estimate's kind: formula_code.orbit).
FORMULA_FORMS = {
    "fractal": Signature("fractal", "fractal", (
        _P("formula", "formula"), _P("iterations", "int", 12.0, "1..1000"), _P("bailout", "num", 0.0, ">0"),
        _P("julia", "vec3", 0.0), _P("bound", "num", 0.0, ">0"), _P("step", "num", 1.0, ">0", "<=1"))),
    "hybrid": Signature("fractal", "hybrid", ()),
}
# `library.NAME(...)` names the library's formula NAME (unless the file
# declares a value called `library`)
LIBRARY = "library"

@lru_cache(maxsize=1)
def library_formulas() -> tuple[tuple[str, tuple], ...]:
    """The formulas of the library (stdlib_frac/*.frac), checked: every
    scene can use them; a file's own formula of the same name replaces one."""
    found = []
    for path in sorted(resource_dir("stdlib_frac").glob("*.frac")):
        program = parse(path.read_text(), str(path))
        checker = _Checker(program, with_library=False)
        for decl in program.decls:
            checker.declare_formula(decl)
        if checker.errors:
            raise SceneError(checker.errors)
        found.extend(checker.formulas.items())
    return tuple(found)


def closest_name(name: str, known) -> str | None:
    """The name among `known` closest to a misspelt `name`, if one is close."""
    close = difflib.get_close_matches(name, known, n=1)
    return close[0] if close else None


def unknown_param(name: str, scene: CheckedScene) -> str | None:
    """What is wrong with setting the param `name` of `scene`: None if the
    scene declares it, else that it does not, with the closest name or the
    names it has."""
    known = [p.name for p in scene.params]
    if name in known:
        return None
    close = closest_name(name, known)
    hint = f"; did you mean '{close}'?" if close else f" (its params: {', '.join(known)})" if known else \
        " (it declares none)"
    return f"the scene has no param '{name}'{hint}"


def check(program: ast.Program) -> CheckedScene:
    """Check a parsed program; raise `SceneError` listing every error."""
    return _Checker(program).run()


def _number_text(number: float) -> str:
    """A number in a message: whole numbers in full (4294967295, not 4.29497e+09)."""
    return str(int(number)) if number.is_integer() and abs(number) < 1e16 else f"{number:g}"


def check_value(param: Parameter, key: str, value, subject: str | None = None):
    """Validate a render setting given from Python or the command line
    (type and range, as in a file); raise ValueError saying what is wrong,
    of `subject` (default: `'key' of 'render'`; '': none). A number is a
    Python or numpy number, never a string or a bool."""
    checker = _Checker(ast.Program((), "<arguments>", ""))
    named = repr(key) if subject is None else subject

    def wrong(says: str) -> ValueError:
        return ValueError(f"{named} {says}".lstrip())
    if param.type == "file":
        if value is not None:
            raise ValueError(f"'{key}' is a scene file's key: from Python give environment_map=FILE "
                             f"(on the command line, --environment-map FILE)")
        return None
    if param.type in BLOCK_KEYS:
        keys, defaults = BLOCK_KEYS[param.type]
        if value is False:
            return None                                  # the effect off
        if isinstance(value, type(defaults)):
            value = {f: getattr(value, f) for f in keys}
        if not isinstance(value, dict):
            raise wrong(f"must be a dict of {', '.join(keys)} (or False for off)")
        unknown = set(value) - set(keys)
        if unknown:
            raise wrong(f"has no key '{sorted(unknown)[0]}' (known: {', '.join(keys)})")
        return replace(defaults, **{k: check_value(keys[k], f"{key}.{k}", v) for k, v in value.items()})
    choices = param.type[5:].split("|") if param.type.startswith("word:") else ()
    if isinstance(value, str) and value in choices:
        return value
    other = _word_alternative(choices) if choices else param.type
    if other is None:
        raise wrong(f"must be {' or '.join(repr(c) for c in choices)}, not {value!r}")
    is_vector = other == "vec3"
    try:
        numbers = tuple(value) if is_vector else (value,)
        if any(isinstance(x, (str, bytes, bool)) for x in numbers):
            raise TypeError
        items = tuple(float(x) for x in numbers)
    except (TypeError, ValueError, OverflowError):
        raise wrong(f"must be {_TYPE_WORDS['vec3' if is_vector else NUM]}, not {value!r}") from None
    if is_vector and len(items) != 3:
        raise wrong(f"must have 3 components, not {len(items)}")
    if not all(in_float_range(x) for x in items):
        raise wrong(f"must be finite (within ±{FLOAT_MAX:.3g}), not {value!r}")
    data = ir.Vec(tuple(ir.const(x) for x in items)) if is_vector else ir.const(items[0])
    numeric = param if not choices else _P(param.name, other, None, *param.constraints)
    try:
        checker.check_constraints(Span(1, 1, 1, 2), data, numeric, "render", subject=subject)
    except _Failed:
        raise ValueError(checker.errors[0].message) from None
    if is_vector:
        return items
    return int(items[0]) if param.type == "int" else items[0]


def check_param_values(scene: CheckedScene, values) -> None:
    """Check every value that depends on params, for these param values;
    raise SceneError at each value's span that is out of its range."""
    checker = _Checker(ast.Program((), scene.file, scene.source))
    # checks between arguments last, and only if each argument is valid alone
    for check_ in sorted(scene.param_checks, key=lambda c: bool(c.others)):
        if check_.others and checker.errors:
            break
        items = check_.value.items if isinstance(check_.value, ir.Vec) else (check_.value,)
        try:
            constants = tuple(ir.const(ir.evaluate(x, values)) for x in items)
        except (ValueError, ZeroDivisionError, OverflowError):
            checker.error(check_.span, f"'{check_.parameter.name}' of '{check_.owner}' is undefined "
                                       f"for these param values")
            continue
        data = ir.Vec(constants) if isinstance(check_.value, ir.Vec) else constants[0]
        others = {k: ir.evaluate(v, values) for k, v in check_.others.items()}
        shown = ", ".join(f"{p.name} = {v:g}" for p, v in zip(scene.params, values))
        try:
            checker.check_constraints(check_.span, data, check_.parameter, check_.owner, others)
        except _Failed:
            last = checker.errors.pop()
            checker.error(check_.span, f"{last.message} (with {shown})")
    if checker.errors:
        raise SceneError(checker.errors)
