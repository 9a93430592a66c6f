"""The checker's blocks: each key of a material, camera, light, render
block, path keyframe and preset against its Parameter (declared beside its
field, fractalc/program.py), and the keys as an editor's controls see
them (`key_specs`)."""
from __future__ import annotations

import os
from dataclasses import dataclass, replace
from enum import Enum

from . import ast, ir, pathtrace
from .check_base import WORD, CheckerBase, Failed, source_text
from .errors import Span
from .lights import LIGHT_KINDS
from .program import (CAMERA_KEYS, DEFAULT_MATERIAL, LIGHT_KEYS, MATERIAL_KEYS, RENDER_KEYS, Camera, CameraPath,
                      Keyframe, Light, LightKind, Material, Preset, RenderSettings, Shadows, light_vector_key)
from .types import TYPE_WORDS, Parameter, Type, in_float_range, keys_of


class BlockChecking(CheckerBase):
    def entries(self, block: ast.Block | None, keys: dict[str, Parameter], owner: str) -> dict:
        """Check a block's entries against `keys` (with types, defaults and
        constraints); unknown and duplicate keys are errors."""
        found: dict[str, object] = {}
        spans: dict[str, Span] = {}
        for entry in block.entries if block else ():
            if entry.key in spans:
                self.error(entry.key_span, f"'{entry.key}' is given twice in '{owner}'")
                continue
            spans[entry.key] = entry.key_span
            param = keys.get(entry.key)
            if param is None:
                hint = self.did_you_mean(entry.key, keys) or \
                    (f" (known: {', '.join(keys)})" if len(keys) <= len(RENDER_KEYS) else "")
                self.error(entry.key_span, f"'{owner}' has no key '{entry.key}'{hint}")
                continue
            nested = param.type is Type.BLOCK
            if isinstance(entry.value, ast.Block) != nested:
                self.error(entry.value.span, f"'{entry.key}' takes a block {{ ... }}" if nested
                           else f"'{entry.key}' takes a value, not a block")
                continue
            if nested:
                values = self.entries(entry.value, keys_of(param.block), entry.key)
                found[entry.key] = param.block(**values)
                continue
            is_file = param.type is Type.FILE
            if isinstance(entry.value, ast.String) != is_file:
                self.error(entry.value.span, f"'{entry.key}' takes a file name in quotes, such as \"sky.exr\""
                           if is_file else f"'{entry.key}' takes a value, not a string "
                                           f"(strings are file names: environment's 'map')")
                continue
            try:
                found[entry.key] = self.file(entry.value) if is_file else self.entry_value(entry, param, owner)
            except Failed:
                pass
        return found

    def file(self, name: ast.String) -> str:
        """The absolute path of the image file a string names, relative to
        the scene file's folder, once it reads (it is read on the host: the
        path never reaches the kernel's source)."""
        for index, character in enumerate(name.value):
            if ord(character) < 32 or ord(character) == 127:
                column = name.span.column + 1 + index
                self.fail(Span(name.span.line, column, name.span.line, column + 1),
                          f"a control character (code {ord(character)}) in a string")
        if not name.value:
            self.fail(name.span, "an empty file name")
        path = os.path.abspath(os.path.join(os.path.dirname(self.program.file), name.value))
        try:
            pathtrace.environment_map(path)
        except ValueError as error:
            self.fail(name.span, str(error))
        return path

    def entry_value(self, entry: ast.Entry, param: Parameter, owner: str):
        value = self.expression(entry.value)
        if param.words:
            if value.type == WORD and value.data in param.words:
                return param.word(value.data)
            if param.type is Type.WORD or value.type != param.type:   # not the value given instead of a word
                listed = " or ".join([f"'{c}'" for c in param.words] + [TYPE_WORDS[param.type]] * (
                    param.type is not Type.WORD))
                self.fail(entry.value.span, f"'{entry.key}' must be {listed}")
        data = self.convert(entry.value.span, value, param, owner)
        if owner == "material":
            return data
        items = data.items if isinstance(data, ir.Vec) else (data,)
        if not all(isinstance(x, ir.Const) for x in items):
            self.fail(entry.value.span, f"'{entry.key}' must be a constant (it depends on a param)")
        values = tuple(x.value for x in items)
        return values if isinstance(data, ir.Vec) else (int(values[0]) if param.type is Type.WHOLE else values[0])

    def material(self, decl: ast.MaterialDecl) -> Material:
        found = self.entries(decl.block, MATERIAL_KEYS, "material")
        return replace(self.materials[DEFAULT_MATERIAL], name=decl.name, **found)

    def camera(self, decl: ast.CameraDecl | None) -> Camera:
        errors_before = len(self.errors)
        found = self.entries(decl.block if decl else None, CAMERA_KEYS, "camera")
        camera = Camera(**found)
        if len(self.errors) > errors_before:
            return camera
        try:
            return camera.aimed(up_given="up" in found)
        except ValueError as error:
            at_fault = camera.aim_problem()[0]
            where = next((x.value.span for x in decl.block.entries if x.key == at_fault), decl.span)
            self.error(where, str(error))
        return camera

    def light(self, decl: ast.LightDecl) -> Light | None:
        keys = LIGHT_KEYS.get(decl.kind)     # the kind as a word: a LightKind is equal to its word
        if keys is None:
            self.error(decl.kind_span, f"unknown light kind '{decl.kind}' (known: {', '.join(LIGHT_KEYS)})")
            return None
        errors_before = len(self.errors)
        found = self.entries(decl.block, keys, "light")
        vector_key = light_vector_key(decl.kind)
        given = {e.key: e for e in decl.block.entries}
        aimed = "target" in keys         # a spot or rectangle light: `direction` or `target`, as a camera
        if aimed and "direction" in given and "target" in given:
            second = max(given["direction"], given["target"], key=lambda e: (e.span.line, e.span.column))
            self.error(second.key_span, f"a {decl.kind} light takes 'direction' or 'target', not both")
        needed = (vector_key, "direction") if aimed else (vector_key,)
        for key in needed:
            if key not in given and not (key == "direction" and "target" in given):
                self.error(decl.span, f"a {decl.kind} light needs '{key}'"
                                      + (" (or 'target', the point it faces)" if key == "direction" else ""))
        if len(self.errors) > errors_before:
            return None
        vector = found.pop(vector_key)
        if aimed and "target" in found:
            target = found.pop("target")
            found["direction"] = tuple(t - p for t, p in zip(target, vector))
            if not any(found["direction"]):
                self.error(given["target"].value.span, f"the {decl.kind} light's target is its position: "
                                                        f"it faces nowhere")
                return None
        if LIGHT_KINDS[decl.kind].area:    # the direct renderer's stand-in for their soft shadows
            found.setdefault("shadows", Shadows.SOFT)
        return Light(LightKind(decl.kind), vector, **found)

    def render(self, decl: ast.RenderDecl | None) -> RenderSettings:
        found = self.entries(decl.block if decl else None, RENDER_KEYS, "render")
        environment = found.get("environment")
        if environment is not None and environment.map is not None:   # the one place a map is kept
            found.update(environment=replace(environment, map=None), environment_map=environment.map)
        return RenderSettings(**found)

    def path(self, decl: ast.PathDecl | None) -> CameraPath | None:
        """Keyframes take the camera's keys (constants, checked the same way)
        and values of params (in the params' ranges); a camera key wins over
        a param of the same name."""
        if decl is None:
            return None
        # the camera keys a path animates (a projection and stereo layout are the block's)
        animated = [key for key in CAMERA_KEYS if key in Keyframe.__dataclass_fields__]
        keys = {key: CAMERA_KEYS[key] for key in animated}
        for name, info in self.params.items():
            keys.setdefault(name, info.as_key())
        keyframes = []
        for before, frame in zip((None,) + decl.keyframes, decl.keyframes):
            if not in_float_range(frame.time):
                self.error(frame.time_span, f"{source_text(self.program, frame.time_span)} is too large a time")
            elif before is not None and frame.time <= before.time:
                self.error(frame.time_span, f"keyframe times must increase: {frame.time:g} does not come after "
                                            f"{before.time:g} (line {before.span.line})")
            found = self.entries(frame.block, keys, "path")
            camera = {key: found.pop(key) for key in animated if key in found}
            if "position" not in camera:
                if not any(e.key == "position" for e in frame.block.entries):
                    self.error(frame.time_span, f"the keyframe at {frame.time:g} needs a 'position'")
                continue
            if camera.get("target") == camera["position"]:
                where = next(e.value.span for e in frame.block.entries if e.key == "target")
                self.error(where, "the keyframe's target is its position: it looks nowhere")
            keyframes.append(Keyframe(frame.time, **camera, params=tuple(found.items())))
        if len(decl.keyframes) < 2:
            self.error(decl.span, f"a path needs at least two keyframes, this one has {len(decl.keyframes)}")
        return CameraPath(tuple(keyframes), decl.span)

    def presets(self, decls: list[ast.PresetDecl]) -> tuple[Preset, ...]:
        """Each `preset NAME { param: value, ... }`: constant values of
        params, in their ranges; one preset of each name."""
        keys, found = {name: info.as_key() for name, info in self.params.items()}, {}
        for decl in decls:
            if decl.name in found:
                first = found[decl.name].span
                self.error(decl.name_span, f"a second preset '{decl.name}' (the first is at line {first.line})")
                continue
            values = self.entries(decl.block, keys, "preset")
            found[decl.name] = Preset(decl.name, tuple(values.items()), decl.span)
        return tuple(found.values())


# The vector keys that are colours (r, g, b): what a colour picker sets.
COLOUR_KEYS = frozenset({"color", "background", "zenith", "horizon", "ground"})


class KeyKind(Enum):
    """What a block key takes (besides the words it names)."""
    NUMBER = "number"
    WHOLE = "whole number"
    VECTOR = "3-vector"
    WORD = "word"           # one of its words only
    BLOCK = "block"         # a block of keys of its own
    FILE = "file"           # a file name in quotes


@dataclass(frozen=True)
class KeySpec:
    """A key of a block as an editor's control sees it (`key_specs`)."""
    name: str
    kind: KeyKind
    words: tuple[str, ...] = ()     # the words it takes
    low: float | None = None        # its range, None: open on that side
    high: float | None = None
    low_excluded: bool = False      # `> low` rather than `>= low`
    high_excluded: bool = False
    colour: bool = False            # an (r, g, b) colour
    keys: tuple["KeySpec", ...] = ()   # a block's keys


def key_specs(block: str) -> tuple[KeySpec, ...]:
    """The keys of a block, their types and ranges from the checker's own
    tables: `block` is "render", "camera", "material" or "light KIND"."""
    kind, _, light = block.partition(" ")
    tables = {"render": RENDER_KEYS, "camera": CAMERA_KEYS, "material": MATERIAL_KEYS}
    keys = LIGHT_KEYS.get(light) if kind == "light" else tables.get(block)
    if keys is None:
        raise ValueError(f"no block '{block}' (blocks: {', '.join(tables)}, light {'|'.join(LIGHT_KEYS)})")
    return tuple(_key_spec(parameter) for parameter in keys.values())


def _key_spec(parameter: Parameter) -> KeySpec:
    if parameter.type is Type.BLOCK:
        return KeySpec(parameter.name, KeyKind.BLOCK,
                       keys=tuple(_key_spec(p) for p in keys_of(parameter.block).values()))
    if parameter.type is Type.FILE:
        return KeySpec(parameter.name, KeyKind.FILE)
    kind = {Type.WORD: KeyKind.WORD, Type.WHOLE: KeyKind.WHOLE, Type.VEC3: KeyKind.VECTOR}.get(
        parameter.type, KeyKind.NUMBER)
    low, high, low_excluded, high_excluded = parameter.range
    return KeySpec(parameter.name, kind, tuple(str(w) for w in parameter.words), low, high, low_excluded,
                   high_excluded, colour=kind is KeyKind.VECTOR and parameter.name in COLOUR_KEYS)
