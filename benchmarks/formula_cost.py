"""The cost of a derived Jacobian against the scalar running derivative on
the same formula: distance estimates at a million points on the device,
the two kernels timed alternately in one process.

    python benchmarks/formula_cost.py [--points N] [--repeat R] [--precision float|double]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from kernel_harness import evaluate_in_kernel  # noqa: E402

import fractalc  # noqa: E402
from fractalc import formula_code, ir  # noqa: E402

P = ir.components(ir.Var("p", ir.VEC3))
BULB = "formula bulb(power = 8) {\n    z = triplex_power(z, power) + c\n}\n"
# name -> (a scene using the formula, the half-width of the cube of points)
CASES = {
    "triplex power 8, 12 iterations": (BULB + "scene fractal(bulb(), iterations: 12, bailout: 2)", 1.3),
    "amazing box (scale 2), 12 iterations": ("scene fractal(amazing_box(), iterations: 12)", 3.0),
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1 << 20)
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--precision", default="float", choices=("float", "double"))
    args = parser.parse_args()
    lanes = 8
    rng = np.random.default_rng(1)
    print(f"{args.points} points, {args.precision}, {lanes} lanes, median of {args.repeat} alternating runs")
    for name, (text, extent) in CASES.items():
        points = rng.uniform(-extent, extent, (args.points, 3))
        shape = fractalc.loads(text).checked.shape
        times = {}
        for path, jacobian in (("scalar dr", False), ("Jacobian", True)):
            estimate = formula_code.orbit(shape.sequence, P, shape.iterations, shape.bailout,
                                          jacobian=jacobian).distance
            evaluate_in_kernel(estimate, points[:lanes * 64], args.precision, lanes)     # build once
            times[path] = (estimate, [])
        for _ in range(args.repeat):
            for path, (estimate, taken) in times.items():
                start = time.perf_counter()
                evaluate_in_kernel(estimate, points, args.precision, lanes)
                taken.append(time.perf_counter() - start)
        scalar, jacobian = (statistics.median(times[k][1]) for k in ("scalar dr", "Jacobian"))
        spread = max(times["Jacobian"][1]) / min(times["Jacobian"][1])
        print(f"{name}: scalar {scalar * 1e3:.0f} ms, Jacobian {jacobian * 1e3:.0f} ms: "
              f"{jacobian / scalar:.2f}x (Jacobian runs spread {spread:.2f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
