"""fractalc bench --sweep: a tiny sweep through the command line (its CSV,
table and plot), then the pieces on hand-made data: the error measures, the
Pareto front, the grid and the combinations."""
import csv
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc import RenderError
from fractalc.api import Image
from fractalc.sweep import (CSV_COLUMNS, KNOB_GRID, KNOBS, PRESELECTION_ROUNDS, REFERENCE_LABEL, SCENE_LABEL,
                            ImageError, SweepRow, compare, one_knob_changes, pareto_front,
                            promising_combinations, reference_settings, require_matplotlib, sweep)

REPO = Path(__file__).resolve().parents[1]
MANDELBULB = REPO / "examples" / "mandelbulb.frac"
NAMED_COLUMNS = {"render_ms_median", "hit_mismatch", "depth_error_median", "depth_error_p99", "color_rmse",
                 "psnr_db", "pareto", *KNOBS}


def fractalc_cli(*args, cwd):
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "fractalc", *map(str, args)], cwd=cwd, env=environment,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory):
    """A 32 x 24 sweep of the Mandelbulb example: its settings, epsilon_scale 2
    and the reference."""
    directory = tmp_path_factory.mktemp("sweep")
    result = fractalc_cli("bench", "--sweep", MANDELBULB, "--width", 32, "--height", 24, "--repeat", 2,
                          "--vary", "epsilon_scale=2", "--csv", "rows.csv", "--plot", "rows.png", cwd=directory)
    assert result.returncode == 0, result.stderr
    with open(directory / "rows.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return result, rows, directory


def number(row, column):
    return float(row[column])


@pytest.mark.opencl
def test_csv_has_every_column_and_the_planned_rows(tiny_sweep):
    _, rows, _ = tiny_sweep
    assert NAMED_COLUMNS <= set(rows[0]) and list(rows[0]) == list(CSV_COLUMNS)
    assert [row["label"] for row in rows] == [SCENE_LABEL, "epsilon_scale=2", REFERENCE_LABEL]
    scene, varied, reference = rows
    assert (scene["width"], scene["height"]) == ("32", "24")
    assert number(varied, "epsilon_scale") == 2 * number(scene, "epsilon_scale")
    assert all(varied[k] == scene[k] for k in KNOBS if k != "epsilon_scale")
    assert reference["precision"] == "double" and reference["reference"] == "True"
    assert number(reference, "epsilon_scale") == pytest.approx(0.1 * number(scene, "epsilon_scale"))
    assert number(reference, "max_steps") == 4 * number(scene, "max_steps")
    assert reference["samples"] == scene["samples"]


@pytest.mark.opencl
def test_figures_are_ordered_and_consistent(tiny_sweep):
    _, rows, _ = tiny_sweep
    for row in rows:
        assert 0 < number(row, "render_ms_min") <= number(row, "render_ms_median") <= number(row, "render_ms_max")
        assert number(row, "depth_error_median") <= number(row, "depth_error_p99")
        assert 0 <= number(row, "hit_mismatch") <= 1 and number(row, "steps_mean") >= 1
        rmse = number(row, "color_rmse")
        assert 0 <= rmse <= 1
        expected_psnr = 20 * math.log10(1 / rmse) if rmse > 0 else math.inf
        assert number(row, "psnr_db") == pytest.approx(expected_psnr)


@pytest.mark.opencl
def test_reference_row_has_zero_error_and_the_others_some(tiny_sweep):
    _, rows, _ = tiny_sweep
    reference = rows[-1]
    assert [number(reference, c) for c in ("hit_mismatch", "depth_error_median", "depth_error_p99",
                                           "color_rmse")] == [0, 0, 0, 0]
    assert number(reference, "psnr_db") == math.inf and reference["pareto"] == "False"
    # the reference is slower and finer: the scene's render differs from it
    assert number(rows[0], "color_rmse") > 0
    assert number(reference, "render_ms_median") > number(rows[0], "render_ms_median")


@pytest.mark.opencl
def test_pareto_column_is_the_non_dominated_rows(tiny_sweep):
    _, rows, _ = tiny_sweep
    measured = [r for r in rows if r["reference"] == "False"]

    def dominates(a, b):
        ta, tb, ea, eb = (number(a, "render_ms_median"), number(b, "render_ms_median"),
                          number(a, "color_rmse"), number(b, "color_rmse"))
        return ta <= tb and ea <= eb and (ta < tb or ea < eb)

    for row in measured:
        dominated = any(dominates(other, row) for other in measured if other is not row)
        assert (row["pareto"] == "True") == (not dominated), row["label"]
    assert any(row["pareto"] == "True" for row in measured)


@pytest.mark.opencl
def test_table_and_plot(tiny_sweep):
    result, _, directory = tiny_sweep
    for text in (SCENE_LABEL, "epsilon_scale=2", REFERENCE_LABEL, "RMSE", "PSNR", "sRGB", "2 renders", "machine"):
        assert text in result.stdout
    assert "sweep:" in result.stderr      # progress
    assert (directory / "rows.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (directory / "rows.png").stat().st_size > 10_000


@pytest.mark.parametrize("args, mentions", [
    (["--csv", "x.csv"], "--sweep"),
    (["--sweep", "--vary", "samples=0"], "samples"),
    (["--sweep", "--vary", "colour=red"], "KNOB"),
    (["--sweep", "--plot", "x.jpg"], ".png"),
    (["--sweep", "--json", "x.json"], "--csv"),
])
def test_usage_errors(tmp_path, args, mentions):
    result = fractalc_cli("bench", MANDELBULB, *args, cwd=tmp_path)
    assert result.returncode == 2 and mentions in result.stderr and "Traceback" not in result.stderr
    assert not list(tmp_path.iterdir())


@pytest.mark.opencl
def test_combinations_are_timed_in_the_same_rounds_as_the_other_rows():
    scene = fractalc.load(MANDELBULB)
    messages = []
    result = sweep(scene, width=16, height=12, repeat=2, changes=[{"epsilon_scale": 4.0}, {"overrelax": 1.3}],
                   progress=messages.append)
    labels = [row.label for row in result.rows]
    assert labels[:3] == [SCENE_LABEL, "epsilon_scale=4", "overrelax=1.3"] and labels[-1] == REFERENCE_LABEL
    for row in result.rows[3:-1]:          # combinations, if any: both knobs changed
        assert row.settings["epsilon_scale"] == 4 and row.settings["overrelax"] == 1.3
    rounds = [m for m in messages if m.startswith("timing round")]
    assert "choosing combinations" in messages and len(rounds) == PRESELECTION_ROUNDS + 2
    assert all(m.endswith(f"({len(result.rows)} renders)") for m in rounds[-2:])


def test_missing_matplotlib_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)     # import matplotlib now fails
    with pytest.raises(RenderError, match=r"pip install 'fractalc\[bench\]'"):
        require_matplotlib()


# ------------------------------------------------------------ on hand-made data

def image(depth, rgb):
    depth = np.asarray(depth, dtype=np.float32)
    rgba = np.concatenate([np.asarray(rgb, dtype=np.float32), np.ones(depth.shape + (1,), np.float32)], axis=-1)
    return Image(rgba, depth, np.zeros(depth.shape + (3,), np.float32), np.ones(depth.shape, np.float32))


def test_compare_measures_what_it_says():
    depth = np.full((4, 5), 2.0)
    black = np.zeros((4, 5, 3))
    reference = image(depth, black)
    moved = depth + np.linspace(0, 0.19, 20).reshape(4, 5)
    moved[0, 0] = np.inf                       # one miss of 20 pixels
    white = black.copy()
    white[1, :2] = 1.0                         # two white pixels: sRGB 1 where the reference is 0
    error = compare(image(moved, white), reference)
    assert error.hit_mismatch == pytest.approx(1 / 20)
    offsets = np.linspace(0, 0.19, 20)[1:]
    assert error.depth_error_median == pytest.approx(np.median(offsets), abs=1e-6)
    assert error.depth_error_p99 == pytest.approx(np.percentile(offsets, 99), abs=1e-6)
    assert error.color_rmse == pytest.approx(math.sqrt(2 * 3 / 60))
    assert error.psnr_db == pytest.approx(20 * math.log10(1 / error.color_rmse))
    # colours above 1 are clipped, as a PNG shows them
    assert compare(image(depth, np.full((4, 5, 3), 5.0)), image(depth, np.ones((4, 5, 3)))).color_rmse == 0
    same = compare(reference, reference)
    assert (same.hit_mismatch, same.color_rmse, same.psnr_db) == (0, 0, math.inf)


def row(name, ms, rmse, samples=1, reference=False, **knobs):
    settings = {"epsilon_scale": 1.0, "max_steps": 256, "precision": "float", "fast_math": "off",
                "normals": "tetrahedral", "overrelax": 1.0, "cone_marching": "on", "samples": samples, **knobs}
    error = ImageError(0.0, 0.0, 0.0, rmse, math.inf if rmse == 0 else 20 * math.log10(1 / rmse))
    return SweepRow(name, reference, settings, 0.0, ms, ms, ms, 10.0, error)


def test_pareto_front_per_samples_without_the_reference():
    rows = [row("scene", 100, 0.02), row("fast", 60, 0.05), row("worse", 110, 0.03),
            row("same time, worse", 60, 0.06), row("slow, best", 300, 0.01),
            row("aa", 400, 0.03, samples=4), row("aa slower, worse", 500, 0.04, samples=4),
            row("reference", 900, 0.0, reference=True)]
    assert {rows[i].label for i in pareto_front(rows)} == {"scene", "fast", "slow, best", "aa"}


def test_promising_knobs_are_combined_least_harmful_first():
    rows = [row(SCENE_LABEL, 100, 0.020),
            row("fast_math=on", 80, 0.021, fast_math="on"),
            row("overrelax=1.3", 90, 0.020, overrelax=1.3),
            row("overrelax=1.6", 70, 0.030, overrelax=1.6),
            row("epsilon_scale=4", 50, 0.090, epsilon_scale=4.0),
            row("normals=central", 120, 0.019, normals="central"),          # slower: not promising
            row("precision=double", 95, 0.010, precision="double"),         # never combined
            row("samples=4", 40, 0.001, samples=4)]                          # another reference
    assert promising_combinations(rows, rows[0]) == [
        {"overrelax": 1.3, "fast_math": "on"},
        {"overrelax": 1.3, "fast_math": "on", "epsilon_scale": 4.0},
    ]


def test_grid_moves_one_knob_away_from_the_scene_and_the_reference_is_finer():
    settings = {"epsilon_scale": 1.0, "max_steps": 200, "precision": "float", "fast_math": "off",
                "normals": "tetrahedral", "overrelax": 1.0, "cone_marching": "on", "samples": 4}
    changes = one_knob_changes(settings)
    assert all(len(c) == 1 and settings[k] != v for c in changes for k, v in c.items())
    expected = sum(len([v for v in values if v != settings[k]]) for k, values in KNOB_GRID.items())
    assert len(changes) == expected == 3 + 4 + 1 + 1 + 2 + 2 + 1 + 1     # 200 is not in the steps grid
    reference = reference_settings({**settings, "epsilon_scale": 2.0, "fast_math": "on"})
    assert reference == {**settings, "epsilon_scale": 0.2, "max_steps": 800, "precision": "double",
                         "fast_math": "off", "cone_marching": "off"}


@pytest.mark.opencl
def test_auto_fast_math_is_the_scenes_row_as_it_runs_on_the_device():
    from fractalc.sweep import scene_settings
    scene = fractalc.loads("scene sphere(1)")
    assert scene.checked.render.fast_math == "auto"
    # auto: native_ functions on CPU lanes whose driver's are exact (PoCL's, not Intel's)
    on_cpu = scene.device.lanes > 1 and scene.device.lane_choice.native_exact
    settings = scene_settings(scene)
    assert settings["fast_math"] == ("on" if on_cpu else "off")
    # the grid then holds the other value only: no row repeats the scene's kernel
    assert [c for c in one_knob_changes(settings) if "fast_math" in c] == [
        {"fast_math": "off" if on_cpu else "on"}]
    assert scene_settings(fractalc.loads("scene sphere(1)\nrender { fast_math: off }"))["fast_math"] == "off"
