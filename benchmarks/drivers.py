"""The OpenCL drivers side by side: for each scene and each usable device,
the cold build (no driver or pyopencl cache), the cached build (pyopencl's
binary cache warm, a new program object), and frame times rendered in
interleaved rounds in this one process (device A, B, B, A, ...), so that
load on a shared machine falls on every driver alike. Also CPU time per
frame (all the driver's threads), which load disturbs less than wall time.

    python benchmarks/drivers.py                        # the three scenes of docs/drivers.md
    python benchmarks/drivers.py SCENE.frac ... --rounds 15

Prints a Markdown table (docs/performance.md, "Drivers") and one JSON line.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENES = (ROOT.parent / "shared/bench/bulb-640.frac", ROOT / "examples/benchmark.frac",
          ROOT / "examples/mandelbulb.frac")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", type=Path, default=[s for s in SCENES if s.exists()])
    parser.add_argument("--rounds", type=int, default=11)
    parser.add_argument("--width", type=int, help="override each scene's width (height follows its aspect)")
    args = parser.parse_args()
    # cold builds: empty binary caches (pyopencl's lives in the XDG cache,
    # and so do fractalc's and PoCL's unless set elsewhere)
    scratch = tempfile.mkdtemp(prefix="fractalc-drivers-")
    os.environ["XDG_CACHE_HOME"] = scratch
    for name in ("FRACTALC_CACHE_DIR", "POCL_CACHE_DIR"):
        os.environ.pop(name, None)

    import fractalc
    from fractalc.devices import list_devices, usable
    infos = [d for d in list_devices() if usable(d)]
    rows = []
    for path in args.scenes:
        scenes = {}
        for info in infos:
            scene = fractalc.load(path, device=str(info.index))
            size = scene.checked.render
            width = args.width or size.width
            height = round(width * size.height / size.width)
            start = time.perf_counter()
            scene.compile(use_cache=False)
            cold = time.perf_counter() - start
            start = time.perf_counter()
            scene.compile(use_cache=False)      # a new program: pyopencl's binary cache answers
            cached = time.perf_counter() - start
            scene.render(width=width, height=height, progress=False)   # warm-up
            scenes[info.index] = (scene, width, height, cold, cached, [], [])
        for round_ in range(args.rounds):
            order = list(scenes) if round_ % 2 == 0 else list(scenes)[::-1]
            for index in order:
                scene, width, height, _, _, walls, cpus = scenes[index]
                wall, cpu = time.perf_counter(), time.process_time()
                scene.render(width=width, height=height, progress=False)
                walls.append(time.perf_counter() - wall)
                cpus.append(time.process_time() - cpu)
        for info in infos:
            scene, width, height, cold, cached, walls, cpus = scenes[info.index]
            rows.append(dict(scene=path.name, device=f"{info.driver_label}", lanes=scene.lanes_in_use,
                             size=f"{width}x{height}", median_ms=1e3 * statistics.median(walls),
                             min_ms=1e3 * min(walls), cpu_median_ms=1e3 * statistics.median(cpus),
                             cold_build_s=cold, cached_build_s=cached, rounds=args.rounds))
    print("| scene | driver | lanes | frame median (min) | CPU time per frame | cold build | cached build |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['scene']} {r['size']} | {r['device']} | {r['lanes']} | {r['median_ms']:.1f} ms "
              f"({r['min_ms']:.1f}) | {r['cpu_median_ms']:.1f} ms | {r['cold_build_s']:.2f} s | "
              f"{r['cached_build_s']:.2f} s |")
    print(json.dumps(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
