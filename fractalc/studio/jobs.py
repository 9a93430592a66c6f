"""Final renders from the studio: a still, or the frames of the path, in a
thread of their own, with progress and cancelling.

A job renders what its command line renders: the command is made first,
and the job takes its values (params and camera as the command writes
them) from it, through the same API calls as `fractalc render` and
`fractalc animate`; the page shows the command.
"""
from __future__ import annotations

import os
import shlex
import threading
import time
from dataclasses import asdict, dataclass, replace
from enum import Enum
from typing import Callable

from ..animate import plan_frames, render_frame, save_frame
from ..api import Camera, Scene
from ..errors import RenderError, SceneError
from ..program import CheckedScene
from ..write import IMAGE_EXTENSIONS, output_problem
from .edits import number_text

FRAME_EXTENSIONS = (".exr", ".png")
CAMERA_KEYS = ("position", "target", "up", "fov")     # the keys the studio's camera moves
PROGRESS_SECONDS = 0.1          # at most this often a progress report


class JobKind(Enum):
    STILL = "still"
    ANIMATION = "animation"


class JobState(Enum):
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"


@dataclass(frozen=True)
class RenderRequest:
    """A final render as the page asks for it; `output` is relative to the
    studio's working folder, as on the command line."""
    kind: JobKind
    output: str
    width: int
    height: int
    samples: int
    integrator: str
    fps: float = 30.0


@dataclass(frozen=True)
class JobStatus:
    state: JobState
    progress: float         # 0 to 1
    output: str
    command: str
    message: str = ""


class _Cancelled(Exception):
    pass


def output_mistake(request: RenderRequest) -> str | None:
    """What is wrong with the request's output name, or None."""
    output = request.output
    if request.kind is JobKind.STILL:
        if not output.lower().endswith(IMAGE_EXTENSIONS):
            return f"the output must end in one of {', '.join(IMAGE_EXTENSIONS)}"
        return output_problem(output)
    try:
        first, second = output % 0, output % 1
    except (TypeError, ValueError):
        first = second = None
    if first is None or first == second:
        return "the frames' name must hold the frame number, e.g. frames/frame_%04d.png"
    if not first.lower().endswith(FRAME_EXTENSIONS):
        return "frames must be .exr or .png"
    return output_problem(first, folders_made=True)


class Job:
    """One final render. `post(status)` is called from its thread."""

    def __init__(self, request: RenderRequest, scene_file: str, checked: CheckedScene, params: dict,
                 camera: Camera, precision: str | None, device: str | None, post: Callable[[JobStatus], None]):
        self.request = request
        self._post = post
        self._cancel = threading.Event()
        # the command's values: params and camera keys that differ from the file's, as written there
        defaults = {p.name: p.default for p in checked.params}
        self.params = {name: float(number_text(value)) for name, value in params.items() if value != defaults[name]}
        self.camera = {}
        for key in CAMERA_KEYS:
            value, written = getattr(camera, key), getattr(checked.camera, key)
            if value != written:
                self.camera[key] = tuple(float(number_text(v)) for v in value) if isinstance(value, tuple) \
                    else float(number_text(value))
        words = ["fractalc", "render" if request.kind is JobKind.STILL else "animate", scene_file,
                 "-o", request.output]
        if request.kind is JobKind.ANIMATION:
            words += ["--fps", number_text(request.fps)]
        words += ["--width", str(request.width), "--height", str(request.height), "--samples", str(request.samples)]
        if request.integrator != checked.render.integrator:
            words += ["--render", f"integrator={request.integrator}"]
        for key, value in self.camera.items():
            shown = ",".join(number_text(v) for v in value) if isinstance(value, tuple) else number_text(value)
            words += ["--camera", f"{key}={shown}"]
        for name, value in self.params.items():
            words += ["--set", f"{name}={number_text(value)}"]
        self.command = shlex.join(words)
        self.scene = Scene(checked, params=self.params, precision=precision, device=device)
        # as the command line's --camera and --render make them the scene's own
        self.scene.set_defaults(Camera(**{**asdict(checked.camera), **self.camera}) if self.camera else None,
                                integrator=request.integrator)
        self.status = JobStatus(JobState.RUNNING, 0.0, request.output, self.command)
        self._thread = threading.Thread(target=self._run, name="fractalc-studio-job", daemon=True)
        self._reported = 0.0

    def start(self) -> None:
        self._thread.start()

    def cancel(self) -> None:
        self._cancel.set()

    @property
    def running(self) -> bool:
        return self.status.state is JobState.RUNNING

    def _report(self, progress: float, force: bool = False) -> None:
        if self._cancel.is_set():
            raise _Cancelled
        now = time.monotonic()
        if force or now - self._reported >= PROGRESS_SECONDS:
            self._reported = now
            self._finish(JobState.RUNNING, progress)

    def _finish(self, state: JobState, progress: float, message: str = "") -> None:
        self.status = replace(self.status, state=state, progress=progress, message=message)
        self._post(self.status)

    def _run(self) -> None:
        request = self.request
        keys = {"width": request.width, "height": request.height, "samples": request.samples}
        try:
            if request.kind is JobKind.STILL:
                image = self.scene.render(progress=lambda done, total: self._report(done / total), **keys)
                image.save(request.output)
                message = f"wrote {request.output}"
            else:
                message = self._animate(keys)
        except _Cancelled:
            self._finish(JobState.CANCELLED, self.status.progress, "cancelled")
        except (RenderError, SceneError, ValueError, OSError) as error:
            self._finish(JobState.FAILED, self.status.progress, str(error).splitlines()[0])
        except Exception as error:     # a bug: one line, the studio goes on
            self._finish(JobState.FAILED, self.status.progress, f"internal error: {type(error).__name__}: {error}")
        else:
            self._finish(JobState.DONE, 1.0, message)

    def _animate(self, keys: dict) -> str:
        """`fractalc animate`'s loop (frames on disk from the same settings
        are kept), reporting progress per tile and frame."""
        request, scene = self.request, self.scene
        plan = plan_frames(scene, request.output, request.fps, 0, False, keys)
        count = len(plan.missing)
        for done, index in enumerate(plan.missing):
            image = render_frame(scene, plan.path, float(plan.times[index]), 0, keys,
                                 progress=lambda pixels, total: self._report((done + pixels / total) / count))
            save_frame(image, plan, index)
            self._report((done + 1) / count, force=True)
        kept = len(plan.files) - count
        return f"wrote {count} of {len(plan.files)} frames ({kept} already there) to " \
               f"{os.path.dirname(request.output) or '.'}"
