"""Two versions of the OpenCL library (stdlib_cl/) on one scene, in one
process: distance evaluations per pixel (as `fractalc bench --count`
counts them), render time (the two kernels rendered alternately, round by
round, the order swapped each round; wall time and the process's CPU time,
which is steadier on a machine others share) and each image's error
against the reference of `fractalc bench --sweep` (double precision, a
tenth of the hit threshold, four times the steps), rendered with the old
library.

    python benchmarks/kernel_ab.py SCENE [--old REV|DIR] [--new REV|DIR]
        [--patch FILE] [--width W --height H] [--rounds N] [--lanes L]

REV is a git revision (its stdlib_cl/ is used), DIR a directory holding a
stdlib_cl/; the old library defaults to HEAD's, the new one to the
working tree's. `--patch` applies a diff (of stdlib_cl/ files, as `git
diff` writes it; benchmarks/patches/ holds the methods tried and dropped)
to a copy of the new library. The Python side (emitter, runner) is the
working tree's for both, so only the library differs.
"""
from __future__ import annotations

import argparse
import contextlib
import shutil
import statistics
import subprocess
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import fractalc
import fractalc.stdlib as stdlib
from fractalc import count, run
from fractalc.image import image_from_pixels
from fractalc.build import build
from fractalc.emit import emit
from fractalc.lower import lower
from fractalc.sweep import compare, reference_settings, scene_settings

ROOT = Path(__file__).resolve().parent.parent


def library_dir(spec: str | None, scratch: Path, patch: str | None = None) -> Path:
    """The directory holding the stdlib_cl/ that `spec` names, with
    `patch` applied (to a copy)."""
    target = Path(tempfile.mkdtemp(dir=scratch))
    if spec is None or Path(spec).is_dir():
        shutil.copytree(Path(spec or ROOT) / "stdlib_cl", target / "stdlib_cl")
    else:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", spec, "stdlib_cl"], capture_output=True,
                                 check=True)
        subprocess.run(["tar", "-x", "-C", str(target)], input=archive.stdout, check=True)
    if patch:
        subprocess.run(["git", "apply", str(Path(patch).resolve())], cwd=target, check=True)
    return target


@contextlib.contextmanager
def using_library(folder: Path):
    """Emit from `folder`/stdlib_cl while inside."""
    original = stdlib.resource_dir
    stdlib.resource_dir = lambda name: folder / name if name == "stdlib_cl" else original(name)
    stdlib.library.cache_clear()
    try:
        yield
    finally:
        stdlib.resource_dir = original
        stdlib.library.cache_clear()


class Kernel:
    """A scene's render kernel built from one library, with the scene's
    settings changed by `render_keys`."""

    def __init__(self, scene, folder: Path, render_keys: dict, width: int, height: int):
        self.renderer = scene.renderer(**render_keys)
        target = self.renderer.target
        with using_library(folder):
            source = emit(lower(replace(scene.checked, render=self.renderer.settings)), target)
        self.kernel = run.RenderKernel(build(source, scene.device), scene.device, target.lanes, target.double)
        self.frame = replace(self.renderer.frame, width=width, height=height)

    def render(self):
        pixels = self.kernel.render(self.frame, self.renderer.params, channels=self.renderer.channels)
        return image_from_pixels(pixels, self.renderer.settings.aovs, {})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene")
    parser.add_argument("--old", default="HEAD")
    parser.add_argument("--new")
    parser.add_argument("--patch")
    parser.add_argument("--width", type=int)
    parser.add_argument("--height", type=int)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--lanes", type=int)
    args = parser.parse_args()
    scene = fractalc.load(args.scene, lanes=args.lanes)
    width, height = args.width or scene.checked.render.width, args.height or scene.checked.render.height
    with tempfile.TemporaryDirectory() as scratch:
        folders = {"old": library_dir(args.old, Path(scratch)), "new": library_dir(args.new, Path(scratch), args.patch)}
        settings = scene.checked.render
        reference = Kernel(scene, folders["old"], reference_settings(scene_settings(scene)),
                           width, height).render()
        kernels = {name: Kernel(scene, folder, {}, width, height) for name, folder in folders.items()}
        counts = {}
        for name, folder in folders.items():
            with using_library(folder):
                counts[name] = count.count(scene, width, height)
        errors = {name: compare(kernel.render(), reference) for name, kernel in kernels.items()}
        seconds = {name: [] for name in kernels}
        cpu_seconds = {name: [] for name in kernels}
        for round_ in range(args.rounds):
            for name in (("old", "new") if round_ % 2 == 0 else ("new", "old")):
                start, start_cpu = time.perf_counter(), time.process_time()
                kernels[name].render()
                seconds[name].append(time.perf_counter() - start)
                cpu_seconds[name].append(time.process_time() - start_cpu)
    print(f"{args.scene} at {width}x{height}, {scene.lanes_in_use} lanes, {settings.precision}; "
          f"old {args.old}, new {args.new or 'working tree'}{' + ' + args.patch if args.patch else ''}; "
          f"{args.rounds} rounds")
    print(f"{'':4s} {'evals/px':>9s} {'by purpose (camera normals shadows ao reflections refraction)':>62s} "
          f"{'ms median [min-max]':>22s} {'hit mism.':>9s} {'depth p99':>10s} {'RMSE':>9s}")
    for name in kernels:
        c, e, ms = counts[name], errors[name], [s * 1000 for s in seconds[name]]
        purposes = " ".join(f"{v:.2f}" for v in list(c.per_pixel().values())[:6])
        print(f"{name:4s} {c.total / c.pixels:9.2f} {purposes:>62s} "
              f"{statistics.median(ms):8.1f} [{min(ms):.1f}-{max(ms):.1f}]".ljust(108)
              + f" {e.hit_mismatch:9.5f} {e.depth_error_p99:10.2e} {e.color_rmse:9.5f}")
    # CPU time (all the process's threads) is steadier than wall time on a machine others share
    for kind, measured in (("wall", seconds), ("CPU", cpu_seconds)):
        ratios = sorted(new / old for old, new in zip(measured["old"], measured["new"]))
        print(f"new / old {kind} time: median of the per-round ratios {statistics.median(ratios):.3f} "
              f"(range {ratios[0]:.3f}-{ratios[-1]:.3f}); medians old {statistics.median(measured['old']) * 1e3:.1f} ms, "
              f"new {statistics.median(measured['new']) * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
