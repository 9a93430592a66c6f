"""The checker's formulas and fractals: a formula's declaration (its
parameters, its statements run once with the defaults), its uses, hybrids
and repeats, and `fractal(formula, ...)` (fractalc/check.py)."""
from __future__ import annotations

import math
import os
from dataclasses import replace

from . import ast, formula_code, ir
from .check_base import FORMULA, NUMBER, SHAPE, WORD, CheckerBase, Failed, Value, default_value
from .errors import Span
from .formula_statements import split
from .expressions import Mistake
from .program import Fractal
from .stdlib import COLORINGS, COMBINATORS, MATH, Signature
from .types import TYPE_WORDS, Parameter, Type, above, at_most, between, empty_range, range_violation

# Formula steps in one round of a hybrid (each `f() * n` counts n): a round
# is written out whole in the orbit loop, so the kernel grows with it. On 2
# cores (load 5), hybrids of bulb and amazing_box steps, iterations 1000,
# check in 0.3-1.7 s and then build and render once in 7 s (100 steps),
# 26 s (200), 64 s (400; benchmarks/hybrid_size.py); 1000 steps built for 84 s.
MAX_HYBRID_STEPS = 256


# `fractal(formula, ...)`: the shape of a formula (docs/formulas.md). The
# bailout, julia and bound are optional (the bailout's default depends on
# the estimate's kind: formula_code.orbit).
FORMULA_FORMS = {
    "fractal": Signature("fractal", "fractal", (
        Parameter("formula", Type.FORMULA), Parameter("iterations", Type.WHOLE, 12.0, (between(1, 1000),)),
        Parameter("bailout", NUMBER, 0.0, (above(0),)), Parameter("julia", Type.VEC3, 0.0),
        Parameter("bound", NUMBER, 0.0, (above(0),)), Parameter("step", NUMBER, 1.0, (above(0), at_most(1))))),
    "hybrid": Signature("fractal", "hybrid", ()),
}


# `library.NAME(...)` names the library's formula NAME (unless the file
# declares a value called `library`)
LIBRARY = "library"


class FormulaChecking(CheckerBase):
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
            if value.type not in (NUMBER, Type.VEC3, Type.VEC4) or not all(ir.is_const(x) for x in items):
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
                    self.error(param.bounds[0].span, empty_range(low, high))
                    return
                if value.type != NUMBER:
                    self.error(param.bounds[0].span, "a range is for a number parameter")
                    return
                outside = range_violation(param.name, items[0].value, low, high)
                if outside:
                    self.error(param.default.span, outside)
                    return
                constraints = (between(low, high),)
            default = items[0].value if value.type == NUMBER else tuple(x.value for x in items)
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
            raise Failed              # its declaration had a mistake, already reported
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
                raise Failed
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
        if e.op != "*" or count.type != NUMBER:
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
            raise Failed
        if formula.type != FORMULA:
            if formula.type == WORD:
                self.unknown_name(bound["formula"][0].value.span, formula.data)
            self.fail(bound["formula"][0].value.span, f"'fractal' needs a formula (declared with 'formula "
                                                      f"name(...) {{ ... }}'), this is {TYPE_WORDS[formula.type]}")
        values = {}
        for p in FORMULA_FORMS["fractal"].parameters[1:]:
            if p.name not in bound:
                values[p.name] = default_value(p) if p.name in ("iterations", "step") else None
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
