"""Peak memory (resident set) of `fractalc render` for large PNG and EXR
images, against the size of the image the kernel writes (9 float32
channels a pixel).

    python benchmarks/peak_memory.py                     # 3840x2160 and 7680x4320
    python benchmarks/peak_memory.py 1920x1080 3840x2160

Each render runs in a child process (a cheap scene: 16 march steps, no AO,
no shadows, so a frame takes seconds); its peak RSS is the child's own, from
os.wait4. The baseline is a 16x12 render of the same scene: the interpreter,
OpenCL and OpenImageIO, after a first render has filled the kernel cache
(a build from source takes memory of its own). Prints a Markdown table.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile

SCENE = """\
scene sphere(1) | box((3, 3, 0.2)).translate((0, 0, -1.2))
camera { position: (2, -3, 1.5), target: (0, 0, 0), fov: 50 }
light directional { direction: (-0.4, 0.7, -1), shadows: none }
render { max_steps: 16, ao: 0, samples: 1 }
"""
CHANNELS = 9
DEFAULT_SIZES = ("3840x2160", "7680x4320")


def peak_rss_bytes(command: list[str]) -> int:
    """Run `command`; its peak resident set size in bytes (Linux: ru_maxrss in KiB)."""
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    error = child.stderr.read()
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({child.returncode}): {error.decode()[-2000:]}")
    return usage.ru_maxrss * 1024


def render_command(scene: str, output: str, width: int, height: int) -> list[str]:
    return [sys.executable, "-m", "fractalc", "render", scene, "-o", output,
            "--width", str(width), "--height", str(height), "-q"]


def measure(sizes: list[tuple[int, int]], folder: str) -> list[dict]:
    scene = os.path.join(folder, "cheap.frac")
    with open(scene, "w") as f:
        f.write(SCENE)
    peak_rss_bytes(render_command(scene, os.path.join(folder, "warm.png"), 16, 12))  # fill the kernel cache
    rows = []
    for extension in ("png", "exr"):
        output = os.path.join(folder, f"out.{extension}")
        baseline = peak_rss_bytes(render_command(scene, output, 16, 12))
        for width, height in sizes:
            peak = peak_rss_bytes(render_command(scene, output, width, height))
            image = width * height * CHANNELS * 4
            rows.append({"size": f"{width}x{height}", "format": extension.upper(), "peak": peak,
                         "baseline": baseline, "image": image})
    return rows


def table(rows: list[dict]) -> str:
    mb = 1e6
    lines = ["| size | format | peak RSS (MB) | baseline (MB) | image, 9 x float32 (MB) | (peak - baseline) / image |",
             "| --- | --- | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lines.append(f"| {r['size']} | {r['format']} | {r['peak'] / mb:.0f} | {r['baseline'] / mb:.0f} | "
                     f"{r['image'] / mb:.0f} | {(r['peak'] - r['baseline']) / r['image']:.2f} |")
    return "\n".join(lines)


def main(arguments: list[str]) -> None:
    sizes = [tuple(int(n) for n in s.lower().split("x")) for s in (arguments or DEFAULT_SIZES)]
    with tempfile.TemporaryDirectory() as folder:
        print(table(measure(sizes, folder)))


if __name__ == "__main__":
    main(sys.argv[1:])
