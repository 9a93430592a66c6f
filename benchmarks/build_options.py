"""OpenCL build options on one scene, on the default device (or
$FRACTALC_DEVICE): the scene's kernel built with each set of options and
rendered alternately, round by round (the order reversed every other
round); the medians of the frame's CPU time (the driver's threads
included) and wall time, and how far each image is from the one built
without options (largest colour change in 1/255, pixels changed, hit
mismatch).

    python benchmarks/build_options.py ROUNDS SCENE
"""
from __future__ import annotations

import json
import statistics
import sys
import time

import numpy as np

import fractalc
from fractalc import run
from fractalc.build import build
from fractalc.passes import channels

VARIANTS = [(), ("-cl-mad-enable",), ("-cl-no-signed-zeros",), ("-cl-mad-enable", "-cl-no-signed-zeros"),
            ("-cl-unsafe-math-optimizations",), ("-cl-fast-relaxed-math",)]


def main(rounds: int, path: str) -> None:
    scene = fractalc.load(path)
    settings = scene.checked.render
    source = scene.kernel_source()
    programs = [build(source, scene.device, options) for options in VARIANTS]
    frame = run.Frame(settings.width, settings.height, settings.samples, 0, run.camera_block(scene.checked.camera))
    params = list(scene.params.values())

    kernels = {id(program): run.RenderKernel(program, scene.device, scene.lanes_in_use, scene.precision == "double")
               for program in programs}

    def render(program):
        return kernels[id(program)].render(frame, params, None, channels(settings.aovs))

    images = [render(program) for program in programs]
    times = [[] for _ in VARIANTS]
    for i in range(rounds):
        for k in (range(len(VARIANTS)) if i % 2 == 0 else reversed(range(len(VARIANTS)))):
            wall, cpu = time.perf_counter(), time.process_time()
            render(programs[k])
            times[k].append((time.perf_counter() - wall, time.process_time() - cpu))
    plain = images[0]
    for options, image, pairs in zip(VARIANTS, images, times):
        change = np.abs(image[..., :3] - plain[..., :3])
        print(json.dumps({"options": " ".join(options) or "none",
                          "cpu_ms": 1e3 * statistics.median(c for _, c in pairs),
                          "wall_ms": 1e3 * statistics.median(w for w, _ in pairs),
                          "max_colour_change_255": float(np.nanmax(change) * 255),
                          "pixels_changed": int((change.max(axis=-1) > 0).sum()),
                          "hit_mismatch": float((np.isfinite(image[..., 4]) != np.isfinite(plain[..., 4])).mean())}),
              flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2])
