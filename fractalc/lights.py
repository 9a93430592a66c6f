"""The light kinds, for both integrators and the checker: each kind's
entry of LIGHT_KINDS gives its word (program.LightKind is made from
them), its block's keys, whether it is an area light, how the direct
renderer's `shade` writes it (which templates of stdlib_cl/shade.cl, with
which values: fractalc/emit.py fills them in) and its code in the path
tracer's LIGHTS table, whose rows `lights_table` writes in the layout
LIGHT_FIELDS (read by name in stdlib_cl/pathtrace.cl). The functions here
take a program.Light and a program.CheckedScene (program imports this
module, so it is not imported here)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Callable

# A light's radiance, and a point light's inverse-square factor, are capped so
# that sums of lights, their reflections and fog stay finite in float (no
# inf, no inf * 0 = NaN under a shadow) however bright the scene makes them
MAX_RADIANCE = 1e20
MAX_INVERSE_SQUARE = 1e8
MAX_IRRADIANCE = 1e20  # the path tracer's light values stay within float's range too

# A template of stdlib_cl/shade.cl and its values: numbers, or vectors as tuples
Filled = tuple[str, dict]


def _unit(v) -> tuple[float, ...]:
    length = sum(c * c for c in v) ** 0.5
    return tuple(c / length for c in v)


def _from_direction(light) -> Filled:
    # the file gives the direction the light travels
    return "light_from_direction", {"to_light": tuple(-c for c in _unit(light.vector))}


def _from_position(light) -> Filled:
    return "light_from_position", {"position": tuple(light.vector), "max_inverse_square": MAX_INVERSE_SQUARE}


def _cone(light) -> tuple[float, float]:
    """A spot's cone cosines, outer and inner (kept apart: smoothstep's edges)."""
    inner, outer = light.cone_cosines()
    return outer, max(inner, outer + 1e-6)


def _spot_cone(light) -> Filled:
    outer, inner = _cone(light)
    return "spot_cone", {"outer": outer, "inner": inner, "axis": _unit(light.direction)}


def _rectangle_facing(light) -> Filled:
    return "rectangle_facing", {"facing": _unit(light.direction)}


# The keys every light block takes, after its kind's own
COMMON_KEYS = ("color", "intensity", "shadows", "softness")


@dataclass(frozen=True)
class LightKindEntry:
    word: str                           # the kind's word in a file (`light WORD { ... }`)
    # its block's keys, in the order messages list them: Light's fields, a
    # `position` (Light.vector), and for an aimed light a `target` instead of its direction
    keys: tuple[str, ...]
    code: int                           # the kind's code in the path tracer's LIGHTS table (LIGHT_IS_KIND)
    # Light.vector is the way its light travels (a `direction` key), not its position
    directional: bool
    # the path tracer samples its area; the direct renderer shines it from
    # its centre, with soft shadows (unless the file says) as a stand-in
    area: bool
    # the direct renderer: what shapes its radiance after its origin
    shaping: tuple[Callable[[object], Filled], ...]

    def origin(self, light) -> Filled:
        """The direct renderer's template of where `light` comes from
        (toward it, how far, how bright), with its values."""
        return _from_direction(light) if self.directional else _from_position(light)


LIGHT_KINDS = {entry.word: entry for entry in (
    LightKindEntry("directional", ("direction", *COMMON_KEYS), code=0, directional=True, area=False, shaping=()),
    LightKindEntry("point", ("position", *COMMON_KEYS), code=1, directional=False, area=False, shaping=()),
    LightKindEntry("spot", ("position", "direction", "target", *COMMON_KEYS, "angle", "falloff"), code=3,
                   directional=False, area=False, shaping=(_spot_cone,)),
    LightKindEntry("sphere", ("position", "radius", *COMMON_KEYS), code=4, directional=False, area=True, shaping=()),
    LightKindEntry("rectangle", ("position", "direction", "target", "width", "height", *COMMON_KEYS), code=5,
                   directional=False, area=True, shaping=(_rectangle_facing,)),
)}
# The kinds as words of the language (LightKind.SPOT == "spot")
LightKind = StrEnum("LightKind", [(word.upper(), word) for word in LIGHT_KINDS])
HEADLIGHT = 2          # no lights in the scene: a light at the eye

# A row of the kernel's LIGHTS table: each field and its width, in order;
# the kernel reads them by name (`LIGHT_KIND`, `LIGHT_VECTOR`, ...: the
# #defines of `light_layout`). `vector`: the direction toward the light, or
# its position; `irradiance`: pi colour intensity (a white diffuse surface
# facing the light shows colour intensity, as in the direct renderer);
# `shadows`: 1 or 0; `axis`: a spot's or rectangle's unit axis; a spot's
# cone cosines (a sphere's radius where a spot has its outer one); a
# rectangle's two edges.
LIGHT_FIELDS = (("kind", 1), ("vector", 3), ("irradiance", 3), ("shadows", 1), ("axis", 3),
                ("cone_outer", 1), ("cone_inner", 1), ("width", 3), ("height", 3))
LIGHT_RADIUS = "cone_outer"    # the field that holds a sphere light's radius
LIGHT_STRIDE = sum(width for _, width in LIGHT_FIELDS)


def light_layout() -> list[str]:
    """The table's layout and the light kinds' codes, as #defines."""
    offsets, at = {}, 0
    for name, width in LIGHT_FIELDS:
        offsets[name], at = at, at + width
    return [*(f"#define LIGHT_{name.upper()} {offset}" for name, offset in offsets.items()),
            f"#define LIGHT_RADIUS {offsets[LIGHT_RADIUS]}", f"#define LIGHT_STRIDE {LIGHT_STRIDE}",
            *(f"#define LIGHT_IS_{name.upper()} {kind.code}" for name, kind in LIGHT_KINDS.items()),
            f"#define LIGHT_IS_HEADLIGHT {HEADLIGHT}"]


def _light_row(kind: int, vector, color, intensity: float, shadows: bool,
               axis=(0.0, 0.0, -1.0), cone=(-1.0, -1.0), edges=(0.0,) * 6) -> list[float]:
    """The table's row of a light (LIGHT_FIELDS)."""
    irradiance = [min(math.pi * c * intensity, MAX_IRRADIANCE) for c in color]
    fields = {"kind": (float(kind),), "vector": vector, "irradiance": irradiance, "shadows": (1.0 if shadows else 0.0,),
              "axis": axis, "cone_outer": cone[:1], "cone_inner": cone[1:], "width": edges[:3], "height": edges[3:]}
    return [float(v) for name, _ in LIGHT_FIELDS for v in fields[name]]


def lights_table(scene) -> list[list[float]]:
    rows = []
    for light in scene.lights:
        kind = LIGHT_KINDS[light.kind]
        vector = light.vector
        if kind.directional:   # the file gives the direction light travels
            length = math.sqrt(sum(c * c for c in vector))
            vector = tuple(-c / length for c in vector)
        length = math.sqrt(sum(c * c for c in light.direction))
        # a spot's cone cosines, or a sphere light's radius
        cone = (light.radius, 0.0) if light.kind == "sphere" else _cone(light)
        edges = sum(light.rectangle_edges(), ()) if light.kind == "rectangle" else (0.0,) * 6
        rows.append(_light_row(kind.code, vector, light.color, light.intensity, light.shadows != "none",
                               tuple(c / length for c in light.direction), cone, edges))
    if not rows and scene.render.environment is None and scene.render.environment_map is None:
        # nothing lights the scene: a headlight
        rows.append(_light_row(HEADLIGHT, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, True))
    return rows
