"""Camera paths: the camera and the animated params at a time `t`.

Each channel of a path (position, target, up, fov, aperture, focus, and
each param a keyframe gives) is a curve through the keyframes that give it,
held constant before the first and after the last of them; a channel that
no keyframe gives keeps the scene camera's value (or the param's current
value). The curve is a cubic Hermite spline with Catmull-Rom tangents for
non-uniform times; segment k is the cubic Bezier curve (as in the camera paths
of Hong and Kook, "Rendering 3-D Fractal Images via Ray Tracing") with the
control points p_k, p_k + h m_k / 3, p_k+1 - h m_k+1 / 3, p_k+1. It passes
through every keyframe exactly and its first derivative is continuous.
Tangents are limited per component as in Fritsch and Carlson's monotone
cubic, so no component overshoots its keyframes: a param stays in its range
and a fov stays between the fovs written.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .arguments import checked
from .program import Camera, CameraPath

CAMERA_CHANNELS = ("position", "target", "up", "fov", "aperture", "focus")


def tangents(times, values) -> np.ndarray:
    """The tangent (d value / d t) at each keyframe: Catmull-Rom's central
    difference, the one-sided difference at the ends; zero where a component
    turns (a local extremum or a flat neighbour), at most three times the
    smaller neighbouring slope elsewhere."""
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64).reshape(len(times), -1)
    slopes = np.diff(values, axis=0) / np.diff(times)[:, None]
    result = np.concatenate([slopes[:1], slopes[-1:]])
    if len(times) > 2:
        central = (values[2:] - values[:-2]) / (times[2:] - times[:-2])[:, None]
        left, right = slopes[:-1], slopes[1:]
        limit = 3.0 * np.minimum(np.abs(left), np.abs(right))
        interior = np.where(left * right > 0.0, np.clip(central, -limit, limit), 0.0)
        result = np.concatenate([slopes[:1], interior, slopes[-1:]])
    return result


def interpolate(times, values, t) -> np.ndarray:
    """The spline through (times[k], values[k]) at `t` (a number or an
    array of them); `values` is (K,) or (K, D). The result has the shape of
    `t`, followed by D for vector values."""
    times = np.asarray(times, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    points = values.reshape(len(times), -1)
    t = np.asarray(t, dtype=np.float64)
    shape = t.shape + values.shape[1:]
    if len(times) == 1:
        return np.broadcast_to(values[0], shape).copy()
    at = np.clip(t.reshape(-1), times[0], times[-1])
    k = np.clip(np.searchsorted(times, at, side="right") - 1, 0, len(times) - 2)
    h = (times[k + 1] - times[k])[:, None]
    s = ((at - times[k]) / (times[k + 1] - times[k]))[:, None]
    m = tangents(times, points)
    result = ((2 * s**3 - 3 * s**2 + 1) * points[k] + (s**3 - 2 * s**2 + s) * h * m[k]
              + (3 * s**2 - 2 * s**3) * points[k + 1] + (s**3 - s**2) * h * m[k + 1])
    return result.reshape(shape)


def _through_keys(path: CameraPath, value_of, t: float):
    """The curve through the keyframes where `value_of(keyframe)` is not
    None, at time t: a float or a tuple; None if no keyframe gives a value."""
    keys = [(k.time, value_of(k)) for k in path.keyframes if value_of(k) is not None]
    if not keys:
        return None
    value = interpolate([time for time, _ in keys], [v for _, v in keys], t)
    return tuple(float(x) for x in value) if value.ndim else float(value)


def camera_at(path: CameraPath, base: Camera, t: float) -> Camera:
    """The camera at time t; channels no keyframe gives come from `base`."""
    given = {name: _through_keys(path, lambda k: getattr(k, name), t) for name in CAMERA_CHANNELS}
    camera = replace(base, **{name: value for name, value in given.items() if value is not None})
    forward = np.subtract(camera.target, camera.position)
    if np.linalg.norm(np.cross(forward, camera.up)) <= 1e-9 * np.linalg.norm(forward) * np.linalg.norm(camera.up):
        # looking straight along up: y is up, as for a camera block
        camera = replace(camera, up=(0.0, 1.0, 0.0))
    return camera


def params_at(path: CameraPath, t: float) -> dict[str, float]:
    """The values of the params the path animates, at time t."""
    names = dict.fromkeys(name for k in path.keyframes for name, _ in k.params)
    return {name: _through_keys(path, lambda k: dict(k.params).get(name), t) for name in names}


# An animation's frames at most: a million frames is over nine hours at 30 fps
MAX_FRAMES = 1_000_000


def frame_times(path: CameraPath, fps: float) -> np.ndarray:
    """One time per frame at `fps`, from the first keyframe to the last,
    both included when the duration is a whole number of frames;
    ValueError for more than MAX_FRAMES frames."""
    fps = checked("fps", fps)
    frames = (path.end - path.start) * fps
    if frames >= MAX_FRAMES:
        raise ValueError(f"fps {fps:g}: the path's {path.end - path.start:g} s would be {frames + 1:.3g} frames, "
                         f"more than {MAX_FRAMES}")
    count = math.floor(frames + 1e-9) + 1
    return path.start + np.arange(count) / fps
