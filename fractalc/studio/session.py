"""The studio's state and what the page asks of it.

The scene file is the truth: the page's text is the file's until edited;
params and the camera move live (kernel arguments, no rebuild) and, with
presets and keyframes, are written into the text by `save` as edits at
their spans. Key controls (render, lights, materials) edit the text at
once. A change of the file on disk reloads the text, unless the page has
edits of its own, which it is asked about.

`Studio` runs on the server's event loop; the live renderer and final
render jobs call back into it through `call_soon`. Every request is
checked here (types, sizes, names) before it changes anything; a refused
one is answered by a notice.
"""
from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field, replace
from typing import Callable

from .. import ast
from ..api import Camera, Scene
from ..check import check
from ..check_blocks import KeyKind, key_specs
from ..errors import RenderError, SceneError, Span
from ..parse import parse
from ..paths import camera_at, params_at
from ..program import CameraPath, CheckedScene, Keyframe
from ..source import MAX_FILE_BYTES, read_scene_file
from ..write import replacing
from . import edits
from .controls import controls
from .jobs import Job, JobKind, JobStatus, RenderRequest, output_mistake
from .live import LiveRenderer, View

MAX_KEYFRAMES = 1000
MAX_PRESETS = 1000
MAX_NAME = 64                     # characters in a preset's name
MAX_OUTPUT = 4096                 # characters in an output path
LIVE_SIZE = (16, 2048)            # the live image's smallest and largest side
CAMERA_KEYS = ("position", "target", "up", "fov")    # what the page's camera moves
_NO_SPAN = Span(1, 1, 1, 1)       # the span of a path made from the timeline's keyframes


class Refused(Exception):
    """A request the studio does not carry out; the page is told why."""


@dataclass(frozen=True)
class Options:
    device: str | None = None
    precision: str | None = None
    preview_scale: int = 2
    max_samples: int = 64
    live_size: tuple[int, int] | None = None     # the live image's size; None: the page's
    params: dict = field(default_factory=dict)   # --set: live values to start from


# ---- checking requests ---------------------------------------------------------

def _number(value, what: str, low: float | None = None, high: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise Refused(f"{what} must be a finite number")
    if (low is not None and value < low) or (high is not None and value > high):
        raise Refused(f"{what} must be from {low:g} to {high:g}")
    return float(value)


def _whole(value, what: str, low: int, high: int) -> int:
    number = _number(value, what, low, high)
    if number != int(number):
        raise Refused(f"{what} must be a whole number")
    return int(number)


def _vector(value, what: str) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise Refused(f"{what} must be 3 numbers")
    return tuple(_number(v, what) for v in value)


def _text(value, what: str, limit: int) -> str:
    if not isinstance(value, str) or len(value) > limit or "\0" in value:
        raise Refused(f"{what} must be text of at most {limit} characters")
    return value


def _camera_keys_given(value) -> dict:
    if not isinstance(value, dict) or set(value) - set(CAMERA_KEYS):
        raise Refused(f"a camera has the keys {', '.join(CAMERA_KEYS)}")
    return {key: _vector(value[key], key) if key != "fov" else _number(value[key], key)
            for key in CAMERA_KEYS if key in value}


def _key_value(spec, value) -> str:
    """A key control's value as the text the file gets: a number, a
    vector, one of the key's words, or `{}` (a block on, at its defaults)."""
    if isinstance(value, str):
        if value not in spec.words:
            raise Refused(f"'{spec.name}' takes {', '.join(spec.words) or 'no words'}, not '{value}'")
        return value
    if spec.kind is KeyKind.BLOCK:
        if value != {}:
            raise Refused(f"'{spec.name}' is a block: turn it on or off, or set its keys")
        return "{}"
    if spec.kind is KeyKind.VECTOR:
        return edits.vector_text(_vector(value, spec.name))
    if spec.kind in (KeyKind.NUMBER, KeyKind.WHOLE):
        number = _number(value, spec.name)
        if spec.kind is KeyKind.WHOLE:
            return str(_whole(number, spec.name, -2 ** 31, 2 ** 31))
        return edits.number_text(number)
    raise Refused(f"'{spec.name}' has no control")


def key_edit(text: str, file: str, message: dict) -> str:
    """`text` with a render, light or material key set as `message` asks:
    {block: "render" | "light" | "material", index (a light's, in the
    file's order) or name (a material's), key: [name] or [block key, name],
    value (None: the key taken out, back to its default)}."""
    try:
        program = parse(text, file)
    except SceneError:
        raise Refused("the text does not parse: fix it to set a key") from None
    block_kind, path = message.get("block"), message.get("key")
    if not isinstance(path, list) or not 1 <= len(path) <= 2 or not all(isinstance(k, str) for k in path):
        raise Refused("key must be [name] or [block, name]")
    if block_kind == "render":
        decl, specs = edits.last_of(program, ast.RenderDecl), key_specs("render")
    elif block_kind == "light":
        lights = [d for d in program.decls if isinstance(d, ast.LightDecl)]
        index = message.get("index")
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(lights):
            raise Refused("no such light in the text")
        decl = lights[index]
        specs = key_specs(f"light {decl.kind}")
    elif block_kind == "material":
        decl = next((d for d in program.decls if isinstance(d, ast.MaterialDecl) and d.name == message.get("name")),
                    None)
        if decl is None:
            raise Refused("no such material in the text")
        specs = key_specs("material")
    else:
        raise Refused("block must be render, light or material")
    spec = next((s for s in specs if s.name == path[0]), None)
    if spec is not None and len(path) == 2:
        spec = next((s for s in spec.keys if s.name == path[1]), None) if spec.kind is KeyKind.BLOCK else None
    if spec is None or spec.kind is KeyKind.FILE:
        raise Refused(f"no key {'.'.join(path)} to set in '{block_kind}'")
    source, value = edits.Text(text), message.get("value")
    if value is None:
        block = decl.block if decl else None
        if block is not None and len(path) == 2:
            entry = edits.find_entry(block, path[0])
            block = entry.value if entry is not None and isinstance(entry.value, ast.Block) else None
        changes = edits.remove_entry(source, block, path[-1]) if block is not None else []
    elif decl is None:          # no render block yet: one at the end
        entry = {path[-1]: _key_value(spec, value)}
        body = edits.entries_text(entry if len(path) == 1 else {path[0]: edits.entries_text(entry)})
        changes = [edits.add_declaration(source, None, f"render {body}")]
    else:
        changes = edits.set_entry(source, decl.block, tuple(path), _key_value(spec, value))
    return edits.apply(text, changes)


def _key_text(value) -> str:
    return edits.vector_text(value) if isinstance(value, tuple) else edits.number_text(value)


def text_with_state(text: str, file: str, checked: CheckedScene, params: dict[str, float], camera: Camera,
                    presets: dict[str, dict[str, float]], keyframes: list[Keyframe] | None) -> str:
    """`text` (which `checked` is the check of) with the live state written
    at its places: each param whose value is not its default, each camera
    key that moved, the `presets` given (new or changed), and the
    keyframes as the path (None: the path as it is; empty: none)."""
    program, source = parse(text, file), edits.Text(text)
    values = {p.name: edits.number_text(params[p.name], p.low, p.high)
              for p in checked.params if params.get(p.name, p.default) != p.default}
    camera_keys = {key: _key_text(getattr(camera, key)) for key in CAMERA_KEYS
                   if getattr(camera, key) != getattr(checked.camera, key)}
    names = {p.name for p in checked.params}
    preset_values = {name: {k: edits.number_text(v) for k, v in given.items() if k in names}
                     for name, given in presets.items()}
    changes = edits.param_edits(source, program, values) + edits.camera_edits(source, program, camera_keys) \
        + edits.preset_edits(source, program, preset_values)
    path = edits.last_of(program, ast.PathDecl)
    if keyframes:
        changes.append(edits.path_edit(source, program, [_keyframe_text(k, names) for k in keyframes]))
    elif keyframes is not None and path is not None:
        changes.append(edits.remove_declaration(source, path))
    return edits.apply(text, changes)


def _keyframe_text(keyframe: Keyframe, params: set[str]) -> tuple[str, dict[str, str]]:
    values = {key: _key_text(getattr(keyframe, key)) for key in ("position", "target", "up", "fov", "aperture", "focus")
              if getattr(keyframe, key) is not None}
    values.update((name, edits.number_text(value)) for name, value in keyframe.params if name in params)
    return edits.number_text(keyframe.time), values


def read_text(path: str) -> tuple[str, str]:
    """The scene file's text with "\n" line breaks (as a browser's text
    area has them), and the line break the file uses, for saving."""
    text = read_scene_file(path)
    return text.replace("\r\n", "\n"), "\r\n" if "\r\n" in text else "\n"


class Studio:
    """One scene file in the studio. `send(message)` goes to every page
    (a dict, or a live `Frame`); `call_soon(function, *args)` runs a
    function on the event loop from any thread."""

    def __init__(self, path: str, options: Options, send: Callable, call_soon: Callable):
        self.path = path
        self.options = options
        self._send = send
        self.disk_text, self.newline = read_text(path)
        self.disk_stamp = self._stamp()
        self.text, self.version = self.disk_text, 0
        self.checked: CheckedScene | None = None
        self.checked_version = -1
        self.diagnostics: list = []
        self.params: dict[str, float] = {}
        self.camera: Camera | None = None
        self.presets: dict[str, dict[str, float]] = {}
        self.unsaved_presets: set[str] = set()
        self.keyframes: list[Keyframe] = []
        self.keyframes_changed = False
        self.time = 0.0
        self.seq = 0
        self.size = options.live_size or (640, 400)
        self.device_name = ""
        self.building = False
        self.disk_changed = False
        self.job: Job | None = None
        self._validator: Scene | None = None     # set_params on it: the checks of a render's params
        self._started = False
        self.live = LiveRenderer(lambda event, payload: call_soon(self._from_live, event, payload),
                                 options.device, options.precision, options.preview_scale, options.max_samples)
        self._call_soon = call_soon
        self.live.start()
        self.live.check(self.version, self.text, self.path)

    def close(self) -> None:
        if self.job is not None:
            self.job.cancel()
        self.live.stop()

    # ---- the page's requests -------------------------------------------------

    def receive(self, message) -> None:
        """One request from a page (a decoded JSON object)."""
        kind = message.get("type") if isinstance(message, dict) else None
        handler = self._REQUESTS.get(kind) if isinstance(kind, str) else None
        try:
            if handler is None:
                raise Refused(f"unknown request {kind!r}")
            handler(self, message)
        except Refused as refusal:
            self.notice(str(refusal), error=True)

    def hello(self, send: Callable) -> None:
        """Everything a page shows, sent with `send` to a page that just
        connected (the others have it)."""
        everyone, self._send = self._send, send
        try:
            self._send({"type": "device", "name": self.device_name})
            self._send({"type": "text", "text": self.text, "version": self.version})
            self._send_diagnostics()
            if self.checked is not None:
                self._send_scene()
            self._send({"type": "status", "building": self.building})
            self._send_dirty()
            if self.job is not None:
                self._send_job(self.job.status)
            if self.disk_changed:
                self._send({"type": "disk_changed"})
        finally:
            self._send = everyone

    def on_text(self, message) -> None:
        text = _text(message.get("text"), "the text", MAX_FILE_BYTES)
        if text != self.text:
            self._set_text(text, tell_pages=False)

    def on_view(self, message) -> None:
        if "seq" in message:
            self.seq = max(self.seq, _whole(message["seq"], "seq", 0, 2 ** 53))
        if "size" in message and self.options.live_size is None:
            size = message["size"]
            if not isinstance(size, list) or len(size) != 2:
                raise Refused("size must be [width, height]")
            self.size = tuple(_whole(x, "size", 1, 1 << 16) for x in size)
            self.size = tuple(min(max(x, LIVE_SIZE[0]), LIVE_SIZE[1]) for x in self.size)
        if "camera" in message:
            given = _camera_keys_given(message["camera"])
            self.camera = self._checked_camera({**self._camera_keys(self.camera), **given})
        if "params" in message:
            given = message["params"]
            if not isinstance(given, dict):
                raise Refused("params must be an object of names and values")
            self._set_params({_text(k, "a param's name", MAX_NAME * 4): _number(v, f"param '{k}'")
                              for k, v in given.items()})
        self._show()
        self._send_dirty()

    def on_camera_reset(self, message) -> None:
        if self.checked is not None:
            self.camera = Camera(**asdict(self.checked.camera))
            self._send_values()
            self._show()
            self._send_dirty()

    def on_key(self, message) -> None:
        changed = key_edit(self.text, self.path, message)
        if changed != self.text:
            self._set_text(changed, tell_pages=True)

    def on_preset_save(self, message) -> None:
        name = _text(message.get("name"), "a preset's name", MAX_NAME)
        if not edits.NAME.fullmatch(name):
            raise Refused(f"'{name}' is not a name: letters, digits and _, not starting with a digit")
        if not self.params:
            raise Refused("the scene has no params to save")
        if name not in self.presets and len(self.presets) >= MAX_PRESETS:
            raise Refused(f"at most {MAX_PRESETS} presets")
        self.presets[name] = dict(self.params)
        self.unsaved_presets.add(name)
        self._send_presets()
        self._send_dirty()

    def on_preset_apply(self, message) -> None:
        name = _text(message.get("name"), "a preset's name", MAX_NAME)
        if name not in self.presets:
            raise Refused(f"no preset {name!r}")
        self._set_params({k: v for k, v in self.presets[name].items() if k in self.params})
        self._send_values()
        self._show()
        self._send_dirty()

    def on_keyframe_add(self, message) -> None:
        """A keyframe of the camera and every param at `time` (replacing
        one at that time)."""
        if self.checked is None:
            raise Refused("the scene has errors: fix them first")
        time = _number(message.get("time"), "time", 0.0, 1e6)
        kept = [k for k in self.keyframes if k.time != time]
        if len(kept) >= MAX_KEYFRAMES:
            raise Refused(f"at most {MAX_KEYFRAMES} keyframes")
        camera = self.camera
        kept.append(Keyframe(time, camera.position, camera.target, camera.up, camera.fov,
                             params=tuple(self.params.items())))
        self.keyframes = sorted(kept, key=lambda k: k.time)
        self.keyframes_changed, self.time = True, time
        self._send_keyframes()
        self._send_dirty()

    def on_keyframe_delete(self, message) -> None:
        time = _number(message.get("time"), "time")
        kept = [k for k in self.keyframes if k.time != time]
        if len(kept) == len(self.keyframes):
            raise Refused(f"no keyframe at {time:g}")
        self.keyframes, self.keyframes_changed = kept, True
        self._send_keyframes()
        self._send_dirty()

    def on_scrub(self, message) -> None:
        """Go to `time` on the timeline: the camera and params the
        keyframes give there."""
        self.time = _number(message.get("time"), "time", 0.0, 1e6)
        if not self.keyframes or self.checked is None:
            return
        path = CameraPath(tuple(self.keyframes), _NO_SPAN)
        camera = camera_at(path, self.checked.camera, self.time)
        self.camera = self._checked_camera({key: getattr(camera, key) for key in CAMERA_KEYS})
        self._set_params({k: v for k, v in params_at(path, self.time).items() if k in self.params})
        self._send_values()
        self._show()
        self._send_dirty()

    def on_save(self, message) -> None:
        self.save()

    def on_reload(self, message) -> None:
        """Take the file on disk, dropping the page's edits."""
        self.disk_changed = False
        self.unsaved_presets.clear()
        self.keyframes_changed = False
        self._set_text(self.disk_text, tell_pages=True)

    def on_keep(self, message) -> None:
        """Keep the page's edits over a file changed on disk."""
        self.disk_changed = False

    def on_render(self, message) -> None:
        if self.job is not None and self.job.running:
            raise Refused("a render is running: cancel it first")
        if self.checked is None or self.checked_version != self.version:
            raise Refused("the scene text has errors: fix them before rendering")
        try:
            kind = JobKind(message.get("kind"))
        except ValueError:
            raise Refused("kind must be still or animation") from None
        integrators = next(s for s in key_specs("render") if s.name == "integrator").words
        integrator = message.get("integrator")
        if integrator not in integrators:
            raise Refused(f"integrator must be {' or '.join(integrators)}")
        request = RenderRequest(kind, _text(message.get("output"), "the output", MAX_OUTPUT),
                                _whole(message.get("width"), "width", 1, 65536),
                                _whole(message.get("height"), "height", 1, 65536),
                                _whole(message.get("samples"), "samples", 1, 4096), integrator,
                                _number(message.get("fps", 30), "fps", 0.001, 1000))
        mistake = output_mistake(request)
        if mistake:
            raise Refused(f"{request.output}: {mistake}")
        checked = self.checked
        if kind is JobKind.ANIMATION:
            if len(self.keyframes) < 2:
                raise Refused("an animation needs two keyframes or more: add them on the timeline")
            checked = replace(checked, path=CameraPath(tuple(self.keyframes), _NO_SPAN))
        try:
            self.job = Job(request, self.path, checked, self.params, self.camera, self.options.precision,
                           self.options.device, lambda status: self._call_soon(self._send_job, status))
        except (ValueError, SceneError) as error:
            raise Refused(str(error).splitlines()[0]) from None
        self.job.start()
        self._send_job(self.job.status)

    def on_cancel(self, message) -> None:
        if self.job is not None:
            self.job.cancel()

    _REQUESTS = {"text": on_text, "view": on_view, "camera_reset": on_camera_reset, "key": on_key,
                 "preset_save": on_preset_save, "preset_apply": on_preset_apply,
                 "keyframe_add": on_keyframe_add, "keyframe_delete": on_keyframe_delete, "scrub": on_scrub,
                 "save": on_save, "reload": on_reload, "keep": on_keep, "render": on_render, "cancel": on_cancel}

    # ---- saving ----------------------------------------------------------------

    def save(self) -> None:
        """Write the text, with the live params, camera, presets and
        keyframes written into it, to the scene file (atomically)."""
        text, written_state = self.text, False
        if self.checked is not None and self.checked_version == self.version:
            keyframes = self.keyframes if self.keyframes_changed else None
            presets = {name: self.presets[name] for name in self.unsaved_presets}
            text, written_state = text_with_state(self.text, self.path, self.checked, self.params, self.camera,
                                                  presets, keyframes), True
            if text != self.text:
                try:
                    check(parse(text, self.path))
                except SceneError as error:
                    raise Refused(f"not saved: {error.errors[0].message}") from None
        real = os.path.realpath(self.path)      # a link to the scene file stays a link
        try:
            with replacing(real) as temporary, open(temporary, "w", encoding="utf-8", newline=self.newline) as f:
                f.write(text)
        except RenderError as error:
            raise Refused(str(error)) from None
        self.disk_text, self.disk_stamp, self.disk_changed = text, self._stamp(), False
        if written_state:
            self.unsaved_presets.clear()
            self.keyframes_changed = False
        if text != self.text:
            self._set_text(text, tell_pages=True)
        self.notice(f"saved {self.path}" + ("" if written_state else
                                            " (the text has errors: params, camera, presets and keyframes "
                                            "are written once it checks)"))
        self._send_dirty()

    # ---- the file on disk --------------------------------------------------------

    def _stamp(self):
        try:
            stat = os.stat(self.path)
        except OSError:
            return None
        return stat.st_mtime_ns, stat.st_size, stat.st_ino

    def poll_disk(self) -> None:
        """Look at the file: a change by another program reloads the text,
        or asks the page if it has edits of its own."""
        stamp = self._stamp()
        if stamp is None or stamp == self.disk_stamp:
            return
        self.disk_stamp = stamp
        try:
            text, self.newline = read_text(self.path)
        except (RenderError, SceneError) as error:
            self.notice(str(error).splitlines()[0], error=True)
            return
        if text == self.disk_text:
            return
        page_edits = self.text != self.disk_text
        self.disk_text = text
        if page_edits:
            self.disk_changed = True
            self._send({"type": "disk_changed"})
        else:
            self._set_text(text, tell_pages=True)
            self.notice(f"{self.path} changed on disk: reloaded")
        self._send_dirty()

    # ---- the live image ---------------------------------------------------------

    def _set_text(self, text: str, tell_pages: bool) -> None:
        if len(text.encode("utf-8", errors="replace")) > MAX_FILE_BYTES:
            raise Refused(f"the text is larger than {MAX_FILE_BYTES // (1024 * 1024)} MB")
        self.text, self.version = text, self.version + 1
        if tell_pages:
            self._send({"type": "text", "text": text, "version": self.version})
        self.live.check(self.version, text, self.path)
        self._send_dirty()

    def _camera_keys(self, camera: Camera | None) -> dict:
        return {key: getattr(camera, key) for key in CAMERA_KEYS} if camera else {}

    def _checked_camera(self, keys: dict) -> Camera:
        base = asdict(self.checked.camera) if self.checked else {}
        try:
            return Camera(**{**base, **keys})
        except ValueError as error:
            raise Refused(str(error)) from None

    def _set_params(self, values: dict[str, float]) -> None:
        if self._validator is None:
            raise Refused("the scene has errors: fix them first")
        changed = {**self.params, **values}
        try:
            self._validator.set_params(changed)
        except SceneError as error:
            raise Refused(error.errors[0].message) from None
        except ValueError as error:
            raise Refused(str(error)) from None
        self.params = changed

    def _show(self) -> None:
        if self.checked is not None and self.camera is not None:
            self.live.show(View(self.seq, self.checked, dict(self.params), self.camera, self.size))

    def _from_live(self, event: str, payload) -> None:
        if event == "frame":
            self.building = False
            self._send(payload)
        elif event == "checked":
            version, checked = payload
            if version == self.version:
                self._adopt(checked)
        elif event == "diagnostics":
            version, error = payload
            if version == self.version:
                self.diagnostics = error.errors
                self._send_diagnostics()
        elif event == "building":
            self.building = True
            self._send({"type": "status", "building": True})
        elif event == "param_error":
            self.notice(payload.errors[0].message, error=True)
        elif event == "failure":
            self.building = False
            self._send({"type": "status", "building": False})
            self.notice(payload, error=True)
        elif event == "device":
            self.device_name = payload
            self._send({"type": "device", "name": payload})

    def _adopt(self, checked: CheckedScene) -> None:
        """A new checked text: params whose default the text kept keep
        their live values; a camera the text changed becomes the view; the
        file's presets and path, unless the page changed them."""
        old = self.checked
        self.checked, self.checked_version, self.diagnostics = checked, self.version, []
        self._validator = Scene(checked, precision=self.options.precision, device=self.options.device)
        before = {p.name: p.default for p in old.params} if old else {}
        params = {}
        for p in checked.params:
            kept = p.name in self.params and before.get(p.name) == p.default
            params[p.name] = self.params[p.name] if kept else p.default
        self.params = {p.name: p.default for p in checked.params}
        try:
            self._set_params(params)
        except Refused:
            pass                       # outside the new ranges: the file's values
        if not self._started:
            self._started = True
            try:
                self._set_params(self.options.params)      # --set
            except Refused as refusal:
                self.notice(f"--set: {refusal}", error=True)
        if old is None or old.camera != checked.camera or self.camera is None:
            self.camera = Camera(**asdict(checked.camera))
        self.presets = {**{p.name: dict(p.params) for p in checked.presets},
                        **{n: v for n, v in self.presets.items() if n in self.unsaved_presets}}
        file_keyframes = list(checked.path.keyframes) if checked.path else []
        file_changed = old is not None and (old.path.keyframes if old.path else []) != file_keyframes
        if not self.keyframes_changed or file_changed:
            self.keyframes, self.keyframes_changed = file_keyframes, False
        self._send_diagnostics()
        self._send_scene()
        self._show()
        self._send_dirty()

    # ---- messages to the pages ---------------------------------------------------

    def notice(self, text: str, error: bool = False) -> None:
        self._send({"type": "notice", "text": text, "error": error})

    def _send_diagnostics(self) -> None:
        self._send({"type": "diagnostics", "items": [
            {"line": d.line, "column": d.column, "width": d.width, "message": d.message, "text": str(d)}
            for d in self.diagnostics]})

    def _send_scene(self) -> None:
        checked = self.checked
        self._send({"type": "scene", "file": self.path,
                    "params": [{"name": p.name, "default": p.default, "low": p.low, "high": p.high}
                               for p in checked.params],
                    "camera": self._camera_keys(Camera(**asdict(checked.camera))),
                    "render_size": [checked.render.width, checked.render.height],
                    "integrator": checked.render.integrator,
                    "live_size": list(self.options.live_size) if self.options.live_size else None,
                    "controls": controls(checked)})
        self._send_values()
        self._send_presets()
        self._send_keyframes()

    def _send_values(self) -> None:
        self._send({"type": "values", "params": self.params, "camera": self._camera_keys(self.camera),
                    "time": self.time})

    def _send_presets(self) -> None:
        self._send({"type": "presets", "presets": self.presets})

    def _send_keyframes(self) -> None:
        self._send({"type": "keyframes", "times": [k.time for k in self.keyframes]})

    def _send_job(self, status: JobStatus) -> None:
        self._send({"type": "job", "state": status.state.value, "progress": status.progress,
                    "output": status.output, "command": status.command, "message": status.message})

    def dirty(self) -> dict[str, bool]:
        """What the file does not have yet."""
        checked = self.checked
        return {"text": self.text != self.disk_text,
                "params": bool(checked) and any(self.params.get(p.name) != p.default for p in checked.params),
                "camera": bool(checked and self.camera) and any(
                    getattr(self.camera, k) != getattr(checked.camera, k) for k in CAMERA_KEYS),
                "presets": bool(self.unsaved_presets), "keyframes": self.keyframes_changed}

    def _send_dirty(self) -> None:
        self._send({"type": "dirty", **self.dirty()})
