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
from .formula_statements import Formula, split
from .formula_values import Mistake
from .program import (CAMERA_KEYS, DEFAULT_MATERIAL, LIGHT_KEYS, MATERIAL_KEYS, RENDER_KEYS, Camera, CameraPath,
                      CheckedScene, Coloring, Combination, CombinationKind, Fractal, Keyframe, Light, LightKind,
                      Material, ParamCheck, ParamInfo, Preset, Primitive, RenderSettings, Shadows, Shape,
                      Transformed, WithMaterial, cosine_palette, default_material, light_vector_key)
from .parse import parse
from .resources import resource_dir
from .stdlib import AUTO_SCALE, COLORINGS, COMBINATORS, MATH, TRANSFORMS, Signature, library
from .types import (FLOAT_MAX, TYPE_WORDS, VECTOR_TYPES, Parameter, Type, above, at_most, between, in_float_range,
                    keys_of, range_violation, vector_type)

NUM, SHAPE, MATERIAL, WORD, COLORING, FORMULA = Type.NUMBER, Type.SHAPE, Type.MATERIAL, Type.WORD, Type.COLORING, \
    Type.FORMULA


@dataclass(frozen=True)
class Value:
    type: Type
    data: object       # ir.Expr | ir.Vec | Shape | material name | word


_ERROR = Value(Type.ERROR, None)

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
# Errors that get a "did you mean" (each costs time in the number of known names)
SUGGESTED_ERRORS = 10


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
        self.library_formulas: dict[str, tuple[Formula, Signature]] = \
            dict(library_formulas() if with_library else ())
        self.formulas: dict[str, tuple[Formula, Signature] | None] = dict(self.library_formulas)
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
        self.materials[DEFAULT_MATERIAL] = default_material()
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
            if value.type not in (SHAPE, Type.ERROR):
                hint = " (make it one with 'fractal(formula(...), iterations: N)')" if value.type == FORMULA else ""
                self.error(scene.shape.span, f"'scene' needs a shape, this is {TYPE_WORDS[value.type]}{hint}")
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
        info = ParamInfo(decl.name, len(self.params), default or 0.0, low, high, decl.span)
        if None not in (low, high, default) and low <= high and info.range_violation(default):
            self.error(decl.default.span, info.range_violation(default))
        self.params[decl.name] = info

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
            if value.type not in (NUM, Type.VEC3, Type.VEC4) or not all(ir.is_const(x) for x in items):
                if value.type != Type.ERROR:
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
                outside = range_violation(param.name, items[0].value, low, high)
                if outside:
                    self.error(param.default.span, outside)
                    return
                constraints = (between(low, high),)
            default = items[0].value if value.type == NUM else tuple(x.value for x in items)
            parameters.append(Parameter(param.name, value.type, default, constraints))
            defaults.append(value.data)
        try:
            formula = split(decl, self.program.file)
            formula_code.orbit((formula_code.Use(formula, tuple(defaults)),), formula_code.POINT, ir.const(2.0))
        except Mistake as mistake:
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
            if value.type == Type.ERROR:
                raise _Failed
            if value.type != FORMULA:
                self.fail(arg.span, f"'hybrid' takes formulas (e.g. hybrid(bulb(8) * 2, amazing_box())), "
                                    f"this is {TYPE_WORDS[value.type]}")
            sequence.extend(value.data)
            self.require_hybrid_steps(sequence, arg.span)
        if not sequence:
            self.fail(e.span, "'hybrid' needs at least one formula")
        sizes = {}                     # 3 or 4 -> the first formula whose z has that many components
        for use in sequence:
            try:
                size = formula_code.z_size(use, formula_code.POINT)
            except Mistake:
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
                              f"with {TYPE_WORDS[count.type]}")
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
        if formula.type == Type.ERROR:
            raise _Failed
        if formula.type != FORMULA:
            if formula.type == WORD:
                self.unknown_name(bound["formula"][0].value.span, formula.data)
            self.fail(bound["formula"][0].value.span, f"'fractal' needs a formula (declared with 'formula "
                                                      f"name(...) {{ ... }}'), this is {TYPE_WORDS[formula.type]}")
        values = {}
        for p in FORMULA_FORMS["fractal"].parameters[1:]:
            if p.name not in bound:
                values[p.name] = _default(p) if p.name in ("iterations", "step") else None
                continue
            arg, value = bound[p.name]
            if p.name == "julia" and value.type == Type.VEC4:
                p = replace(p, type=Type.VEC4)
            values[p.name] = self.convert(arg.value.span, value, p, "fractal")
        # the estimate's kind from |z|'s growth at the params' defaults and range ends
        params = tuple(self.params.values())
        param_values = tuple(tuple(p.default if value is None else value for p, value in zip(params, chosen))
                             for chosen in ([None] * len(params), [p.low for p in params], [p.high for p in params]))
        try:
            growth = formula_code.growth(formula.data, values["julia"], param_values)
            formula_code.orbit(formula.data, formula_code.POINT, ir.const(2.0), values["bailout"], values["julia"],
                               where=e.span, estimate=growth.estimate)
        except Mistake as mistake:
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
        if value.type == Type.ERROR:
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
            if any(v.type == Type.ERROR for v in items):
                return _ERROR
            for item, v in zip(e.items, items):
                if v.type != NUM:
                    self.fail(item.span, f"a vector's components must be numbers, this is {TYPE_WORDS[v.type]}")
            if len(items) > 4:
                self.fail(e.span, f"vectors have 2 to 4 components, this one has {len(items)}")
            return Value(vector_type(len(items)), ir.Vec(tuple(v.data for v in items)))
        if isinstance(e, ast.Unary):
            operand = self._evaluate(e.operand)
            if operand.type == Type.ERROR:
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
        if Type.ERROR in (left.type, right.type):
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
            return self.shape(Combination(CombinationKind.SUBTRACT, (left.data, right.data), ir.const(0.0), e.span))
        if SHAPE in (left.type, right.type):
            other = right if left.type == SHAPE else left
            self.fail(e.span, f"'{e.op}' needs two shapes or two numbers/vectors, not a shape and {TYPE_WORDS[other.type]}")
        return self.arithmetic(e, e.op, [left, right])

    def chain(self, e: ast.Chain) -> Value:
        """`a | b | ...` (a union) or `a & b & ...` (an intersection) of shapes:
        one combination of them all, as union(...) and intersect(...) are."""
        shapes = []
        for operand in e.operands:
            value = self.value_of(operand)
            if value.type == Type.ERROR:
                raise _Failed
            if value.type != SHAPE:
                self.fail(operand.span, "this is a formula: make it a shape with 'fractal(formula(...), iterations: N)'"
                          if value.type == FORMULA else
                          f"'{e.op}' combines shapes ({'union' if e.op == '|' else 'intersection'}), "
                          f"this is {TYPE_WORDS[value.type]}")
            shapes.append(value.data)
        return self.shape(Combination(CombinationKind.UNION if e.op == "|" else CombinationKind.INTERSECT, tuple(shapes), ir.const(0.0), e.span))

    def arithmetic(self, e, op: str, operands: list[Value], mode: str = "map") -> Value:
        """Component-wise arithmetic on numbers and vectors; numbers broadcast."""
        for operand in operands:
            if operand.type not in (NUM, *VECTOR_TYPES):
                self.fail(e.span, f"'{op}' needs numbers or vectors, not {TYPE_WORDS[operand.type]}")
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
        return Value(vector_type(size), ir.Vec(items))

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
        if value.type == Type.ERROR:
            raise _Failed
        want = param.type
        if want is Type.WORD:
            if value.type == WORD and value.data in param.words:
                return param.word(value.data)
            self.fail(span, f"'{param.name}' of '{owner}' must be one of {', '.join(param.words)}")
        if want is Type.COLOR and value.type == COLORING:
            return value.data
        if value.type not in _ACCEPTED[want]:
            word = TYPE_WORDS.get(want)
            if value.type == WORD and want is not Type.MATERIAL:
                self.unknown_name(span, value.data)
            if value.type == WORD:
                hint = self.did_you_mean(value.data, self.material_decls)
                self.fail(span, f"unknown material '{value.data}'{hint}")
            self.fail(span, f"'{param.name}' of '{owner}' needs {word}, this is {TYPE_WORDS[value.type]}")
        data = value.data
        if want is Type.SIZE and value.type == NUM:
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
            if (param.constraints or param.type is Type.WHOLE) and others is None:
                self.param_checks.append(ParamCheck(span, data, param, owner))
            return   # depends on a param: checked for each set of param values
        says = param.violation([x.value for x in items], others)
        if says:
            self.fail(span, f"{subject} {says}".lstrip())

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
            related = tuple(c for c in p.constraints if getattr(c, "relative", False))
            if not related or p.name not in scalars:
                continue
            relation = replace(p, constraints=related)
            span = bound[p.name][0].value.span if p.name in bound else e.span
            others = {c.limit: scalars[c.limit] for c in related if c.limit in scalars}
            if all(ir.is_const(x) for x in (scalars[p.name], *others.values())):
                self.check_constraints(span, scalars[p.name], relation, signature.name,
                                       {k: v.value for k, v in others.items()})
            else:
                self.param_checks.append(ParamCheck(span, scalars[p.name], relation, signature.name, others))
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
            if value.type not in (SHAPE, Type.ERROR):
                self.fail(arg.span, f"'{e.name}' combines shapes, this is {TYPE_WORDS[value.type]}")
        if any(v.type == Type.ERROR for v in values):
            raise _Failed
        need = 2
        if len(values) < need:
            self.fail(e.span, f"'{e.name}' needs at least {need} shapes")
        if e.name == "subtract" and len(values) != 2:
            self.fail(e.span, f"'subtract' takes exactly 2 shapes (a with b cut away), not {len(values)}")
        (smooth,) = self.bound_args(e, signature, options)
        return self.shape(Combination(CombinationKind(e.name), tuple(v.data for v in values), smooth, e.span))

    def math(self, e: ast.Call) -> Value:
        function = MATH[e.name]
        arity = len(function.arguments)
        if any(a.name is not None for a in e.args):
            named = next(a for a in e.args if a.name is not None)
            self.fail(named.span, f"'{e.name}' takes positional arguments only")
        if len(e.args) != arity:
            self.fail(e.span, f"'{e.name}' takes {arity} argument{'s' if arity > 1 else ''}, not {len(e.args)}")
        values = [self.value_of(a.value) for a in e.args]
        if any(v.type == Type.ERROR for v in values):
            raise _Failed
        if function.per_component:
            return self.arithmetic(e, e.name, values)
        for arg, want, v in zip(e.args, function.arguments, values):
            if v.type not in VECTOR_TYPES or (want == "3" and v.type != Type.VEC3):
                self.fail(arg.span, f"'{e.name}' needs {'a 3-vector' if want == '3' else 'a vector'}, "
                                    f"this is {TYPE_WORDS[v.type]}")
        if len(values) == 2 and len(values[0].data) != len(values[1].data):
            self.fail(e.span, f"'{e.name}' on vectors of different sizes")
        try:
            return _vector_math(e.name, [v.data for v in values])
        except (ValueError, ZeroDivisionError):
            self.fail(e.span, f"'{e.name}' is undefined here (a zero vector?)")

    def field(self, e: ast.Field) -> Value:
        """`v.x`, `v.xy`: components of a vector."""
        receiver = self.value_of(e.receiver)
        if receiver.type == Type.ERROR:
            raise _Failed
        if receiver.type not in VECTOR_TYPES:
            self.fail(e.span, f"'.{e.name}' takes components of a vector, this is {TYPE_WORDS[receiver.type]}")
        names = "xyzw"[:len(receiver.data)]
        if len(e.name) > 4 or any(ch not in names for ch in e.name):
            self.fail(e.name_span, f"'.{e.name}' is not a component of {TYPE_WORDS[receiver.type]} "
                                   f"(components: {', '.join(names)})")
        items = tuple(receiver.data.items[names.index(ch)] for ch in e.name)
        return Value(NUM, items[0]) if len(items) == 1 else Value(vector_type(len(items)), ir.Vec(items))

    def method(self, e: ast.Method) -> Value:
        if isinstance(e.receiver, ast.Name) and e.receiver.name == LIBRARY and not any(
                LIBRARY in names for names in (self.params, self.lets, self.material_decls)):
            return self.library_formula(e)
        receiver = self.value_of(e.receiver)
        if receiver.type == Type.ERROR:
            raise _Failed
        signature = TRANSFORMS.get(e.name)
        if signature is None:
            self.fail(e.name_span, f"unknown transform '.{e.name}'{self.did_you_mean(e.name, TRANSFORMS)}")
        if receiver.type != SHAPE:
            self.fail(e.name_span, f"'.{e.name}' transforms a shape, this is {TYPE_WORDS[receiver.type]}")
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
            nested = param.type is Type.BLOCK
            if isinstance(entry.value, ast.Block) != nested:
                self.error(entry.value.span, f"'{entry.key}' takes a block {{ ... }}" if nested
                           else f"'{entry.key}' takes a value, not a block")
                continue
            if nested:
                values = self.entries(entry.value, keys_of(param.block), entry.key)
                found[entry.key] = param.block(**values)
                continue
            is_file = param.type is Type.FILE
            if isinstance(entry.value, ast.String) != is_file:
                self.error(entry.value.span, f"'{entry.key}' takes a file name in quotes, such as \"sky.exr\""
                           if is_file else f"'{entry.key}' takes a value, not a string "
                                           f"(strings are file names: environment's 'map')")
                continue
            try:
                found[entry.key] = self.file(entry.value) if is_file else self.entry_value(entry, param, owner)
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
        if param.words:
            if value.type == WORD and value.data in param.words:
                return param.word(value.data)
            if param.type is Type.WORD or value.type != param.type:   # not the value given instead of a word
                listed = " or ".join([f"'{c}'" for c in param.words] + [TYPE_WORDS[param.type]] * (
                    param.type is not Type.WORD))
                self.fail(entry.value.span, f"'{entry.key}' must be {listed}")
        data = self.convert(entry.value.span, value, param, owner)
        if owner == "material":
            return data
        items = data.items if isinstance(data, ir.Vec) else (data,)
        if not all(isinstance(x, ir.Const) for x in items):
            self.fail(entry.value.span, f"'{entry.key}' must be a constant (it depends on a param)")
        values = tuple(x.value for x in items)
        return values if isinstance(data, ir.Vec) else (int(values[0]) if param.type is Type.WHOLE else values[0])

    def material(self, decl: ast.MaterialDecl) -> Material:
        found = self.entries(decl.block, MATERIAL_KEYS, "material")
        return replace(self.materials[DEFAULT_MATERIAL], name=decl.name, **found)

    def camera(self, decl: ast.CameraDecl | None) -> Camera:
        errors_before = len(self.errors)
        found = self.entries(decl.block if decl else None, CAMERA_KEYS, "camera")
        camera = Camera(**found)
        if len(self.errors) > errors_before:
            return camera
        try:
            return camera.aimed(up_given="up" in found)
        except ValueError as error:
            at_fault = camera.aim_problem()[0]
            where = next((x.value.span for x in decl.block.entries if x.key == at_fault), decl.span)
            self.error(where, str(error))
        return camera

    def light(self, decl: ast.LightDecl) -> Light | None:
        keys = LIGHT_KEYS.get(decl.kind)     # the kind as a word: a LightKind is equal to its word
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
        kind = LightKind(decl.kind)
        if kind in (LightKind.SPHERE, LightKind.RECTANGLE):    # the direct renderer's stand-in for their soft shadows
            found.setdefault("shadows", Shadows.SOFT)
        return Light(kind, vector, **found)

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
        for name, info in self.params.items():
            keys.setdefault(name, info.as_key())
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

    def presets(self, decls: list[ast.PresetDecl]) -> tuple[Preset, ...]:
        """Each `preset NAME { param: value, ... }`: constant values of
        params, in their ranges; one preset of each name."""
        keys, found = {name: info.as_key() for name, info in self.params.items()}, {}
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
    if p.type is Type.SIZE:
        return ir.vec(*(ir.const(p.default),) * 3)
    return ir.const(p.default)


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
        return Value(vector_type(len(a)), ir.Vec(tuple(ir.div(x, length) for x in a)))
    b = vectors[1].items
    return Value(Type.VEC3, ir.vec(ir.sub(ir.mul(a[1], b[2]), ir.mul(a[2], b[1])),
                                ir.sub(ir.mul(a[2], b[0]), ir.mul(a[0], b[2])),
                                ir.sub(ir.mul(a[0], b[1]), ir.mul(a[1], b[0]))))


# What a value of each parameter type may be
_ACCEPTED = {Type.NUMBER: (NUM,), Type.WHOLE: (NUM,), Type.VEC3: (Type.VEC3,), Type.VEC4: (Type.VEC4,),
             Type.COLOR: (Type.VEC3,), Type.SIZE: (NUM, Type.VEC3), Type.MATERIAL: (MATERIAL,),
             Type.SHAPE: (SHAPE,)}


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
    if parameter.type is Type.BLOCK:
        return KeySpec(parameter.name, KeyKind.BLOCK,
                       keys=tuple(_key_spec(p) for p in keys_of(parameter.block).values()))
    if parameter.type is Type.FILE:
        return KeySpec(parameter.name, KeyKind.FILE)
    kind = {Type.WORD: KeyKind.WORD, Type.WHOLE: KeyKind.WHOLE, Type.VEC3: KeyKind.VECTOR}.get(
        parameter.type, KeyKind.NUMBER)
    low, high, low_excluded, high_excluded = parameter.range
    return KeySpec(parameter.name, kind, tuple(str(w) for w in parameter.words), low, high, low_excluded,
                   high_excluded, colour=kind is KeyKind.VECTOR and parameter.name in COLOUR_KEYS)


# `fractal(formula, ...)`: the shape of a formula (docs/formulas.md). The
# bailout, julia and bound are optional (the bailout's default depends on
# the estimate's kind: formula_code.orbit).
FORMULA_FORMS = {
    "fractal": Signature("fractal", "fractal", (
        Parameter("formula", Type.FORMULA), Parameter("iterations", Type.WHOLE, 12.0, (between(1, 1000),)),
        Parameter("bailout", NUM, 0.0, (above(0),)), Parameter("julia", Type.VEC3, 0.0),
        Parameter("bound", NUM, 0.0, (above(0),)), Parameter("step", NUM, 1.0, (above(0), at_most(1))))),
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


def check_value(param: Parameter, key: str, value, subject: str | None = None):
    """Validate a render setting given from Python or the command line
    (type and range, as in a file); raise ValueError saying what is wrong,
    of `subject` (default: `'key' of 'render'`; '': none). A number is a
    Python or numpy number, never a string or a bool."""
    named = repr(key) if subject is None else subject

    def wrong(says: str) -> ValueError:
        return ValueError(f"{named} {says}".lstrip())
    if param.type is Type.FILE:
        if value is not None:
            raise ValueError(f"'{key}' is a scene file's key: from Python give environment_map=FILE "
                             f"(on the command line, --environment-map FILE)")
        return None
    if param.type is Type.BLOCK:
        keys = keys_of(param.block)
        if value is False:
            return None                                  # the effect off
        if isinstance(value, param.block):
            value = {f: getattr(value, f) for f in keys}
        if not isinstance(value, dict):
            raise wrong(f"must be a dict of {', '.join(keys)} (or False for off)")
        unknown = set(value) - set(keys)
        if unknown:
            raise wrong(f"has no key '{sorted(unknown)[0]}' (known: {', '.join(keys)})")
        return param.block(**{k: check_value(keys[k], f"{key}.{k}", v) for k, v in value.items()})
    word = param.word(value)
    if word is not None:
        return word
    if param.type is Type.WORD:
        raise wrong(f"must be {' or '.join(repr(str(c)) for c in param.words)}, not {value!r}")
    is_vector = param.type is Type.VEC3
    try:
        numbers = tuple(value) if is_vector else (value,)
        if any(isinstance(x, (str, bytes, bool)) for x in numbers):
            raise TypeError
        items = tuple(float(x) for x in numbers)
    except (TypeError, ValueError, OverflowError):
        raise wrong(f"must be {TYPE_WORDS[Type.VEC3 if is_vector else NUM]}, not {value!r}") from None
    if is_vector and len(items) != 3:
        raise wrong(f"must have 3 components, not {len(items)}")
    if not all(in_float_range(x) for x in items):
        raise wrong(f"must be finite (within ±{FLOAT_MAX:.3g}), not {value!r}")
    says = param.violation(items)
    if says:
        raise ValueError(f"{repr(param.name) + ' of ' + repr('render') if subject is None else subject} {says}".lstrip())
    if is_vector:
        return items
    return int(items[0]) if param.type is Type.WHOLE else items[0]


def check_param_values(scene: CheckedScene, values) -> None:
    """Check every value that depends on params, for these param values;
    raise SceneError at each value's span that is out of its range."""
    errors = []

    def error(span: Span, message: str) -> None:
        errors.append(diagnostic(scene.file, scene.source, span, message))
    shown = ", ".join(f"{p.name} = {v:g}" for p, v in zip(scene.params, values))
    # checks between arguments last, and only if each argument is valid alone
    for check_ in sorted(scene.param_checks, key=lambda c: bool(c.others)):
        if check_.others and errors:
            break
        items = check_.value.items if isinstance(check_.value, ir.Vec) else (check_.value,)
        try:
            constants = [ir.evaluate(x, values) for x in items]
        except (ValueError, ZeroDivisionError, OverflowError):
            error(check_.span, f"'{check_.parameter.name}' of '{check_.owner}' is undefined for these param values")
            continue
        others = {k: ir.evaluate(v, values) for k, v in check_.others.items()}
        says = check_.parameter.violation(constants, others)
        if says:
            error(check_.span, f"'{check_.parameter.name}' of '{check_.owner}' {says} (with {shown})")
    if errors:
        raise SceneError(errors)
