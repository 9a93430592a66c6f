"""The checked scene: plain immutable values that `check` produces and the
later stages read. Numbers that may depend on params are IR expressions
(`ir.Const` once folded); the camera, lights and render settings are
constants."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Union

from . import ir
from .errors import Diagnostic, Span
from .lights import LIGHT_KINDS, LightKind
from .stdlib import Signature
from .types import (NONZERO, Constant, Feature, Parameter, Type, above, at_least, at_most, below, between, key,
                    keys_of, range_violation)
from .write import DEFAULT_TONE_CURVE, TONE_CURVES

Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class ParamInfo:
    name: str
    index: int
    default: float
    low: float | None
    high: float | None
    span: Span

    def range_violation(self, value: float) -> str | None:
        """What is wrong with `value` for this param: outside its range (None: nothing)."""
        return range_violation(self.name, value, self.low, self.high)

    def as_key(self) -> Parameter:
        """The param as a block's key (a path's keyframes, presets): a
        constant number in its range."""
        in_range = (between(self.low, self.high),) if None not in (self.low, self.high) else ()
        return Parameter(self.name, Type.NUMBER, None, in_range)


# ---- shapes ----------------------------------------------------------------

@dataclass(frozen=True)
class Primitive:
    """A library shape or fractal with its arguments in signature order."""
    signature: Signature
    args: tuple[ir.Arg, ...]
    span: Span


class CombinationKind(StrEnum):
    UNION = "union"
    INTERSECT = "intersect"
    SUBTRACT = "subtract"


@dataclass(frozen=True)
class Combination:
    kind: CombinationKind
    shapes: tuple["Shape", ...]
    smooth: ir.Expr
    span: Span


@dataclass(frozen=True)
class Transformed:
    kind: str                   # a key of transforms.TRANSFORMS
    shape: "Shape"
    args: tuple[ir.Arg, ...]
    span: Span


@dataclass(frozen=True)
class Coloring:
    """`orbit_trap(near, far, trap, scale)` or `palette(a, b, c, d, trap,
    scale)`: colour by the orbit trap. A palette's `near` and `far` are
    its colour at t = 0 (what shapes that are not fractals show)."""
    near: ir.Vec
    far: ir.Vec
    trap: str                   # one of stdlib.TRAP_KINDS
    scale: ir.Expr | None       # None: `auto`, spread over the trap's range (fractalc/lower.py)
    palette: tuple[ir.Vec, ir.Vec, ir.Vec, ir.Vec] | None = None   # a, b, c, d


def cosine_palette(palette: tuple[ir.Vec, ir.Vec, ir.Vec, ir.Vec], t: ir.Expr) -> ir.Vec:
    """A cosine palette's colour a + b cos(2 pi (c t + d)) (Quilez,
    "palettes"), at least 0."""
    def channel(a, b, c, d):
        phase = ir.mul(ir.const(2 * math.pi), ir.add(ir.mul(c, t), d))
        return ir.op("max", ir.add(a, ir.mul(b, ir.op("cos", phase))), ir.const(0.0))
    return ir.Vec(tuple(channel(*items) for items in zip(*(v.items for v in palette))))


@dataclass(frozen=True)
class WithMaterial:
    shape: "Shape"
    material: str               # a key of CheckedScene.materials
    span: Span
    coloring: Coloring | None = None   # fractals inside take their colour from it


@dataclass(frozen=True)
class Fractal:
    """`fractal(formula, ...)`: the fractal of a formula written in the
    language, or of a hybrid of several (fractalc/formula_code.py)."""
    sequence: tuple                       # formula_code.Use, in turn
    iterations: ir.Expr
    bailout: ir.Expr | None               # None: no bailout
    julia: ir.Vec | None                  # c: this constant, not the point
    bound: ir.Expr | None                 # a radius holding the fractal (None: not known)
    step: ir.Expr                         # the estimate's factor: check --de's safe step factor
    span: Span
    growth: object = None                 # formula_code.Growth: |z|'s growth measured, the estimate's kind
    estimate_reason: str | None = None    # which estimate the kind chose and why (None: the formula's final lines)


Shape = Union[Primitive, Combination, Transformed, WithMaterial, Fractal]


def fold_shape(root: Shape, context, parts, combine):
    """A value computed over a shape tree bottom-up, without recursion (let
    chains make trees of any depth). `parts(shape, context)` lists the
    (part, context) pairs a shape is made of; `combine(shape, context,
    values)` gives its value from its parts' values, in that order."""
    values: list = []
    stack = [(root, context, None)]
    while stack:
        shape, here, count = stack.pop()
        if count is None:
            children = parts(shape, here)
            stack.append((shape, here, len(children)))
            stack.extend((child, there, None) for child, there in reversed(children))
            continue
        start = len(values) - count
        made = combine(shape, here, values[start:])
        del values[start:]
        values.append(made)
    return values[0]


# ---- the rest of the scene -------------------------------------------------

@dataclass(frozen=True)
class Material:
    """A material block's values (IR: they may depend on params); its
    keys' defaults are the default material's (`default_material`)."""
    name: str
    color: ir.Vec = key((0.8, 0.8, 0.8), Type.VEC3, between(0, 1000), field_default=False)
    specular: ir.Expr = key(0.3, Type.NUMBER, between(0, 1), field_default=False)
    shininess: ir.Expr = key(32.0, Type.NUMBER, above(0), field_default=False)
    reflectivity: ir.Expr = key(0.0, Type.NUMBER, between(0, 1), field_default=False)
    transparency: ir.Expr = key(0.0, Type.NUMBER, between(0, 1), field_default=False)
    ior: ir.Expr = key(1.5, Type.NUMBER, between(1, 10), field_default=False)


MATERIAL_KEYS = keys_of(Material)


# Names the compiler makes (this one, `.color(...)`'s materials) hold
# characters a name in a scene cannot: no material of the file replaces them.
DEFAULT_MATERIAL = "(default)"


def default_material() -> Material:
    return Material(DEFAULT_MATERIAL, **{name: constant(p.default) for name, p in MATERIAL_KEYS.items()})


def constant(value) -> ir.Expr | ir.Vec:
    """A default's number or tuple as IR constants."""
    return ir.Vec(tuple(ir.const(x) for x in value)) if isinstance(value, tuple) else ir.const(value)


# A camera's projections and stereo layouts, in the order of their codes in
# the kernel's camera block (stdlib_cl/engine/interface.cl, CAMERA_PROJECTION).
class Projection(StrEnum):
    PINHOLE = "pinhole"
    FISHEYE = "fisheye"
    EQUIRECTANGULAR = "equirectangular"


class StereoLayout(StrEnum):
    NONE = "none"
    SIDE_BY_SIDE = "side_by_side"
    TOP_BOTTOM = "top_bottom"


PROJECTIONS = tuple(Projection)
STEREO_LAYOUTS = tuple(StereoLayout)


@dataclass(frozen=True)
class Camera:
    position: Vector3 = key((0.0, -5.0, 2.0), Type.VEC3)
    target: Vector3 = key((0.0, 0.0, 0.0), Type.VEC3)
    up: Vector3 = key((0.0, 0.0, 1.0), Type.VEC3, NONZERO)
    fov: float = key(45.0, Type.NUMBER, above(0), below(180))
    aperture: float = key(0.0, Type.NUMBER, at_least(0), feature=Feature("DEPTH_OF_FIELD", lambda a: a > 0))
    focus: float | None = key(None, Type.NUMBER, above(0))
    projection: Projection = key(Projection.PINHOLE, Type.WORD, words=Projection)
    # a fisheye's angle across the image height, degrees
    fisheye_fov: float = key(180.0, Type.NUMBER, above(0), at_most(360))
    # where the two eyes' images go
    stereo: StereoLayout = key(StereoLayout.NONE, Type.WORD, words=StereoLayout)
    # distance between the eyes of a stereo camera
    eye_separation: float = key(0.065, Type.NUMBER, at_least(0))

    def aim_problem(self, keys_quoted: bool = False) -> tuple[str, str] | None:
        """(the key at fault, what is wrong) where the camera cannot aim:
        its target is its position, or its up lies along the view
        (`keys_quoted`: the message quotes the keys, as the API's do)."""
        forward = [t - p for t, p in zip(self.target, self.position)]
        if _norm(forward) == 0:
            target, position = ("'target'", "'position'") if keys_quoted else ("target", "position")
            return "target", f"the camera's {target} is its {position}: it looks nowhere"
        if _norm(_cross(forward, self.up)) <= 1e-9 * _norm(forward) * _norm(self.up):
            return "up", "the camera's 'up' is parallel to its view direction (target - position)"
        return None

    def aimed(self, up_given: bool, keys_quoted: bool = False) -> "Camera":
        """The camera as checked: looking straight along the default up
        (not given), y is up instead; ValueError where it cannot aim."""
        problem = self.aim_problem(keys_quoted)
        if problem is None:
            return self
        if problem[0] == "up" and not up_given:
            return replace(self, up=(0.0, 1.0, 0.0))
        raise ValueError(problem[1])


CAMERA_KEYS = keys_of(Camera)


def _norm(v) -> float:
    return math.sqrt(sum(x * x for x in v))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


class Shadows(StrEnum):
    NONE = "none"
    HARD = "hard"
    SOFT = "soft"


def light_vector_key(kind: str) -> str:
    """The key of a light block that `Light.vector` holds: the way a
    directional light travels, any other light's position."""
    return "direction" if LIGHT_KINDS[kind].directional else "position"


@dataclass(frozen=True)
class Light:
    kind: LightKind
    vector: Vector3             # direction the light travels, or position
    color: Vector3 = key((1.0, 1.0, 1.0), Type.VEC3, at_least(0))
    intensity: float = key(1.0, Type.NUMBER, at_least(0))
    shadows: Shadows = key(Shadows.HARD, Type.WORD, words=Shadows)
    softness: float = key(16.0, Type.NUMBER, above(0))
    # spot: the cone's axis, the way it points
    direction: Vector3 = key((0.0, 0.0, -1.0), Type.VEC3, NONZERO)
    # spot: full brightness within this angle of the axis, degrees ...
    angle: float = key(30.0, Type.NUMBER, above(0), below(180))
    # ... then fading to none over this many degrees more
    falloff: float = key(10.0, Type.NUMBER, at_least(0), at_most(180))
    radius: float = key(0.25, Type.NUMBER, above(0))    # sphere: the light's radius
    width: float = key(1.0, Type.NUMBER, above(0))      # rectangle: its size along `right` ...
    height: float = key(1.0, Type.NUMBER, above(0))     # ... and along `up` (rectangle_edges)

    def key_value(self, key: str):
        """The value of the light block's key `key`, as checked."""
        return self.vector if key == light_vector_key(self.kind) else getattr(self, key)

    def rectangle_edges(self) -> tuple[Vector3, Vector3]:
        """A rectangle light's edges, width along `right` (horizontal, across
        `direction`; along x where `direction` is vertical) and height along
        `up` = right x direction: (width * right, height * up)."""
        length = math.sqrt(sum(c * c for c in self.direction))
        n = [c / length for c in self.direction]
        right = (n[1], -n[0], 0.0) if abs(n[2]) < 0.999999 else (1.0, 0.0, 0.0)
        across = math.sqrt(sum(c * c for c in right))
        right = [c / across for c in right]
        up = (right[1] * n[2] - right[2] * n[1], right[2] * n[0] - right[0] * n[2], right[0] * n[1] - right[1] * n[0])
        return tuple(self.width * c for c in right), tuple(self.height * c for c in up)

    def cone_cosines(self) -> tuple[float, float]:
        """A spot's cosines of the angle where its light starts fading
        (inner) and where it ends (outer)."""
        inner = math.radians(self.angle)
        return math.cos(inner), math.cos(min(inner + math.radians(self.falloff), math.pi))


# A light block's keys by kind (lights.LIGHT_KINDS: in the order messages
# list them): the Light's fields, a position (Light.vector) and, for an
# aimed light, a target instead of its direction.
_LIGHT_PLACE = (Parameter("position", Type.VEC3), Parameter("target", Type.VEC3))
_ALL_LIGHT_KEYS = keys_of(Light, *_LIGHT_PLACE)
LIGHT_KEYS = {LightKind(word): {name: _ALL_LIGHT_KEYS[name] for name in kind.keys}
              for word, kind in LIGHT_KINDS.items()}


@dataclass(frozen=True)
class Glow:
    """Light around the surface for rays that miss: strength * exp(-closest / radius)."""
    color: Vector3 = key((1.0, 0.8, 0.5), Type.VEC3, at_least(0), constant="GLOW")
    strength: float = key(1.0, Type.NUMBER, at_least(0), feature=Feature("GLOW", lambda s: s > 0),
                          constant="GLOW_STRENGTH")
    radius: float = key(0.1, Type.NUMBER, above(0), constant="GLOW_RADIUS")


@dataclass(frozen=True)
class Fog:
    """Exponential distance fog: colour mixes toward `color` by 1 - exp(-density t)."""
    color: Vector3 = key((0.5, 0.6, 0.7), Type.VEC3, at_least(0), constant="FOG")
    density: float = key(0.1, Type.NUMBER, at_least(0), feature=Feature("FOG", lambda d: d > 0), constant="FOG_DENSITY")


@dataclass(frozen=True)
class Slice:
    """Cuts away the part of the scene where dot(p, normalize(normal)) > offset."""
    normal: Vector3 = key((0.0, -1.0, 0.0), Type.VEC3, NONZERO)
    offset: float = key(0.0, Type.NUMBER)


@dataclass(frozen=True)
class Environment:
    """The path tracer's sky: radiance `horizon` at the horizon, blending
    linearly with the height of the direction to `zenith` straight up and
    `ground` straight down, times `intensity`."""
    zenith: Vector3 = key((0.35, 0.5, 0.9), Type.VEC3, at_least(0))
    horizon: Vector3 = key((0.9, 0.9, 0.95), Type.VEC3, at_least(0))
    ground: Vector3 = key((0.3, 0.27, 0.25), Type.VEC3, at_least(0))
    intensity: float = key(1.0, Type.NUMBER, at_least(0))
    # the file's `map`: the checker moves it to RenderSettings.environment_map
    map: str | None = key(None, Type.FILE)


class Precision(StrEnum):
    FLOAT = "float"
    DOUBLE = "double"


class AoMethod(StrEnum):
    NORMAL = "normal"       # sample along the normal
    STEPS = "steps"         # from the step count


class Switch(StrEnum):
    ON = "on"
    OFF = "off"


class Normals(StrEnum):
    """Finite differences of the estimate: tetrahedral (4 evaluations), central (6) or forward (4)."""
    TETRAHEDRAL = "tetrahedral"
    CENTRAL = "central"
    FORWARD = "forward"


class FastMath(StrEnum):
    """on: native_ transcendental functions; auto: on CPUs."""
    AUTO = "auto"
    ON = "on"
    OFF = "off"


class Integrator(StrEnum):
    DIRECT = "direct"       # Blinn-Phong and the effects
    PATH = "path"           # Monte Carlo path tracing


# The hit threshold's largest multiple: normals are differences over that
# step, which beyond it can pass float's range on the scene (NaN normals).
MAX_EPSILON_SCALE = 1000

# The path tracer's part of the kernel: `integrator`'s feature, which `bounces` is written under too
PATH_TRACE = Feature("PATH_TRACE", lambda integrator: integrator == Integrator.PATH)


@dataclass(frozen=True)
class RenderSettings:
    """A render block's keys (`runtime`: kernel arguments, changed without
    a rebuild; exposure and tonemap only PNG writing reads)."""
    width: int = key(640, Type.WHOLE, at_least(1), at_most(65536), runtime=True)
    height: int = key(480, Type.WHOLE, at_least(1), at_most(65536), runtime=True)
    max_steps: int = key(256, Type.WHOLE, between(1, 100000), constant="MAX_STEPS")
    max_distance: float = key(50.0, Type.NUMBER, above(0), constant="MAX_DISTANCE")
    # a number, or "pixel": the threshold grows with the distance, a pixel's footprint (stdlib_cl/engine/hits.cl)
    epsilon: float | str = key("pixel", Type.NUMBER, above(0), words=("pixel",), constant=Constant(values=lambda e: {
        "HIT_EPSILON_IS_PIXEL": e == "pixel", "HIT_EPSILON": 0.0 if e == "pixel" else float(e)}))
    ao: float = key(0.0, Type.NUMBER, between(0, 1))
    samples: int = key(1, Type.WHOLE, at_least(1), at_most(4096), runtime=True)
    background: Vector3 | str = key((0.05, 0.05, 0.08), Type.VEC3, at_least(0), words=("transparent",),
                                    feature=Feature("TRANSPARENT_BACKGROUND", lambda b: b == "transparent"),
                                    constant=Constant(values=lambda b: {
                                        "BACKGROUND": (0.0, 0.0, 0.0) if b == "transparent" else b}, always=True))
    precision: Precision = key(Precision.FLOAT, Type.WORD, words=Precision)
    reflections: int = key(0, Type.WHOLE, between(0, 16), feature=Feature("REFLECTIONS", lambda r: r > 0),
                           constant="REFLECTIONS")
    glow: Glow | None = key(None, Type.BLOCK, block=Glow)
    fog: Fog | None = key(None, Type.BLOCK, block=Fog)
    slice: Slice | None = key(None, Type.BLOCK, block=Slice)
    ao_method: AoMethod = key(AoMethod.NORMAL, Type.WORD, words=AoMethod)
    # random fraction of the first step, against banding
    dither: float = key(1.0, Type.NUMBER, between(0, 1), feature=Feature("DITHER", lambda d: d > 0), constant="DITHER")
    # over-relaxation factor of sphere tracing (1 = plain)
    overrelax: float = key(1.3, Type.NUMBER, between(1, 1.99),
                           feature=Feature("OVERRELAX", lambda o: o > 1, alters_march=True), constant="OVERRELAX")
    # march a work-item's packet of camera rays as one cone first (CPU lanes: emit clears it for one ray a work-item)
    cone_marching: Switch = key(Switch.ON, Type.WORD, words=Switch,
                                feature=Feature("CONE", lambda c: c == Switch.ON, alters_march=True))
    # multiplies the hit threshold (a quality knob)
    epsilon_scale: float = key(1.0, Type.NUMBER, above(0), at_most(MAX_EPSILON_SCALE), constant="EPSILON_SCALE")
    # the march keeps its last estimate for the forward differences that reuse it
    normals: Normals = key(Normals.TETRAHEDRAL, Type.WORD, words=Normals,
                           feature=Feature("FORWARD_NORMALS", lambda n: n == Normals.FORWARD))
    fast_math: FastMath = key(FastMath.AUTO, Type.WORD, words=FastMath)
    # stops: PNG colour times 2^exposure (EXR stays as rendered)
    exposure: float = key(0.0, Type.NUMBER, between(-20, 20), runtime=True)
    # PNG tone curve: soft (a shoulder above 0.8) | none (clip) | reinhard | aces
    tonemap: str = key(DEFAULT_TONE_CURVE, Type.WORD, words=TONE_CURVES, runtime=True)
    integrator: Integrator = key(Integrator.DIRECT, Type.WORD, words=Integrator, feature=PATH_TRACE)
    # path: the most surface scatterings of a path
    bounces: int = key(4, Type.WHOLE, between(1, 64), constant=Constant("BOUNCES", when=PATH_TRACE))
    # path: the sky; None: the background everywhere
    environment: Environment | None = key(None, Type.BLOCK, block=Environment)
    environment_map: str | None = None       # an equirectangular image, the sky instead; not a file key
    aovs: tuple[str, ...] = ()       # passes beyond the default channels (run.PASSES); not a file key


RENDER_KEYS = keys_of(RenderSettings)


@dataclass(frozen=True)
class ParamCheck:
    """A range check on a value that depends on params, made whenever the
    params change (LANGUAGE.md: values outside their range are errors)."""
    span: Span
    value: object                # ir.Expr or ir.Vec
    parameter: Parameter
    owner: str
    others: dict = field(default_factory=dict, hash=False)   # other arguments a constraint names


@dataclass(frozen=True)
class Keyframe:
    """A path keyframe: the camera values and param values given at `time`
    (None, or no entry in `params`: not given here; see `paths`)."""
    time: float
    position: Vector3
    target: Vector3 | None = None
    up: Vector3 | None = None
    fov: float | None = None
    aperture: float | None = None
    focus: float | None = None
    params: tuple[tuple[str, float], ...] = ()    # (name, value) in the order written


@dataclass(frozen=True)
class CameraPath:
    """A `path` declaration: two or more keyframes, times increasing."""
    keyframes: tuple[Keyframe, ...]
    span: Span

    @property
    def start(self) -> float:
        return self.keyframes[0].time

    @property
    def end(self) -> float:
        return self.keyframes[-1].time


@dataclass(frozen=True)
class Preset:
    """A `preset` declaration: values of params saved under a name."""
    name: str
    params: tuple[tuple[str, float], ...]    # (name, value) in the order written
    span: Span


@dataclass(frozen=True)
class CheckedScene:
    file: str
    source: str
    params: tuple[ParamInfo, ...]
    materials: dict = field(hash=False)      # name -> Material, DEFAULT_MATERIAL first
    shape: Shape = None
    camera: Camera = Camera()
    lights: tuple[Light, ...] = ()           # empty: a headlight
    render: RenderSettings = RenderSettings()
    param_checks: tuple[ParamCheck, ...] = ()
    path: CameraPath | None = None
    presets: tuple[Preset, ...] = ()
    notes: tuple[Diagnostic, ...] = field(default=(), compare=False)   # what check says of a scene it accepts
