"""Parse and check time and peak memory of large valid scene files, up to
the 8 MB limit, and the parse time of the example scenes.

    python benchmarks/large_input.py                 # 1 MB and 8 MB of each kind
    python benchmarks/large_input.py --mb 1 2 4 8

Each measurement runs in a child process (`python -c`), which times (CPU
seconds, which a loaded machine changes less than wall-clock ones)
`fractalc.parse.parse` and then (unless --no-check) `fractalc.check.check`;
its peak RSS is the child's own (ru_maxrss from os.wait4). A check
that rejects a scene (the part limit) still counts: the time is the time
to answer. Prints a Markdown table.
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

CHILD = """
import json, sys, time
from fractalc.check import check
from fractalc.errors import SceneError
from fractalc.parse import parse
text = open(sys.argv[1], encoding="utf-8").read()
start, wall = time.process_time(), time.perf_counter()
try:
    program = parse(text, sys.argv[1])
except SceneError as error:
    program, verdict = None, "parse error: " + error.message[:40]
parsed = time.process_time()
try:
    if program is not None and sys.argv[2] == "check":
        check(program)
        verdict = "checks"
    elif program is not None:
        verdict = "parses"
except SceneError as error:
    verdict = "check error: " + error.message[:40]
print(json.dumps({"parse": parsed - start, "check": time.process_time() - parsed,
                  "wall": time.perf_counter() - wall, "verdict": verdict}))
"""

CAMERA = "camera { position: (0, -4, 1), target: (0, 0, 0) }\n"


def flat_union(size: int) -> str:
    """`scene union(sphere(), sphere(), ...)` on one line."""
    head, item, tail = "scene union(", "sphere(), ", "sphere())\n" + CAMERA
    return head + item * ((size - len(head) - len(tail)) // len(item)) + tail


def operator_chains(size: int) -> str:
    """Lines `let cN = sphere() | sphere() | ...`, 200 shapes each (the
    nesting limit allows 255), the last one the scene."""
    line_of = lambda n: f"let c{n} = " + " | ".join(["sphere()"] * 200) + "\n"
    lines, total, n = [], 0, 0
    while total + len(line_of(n)) < size - 100:
        lines.append(line_of(n))
        total += len(lines[-1])
        n += 1
    return "".join(lines) + f"scene c{n - 1}\n" + CAMERA


def let_lines(size: int) -> str:
    """Lines `let aN = sphere(N)`, each name used once by a chain of
    unions: `let uN = union(uN-1, aN)` would nest, so the scene names the
    last let only and the others are unused."""
    lines, total, n = [], 0, 0
    while total < size - 100:
        lines.append(f"let a{n} = sphere({n % 97 + 1}).translate(({n}, 0, 0))\n")
        total += len(lines[-1])
        n += 1
    return "".join(lines) + f"scene a{n - 1}\n" + CAMERA


def path_block(size: int) -> str:
    """One `path { ... }` with a keyframe a line."""
    lines, total, n = ["path {\n"], 7, 0
    while total < size - 200:
        lines.append(f"  {n}: {{ position: ({n}, -4, 1), target: (0, 0, 0), fov: 50 }}\n")
        total += len(lines[-1])
        n += 1
    return "".join(lines) + "}\nscene sphere()\n" + CAMERA


def one_chain(size: int) -> str:
    """`scene sphere() | sphere() | ...`: past the nesting limit at the
    256th '|', an error that must come at once."""
    return "scene " + " | ".join(["sphere()"] * (size // len("sphere() | "))) + "\n"


KINDS = {"flat union": flat_union, "| chains": operator_chains, "one | chain": one_chain, "let lines": let_lines, "path block": path_block}


def measure(path: str, stage: str) -> dict:
    """The child's times and verdict, and its own peak RSS (os.wait4)."""
    child = subprocess.Popen([sys.executable, "-c", CHILD, path, stage], stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, text=True)
    output = child.stdout.read()
    _, status, usage = os.wait4(child.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{path}: {output[-2000:]}")
    return {**json.loads(output.splitlines()[-1]), "peak_mb": usage.ru_maxrss / 1024}


def example_parse_ms(repeats: int) -> float:
    """Median over `repeats` of the CPU time to parse every example scene once."""
    from fractalc.parse import parse
    texts = [(open(p).read(), p) for p in sorted(glob.glob(os.path.join(os.path.dirname(__file__), "..",
                                                                        "examples", "*.frac")))]
    times = []
    for _ in range(repeats):
        start = time.process_time()
        for text, name in texts:
            parse(text, name)
        times.append(time.process_time() - start)
    return statistics.median(times) * 1000 / len(texts)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mb", type=float, nargs="+", default=[1, 8], help="file sizes in MB")
    parser.add_argument("--repeats", type=int, default=200, help="runs of the example scenes")
    parser.add_argument("--no-check", action="store_true", help="parse only")
    args = parser.parse_args()
    print(f"examples/*.frac: median parse time {example_parse_ms(args.repeats):.2f} ms (CPU) a file\n")
    print("| scene | size | parse, CPU s | check, CPU s | wall s | peak RSS MB | verdict |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        for mb in sorted(args.mb):
            for kind, make in KINDS.items():
                path = os.path.join(folder, "scene.frac")
                with open(path, "w") as f:
                    f.write(make(int(mb * 1024 * 1024)))
                size = os.path.getsize(path)
                row = measure(path, "parse" if args.no_check else "check")
                check_seconds = "-" if args.no_check else f"{row['check']:.2f}"
                print(f"| {kind.replace('|', '&#124;')} | {size / 1024 / 1024:.1f} MB | {row['parse']:.2f} | {check_seconds} "
                      f"| {row['wall']:.1f} | {row['peak_mb']:.0f} | {row['verdict']} |", flush=True)


if __name__ == "__main__":
    main()
