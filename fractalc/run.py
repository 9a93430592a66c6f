"""Stage 6: run a built program (`RenderKernel`, `distances`).

The image is rendered in tiles, each launched while the ones before it still
run (the device never waits for the host): no single launch covers a large
frame (GPU watchdogs), and progress is reported per tile. The kernel writes
every pixel in place into one image-sized buffer, read back once; that
buffer is the image returned (no copy), which writers take as it is.
"""
from __future__ import annotations

import math
import sys
import threading
from collections import OrderedDict, deque
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import numpy as np

from .devices import Device
from .emit import lane_block
from .errors import RenderError
from .hoist import DERIVED_SLOTS
from .memory import is_out_of_memory
from .passes import DEFAULT_CHANNELS
from .program import PROJECTIONS, STEREO_LAYOUTS, Camera

CHANNELS = DEFAULT_CHANNELS   # of a pixel, as in a kernel without extra passes (passes.channels)
# Tiles: launches of at most this many pixels (GPU watchdogs; progress). On
# a CPU, where no watchdog ends a launch, taller ones: each launch costs
# its start and, at its end, a core waiting for the last work-group
# (bulb-640 in one launch instead of eight: 3% faster on Intel's runtime,
# 5% on PoCL; docs/performance.md).
TILE_WIDTH, TILE_HEIGHT = 1024, 64
CPU_TILE_HEIGHT = 512
TILES_IN_FLIGHT = 3


def tile_size(device: Device) -> tuple[int, int]:
    """The largest launch, in pixels, on `device`."""
    return TILE_WIDTH, TILE_HEIGHT if device.info.kind == "GPU" else CPU_TILE_HEIGHT


@dataclass(frozen=True)
class Frame:
    """What a render launch needs besides the program: image size, samples,
    jitter seed, and the camera as the kernel's 13-value block."""
    width: int
    height: int
    samples: int
    seed: int
    camera: tuple[float, ...]


@lru_cache(maxsize=64)    # a frame's camera: its metadata asks again for the matrices
def camera_block(camera: Camera) -> tuple[float, ...]:
    """position, forward, right, up', tan(fov/2), aperture, focus distance
    (LANGUAGE.md's camera model), then the projection, the fisheye's half
    angle (radians), the stereo layout and the eye separation
    (docs/looks.md#cameras)."""
    position = np.array(camera.position, dtype=np.float64)
    forward = np.array(camera.target, dtype=np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.array(camera.up, dtype=np.float64))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    tan_half_fov = math.tan(math.radians(camera.fov) / 2.0)
    focus = camera.focus if camera.focus is not None else float(
        np.linalg.norm(np.array(camera.target, dtype=np.float64) - position))
    return tuple(float(x) for x in (*position, *forward, *right, *up, tan_half_fov,
                                    camera.aperture, focus, PROJECTIONS.index(camera.projection),
                                    math.radians(camera.fisheye_fov) / 2.0,
                                    STEREO_LAYOUTS.index(camera.stereo), camera.eye_separation))


def world_to_camera(camera: Camera) -> np.ndarray:
    """OpenEXR's `worldToCamera` (row vectors: [x y z 1] @ M): camera space
    is left-handed, x right, y up, z along the view (positive in front)."""
    block = camera_block(camera)
    position, axes = np.array(block[0:3]), np.array([block[6:9], block[9:12], block[3:6]])
    matrix = np.identity(4)
    matrix[:3, :3] = axes.T          # column k: the k-th camera axis
    matrix[3, :3] = -axes @ position
    return matrix


def world_to_ndc(camera: Camera, width: int, height: int) -> np.ndarray:
    """OpenEXR's `worldToNDC` (row vectors; divide by w, drop z): NDC (0, 0)
    is the image's top-left corner, (1, 1) its bottom-right, y down. By
    LANGUAGE.md's camera model, pixel (i, j)'s centre lands on
    ((i + 0.5) / W, (j + 0.5) / H); z / w is 1 / depth."""
    tan_half_fov = camera_block(camera)[12]
    aspect = width / height
    projection = np.array([[0.5 / (aspect * tan_half_fov), 0.0, 0.0, 0.0],
                           [0.0, -0.5 / tan_half_fov, 0.0, 0.0],
                           [0.5, 0.5, 0.0, 1.0],
                           [0.0, 0.0, 1.0, 0.0]])
    return world_to_camera(camera) @ projection


def _scalar(double: bool):
    return np.float64 if double else np.float32


def _constant_buffer(device: Device, values, double: bool):
    import pyopencl as cl
    data = np.asarray(list(values) or [0.0], dtype=_scalar(double))
    return cl.Buffer(device.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=data)


# the params buffers of the last few (program, param values): the derived
# params are computed once when the params change, not per frame (a lock:
# the studio renders from more than one thread)
_PARAMS_BUFFERS: OrderedDict = OrderedDict()
_PARAMS_BUFFERS_LOCK = threading.Lock()
PARAMS_BUFFERS_KEPT = 16


def kernel_params(program, device: Device, params, double: bool, extra: int = 0):
    """The kernels' `params` buffer: the scene's param values, then the
    DERIVED_SLOTS values that the program's `derived_params` kernel
    computes from them (fractalc/hoist.py), then `extra` zeros (the
    counting build's counters, which its kernel writes: never shared)."""
    import pyopencl as cl
    key = (program, tuple(float(v) for v in params), double)
    with _PARAMS_BUFFERS_LOCK:
        if not extra and key in _PARAMS_BUFFERS:
            _PARAMS_BUFFERS.move_to_end(key)
            return _PARAMS_BUFFERS[key]
    data = np.zeros(len(params) + DERIVED_SLOTS + extra, dtype=_scalar(double))
    data[:len(params)] = params
    buffer = cl.Buffer(device.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=data)
    cl.Kernel(program, "derived_params")(device.queue, (1,), None, buffer)
    if not extra:
        with _PARAMS_BUFFERS_LOCK:
            _PARAMS_BUFFERS[key] = buffer
            while len(_PARAMS_BUFFERS) > PARAMS_BUFFERS_KEPT:
                _PARAMS_BUFFERS.popitem(last=False)
    return buffer


class _Guard:
    """A context manager that turns OpenCL runtime failures into RenderError
    with one-line causes, naming the `action` under way (a class of its
    own: one made per render cost 20 us of each frame's Python)."""

    def __init__(self, action: str):
        self.action = action

    def __enter__(self):
        return self

    def __exit__(self, kind, error, trace):
        if error is None:
            return False
        import pyopencl as cl
        if is_out_of_memory(error):
            raise RenderError(f"out of memory while {self.action}") from None
        if isinstance(error, cl.Error):
            raise RenderError(f"OpenCL failed while {self.action}: {error}") from None
        return False



def render_arguments(out, params, camera, frame: Frame, x0: int, y0: int, pitch: int) -> tuple:
    """The render kernel's arguments after its global size, in the order
    of its parameters (stdlib_cl/engine/render.cl): the output, the params' and
    camera's buffers, then the frame and the launch's place in it."""
    return (out, params, camera, np.int32(frame.width), np.int32(frame.height), np.int32(x0), np.int32(y0),
            np.int32(pitch), np.int32(frame.samples), np.uint32(frame.seed))


@dataclass(frozen=True)
class Grid:
    """How a device's launches cover an image: a work-item renders a lane
    block, a work-group `group` of blocks (None: the driver's choice), so
    launches start and end on multiples of `step` pixels."""
    block: tuple[int, int]
    group: tuple[int, int] | None
    step: tuple[int, int]

    @staticmethod
    def of(device: Device, lanes: int) -> Grid:
        block, group = lane_block(lanes), device.work_group
        return Grid(block, group, (block[0] * group[0], block[1] * group[1]) if group else block)

    def padded(self, width: int, height: int) -> tuple[int, int]:
        """The image's pitch and rows: its size rounded up to whole steps."""
        return _round_up(width, self.step[0]), _round_up(height, self.step[1])

    def items(self, columns: int, lines: int) -> tuple[int, int]:
        """The global size of a launch over `columns` x `lines` pixels."""
        return columns // self.block[0], lines // self.block[1]


class _Uniforms:
    """A read-only buffer of a kernel's values, kept from launch to launch
    and written again only when they change."""

    def __init__(self, device: Device, double: bool):
        self.device, self.scalar = device, _scalar(double)
        self.values, self.buffer = None, None

    def buffer_of(self, values) -> object:
        import pyopencl as cl
        values = tuple(values) or (0.0,)
        if values != self.values:
            data = np.array(values, dtype=self.scalar)
            if self.buffer is not None and self.buffer.size == data.nbytes:
                cl.enqueue_copy(self.device.queue, self.buffer, data, is_blocking=True)
            else:
                self.buffer = cl.Buffer(self.device.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                        hostbuf=data)
            self.values = values
        return self.buffer


class RenderKernel:
    """A built program's `render` kernel on its device, taken from the
    program once, with the buffers of its params (`kernel_params`) and
    camera block, which frames reuse (each written only when its values
    change). It renders one frame at a time: a scene's frames, one after
    the other."""

    def __init__(self, program, device: Device, lanes: int, double: bool):
        import pyopencl as cl
        self.program, self.device, self.lanes, self.double = program, device, lanes, double
        self.kernel = cl.Kernel(program, "render")
        self.grid = Grid.of(device, lanes)
        self._camera = _Uniforms(device, double)

    def _uniforms(self, frame: Frame, params) -> tuple:
        """The params' and camera's buffers, holding the values of this frame."""
        return kernel_params(self.program, self.device, params, self.double), self._camera.buffer_of(frame.camera)

    def _launch(self, global_size, out, uniforms: tuple, frame: Frame, x0: int, y0: int, pitch: int):
        return self.kernel(self.device.queue, global_size, self.grid.group,
                           *render_arguments(out, *uniforms, frame, x0, y0, pitch))

    def render(self, frame: Frame, params, progress: Callable[[int], None] | None = None,
               channels: tuple[str, ...] = CHANNELS) -> np.ndarray:
        """Render `frame`: an (H, W, len(channels)) float32 array, a pixel's
        `channels` (those the program was emitted with) in order."""
        import pyopencl as cl
        width, height = frame.width, frame.height
        grid = self.grid
        pitch, rows = grid.padded(width, height)
        most_columns, most_lines = tile_size(self.device)
        tile_width, tile_height = grid.padded(min(most_columns, pitch), min(most_lines, rows))
        # a new array per frame: the image returned is this array, which the caller keeps
        image = np.empty((rows, pitch, len(channels)), dtype=np.float32)
        with _Guard("rendering"):
            # the kernel writes into `image` itself where the device can (CPUs):
            # no copy; mapping it at the end makes its contents current anywhere
            out = cl.Buffer(self.device.context, cl.mem_flags.WRITE_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=image)
            uniforms = self._uniforms(frame, params)
            queued = deque()    # (launch event, pixels) of the tiles in flight
            try:
                for y0 in range(0, rows, tile_height):
                    for x0 in range(0, pitch, tile_width):
                        columns, lines = min(tile_width, pitch - x0), min(tile_height, rows - y0)
                        event = self._launch(grid.items(columns, lines), out, uniforms, frame, x0, y0, pitch)
                        queued.append((event, max(0, min(columns, width - x0)) * max(0, min(lines, height - y0))))
                        # a few tiles ahead keep the device busy while we
                        # report progress; an interrupt waits for those few
                        while len(queued) > TILES_IN_FLIGHT:
                            _finish(queued.popleft(), progress)
                while queued:
                    _finish(queued.popleft(), progress)
            except BaseException:
                self.device.queue.finish()    # no kernel may write into `image` once it is gone
                raise
            mapped, _ = cl.enqueue_map_buffer(self.device.queue, out, cl.map_flags.READ, 0, image.shape,
                                              image.dtype, is_blocking=True)
            mapped.base.release(self.device.queue)
        return _without_padding(image, height, width)

    def rows(self, frame: Frame, params, first: int, count: int,
             channels: tuple[str, ...] = CHANNELS) -> np.ndarray:
        """Rows `first` to `first + count - 1` of `frame` (a render farm's
        tile, fractalc/cluster.py): a (count, W, len(channels)) float32
        array, equal bit for bit to those rows of `render`'s image, since a
        pixel's rays and seed depend on its place in the whole frame, not on
        the launch. The kernel addresses the whole image, so the device
        buffer spans the rows above the tile too; only the tile's rows are
        written and read back (on CPUs the others are never touched, so they
        take no memory)."""
        import pyopencl as cl
        grid = self.grid
        pitch, _ = grid.padded(frame.width, frame.height)
        top, bottom = first // grid.step[1] * grid.step[1], _round_up(first + count, grid.step[1])   # whole blocks
        launch_width, _ = grid.padded(min(TILE_WIDTH, pitch), 0)
        tile = np.empty((bottom - top, pitch, len(channels)), dtype=np.float32)
        with _Guard("rendering"):
            out = cl.Buffer(self.device.context, cl.mem_flags.WRITE_ONLY, bottom * pitch * len(channels) * 4)
            uniforms = self._uniforms(frame, params)
            for x0 in range(0, pitch, launch_width):
                self._launch(grid.items(min(launch_width, pitch - x0), bottom - top), out, uniforms, frame, x0, top,
                             pitch)
            cl.enqueue_copy(self.device.queue, tile, out, src_offset=top * pitch * len(channels) * 4,
                            is_blocking=True)
        return np.ascontiguousarray(tile[first - top:first - top + count, :frame.width])


def counted_render(program, device: Device, frame: Frame, params, lanes: int, double: bool,
                   slots: int, channels: int = len(CHANNELS)) -> np.ndarray:
    """Run the counting build of fractalc/count.py over `frame` in one
    launch (work-item (i, j) renders block (i, j), and owns its `slots`
    counters per ray after the params); the counters, one row per
    work-item, each slot summed over its rays."""
    import pyopencl as cl
    kernel = cl.Kernel(program, "render")
    grid = Grid.of(device, lanes)
    pitch, rows = grid.padded(frame.width, frame.height)
    columns, lines = grid.items(pitch, rows)
    base = len(params) + DERIVED_SLOTS
    state = np.zeros(base + columns * lines * slots * lanes, dtype=_scalar(double))
    with _Guard("counting distance evaluations"):
        flags = cl.mem_flags
        state_buffer = kernel_params(program, device, params, double, columns * lines * slots * lanes)
        out = cl.Buffer(device.context, flags.WRITE_ONLY, rows * pitch * channels * 4)
        kernel(device.queue, (columns, lines), grid.group,
               *render_arguments(out, state_buffer, _constant_buffer(device, frame.camera, double), frame, 0, 0, pitch))
        cl.enqueue_copy(device.queue, state, state_buffer, is_blocking=True)
    return state[base:].reshape(columns * lines, slots, lanes).sum(axis=2)


def _without_padding(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """The top-left height x width pixels of `image` as one contiguous
    array in the same memory (a writer takes it as it is): rows are moved
    down in place over the padding of the pitch, never copied whole."""
    rows, pitch, channels = image.shape
    if pitch == width:
        return image[:height]
    flat, row = image.reshape(-1), width * channels
    for y in range(1, height):    # row y lands before row y + 1 starts: nothing is overwritten unread
        flat[y * row:(y + 1) * row] = image[y, :width].reshape(-1)
    return flat[:height * row].reshape(height, width, channels)


def _finish(tile, progress: Callable[[int], None] | None) -> None:
    event, pixels = tile
    event.wait()
    if progress:
        progress(pixels)


def _round_up(n: int, multiple: int) -> int:
    return -(-n // multiple) * multiple


def distances(program, device: Device, points: np.ndarray, params, lanes: int, double: bool) -> np.ndarray:
    """The scene's distance estimate at each of the (N, 3) `points`."""
    import pyopencl as cl
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), not {points.shape}")
    count = len(points)
    padded = max(lanes, math.ceil(count / lanes) * lanes)
    planar = np.zeros((3, padded), dtype=_scalar(double))
    planar[:, :count] = points.T
    result = np.empty(padded, dtype=_scalar(double))
    with _Guard("evaluating distances"):
        flags = cl.mem_flags
        points_buffer = cl.Buffer(device.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=planar)
        out = cl.Buffer(device.context, flags.WRITE_ONLY, result.nbytes)
        cl.Kernel(program, "distance_at_points")(device.queue, (padded // lanes,), None, points_buffer, out,
                                   kernel_params(program, device, params, double), np.int32(padded))
        cl.enqueue_copy(device.queue, result, out)
    return result[:count].astype(np.float64)


class ProgressReporter:
    """A render's progress for a function: `report(done, total)` in
    pixels after each tile (an exception it raises stops the render)."""

    def __init__(self, report: Callable[[int, int], None], total_pixels: int):
        self.report, self.total, self.done = report, total_pixels, 0

    def update(self, pixels: int) -> None:
        self.done += pixels
        self.report(self.done, self.total)

    def close(self) -> None:
        pass


def terminal_progress(total_pixels: int):
    """A progress bar on stderr for renders that take over a second."""
    from tqdm import tqdm
    return tqdm(total=total_pixels, unit="px", unit_scale=True, delay=1.0, leave=False,
                disable=not sys.stderr.isatty(), desc="rendering")


def uniform_values(program, device: Device, params, count: int, double: bool) -> np.ndarray:
    """The `count` values the program's `uniform_values` kernel writes
    (emit.uniform_source)."""
    import pyopencl as cl
    result = np.empty(count, dtype=_scalar(double))
    with _Guard("evaluating the scene's bound"):
        out = cl.Buffer(device.context, cl.mem_flags.WRITE_ONLY, result.nbytes)
        cl.Kernel(program, "uniform_values")(device.queue, (1,), None, _constant_buffer(device, params, double), out)
        cl.enqueue_copy(device.queue, result, out)
    return result.astype(np.float64)
