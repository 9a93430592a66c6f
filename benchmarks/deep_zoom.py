"""Deep zoom: the feature scale at which float stops rendering a fractal
cleanly and double still does (docs/performance.md, "Deep zoom").

The camera approaches a surface point along the scene camera's view
direction: the point is where the centre ray of the scene's camera meets
the surface (traced in double with a threshold of 1e-13, then refined along
the ray with the double estimate until it is below 1e-15, since the depth
image holds floats), and the camera is put at distance D = 1e-1, 1e-2,
..., 1e-7 (1e-K with --deepest K) before it, looking at it; the
view then spans about D, so D is the feature scale on screen. At each D
three renders are made with the scene's settings and one sample: float,
double, and the reference of `fractalc bench --sweep` (double, a tenth of
the hit threshold, four times the steps). Compared pairwise, they give the
fraction of pixels hit in one and missed in the other, and the depth error
on pixels both hit, relative to D:

- float vs double isolates float's rounding: float is clean at D while
  under 1% of pixels disagree and the median depth error is under 1% of D;
- double vs the reference shows the effect of the threshold, which scales
  with D; it stays at the same level at every D while double is clean.

    python benchmarks/deep_zoom.py [SCENE] [--width W --height H] [--deepest K] [--images DIR]

(with fractalc importable: installed, or PYTHONPATH=. from the repository).
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace

import numpy as np

import fractalc
from fractalc.bench import aligned, machine, machine_rows
from fractalc.program import Camera
from fractalc.sweep import compare, reference_settings, scene_settings

DEEPEST = 7                    # D down to 1e-DEEPEST
CLEAN_MISMATCH = 0.01          # at most 1% of pixels hit in one render and missed in the other
CLEAN_DEPTH = 0.01             # the median |Z - Z_ref| at most 1% of the camera distance
SURFACE_EPSILON = 1e-13
REFINED_EPSILON = 1e-15        # the surface point's estimate, refined on the host
# name: (render, compared with)
COMPARISONS = {"float vs double": ("float", "double"), "float vs reference": ("float", "reference"),
               "double vs reference": ("double", "reference")}


def surface_point(scene: fractalc.Scene) -> np.ndarray:
    """Where the centre ray of the scene's camera meets the surface (double)."""
    camera = scene.checked.camera
    image = scene.render(width=1, height=1, samples=1, precision="double", epsilon=SURFACE_EPSILON,
                         max_steps=100000, dither=0)
    depth = float(image.depth[0, 0])
    if not np.isfinite(depth):
        sys.exit("deep_zoom: the centre ray of the scene's camera misses the scene; aim it at the surface")
    # the depth image holds floats (7 digits): from a little before it, on
    # along the ray in double (sphere tracing, host-side) to where the
    # estimate falls below REFINED_EPSILON
    double = fractalc.Scene(scene.checked, scene.params, precision="double", device=scene.device_spec)
    position, forward = np.asarray(camera.position, dtype=np.float64), _forward(camera)

    def estimate(t: float) -> float:
        return float(double.distance((position + forward * t)[None])[0])
    back = 1e-5 * max(depth, 1.0)
    while estimate(depth - back) <= 0:
        back *= 10
    depth -= back
    for _ in range(10000):
        distance = estimate(depth)
        if distance < REFINED_EPSILON:
            break
        depth += distance
    return position + forward * depth


def _forward(camera: Camera) -> np.ndarray:
    forward = np.subtract(camera.target, camera.position)
    return forward / np.linalg.norm(forward)


def zoom(scene: fractalc.Scene, width: int, height: int, images: str | None = None,
         deepest: int = DEEPEST) -> list[dict]:
    """One row per distance: the COMPARISONS of the float, double and
    reference renders."""
    camera = scene.checked.camera
    target = surface_point(scene)
    forward = _forward(camera)
    settings = {**scene_settings(scene), "samples": 1}
    renders = {"float": {**settings, "precision": "float"}, "double": {**settings, "precision": "double"},
               "reference": reference_settings(settings)}
    rows = []
    for distance in (10.0 ** -k for k in range(1, deepest + 1)):
        view = replace(camera, position=tuple(target - distance * forward), target=tuple(target), focus=None)
        image = {name: scene.render(width=width, height=height, camera=view, **keys)
                 for name, keys in renders.items()}
        row = {"distance": distance}
        for name, (render, against) in COMPARISONS.items():
            error = compare(image[render], image[against])
            row[name] = {"hit_mismatch": error.hit_mismatch,
                         "depth_median": error.depth_error_median / distance,
                         "depth_p99": error.depth_error_p99 / distance}
        rows.append(row)
        if images:
            _save_strip(images, distance, image)
    return rows


def clean(figures: dict) -> bool:
    return figures["hit_mismatch"] <= CLEAN_MISMATCH and figures["depth_median"] <= CLEAN_DEPTH


def _save_strip(directory: str, distance: float, image: dict) -> None:
    """float | double | reference, side by side, as a PNG."""
    from fractalc.write import write
    os.makedirs(directory, exist_ok=True)
    names = ("float", "double", "reference")
    rgba = np.concatenate([image[n].rgba for n in names], axis=1)
    planes = {c: rgba[..., i] for i, c in enumerate("RGBA")}
    planes["Z"] = np.concatenate([image[n].depth for n in names], axis=1)
    write(os.path.join(directory, f"zoom_{distance:.0e}.png"), planes, {})


def table(rows: list[dict]) -> str:
    names = list(COMPARISONS)
    lines = ["| D | " + " | ".join(f"{n}: hit mismatch | {n}: depth error median / p99 (x D)" for n in names) + " |",
             "|" + " --- |" * (1 + 2 * len(names))]
    for row in rows:
        cells = [f"{row['distance']:.0e}"]
        for name in names:
            f = row[name]
            cells += [f"{f['hit_mismatch']:.2%}", f"{f['depth_median']:.2g} / {f['depth_p99']:.2g}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", default=os.path.join(os.path.dirname(__file__), "..", "examples",
                                                                 "mandelbulb.frac"))
    parser.add_argument("--width", type=int, help="default: the scene's")
    parser.add_argument("--height", type=int, help="default: the scene's")
    parser.add_argument("--deepest", type=int, default=DEEPEST, metavar="K", help=f"down to D = 1e-K (default {DEEPEST})")
    parser.add_argument("--images", metavar="DIR", help="also save float | double | reference strips as PNGs")
    args = parser.parse_args(argv)
    scene = fractalc.load(args.scene)
    width, height = args.width or scene.checked.render.width, args.height or scene.checked.render.height
    rows = zoom(scene, width, height, args.images, args.deepest)
    print(aligned([("scene", os.path.relpath(args.scene)), ("size", f"{width}x{height}, 1 sample"),
                   *machine_rows(machine(scene))]))
    print()
    print(table(rows))
    print()
    broken = [r["distance"] for r in rows if not clean(r["float vs double"])]
    print(f"float departs from double first at D = {broken[0]:.0e}" if broken else
          "float matches double at every distance")
    medians = [r["double vs reference"]["depth_median"] for r in rows]
    print(f"double against the reference: median depth error {min(medians):.2g} to {max(medians):.2g} D "
          f"over D = 1e-1 to {rows[-1]['distance']:.0e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
