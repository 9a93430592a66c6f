"""The five built-in fractals written as formulas (stdlib_frac/builtins.frac)
against the IR builders they replaced (fractalc/fractals.py before commit
"built-ins as formulas"): distances on 10,000 seeded points in float and
double, and depth maps of 64x48 renders.

    git show c4f39e7:fractalc/fractals.py > /tmp/old_fractals.py
    python benchmarks/builtins_as_formulas.py /tmp/old_fractals.py [OLD.cl NEW.cl]

With OLD.cl and NEW.cl it also writes bulb-640's kernel both ways (from
the same template, in one process), for
`python benchmarks/handwritten_vs_ir.py OLD.cl NEW.cl 12`.
"""
import importlib.util
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
import fractalc                                       # noqa: E402
from fractalc import fractals, ir, lower             # noqa: E402
from kernel_harness import evaluate_in_kernel         # noqa: E402

spec = importlib.util.spec_from_file_location("fractalc.old_fractals", sys.argv[1])
old = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = old
spec.loader.exec_module(old)

root = Path(__file__).resolve().parent.parent
if len(sys.argv) == 4:
    for module, out in ((old, sys.argv[2]), (fractals, sys.argv[3])):
        lower.orbit = module.orbit                   # the lowering's fractal builders
        Path(out).write_text(fractalc.load(str(root.parent / "shared/bench/bulb-640.frac"), lanes=16).kernel_source())
    lower.orbit = fractals.orbit

P = tuple(ir.Comp(ir.Var("p", ir.VEC3), i) for i in range(3))
c = ir.const
QUATERNION = ir.vec(c(-0.2), c(0.6), c(0.2), c(0.0))
CASES = [
    ("mandelbulb", (c(8.0), ir.Const(12.0, ir.INT), c(2.0)), 1.3, "mandelbulb(8)"),
    ("mandelbulb", (c(3.0), ir.Const(10.0, ir.INT), c(4.0)), 1.6, "mandelbulb(3, 10, 4)"),
    ("julia", (QUATERNION, c(0.0), ir.Const(12.0, ir.INT), c(4.0)), 1.6, "julia()"),
    ("mandelbox", (c(2.0), c(0.5), c(1.0), c(1.0), ir.Const(12.0, ir.INT)), 6.5, "mandelbox(2)"),
    ("mandelbox", (c(-1.5), c(0.5), c(1.0), c(1.0), ir.Const(12.0, ir.INT)), 2.5, "mandelbox(-1.5)"),
    ("menger", (ir.Const(4.0, ir.INT),), 1.8, "menger(4)"),
    ("sierpinski", (ir.Const(6.0, ir.INT),), 1.8, "sierpinski(6)"),
]
rng = np.random.default_rng(20261127)
print(f"{'fractal':22s} {'precision':9s} {'p99 rel':>9s} {'max rel':>9s}")
for name, args, radius, label in CASES:
    points = rng.uniform(-radius, radius, (10_000, 3))
    before = old.FRACTALS[name][1](P, *args).distance
    after = fractals.FRACTALS[name][1](P, *args).distance
    for precision in ("float", "double"):
        a = evaluate_in_kernel(before, points, precision, 16)
        b = evaluate_in_kernel(after, points, precision, 16)
        rel = np.abs(a - b) / np.maximum(np.abs(a), 1e-3)
        print(f"{label:22s} {precision:9s} {np.percentile(rel, 99):9.2e} {rel.max():9.2e}")

print()
SCENES = {"mandelbulb": "examples/mandelbulb.frac", "julia": "examples/julia.frac",
          "mandelbox": "examples/mandelbox.frac", "menger": "examples/menger.frac",
          "sierpinski": "examples/sierpinski.frac"}
for name, path in SCENES.items():
    depths = []
    for module in (old, fractals):
        lower.orbit = module.orbit                   # the lowering's fractal builders
        depths.append(fractalc.load(str(root / path)).render(width=64, height=48).depth)
    lower.orbit = fractals.orbit
    a, b = depths
    with np.errstate(invalid="ignore"):
        agree = (np.isfinite(a) == np.isfinite(b)) & (~np.isfinite(a) | (np.abs(a - b) <= 1e-3 * np.maximum(1, np.abs(a))))
    print(f"{path}: depth agrees on {agree.mean() * 100:.2f}% of 64x48 pixels")
