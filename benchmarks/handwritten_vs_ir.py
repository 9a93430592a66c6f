"""Two kernels of bulb-640 rendered alternately in one process: min and
median frame times, and how far their images differ. Used to compare the
hand-written Mandelbulb (the kernel `fractalc compile` wrote before the
fractals became IR loops) with the IR-loop kernel:

    (cd /tmp && PYTHONPATH=OLD_CHECKOUT python -m fractalc compile ../shared/bench/bulb-640.frac -o old.cl --lanes 16)
    fractalc compile ../shared/bench/bulb-640.frac -o new.cl --lanes 16
    python benchmarks/handwritten_vs_ir.py old.cl new.cl 12
"""
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import fractalc
from fractalc import build, run
scene = fractalc.load(str(Path(__file__).resolve().parent.parent.parent / "shared/bench/bulb-640.frac"), lanes=16)
renderer = scene.renderer()
kernels = {name: run.RenderKernel(build.build(open(path).read(), scene.device), scene.device, 16, False)
           for name, path in (("hand-written", sys.argv[1]), ("IR loops", sys.argv[2]))}
times = {name: [] for name in kernels}
images = {}
for round_ in range(int(sys.argv[3])):
    for name, kernel in kernels.items():
        start = time.perf_counter()
        images[name] = kernel.render(renderer.frame, renderer.params)
        times[name].append(time.perf_counter() - start)
for name, t in times.items():
    print(f"{name:13s} min {min(t)*1e3:.1f} ms  median {statistics.median(t)*1e3:.1f} ms  ({len(t)} renders)")
a, b = images["hand-written"], images["IR loops"]
za, zb = a[..., 4], b[..., 4]
with np.errstate(invalid="ignore"):
    agree = (np.isfinite(za) == np.isfinite(zb)) & (~np.isfinite(za) | (np.abs(za - zb) <= 1e-3 * np.maximum(1, np.abs(za))))
print(f"depth agrees on {agree.mean() * 100:.3f}% of pixels; colour RMSE {np.sqrt(np.mean((a[..., :3] - b[..., :3]) ** 2)):.2e}")
pairs = sorted(b / a for a, b in zip(times["hand-written"], times["IR loops"]))
print(f"IR / hand-written: median of the per-round ratios {statistics.median(pairs):.3f} "
      f"(middle half {pairs[len(pairs) // 4]:.3f}-{pairs[3 * len(pairs) // 4]:.3f}), "
      f"ratio of minima {min(times['IR loops']) / min(times['hand-written']):.3f}")
