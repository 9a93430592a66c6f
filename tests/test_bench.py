"""fractalc bench: the figures of seed 000's benchmark, consistent with each other."""
import json
import math
import subprocess
import sys

import pytest

import fractalc
from fractalc.bench import frame_statistics, orbit_camera
from fractalc.program import Camera

SCENE = """
scene sphere(1) | plane(offset: -1)
camera { position: (0, -4, 1), target: (0, 0, 0) }
render { width: 48, height: 32 }
"""

FIGURES = {"scene", "width", "height", "frames", "repeat", "compile_seconds", "duration_seconds",
           "frame_ms_min", "frame_ms_avg", "frame_ms_max", "fps_avg", "fps_min", "fps_max",
           "device", "platform", "driver", "opencl_version", "cpu", "cores", "memory_gib",
           "precision", "lanes"}


@pytest.mark.opencl
def test_bench_json_holds_every_figure_and_they_agree(tmp_path):
    scene_file = tmp_path / "scene.frac"
    scene_file.write_text(SCENE)
    out = tmp_path / "bench.json"
    result = subprocess.run([sys.executable, "-m", "fractalc", "bench", str(scene_file), "--frames", "4",
                             "--repeat", "3", "--width", "40", "--height", "24", "--json", str(out)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    figures = json.loads(out.read_text())
    assert FIGURES <= set(figures)
    assert (figures["width"], figures["height"], figures["frames"], figures["repeat"]) == (40, 24, 4, 3)
    assert 0 < figures["frame_ms_min"] <= figures["frame_ms_avg"] <= figures["frame_ms_max"]
    assert math.isclose(figures["fps_avg"], 1000.0 / figures["frame_ms_avg"], rel_tol=1e-9)
    assert math.isclose(figures["fps_min"], 1000.0 / figures["frame_ms_max"], rel_tol=1e-9)
    assert math.isclose(figures["fps_max"], 1000.0 / figures["frame_ms_min"], rel_tol=1e-9)
    assert figures["cores"] >= 1 and figures["memory_gib"] > 0 and figures["compile_seconds"] >= 0
    for name in ("resolution", "frame time", "FPS", "compile", "device", "machine"):
        assert name in result.stdout


def test_frame_statistics_medians_and_inverse():
    stats = frame_statistics([0.1, 0.2, 0.4])
    assert stats["frame_ms_min"] == pytest.approx(100) and stats["frame_ms_max"] == pytest.approx(400)
    assert stats["frame_ms_avg"] == pytest.approx(700 / 3)
    assert stats["fps_min"] == pytest.approx(2.5) and stats["fps_max"] == pytest.approx(10)
    assert stats["duration_seconds"] == pytest.approx(0.7)


def test_orbit_keeps_distance_and_height_and_comes_round():
    camera = Camera(position=(0, -4, 1), target=(0, 0, 0.5), up=(0, 0, 1))
    quarter = orbit_camera(camera, 1, 4)
    assert quarter.position == pytest.approx((4, 0, 1))
    assert orbit_camera(camera, 4, 4).position == pytest.approx(camera.position)
    for i in range(7):
        p = orbit_camera(camera, i, 7).position
        assert math.dist(p, camera.target) == pytest.approx(math.dist(camera.position, camera.target))
        assert p[2] == pytest.approx(1)


def test_resolution_names_and_bad_arguments(tmp_path):
    scene_file = tmp_path / "scene.frac"
    scene_file.write_text(SCENE)
    bad = subprocess.run([sys.executable, "-m", "fractalc", "bench", str(scene_file), "--resolution", "8k"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "1920x1080" in bad.stderr and "Traceback" not in bad.stderr
    zero = subprocess.run([sys.executable, "-m", "fractalc", "bench", str(scene_file), "--frames", "0"],
                          capture_output=True, text=True, timeout=60)
    assert zero.returncode == 2 and "--frames" in zero.stderr


@pytest.mark.opencl
def test_render_with_another_camera_does_not_rebuild():
    from fractalc import build
    scene = fractalc.loads(SCENE)
    first = scene.render(width=24, height=16)
    builds = build.statistics.builds
    moved = scene.render(width=24, height=16, camera=orbit_camera(scene.checked.camera, 1, 4))
    assert build.statistics.builds == builds
    assert not (first.depth == moved.depth).all()


def test_bench_follows_the_scenes_path_from_first_to_last_keyframe():
    from fractalc.bench import bench_view
    scene = fractalc.loads("""
        param power = 8 in [2, 16]
        scene mandelbulb(power: power)
        path {
            0: { position: (0, -4, 1), target: (0, 0, 0), power: 6 }
            2: { position: (4, 0, 1), target: (0, 0, 0), power: 9 }
        }
    """)
    first, first_params = bench_view(scene, 0, 5)
    last, last_params = bench_view(scene, 4, 5)
    assert first.position == pytest.approx((0, -4, 1)) and last.position == pytest.approx((4, 0, 1))
    assert first_params == pytest.approx({"power": 6}) and last_params == pytest.approx({"power": 9})
    middle, _ = bench_view(scene, 2, 5)
    assert middle.position != pytest.approx(first.position)


@pytest.mark.opencl
def test_still_bench_renders_the_files_own_view_every_frame():
    from fractalc.bench import bench, bench_view
    scene = fractalc.loads("""
        scene sphere(1)
        camera { position: (0, -4, 1), target: (0, 0, 0) }
        path {
            0: { position: (0, -5, 1), target: (0, 0, 0) }
            2: { position: (5, 0, 1), target: (0, 0, 0) }
        }
    """)
    for frame in range(4):
        assert bench_view(scene, frame, 4, still=True) == (scene.checked.camera, {})
    assert bench_view(scene, 0, 4)[0].position == pytest.approx((0, -5, 1))   # the path, without still
    result = bench(scene, frames=2, width=16, height=12, still=True)
    assert result.path == "still" and result.frames == 2
