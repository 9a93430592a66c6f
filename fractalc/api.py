"""The Python API (LANGUAGE.md, "Python API"): the pipeline as one object.

    parse -> check -> lower -> emit -> build -> run -> write

`load`/`loads` run the first three stages at once (so scene errors surface
immediately); the kernel is emitted and built on first use, per render
settings, and reused while only params, size, samples or seed change.
A render is prepared by `Scene.renderer` (a `Renderer`: settings, camera,
frame, params, target, metadata) and run whole or a block of rows at a
time: the seam that `Scene.render`, the render farm (fractalc/cluster.py),
animations and the evaluation counter (fractalc/count.py) share.
"""
from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields, replace
from functools import lru_cache

import numpy as np

from . import pathtrace, program, run
from .arguments import checked, require_type
from .build import build
from .check import check, check_param_values, check_value, unknown_param
from .cluster import render_still
from .denoise import denoise_image, require_denoiser
from .devices import build_options, open_device, refines_rsqrt
from .emit import Target, emit, emit_distance, uniform_source
from .errors import RenderError, SceneError, diagnostic
from .image import Image, image_from_pixels, require_image_memory
from .lanes import CHOICES as LANE_CHOICES
from .lower import lower
from .mesh import mesh
from .parse import parse
from .passes import PASSES, channels
from .program import CAMERA_KEYS, RENDER_KEYS, Camera, CheckedScene, Precision, RenderSettings
from .source import read_scene_file
from .types import FLOAT_MAX, in_float_range
from .version import __version__

PRECISIONS = tuple(Precision)
SETTING_NAMES = frozenset(f.name for f in fields(RenderSettings))
# change without rebuilding (exposure and tonemap: only PNG writing reads them)
_RUNTIME_DEFAULTS = {name: getattr(RenderSettings(), name) for name, key in RENDER_KEYS.items() if key.runtime}
CAMERA_BASE = program.Camera    # a file's camera and a fractalc.Camera made from Python alike
SCENE_TEXT_LIMIT = 64 * 1024   # longer scene text is left out of the metadata (its sha256 and path stay)


@dataclass(frozen=True)
class Camera(program.Camera):
    """A camera for `Scene.render(camera=...)`: the keys of a file's
    camera block, checked as there; a mistake is a ValueError naming the
    key. Looking straight along the default up, y is up instead."""

    def __post_init__(self):
        for key, parameter in CAMERA_KEYS.items():
            value = getattr(self, key)
            if value is None and key == "focus":      # on the target
                continue
            try:
                value = check_value(parameter, key, value)
            except ValueError as error:   # check_value speaks of render keys
                raise ValueError(str(error).replace(" of 'render'", " of 'camera'")) from None
            object.__setattr__(self, key, value)
        object.__setattr__(self, "up", self.aimed(self.up != program.Camera.up, keys_quoted=True).up)


class Scene:
    """A checked scene, ready to compile and render."""

    def __init__(self, checked: CheckedScene, params: dict | None = None,
                 precision: str | None = None, device: str | int | None = None, lanes: int | None = None):
        if precision is not None:
            require_type("precision", precision, str, "'float' or 'double'")
        precision = precision or checked.render.precision
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be 'float' or 'double', not {precision!r}")
        _check_lanes(lanes)
        if device is not None:
            require_type("device", device, (str, int), "a device's index (0, 1, ...) or a name ('cpu', 'gpu')")
            if isinstance(device, int) and device < 0:
                raise ValueError(f"device must be an index from 0 (see 'fractalc devices'), not {device}")
        self.lanes = lanes      # rays per work-item; None: the device's (fractalc/lanes.py)
        self.checked = replace(checked, render=replace(checked.render, precision=precision))
        self.device_spec = None if device is None else str(device)
        # (compiled settings, aperture or not, target) -> the RenderKernel; ("distance", ...) -> the estimate's program
        self._programs: dict = {}
        self._device = None          # opened on first use
        self._targets: dict[str, Target] = {}    # precision -> the kernels' target on the device
        self.params = {p.name: p.default for p in checked.params}
        self.set_params({} if params is None else params)

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={v:g}" for k, v in self.params.items()) or "none"
        return (f"<Scene {self.checked.file}: params {params}; precision {self.precision}; "
                f"device {self.device_spec or os.environ.get('FRACTALC_DEVICE') or 'default'}>")

    # ---- params ------------------------------------------------------------

    def set_params(self, values: dict) -> None:
        """Change param values (no rebuild); each must lie in its range, and
        so must every value computed from them. On an error nothing changes."""
        require_type("params", values, Mapping, "a dict of param name -> number")
        declared = {p.name: p for p in self.checked.params}
        changed = dict(self.params)
        for name, value in values.items():
            require_type("a param's name", name, str, "a str")
            info = declared.get(name)
            if info is None:     # the caller's mistake, not the file's
                raise ValueError(unknown_param(name, self.checked))
            try:
                if isinstance(value, (str, bytes, bool)):
                    raise TypeError
                value = float(value)
            except (TypeError, ValueError):
                raise TypeError(f"param '{name}' must be a number, not {value!r}") from None
            except OverflowError:       # an int beyond float's range: 10**400
                raise ValueError(f"param '{name}' must be a finite number within ±{FLOAT_MAX:.3g}, "
                                 f"not a whole number of {len(str(abs(value)))} digits") from None
            if not in_float_range(value):   # NaN would pass any range check
                raise ValueError(f"param '{name}' must be a finite number within ±{FLOAT_MAX:.3g}, not {value!r}")
            outside = info.range_violation(value)
            if outside:
                raise SceneError([diagnostic(self.checked.file, self.checked.source, info.span, outside)])
            changed[name] = value
        check_param_values(self.checked, [changed[p.name] for p in self.checked.params])
        self.params = changed

    def apply_preset(self, name: str) -> None:
        """Set the params a `preset NAME { ... }` of the file gives to its
        values (the others keep theirs); a ValueError names an unknown preset."""
        presets = {preset.name: preset for preset in self.checked.presets}
        if name not in presets:
            raise ValueError(f"the scene has no preset '{name}' (its presets: {', '.join(presets) or 'none'})")
        self.set_params(dict(presets[name].params))

    def _param_values(self) -> list[float]:
        return [self.params[p.name] for p in self.checked.params]

    @property
    def source_sha256(self) -> str:
        """The sha256 of the scene's text (in every image's metadata)."""
        return _sha256(self.checked.source)

    # ---- compiling ---------------------------------------------------------

    @property
    def device(self):
        if self._device is None:
            self._device = open_device(self.device_spec)
        return self._device

    @property
    def precision(self) -> str:
        return self.checked.render.precision

    def _target(self, settings: RenderSettings, lanes: int | None = None) -> Target:
        """The kernel's target: this scene's device, or (`lanes` given, as
        `fractalc compile --lanes` does) no device in particular."""
        double = settings.precision == "double"
        if lanes is not None:
            return Target(lanes=lanes, double=double)
        if settings.precision not in self._targets:     # the device's lane choice, read once
            device = self.device
            if double and not device.info.double:
                raise RenderError(f"the OpenCL device '{device.info.name}' does not support double precision")
            self._targets[settings.precision] = Target(lanes=self.lanes_in_use, double=double,
                                                       exact_native=device.lane_choice.native_exact,
                                                       refined_rsqrt=refines_rsqrt(device.info),
                                                       build_options=build_options(device.info, double))
        return self._targets[settings.precision]

    @property
    def lanes_in_use(self) -> int:
        """Rays per work-item: the `lanes` given, else the device's."""
        return self.lanes or self.device.lanes

    def kernel_source(self, lanes: int | None = None, **render_keys) -> str:
        """The standalone OpenCL C source (no includes) for this scene."""
        _check_lanes(lanes)
        settings = self.render_settings(**render_keys)
        scene = replace(self.checked, render=settings)
        return emit(lower(scene), self._target(settings, lanes))

    def compile(self, use_cache: bool = True, **render_keys):
        """Build the render kernel now (it is otherwise built on first use);
        `use_cache=False` compiles even if this process built it before."""
        settings = self.render_settings(**render_keys)
        return self._render_kernel(settings, self.checked.camera, self._target(settings), use_cache).program

    def _render_kernel(self, settings: RenderSettings, camera: Camera, target: Target,
                       use_cache: bool = True) -> run.RenderKernel:
        """The render kernel of `settings` for `camera`, built once: frames
        that change only runtime settings, the camera or params reuse it."""
        # Size, samples and the camera are kernel arguments: keep them out of
        # the source (only whether the lens has an aperture shapes the kernel).
        key = (_compiled(settings), camera.aperture > 0, target)
        if use_cache and key in self._programs:
            return self._programs[key]   # no lowering or emitting per frame
        lens = Camera(aperture=1.0 if camera.aperture > 0 else 0.0)
        source = emit(lower(replace(self.checked, render=key[0], camera=lens)), target)
        program = build(source, self.device, target.build_options, use_cache=use_cache)
        self._programs[key] = run.RenderKernel(program, self.device, target.lanes, target.double)
        return self._programs[key]

    def set_defaults(self, camera: Camera | None = None, **render_keys) -> None:
        """Replace the file's camera and render settings (any render key,
        checked as `render` checks it) for every later render."""
        if camera is not None:
            require_type("camera", camera, CAMERA_BASE, "a fractalc.Camera")
        self.checked = replace(self.checked, render=self.render_settings(**render_keys),
                               camera=camera or self.checked.camera)

    def render_settings(self, **render_keys) -> RenderSettings:
        """The scene's render settings with `render_keys` (any render key;
        None keeps the scene's), each checked as `render` checks it."""
        settings = self.checked.render
        changed = {}
        for key, value in render_keys.items():
            if key not in SETTING_NAMES:
                raise ValueError(f"unknown render setting '{key}' (known: {', '.join(sorted(SETTING_NAMES))})")
            if value is None:
                continue
            if key == "environment_map":    # not a file's key: an image file, the sky
                require_type("environment_map", value, (str, os.PathLike), "an image file's name")
                path = os.path.abspath(os.fspath(value))
                pathtrace.environment_map(path)      # a ValueError where it cannot be read
                changed["environment_map"] = path
                continue
            if key == "aovs":    # not a file's key: passes to add to the default channels
                if isinstance(value, str):
                    raise ValueError(f"aovs must be a list of pass names, not the string {value!r}")
                require_type("aovs", value, (list, tuple, set, frozenset),
                             f"a list of pass names ({', '.join(PASSES)})")
                for name in value:
                    require_type("a pass in aovs", name, str, f"a pass name ({', '.join(PASSES)})")
                channels(value)     # raises ValueError naming an unknown pass
                changed["aovs"] = tuple(p for p in PASSES if p in value)
                continue
            if not _unchanged(settings, key, value):
                changed[key] = check_value(RENDER_KEYS[key], key, value)
        return replace(settings, **changed) if changed else settings

    # ---- running -----------------------------------------------------------

    def bound(self) -> tuple[np.ndarray, float] | None:
        """The centre and radius of a sphere holding the whole scene (for
        the current params), or None for an unbounded scene (a ground
        plane, repetition, a warp)."""
        scene_ir = lower(self.checked)
        if scene_ir.bound is None or scene_ir.bound.sphere is None or scene_ir.bound.half_spaces:
            return None
        centre, radius = scene_ir.bound.sphere
        double = self.precision == "double"
        program = build(uniform_source((*centre, radius), double), self.device, kernels=("uniform_values",))
        values = run.uniform_values(program, self.device, self._param_values(), 4, double)
        return values[:3], float(values[3])

    def distance(self, points) -> np.ndarray:
        """Distance estimates at (N, 3) points, computed by the compiled kernel."""
        if isinstance(points, (str, bytes)) or points is None:
            raise TypeError(f"points must be an (N, 3) array of numbers, not {points!r}")
        try:
            points = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):
            raise TypeError("points must be an (N, 3) array of numbers") from None
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), not {points.shape}")
        if not np.isfinite(points).all():
            raise ValueError("points must be finite (no NaN or infinity)")
        program, target = self._distance_program()
        return run.distances(program, self.device, points, self._param_values(),
                             target.lanes, target.double)

    def _distance_program(self, escape_time_sets: bool = False):
        """The program of the estimate alone (emit_distance): sampling it
        needs no render kernel, which takes several times longer to build."""
        target = self._target(self.checked.render)
        key = ("distance", escape_time_sets, self.checked.render, target)
        if key not in self._programs:
            source = emit_distance(lower(self.checked, escape_time_sets=escape_time_sets), target)
            self._programs[key] = build(source, self.device, target.build_options, kernels=("distance_at_points",))
        return self._programs[key], target

    def escape_time_set(self, points) -> np.ndarray:
        """At (N, 3) points, the scene with each fractal that has a bailout
        replaced by its escape-time set: -1 where the orbit stays within the
        bailout for all the iterations (what the formula means), 1 where it
        escapes; other shapes give their distances. `check --de` marches it
        to measure the estimate against the set."""
        program, target = self._distance_program(escape_time_sets=True)
        return run.distances(program, self.device, points, self._param_values(), target.lanes, target.double)

    def mesh(self, resolution: int = 256, bounds=None, progress: bool = False):
        """The surface as a watertight triangle mesh (fractalc.mesh.Mesh:
        vertices, faces, normals; `.save(path)`), sampled on a grid of
        `resolution` cells along the longest side of `bounds` (xmin, ymin,
        zmin, xmax, ymax, zmax; default: around the scene's bound, which an
        unbounded scene lacks). Needs the 'mesh' extra (scikit-image)."""
        return mesh(self, resolution, bounds, progress)

    def render(self, seed: int = 0, progress=False, camera: Camera | None = None,
               cluster=None, denoise: bool = False, **render_keys) -> Image:
        """Render with the file's settings, overridden by keyword (any render
        key: width=, height=, samples=, ao=, max_steps=, ...); `camera`
        replaces the file's camera (no rebuild); `aovs` names the passes
        to add to the default channels (passes.PASSES: P, diffuse, ...).
        `cluster`: a Dask client (distributed.Client) whose workers render
        the image in row tiles (docs/cluster.md). `progress`: True for a
        bar on the terminal, or a function called with the pixels done and
        the total after each tile (an exception it raises stops the
        render). `denoise`: the colour
        denoised by Intel Open Image Denoise (the 'denoise' extra), guided
        by the albedo pass, which the image then has (docs/looks.md)."""
        if denoise:
            require_denoiser()
            aovs = tuple(render_keys.pop("aovs", None) or ()) + ("albedo",)
            return denoise_image(self.render(seed, progress, camera, cluster, aovs=aovs, **render_keys))
        if cluster is not None:
            if not all(hasattr(cluster, name) for name in ("submit", "nthreads")):
                raise TypeError(f"cluster must be a Dask client (distributed.Client), not {cluster!r:.60}")
            return render_still(self, cluster, _checked_seed(seed, camera), camera, progress, **render_keys)
        renderer = self.renderer(seed, camera, **render_keys)
        settings = renderer.settings
        require_image_memory(settings.width, settings.height, len(renderer.channels), renderer.path_traced)
        renderer.kernel   # built before the clock starts
        total = settings.width * settings.height * renderer.passes
        bar = run.ProgressReporter(progress, total) if callable(progress) else \
            run.terminal_progress(total) if progress else None
        start = time.perf_counter()
        try:
            pixels = renderer.pixels(bar.update if bar else None)
        except MemoryError:   # the host's image array: a runtime failure, in one line
            raise RenderError(f"out of memory for a {settings.width}x{settings.height} image") from None
        finally:
            if bar:
                bar.close()
        return renderer.image(pixels, time.perf_counter() - start)

    def renderer(self, seed: int = 0, camera: Camera | None = None, **render_keys) -> Renderer:
        """A render prepared with the file's settings overridden by
        `render_keys` and its camera by `camera`, as `render` takes them:
        a `Renderer`, which renders the frame whole or a block of its rows
        at a time. Its kernel is built on first use."""
        seed = _checked_seed(seed, camera)
        settings = self.render_settings(**render_keys)
        return Renderer(self, settings, camera or self.checked.camera, seed, self._target(settings))


class Renderer:
    """One render of a scene, prepared (`Scene.renderer`): its settings,
    camera, channels, frame (size, samples, seed, camera block), param
    values and kernel target. The whole frame (`pixels`) and any block of
    its rows (`rows`) give the same pixels bit for bit, sampling being
    seeded per pixel of the whole frame."""

    def __init__(self, scene: Scene, settings: RenderSettings, camera: Camera, seed: int, target: Target):
        self.scene, self.settings, self.camera, self.target = scene, settings, camera, target
        self.channels = _channels(settings.aovs)
        self.frame = run.Frame(settings.width, settings.height, settings.samples, seed, run.camera_block(camera))
        self.params = scene._param_values()
        self.path_traced = settings.integrator == "path"    # in passes of samples (pathtrace.pass_frames)

    @property
    def kernel(self) -> run.RenderKernel:
        """The scene's render kernel for these settings, built on first use."""
        return self.scene._render_kernel(self.settings, self.camera, self.target)

    @property
    def passes(self) -> int:
        """The launches over the whole frame: the path tracer's passes, else one."""
        return len(pathtrace.pass_frames(self.frame)) if self.path_traced else 1

    def pixels(self, progress: Callable[[int], None] | None = None) -> np.ndarray:
        """The frame: an (H, W, channels) float32 array (run.CHANNELS, then
        the passes' channels); `progress(pixels)` after each tile."""
        kernel = self.kernel
        return self._over_passes(lambda frame: kernel.render(frame, self.params, progress, self.channels))

    def rows(self, first: int, count: int) -> np.ndarray:
        """Rows `first` to `first + count - 1` of the frame: a (count, W,
        channels) float32 array, equal to those rows of `pixels`."""
        kernel = self.kernel
        return self._over_passes(lambda frame: kernel.rows(frame, self.params, first, count, self.channels))

    def _over_passes(self, render_pass: Callable[[run.Frame], np.ndarray]) -> np.ndarray:
        """`render_pass` over the frame: once, or over the path tracer's
        passes as a whole frame's are (so rows and frame give the same pixels)."""
        return pathtrace.render_passes(render_pass, self.frame) if self.path_traced else render_pass(self.frame)

    def image(self, pixels: np.ndarray, seconds: float) -> Image:
        """The Image of the frame's `pixels` (no copy), with its metadata."""
        return image_from_pixels(pixels, self.settings.aovs, self.metadata(seconds))

    def metadata(self, seconds: float) -> dict[str, str]:
        """The image's metadata (docs/compositing.md), `seconds` its render time."""
        scene = self.scene
        before, after = _frame_metadata(scene.checked.file, scene.checked.source,
                                        tuple(p.name for p in scene.checked.params), tuple(self.params),
                                        self.settings, self.camera, scene.device.info.name)
        return {**before,
                "render_seconds": f"{seconds:.6f}",   # a small frame takes under a millisecond
                "rendered_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                **after}


def _vector(v) -> str:
    return " ".join(f"{x:g}" for x in v)


@lru_cache(maxsize=16)
def _frame_metadata(file: str, source: str, names: tuple[str, ...], values: tuple[float, ...],
                    settings: RenderSettings, camera: Camera, device: str) -> tuple[dict[str, str], dict[str, str]]:
    """A frame's metadata but its render time and date: the entries before
    them and those after, the same for each frame of one scene, settings,
    camera and params (composed once: Python's work per frame, after the
    kernel has left its caches cold, took 0.12 ms at 640x480 composing them)."""
    view, matrices = _camera_metadata(camera, settings.width, settings.height)
    before = {"version": __version__, "scene_file": file, "scene_sha256": _sha256(source), **view,
              "params": " ".join(f"{name}={v:g}" for name, v in zip(names, values)),
              "precision": settings.precision, "device": device}
    return before, {**matrices, **_text_metadata(source), **_settings_metadata(settings)}


def _camera_metadata(camera: Camera, width: int, height: int) -> tuple[dict[str, str], dict[str, str]]:
    """A camera's entries in an image's metadata: its view, then OpenEXR's
    standard camera attributes (write.MATRICES), row-major, and its
    projection."""
    view = {"camera.position": _vector(camera.position), "camera.target": _vector(camera.target),
            "camera.up": _vector(camera.up), "camera.fov": f"{camera.fov:g}"}
    matrices = {"worldToCamera": " ".join(f"{x:.9g}" for x in run.world_to_camera(camera).flat)}
    if (camera.projection, camera.stereo) == ("pinhole", "none"):   # a single pinhole's projection, no other's
        matrices["worldToNDC"] = " ".join(f"{x:.9g}" for x in run.world_to_ndc(camera, width, height).flat)
    matrices.update({"camera.projection": camera.projection, "camera.stereo": camera.stereo})
    return view, matrices


def _text_metadata(source: str) -> dict[str, str]:
    """The scene text's entry in the metadata, if it is short enough."""
    return {"scene_text": source} if len(source.encode()) <= SCENE_TEXT_LIMIT else {}


def _settings_metadata(settings: RenderSettings) -> dict[str, str]:
    """The render settings' entries in the metadata."""
    metadata = {}
    for f in fields(RenderSettings):
        value = getattr(settings, f.name)
        if f.name == "aovs":
            metadata["render.aovs"] = " ".join(value)
        else:
            metadata[f"render.{f.name}"] = _vector(value) if isinstance(value, tuple) else str(value)
    return metadata


@lru_cache(maxsize=16)
def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


@lru_cache(maxsize=16)
def _compiled(settings: RenderSettings) -> RenderSettings:
    """`settings` with the runtime keys at their defaults: the settings the
    kernel's source depends on."""
    return replace(settings, **_RUNTIME_DEFAULTS)


def _unchanged(settings: RenderSettings, key: str, value) -> bool:
    """Whether `value` is the setting's own, of its very type (an int, a
    float, a str: checked when it was set), so that it needs no check
    again: the same width and height given each frame, for one (a check
    and a copy of the settings cost 20 us a key, a fifth of a frame's
    Python work at 640x480 after the kernel has run)."""
    current = getattr(settings, key)
    return type(value) is type(current) and type(value) in (int, float, str) and value == current


def _checked_seed(seed, camera) -> int:
    """A render's `seed`, checked, once `camera` is checked to be a camera."""
    require_type("seed", seed, (int, np.integer), "a whole number")
    seed = _seed(seed)
    if camera is not None:
        require_type("camera", camera, CAMERA_BASE, "a fractalc.Camera")
    return seed


@lru_cache(maxsize=64)    # an animation's seed, checked once (an error is never kept)
def _seed(seed) -> int:
    return checked("seed", seed)


@lru_cache(maxsize=16)
def _channels(aovs: tuple[str, ...]) -> tuple[str, ...]:
    return channels(aovs)


def _check_lanes(lanes) -> None:
    if lanes is not None:
        require_type("lanes", lanes, int, f"one of {', '.join(map(str, LANE_CHOICES))}")
        if lanes not in LANE_CHOICES:
            raise ValueError(f"lanes must be one of {', '.join(map(str, LANE_CHOICES))}, not {lanes!r}")


def loads(text: str, params: dict | None = None, precision: str | None = None,
          device: str | int | None = None, path: str = "<string>", lanes: int | None = None) -> Scene:
    """Parse and check scene text; raise SceneError on any mistake in it.
    `device`: an index or a name, as --device takes; `lanes` (1, 2, 4, 8,
    16) overrides the rays per work-item."""
    require_type("text", text, str, "the scene's text as a str (load() reads a file)")
    require_type("path", path, (str, os.PathLike), "the file name to show in messages")
    if params is not None:
        require_type("params", params, Mapping, "a dict of param name -> number")
    return Scene(check(parse(text, os.fspath(path))), params, precision, device, lanes)


def load(path: str | os.PathLike, params: dict | None = None, precision: str | None = None,
         device: str | int | None = None, lanes: int | None = None) -> Scene:
    """Read, parse and check a .frac file (see `source.read_scene_file`)."""
    require_type("path", path, (str, os.PathLike), "a .frac file's name (str or pathlib.Path)")
    path = os.fspath(path)
    return loads(read_scene_file(path), params, precision, device, path, lanes)
