"""Compile latency of every example: parse -> check -> lower -> emit (the
source), then the OpenCL build cold (driver cache off) and cached.

    python benchmarks/compile_latency.py            # prints a Markdown table

The cold build runs in a child process with POCL_KERNEL_CACHE=0 and
PYOPENCL_NO_CACHE=1 (they must be set before OpenCL loads); the cached build
is a fresh process whose driver cache already holds the program.
"""
from __future__ import annotations

import glob
import os
import statistics
import subprocess
import sys
import time

# PoCL builds a program in two parts: the front end at build time, the
# machine code for a work-group size at the first launch; we time both.
CHILD = """
import sys, time
import fractalc
scene = fractalc.load(sys.argv[1])
start = time.perf_counter()
scene.compile()
built = time.perf_counter()
scene.render(width=16, height=16)
print(built - start, time.perf_counter() - built)
"""


def source_milliseconds(path: str, repeats: int = 7) -> float:
    from fractalc.check import check
    from fractalc.emit import Target, emit
    from fractalc.lower import lower
    from fractalc.parse import parse
    text = open(path).read()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        emit(lower(check(parse(text, path))), Target(16))
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def build_seconds(path: str, cold: bool) -> tuple[float, float]:
    env = dict(os.environ)
    if cold:
        env.update(POCL_KERNEL_CACHE="0", PYOPENCL_NO_CACHE="1")
    result = subprocess.run([sys.executable, "-c", CHILD, path], env=env, capture_output=True,
                            text=True, check=True)
    build, first_launch = result.stdout.strip().splitlines()[-1].split()
    return float(build), float(first_launch)


def main() -> None:
    print("| example | parse to source (ms) | cold build + first launch (s) | cached build + first launch (s) |")
    print("| --- | --- | --- | --- |")
    for path in sorted(glob.glob("examples/*.frac")):
        build_seconds(path, cold=False)          # make sure the cache holds it
        cold, cached = build_seconds(path, cold=True), build_seconds(path, cold=False)
        print(f"| {os.path.basename(path)} | {source_milliseconds(path):.1f} | "
              f"{cold[0]:.2f} + {cold[1]:.2f} | {cached[0]:.3f} + {cached[1]:.3f} |")


if __name__ == "__main__":
    main()
