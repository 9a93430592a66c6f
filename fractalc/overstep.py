"""How far a scene's distance estimate can overstep (`fractalc check --de`).

A distance estimate is safe where it never exceeds the true distance to
the surface: then a ray may step by it. Along seeded rays aimed at the
scene's bound, this marches finely (fixed steps of a small fraction of the
bound, never trusting the estimate) to the first point inside the surface,
bisects to the crossing, and compares the estimate at points before it
with their distance to the crossing along the ray. That distance is at
least the true distance to the surface, so a ratio estimate / distance
above 1 is an overstep for certain; its largest value gives a safe step
factor (1 / ratio) to march with. The estimate is evaluated by the
compiled kernel, like a render's.

Two surfaces: the estimate's own (where it falls below a small level:
what the marcher sees), and, for fractals with a bailout, the escape-time
set at the scene's iterations (the points whose orbit never escapes: what
the formula means). An estimate can be safe against the first and
overstep the second many times over.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from .api import Scene
from .arguments import checked
from .lower import lower
from .memory import require_memory

# memory per sample along the rays: the estimates (float64), whether each
# is inside (bool), the ratios compared (float64)
SAMPLE_BYTES = 17

# An estimate that meets no surface yet whose median inside the bound is
# below this (in bound radii) is small everywhere there, with no surface
# to find: a space-filling formula's (a Kaliset measures 0.006; a thin
# IFS at 6 iterations, whose estimate only misses the level, 0.27)
_SPACE_FILLING = 0.02


class Against(enum.Enum):
    """The surface an estimate is measured against."""
    ESTIMATE = "the estimate's own surface (what the marcher sees)"
    ESCAPE_TIME_SET = "the escape-time set at the scene's iterations (what the formula means)"


@dataclass(frozen=True)
class Overstep:
    rays: int                  # rays that met the surface
    samples: int               # points compared
    largest_ratio: float       # max estimate / distance along the ray to the surface
    p99_ratio: float
    against: Against = Against.ESTIMATE

    @property
    def safe_step_factor(self) -> float:
        return min(1.0, 1.0 / self.largest_ratio) if self.largest_ratio > 0 else 1.0

    def report(self) -> str:
        verdict = "never oversteps" if self.largest_ratio <= 1.001 else \
            f"oversteps: march with a step factor of at most {self.safe_step_factor:.3f}"
        met = "the surface" if self.against is Against.ESTIMATE else "the set"
        return (f"against {self.against.value}: {self.rays} rays met {met}, {self.samples} points compared: "
                f"largest estimate / distance {self.largest_ratio:.4f} (99th percentile {self.p99_ratio:.4f}); "
                f"{verdict}")


def _bound(scene) -> tuple[np.ndarray, float]:
    bound = scene.bound()
    if bound is None or not np.isfinite(bound[1]) or bound[1] <= 0:
        raise ValueError("the scene has no finite bound (a plane, repetition or a warp, or a fractal "
                         "whose bound is unknown): --de needs one to aim its rays at")
    return bound


def has_escape_time_set(scene) -> bool:
    """Whether a fractal of the scene has a bailout, so an escape-time set
    other than its estimate's surface (the lowered IR is interned: the
    same scene is the same expression)."""
    return lower(scene.checked, escape_time_sets=True).distance is not lower(scene.checked).distance


def measure(scene, rays: int = 400, steps: int = 1500, seed: int = 0, surface: float = 1e-5,
            against: Against = Against.ESTIMATE) -> Overstep:
    """Compare the estimate with the distance along `rays` seeded rays,
    each marched in `steps` fixed steps across the bound's diameter; in
    double where the device has it (the estimate's formula is measured,
    not float's rounding), at points at least 1e-3 bound radii from the
    surface (nearer, rounding dominates). The estimate's surface is where
    it falls to `surface` bound radii: a renderer's hit (an estimate need
    not reach 0 inside: the Mandelbox's is 1e-5 there after 12
    iterations); the escape-time set's is where orbits stop escaping."""
    rays, seed, surface = checked("rays", rays), checked("seed", seed), checked("surface", surface)
    require_memory(rays * steps * SAMPLE_BYTES, f"measuring along {rays} rays of {steps} steps")
    if scene.device.info.double and scene.precision != "double":
        scene = Scene(scene.checked, scene.params, precision="double", device=scene.device_spec, lanes=scene.lanes)
    centre, radius = _bound(scene)
    level = surface * radius
    # inside the surface measured against: where this is at most `threshold`
    inside_of, threshold = (scene.distance, level) if against is Against.ESTIMATE else (scene.escape_time_set, 0.0)
    rng = np.random.default_rng(seed)
    # from a point on a sphere 1.5 radii out, towards a point inside the bound
    start = rng.normal(size=(rays, 3))
    start = centre + 1.5 * radius * start / np.linalg.norm(start, axis=1, keepdims=True)
    aim = rng.normal(size=(rays, 3))
    aim = centre + 0.7 * radius * rng.uniform(0, 1, (rays, 1)) ** (1 / 3) * aim / np.linalg.norm(aim, axis=1,
                                                                                              keepdims=True)
    direction = aim - start
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    length = 3.0 * radius
    t = np.linspace(0.0, length, steps)
    distances = np.empty((rays, steps))
    inside = np.empty((rays, steps), dtype=bool)
    for first in range(0, rays, 64):   # in chunks: bounded memory
        block = slice(first, first + 64)
        points = (start[block, None, :] + t[None, :, None] * direction[block, None, :]).reshape(-1, 3)
        distances[block] = scene.distance(points).reshape(-1, steps)
        inside[block] = (distances[block] if against is Against.ESTIMATE else
                         inside_of(points).reshape(-1, steps)) <= threshold
    first = np.argmax(inside, axis=1)
    met = np.flatnonzero(inside.any(axis=1) & (first > 0))     # rays starting inside compare nothing
    if not len(met):
        within = np.linalg.norm(start[:, None, :] + t[None, :, None] * direction[:, None, :] - centre, axis=2) <= radius
        raise ValueError(_nothing_met(against, surface, float(distances.min()) / radius,
                                      float(np.median(distances[within])) / radius))
    low, high = t[first[met] - 1], t[first[met]]
    for _ in range(40):                       # bisect every ray's crossing at once
        middle = 0.5 * (low + high)
        outside = inside_of(start[met] + middle[:, None] * direction[met]) > threshold
        low, high = np.where(outside, middle, low), np.where(outside, high, middle)
    ratios = []
    for ray, crossing in zip(met, high):
        before = t < crossing
        gap = crossing - t[before]
        useful = gap > 1e-3 * radius
        ratios.append((distances[ray, before][useful] - threshold) / gap[useful])
    ratios = np.concatenate(ratios)
    return Overstep(len(met), len(ratios), float(ratios.max()), float(np.percentile(ratios, 99)), against)


def _nothing_met(against: Against, surface: float, smallest: float, typical: float) -> str:
    """Why no ray met the surface, from the smallest estimate along the
    rays and its median inside the bound (in bound radii), and what to do."""
    if against is Against.ESCAPE_TIME_SET:
        return "no ray met the escape-time set (every orbit along the rays escapes)"
    if typical < _SPACE_FILLING:
        return (f"no ray met the surface: the estimate is small all through the bound (its median there "
                f"{typical:.3g} bound radii) but never falls to {surface:g} (its smallest {smallest:.3g}): a "
                f"space-filling formula (a Kaliset, z = abs(z) / dot(z, z) + c) has no surface its derived "
                f"estimate finds. Give the formula its own 'final distance = ...' (docs/formulas.md), or raise "
                f"--surface above {smallest:.3g}")
    return (f"no ray met the surface (the estimate stayed above {surface:g} bound radii along every ray, its "
            f"smallest {smallest:.3g}; a thin set's may: raise --surface above it)")
