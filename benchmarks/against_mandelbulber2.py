"""bulb-640 in fractalc and in Mandelbulber2, side by side.

    python benchmarks/against_mandelbulber2.py [--pairs 6] [--device D]

Runs PAIRS pairs, alternating: one Mandelbulber2 render of
../shared/bench/bulb-640.fract (its CPU engine; the time is the `total
time` it reports), then the median of 10 `Scene.render` calls of
../shared/bench/bulb-640.frac (the same view) in this process. Alternating
puts both in the same minutes of a shared machine; the ratio of each pair
is reported with the median and range over the pairs. Needs
`mandelbulber2` on the PATH (`apt-get install mandelbulber2`); runs it
with QT_QPA_PLATFORM=offscreen.
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1].parent / "shared" / "bench"
FRACTALC_RENDERS = 10


def mandelbulber_seconds(settings: Path, out_dir: str) -> float:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen"}
    result = subprocess.run(["mandelbulber2", "-n", str(settings), "-f", "png", "-o",
                             os.path.join(out_dir, "mb2.png")],
                            env=env, capture_output=True, text=True, check=True)
    times = re.findall(r"total time: ([0-9.]+)s", result.stdout + result.stderr)
    if not times:
        sys.exit("mandelbulber2 did not report a total time; its output:\n" + result.stdout[-2000:])
    return float(times[-1])


def fractalc_seconds(scene) -> float:
    times = []
    for _ in range(FRACTALC_RENDERS):
        start = time.perf_counter()
        scene.render()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=6)
    parser.add_argument("--device", help="fractalc's OpenCL device (index or name)")
    parser.add_argument("--bench-dir", type=Path, default=BENCH, help="folder of bulb-640.frac/.fract")
    args = parser.parse_args()
    if shutil.which("mandelbulber2") is None:
        sys.exit("mandelbulber2 is not installed (apt-get install mandelbulber2)")
    import fractalc
    scene = fractalc.load(args.bench_dir / "bulb-640.frac", device=args.device)
    scene.render()      # build and first launch, not timed
    print(f"fractalc device: {scene.device.info.name} ({scene.device.info.driver})")
    print("| pair | Mandelbulber2 (s) | fractalc (ms) | ratio |")
    print("| ---: | ---: | ---: | ---: |")
    ratios = []
    with tempfile.TemporaryDirectory() as out_dir:
        for pair in range(1, args.pairs + 1):
            theirs = mandelbulber_seconds(args.bench_dir / "bulb-640.fract", out_dir)
            ours = fractalc_seconds(scene)
            ratios.append(theirs / ours)
            print(f"| {pair} | {theirs:.2f} | {1000 * ours:.1f} | {ratios[-1]:.0f} |", flush=True)
    print(f"\nfractalc is {statistics.median(ratios):.0f}x faster (median of {len(ratios)} pairs; "
          f"range {min(ratios):.0f} to {max(ratios):.0f})")


if __name__ == "__main__":
    main()
