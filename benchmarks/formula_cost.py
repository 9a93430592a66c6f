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

from fractalc import formulas as F  # noqa: E402
from fractalc import ir  # noqa: E402

P = ir.components(ir.Var("p", ir.VEC3))


def amazing_box(z, c):
    folded = F.box_fold(z, ir.const(1.0))
    inverted = F.sphere_fold(folded.z, ir.const(0.5), ir.const(1.0))
    return [folded, inverted, F.scale(inverted.z, ir.const(2.0))]


CASES = {
    "mandelbulb (power 8, 12 iterations)": (F.Formula("mandelbulb", lambda z, c: [F.triplex_power(z, ir.const(8.0))]),
                                            "escape", 2.0, 1.3),
    "amazing box (scale 2, 12 iterations)": (F.Formula("amazing_box", amazing_box), "linear", 1e30, 3.0),
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
    for name, (formula, kind, bailout, extent) in CASES.items():
        points = rng.uniform(-extent, extent, (args.points, 3))
        times = {}
        for path, jacobian in (("scalar dr", False), ("Jacobian", True)):
            estimate = F.orbit(P, [(formula, 1)], ir.Const(12.0, ir.INT), ir.const(bailout), kind=kind,
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
