"""`fractalc view`: a window on a scene, rendered by its compiled kernel.

While the camera moves, frames are rendered at a fraction of the window's
size. When it stops, the full-size image refines: first the pinhole image
(one ray through each pixel centre, as `fractalc render --samples 1`), then
the running average of jittered passes with new seeds, which converges to
the anti-aliased render (`--samples N` for large N).

`Viewer` is the state: it takes pygame events (`handle`) and time steps
(`step`) and needs no display, so tests drive it with synthetic events.
`show` is the window around it; `measure` times its frame loop.
"""
from __future__ import annotations

import enum
import math
import os
import sys
import textwrap
import time
from dataclasses import dataclass, replace

import numpy as np

from .errors import RenderError, SceneError

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
try:
    import pygame
except ImportError:
    raise RenderError("fractalc view needs pygame: pip install 'fractalc[view]'") from None

from .api import Image, Scene, load                      # noqa: E402  (after the pygame check)
from .bench import orbit_camera                          # noqa: E402
from .paths import camera_at, params_at                  # noqa: E402
from .program import Camera                              # noqa: E402
from .write import linear_to_srgb, tone_mapped           # noqa: E402

PASS_SAMPLES = 2              # per refining pass: short passes keep the window responsive
LOOK_RADIANS_PER_PIXEL = 0.004
SPEED_FACTOR = 1.25           # per wheel notch or +/- press
PITCH_LIMIT = math.radians(88.0)   # above or below the horizontal: the view never tips over up
MESSAGE_SECONDS = 3.0

# Held keys that move the camera: (axis, sign); axes are the view's.
MOVES = {pygame.K_w: ("forward", 1.0), pygame.K_s: ("forward", -1.0),
         pygame.K_d: ("right", 1.0), pygame.K_a: ("right", -1.0),
         pygame.K_e: ("up", 1.0), pygame.K_q: ("up", -1.0)}
FASTER = (pygame.K_PLUS, pygame.K_EQUALS, pygame.K_KP_PLUS)
SLOWER = (pygame.K_MINUS, pygame.K_KP_MINUS)

HELP = (
    "W A S D     move forward, left, back, right",
    "Q E         move down, up",
    "drag        look around (left mouse button)",
    "wheel + -   faster, slower",
    "Tab         select the next param (Shift: previous)",
    "[ ]         decrease, increase the selected param",
    "Space       play the scene's path from its start; again: stop",
    "R           back to the scene's camera",
    "C           print the camera as a camera { } block",
    "P           save the view as PNG and EXR",
    "H           this help",
    "Esc         quit",
)


def _rotate(vector: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation about a unit axis, right-handed."""
    c, s = math.cos(angle), math.sin(angle)
    return vector * c + np.cross(axis, vector) * s + axis * np.dot(axis, vector) * (1.0 - c)


def _number(x: float) -> str:
    return f"{round(x, 4) + 0.0:g}"     # + 0.0: no "-0"


def _vector(v) -> str:
    return "(" + ", ".join(_number(x) for x in v) + ")"


class Viewer:
    """A fly camera over a scene file, with progressive refinement and live
    reloading. `width` and `height` default to the file's render size."""

    def __init__(self, path: str, width: int | None = None, height: int | None = None,
                 params: dict | None = None, precision: str | None = None, device: str | None = None,
                 preview_scale: int = 2, max_samples: int = 64, output_dir: str = ".",
                 out=sys.stdout, err=sys.stderr):
        self.path = path
        self.precision, self.device = precision, device
        self.overrides = dict(params or {})     # params set here or by --set: kept across reloads
        self.scene: Scene = load(path, params=self.overrides, precision=precision, device=device)
        self._stamp = self._file_stamp()
        settings = self.scene.checked.render
        self.width, self.height = width or settings.width, height or settings.height
        self.preview_scale, self.max_samples = preview_scale, max_samples
        self.output_dir = output_dir
        self.out, self.err = out, err
        self.running = True
        self.error: str | None = None           # the scene file's error, shown until it is fixed
        self._reported: str | None = None       # the last error printed on stderr
        self.message: str | None = None         # a passing note ("saved ...")
        self._message_left = 0.0
        self.show_help = False
        self.selected = 0                       # index of the param [ and ] change
        self.held: set[int] = set()
        self.dragging = False
        self.play_time: float | None = None     # time on the scene's path while it plays
        self.frame_seconds: float | None = None # smoothed time between rendered frames
        self._since_frame = 0.0
        self.look_from(self.scene.checked.camera)
        self.speed = 0.25 * self.distance       # units per second
        # the displayed image: linear RGB, with the samples per pixel in it
        self.linear = np.zeros((self.height, self.width, 3), dtype=np.float32)
        self.samples = 0
        self._pinhole: Image | None = None      # the full-size pinhole render of this view
        self._sum: np.ndarray | None = None     # sum of the jittered passes
        self._passes = 0
        self._moved = True

    # ---- the camera --------------------------------------------------------

    def look_from(self, camera: Camera) -> None:
        """Put the fly camera where `camera` is (a move: the view restarts)."""
        self.position = np.array(camera.position, dtype=np.float64)
        offset = np.subtract(camera.target, camera.position)
        self.distance = float(np.linalg.norm(offset))
        self.forward = offset / self.distance
        self.up = np.array(camera.up, dtype=np.float64) / np.linalg.norm(camera.up)
        self.lens = camera
        self._moved = True

    @property
    def camera(self) -> Camera:
        """The current view; its target is as far ahead as the file's was."""
        return replace(self.lens, position=tuple(float(x) for x in self.position),
                       target=tuple(float(x) for x in self.position + self.forward * self.distance),
                       up=tuple(float(x) for x in self.up))

    def _axes(self) -> dict[str, np.ndarray]:
        right = np.cross(self.forward, self.up)
        return {"forward": self.forward, "right": right / np.linalg.norm(right), "up": self.up}

    def _move(self, dt: float) -> None:
        axes = self._axes()
        direction = sum((axes[MOVES[k][0]] * MOVES[k][1] for k in self.held if k in MOVES), np.zeros(3))
        if np.any(direction):
            self.position = self.position + direction * self.speed * dt
            self._moved = True

    def _look(self, dx: float, dy: float) -> None:
        """Turn by a mouse drag of (dx, dy) pixels (right and down are
        positive): about the up axis, and up or down to PITCH_LIMIT."""
        height = float(np.dot(self.forward, self.up))
        level = self.forward - self.up * height
        level = _rotate(level / np.linalg.norm(level), self.up, -dx * LOOK_RADIANS_PER_PIXEL)
        elevation = min(max(math.asin(min(max(height, -1.0), 1.0)) - dy * LOOK_RADIANS_PER_PIXEL,
                            -PITCH_LIMIT), PITCH_LIMIT)
        self.forward = level * math.cos(elevation) + self.up * math.sin(elevation)
        self._moved = True

    def camera_block(self) -> str:
        """The current camera as a `camera { ... }` block for a .frac file."""
        camera = self.camera
        lines = [f"    position: {_vector(camera.position)}", f"    target: {_vector(camera.target)}",
                 f"    up: {_vector(camera.up)}", f"    fov: {_number(camera.fov)}"]
        if camera.aperture > 0:
            lines.append(f"    aperture: {_number(camera.aperture)}")
        if camera.focus is not None:
            lines.append(f"    focus: {_number(camera.focus)}")
        # the projection and stereo keys where they are not the defaults
        default = Camera()
        for key, show in (("projection", str), ("fisheye_fov", _number), ("stereo", str),
                          ("eye_separation", _number)):
            if getattr(camera, key) != getattr(default, key):
                lines.append(f"    {key}: {show(getattr(camera, key))}")
        return "camera {\n" + "\n".join(lines) + "\n}"

    # ---- input -------------------------------------------------------------

    def handle(self, event) -> None:
        """Take one pygame event."""
        if event.type == pygame.QUIT:
            self.running = False
        elif event.type == pygame.KEYDOWN:
            self._key(event.key, event.mod)
        elif event.type == pygame.KEYUP:
            self.held.discard(event.key)
        elif event.type == pygame.WINDOWFOCUSLOST:
            self.held.clear()            # a key released elsewhere never sends KEYUP here
            self.dragging = False
        elif event.type == pygame.MOUSEBUTTONDOWN and event.button == 1:
            self.dragging = True
        elif event.type == pygame.MOUSEBUTTONUP and event.button == 1:
            self.dragging = False
        elif event.type == pygame.MOUSEMOTION and self.dragging:
            self._look(*event.rel)
        elif event.type == pygame.MOUSEWHEEL:
            self.speed *= SPEED_FACTOR ** event.y

    def _key(self, key: int, mod: int) -> None:
        if key in MOVES:
            self.held.add(key)
        elif key == pygame.K_ESCAPE:
            self.running = False
        elif key in FASTER or key in SLOWER:
            self.speed *= SPEED_FACTOR if key in FASTER else 1.0 / SPEED_FACTOR
        elif key == pygame.K_TAB and self.scene.checked.params:
            self.selected = (self.selected + (-1 if mod & pygame.KMOD_SHIFT else 1)) % len(self.scene.checked.params)
        elif key in (pygame.K_LEFTBRACKET, pygame.K_RIGHTBRACKET):
            self.adjust_param(1 if key == pygame.K_RIGHTBRACKET else -1)
        elif key == pygame.K_SPACE:
            self.toggle_path()
        elif key == pygame.K_r:
            self.look_from(self.scene.checked.camera)
        elif key == pygame.K_c:
            print(self.camera_block(), file=self.out, flush=True)
            self.notify("camera printed to the terminal")
        elif key == pygame.K_p:
            try:
                png, exr = self.save()
            except (RenderError, OSError) as error:
                self._fail(error)
            else:
                self.notify(f"saved {png} and {exr}")
        elif key in (pygame.K_h, pygame.K_F1):
            self.show_help = not self.show_help

    def notify(self, message: str) -> None:
        self.message, self._message_left = message, MESSAGE_SECONDS

    # ---- params and the path -----------------------------------------------

    def adjust_param(self, direction: int) -> None:
        """Step the selected param by a fiftieth of its range (5% of its
        value if it has none), staying in the range."""
        params = self.scene.checked.params
        if not params:
            return
        info = params[self.selected]
        value = self.scene.params[info.name]
        if info.low is not None and info.high is not None:
            value = min(max(value + direction * (info.high - info.low) / 50.0, info.low), info.high)
        else:
            value += direction * 0.05 * max(abs(value), 1.0)
        try:
            self.scene.set_params({info.name: value})
        except SceneError as error:
            self.notify(error.message)
            return
        self.overrides[info.name] = value
        self._restart()

    def toggle_path(self) -> None:
        path = self.scene.checked.path
        if path is None:
            self.notify("the scene has no path")
        else:
            self.play_time = None if self.play_time is not None else path.start

    def _play(self, dt: float) -> None:
        path = self.scene.checked.path
        if self.play_time is None or path is None:
            self.play_time = None
            return
        self.play_time = min(self.play_time + dt, path.end)
        try:
            self.scene.set_params(params_at(path, self.play_time))
        except SceneError as error:
            self._fail(error)
            self.play_time = None
            return
        self.look_from(camera_at(path, self.scene.checked.camera, self.play_time))
        if self.play_time >= path.end:
            self.play_time = None

    # ---- the scene file ----------------------------------------------------

    def _file_stamp(self):
        try:
            stat = os.stat(self.path)
        except OSError:
            return None        # being replaced by an editor: look again next step
        return stat.st_mtime_ns, stat.st_size

    def reload_if_changed(self) -> None:
        """Load the file again if it changed since the last look; on an
        error keep the scene and the image, and show the error."""
        stamp = self._file_stamp()
        if stamp is None or stamp == self._stamp:
            return
        self._stamp = stamp
        try:
            scene = load(self.path, precision=self.precision, device=self.device)
        except (SceneError, RenderError) as error:
            self.error = str(error)
            print(self.error, file=self.err, flush=True)
            return
        kept = {k: v for k, v in self.overrides.items() if k in scene.params}
        try:
            scene.set_params(kept)
        except SceneError:       # outside the new ranges: the file's values
            kept = {}
        self.overrides = kept
        self.scene = scene
        self.selected = min(self.selected, max(len(scene.checked.params) - 1, 0))
        self.error = None
        self._restart()

    # ---- rendering ---------------------------------------------------------

    def _restart(self) -> None:
        self._pinhole, self._sum, self._passes = None, None, 0

    def step(self, dt: float) -> bool:
        """Advance by dt seconds: reload the file if it changed, move the
        camera, render the next frame. Returns whether it rendered one
        (False once the still image has `max_samples` samples)."""
        self._message_left -= dt
        if self._message_left <= 0:
            self.message = None
        self.reload_if_changed()
        self._move(dt)
        self._play(dt)
        try:
            rendered = self._render()
        except RenderError as error:
            self._fail(error)
            rendered = False
        self._since_frame += dt
        if rendered:
            seconds = self._since_frame
            self.frame_seconds = seconds if self.frame_seconds is None else 0.8 * self.frame_seconds + 0.2 * seconds
            self._since_frame = 0.0
        return rendered

    def _fail(self, error: Exception) -> None:
        """A failed render or path param: on stderr (once while it repeats)
        and in the window."""
        text = str(error)
        if text != self._reported:
            print(text, file=self.err, flush=True)
        self._reported = text
        self.notify(text.splitlines()[0])

    def _render(self) -> bool:
        camera = self.camera
        if self._moved:
            self._moved = False
            self._restart()
            image = self.scene.render(camera=camera, width=max(1, self.width // self.preview_scale),
                                      height=max(1, self.height // self.preview_scale), samples=1)
            self._show(image.rgba[..., :3], 1)
        elif self._pinhole is None:
            self._pinhole = self.scene.render(camera=camera, width=self.width, height=self.height, samples=1)
            self._show(self._pinhole.rgba[..., :3], 1)
        elif self.samples < self.max_samples:
            self._passes += 1
            image = self.scene.render(camera=camera, width=self.width, height=self.height,
                                      samples=PASS_SAMPLES, seed=self._passes)
            rgb = image.rgba[..., :3].astype(np.float64)
            self._sum = rgb if self._sum is None else self._sum + rgb
            self._show((self._sum / self._passes).astype(np.float32), self._passes * PASS_SAMPLES)
        else:
            return False
        return True

    def _show(self, rgb: np.ndarray, samples: int) -> None:
        self.linear, self.samples = rgb, samples

    def pixels(self) -> np.ndarray:
        """The displayed image as sRGB 8-bit (H, W, 3), at its render size,
        through the scene's exposure and tone curve, as a PNG shows it."""
        render = self.scene.checked.render
        return np.round(linear_to_srgb(tone_mapped(self.linear, render.exposure, render.tonemap)) * 255.0
                        ).astype(np.uint8)

    def status(self) -> str:
        height, width = self.linear.shape[:2]
        fps = f"{1.0 / self.frame_seconds:.1f}" if self.frame_seconds else "-"
        samples = f"{self.samples} sample{'s' if self.samples != 1 else ''}"
        playing = f" | path t={self.play_time:.2f}" if self.play_time is not None else ""
        return f"{fps} FPS | {width}x{height} | {samples} | speed {self.speed:.3g}/s{playing}"

    def param_lines(self) -> list[str]:
        return [f"{'>' if i == self.selected else ' '} {p.name} = {self.scene.params[p.name]:.4g}"
                for i, p in enumerate(self.scene.checked.params)]

    def save(self) -> tuple[str, str]:
        """Write the full-size view as PNG and EXR (`NAME-view-N.png/.exr`
        in the output folder): the refined image if there is one, else a
        render with the file's samples."""
        if self._pinhole is not None and not self._moved:
            base = self._pinhole
            image = replace(base, rgba=np.concatenate([self.linear, base.rgba[..., 3:]], axis=-1),
                            metadata={**base.metadata, "render.samples": str(self.samples)})
        else:
            image = self.scene.render(camera=self.camera, width=self.width, height=self.height)
        stem = os.path.splitext(os.path.basename(self.path))[0]
        number = 1
        while any(os.path.exists(os.path.join(self.output_dir, f"{stem}-view-{number}{ext}"))
                  for ext in (".png", ".exr")):
            number += 1
        names = tuple(os.path.join(self.output_dir, f"{stem}-view-{number}{ext}") for ext in (".png", ".exr"))
        for name in names:
            image.save(name)
        return names


# ---- the window --------------------------------------------------------------

def _no_display() -> str | None:
    """Why no window can open here, if we can tell before asking SDL (which
    would fall back to an invisible window)."""
    if os.environ.get("SDL_VIDEODRIVER"):
        return None                 # the user chose the driver, dummy included
    if sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")) and not (
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "no display (DISPLAY and WAYLAND_DISPLAY are not set)"
    return None


def _open_window(viewer: Viewer):
    reason = _no_display()
    try:
        if reason is None:
            pygame.display.init()
            if pygame.display.get_driver() in ("offscreen", "dummy") and not os.environ.get("SDL_VIDEODRIVER"):
                reason = "no display"
        if reason is None:
            screen = pygame.display.set_mode((viewer.width, viewer.height))
    except pygame.error as error:
        reason = str(error)
    if reason is not None:
        pygame.display.quit()
        raise RenderError(f"cannot open a window: {reason}")
    pygame.display.set_caption(f"fractalc view {viewer.path}")
    pygame.key.set_repeat(300, 50)     # a held [ or ] keeps stepping the param
    pygame.font.init()
    return screen, overlay_font(screen.get_size())


# The overlay's text: 14 px where the window has room for the help list
# and the status line under it, smaller in smaller windows, never below
# 8 px; what still does not fit is wrapped, then cut (and says so).
FONT_PIXELS = (8, 14)
FONT_NAMES = "dejavusansmono,menlo,consolas,monospace"
PANEL_PADDING = (8, 6)        # a text panel's width and height beyond its text
ERROR_COLOR, TEXT_COLOR = (255, 110, 100), (230, 230, 230)


def overlay_font(size: tuple[int, int]):
    """The overlay's monospace font for a window of `size` pixels: the
    largest in FONT_PIXELS that shows the help list unwrapped, with a line
    to spare for the status."""
    width, height = size
    widest = max(HELP, key=len)
    for pixels in range(FONT_PIXELS[1], FONT_PIXELS[0], -1):
        font = pygame.font.SysFont(FONT_NAMES, pixels)
        if (font.size(widest)[0] + PANEL_PADDING[0] <= width
                and font.get_linesize() * (len(HELP) + 1) + 2 * PANEL_PADDING[1] <= height):
            return font
    return pygame.font.SysFont(FONT_NAMES, FONT_PIXELS[0])


@dataclass(frozen=True)
class TextBlock:
    """Lines of the overlay on a panel at `topleft`."""
    lines: tuple[str, ...]
    topleft: tuple[int, int]
    color: tuple[int, int, int]

    def size(self, font) -> tuple[int, int]:
        if not self.lines:
            return 0, 0
        return (max(font.size(line)[0] for line in self.lines) + PANEL_PADDING[0],
                font.get_linesize() * len(self.lines) + PANEL_PADDING[1])


def _columns(font, width: int) -> int:
    return max(1, (width - PANEL_PADDING[0]) // max(1, font.size("M")[0]))


def fitted(font, lines, width: int, height: int) -> tuple[str, ...]:
    """`lines` wrapped to panels `width` pixels wide (continuations
    indented) and cut to `height`: a cut block ends with how many lines did
    not fit."""
    columns = _columns(font, width)
    rows = max(0, (height - PANEL_PADDING[1]) // font.get_linesize())
    wrapped = [piece for line in lines
               for piece in (textwrap.wrap(line, columns, subsequent_indent="  ", drop_whitespace=False,
                                           break_on_hyphens=False) or [""])]
    if len(wrapped) <= rows:
        return tuple(wrapped)
    if rows == 0:
        return ()
    left = len(wrapped) - (rows - 1)
    return (*wrapped[:rows - 1], f"... {left} more line{'s' if left != 1 else ''}"[:columns])


def _error_lines(error: str, columns: int) -> list[str]:
    """A scene error's lines for a panel `columns` wide: its message as it
    is (to be wrapped), and its source line and caret line (a line of
    carets under it) cut alike to a window of columns around the carets,
    so that the carets still point at their place."""
    lines = error.splitlines()
    out = []
    for i, text in enumerate(lines):
        caret = text.strip() and set(text.strip()) <= {"^"}
        if caret and out and out[-1] == lines[i - 1] and len(max(text, lines[i - 1], key=len)) > columns:
            first = min(text.index("^"), max(0, len(text.rstrip()) - columns))
            out[-1], text = lines[i - 1][first:first + columns], text[first:first + columns]
        out.append(text)
    return out


class Panel(enum.Enum):
    """The overlay's panels, in the order they are drawn."""
    STATUS = "status"
    MESSAGE = "message"
    ERROR = "error"
    PARAMS = "params"
    HELP = "help"


def overlay(viewer: "Viewer", size: tuple[int, int], font) -> dict[Panel, TextBlock]:
    """What the window shows over the image, fitted to it: the status line
    at the bottom and a passing message over it, the scene's error at the
    top, the params under it, and the help list over them; room goes first
    to the status, then the error, the message and the params."""
    width, height = size
    line = font.get_linesize()

    def tall(lines):
        return line * len(lines) + PANEL_PADDING[1] if lines else 0

    status = fitted(font, [viewer.status() + ("" if viewer.show_help else " | H: help")], width, height)
    room = height - tall(status)
    errors = fitted(font, _error_lines(viewer.error, _columns(font, width)), width, room) if viewer.error else ()
    message = fitted(font, [viewer.message], width, room - tall(errors)) if viewer.message else ()
    params = fitted(font, viewer.param_lines(), width, room - tall(errors) - tall(message))
    blocks = {Panel.STATUS: TextBlock(status, (0, height - tall(status)), TEXT_COLOR),
              Panel.MESSAGE: TextBlock(message, (0, room - tall(message)), TEXT_COLOR),
              Panel.ERROR: TextBlock(errors, (0, 0), ERROR_COLOR),
              Panel.PARAMS: TextBlock(params, (0, tall(errors)), TEXT_COLOR)}
    if viewer.show_help:
        # a sixth of the way in where it fits there whole, else from the corner
        corner = (width // 6, height // 6)
        help_lines = fitted(font, HELP, width - corner[0], room - corner[1])
        if help_lines != HELP:
            corner, help_lines = (0, 0), fitted(font, HELP, width, room)
        blocks[Panel.HELP] = TextBlock(help_lines, corner, TEXT_COLOR)
    return {panel: block for panel, block in blocks.items() if block.lines}


def _text_block(screen, font, block: TextBlock) -> None:
    """A block's lines on a dark translucent panel."""
    panel = pygame.Surface(block.size(font), pygame.SRCALPHA)
    panel.fill((0, 0, 0, 170))
    screen.blit(panel, block.topleft)
    x, y = block.topleft[0] + PANEL_PADDING[0] // 2, block.topleft[1] + PANEL_PADDING[1] // 2
    for text in block.lines:
        screen.blit(font.render(text, True, block.color), (x, y))
        y += font.get_linesize()


def _image_surface(viewer: Viewer, size: tuple[int, int]):
    """The viewer's image as a surface of the window's size."""
    image = pygame.surfarray.make_surface(viewer.pixels().swapaxes(0, 1))
    return image if image.get_size() == size else pygame.transform.scale(image, size)


def _draw(screen, font, image, viewer: Viewer) -> None:
    """The image, then the overlay's text over it."""
    screen.blit(image, (0, 0))
    for block in overlay(viewer, screen.get_size(), font).values():
        _text_block(screen, font, block)
    pygame.display.flip()


def show(viewer: Viewer) -> None:
    """Run the window until it is closed or Esc is pressed."""
    screen, font = _open_window(viewer)
    try:
        last, image = time.perf_counter(), None
        while viewer.running:
            for event in pygame.event.get():
                viewer.handle(event)
            now = time.perf_counter()
            rendered = viewer.step(now - last)
            last = now
            if rendered or image is None:
                image = _image_surface(viewer, screen.get_size())
            _draw(screen, font, image, viewer)
            if not rendered:
                pygame.time.wait(20)     # the image is final: wait for input without spinning
    finally:
        pygame.quit()


def measure(viewer: Viewer, frames: int) -> float:
    """Frames per second of the window's loop while the camera moves: the
    camera orbits its target as in `fractalc bench`; each frame is a step
    (a preview render) and a redraw. Works with SDL_VIDEODRIVER=dummy."""
    screen, font = _open_window(viewer)
    start_camera = viewer.camera
    try:
        viewer.step(0.0)                 # builds the kernel: not a frame of the loop
        last = start = time.perf_counter()
        for i in range(frames):
            pygame.event.pump()
            viewer.look_from(orbit_camera(start_camera, i, frames))
            now = time.perf_counter()
            viewer.step(now - last)
            last = now
            _draw(screen, font, _image_surface(viewer, screen.get_size()), viewer)
        return frames / (time.perf_counter() - start)
    finally:
        pygame.quit()
