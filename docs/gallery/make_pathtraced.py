"""The path-traced gallery (docs/looks.md#gallery): four examples rendered
with `integrator: path` under a sky, denoised, tone-mapped with ACES.

    python docs/gallery/make_pathtraced.py [WIDTH HEIGHT SAMPLES]   # default 1280 720 16

Writes docs/gallery/path/NAME.png and prints each render's time (the
build excluded) as a Markdown table row.
"""
from __future__ import annotations

import os
import sys
import time

import fractalc

HERE = os.path.dirname(os.path.abspath(__file__))
EXAMPLES = os.path.join(HERE, "..", "..", "examples")
SKY = {"zenith": (0.12, 0.2, 0.45), "horizon": (0.4, 0.4, 0.45), "ground": (0.05, 0.05, 0.05), "intensity": 1.0}
SCENES = ("mandelbulb", "mandelbox", "menger", "benchmark")


def main() -> None:
    width, height, samples = (int(x) for x in sys.argv[1:4]) if len(sys.argv) == 4 else (1280, 720, 16)
    os.makedirs(os.path.join(HERE, "path"), exist_ok=True)
    print("| scene | size | samples | seconds |")
    print("| --- | --- | --- | --- |")
    for name in SCENES:
        scene = fractalc.load(os.path.join(EXAMPLES, f"{name}.frac"))
        keys = dict(width=width, height=height, integrator="path", bounces=4, environment=SKY,
                    tonemap="aces", exposure=-1.2, background=(0.0, 0.0, 0.0))
        scene.compile(aovs=("albedo",), **keys)      # the denoiser's pass: built before the clock starts
        start = time.perf_counter()
        image = scene.render(samples=samples, denoise=True, **keys)
        seconds = time.perf_counter() - start
        image.save(os.path.join(HERE, "path", f"{name}.png"))
        print(f"| {name} | {width} x {height} | {samples} | {seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
