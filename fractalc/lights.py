"""The scene's lights in the kernel, for both integrators: each light
kind's entry says how the direct renderer's `shade` writes it (which
templates of stdlib_cl/shade.cl, with which values: fractalc/emit.py
fills them in) and its code in the path tracer's LIGHTS table, whose rows
`lights_table` writes in the layout LIGHT_FIELDS (read by name in
stdlib_cl/pathtrace.cl)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from .program import CheckedScene, Light

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


def _from_direction(light: Light) -> Filled:
    # the file gives the direction the light travels
    return "light_from_direction", {"to_light": tuple(-c for c in _unit(light.vector))}


def _from_position(light: Light) -> Filled:
    return "light_from_position", {"position": tuple(light.vector), "max_inverse_square": MAX_INVERSE_SQUARE}


def _cone(light: Light) -> tuple[float, float]:
    """A spot's cone cosines, outer and inner (kept apart: smoothstep's edges)."""
    inner, outer = light.cone_cosines()
    return outer, max(inner, outer + 1e-6)


def _spot_cone(light: Light) -> Filled:
    outer, inner = _cone(light)
    return "spot_cone", {"outer": outer, "inner": inner, "axis": _unit(light.direction)}


def _rectangle_facing(light: Light) -> Filled:
    return "rectangle_facing", {"facing": _unit(light.direction)}


@dataclass(frozen=True)
class LightKind:
    code: int                           # the kind's code in the path tracer's LIGHTS table (LIGHT_IS_KIND)
    # the direct renderer: where the light comes from (toward it, how far,
    # how bright), and what then shapes its radiance
    origin: Callable[[Light], Filled]
    shaping: tuple[Callable[[Light], Filled], ...]


# Sphere and rectangle lights shine from their centres in the direct
# renderer; the path tracer samples their areas (stdlib_cl/pathtrace.cl).
LIGHT_KINDS = {
    "directional": LightKind(0, _from_direction, ()),
    "point": LightKind(1, _from_position, ()),
    "spot": LightKind(3, _from_position, (_spot_cone,)),
    "sphere": LightKind(4, _from_position, ()),
    "rectangle": LightKind(5, _from_position, (_rectangle_facing,)),
}
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


def lights_table(scene: CheckedScene) -> list[list[float]]:
    rows = []
    for light in scene.lights:
        vector = light.vector
        if light.kind == "directional":   # the file gives the direction light travels
            length = math.sqrt(sum(c * c for c in vector))
            vector = tuple(-c / length for c in vector)
        length = math.sqrt(sum(c * c for c in light.direction))
        # a spot's cone cosines, or a sphere light's radius
        cone = (light.radius, 0.0) if light.kind == "sphere" else _cone(light)
        edges = sum(light.rectangle_edges(), ()) if light.kind == "rectangle" else (0.0,) * 6
        rows.append(_light_row(LIGHT_KINDS[light.kind].code, vector, light.color, light.intensity,
                               light.shadows != "none", tuple(c / length for c in light.direction), cone, edges))
    if not rows and scene.render.environment is None and scene.render.environment_map is None:
        # nothing lights the scene: a headlight
        rows.append(_light_row(HEADLIGHT, (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, True))
    return rows
