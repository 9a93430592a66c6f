"""Stage 2: AST -> checked scene (`check`).

Resolves names, types and arguments, folds constants (through `ir`), checks
ranges, and collects every error with its span before raising one
`SceneError`. An expression that failed evaluates to `ERROR`, which later
checks accept silently, so one mistake gives one message. The checker's
parts, by what they check: check_names.py (params, lets, names),
check_expressions.py (arithmetic, calls, shapes), check_formulas.py
(formulas, hybrids, fractals), check_blocks.py (each block's keys), on
the state and diagnostics of check_base.py.
"""
from __future__ import annotations

from functools import lru_cache

from . import ast, ir
from .check_base import FORMULA, NUMBER, SHAPE, closest_name
from .check_blocks import BlockChecking
from .check_expressions import ExpressionChecking
from .check_formulas import FormulaChecking
from .check_names import NameChecking
from .errors import SceneError, Span, diagnostic
from .parse import parse
from .program import DEFAULT_MATERIAL, CheckedScene, default_material
from .resources import resource_dir
from .types import FLOAT_MAX, TYPE_WORDS, Parameter, Type, in_float_range, keys_of


class _Checker(NameChecking, ExpressionChecking, FormulaChecking, BlockChecking):
    """A scene's checker, its parts by what they check: names and lets,
    expressions and calls, formulas and fractals, blocks."""

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


@lru_cache(maxsize=1)
def library_formulas() -> tuple[tuple[str, tuple], ...]:
    """The formulas of the library (stdlib_frac/*.frac), checked: every
    scene can use them; a file's own formula of the same name replaces one."""
    found = []
    for path in sorted(resource_dir("stdlib_frac").glob("*.frac")):
        program = parse(path.read_text(), str(path))
        checker = _Checker(program)
        for decl in program.decls:
            checker.declare_formula(decl)
        if checker.errors:
            raise SceneError(checker.errors)
        found.extend(checker.formulas.items())
    return tuple(found)


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
    return _Checker(program, library_formulas()).run()


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
        raise wrong(f"must be {TYPE_WORDS[Type.VEC3 if is_vector else NUMBER]}, not {value!r}") from None
    if is_vector and len(items) != 3:
        raise wrong(f"must have 3 components, not {len(items)}")
    if not all(in_float_range(x) for x in items):
        raise wrong(f"must be finite (within ±{FLOAT_MAX:.3g}), not {value!r}")
    says = param.violation(items)
    if says:
        who = f"'{param.name}' of 'render'" if subject is None else subject
        raise ValueError(f"{who} {says}".lstrip())
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
