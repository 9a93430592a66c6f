"""`fractalc bench --sweep`: render time against error over the quality knobs.

Each row renders the scene's own view with some quality knobs changed from
the scene's settings and reports how long a render takes (the median of a
few renders after a warm-up render; compiling is timed apart) and how far
its image is from a reference render of the same view: double precision,
a tenth of the scene's hit threshold, four times its steps, the row's
samples. The rows are the scene's settings, each knob of `KNOB_GRID` moved
alone, then "promising" combinations: knobs that were faster than the
scene's settings and on the Pareto front of time against colour error,
added one by one, least harmful first.

Colour errors are measured on the sRGB encoding of the linear colour
clipped to [0, 1] (what a PNG shows, before 8-bit rounding), so a peak
signal of 1: PSNR = 20 log10(1 / RMSE).
"""
from __future__ import annotations

import math
import os
import statistics
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from typing import Callable

import numpy as np

from .api import Image, Scene
from .bench import aligned, machine, machine_rows
from .emit import Target, fast_math
from .errors import RenderError
from .write import linear_to_srgb, publish

# The values each knob takes in the sweep (the scene's own value is the
# scene's row, whatever it is).
KNOB_GRID = {
    "epsilon_scale": (0.5, 1.0, 2.0, 4.0),
    "max_steps": (64, 128, 256, 512),
    "precision": ("float", "double"),
    "fast_math": ("off", "on"),
    "normals": ("tetrahedral", "central", "forward"),
    "overrelax": (1.0, 1.3, 1.6),
    "cone_marching": ("off", "on"),
    "samples": (1, 4),
}
KNOBS = tuple(KNOB_GRID)
# Knobs never combined: double is the reference's precision, not a speed-up,
# and samples change the reference itself.
UNCOMBINED_KNOBS = ("precision", "samples")
# The reference: REFERENCE_EPSILON_SCALE x the scene's hit threshold and
# REFERENCE_STEPS x its max_steps, in double precision.
REFERENCE_EPSILON_SCALE = 0.1
REFERENCE_STEPS = 4
DEFAULT_REPEAT = 5
PRESELECTION_ROUNDS = 2       # timing rounds of the one-knob rows that pick the combinations

SCENE_LABEL = "scene settings"
REFERENCE_LABEL = "reference"
CSV_COLUMNS = ("scene", "width", "height", "device", "label", "reference", *KNOBS, "compile_seconds",
               "render_ms_median", "render_ms_min", "render_ms_max", "steps_mean", "hit_mismatch",
               "depth_error_median", "depth_error_p99", "color_rmse", "psnr_db", "pareto")


# ------------------------------------------------------------------ settings

def scene_settings(scene: Scene) -> dict:
    """The scene's own value of every knob (its file, --precision, ...),
    `fast_math: auto` as what it means on the scene's device (so that no
    row repeats the scene's kernel)."""
    settings = {knob: getattr(scene.checked.render, knob) for knob in KNOBS}
    if settings["fast_math"] == "auto":
        native = fast_math("auto", Target(lanes=scene.lanes_in_use,
                                          exact_native=scene.device.lane_choice.native_exact))
        settings["fast_math"] = "on" if native else "off"
    return settings


def reference_settings(settings: dict) -> dict:
    """The reference for `settings`: double, a tenth of the scene's hit
    threshold, four times its steps, plain sphere tracing (no cone), exact
    functions, the same samples and normals."""
    return {**settings, "precision": "double",
            "epsilon_scale": settings["epsilon_scale"] * REFERENCE_EPSILON_SCALE,
            "max_steps": settings["max_steps"] * REFERENCE_STEPS,
            "fast_math": "off", "overrelax": 1.0, "cone_marching": "off"}


def label(changes: dict) -> str:
    """`knob=value+knob=value` for the knobs a row changes."""
    return "+".join(f"{knob}={_text(value)}" for knob, value in changes.items()) or SCENE_LABEL


def _text(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def one_knob_changes(settings: dict) -> list[dict]:
    """Every value of every knob of KNOB_GRID other than the scene's, alone."""
    return [{knob: value} for knob, values in KNOB_GRID.items() for value in values if value != settings[knob]]


def parse_changes(items: list[str]) -> list[dict]:
    """`KNOB=V1,V2` items (from --vary) as one-knob changes; ValueError
    saying what is wrong."""
    from .arguments import parse_number
    from .check import check_value
    from .program import RENDER_KEYS
    changes = []
    for item in items:
        knob, sep, values = item.partition("=")
        knob = knob.strip()
        if not sep or knob not in KNOB_GRID:
            raise ValueError(f"--vary takes KNOB=VALUE[,VALUE...] with KNOB one of {', '.join(KNOBS)}, "
                             f"not '{item}'")
        for text in values.split(","):
            try:
                given = parse_number(text)
            except ValueError:
                given = text.strip()        # a word: precision=double, normals=central
            value = check_value(RENDER_KEYS[knob], knob, given)
            changes.append({knob: type(KNOB_GRID[knob][0])(value)})
    return changes


# ------------------------------------------------------------------ errors

@dataclass(frozen=True)
class ImageError:
    hit_mismatch: float          # fraction of pixels hit in one image and missed in the other
    depth_error_median: float    # |Z - Z_ref| on pixels hit in both (scene units); nan if none
    depth_error_p99: float
    color_rmse: float            # on sRGB in [0, 1]
    psnr_db: float               # 20 log10(1 / RMSE); inf for identical images


def compare(image: Image, reference: Image) -> ImageError:
    """How far `image` is from `reference` (the same view and size)."""
    hit, reference_hit = np.isfinite(image.depth), np.isfinite(reference.depth)
    both = hit & reference_hit
    depth_error = np.abs(image.depth[both].astype(np.float64) - reference.depth[both])
    median, p99 = (np.percentile(depth_error, [50, 99]) if both.any() else (math.nan, math.nan))
    difference = linear_to_srgb(image.rgba[..., :3].astype(np.float64)) - linear_to_srgb(
        reference.rgba[..., :3].astype(np.float64))
    rmse = float(np.sqrt(np.mean(difference ** 2)))
    return ImageError(hit_mismatch=float(np.mean(hit != reference_hit)),
                      depth_error_median=float(median), depth_error_p99=float(p99),
                      color_rmse=rmse, psnr_db=psnr(rmse))


def psnr(rmse: float) -> float:
    """Peak signal-to-noise ratio in dB for a peak of 1."""
    return 20.0 * math.log10(1.0 / rmse) if rmse > 0 else math.inf


# ------------------------------------------------------------------ rows

@dataclass(frozen=True)
class SweepRow:
    label: str
    reference: bool
    settings: dict               # every knob's value
    compile_seconds: float
    render_ms_median: float
    render_ms_min: float
    render_ms_max: float
    steps_mean: float            # march steps per pixel-centre ray
    error: ImageError
    pareto: bool = False


@dataclass(frozen=True)
class SweepResult:
    scene: str
    width: int
    height: int
    repeat: int
    machine: dict
    load_average: tuple[float, float]      # 1-minute load before and after the sweep
    rows: tuple[SweepRow, ...]

    def records(self) -> list[dict]:
        """One flat dict per row, keyed by CSV_COLUMNS."""
        return [{"scene": self.scene, "width": self.width, "height": self.height,
                 "device": self.machine["device"], "label": row.label, "reference": row.reference,
                 **row.settings, "compile_seconds": row.compile_seconds,
                 "render_ms_median": row.render_ms_median, "render_ms_min": row.render_ms_min,
                 "render_ms_max": row.render_ms_max, "steps_mean": row.steps_mean,
                 **asdict(row.error), "pareto": row.pareto} for row in self.rows]


@dataclass(frozen=True)
class _Prepared:
    """A row's kernel built and its warm-up render made and measured."""
    label: str
    settings: dict
    compile_seconds: float
    steps_mean: float
    error: ImageError


def _prepare(scene: Scene, settings: dict, width: int, height: int, use_cache: bool) -> tuple[float, Image]:
    """Build the kernel for `settings` (timed) and make the warm-up render."""
    start = time.perf_counter()
    scene.compile(use_cache=use_cache, **settings)
    compile_seconds = time.perf_counter() - start
    return compile_seconds, scene.render(width=width, height=height, **settings)


def _time_rounds(scene: Scene, settings: list[dict], width: int, height: int, repeat: int,
                 say: Callable[[str], None]) -> list[list[float]]:
    """Seconds of `repeat` renders of each settings, in rounds over all of
    them: a burst of load on the machine then spreads over the rows instead
    of landing on one row's renders. Each round starts one row further on,
    so no row always follows the same one (a render right after a long
    one, the reference's, runs measurably slower here)."""
    seconds: list[list[float]] = [[] for _ in settings]
    for round_ in range(repeat):
        say(f"timing round {round_ + 1} of {repeat} ({len(settings)} renders)")
        for i in range(len(settings)):
            row = (i + round_) % len(settings)
            start = time.perf_counter()
            scene.render(width=width, height=height, **settings[row])
            seconds[row].append(time.perf_counter() - start)
    return seconds


def _row(prepared: _Prepared, seconds: list[float], is_reference: bool = False) -> SweepRow:
    ms = [s * 1000.0 for s in seconds]
    return SweepRow(label=prepared.label, reference=is_reference, settings=dict(prepared.settings),
                    compile_seconds=prepared.compile_seconds, render_ms_median=statistics.median(ms),
                    render_ms_min=min(ms), render_ms_max=max(ms), steps_mean=prepared.steps_mean,
                    error=prepared.error)


def pareto_front(rows: list[SweepRow]) -> set[int]:
    """Indices of the rows no other row beats in both render time and colour
    error, among the rows of the same samples (each is measured against its
    own reference); reference rows are left out."""
    front = set()
    for i, row in enumerate(rows):
        if row.reference:
            continue
        rivals = [other for other in rows if not other.reference and other is not row
                  and other.settings["samples"] == row.settings["samples"]]
        if not any(_dominates(other, row) for other in rivals):
            front.add(i)
    return front


def _dominates(a: SweepRow, b: SweepRow) -> bool:
    no_worse = a.render_ms_median <= b.render_ms_median and a.error.color_rmse <= b.error.color_rmse
    better = a.render_ms_median < b.render_ms_median or a.error.color_rmse < b.error.color_rmse
    return no_worse and better


def promising_combinations(rows: list[SweepRow], baseline: SweepRow) -> list[dict]:
    """Knob changes worth combining: for each knob (but precision and
    samples), its least harmful value among the one-knob rows that are on
    the Pareto front and faster than the scene's settings; then the first
    two of them together, the first three, ..., least colour error first."""
    settings = baseline.settings
    candidates = [row for row in rows if row.settings["samples"] == settings["samples"]]
    front = [candidates[i] for i in sorted(pareto_front(candidates))]
    best: dict[str, SweepRow] = {}
    for row in front:
        changed = [k for k in KNOBS if row.settings[k] != settings[k]]
        if len(changed) != 1 or changed[0] in UNCOMBINED_KNOBS:
            continue
        if row.render_ms_median >= baseline.render_ms_median:
            continue
        knob = changed[0]
        if knob not in best or row.error.color_rmse < best[knob].error.color_rmse:
            best[knob] = row
    ordered = sorted(best.items(), key=lambda item: item[1].error.color_rmse)
    changes = [{knob: row.settings[knob]} for knob, row in ordered]
    return [dict(kv for change in changes[:n] for kv in change.items()) for n in range(2, len(changes) + 1)]


def sweep(scene: Scene, width: int | None = None, height: int | None = None,
          repeat: int = DEFAULT_REPEAT, changes: list[dict] | None = None, combine: bool = True,
          use_cache: bool = True, progress: Callable[[str], None] | None = None) -> SweepResult:
    """Render the scene's view with its own settings, with each of `changes`
    (default: every one-knob change of KNOB_GRID) and, if `combine`, with
    the promising combinations; measure each against its reference."""
    render = scene.checked.render
    width, height = width or render.width, height or render.height
    baseline = scene_settings(scene)
    load_before = _load_average()
    say = progress or (lambda message: None)

    # the references first (one per samples value), so that each row's
    # warm-up image is measured at once and dropped
    references: dict[int, tuple[_Prepared, Image]] = {}
    planned = [{}] + list(one_knob_changes(baseline) if changes is None else changes)
    for samples in sorted({change.get("samples", baseline["samples"]) for change in planned}):
        name = f"{REFERENCE_LABEL} samples={samples}"
        settings = reference_settings({**baseline, "samples": samples})
        say(f"compile and warm-up: {name}")
        compile_seconds, image = _prepare(scene, settings, width, height, use_cache)
        references[samples] = (_Prepared(name, settings, compile_seconds, float(np.mean(image.steps)),
                                         compare(image, image)), image)

    def prepare(change: dict) -> _Prepared:
        settings = {**baseline, **change}
        say(f"compile and warm-up: {label(change)}")
        compile_seconds, image = _prepare(scene, settings, width, height, use_cache)
        return _Prepared(label(change), settings, compile_seconds, float(np.mean(image.steps)),
                         compare(image, references[settings["samples"]][1]))

    def measure(batch: list[_Prepared], rounds: int) -> list[list[float]]:
        return _time_rounds(scene, [p.settings for p in batch], width, height, rounds, say)

    prepared = [prepare(change) for change in planned]
    if combine:
        # a first, short timing of the one-knob rows picks the combinations;
        # then every row is timed in the same rounds, so that all times
        # share the machine's conditions
        say("choosing combinations")
        first = [_row(p, s) for p, s in zip(prepared, measure(prepared, PRESELECTION_ROUNDS))]
        prepared += [prepare(change) for change in promising_combinations(first, first[0])]
    reference_rows = [r for r, _ in references.values()]
    if len(references) == 1:
        reference_rows = [replace(reference_rows[0], label=REFERENCE_LABEL)]
    seconds = measure(prepared + reference_rows, repeat)
    rows = [_row(p, s) for p, s in zip(prepared, seconds)]
    rows += [_row(p, s, is_reference=True) for p, s in zip(reference_rows, seconds[len(prepared):])]
    front = pareto_front(rows)
    rows = [replace(row, pareto=i in front) for i, row in enumerate(rows)]
    return SweepResult(scene=scene.checked.file, width=width, height=height, repeat=repeat,
                       machine=machine(scene), load_average=(load_before, _load_average()), rows=tuple(rows))


def _load_average() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return math.nan


# ------------------------------------------------------------------ output

def table(result: SweepResult) -> str:
    """A header (scene, reference, metric, machine) and one line per row;
    `*` marks the Pareto front."""
    header = aligned([
        ("scene", result.scene),
        ("resolution", f"{result.width}x{result.height}"),
        ("time", f"median of {result.repeat} renders after a warm-up render, taken in rounds over the "
                 f"rows (compile time apart)"),
        ("reference", f"double, epsilon_scale x{REFERENCE_EPSILON_SCALE:g}, max_steps x{REFERENCE_STEPS}, "
                      f"fast_math off, overrelax 1, cone_marching off, the row's samples"),
        ("colour error", "on sRGB (linear clipped to [0, 1]); PSNR = 20 log10(1 / RMSE)"),
        ("depth error", "|Z - Z_ref| on pixels both hit, scene units"),
        *machine_rows(result.machine),
        ("load", f"1-minute load average {result.load_average[0]:.2f} before, {result.load_average[1]:.2f} "
                 f"after (the sweep itself keeps the cores busy; more means other work shared them)"),
    ])
    columns = ("", "settings", "ms", "min ms", "steps", "hit mism.", "dZ median", "dZ p99",
               "RMSE", "PSNR dB")
    lines = [columns]
    for row in result.rows:
        e = row.error
        lines.append(("*" if row.pareto else "", row.label, f"{row.render_ms_median:.1f}",
                      f"{row.render_ms_min:.1f}", f"{row.steps_mean:.1f}", f"{e.hit_mismatch:.2%}",
                      f"{e.depth_error_median:.2g}", f"{e.depth_error_p99:.2g}",
                      f"{e.color_rmse:.4f}", f"{e.psnr_db:.1f}"))
    widths = [max(len(line[i]) for line in lines) for i in range(len(columns))]
    body = ["  ".join(cell.ljust(w) if i < 2 else cell.rjust(w) for i, (cell, w) in enumerate(zip(line, widths)))
            for line in lines]
    return header + "\n\n" + "\n".join(line.rstrip() for line in body) + "\n* Pareto front (time against RMSE, per samples)"


def csv_text(result: SweepResult) -> str:
    import csv
    import io
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for record in result.records():
        writer.writerow({key: _csv_value(value) for key, value in record.items()})
    return out.getvalue()


def _csv_value(value):
    if isinstance(value, float):
        return repr(value)     # round-trips; nan and inf as Python spells them
    return value


MATPLOTLIB_HINT = "--plot needs matplotlib: pip install 'fractalc[bench]' (or pip install matplotlib)"


def require_matplotlib():
    """matplotlib with the Agg backend, or a RenderError that says how to get it."""
    try:
        import matplotlib
    except ImportError:
        raise RenderError(MATPLOTLIB_HINT) from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as pyplot
    return pyplot


def save_plot(result: SweepResult, path: str) -> None:
    """A PNG of render time against colour RMSE (log scale), one marker per
    samples value, the Pareto front joined and labelled, the reference's
    time as a dashed line. Written atomically, like the images."""
    pyplot = require_matplotlib()
    figure, axes = pyplot.subplots(figsize=(9, 6), dpi=110)
    rows = [row for row in result.rows if not row.reference]
    positive = [row.error.color_rmse for row in rows if row.error.color_rmse > 0]
    floor = min(positive) / 2 if positive else 1e-6
    rmse = lambda row: max(row.error.color_rmse, floor)  # noqa: E731  (log scale: no zeros)
    markers = "os^Dv"
    for n, samples in enumerate(sorted({row.settings["samples"] for row in rows})):
        group = [row for row in rows if row.settings["samples"] == samples]
        axes.scatter([r.render_ms_median for r in group], [rmse(r) for r in group], marker=markers[n % 5],
                     color="0.6", label=f"samples {samples}", zorder=2)
        front = sorted((r for r in group if r.pareto), key=lambda r: r.render_ms_median)
        axes.plot([r.render_ms_median for r in front], [rmse(r) for r in front], marker=markers[n % 5],
                  color=f"C{n}", label=f"Pareto front, samples {samples}", zorder=3)
        for r in front:
            axes.annotate(r.label, (r.render_ms_median, rmse(r)), textcoords="offset points",
                          xytext=(6, 4), fontsize=7, color=f"C{n}")
    scene_row = next(row for row in rows if row.label == SCENE_LABEL)
    axes.scatter([scene_row.render_ms_median], [rmse(scene_row)], marker="*", s=240, facecolors="none",
                 edgecolors="k", linewidths=1.2, label=SCENE_LABEL, zorder=4)
    for row in result.rows:
        if row.reference:
            axes.axvline(row.render_ms_median, color="0.4", linestyle="--", linewidth=1)
            axes.annotate(row.label, (row.render_ms_median, 1), xycoords=("data", "axes fraction"),
                          xytext=(-4, -12), textcoords="offset points", ha="right", fontsize=7, color="0.3")
    axes.set_xscale("log")
    axes.set_yscale("log")
    from matplotlib.ticker import FuncFormatter
    # 300, not 3 x 10^2; times (a wide range) only at 1, 2, 3, 5 x 10^k
    for axis, digits in ((axes.xaxis, (1, 2, 3, 5)), (axes.yaxis, range(1, 10))):
        formatter = FuncFormatter(lambda value, _, digits=digits: f"{value:g}" if value > 0 and round(
            value / 10 ** math.floor(math.log10(value))) in digits else "")
        axis.set_major_formatter(formatter)
        axis.set_minor_formatter(formatter)
    axes.set_xlabel("render time, median (ms)")
    axes.set_ylabel("colour RMSE against the reference (sRGB)")
    axes.set_title(f"{os.path.basename(result.scene)} {result.width}x{result.height}: time against error",
                   fontsize=10)
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    directory = os.path.dirname(os.path.abspath(path))
    handle, temporary = tempfile.mkstemp(prefix=".fractalc-", suffix=".png", dir=directory)
    os.close(handle)
    try:
        figure.savefig(temporary, format="png")
        publish(temporary, path)
    finally:
        pyplot.close(figure)
        if os.path.exists(temporary):
            os.unlink(temporary)
