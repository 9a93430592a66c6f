"""Compile time against scene size: a flat union of N translated spheres,
built cold (driver cache off) and rendered once at 16x12, in a child
process per size, one after another. Sets check_expressions.MAX_SHAPES (issue 10).

    python benchmarks/scene_size.py 1000 2000 4000     # prints a Markdown table

Each row: shapes, parts (as check counts them: a sphere, its translate and
the union), the build (PoCL's front end), the first render (machine code
for the work-group size, then the image) and the load average before it.
"""
from __future__ import annotations

import os
import subprocess
import sys

CHILD = """
import sys, time
import numpy as np
import fractalc
n = int(sys.argv[1])
centres = np.random.default_rng(10).uniform(-2, 2, (n, 3))
shapes = ", ".join(f"sphere(0.05).translate(({x:.6f}, {y:.6f}, {z:.6f}))" for x, y, z in centres)
start = time.perf_counter()
scene = fractalc.loads(f"scene union({shapes})")
scene.compile()
built = time.perf_counter()
scene.render(width=16, height=12)
print(built - start, time.perf_counter() - built)
"""


def seconds(shapes: int) -> tuple[float, float]:
    env = dict(os.environ, POCL_KERNEL_CACHE="0", PYOPENCL_NO_CACHE="1")
    result = subprocess.run([sys.executable, "-c", CHILD, str(shapes)], env=env, capture_output=True,
                            text=True, check=True)
    build, first_render = result.stdout.strip().splitlines()[-1].split()
    return float(build), float(first_render)


def main() -> None:
    print("| shapes | parts | build (s) | first render (s) | total (s) | load average before |")
    print("| --- | --- | --- | --- | --- | --- |")
    for shapes in map(int, sys.argv[1:] or ("1000", "2000", "4000")):
        load = os.getloadavg()[0]
        build, first_render = seconds(shapes)
        print(f"| {shapes} | {2 * shapes + 1} | {build:.1f} | {first_render:.1f} | {build + first_render:.1f} "
              f"| {load:.2f} |", flush=True)


if __name__ == "__main__":
    main()
