"""Render farms (fractalc/cluster.py) on a Dask LocalCluster of 2 worker
processes: frames and tiled stills bit-identical to local renders, kernels
built once per worker, a worker killed mid-job, a build failure on the
workers; and Dask left alone without --workers/--cluster."""

import collections
import logging
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import fractalc
from fractalc import animate, api, cluster
from fractalc.errors import RenderError
from fractalc.cache import cache_dir
from test_animate import SCENE   # 32x24, a path of 1 s

oiio = pytest.importorskip("OpenImageIO")

REPO = Path(__file__).resolve().parents[1]

FPS = 6             # 7 frames
# frames that take a while, so that a worker is killed in the middle of one
SLOW_SCENE = textwrap.dedent("""\
    param power = 8 in [2, 12]
    scene mandelbulb(power: power, iterations: 12)
    camera { target: (0, 0, 0), fov: 40 }
    render { width: 32, height: 24, max_steps: 256, samples: 256 }
    path {
        0: { position: (0.5, -3, 1.5), power: 6 }
        1: { position: (3, 0.5, 1.5), power: 9 }
    }
    """)
SLOW_FPS = 9        # 10 frames


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=logging.ERROR) as local, distributed.Client(local) as client:
        yield client


def fractalc_cli(*args, cwd, prelude=""):
    """`python -m fractalc ARGS`; `prelude`: Python run first in that process."""
    environment = {k: v for k, v in os.environ.items() if k != "FRACTALC_DEVICE"}
    environment["PYTHONPATH"] = os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    code = f"{prelude}\nimport sys\nfrom fractalc.cli import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], cwd=cwd, env=environment,
                          capture_output=True, text=True, timeout=300)


def pixels(path) -> np.ndarray:
    image = oiio.ImageInput.open(str(path))
    data = np.asarray(image.read_image(oiio.FLOAT))
    image.close()
    return data


def assert_same_frames(files, others):
    assert len(files) == len(others)
    for file, other in zip(files, others):
        np.testing.assert_array_equal(pixels(file), pixels(other), err_msg=file)


def builds_per_worker(client) -> dict:
    return client.run(lambda: __import__("fractalc.build").build.statistics.builds)


@pytest.mark.opencl
def test_frames_on_the_cluster_equal_local_frames_and_each_worker_builds_once(client, tmp_path):
    scene = fractalc.loads(SCENE, path="fly.frac")
    files, rendered = animate.render_frames(scene, str(tmp_path / "farm" / "f_%02d.exr"), FPS, seed=5,
                                            samples=4, cluster=client)
    assert rendered == 7 and all(os.path.isfile(f) for f in files)
    local, _ = animate.render_frames(scene, str(tmp_path / "local" / "f_%02d.exr"), FPS, seed=5, samples=4)
    assert_same_frames(files, local)
    # the frames are on disk: a second run renders none; with --overwrite
    # all again, on kernels the workers built before
    assert animate.render_frames(scene, str(tmp_path / "farm" / "f_%02d.exr"), FPS, seed=5, samples=4,
                                 cluster=client)[1] == 0
    before = builds_per_worker(client)
    animate.render_frames(scene, str(tmp_path / "farm" / "f_%02d.exr"), FPS, seed=5, samples=4,
                          overwrite=True, cluster=client)
    assert builds_per_worker(client) == before
    assert_same_frames(files, local)


@pytest.mark.opencl
def test_a_still_assembled_from_row_tiles_equals_the_local_render(client):
    scene = fractalc.loads(SCENE)
    local = scene.render(seed=3, samples=4, aovs=["P"])
    for tile_rows in (5, 24):       # tiles of rows not on block edges; one tile
        farmed = cluster.render_still(scene, client, seed=3, samples=4, aovs=["P"], tile_rows=tile_rows)
        planes = farmed.planes()
        assert planes.keys() == local.planes().keys()
        for name, plane in local.planes().items():
            np.testing.assert_array_equal(planes[name], plane, err_msg=name)
    # the default: tiles of 4 rows, 24 / (4 tiles x 2 workers) rounded up to lane blocks; without
    # the P pass, so against the local render of the same kernel (another program may round
    # otherwise where the driver's build options let it reassociate: devices.build_options)
    np.testing.assert_array_equal(scene.render(seed=3, samples=4, cluster=client).rgba,
                                  scene.render(seed=3, samples=4).rgba)


@pytest.mark.opencl
def test_render_on_a_cluster_from_the_command_line_equals_the_local_render(client, tmp_path):
    (tmp_path / "fly.frac").write_text(SCENE)
    farmed = fractalc_cli("render", "fly.frac", "-o", "farm.exr", "--samples", 4,
                          "--cluster", client.scheduler.address, cwd=tmp_path)
    assert farmed.returncode == 0, farmed.stderr
    # the summary: 24 rows in tiles of 4 (4 tiles per worker, whole lane blocks), and each worker's share
    assert re.search(r"^cluster: 6 tiles on [12] workers? in ", farmed.stderr, re.M), farmed.stderr
    assert sum(int(n) for n in re.findall(r"^  tcp://\S+: (\d+) tiles?, ", farmed.stderr, re.M)) == 6
    fractalc.loads(SCENE).render(samples=4).save(str(tmp_path / "local.exr"))
    np.testing.assert_array_equal(pixels(tmp_path / "farm.exr"), pixels(tmp_path / "local.exr"))


@pytest.mark.opencl
def test_a_kernel_build_failure_on_the_workers_is_an_error_not_a_hang(client, tmp_path):
    def break_builds():
        import fractalc.api
        import fractalc.build
        fractalc.api.build = lambda source, *args, **kwargs: fractalc.build.build(
            source + "\nthis is not OpenCL;\n", *args, **kwargs)

    def mend_builds():
        import fractalc.api
        import fractalc.build
        fractalc.api.build = fractalc.build.build

    text = SCENE + "# not built on the workers before\n"
    (tmp_path / "broken.frac").write_text(text)
    client.run(break_builds)
    try:
        with pytest.raises(RenderError, match="failed to build"):
            animate.render_frames(fractalc.loads(text), str(tmp_path / "api" / "f_%02d.png"), FPS, cluster=client)
        assert not os.listdir(tmp_path / "api")
        result = fractalc_cli("animate", "broken.frac", "-o", "cli/f_%02d.png", "--fps", FPS,
                              "--cluster", client.scheduler.address, cwd=tmp_path)
    finally:
        client.run(mend_builds)
    assert result.returncode == 1 and "failed to build" in result.stderr and "Traceback" not in result.stderr
    assert not os.listdir(tmp_path / "cli")


@pytest.mark.opencl
def test_a_worker_killed_mid_job_has_its_frames_rendered_elsewhere_each_written_once(client, tmp_path,
                                                                                    monkeypatch):
    saved, killed = collections.Counter(), []
    save = api.Image.save

    def save_and_kill_a_busy_worker(image, path, *args, **kwargs):
        # the client writes frames as they arrive: at the first, kill a
        # worker in the middle of its next frame
        if not killed:
            busy = [worker for worker, keys in client.processing().items() if keys]
            assert busy, "no frame was in flight to lose"
            pids = client.run(os.getpid, workers=busy[:1])
            killed.extend(pids.values())
            os.kill(killed[0], signal.SIGKILL)
        saved[path] += 1
        save(image, path, *args, **kwargs)

    monkeypatch.setattr(api.Image, "save", save_and_kill_a_busy_worker)
    scene = fractalc.loads(SLOW_SCENE)
    files, rendered = animate.render_frames(scene, str(tmp_path / "farm" / "f_%02d.exr"), SLOW_FPS, cluster=client)
    assert killed and killed[0] not in client.run(os.getpid).values()
    # killed on purpose, not by the driver: no need to clear the kernel cache
    (cache_dir() / "building" / str(killed[0])).unlink(missing_ok=True)
    assert rendered == 10 and sorted(saved) == files and set(saved.values()) == {1}
    monkeypatch.undo()
    local, _ = animate.render_frames(scene, str(tmp_path / "local" / "f_%02d.exr"), SLOW_FPS)
    assert_same_frames(files, local)
    client.wait_for_workers(2)


@pytest.mark.opencl
def test_a_local_cluster_closes_leaving_no_marker_of_a_crash():
    # build.py marks processes that use the driver until they exit
    # normally; Dask's worker processes skip atexit
    pytest.importorskip("distributed")
    with cluster.connect(workers=1) as client:
        fractalc.loads(SCENE).render(cluster=client)
        (pid,) = client.run(os.getpid).values()
        assert (cache_dir() / "building" / str(pid)).exists()
    assert not (cache_dir() / "building" / str(pid)).exists()


@pytest.mark.opencl
def test_without_cluster_options_dask_is_never_imported(tmp_path):
    (tmp_path / "fly.frac").write_text(SCENE)
    code = textwrap.dedent("""\
        import sys
        import fractalc
        from fractalc.cli import main
        fractalc.load("fly.frac").render(width=16, height=12)
        assert main(["animate", "fly.frac", "-o", "frames/f_%02d.png", "--fps", "2", "-q"]) == 0
        print(sorted(m for m in sys.modules if m.split(".")[0] in ("dask", "distributed")))
        """)
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]" and len(os.listdir(tmp_path / "frames")) == 3


@pytest.mark.parametrize("command", ["render", "animate"])
def test_a_missing_cluster_extra_is_a_usage_error_before_any_work(tmp_path, command):
    (tmp_path / "fly.frac").write_text(SCENE)
    output = "out.png" if command == "render" else "frames/f_%02d.png"
    result = fractalc_cli(command, "fly.frac", "-o", output, "--workers", 2, cwd=tmp_path,
                          prelude="import sys; sys.modules['distributed'] = None")
    assert result.returncode == 2 and "pip install 'fractalc[cluster]'" in result.stderr
    assert "Traceback" not in result.stderr and sorted(os.listdir(tmp_path)) == ["fly.frac"]


def test_workers_and_cluster_exclude_each_other(tmp_path):
    (tmp_path / "fly.frac").write_text(SCENE)
    result = fractalc_cli("render", "fly.frac", "-o", "out.png", "--workers", 2, "--cluster", "tcp://x:1",
                          cwd=tmp_path)
    assert result.returncode == 2 and "--cluster" in result.stderr and not (tmp_path / "out.png").exists()
