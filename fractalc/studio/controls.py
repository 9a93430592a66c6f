"""What the page's controls show: the params from their declarations and
the render, light and material keys from the language's own key specs
(`check_blocks.key_specs`), each with its value in the checked scene."""
from __future__ import annotations

from dataclasses import fields, is_dataclass

from .. import ast, ir
from ..check_blocks import KeySpec, key_specs
from ..parse import parse
from ..program import CheckedScene


def spec_description(spec: KeySpec) -> dict:
    return {"name": spec.name, "kind": spec.kind.value, "words": list(spec.words), "low": spec.low,
            "high": spec.high, "low_excluded": spec.low_excluded, "high_excluded": spec.high_excluded,
            "colour": spec.colour, "keys": [spec_description(k) for k in spec.keys]}


def plain(value):
    """A checked setting as JSON: numbers, words, lists for vectors, dicts
    for blocks, None for an effect that is off."""
    if is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, tuple):
        return list(value)
    return value


def material_value(value):
    """A material's key: its number or vector, or None where an expression
    of params computes it (no control sets it)."""
    if isinstance(value, ir.Vec):
        items = [material_value(x) for x in value.items]
        return None if None in items else items
    return value.value if ir.is_const(value) else None


def controls(checked: CheckedScene) -> dict:
    """The keys of the render block, of each light (in the file's order)
    and of each material the file declares, with their values."""
    render = checked.render
    render_specs, material_specs = key_specs("render"), key_specs("material")
    render_values = {spec.name: plain(getattr(render, spec.name)) for spec in render_specs}
    if render_values["environment"] is not None:
        render_values["environment"]["map"] = render.environment_map    # where the checker keeps it
    lights = []
    for light in checked.lights:
        specs = key_specs(f"light {light.kind}")
        lights.append({"kind": light.kind, "specs": [spec_description(s) for s in specs],
                       "values": {s.name: plain(light.key_value(s.name)) for s in specs}})
    declared = [d.name for d in parse(checked.source, checked.file).decls if isinstance(d, ast.MaterialDecl)]
    materials = [{"name": name, "specs": [spec_description(s) for s in material_specs],
                  "values": {s.name: material_value(getattr(checked.materials[name], s.name)) for s in material_specs}}
                 for name in declared]
    return {"render": {"specs": [spec_description(s) for s in render_specs], "values": render_values},
            "lights": lights, "materials": materials}
