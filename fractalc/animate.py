"""`fractalc animate`: a scene's camera path rendered to numbered frames,
and optionally an MP4 of them.

Frames already on disk are kept, so a run that stopped resumes where it
stopped; each frame file appears atomically (`Image.save`), so a frame on
disk is a whole frame. Each frame also carries, in its metadata, a digest
of the scene text and settings it was rendered with: a frame on disk is
kept only if its digest is this run's, so a run with other text or
settings renders stale frames again instead of mixing them in.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import sys

import numpy as np

from .api import Scene
from .arguments import checked, require_type
from .cluster import Done, Job, on_worker, scene_spec
from .errors import RenderError
from .paths import camera_at, frame_times, params_at
from .version import __version__
from .write import DEFAULT_TONE_CURVE, linear_to_srgb, replacing, tone_mapped


FRAME_EXTENSIONS = (".exr", ".png")
# printf's conversions of a whole number, with flags and a width: %d, %04d, %-6i, %u
_FRAME_NUMBER = re.compile(r"%[-+ #0]*\d*[diu]")


def check_pattern(pattern) -> str:
    """`pattern`, the frames' file names with the frame number (e.g.
    `frames/frame_%04d.png`), checked whole before any frame is rendered:
    one whole-number conversion (%d, %04d, %i or %u; `%%` for a percent
    sign), in the file's name (frames share one folder), and an .exr or
    .png name without control characters; ValueError saying what is wrong."""
    require_type("the frames' pattern", pattern, (str, os.PathLike), "a file name with %d, e.g. frames/f_%04d.png")
    pattern = os.fspath(pattern)
    example = "e.g. frames/frame_%04d.png"
    numbers = list(_FRAME_NUMBER.finditer(pattern))
    others = re.sub("%%", "", _FRAME_NUMBER.sub("", pattern))
    if len(numbers) != 1 or "%" in others:
        raise ValueError(f"{pattern}: the name must hold the frame number once, as %d or %04d (%% for a "
                         f"percent sign), {example}")
    folder_end = max(pattern.rfind("/"), pattern.rfind(os.sep))
    if numbers[0].start() < folder_end:
        raise ValueError(f"{pattern}: the frame number goes in the file's name, not a folder's, {example}")
    first = pattern % 0
    if any(ord(c) < 32 or ord(c) == 127 for c in first):
        raise ValueError(f"{pattern!r}: a control character in the name")
    if not first.lower().endswith(FRAME_EXTENSIONS):
        raise ValueError(f"{pattern}: frames must be {' or '.join(FRAME_EXTENSIONS)}")
    return pattern


def frame_file(pattern: str, index: int) -> str:
    """The file of frame `index`: `pattern` holds a printf number (check_pattern)."""
    return pattern % index


SETTINGS_KEY = "path.settings_sha256"      # frame metadata: the digest of _frame_settings


def _frame_settings(scene: Scene, fps: float, seed: int, render_keys: dict) -> str:
    """The digest of all that makes a frame what it is besides its index:
    the scene text, params, every render setting (size, samples,
    precision, ...), fps, seed and the fractalc version."""
    settings = {
        "fractalc": __version__,
        "scene_sha256": scene.source_sha256,
        "params": scene.params,
        "render": dataclasses.asdict(scene.render_settings(**render_keys)),
        "camera": dataclasses.asdict(scene.checked.camera),    # the file's, or --camera's
        "fps": fps,
        "seed": seed,
    }
    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()


def _stamp(file: str) -> str | None:
    """The settings digest a frame file carries; None if there is no
    readable frame there."""
    import OpenImageIO as oiio
    if not os.path.isfile(file):
        return None
    image = oiio.ImageInput.open(file)
    if image is None:
        oiio.geterror()          # not a frame: render it, and let the error go
        return None
    stamp = image.spec().getattribute(f"fractalc:{SETTINGS_KEY}")
    image.close()
    return stamp


@dataclasses.dataclass(frozen=True)
class FramePlan:
    """An animation's frames: their files, times and settings digest, and
    the indices of those to render now."""
    path: object                # the scene's Path
    times: np.ndarray
    files: list[str]
    settings: str               # _frame_settings
    missing: list[int]
    chosen: range               # the frames asked for (all of them, or a --frames range)


def parse_frame_range(text: str) -> tuple[int, int | None]:
    """`--frames`: FIRST-LAST, FIRST- (to the end) or one frame N, counted
    from 0; (first, last), last None for the end."""
    first, dash, last = (part.strip() for part in text.partition("-"))
    numbers = [first, last] if last else [first]
    if not all(n.isascii() and n.isdigit() for n in numbers) or (last and int(last) < int(first)):
        raise ValueError(f"'{text}' is not a frame range: N, FIRST-LAST or FIRST- (frames count from 0, "
                         "FIRST at most LAST)")
    if not dash:
        return int(first), int(first)
    return int(first), int(last) if last else None


def _frame_range(frames) -> tuple[int, int | None]:
    """`frames` (first, last or None: to the end), checked; all frames for None."""
    if frames is None:
        return 0, None
    takes = "a pair (first, last) of frame numbers from 0, last None for the end"
    require_type("frames", frames, (tuple, list), takes)
    if len(frames) != 2:
        raise ValueError(f"frames must be {takes}, not {frames!r}")
    first, last = frames
    require_type("frames' first", first, int, "a frame number from 0")
    if last is not None:
        require_type("frames' last", last, int, "a frame number from 0, or None for the end")
    if first < 0 or (last is not None and last < first):
        raise ValueError(f"frames must be {takes}, first at most last, not {frames!r}")
    return first, last


def plan_frames(scene: Scene, pattern: str, fps: float, seed: int, overwrite: bool, render_keys: dict,
                frames: tuple[int, int | None] | None = None) -> FramePlan:
    """The frames of the scene's path and which of them are not on disk yet
    from the same scene text and settings (all of them with `overwrite`),
    among `frames` (first, last or None: the end) if given, so that
    machines can share an animation; makes the frames' folder."""
    pattern = check_pattern(pattern)
    require_type("seed", seed, int, "a whole number")
    seed = checked("seed", seed)
    path = scene.checked.path
    if path is None:
        raise ValueError(f"{scene.checked.file} has no 'path' to animate")
    times = frame_times(path, fps)
    files = [frame_file(pattern, i) for i in range(len(times))]
    first, last = _frame_range(frames)
    if first >= len(times):
        raise ValueError(f"--frames {first}-{'' if last is None else last}: the path has {len(times)} frames "
                         f"at {fps:g} fps, 0 to {len(times) - 1}")
    chosen = range(first, len(times) if last is None else min(last + 1, len(times)))
    settings = _frame_settings(scene, fps, seed, render_keys)
    missing = [i for i in chosen if overwrite or _stamp(files[i]) != settings]
    os.makedirs(os.path.dirname(os.path.abspath(files[0])), exist_ok=True)
    return FramePlan(path, times, files, settings, missing, chosen)


def render_frame(scene: Scene, path, time: float, seed: int, render_keys: dict, progress=False):
    """The frame at `time` on `path` as an Image (its params and camera
    from the path; the scene's params are left at the frame's);
    `progress` as for `Scene.render`."""
    scene.set_params(params_at(path, time))
    return scene.render(seed=seed, camera=camera_at(path, scene.checked.camera, time), progress=progress,
                        **render_keys)


def save_frame(image, plan: FramePlan, index: int) -> None:
    """Write frame `index` atomically, stamped with its settings digest."""
    metadata = {**image.metadata, "path.frame": str(index), "path.time": f"{float(plan.times[index]):g}",
                SETTINGS_KEY: plan.settings}
    dataclasses.replace(image, metadata=metadata).save(plan.files[index])


def render_frames(scene: Scene, pattern: str, fps: float, seed: int = 0, overwrite: bool = False,
                  progress: bool = False, cluster=None, frames: tuple[int, int | None] | None = None,
                  **render_keys) -> tuple[list[str], int]:
    """Render every frame of the scene's path that is not on disk yet from
    the same scene text and settings (all of them with `overwrite`), here
    or by the workers of `cluster`, a Dask client (docs/cluster.md); only
    `frames` (first, last or None: the end), if given (here, not on a cluster).
    Returns the frame files, in order, and how many were rendered now. The
    scene's params are restored afterwards."""
    if cluster is not None:
        if frames is not None:
            raise ValueError("--frames is for sharing an animation between machines without a cluster; "
                             "a cluster shares the frames itself")
        return _render_on_cluster(scene, plan_frames(scene, pattern, fps, seed, overwrite, render_keys), cluster,
                                  seed, progress, render_keys)
    from tqdm import tqdm
    plan = plan_frames(scene, pattern, fps, seed, overwrite, render_keys, frames)
    original = dict(scene.params)
    files = [plan.files[i] for i in plan.chosen]
    bar = tqdm(total=len(files), initial=len(files) - len(plan.missing), unit="frame", leave=False,
               disable=not (progress and sys.stderr.isatty()), desc="animating")
    try:
        for index in plan.missing:
            save_frame(render_frame(scene, plan.path, float(plan.times[index]), seed, render_keys), plan, index)
            bar.update(1)
    finally:
        bar.close()
        scene.set_params(original)
    return files, len(plan.missing)


def frame_task(spec, path, at: float, seed: int) -> Done:
    """On a worker of a render farm (fractalc/cluster.py): the frame at
    time `at` on the camera `path` of the scene of `spec` (a SceneSpec)."""
    return on_worker(spec, lambda scene, keys: render_frame(scene, path, at, seed, keys))


def _render_on_cluster(scene: Scene, plan: FramePlan, client, seed: int, progress: bool,
                       render_keys: dict) -> tuple[list[str], int]:
    """The frames of `plan` not on disk yet rendered by the workers of
    `client` (a distributed.Client), each written here as it arrives."""
    spec = scene_spec(scene, render_keys)
    job = Job(client, len(plan.files), len(plan.files) - len(plan.missing), "frame", progress)
    job.run(((index, frame_task, (spec, plan.path, float(plan.times[index]), seed)) for index in plan.missing),
            lambda index, image: save_frame(image, plan, index))
    job.report()
    return plan.files, len(plan.missing)


def _display_pixels(file: str) -> np.ndarray:
    """A frame file as sRGB 8-bit RGB: PNG as it is, EXR converted through
    the exposure and tone curve its header names, as its PNG would be."""
    import OpenImageIO as oiio
    image = oiio.ImageInput.open(file)
    if image is None:
        raise RenderError(f"cannot read {file}: {oiio.geterror()}")
    pixels = np.asarray(image.read_image(oiio.FLOAT))[..., :3]
    spec = image.spec()
    image.close()
    if file.lower().endswith(".exr"):
        exposure = float(spec.get_string_attribute("fractalc:render.exposure", "0"))
        curve = spec.get_string_attribute("fractalc:render.tonemap", DEFAULT_TONE_CURVE)
        pixels = linear_to_srgb(tone_mapped(pixels, exposure, curve))
    return np.round(np.clip(pixels, 0.0, 1.0) * 255.0).astype(np.uint8)


def require_mp4_writer() -> None:
    """Fail before any rendering if MP4 output cannot be written."""
    try:
        import imageio  # noqa: F401
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        raise RenderError("writing MP4 needs imageio and imageio-ffmpeg: pip install 'fractalc[mp4]'") from None


def write_mp4(files: list[str], path: str, fps: float) -> None:
    """Encode the frames as H.264 (yuv420p, which players expect) into
    `path`, atomically."""
    require_mp4_writer()
    import imageio.v2 as imageio
    with replacing(path) as temporary:
        # yuv420p halves the chroma resolution: sizes must be even
        writer = imageio.get_writer(temporary, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                    pixelformat="yuv420p", macro_block_size=2, quality=8)
        try:
            for file in files:
                writer.append_data(_display_pixels(file))
        finally:
            writer.close()
