"""The studio's live image: one thread checks the page's text and renders
the newest view of the scene.

Requests wait in one slot each (a text to check, a view to render): a new
request replaces the one waiting, so under any flood of changes the thread
does the newest and memory stays bounded. A view is first rendered small
with one sample (the preview, never cut short: a steady stream of changes
still shows images), then, once no request came for a moment, refined
while nothing newer waits: the full-size pinhole image, then the running
mean of jittered two-sample passes up to `max_samples`. A refining pass
stops at its next tile when a request comes.
Params and the camera are kernel arguments: only a new scene text builds.
"""
from __future__ import annotations

import io
import threading
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .. import build
from ..api import Camera, Scene
from ..check import check
from ..devices import open_device
from ..errors import RenderError, SceneError
from ..parse import parse
from ..program import CheckedScene
from ..write import linear_to_srgb, tone_mapped

# Samples per refining pass: few, so that a pass ends soon when a request
# comes, but two: one sample is the pinhole ray through the pixel's centre,
# the same in every pass (LANGUAGE.md's camera model), two are jittered.
PASS_SAMPLES = 2
# Refining starts once no request came, and no preview was shown, for this
# long: while a slider or the camera moves, every image is a preview, and
# a move finds the thread free.
REFINE_AFTER_SECONDS = 0.25
JPEG_QUALITY = 90


@dataclass(frozen=True)
class View:
    """What the live image shows: `seq` is the page's request it answers."""
    seq: int
    checked: CheckedScene
    params: dict
    camera: Camera
    size: tuple[int, int]      # the still image's width and height


@dataclass(frozen=True)
class Frame:
    """A rendered image of a view, JPEG-encoded for the page."""
    seq: int
    width: int
    height: int
    samples: int
    builds: int                # kernels this process has built so far
    milliseconds: float        # render time
    jpeg: bytes


class _Superseded(Exception):
    """A newer request waits: the refining pass in progress stops."""


class LiveRenderer:
    """The thread behind the live image. `post(event, payload)` is called
    from it: ("checked", (version, CheckedScene)), ("diagnostics",
    (version, SceneError)), ("frame", Frame), ("building", View),
    ("param_error", SceneError), ("failure", message) and ("device", name)."""

    def __init__(self, post: Callable[[str, object], None], device: str | None = None,
                 precision: str | None = None, preview_scale: int = 2, max_samples: int = 64):
        self._post = post
        self._device, self._precision = device, precision
        self._preview_scale, self._max_samples = preview_scale, max_samples
        self._wake = threading.Condition()
        self._text: tuple[int, str, str] | None = None     # (version, text, file) waiting to be checked
        self._view: View | None = None                     # waiting to be rendered
        self._stopped = False
        self._active = 0.0             # when the last request came or its preview was shown (monotonic)
        self._thread = threading.Thread(target=self._run, name="fractalc-studio-live", daemon=True)
        # the thread's own
        self._scene: Scene | None = None
        self._shown: View | None = None       # the view being refined
        self._sum: np.ndarray | None = None   # of the refining passes
        self._passes = 0
        self._full_size = False               # the full-size image of the view is shown

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        with self._wake:
            self._stopped = True
            self._wake.notify()
        self._thread.join(timeout=30)

    def check(self, version: int, text: str, file: str) -> None:
        with self._wake:
            self._text = (version, text, file)
            self._active = time.monotonic()
            self._wake.notify()

    def show(self, view: View) -> None:
        with self._wake:
            self._view = view
            self._active = time.monotonic()
            self._wake.notify()

    # ---- the thread ------------------------------------------------------------

    def _waiting(self) -> bool:
        return self._stopped or self._text is not None or self._view is not None

    def _refining(self) -> bool:
        return self._shown is not None and self._passes * PASS_SAMPLES < self._max_samples

    def _still_for(self) -> float:
        """Seconds until the view has been still long enough to refine."""
        return self._active + REFINE_AFTER_SECONDS - time.monotonic()

    def _run(self) -> None:
        try:
            self._post("device", open_device(self._device).info.name)
        except RenderError as error:
            self._post("failure", str(error))
        while True:
            with self._wake:
                while not (self._waiting() or (self._refining() and self._still_for() <= 0)):
                    self._wake.wait(self._still_for() if self._refining() else None)
                if self._stopped:
                    return
                text, self._text = self._text, None
                view = None if text else self._view
                if view is not None:
                    self._view = None
            try:
                if text is not None:
                    self._check(*text)
                elif view is not None:
                    self._preview(view)
                else:
                    self._refine()
            except _Superseded:
                pass
            except RenderError as error:
                self._shown = None
                self._post("failure", str(error))
            except SceneError as error:       # values computed from the params out of range
                self._shown = None
                self._post("param_error", error)
            except Exception as error:        # a bug: said in one line, the thread goes on
                self._shown = None
                self._post("failure", f"internal error: {type(error).__name__}: {error}")

    def _check(self, version: int, text: str, file: str) -> None:
        try:
            checked = check(parse(text, file))
        except SceneError as error:
            self._post("diagnostics", (version, error))
        else:
            self._shown = None          # the old text's view: refining it is no use now
            self._post("checked", (version, checked))

    def _scene_for(self, view: View) -> Scene:
        if self._scene is None or self._scene.checked.source != view.checked.source \
                or self._scene.checked.file != view.checked.file:
            self._post("building", view)
            self._scene = Scene(view.checked, precision=self._precision, device=self._device)
        self._scene.set_params(view.params)
        return self._scene

    def _render(self, view: View, width: int, height: int, samples: int, seed: int, stoppable: bool):
        def stop_if_superseded(done: int, total: int) -> None:
            if self._waiting():
                raise _Superseded
        scene = self._scene_for(view)
        start = time.perf_counter()
        image = scene.render(camera=view.camera, width=width, height=height, samples=samples, seed=seed,
                             progress=stop_if_superseded if stoppable else False)
        return image.rgba[..., :3], (time.perf_counter() - start) * 1000.0

    def _preview(self, view: View) -> None:
        width, height = view.size
        scale = self._preview_scale
        self._shown, self._sum, self._passes = None, None, 0
        rgb, milliseconds = self._render(view, max(1, width // scale), max(1, height // scale), 1, 0, False)
        self._shown, self._full_size = view, scale == 1
        self._send(view, rgb, 1, milliseconds)
        self._active = time.monotonic()

    def _refine(self) -> None:
        view = self._shown
        width, height = view.size
        if not self._full_size:
            rgb, milliseconds = self._render(view, width, height, 1, 0, True)
            self._full_size = True
            self._send(view, rgb, 1, milliseconds)
            return
        rgb, milliseconds = self._render(view, width, height, PASS_SAMPLES, self._passes + 1, True)
        rgb = rgb.astype(np.float64)
        self._sum = rgb if self._sum is None else self._sum + rgb
        self._passes += 1
        self._send(view, self._sum / self._passes, self._passes * PASS_SAMPLES, milliseconds)

    def _send(self, view: View, rgb: np.ndarray, samples: int, milliseconds: float) -> None:
        render = view.checked.render
        pixels = np.round(linear_to_srgb(tone_mapped(rgb.astype(np.float32), render.exposure, render.tonemap))
                          * 255.0).astype(np.uint8)
        self._post("frame", Frame(view.seq, pixels.shape[1], pixels.shape[0], samples, build.statistics.builds,
                                  milliseconds, encode_jpeg(pixels)))


def encode_jpeg(pixels: np.ndarray) -> bytes:
    """(H, W, 3) sRGB 8-bit pixels as JPEG."""
    from PIL import Image
    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels), "RGB").save(out, "JPEG", quality=JPEG_QUALITY)
    return out.getvalue()
