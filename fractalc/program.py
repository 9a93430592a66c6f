"""The checked scene: plain immutable values that `check` produces and the
later stages read. Numbers that may depend on params are IR expressions
(`ir.Const` once folded); the camera, lights and render settings are
constants."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Union

from . import ir
from .errors import Diagnostic, Span
from .stdlib import Parameter, Signature
from .write import DEFAULT_TONE_CURVE

Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class ParamInfo:
    name: str
    index: int
    default: float
    low: float | None
    high: float | None
    span: Span


# ---- shapes ----------------------------------------------------------------

@dataclass(frozen=True)
class Primitive:
    """A library shape or fractal with its arguments in signature order."""
    signature: Signature
    args: tuple[ir.Arg, ...]
    span: Span


@dataclass(frozen=True)
class Combination:
    kind: str                   # union | intersect | subtract
    shapes: tuple["Shape", ...]
    smooth: ir.Expr
    span: Span


@dataclass(frozen=True)
class Transformed:
    kind: str                   # a key of stdlib.TRANSFORMS other than material/color
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
    name: str
    color: ir.Vec
    specular: ir.Expr
    shininess: ir.Expr
    reflectivity: ir.Expr
    transparency: ir.Expr
    ior: ir.Expr


# Names the compiler makes (this one, `.color(...)`'s materials) hold
# characters a name in a scene cannot: no material of the file replaces them.
DEFAULT_MATERIAL = "(default)"


# A camera's projections and stereo layouts, in the order of their codes in
# the kernel's camera block (stdlib_cl/engine/interface.cl, CAMERA_PROJECTION).
PROJECTIONS = ("pinhole", "fisheye", "equirectangular")
STEREO_LAYOUTS = ("none", "side_by_side", "top_bottom")


@dataclass(frozen=True)
class Camera:
    position: Vector3 = (0.0, -5.0, 2.0)
    target: Vector3 = (0.0, 0.0, 0.0)
    up: Vector3 = (0.0, 0.0, 1.0)
    fov: float = 45.0
    aperture: float = 0.0
    focus: float | None = None
    projection: str = "pinhole"      # PROJECTIONS
    fisheye_fov: float = 180.0       # a fisheye's angle across the image height, degrees
    stereo: str = "none"             # STEREO_LAYOUTS: where the two eyes' images go
    eye_separation: float = 0.065    # distance between the eyes of a stereo camera


def light_vector_key(kind: str) -> str:
    """The key of a light block that `Light.vector` holds: the way a
    directional light travels, any other light's position."""
    return "direction" if kind == "directional" else "position"


@dataclass(frozen=True)
class Light:
    kind: str                   # directional | point | spot
    vector: Vector3             # direction the light travels, or position
    color: Vector3 = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    shadows: str = "hard"       # none | hard | soft
    softness: float = 16.0
    direction: Vector3 = (0.0, 0.0, -1.0)   # spot: the cone's axis, the way it points
    angle: float = 30.0         # spot: full brightness within this angle of the axis, degrees
    falloff: float = 10.0       # spot: then fading to none over this many degrees more
    radius: float = 0.25        # sphere: the light's radius
    width: float = 1.0          # rectangle: its size along `right` ...
    height: float = 1.0         # ... and along `up` (rectangle_edges)

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


@dataclass(frozen=True)
class Glow:
    """Light around the surface for rays that miss: strength * exp(-closest / radius)."""
    color: Vector3 = (1.0, 0.8, 0.5)
    strength: float = 1.0
    radius: float = 0.1


@dataclass(frozen=True)
class Fog:
    """Exponential distance fog: colour mixes toward `color` by 1 - exp(-density t)."""
    color: Vector3 = (0.5, 0.6, 0.7)
    density: float = 0.1


@dataclass(frozen=True)
class Slice:
    """Cuts away the part of the scene where dot(p, normalize(normal)) > offset."""
    normal: Vector3 = (0.0, -1.0, 0.0)
    offset: float = 0.0


@dataclass(frozen=True)
class Environment:
    """The path tracer's sky: radiance `horizon` at the horizon, blending
    linearly with the height of the direction to `zenith` straight up and
    `ground` straight down, times `intensity`."""
    zenith: Vector3 = (0.35, 0.5, 0.9)
    horizon: Vector3 = (0.9, 0.9, 0.95)
    ground: Vector3 = (0.3, 0.27, 0.25)
    intensity: float = 1.0
    map: str | None = None    # the file's `map`: the checker moves it to RenderSettings.environment_map


@dataclass(frozen=True)
class RenderSettings:
    width: int = 640
    height: int = 480
    max_steps: int = 256
    max_distance: float = 50.0
    epsilon: float | str = "pixel"   # a number, or "pixel"
    ao: float = 0.0
    samples: int = 1
    background: Vector3 | str = (0.05, 0.05, 0.08)   # or "transparent"
    precision: str = "float"
    reflections: int = 0
    glow: Glow | None = None
    fog: Fog | None = None
    slice: Slice | None = None
    ao_method: str = "normal"        # normal: sample along the normal; steps: from the step count
    dither: float = 1.0              # random fraction of the first step, against banding
    overrelax: float = 1.3           # over-relaxation factor of sphere tracing (1 = plain)
    cone_marching: str = "on"        # march a work-item's packet of camera rays as one cone first (CPU lanes)
    epsilon_scale: float = 1.0       # multiplies the hit threshold (a quality knob)
    normals: str = "tetrahedral"     # finite differences: tetrahedral (4 evaluations) or central (6)
    fast_math: str = "auto"          # on: native_ transcendental functions; auto: on CPUs
    exposure: float = 0.0            # stops: PNG colour times 2^exposure (EXR stays as rendered)
    tonemap: str = DEFAULT_TONE_CURVE   # PNG tone curve: soft (a shoulder above 0.8) | none (clip) | reinhard | aces
    integrator: str = "direct"       # direct: Blinn-Phong and the effects; path: Monte Carlo path tracing
    bounces: int = 4                 # path: the most surface scatterings of a path
    environment: Environment | None = None   # path: the sky; None: the background everywhere
    environment_map: str | None = None       # an equirectangular image, the sky instead; not a file key
    aovs: tuple[str, ...] = ()       # passes beyond the default channels (run.PASSES); not a file key


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
