"""Two checkouts of fractalc, compiler and host alike, on the same scenes in
one process: each scene's file view rendered by both in turn, round by
round, the order swapped each round, so that load on a shared machine
falls on both alike. Prints one JSON line per scene: the medians of the
frame's wall time and of the process's CPU time (the driver's threads
included; steadier where others share the cores), and how far the new
image is from the old (hit mismatch, colour RMSE).

    python benchmarks/checkout_ab.py SCENE... [--old REV|DIR] [--rounds 9]

REV is a git revision (its tree is exported to a temporary folder), DIR a
folder holding a fractalc/ package; the old one defaults to `main`, the
new one is this working tree's.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def package(name: str, root: Path):
    """The fractalc package under `root`, imported as `name`."""
    spec = importlib.util.spec_from_file_location(name, root / "fractalc" / "__init__.py",
                                                  submodule_search_locations=[str(root / "fractalc")])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def checkout(revision: str, folder: Path) -> Path:
    if Path(revision, "fractalc").is_dir():
        return Path(revision)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", revision], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


def timed(scene) -> tuple[float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    scene.render()
    return time.perf_counter() - wall, time.process_time() - cpu


def compare(path: str, old, new, rounds: int) -> dict:
    scenes = {"old": old.load(path), "new": new.load(path)}
    images = {who: scene.render() for who, scene in scenes.items()}      # builds and warms up
    times: dict = {"old": [], "new": []}
    for i in range(rounds):
        for who in ("old", "new") if i % 2 == 0 else ("new", "old"):
            times[who].append(timed(scenes[who]))
    depth = {who: np.asarray(image.depth) for who, image in images.items()}
    colour = {who: np.asarray(image.rgba)[..., :3] for who, image in images.items()}
    row = {"scene": path, "rounds": rounds,
           "hit_mismatch": float((np.isfinite(depth["old"]) != np.isfinite(depth["new"])).mean()),
           "colour_rmse": float(np.sqrt(np.mean((colour["old"] - colour["new"]) ** 2)))}
    for who, pairs in times.items():
        row[who] = {"wall_ms": 1e3 * statistics.median(w for w, _ in pairs),
                    "cpu_ms": 1e3 * statistics.median(c for _, c in pairs)}
    row["cpu_ratio"] = row["new"]["cpu_ms"] / row["old"]["cpu_ms"]
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenes", nargs="+")
    parser.add_argument("--old", default="main", help="a git revision or a folder holding fractalc/")
    parser.add_argument("--rounds", type=int, default=9)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        old = package("fractalc_old", checkout(args.old, Path(folder)))
        new = package("fractalc", ROOT)
        for path in args.scenes:
            print(json.dumps(compare(path, old, new, args.rounds)), flush=True)


if __name__ == "__main__":
    main()
