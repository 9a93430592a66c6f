"""`fractalc bench --count`: distance evaluations per pixel, by purpose.

The counting build is the scene's kernel emitted with the counting hooks
(emit.Target.count: the engine's and library's `COUNT_` hooks kept, and
each formula loop of the distance estimate counting its iterations for the
rays being evaluated; normal kernels hold no trace of them) and
stdlib_cl/count.cl after the prelude, which makes `params` a __global
buffer (PARAMS_SPACE), whose values are followed by a work-item's
counters. A ray counts where it is marched (its lane of the mask), not
where a vector evaluates it along with rays that are done, so the counts are
those of one ray per work-item, the same on every machine, and the same
from run to run (no atomics: each work-item owns its counters).
"""
from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, replace

from . import run
from .bench import aligned
from .build import build
from .emit import emit
from .lower import lower

# the kernel's purposes, in the order of stdlib_cl/count.cl's COUNT_ constants
PURPOSES = ("camera", "normals", "shadows", "ao", "reflections", "refraction", "other")
# a work-item's counters per ray: three bookkeeping slots, then one per purpose, then iterations
BOOKKEEPING_SLOTS = 3
COUNT_SLOTS = BOOKKEEPING_SLOTS + len(PURPOSES) + 1


@dataclass(frozen=True)
class Counts:
    scene: str
    width: int
    height: int
    lanes: int
    precision: str
    evaluations: dict          # purpose -> distance evaluations, all pixels together
    iterations: int            # formula iterations in those evaluations
    frame_seconds: float | None = None    # the median time of the same render (normal kernel), if timed

    @property
    def per_second(self) -> float | None:
        """Evaluations per second of the normal kernel's render: falls where
        an evaluation costs more, however many the march makes."""
        return None if not self.frame_seconds else self.total / self.frame_seconds

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def total(self) -> int:
        return sum(self.evaluations.values())

    def per_pixel(self) -> dict:
        return {purpose: n / self.pixels for purpose, n in self.evaluations.items()}

    def as_dict(self) -> dict:
        return {"scene": self.scene, "width": self.width, "height": self.height, "lanes": self.lanes,
                "precision": self.precision, "evaluations": dict(self.evaluations),
                "evaluations_per_pixel": self.total / self.pixels,
                "by_purpose_per_pixel": self.per_pixel(),
                "iterations_per_evaluation": self.iterations / max(self.total, 1),
                "frame_seconds": self.frame_seconds, "evaluations_per_second": self.per_second}


def count(scene, width: int | None = None, height: int | None = None, camera=None, timed_frames: int = 0) -> Counts:
    """Distance evaluations of one render of `scene` (its file's view and
    settings unless given), by purpose, and the formula iterations in them;
    with `timed_frames`, the median time of that many renders of the same
    view with the normal kernel (after one that builds it)."""
    renderer = scene.renderer(camera=camera)    # the file's settings: its size only in the frame
    settings, params = renderer.settings, renderer.params
    width, height = width or settings.width, height or settings.height
    target = replace(renderer.target, count=True)
    program = build(emit(lower(replace(scene.checked, render=settings, camera=renderer.camera)), target), scene.device,
                    target.build_options)
    frame = replace(renderer.frame, width=width, height=height)
    counters = run.counted_render(program, scene.device, frame, params, target.lanes, target.double,
                                  COUNT_SLOTS, len(renderer.channels))
    totals = counters.sum(axis=0)
    evaluations = {p: int(round(totals[BOOKKEEPING_SLOTS + i])) for i, p in enumerate(PURPOSES)}
    seconds = []
    for frame_index in range(timed_frames + 1 if timed_frames else 0):
        start = time.perf_counter()
        scene.render(width=width, height=height, camera=camera)
        if frame_index:
            seconds.append(time.perf_counter() - start)
    return Counts(scene.checked.file, width, height, target.lanes, settings.precision, evaluations,
                  int(round(totals[-1])), statistics.median(seconds) if seconds else None)


def table(counts: Counts) -> str:
    """The counts as a report: per pixel by purpose, with the totals."""
    c = counts
    per_pixel = c.per_pixel()
    rows = [("scene", c.scene), ("resolution", f"{c.width}x{c.height}"),
            ("kernel", f"{c.precision}, {c.lanes} ray{'s' if c.lanes > 1 else ''} per work-item"),
            ("evaluations/pixel", f"{c.total / c.pixels:.2f} ({c.total:,} in all)")]
    if c.per_second is not None:
        rows.append(("evaluations/second", f"{c.per_second / 1e6:.2f} M (frame {c.frame_seconds * 1e3:.1f} ms)"))
    rows += [(f"  {p}", f"{per_pixel[p]:.2f} ({c.evaluations[p]:,})") for p in PURPOSES]
    rows.append(("iterations/eval", f"{c.iterations / max(c.total, 1):.2f}"))
    return aligned(rows)

