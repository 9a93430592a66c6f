"""Render farm figures for docs/cluster.md: the overhead of a Dask task
against a local render, and a 60-frame animation locally and on local
clusters of 1 and 2 worker processes.

    python benchmarks/cluster_farm.py [--width 320 --height 240 --frames 60]

Each worker builds the kernel once (PoCL's disk cache holds it after the
first run); "cold" job times include that, "warm" ones are a second job on
the same workers. The cluster's start is timed apart.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
import time

import fractalc
from fractalc import animate

EXAMPLE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "examples", "flythrough.frac")


def timed_frames(scene, folder: str, fps: float, client=None, **keys) -> tuple[float, int]:
    start = time.perf_counter()
    _, rendered = animate.render_frames(scene, os.path.join(folder, "f_%04d.png"), fps, overwrite=True,
                                        cluster=client, **keys)
    return time.perf_counter() - start, rendered


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    parser.add_argument("--frames", type=int, default=60)
    args = parser.parse_args()
    import distributed
    scene = fractalc.load(EXAMPLE)
    path = scene.checked.path
    fps = (args.frames - 1) / (path.end - path.start)
    sizes = {"tiny": dict(width=32, height=24), "full": dict(width=args.width, height=args.height)}
    with tempfile.TemporaryDirectory() as folder:
        scene.render(width=16, height=12)          # build once here
        local = {name: timed_frames(scene, folder, fps, **keys) for name, keys in sizes.items()}
        for name, (seconds, count) in local.items():
            print(f"local, {name} frames: {count} frames in {seconds:.2f} s, {seconds / count * 1000:.1f} ms each")
        for workers in (1, 2):
            start = time.perf_counter()
            with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                          dashboard_address=None, silence_logs=logging.ERROR) as cluster, \
                    distributed.Client(cluster) as client:
                print(f"{workers} worker(s): cluster started in {time.perf_counter() - start:.2f} s")
                for name, keys in sizes.items():
                    for run in ("cold", "warm"):
                        seconds, count = timed_frames(scene, folder, fps, client, **keys)
                        per_frame = seconds / count
                        overhead = per_frame - local[name][0] / local[name][1]
                        print(f"{workers} worker(s), {name} frames, {run}: {count} frames in {seconds:.2f} s, "
                              f"{per_frame * 1000:.1f} ms each ({overhead * 1000:+.1f} ms against local)")
                        sys.stdout.flush()


if __name__ == "__main__":
    main()
