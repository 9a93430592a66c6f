"""Speed against error of the path tracer (docs/performance.md, "Path
tracing: speed against error"): the Mandelbulb of examples/mandelbulb.frac
under its lights and a sky, path traced at 16 to 1024 samples, with and
without denoising, against a 4096-sample render; the direct renderer's
time beside it.

    python benchmarks/pathtrace_error.py [WIDTH HEIGHT]    # default 120 90

Prints a Markdown table: samples, RMSE of the linear colour against the
reference (mean over 2 seeds), its ratio to the previous row, seconds per
image; then the same denoised (needs the 'denoise' extra).
"""
from __future__ import annotations

import statistics
import sys
import time

import numpy as np

import fractalc

SKY = {"zenith": (0.2, 0.3, 0.6), "horizon": (0.5, 0.5, 0.55), "ground": (0.1, 0.1, 0.1)}
SEEDS = (1, 2)


def timed(scene, **keys):
    start = time.perf_counter()
    image = scene.render(**keys)
    return image.rgba[..., :3].astype(np.float64), time.perf_counter() - start


def main() -> None:
    width, height = (int(sys.argv[1]), int(sys.argv[2])) if len(sys.argv) == 3 else (120, 90)
    scene = fractalc.load("examples/mandelbulb.frac")
    keys = dict(width=width, height=height, integrator="path", bounces=4, environment=SKY)
    scene.render(samples=1, **keys)                    # build first
    reference, seconds = timed(scene, samples=4096, seed=1000, **keys)
    print(f"{width} x {height}; reference: 4096 samples, {seconds:.1f} s\n")
    try:
        import pyoidn  # noqa: F401
        variants = (False, True)
    except ImportError:
        variants = (False,)
    print("| integrator | samples | denoised | RMSE | ratio | seconds |")
    print("| --- | --- | --- | --- | --- | --- |")
    direct = fractalc.load("examples/mandelbulb.frac")
    direct.render(samples=1, width=width, height=height)
    for samples in (1, 16):
        _, seconds = timed(direct, samples=samples, width=width, height=height)
        print(f"| direct | {samples} | no | - | - | {seconds:.3f} |")
    for denoise in variants:
        previous = None
        for samples in (16, 64, 256, 1024):
            runs = [timed(scene, samples=samples, seed=seed, denoise=denoise, **keys) for seed in SEEDS]
            error = statistics.mean(float(np.sqrt(((rgb - reference) ** 2).mean())) for rgb, _ in runs)
            seconds = statistics.median(s for _, s in runs)
            ratio = f"{previous / error:.2f}" if previous else "-"
            print(f"| path | {samples} | {'yes' if denoise else 'no'} | {error:.4f} | {ratio} | {seconds:.3f} |")
            previous = error


if __name__ == "__main__":
    main()
