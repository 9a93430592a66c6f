"""Peak memory, time and size of `fractalc mesh` against the resolution.

    python benchmarks/mesh_memory.py                  # resolutions 256, 512, 1024
    python benchmarks/mesh_memory.py 128 256

Each mesh is made in a child process (`fractalc mesh ... -o out.ply -q`);
its peak RSS is the child's own, from os.wait4 (see peak_memory.py). The
distance field is sampled in slabs of z-planes (fractalc/mesh.py,
CHUNK_POINTS), so the grid costs the same few hundred MB at any
resolution: what grows is the mesh itself, with the surface's area. The
scenes: a sphere (the least surface for its bound) and a level-3 Menger
sponge (much more). Prints a Markdown table.
"""
from __future__ import annotations

import os
import sys
import tempfile
import time

from peak_memory import peak_rss_bytes

SCENES = {"sphere": "scene sphere(1)\n", "menger level 3": "scene menger(level: 3)\n"}
DEFAULT_RESOLUTIONS = (256, 512, 1024)


def ply_counts(path: str) -> tuple[int, int]:
    """(vertices, faces) from a PLY header."""
    counts = {}
    with open(path, "rb") as f:
        for line in f:
            if line.startswith(b"element"):
                _, name, count = line.split()
                counts[name.decode()] = int(count)
            if line.startswith(b"end_header"):
                return counts["vertex"], counts["face"]
    raise ValueError(f"{path}: no PLY header")


def main(resolutions: list[int]) -> None:
    print("| scene | resolution | peak RSS | time | vertices | triangles | PLY size |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as folder:
        for name, text in SCENES.items():
            scene = os.path.join(folder, "scene.frac")
            with open(scene, "w") as f:
                f.write(text)
            output = os.path.join(folder, "out.ply")
            # a first run builds the kernel (the compiler's memory is not the mesh's)
            peak_rss_bytes([sys.executable, "-m", "fractalc", "mesh", scene, "-o", output, "--resolution", "8", "-q"])
            for resolution in resolutions:
                start = time.perf_counter()
                peak = peak_rss_bytes([sys.executable, "-m", "fractalc", "mesh", scene, "-o", output,
                                       "--resolution", str(resolution), "-q"])
                seconds = time.perf_counter() - start
                vertices, faces = ply_counts(output)
                print(f"| {name} | {resolution} | {peak / 2**20:.0f} MiB | {seconds:.1f} s | {vertices:,} "
                      f"| {faces:,} | {os.path.getsize(output) / 2**20:.0f} MiB |", flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or list(DEFAULT_RESOLUTIONS))
