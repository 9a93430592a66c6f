"""Stage 4: distance IR -> OpenCL C source (`emit`).

The source is one self-contained program: scene constants, the prelude, the
library functions the scene calls (and nothing else), the generated
`distance_estimate`, `surface_at` and `shade`, and the fixed
template with the kernels. `Target.lanes` chooses one ray per work-item (1,
for GPUs) or one ray per vector lane (8 or 16, for CPUs); `Target.double`
makes every `real` a double. Output is deterministic: the same scene and
target give the same text, which is the build cache's key.
"""
from __future__ import annotations

import dataclasses
import re
import textwrap
from dataclasses import dataclass, field

from . import ir, pathtrace, ranges
from .hoist import DERIVED_SLOTS, Hoisted, hoist
from .lower import POINT, SceneIR, marched_distance
from .transforms import Bound
from .types import FLOAT_MAX, Feature, Parameter, Type, keys_of
from .schedule import ForBlock, Hoist, IfBlock, schedule, varying
from .passes import PASSES, SHADING_PASSES, channels
from .lights import LIGHT_KINDS, MAX_RADIANCE
from .program import CAMERA_KEYS, RENDER_KEYS, Light
from .stdlib import library, templates
from .version import __version__

AMBIENT = 0.25          # ambient light, times the material's colour and AO
AO_DELTA = 0.05         # spacing of the AO samples along the normal


@dataclass(frozen=True)
class Target:
    lanes: int = 8          # rays per work-item: 1 (GPU) or 8/16 (CPU vector lanes)
    double: bool = False    # `real` is double
    exact_native: bool = False  # the device's native_ functions are exact (lanes.LaneChoice.native_exact)
    count: bool = False     # the counting build's hooks kept (stdlib_cl/count.cl, fractalc/count.py)
    refined_rsqrt: bool = False  # rsqrt as native_rsqrt and a Newton step (devices.refines_rsqrt)
    build_options: tuple[str, ...] = ()  # the program's OpenCL build options (devices.build_options)


def literal(value: float) -> str:
    """A float literal; `f`-suffixed (the double build strips the suffix)."""
    if value != value or value in (float("inf"), float("-inf")):
        raise ValueError(f"non-finite constant {value}")
    text = repr(float(value))
    return f"{text}f"


# C types of temporaries: per-ray values, and uniform ones (params and
# constants only), which stay scalars
_C_TYPES = {ir.REAL: "real", ir.VEC3: "vec3", ir.INT: "lane_int", ir.MASK: "mask"}
_UNIFORM_C_TYPES = {ir.REAL: "scalar", ir.INT: "int", ir.MASK: "int"}
_TEMP_PREFIX = {"real": "r", "vec3": "q", "lane_int": "id", "mask": "m", "scalar": "u", "int": "k"}
_C_AXES = "xyz"
# operations rendered as OpenCL functions that take one type throughout: a
# uniform argument beside a per-ray one is widened to `real`
_OVERLOADED = ("min", "max", "min_of_numbers", "max_of_numbers", "abs")
# Expressions nest at most this deep before a temporary is named: clang
# refuses more than 256 nested brackets, and each level costs up to four
# (SELECT expands to a call with parenthesised arguments)
MAX_INLINE_DEPTH = 32


@dataclass
class _Copy:
    """One point's names and texts in a function of several points."""
    point: str                  # the C name of its point
    suffix: str                 # of its temporaries' names
    text: dict = field(default_factory=dict)
    depth: dict = field(default_factory=dict)     # how deeply a node's inlined text nests
    active: list = field(default_factory=list)    # the active masks of the loops being written (None: no condition)
    rays: list = field(default_factory=list)      # the masks of the per-ray branches open (the counting build)
    counts: dict = field(default_factory=dict)


class _FunctionWriter:
    """Writes one C function computing IR expressions of the point: renders
    the blocks that `schedule` orders.

    Nodes used more than once, library calls and expressions nested deeper
    than MAX_INLINE_DEPTH get a named temporary, the rest is inlined. A node
    is uniform where it depends on params and constants only: it is
    computed as a `scalar` (or `int`). Everything else (the point, library
    calls, loop and branch results) is per ray; a per-ray node's uniform
    arguments are widened where C's overloads need one type. Inside a loop,
    a per-ray branch runs only for the rays still iterating.

    With `points` > 1, the function computes the same expressions at that
    many points (p0, p1, ...) side by side: each statement once per point
    (a uniform one once), one loop for a loop of all points (it ends when
    none of their rays iterates), one branch for a per-ray branch of any:
    independent chains of operations that a CPU core overlaps, where one
    point's estimate waits on its own results."""

    def __init__(self, root: ir.Expr, counting: bool = False, points: int = 1):
        self.root = root
        # the counting build: each loop counts the iterations of its rays
        # (COUNT_ITERATIONS, stdlib_cl/count.cl) within the per-ray branches
        # open around it
        self.counting = counting
        self.uses: dict = {}
        for node in ir.walk(root):
            for child in ir.children(node):
                self.uses[child] = self.uses.get(child, 0) + 1
        self.varying = varying((root,))
        self.lines: list[str] = []
        self.copies = [_Copy(POINT.name, "")] if points == 1 else \
            [_Copy(f"{POINT.name}{k}", f"_{k}") for k in range(points)]
        self.copy = self.copies[0]

    # the point being written's
    text = property(lambda self: self.copy.text, lambda self, value: setattr(self.copy, "text", value))
    depth = property(lambda self: self.copy.depth)
    active = property(lambda self: self.copy.active)
    rays = property(lambda self: self.copy.rays)

    def each(self):
        """Each point in turn, as the one being written."""
        for copy in self.copies:
            self.copy = copy
            yield copy
        self.copy = self.copies[0]

    def block(self, roots, indent: str) -> None:
        """Write the statements computing `roots` (a node or a tuple)."""
        self.statements(schedule(roots if isinstance(roots, tuple) else (roots,), self.varying), indent)

    def statements(self, statements, indent: str) -> None:
        run = []    # plain statements, written for one point after the other
        for statement in statements:
            if isinstance(statement, (ForBlock, IfBlock)):
                self.plain(run, indent)
                run = []
                if isinstance(statement, ForBlock):
                    self.loop(statement, indent)
                else:
                    self.branch(statement, indent)
            else:
                run.append(statement)
        self.plain(run, indent)

    def plain(self, statements, indent: str) -> None:
        """Statements without blocks, at each point in turn; a uniform value
        (params and constants alone) is the same at every point: written
        once, at the first."""
        first = self.copies[0]
        for copy in self.each():
            for statement in statements:
                node = statement.node
                if copy is first or node in self.varying:
                    self.statement(statement, indent)
                else:
                    self.text[node], self.depth[node] = first.text[node], first.depth[node]

    def statement(self, statement, indent: str) -> None:
        if isinstance(statement, Hoist):
            node = statement.node
            if not self.trivial(node) and self.depth[node]:
                self.text[node] = self.declare(self.c_type(node), self.text[node], indent)
                self.depth[node] = 0
        elif isinstance(statement.node, ir.Out):
            self.text[statement.node] = self.text[statement.node.source][statement.node.index]
            self.depth[statement.node] = 0
        else:
            self.value(statement.node, indent)

    def value(self, node, indent: str) -> None:
        text = self.expression(node)
        self.depth[node] = 1 + max((self.depth.get(c, 0) for c in ir.children(node)), default=0)
        if self.named(node) and node is not self.root:
            text = self.declare(self.c_type(node), text, indent)
            self.depth[node] = 0
        self.text[node] = text

    def loop(self, block: ForBlock, indent: str) -> None:
        node = block.loop
        names = [[self.declare(_C_TYPES[e.type], self.argument(e), indent, "s") for e in node.init]
                 for _ in self.each()]
        counter = self.fresh("i")
        count = str(int(node.count.value)) if ir.is_const(node.count) else f"(int){self.text[node.count]}"
        actives = [self.declare("mask", "MASK_TRUE", indent, "a") if node.condition is not None else None
                   for _ in self.each()]
        self.write_statement("loop", indent, counter=counter, count=count)
        inside, outsides = indent + "    ", []
        for _, states in zip(self.each(), names):
            outsides.append(dict(self.text))
            for i, e in enumerate(node.init):
                self.text[ir.State(node.level, i, e.type)] = states[i]
                self.depth[ir.State(node.level, i, e.type)] = 0
        if node.condition is not None:
            self.statements(block.condition, inside)
            for _, active in zip(self.each(), actives):
                self.write_statement("narrow", inside, active=active, condition=self.text[node.condition])
            self.write_statement("loop_stop", inside, active=" | ".join(actives))
        for _, active in zip(self.each(), actives):
            if self.counting:
                counted = " & ".join([active] * (active is not None) + ["MASK_TRUE", *self.rays])
                self.write_statement("count_iterations", inside, rays=counted)
            self.active.append(active)
        self.statements(block.body, inside)
        for _, states, active in zip(self.each(), names, actives):
            self.active.pop()
            updates = [self.declare(_C_TYPES[e.type], self.argument(e), inside, "n") for e in node.next]
            for name, update in zip(states, updates):
                if active is None:
                    self.write_statement("assign", inside, name=name, value=update)
                else:
                    self.write_statement("assign_selected", inside, name=name, value=update, mask=active)
        self.write_statement("end", indent)
        for _, outside, states in zip(self.each(), outsides, names):
            self.text = outside
            self.text[node] = states
            self.depth[node] = 0

    def branch(self, block: IfBlock, indent: str) -> None:
        node = block.branch
        inside, outsides = indent + "    ", [dict(copy.text) for copy in self.copies]
        types = [_C_TYPES[e.type] for e in node.then]
        names, conditions = [], []
        if node.condition in self.varying:
            for _ in self.each():
                names.append([self.declare(t, self.argument(e), indent, "b") for t, e in zip(types, node.otherwise)])
                # in a loop, rays that have stopped iterating need neither side
                condition = self.text[node.condition]
                stopped = [a for a in self.active if a is not None]
                if stopped:
                    condition = " & ".join([condition, *stopped])
                if self.depth[node.condition] or stopped or len(self.copies) > 1:
                    condition = self.declare("mask", condition, indent)
                conditions.append(condition)
            self.write_statement("if_any", indent, condition=" | ".join(conditions))
            for _, condition in zip(self.each(), conditions):
                self.rays.append(condition)
            self.statements(block.then, inside)
            for _, condition, selected in zip(self.each(), conditions, names):
                self.rays.pop()
                for name, e in zip(selected, node.then):
                    self.write_statement("assign_selected", inside, name=name, value=self.argument(e),
                                         mask=condition)
        else:
            for _ in self.each():
                names.append([self.fresh("b") for _ in types])
                for t, name in zip(types, names[-1]):
                    self.write_statement("declare_unset", indent, type=t, name=name)
            # a uniform condition: the same at every point
            self.write_statement("if", indent, condition=self.text[node.condition])
            self.statements(block.then, inside)
            for _, outside, chosen in zip(self.each(), outsides, names):
                for name, e in zip(chosen, node.then):
                    self.write_statement("assign", inside, name=name, value=self.argument(e))
                self.text = dict(outside)
            self.write_statement("else", indent)
            self.statements(block.otherwise, inside)
            for _, chosen in zip(self.each(), names):
                for name, e in zip(chosen, node.otherwise):
                    self.write_statement("assign", inside, name=name, value=self.argument(e))
        self.write_statement("end", indent)
        for _, outside, chosen in zip(self.each(), outsides, names):
            self.text = outside
            self.text[node] = chosen
            self.depth[node] = 0

    # ---- rendering -------------------------------------------------------------

    @staticmethod
    def trivial(node) -> bool:
        return isinstance(node, (ir.Const, ir.Param, ir.Var, ir.Vec)) or (
            isinstance(node, ir.Comp) and isinstance(node.vector, ir.Var))

    def named(self, node) -> bool:
        if isinstance(node, (ir.Const, ir.Param, ir.Var, ir.Vec, ir.State, ir.Out)):
            return False
        if isinstance(node, ir.Comp):
            return not isinstance(node.vector, (ir.Var, ir.Call))
        return isinstance(node, ir.Call) or self.uses.get(node, 0) > 1 or self.depth[node] > MAX_INLINE_DEPTH

    def argument(self, node, c_type: str = "real") -> str:
        """A value passed to a function: uniform scalars widened to `real`
        (or converted to the parameter's C type)."""
        text = self.text[node]
        if isinstance(node, ir.Vec):
            return text
        if c_type == "int":
            return f"(int){text}"
        if node not in self.varying and node.type == ir.REAL:
            return f"(real){text}"
        if node not in self.varying and node.type in (ir.INT, ir.MASK):
            return f"(lane_int){text}"
        return text

    def call_arguments(self, node: ir.Call) -> list[str]:
        """A library call's arguments: vec3s as `v3`, other vectors spread
        into their components, each converted to its parameter's C type."""
        flat = []
        for arg in node.args:
            if isinstance(arg, ir.Vec) and len(arg) != 3:
                flat.extend(arg.items)
            else:
                flat.append(arg)
        types = library().functions[node.function].parameter_types
        return [self.argument(a, t) for a, t in zip(flat, types)]

    def expression(self, node) -> str:
        if isinstance(node, ir.Const):
            return f"{int(node.value)}" if node.type in (ir.INT, ir.MASK) else literal(node.value)
        if isinstance(node, ir.Param):
            return f"params[{node.index}]"
        if isinstance(node, ir.Var):
            return self.copy.point if node == POINT else node.name
        if isinstance(node, ir.Comp):
            return f"{self.text[node.vector]}.{_C_AXES[node.index]}"
        if isinstance(node, ir.Vec):
            items = node.items
            if all(isinstance(c, ir.Comp) and c.index == i for i, c in enumerate(items)) \
                    and len({c.vector for c in items}) == 1:
                return self.text[items[0].vector]
            return f"v3({', '.join(self.argument(c) for c in items)})"
        if isinstance(node, ir.Call):
            return f"{node.function}({', '.join(self.call_arguments(node))})"
        # a uniform node's arguments are all scalars: no conversions
        value = self.argument if node in self.varying else self.text.__getitem__
        if node.op == "select":
            condition, if_true, if_false = node.args
            if condition in self.varying:
                return f"SELECT({value(if_false)}, {value(if_true)}, {self.text[condition]})"
            # a uniform condition is a scalar int: C's conditional takes it
            return f"({self.text[condition]} ? {value(if_true)} : {value(if_false)})"
        render = ir.OPS[node.op].c
        if render is not None:
            args = [value(a) if node.op in _OVERLOADED else self.text[a] for a in node.args]
            return render(*args)
        return f"{node.op}({', '.join(value(a) for a in node.args)})"

    def c_type(self, node) -> str:
        if node in self.varying or node.type == ir.VEC3:
            return _C_TYPES[node.type]
        return _UNIFORM_C_TYPES[node.type]

    def fresh(self, prefix: str) -> str:
        counts = self.copy.counts
        name = f"{prefix}{counts.get(prefix, 0)}{self.copy.suffix}"
        counts[prefix] = counts.get(prefix, 0) + 1
        return name

    def declare(self, c_type: str, text: str, indent: str, prefix: str | None = None) -> str:
        name = self.fresh(prefix or _TEMP_PREFIX[c_type])
        self.write_statement("declare", indent, type=c_type, name=name, value=text)
        return name

    def write_statement(self, template: str, indent: str, **values: str) -> None:
        """The statement `template` of stdlib_cl/statements.cl with `values`, at the depth of `indent`."""
        self.lines += [indent + line for line in templates("statements.cl")[template].substitute(values).split("\n")]

    def write(self, signature: str) -> str:
        """The function: its result returned, or with several points, each
        point's stored where its pointer argument (d0, d1, ...) points."""
        self.block(self.root, "    ")
        if len(self.copies) == 1:
            return templates("statements.cl")["function"].substitute(signature=signature, body=_body(self.lines),
                                                                     result=self.argument(self.root))
        for k, _ in enumerate(self.each()):
            self.write_statement("store_result", "    ", name=f"d{k}", value=self.argument(self.root))
        return templates("statements.cl")["function_of_points"].substitute(signature=signature,
                                                                           body=_body(self.lines))


def function_source(root: ir.Expr, signature: str, counting: bool = False, points: int = 1) -> str:
    """A C function of the point computing `root` (`counting`: with the
    counting build's hooks of its loops' iterations; `points`: at that
    many points side by side, _FunctionWriter)."""
    return _FunctionWriter(root, counting, points).write(signature)


def _calls(root) -> list[str]:
    return sorted({n.function for n in ir.walk(root) if isinstance(n, ir.Call)})


def _vector(v) -> str:
    return f"v3({', '.join(literal(x) for x in v)})"


def _scene_template(name: str, **values) -> str:
    return templates("scene.cl")[name].substitute(values)


def _shade_template(name: str, **values) -> str:
    return templates("shade.cl")[name].substitute(values)


def _body(lines) -> str:
    """Statements for a template's `$body`: each line ending in a newline."""
    return "".join(f"{line}\n" for line in lines)


def _surface_function(scene_ir: SceneIR) -> str:
    """The surface properties at a point: the nearest part's material."""
    fields = [f.name for f in dataclasses.fields(scene_ir.surface)]
    writer = _FunctionWriter(ir.Vec(scene_ir.surface.items()))
    writer.block(writer.root, "    ")
    values = ", ".join(writer.argument(x) for x in scene_ir.surface.items())
    return _scene_template("surface_at", fields=", ".join(fields), body=_body(writer.lines), values=values)


def _half_space_expressions(half_spaces) -> tuple[ir.Expr, ...]:
    return tuple(e for normal, offset in half_spaces for e in (*normal, offset))


def _bound_expressions(bound) -> tuple[ir.Expr, ...]:
    (centre, radius), half_spaces = bound.sphere, bound.half_spaces
    return (*centre, radius, *_half_space_expressions(half_spaces))


def _bound_with(bound: Bound, values: tuple[ir.Expr, ...]) -> Bound:
    """`bound` with its expressions replaced by `values`, in the order of
    `_bound_expressions`."""
    centre, radius, rest = tuple(values[:3]), values[3], values[4:]
    return Bound((centre, radius), tuple((tuple(rest[i:i + 3]), rest[i + 3]) for i in range(0, len(rest), 4)))


def _bound_function(scene_ir: SceneIR, with_half_spaces: bool) -> str:
    """`scene_bound`: the radius and (through `centre`) the centre of a
    sphere holding the whole scene but its ground half-spaces; uniform, so
    computed from params only; and `clear_of_half_spaces` if asked for and
    the scene has half-spaces."""
    (centre, radius), half_spaces = scene_ir.bound.sphere, scene_ir.bound.half_spaces
    writer = _FunctionWriter(ir.Vec(tuple(centre) + (radius,)))
    writer.block(writer.root, "    ")
    x, y, z, r = (writer.argument(e) for e in tuple(centre) + (radius,))
    text = _scene_template("scene_bound", body=_body(writer.lines), x=x, y=y, z=z, radius=r)
    if half_spaces and with_half_spaces:
        writer = _FunctionWriter(ir.Vec(_half_space_expressions(half_spaces)))
        writer.block(writer.root, "    ")
        tests = [_scene_template("half_space_test", normal=", ".join(writer.argument(c) for c in normal),
                                 offset=writer.argument(offset)) for normal, offset in half_spaces]
        text += "\n\n" + _scene_template("clear_of_half_spaces", body=_body(writer.lines), tests=_body(tests))
    return text


def _filled(template: str, values: dict) -> str:
    """A template of shade.cl with numbers as literals and vectors as v3s."""
    return _shade_template(template, **{name: _vector(v) if isinstance(v, tuple) else literal(v)
                                        for name, v in values.items()})


def _light_block(index: int, light: Light, bound, transparent: bool, passes: bool) -> tuple[str, set[str]]:
    kind = LIGHT_KINDS[light.kind]
    radiance = tuple(min(c * light.intensity, MAX_RADIANCE) for c in light.color)
    origin, values = kind.origin(light)
    lines = [_shade_template("light_start", index=index, kind=light.kind, shadows=light.shadows),
             _filled(origin, {**values, "radiance": radiance}),
             *(_filled(*shaping(light)) for shaping in kind.shaping)]
    needs = set()
    widened = _shadow_bound_radius(light)
    if bound is not None and widened is not None:
        lines.append(_shade_template("shadow_ray_bound", widened=widened))
        lines.append(_shade_template("shadow_reach_bounded_unless_ground" if bound.half_spaces
                                     else "shadow_reach_bounded"))
    if light.shadows != "none":
        lines.append(_shade_template("shadow_facing"))
    if light.shadows == "hard":
        # through transparent solids where the scene has some
        function = "hard_shadow_through" if transparent else "hard_shadow"
        lines.append(_shade_template("hard_shadow", function=function))
        needs.add(function)
    elif light.shadows == "soft":
        lines.append(_shade_template("soft_shadow", softness=literal(light.softness)))
        needs.add("soft_shadow")
    if light.shadows != "none":
        lines.append(_shade_template("shadowed"))
    lines.append(textwrap.indent(_lit("to_light", "radiance", passes), "    "))
    if passes and light.shadows != "none":
        lines.append(_shade_template("shadow_pass"))
    lines.append(_shade_template("light_end"))
    return "\n".join(lines), needs


def _shadow_bound_radius(light: Light) -> str | None:
    """The radius about the scene's bounding sphere's centre past which a
    light's shadow ray meets nothing that dims it (None: no such radius).
    A shadow ray is blocked where it passes within the hit threshold of a
    surface, as a camera ray hits it; a soft shadow dims the light where
    k d / t < 1 along it. For a soft shadow the sphere widens by
    (|o - c| + R) / (k - 1): a ray that misses the sphere by s has d >= s,
    and d >= t - |o - c| - R, so k d / t >= 1 for every t once s is that
    wide (and past the widened sphere). With k <= 1 no width will do."""
    if light.shadows == "hard":
        return _shade_template("hard_widening")
    if light.shadows == "soft" and light.softness > 1.0:
        return _shade_template("soft_widening", factor=literal(1.0 / (light.softness - 1.0)))
    return None


def _lit(to_light: str, radiance: str, passes: bool) -> str:
    """Add a light's Blinn-Phong term to `color` (and with the shading
    passes, to the diffuse and specular passes)."""
    return _shade_template("lit_passes" if passes else "lit", to_light=to_light, radiance=radiance)


def _shade_function(scene_ir: SceneIR, on: dict[str, bool]) -> tuple[str, list[str]]:
    """Blinn-Phong over every light, with shadows and AO only where asked."""
    scene = scene_ir.scene
    ao = scene.render.ao > 0
    # the diffuse, specular, shadow and AO passes: `shade_passes` fills them
    # in, and `shade` is it with the passes thrown away (the compiler drops them)
    passes = on["SHADING_PASSES"]
    needs = {"blinn_phong"}
    lines = [_shade_template("passes_signature" if passes else "signature"), _shade_template("surface")]
    # an AO pass of a scene without AO shows the occlusion at full strength
    strength = literal(scene.render.ao if ao else 1.0)
    if (ao or on["PASS_AO"]) and scene.render.ao_method == "steps":
        needs.add("step_occlusion")
        lines.append(_shade_template("step_occlusion", strength=strength))
    elif ao or on["PASS_AO"]:
        needs.add("ambient_occlusion")
        lines.append(_shade_template("ambient_occlusion", delta=literal(AO_DELTA), strength=strength))
    sky_lit = pathtrace.lights_surfaces(scene.render)
    if sky_lit:     # the environment's diffuse light replaces the constant ambient light
        needs.add("environment_light")
        lines.append(_shade_template("ambient_environment_occluded" if ao else "ambient_environment"))
    else:
        lines.append(_shade_template("ambient_occluded" if ao else "ambient", ambient=literal(AMBIENT)))
    if passes:
        lines.append(_shade_template("passes_start",
                                     occlusion="occlusion" if ao or on["PASS_AO"] else literal(1.0)))
    if any(light.shadows != "none" for light in scene.lights):
        lines.append(_shade_template("shadow_start"))
        if scene_ir.bound is not None:
            lines.append(_shade_template("shadow_bound"))
    if not scene.lights and not sky_lit:
        lines += [_shade_template("headlight"), _lit("to_eye", _vector((1.0, 1.0, 1.0)), passes)]
    for index, light in enumerate(scene.lights):
        block, light_needs = _light_block(index, light, scene_ir.bound, on["TRANSPARENCY"], passes)
        lines.append(block)
        needs |= light_needs
    if passes and scene.lights:
        lines.append(_shade_template("shadow_share", share=literal(1.0 / len(scene.lights))))
    lines.append(_shade_template("end"))
    if passes:
        lines += ["", _shade_template("signature"), _shade_template("discarding_passes")]
    return "\n".join(lines), sorted(needs)


def _kernel_keys(scene) -> list[tuple[Parameter, object, Feature | None]]:
    """Each camera and render key (a block's keys in its place) with its
    value (None: its block is absent) and its block's feature (None: none)."""
    found = []
    for keys, values in ((CAMERA_KEYS, scene.camera), (RENDER_KEYS, scene.render)):
        for name, parameter in keys.items():
            value = getattr(values, name)
            if parameter.block is None:
                found.append((parameter, value, None))
                continue
            inner = keys_of(parameter.block)
            block_feature = next((p.feature for p in inner.values() if p.feature is not None), None)
            found += [(p, None if value is None else getattr(value, p.name), block_feature) for p in inner.values()]
    return found


def features(scene_ir: SceneIR) -> dict[str, bool]:
    """The template's optional effects, on where the scene uses them: the
    features its keys declare (Parameter.feature), then what the scene's
    shape, materials and passes need."""
    render, surface, bound = scene_ir.scene.render, scene_ir.surface, scene_ir.bound
    keys = _kernel_keys(scene_ir.scene)
    on = {p.feature.name: value is not None and p.feature.on(value) for p, value, _ in keys if p.feature is not None}
    # glow and step-count AO show the plain march (its closest approach,
    # its steps), which a feature that alters the march would skip through
    if on["GLOW"] or (render.ao > 0 and render.ao_method == "steps"):
        on.update({p.feature.name: False for p, _, _ in keys if p.feature is not None and p.feature.alters_march})
    bounded, half_spaces = bound is not None, bound is not None and bool(bound.half_spaces)
    return {
        **on,
        "TRANSPARENCY": not (ir.is_const(surface.transparency) and surface.transparency.value == 0),
        # glow needs every miss's closest approach, so misses must be marched
        "SCENE_BOUND": bounded and not on["GLOW"],
        "SCENE_HALF_SPACES": bounded and half_spaces and not on["GLOW"],
        # the passes asked for beyond the default channels (run.PASSES)
        **{f"PASS_{name.upper()}": name in render.aovs for name in PASSES},
        "SHADING_PASSES": bool(set(SHADING_PASSES) & set(render.aovs)),
        "ENVIRONMENT": pathtrace.uses_environment(render),
        # the estimate iterates (a fractal's or a formula's loop): its cost varies with the point
        "ITERATED_ESTIMATE": any(isinstance(node, ir.Loop) for node in ir.walk(scene_ir.distance)),
    }


def _key_constants(scene, on: dict[str, bool]) -> list[str]:
    """The #defines of the keys' values the kernel reads (Parameter.constant),
    each where its feature is on: numbers as float literals, whole numbers
    and truths as integers, colours as NAME_R, NAME_G, NAME_B."""
    lines = []
    for parameter, value, block_feature in _kernel_keys(scene):
        constant = parameter.constant
        if constant is None:
            continue
        gate = None if constant.always else constant.when or parameter.feature or block_feature
        if gate is not None and not on[gate.name]:
            continue
        if constant.values is not None:
            values = constant.values(value)
        else:
            values = {constant.name: {Type.WHOLE: int, Type.NUMBER: float, Type.VEC3: tuple}[parameter.type](value)}
        for name, v in values.items():
            if isinstance(v, tuple):
                lines += [f"#define {name}_{c} {literal(x)}" for c, x in zip("RGB", v)]
            else:
                lines.append(f"#define {name} {int(v) if isinstance(v, (bool, int)) else literal(v)}")
    return lines


_FEATURE_IF = re.compile(r"^#if FEATURE_(\w+)\s*$")
# a hook of the counting build (stdlib_cl/count.cl): a line of its own
_COUNT_HOOK = re.compile(r"^\s*COUNT_(EVALUATIONS|MARCH|SCOPE)\(.*\);")


def resolve_features(text: str, enabled: dict[str, bool]) -> str:
    """Keep the `#if FEATURE_X` blocks of enabled features (without their
    directives) and drop the others; other preprocessor lines stay. The
    counting build's hooks stay only in the counting build (`COUNT`)."""
    out, stack = [], []      # stack: None for a foreign #if, else whether kept
    for line in text.splitlines():
        match = _FEATURE_IF.match(line)
        keeping = all(k for k in stack if k is not None)
        if match:
            stack.append(enabled[match.group(1)])
            continue
        if line.startswith("#if"):
            stack.append(None)
        elif line.startswith("#else") and stack and stack[-1] is not None:
            stack[-1] = not stack[-1]
            continue
        elif line.startswith("#endif") and stack:
            if stack.pop() is not None:
                continue
        if keeping and (enabled["COUNT"] or not _COUNT_HOOK.match(line)):
            out.append(line)
    return "\n".join(out)


def fast_math(setting: str, target: Target) -> bool:
    """Whether the kernel uses `native_` functions: `on`, or `auto` on CPUs
    (vector lanes) whose driver's native_ functions the lane probe measured
    exact (PoCL's; the speed/error sweep measured no error growth there,
    docs/performance.md; Intel's are approximate: native_exp off by 2e-4);
    never in double, as OpenCL's `native_` functions are float-only."""
    wanted = setting == "on" or (setting == "auto" and target.lanes > 1 and target.exact_native)
    return wanted and not target.double


def lane_block(lanes: int) -> tuple[int, int]:
    """The pixel block (columns, rows) one work-item renders: as square as
    the lane count allows (16: 4 x 4, 8: 4 x 2)."""
    rows = 1
    while rows * rows * 4 <= lanes:
        rows *= 2
    return lanes // rows, rows


def _arithmetic_constants(scene_ir: SceneIR, target: Target) -> str:
    """What the prelude reads: the lanes, the precision, the math functions
    (the refined rsqrt where no native_ functions replace it, in float)."""
    native = fast_math(scene_ir.scene.render.fast_math, target)
    refined = target.refined_rsqrt and not native and not target.double
    return "\n".join([f"#define LANES {target.lanes}", f"#define PRECISION_DOUBLE {int(target.double)}",
                      f"#define FAST_MATH {int(native)}", f"#define REFINED_RSQRT {int(refined)}"])


def _constants(scene_ir: SceneIR, target: Target, on: dict[str, bool]) -> str:
    render = scene_ir.scene.render
    lanes = target.lanes
    width, height = lane_block(lanes)

    def lane_vector(values):
        return "0.0f" if lanes == 1 else f"((real)({', '.join(literal(v) for v in values)}))"
    names = channels(render.aovs)
    return "\n".join([
        _arithmetic_constants(scene_ir, target),
        *_key_constants(scene_ir.scene, on),
        f"#define CHANNELS {len(names)}",
        *(f"#define CHANNEL_{_channel_macro(name)} {i}" for i, name in enumerate(names)),
        f"#define LANES_X {width}",
        f"#define LANES_Y {height}",
        f"#define LANE_X {lane_vector([i % width for i in range(lanes)])}",
        f"#define LANE_Y {lane_vector([i // width for i in range(lanes)])}",
        *(pathtrace.environment_constants(render, literal) if on["ENVIRONMENT"] else []),
        # the counting build's counters follow the params and the derived slots (stdlib_cl/count.cl)
        *([f"#define COUNT_BASE {len(scene_ir.scene.params) + DERIVED_SLOTS}"] if target.count else []),
    ])


def _channel_macro(name: str) -> str:
    """The C name of a channel's index: N.x -> N_X, diffuse.R -> DIFFUSE_R."""
    return name.upper().replace(".", "_")


def _comment_text(text: str) -> str:
    """User text (the scene's path, a name) fit for a `//` comment: a
    newline would end the comment and a backslash or `??/` before one would
    splice the next line into it, so those and any character outside
    printable ASCII are written as escapes."""
    return "".join(c if " " <= c <= "~" and c not in "\\?" else f"\\u{ord(c):04x}" if ord(c) <= 0xFFFF
                   else f"\\U{ord(c):08x}" for c in text)


def uniform_source(values: tuple[ir.Expr, ...], double: bool) -> str:
    """A program whose kernel `uniform_values(params, out)` writes the
    values of point-independent expressions (a scene's bound, which may
    call library functions) into `out`, one work-item."""
    lib = library()
    writer = _FunctionWriter(ir.Vec(tuple(values)))
    writer.block(writer.root, "    ")
    stores = [_scene_template("uniform_store", index=i, value=writer.argument(v)) for i, v in enumerate(values)]
    source = "\n\n".join([
        _scene_template("uniform_constants", double=int(double)), lib.prelude,
        _library_text(lib.closure(sorted({name for v in values for name in _calls(v)}))),
        _scene_template("uniform_values", body=_body(writer.lines), stores=_body(stores))])
    return double_literals(source) if double else source


def emit_distance(scene_ir: SceneIR, target: Target = Target()) -> str:
    """A program of the scene's distance estimate alone, with the kernel
    `distance_at_points`: what sampling the estimate needs (Scene.distance,
    meshes, check --de), built several times faster than a render program
    (Intel's compiler: 0.2 s against 2 s for examples/csg.frac)."""
    lib = library()
    scene = scene_ir.scene
    hoisted = _lean((scene_ir.distance,), scene_ir)
    params = ", ".join(f"[{p.index}] {_comment_text(p.name)}" for p in scene.params) or "none"
    parts = [
        _scene_template("distance_header", version=__version__, file=_comment_text(scene.file), params=params,
                        slots=DERIVED_SLOTS),
        _arithmetic_constants(scene_ir, target),
        lib.prelude,
        _library_text(lib.closure(_calls(hoisted.roots[0]))),
        "// ---- the scene " + "-" * 60,
        function_source(hoisted.roots[0], _scene_template("distance_signature")),
        _derived_params(lib, hoisted.derived, len(scene.params)),
        lib.distance_kernel,
    ]
    source = "\n\n".join(p.strip("\n") for p in parts if p) + "\n"
    return double_literals(source) if target.double else source


def emit(scene_ir: SceneIR, target: Target = Target()) -> str:
    """The complete OpenCL program for a lowered scene."""
    lib = library()
    scene = scene_ir.scene
    scene_ir = dataclasses.replace(scene_ir, distance=marched_distance(scene_ir, features(scene_ir)["SCENE_BOUND"]))
    # the bound too: its radius is often the fractal's, a derived param already
    bound_values = _bound_expressions(scene_ir.bound) if scene_ir.bound is not None else ()
    hoisted = _lean((scene_ir.distance, *scene_ir.surface.items(), *bound_values), scene_ir)
    surface_end = 1 + len(scene_ir.surface.items())
    scene_ir = dataclasses.replace(
        scene_ir, distance=hoisted.roots[0], surface=type(scene_ir.surface)(*hoisted.roots[1:surface_end]),
        bound=_bound_with(scene_ir.bound, hoisted.roots[surface_end:]) if bound_values else scene_ir.bound)
    distance = function_source(scene_ir.distance, _scene_template("distance_signature"))
    on = features(scene_ir)
    on = {**on, "CONE": on["CONE"] and target.lanes > 1, "COUNT": target.count}
    shade, shading_needs = _shade_function(scene_ir, on)
    # the bound serves the march (not with glow) and the shadow rays
    shadows = any(light.shadows != "none" for light in scene.lights)
    bound = ""
    roots = [scene_ir.distance, ir.Vec(scene_ir.surface.items())]
    if scene_ir.bound is not None and (on["SCENE_BOUND"] or shadows):
        bound = _bound_function(scene_ir, on["SCENE_HALF_SPACES"] or shadows)
        shading_needs = shading_needs + ["ray_sphere_span"]
        roots.append(ir.Vec(_bound_expressions(scene_ir.bound)))
    scene_functions = lib.closure(sorted({name for root in roots for name in _calls(root)}))
    placed = {f.name for f in scene_functions}
    normal_method = f"{scene.render.normals}_normal"
    shading_functions = [f for f in lib.closure([normal_method] + shading_needs) if f.name not in placed]

    # names only: a param's default is no part of the kernel (a new default in
    # the file is no new source, so no rebuild)
    params = ", ".join(f"[{p.index}] {_comment_text(p.name)}" for p in scene.params) or "none"
    scalar = "double" if target.double else "float"
    parts = [
        _scene_template("header", version=__version__, file=_comment_text(scene.file),
                        block="{} x {}".format(*lane_block(target.lanes)),
                        real=scalar if target.lanes == 1 else f"{scalar}{target.lanes}", lanes=target.lanes,
                        scalar=scalar, params=params, slots=DERIVED_SLOTS,
                        options=" ".join(target.build_options) or "no options") + "\n",
        _constants(scene_ir, target, on),
        lib.prelude,
        lib.counting if target.count else "",
        _library_text(scene_functions),
        "// ---- the scene " + "-" * 60,
        function_source(scene_ir.distance, _scene_template("distance_signature"), counting=True)
        if target.count else distance,
        _distances(scene_ir.distance, target),
        _derived_params(lib, hoisted.derived, len(scene.params)),
        _surface_function(scene_ir), bound,
        resolve_features(_library_text(shading_functions), on),
        _normal_functions(scene.render.normals),
        shade,
        resolve_features(lib.engine, on),
        lib.distance_kernel,
        resolve_features(pathtrace.source(scene, literal, on["TRANSPARENCY"]), on) if on["PATH_TRACE"] else "",
    ]
    source = "\n\n".join(p.strip("\n") for p in parts if p) + "\n"
    return double_literals(source) if target.double else source


# The per-ray names of the prelude and what a distance estimate's text may
# use, and their scalar forms (the prelude's LANES 1 definitions).
_UNIFORM_NAMES = {"real": "scalar", "mask": "int", "lane_int": "int", "lane_uint": "uint", "lane_float": "float",
                  "vec3": "uvec3", "MASK_TRUE": "1", "ANY": "", "ALL": "", "SELECT": "UNIFORM_SELECT",
                  "TO_REAL": "(scalar)", "TO_FLOAT": "(float)", "TO_UINT": "(uint)"}
_FUNCTION_NAME = re.compile(r"^(?:ALWAYS_INLINE )?\w+ (\w+)\(", re.M)
_IDENTIFIER = re.compile(r"\b[A-Za-z_]\w*\b")


def _distances(distance: ir.Expr, target: Target) -> str:
    """`distance_estimates`: the estimate at two points, side by side
    where a work-item holds vector lanes (two chains of dependent operations
    that a CPU core overlaps; bulb-640 2.5-4.4% faster on Intel's runtime
    with its normals and occlusion in pairs, docs/performance.md), one
    after the other with one ray per work-item."""
    if target.lanes == 1:
        return _scene_template("distances_one_by_one")
    return function_source(distance, _scene_template("distances_signature"), counting=target.count, points=2)


def _lean(roots: tuple, scene_ir: SceneIR) -> Hoisted:
    """`roots` without the guards that cannot fire (fractalc/ranges.py), the
    range promises it read and the loop carries they leave idle, their
    uniform values hoisted into derived params (fractalc/hoist.py)."""
    params = scene_ir.scene.params
    declared = {p.index: (-FLOAT_MAX if p.low is None else p.low, FLOAT_MAX if p.high is None else p.high)
                for p in params}
    return hoist(ir.without_idle_carries(ir.without_promises(ranges.simplify(roots, declared))), len(params))


def _derived_kernel(derived: tuple[ir.Expr, ...], first: int) -> str:
    """The kernel `derived_params`: the hoisted values (fractalc/hoist.py)
    into the params buffer's slots from `first` on, written with the
    per-ray names that `_derived_params` renames."""
    writer = _FunctionWriter(ir.Vec(derived))
    writer.block(writer.root, "    ")
    stores = [_scene_template("derived_store", slot=first + i, value=writer.text[v]) for i, v in enumerate(derived)]
    return _scene_template("derived_params", lines=_body([*writer.lines, *stores]))


def _derived_params(lib, derived: tuple[ir.Expr, ...], first: int) -> str:
    """The derived params' kernel, with the vec3 helpers and the library
    functions it calls, in scalar types (`uvec3`, `uniform_v3`, ...: cone
    marching's axes use them too). The same text with the per-ray types
    renamed: the library is written to compile with one ray per work-item,
    which is this."""
    called = {name for e in derived for name in _calls(e)}
    vectors = lib.prelude[lib.prelude.index("typedef struct { real x, y, z; } vec3;"):]
    text = "\n\n".join([vectors, *(f.source for f in lib.closure(sorted(called))), _derived_kernel(derived, first)])
    renames = {**_UNIFORM_NAMES, **{name: f"uniform_{name}" for name in _FUNCTION_NAME.findall(text)}}
    renamed = _IDENTIFIER.sub(lambda m: renames.get(m.group(0), m.group(0)), text)
    return _scene_template("in_scalar_types", text=renamed)


def _normal_functions(method: str) -> str:
    """`estimate_normal` at any point, and `estimate_hit_normal` where a
    march hit with the estimate `here`, which forward differences reuse."""
    anywhere = at_hit = _scene_template("normal", method=method)
    if method == "forward":
        anywhere, at_hit = _scene_template("forward_normal_anywhere"), _scene_template("forward_normal_at_hit")
    return _scene_template("normals", anywhere=anywhere, at_hit=at_hit)


_FLOAT_LITERAL = re.compile(r"\b((?:\d+\.\d*|\.\d+)(?:[eE][+-]?\d+)?|\d+[eE][+-]?\d+)f\b")


def double_literals(source: str) -> str:
    """`source` with its `f` suffixes stripped: every literal a double."""
    return _FLOAT_LITERAL.sub(r"\1", source)


def _library_text(functions) -> str:
    """Library functions in order, each file's header comment once."""
    out, headers = [], set()
    for f in functions:
        if f.header and f.file not in headers:
            headers.add(f.file)
            out.append(f.header)
        out.append(f.source)
    return "\n\n".join(out)
