"""`fractalc bench`: the benchmark of the dissertation plan "Real-time Rendering of 3D
'Fractal-like' Geometry" (Solomon Baarda; its section 5.2, the performance benchmark scene).

The camera orbits the scene's target about its up axis for a fixed number
of frames at a fixed resolution; we report frame-time statistics, compile
time apart from frame time, and the machine they were measured on.
"""
from __future__ import annotations

import math
import os
import platform
import statistics
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from .api import Scene
from .paths import camera_at, params_at
from .program import Camera

RESOLUTIONS = {"1366x768": (1366, 768), "1920x1080": (1920, 1080), "2560x1440": (2560, 1440),
               "3840x2160": (3840, 2160), "720p": (1280, 720), "1080p": (1920, 1080),
               "1440p": (2560, 1440), "4k": (3840, 2160)}


@dataclass(frozen=True)
class BenchResult:
    scene: str
    path: str                 # "path" (the scene's), "orbit" or "still" (the file's view)
    width: int
    height: int
    frames: int
    repeat: int
    compile_seconds: float
    duration_seconds: float
    frame_ms_min: float
    frame_ms_avg: float
    frame_ms_max: float
    fps_avg: float
    fps_min: float
    fps_max: float
    device: str
    platform: str
    driver: str
    opencl_version: str
    cpu: str
    cores: int
    memory_gib: float
    precision: str
    lanes: int

    def as_dict(self) -> dict:
        return asdict(self)


def orbit_camera(camera: Camera, frame: int, frames: int) -> Camera:
    """The camera turned by 360 * frame / frames degrees about the up axis
    through its target (Rodrigues)."""
    angle = 2.0 * math.pi * frame / frames
    axis = np.asarray(camera.up, dtype=np.float64)
    axis /= np.linalg.norm(axis)
    target = np.asarray(camera.target, dtype=np.float64)
    offset = np.asarray(camera.position, dtype=np.float64) - target
    c, s = math.cos(angle), math.sin(angle)
    turned = offset * c + np.cross(axis, offset) * s + axis * np.dot(axis, offset) * (1.0 - c)
    return replace(camera, position=tuple(float(x) for x in target + turned))


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _memory_gib() -> float:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2 ** 30
    except (ValueError, OSError, AttributeError):
        return float("nan")


def machine(scene: Scene) -> dict:
    """The OpenCL device and the computer a scene renders on."""
    info = scene.device.info
    return {"device": info.name, "platform": info.platform, "driver": info.driver,
            "opencl_version": info.version, "cpu": _cpu_model(), "cores": os.cpu_count() or 0,
            "memory_gib": round(_memory_gib(), 1)}


def machine_rows(figures: dict) -> list[tuple[str, str]]:
    """The device and machine lines of a report, from `machine`'s figures."""
    f = figures
    return [("device", f"{f['device']} ({f['platform']}; {f['opencl_version']}; driver {f['driver']})"),
            ("machine", f"{f['cpu']}, {f['cores']} cores, {f['memory_gib']} GiB")]


def aligned(rows: list[tuple[str, str]]) -> str:
    """`name  value` lines, the values aligned."""
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def frame_statistics(frame_seconds: list[float]) -> dict[str, float]:
    """min/avg/max frame time in ms and the FPS each implies (1000 / ms)."""
    ms = [s * 1000.0 for s in frame_seconds]
    low, mean, high = min(ms), sum(ms) / len(ms), max(ms)
    return {"frame_ms_min": low, "frame_ms_avg": mean, "frame_ms_max": high,
            "fps_avg": 1000.0 / mean, "fps_min": 1000.0 / high, "fps_max": 1000.0 / low,
            "duration_seconds": sum(frame_seconds)}


def bench_view(scene: Scene, frame: int, frames: int, still: bool = False) -> tuple[Camera, dict[str, float]]:
    """Camera and param values of a benchmark frame: the file's own view
    if `still`, else along the scene's `path` from its first keyframe to
    its last if it has one, else the orbit of the camera about its target."""
    path = scene.checked.path
    if still:
        return scene.checked.camera, {}
    if path is None:
        return orbit_camera(scene.checked.camera, frame, frames), {}
    t = path.start + (path.end - path.start) * frame / max(frames - 1, 1)
    return camera_at(path, scene.checked.camera, t), params_at(path, t)


def bench(scene: Scene, frames: int = 30, width: int | None = None, height: int | None = None,
          repeat: int = 1, use_cache: bool = True, still: bool = False) -> BenchResult:
    """Render `frames` frames along the path or orbit (or of the file's
    view, `still`), `repeat` times; figures are medians over the repeats."""
    settings = scene.checked.render
    width, height = width or settings.width, height or settings.height
    # compile time: the build and the first launch, where PoCL generates
    # the machine code for the work-group size (not part of any frame)
    start = time.perf_counter()
    scene.compile(use_cache=use_cache)
    camera, params = bench_view(scene, 0, frames, still)
    scene.set_params(params)
    scene.render(width=width, height=height, camera=camera)
    compile_seconds = time.perf_counter() - start
    runs = []
    for _ in range(repeat):
        seconds = []
        for i in range(frames):
            camera, params = bench_view(scene, i, frames, still)
            scene.set_params(params)
            start = time.perf_counter()
            scene.render(width=width, height=height, camera=camera)
            seconds.append(time.perf_counter() - start)
        runs.append(frame_statistics(seconds))
    medians = {key: statistics.median(run[key] for run in runs) for key in runs[0]}
    return BenchResult(
        scene=scene.checked.file, path="still" if still else "path" if scene.checked.path else "orbit",
        width=width, height=height, frames=frames, repeat=repeat,
        compile_seconds=compile_seconds, **medians, **machine(scene), precision=scene.precision,
        lanes=scene.lanes_in_use)


def table(result: BenchResult) -> str:
    r = result
    rows = [
        ("scene", r.scene),
        ("resolution", f"{r.width}x{r.height}"),
        ("frames", f"{r.frames} ({r.path}; medians of {r.repeat} run{'s' if r.repeat > 1 else ''})"),
        ("compile", f"{r.compile_seconds:.3f} s"),
        ("duration", f"{r.duration_seconds:.3f} s"),
        ("frame time", f"min {r.frame_ms_min:.1f} ms, avg {r.frame_ms_avg:.1f} ms, max {r.frame_ms_max:.1f} ms"),
        ("FPS", f"avg {r.fps_avg:.2f}, min {r.fps_min:.2f}, max {r.fps_max:.2f}"),
        ("kernel", f"{r.precision}, {r.lanes} ray{'s' if r.lanes > 1 else ''} per work-item"),
        *machine_rows(r.as_dict()),
    ]
    return aligned(rows)
