"""Peak memory and time of reading an environment map (the sky reduced to
fractalc.pathtrace's MAP_WIDTH x MAP_HEIGHT table), against its size.

    python benchmarks/environment_map_memory.py                   # 8000x4000 and 20000x10000
    python benchmarks/environment_map_memory.py 4000x2000 8000x4000

Each map is an 8-bit RGB PNG of smooth bands (small on disk, as a real
sky's PNG is not), written once into a temporary folder; each is read in
a child process (`pathtrace.environment_map`), whose peak RSS is its own,
from os.wait4 (see peak_memory.py). The baseline is the same child reading
a 64x32 map: the interpreter, numpy and OpenImageIO. Prints a Markdown table.
"""
from __future__ import annotations

import os
import sys
import tempfile
import time

import numpy as np

from peak_memory import peak_rss_bytes

DEFAULT_SIZES = ("8000x4000", "20000x10000")
READ = "import sys; from fractalc import pathtrace; pathtrace.environment_map(sys.argv[1])"


def write_map(path: str, width: int, height: int) -> None:
    """An RGB PNG of bands: a gradient down the rows, brighter to the east."""
    import OpenImageIO as oiio
    output = oiio.ImageOutput.create(path)
    spec = oiio.ImageSpec(width, height, 3, oiio.UINT8)
    output.open(path, spec)
    band = 256                  # rows written at a time: the map is never whole in memory here
    for y0 in range(0, height, band):
        rows = np.arange(y0, min(y0 + band, height))
        pixels = np.empty((len(rows), width, 3), np.uint8)
        pixels[..., 0] = (rows * 255 // height)[:, None]
        pixels[..., 1] = (np.arange(width) * 4 // width * 60)[None, :]
        pixels[..., 2] = 128
        output.write_scanlines(int(y0), int(y0 + len(rows)), 0, pixels)
    output.close()


def main(sizes: list[str]) -> None:
    print("| map | PNG size | peak RSS | over the baseline | read time |")
    print("|---|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as folder:
        small = os.path.join(folder, "small.png")
        write_map(small, 64, 32)
        baseline = peak_rss_bytes([sys.executable, "-c", READ, small])
        for size in sizes:
            width, height = (int(x) for x in size.split("x"))
            path = os.path.join(folder, f"{size}.png")
            write_map(path, width, height)
            start = time.perf_counter()
            peak = peak_rss_bytes([sys.executable, "-c", READ, path])
            seconds = time.perf_counter() - start
            print(f"| {size} | {os.path.getsize(path) / 1024:.0f} KB | {peak / 2**20:.0f} MiB "
                  f"| {(peak - baseline) / 2**20:.0f} MiB | {seconds:.1f} s |", flush=True)
            os.remove(path)
    print(f"\nbaseline (a 64x32 map): {baseline / 2**20:.0f} MiB")


if __name__ == "__main__":
    main(sys.argv[1:] or list(DEFAULT_SIZES))
