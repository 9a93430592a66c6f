"""Host time per frame: what `Scene.render` adds around the kernel.

Each round renders the frame with `Scene.render` (a new image, as a caller
gets it) and then launches the same program's kernel over the same tiles
directly (its kernel, buffers and image made once, before the rounds: the
kernel's own time and the launches that no host loop avoids); the host
time is the median of the rounds' differences. Each round runs the two
back to back, so that load on a shared machine falls on both alike. The
calling thread's CPU time is measured too (the waits for the kernel
sleep): its difference is the host's own work, which load hardly changes.

    python benchmarks/host_time.py                      # a sphere and bulb-640, 640x480
    python benchmarks/host_time.py SCENE.frac --rounds 41

Prints one line per scene and one JSON line (docs/performance.md, "Host
time per frame").
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from collections import deque
from pathlib import Path

import numpy as np

import fractalc
from fractalc import run
from fractalc.emit import lane_block

ROOT = Path(__file__).resolve().parent.parent
SPHERE = "scene sphere(1)\ncamera { position: (0, 0, 3), target: (0, 0, 0) }\nrender { samples: 1 }\n"
BULB = ROOT.parent / "shared/bench/bulb-640.frac"


def launches(scene, width: int, height: int):
    """A function that renders the frame by the scene's kernel alone, as
    run.py tiles it; everything else made once, here."""
    import pyopencl as cl
    device, program = scene.device, scene.compile()
    kernel = cl.Kernel(program, "render")
    lanes = scene.lanes_in_use
    double = scene.precision == "double"
    scalar = np.float64 if double else np.float32
    block_width, block_height = lane_block(lanes)
    group = device.work_group
    step_x, step_y = (block_width * group[0], block_height * group[1]) if group else (block_width, block_height)
    pitch, rows = -(-width // step_x) * step_x, -(-height // step_y) * step_y
    most_columns, most_lines = run.tile_size(device)
    tile_width = -(-min(most_columns, pitch) // step_x) * step_x
    tile_height = -(-min(most_lines, rows) // step_y) * step_y
    flags = cl.mem_flags
    camera = np.array(run.camera_block(scene.checked.camera), dtype=scalar)
    # the params and the derived params after them, as the kernel reads them
    params_buffer = run.kernel_params(program, device, [scene.params[p.name] for p in scene.checked.params], double)
    camera_buffer = cl.Buffer(device.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=camera)
    image = np.empty((rows, pitch, len(run.CHANNELS)), dtype=np.float32)
    out = cl.Buffer(device.context, flags.WRITE_ONLY | flags.USE_HOST_PTR, hostbuf=image)
    samples = scene.checked.render.samples

    def frame():
        queued = deque()
        for y0 in range(0, rows, tile_height):
            for x0 in range(0, pitch, tile_width):
                columns, lines = min(tile_width, pitch - x0), min(tile_height, rows - y0)
                queued.append(kernel(device.queue, (columns // block_width, lines // block_height), group,
                                     out, params_buffer, camera_buffer, np.int32(width), np.int32(height),
                                     np.int32(x0), np.int32(y0), np.int32(pitch), np.int32(samples),
                                     np.uint32(0)))
                while len(queued) > run.TILES_IN_FLIGHT:
                    queued.popleft().wait()
        while queued:
            queued.popleft().wait()
        mapped, _ = cl.enqueue_map_buffer(device.queue, out, cl.map_flags.READ, 0, image.shape, image.dtype,
                                          is_blocking=True)
        mapped.base.release(device.queue)
    return frame


def measure(name: str, scene, width: int, height: int, rounds: int) -> dict:
    scene.set_defaults(width=width, height=height)
    kernel_only = launches(scene, width, height)
    render = lambda: scene.render()    # noqa: E731
    for warm in (render, kernel_only):
        warm()
    times = {"render": [], "kernel": []}
    cpu = {"render": [], "kernel": []}     # the calling thread's
    for _ in range(rounds):
        for key, work in (("render", render), ("kernel", kernel_only)):
            start, start_cpu = time.perf_counter(), time.thread_time()
            work()
            times[key].append(time.perf_counter() - start)
            cpu[key].append(time.thread_time() - start_cpu)
    render_ms, kernel_ms = (1000 * statistics.median(times[k]) for k in ("render", "kernel"))
    host_ms = 1000 * statistics.median(r - k for r, k in zip(times["render"], times["kernel"]))
    host_cpu_ms = 1000 * statistics.median(r - k for r, k in zip(cpu["render"], cpu["kernel"]))
    result = {"scene": name, "width": width, "height": height, "rounds": rounds, "device": scene.device.info.name,
              "render_ms": round(render_ms, 3), "kernel_ms": round(kernel_ms, 3), "host_ms": round(host_ms, 3),
              "host_cpu_ms": round(host_cpu_ms, 3)}
    print(f"{name}: Scene.render {render_ms:.3f} ms, kernel alone {kernel_ms:.3f} ms, host {host_ms:.3f} ms, "
          f"host CPU {host_cpu_ms:.3f} ms (medians of {rounds})")
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="*", type=Path)
    parser.add_argument("--rounds", type=int, default=31)
    parser.add_argument("--width", type=int, default=640)
    parser.add_argument("--height", type=int, default=480)
    args = parser.parse_args()
    scenes = [(str(s), fractalc.load(s)) for s in args.scenes] or \
        [("sphere", fractalc.loads(SPHERE))] + ([("bulb-640", fractalc.load(BULB))] if BULB.exists() else [])
    results = [measure(name, scene, args.width, args.height, args.rounds) for name, scene in scenes]
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
