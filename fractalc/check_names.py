"""The checker's names: params, lets (in dependency order, cycles
reported) and the names an expression reads (fractalc/check.py)."""
from __future__ import annotations


from . import ast, ir
from .check_base import ERROR, MATERIAL, NUMBER, WORD, CheckerBase, Failed, Value
from .check_formulas import FORMULA_FORMS
from .errors import Span
from .expressions import uncalled_function
from .program import ParamInfo
from .stdlib import COLORINGS, COMBINATORS, MATH
from .types import Type, empty_range


class NameChecking(CheckerBase):
    def declare_param(self, decl: ast.ParamDecl) -> None:
        default = self.constant_number(decl.default, "a param's value")
        low = high = None
        if decl.bounds:
            low = self.constant_number(decl.bounds[0], "a param's bound")
            high = self.constant_number(decl.bounds[1], "a param's bound")
            if None not in (low, high, default):
                if low > high:
                    self.error(decl.bounds[0].span, empty_range(low, high))
        info = ParamInfo(decl.name, len(self.params), default or 0.0, low, high, decl.span)
        if None not in (low, high, default) and low <= high and info.range_violation(default):
            self.error(decl.default.span, info.range_violation(default))
        self.params[decl.name] = info

    def constant_number(self, expr: ast.Expr, what: str) -> float | None:
        value = self.evaluate(expr)
        if value.type == Type.ERROR:
            return None
        if value.type != NUMBER or not ir.is_const(value.data):
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
        except Failed:
            return ERROR

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
                self.let_values[used] = ERROR
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

    def name(self, e: ast.Name) -> Value:
        if e.name in self.params:
            info = self.params[e.name]
            return Value(NUMBER, ir.Param(info.index, info.name))
        if e.name in self.lets:
            return self.let_value(e.name)
        if e.name in self.material_decls:
            return Value(MATERIAL, e.name)
        if e.name in self.library.signatures or e.name in COMBINATORS or e.name in MATH \
                or e.name in COLORINGS or e.name in self.formulas or e.name in FORMULA_FORMS:
            self.fail(e.span, uncalled_function(e.name))
        return Value(WORD, e.name)

    def unknown_name(self, span: Span, name: str) -> None:
        hint = self.did_you_mean(name, self.params, self.lets, self.material_decls)
        self.fail(span, f"unknown name '{name}'{hint}")

    def value_of(self, e: ast.Expr) -> Value:
        """Evaluate an expression that must be a value (not a bare word)."""
        value = self.expression(e)
        if value.type == WORD:
            self.unknown_name(e.span, value.data)
        return value
