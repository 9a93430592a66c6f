"""Multiple importance sampling against next-event estimation alone
(docs/performance.md, "Path tracing: speed against error"): a sharp glossy
floor reflecting a large panel light, and a diffuse ball and floor under a
sphere and a panel light, path traced at 16 to 256 samples each way,
against a 4096-sample render with multiple importance sampling.

    python benchmarks/pathtrace_mis.py [WIDTH HEIGHT]    # default 128 96

Prints a Markdown table: scene, samples, RMSE of the linear colour against
the reference (mean over 2 seeds) and seconds per image, each way.
"""
from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

import fractalc
from fractalc import pathtrace

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_pathtrace import DIFFUSE_UNDER_AREA_LIGHTS  # noqa: E402   (the tests' scene)

DARK = "environment: { zenith: (0, 0, 0), horizon: (0, 0, 0), ground: (0, 0, 0) }"
SCENES = {
    "glossy floor, 4 x 2 panel": f"""
        material floor {{ color: (0.5, 0.5, 0.5), specular: 1, shininess: 400 }}
        scene plane().material(floor)
        camera {{ position: (0, -3, 1.5), target: (0, 0, 0), fov: 50 }}
        light rectangle {{ position: (0, 2, 1.5), direction: (0, -1, -0.6), width: 4, height: 2, intensity: 8 }}
        render {{ integrator: path, bounces: 1, {DARK} }}""",
    "diffuse, sphere and panel lights": DIFFUSE_UNDER_AREA_LIGHTS + f"render {{ integrator: path, bounces: 4, {DARK} }}",
}
SEEDS = (1, 2)


def images(text: str, mis: bool, samples: int, seeds, size) -> tuple[list[np.ndarray], float]:
    pathtrace.MIS = mis
    scene = fractalc.loads(text)
    scene.render(samples=1, width=size[0], height=size[1])          # build first
    found, seconds = [], []
    for seed in seeds:
        start = time.perf_counter()
        found.append(scene.render(samples=samples, seed=seed, width=size[0], height=size[1]).rgba[..., :3]
                     .astype(np.float64))
        seconds.append(time.perf_counter() - start)
    return found, statistics.median(seconds)


def main() -> None:
    size = (int(sys.argv[1]), int(sys.argv[2])) if len(sys.argv) == 3 else (128, 96)
    print(f"{size[0]} x {size[1]}\n")
    print("| scene | samples | RMSE, MIS | seconds | RMSE, next-event estimation alone | seconds |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, text in SCENES.items():
        reference = images(text, True, 4096, [1000], size)[0][0]
        # the lights seen directly are the same both ways, and far brighter
        surface = reference.max(axis=-1) < 5
        for samples in (16, 64, 256):
            row = [name, str(samples)]
            for mis in (True, False):
                found, seconds = images(text, mis, samples, SEEDS, size)
                error = np.mean([np.sqrt(((image - reference)[surface] ** 2).mean()) for image in found])
                row += [f"{error:.4f}", f"{seconds:.3f}"]
            print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
