"""The checker's expressions: arithmetic, calls with their arguments
bound and converted to their parameters' types and constraints, shapes,
transforms and colourings (fractalc/check.py)."""
from __future__ import annotations

from dataclasses import replace

from . import ast, ir
from .check_base import (COLORING, ERROR, FORMULA, MATERIAL, NUMBER, SHAPE, WORD, CheckerBase, Failed, Value,
                         default_value, source_text)
from .check_formulas import LIBRARY
from .expressions import (argument_count, beyond_floats, broadcast, component_not_number, components,
                          different_sizes, named_argument, not_numbers, require_vector_size, undefined,
                          wrong_argument)
from .errors import Span
from .program import (DEFAULT_MATERIAL, Coloring, Combination, CombinationKind, Fractal, ParamCheck, Primitive, Shape,
                      Transformed, WithMaterial, cosine_palette)
from .stdlib import AUTO_SCALE, COLORINGS, COMBINATORS, MATH, Signature
from .transforms import SIGNATURES as TRANSFORMS
from .types import FLOAT_MAX, NUMBER_TYPES, TYPE_WORDS, VECTOR_TYPES, Parameter, Type, in_float_range, vector_type

# Parts (primitives, transforms, combinations) a scene may have, counting a
# let each time it is used. The kernel's build time grows faster than its
# size: on 2 cores, a union of 1000 translated spheres (2001 parts) takes
# 11 s to build and render once, 2000 spheres 30 s, 4000 spheres 73 s
# (benchmarks/scene_size.py; 10000 spheres took 17 minutes).
MAX_SHAPES = 6000


class ExpressionChecking(CheckerBase):
    def evaluate(self, expr: ast.Expr) -> Value:
        try:
            return self.expression(expr)
        except Failed:
            return ERROR

    def expression(self, e: ast.Expr) -> Value:
        if isinstance(e, ast.Number):
            if not in_float_range(e.value):
                self.fail(e.span, f"{source_text(self.program, e.span)} is too large a number "
                                  f"(the kernel's floats reach {FLOAT_MAX:.3g})")
            return Value(NUMBER, ir.const(e.value))
        if isinstance(e, ast.Name):
            return self.name(e)
        if isinstance(e, ast.Vector):
            items = [self.expression(x) for x in e.items]
            if any(v.type == Type.ERROR for v in items):
                return ERROR
            for item, v in zip(e.items, items):
                if v.type != NUMBER:
                    self.fail(item.span, component_not_number(v.type))
            self.shared(require_vector_size, e, len(items))
            return Value(vector_type(len(items)), ir.Vec(tuple(v.data for v in items)))
        if isinstance(e, ast.Unary):
            operand = self.expression(e.operand)
            if operand.type == Type.ERROR:
                return ERROR
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

    def binary(self, e: ast.Binary) -> Value:
        left, right = self.value_of(e.left), self.value_of(e.right)
        if Type.ERROR in (left.type, right.type):
            return ERROR
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
                raise Failed
            if value.type != SHAPE:
                self.fail(operand.span, "this is a formula: make it a shape with 'fractal(formula(...), iterations: N)'"
                          if value.type == FORMULA else
                          f"'{e.op}' combines shapes ({'union' if e.op == '|' else 'intersection'}), "
                          f"this is {TYPE_WORDS[value.type]}")
            shapes.append(value.data)
        kind = CombinationKind.UNION if e.op == "|" else CombinationKind.INTERSECT
        return self.shape(Combination(kind, tuple(shapes), ir.const(0.0), e.span))

    def arithmetic(self, e, op: str, operands: list[Value], mode: str = "map") -> Value:
        """Component-wise arithmetic on numbers and vectors; numbers broadcast."""
        for operand in operands:
            if operand.type not in NUMBER_TYPES:
                self.fail(e.span, not_numbers(op, operand.type))
        combined = broadcast([(o.type, o.data.items if o.type != NUMBER else (o.data,)) for o in operands])
        if combined is None:
            self.fail(e.span, different_sizes(op, [len(o.data) for o in operands if o.type != NUMBER]))
        size, lanes = combined
        try:
            items = tuple(ir.op(op, *args) for args in zip(*lanes))
        except (ValueError, ZeroDivisionError, OverflowError):
            self.fail(e.span, undefined(op))
        for item in items:
            if ir.is_const(item) and not in_float_range(item.value):
                self.fail(e.span, beyond_floats(op, item.value))
        if size == 1:
            return Value(NUMBER, items[0])
        return Value(vector_type(size), ir.Vec(items))

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
            bound[name] = (arg, self.expression(arg.value))
        for p in params:
            if p.name not in bound and p.default is None:
                self.fail(e.span, f"'{signature.name}' needs the argument '{p.name}'")
        return bound

    def convert(self, span: Span, value: Value, param: Parameter, owner: str):
        """An argument value as the parameter's type (ir.Expr or ir.Vec)."""
        if value.type == Type.ERROR:
            raise Failed
        want = param.type
        if want is Type.WORD:
            if value.type == WORD and value.data in param.words:
                return param.word(value.data)
            self.fail(span, f"'{param.name}' of '{owner}' must be one of {', '.join(param.words)}")
        if want is Type.COLOR and value.type == COLORING:
            return value.data
        if value.type not in ACCEPTED[want]:
            word = TYPE_WORDS.get(want)
            if value.type == WORD and want is not Type.MATERIAL:
                self.unknown_name(span, value.data)
            if value.type == WORD:
                hint = self.did_you_mean(value.data, self.material_decls)
                self.fail(span, f"unknown material '{value.data}'{hint}")
            self.fail(span, f"'{param.name}' of '{owner}' needs {word}, this is {TYPE_WORDS[value.type]}")
        data = value.data
        if want is Type.SIZE and value.type == NUMBER:
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
                    converted[p.name] = default_value(p)
            except Failed:
                failed = True
        if failed:
            raise Failed
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
            return Value(COLORING, Coloring(start, start, trap, given_scale(scale), tuple(palette)))
        if name in COLORINGS:
            near, far, trap, scale = self.bound_args(e, COLORINGS[name], e.args)
            return Value(COLORING, Coloring(near, far, trap, given_scale(scale)))
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
            raise Failed
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
            self.fail(named.span, named_argument(e.name))
        if len(e.args) != arity:
            self.fail(e.span, argument_count(e.name, arity, arity, function.about, len(e.args)))
        values = [self.value_of(a.value) for a in e.args]
        if any(v.type == Type.ERROR for v in values):
            raise Failed
        if function.per_component:
            return self.arithmetic(e, e.name, values)
        for arg, want, v in zip(e.args, function.arguments, values):
            if v.type not in VECTOR_TYPES or (want == "3" and v.type != Type.VEC3):
                self.fail(arg.span, wrong_argument(e.name, "a 3-vector" if want == "3" else "a vector", function.about,
                                                   v.type))
        if len(values) == 2 and len(values[0].data) != len(values[1].data):
            self.fail(e.span, different_sizes(e.name, [len(v.data) for v in values]))
        try:
            return vector_math(e.name, [v.data for v in values])
        except (ValueError, ZeroDivisionError):
            self.fail(e.span, f"'{e.name}' is undefined here (a zero vector?)")

    def field(self, e: ast.Field) -> Value:
        """`v.x`, `v.xy`: components of a vector."""
        receiver = self.value_of(e.receiver)
        if receiver.type == Type.ERROR:
            raise Failed
        vector = receiver.data.items if receiver.type in VECTOR_TYPES else ()
        items = self.shared(components, e, receiver.type, vector)
        return Value(NUMBER, items[0]) if len(items) == 1 else Value(vector_type(len(items)), ir.Vec(items))

    def method(self, e: ast.Method) -> Value:
        if isinstance(e.receiver, ast.Name) and e.receiver.name == LIBRARY and not any(
                LIBRARY in names for names in (self.params, self.lets, self.material_decls)):
            return self.library_formula(e)
        receiver = self.value_of(e.receiver)
        if receiver.type == Type.ERROR:
            raise Failed
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


def given_scale(scale):
    """An orbit trap's scale, or None for the default: spread over the trap's range."""
    return None if scale == AUTO_SCALE else scale


def vector_math(name: str, vectors: list[ir.Vec]) -> Value:
    a = vectors[0].items

    def dot(u, v):
        total = ir.mul(u[0], v[0])
        for x, y in zip(u[1:], v[1:]):
            total = ir.add(total, ir.mul(x, y))
        return total

    if name == "length":
        return Value(NUMBER, ir.op("sqrt", dot(a, a)))
    if name == "dot":
        return Value(NUMBER, dot(a, vectors[1].items))
    if name == "normalize":
        length = ir.op("sqrt", dot(a, a))
        return Value(vector_type(len(a)), ir.Vec(tuple(ir.div(x, length) for x in a)))
    b = vectors[1].items
    return Value(Type.VEC3, ir.vec(ir.sub(ir.mul(a[1], b[2]), ir.mul(a[2], b[1])),
                                ir.sub(ir.mul(a[2], b[0]), ir.mul(a[0], b[2])),
                                ir.sub(ir.mul(a[0], b[1]), ir.mul(a[1], b[0]))))


# What a value of each parameter type may be
ACCEPTED = {Type.NUMBER: (NUMBER,), Type.WHOLE: (NUMBER,), Type.VEC3: (Type.VEC3,), Type.VEC4: (Type.VEC4,),
             Type.COLOR: (Type.VEC3,), Type.SIZE: (NUMBER, Type.VEC3), Type.MATERIAL: (MATERIAL,),
             Type.SHAPE: (SHAPE,)}
