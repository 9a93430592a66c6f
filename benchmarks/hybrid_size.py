"""Check and build time against a hybrid's steps per round: a hybrid of N
formula steps (bulb and amazing_box in turn) with `iterations: 1000`,
checked and then built cold (driver cache off) and rendered once at
16x12, in a child process per size, one after another. Sets
check_formulas.MAX_HYBRID_STEPS (issue 22).

    python benchmarks/hybrid_size.py 100 200 400     # prints a Markdown table

A round of a hybrid is one pass of all its steps, written out in the
kernel's orbit loop (formula_code.orbit), so the kernel grows with the
steps however few formulas they name; the iteration count is the loop's.
"""
from __future__ import annotations

import os
import subprocess
import sys

CHILD = """
import sys, time
import fractalc
n = int(sys.argv[1])
steps = ", ".join("bulb()" if i % 2 == 0 else "amazing_box(scale: -1.5)" for i in range(n))
text = f"scene fractal(hybrid({steps}), iterations: 1000, bound: 4)"
start = time.perf_counter()
scene = fractalc.loads(text)
checked = time.perf_counter()
scene.compile()
built = time.perf_counter()
scene.render(width=16, height=12)
print(checked - start, built - checked, time.perf_counter() - built)
"""


def seconds(steps: int) -> tuple[float, float, float]:
    env = dict(os.environ, POCL_KERNEL_CACHE="0", PYOPENCL_NO_CACHE="1")
    result = subprocess.run([sys.executable, "-c", CHILD, str(steps)], env=env, capture_output=True,
                            text=True, check=True)
    check, build, first_render = result.stdout.strip().splitlines()[-1].split()
    return float(check), float(build), float(first_render)


def main(sizes: list[int]) -> None:
    print("| steps per round | check (s) | build (s) | first render (s) | load before |")
    print("|---:|---:|---:|---:|---:|")
    for steps in sizes:
        load = os.getloadavg()[0]
        check, build, first_render = seconds(steps)
        print(f"| {steps} | {check:.2f} | {build:.1f} | {first_render:.1f} | {load:.1f} |", flush=True)


if __name__ == "__main__":
    main([int(x) for x in sys.argv[1:]] or [50, 100, 200, 400])
