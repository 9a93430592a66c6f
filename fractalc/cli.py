"""The `fractalc` command line (LANGUAGE.md, "Command line").

Exit codes: 0 success; 2 a scene or usage error (`FILE:LINE:COL: error:`
with the source line and a caret); 1 a runtime failure, in one line;
130 interrupted. Never a traceback for any of these.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from .errors import RenderError, SceneError
from .write import publish

IMAGE_EXTENSIONS = (".exr", ".png", ".jpg", ".jpeg", ".tif", ".tiff")


class UsageError(Exception):
    pass


def _parse_set(values: list[str]) -> dict[str, float]:
    params = {}
    for item in values or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise UsageError(f"--set takes NAME=VALUE, not '{item}'")
        try:
            params[name.strip()] = float(value)
        except ValueError:
            raise UsageError(f"--set {name.strip()}: '{value}' is not a number") from None
    return params


def _require_file(path: str) -> None:
    if not os.path.isfile(path):
        raise UsageError(f"cannot read {path}: no such file")


def _load(args):
    from .api import load
    _require_file(args.scene)
    params = _parse_set(getattr(args, "set", None))
    return load(args.scene, params=params, precision=getattr(args, "precision", None),
                device=getattr(args, "device", None))


def _write_text_atomically(path: str, text: str) -> None:
    import tempfile
    directory = os.path.dirname(os.path.abspath(path))
    handle, temporary = tempfile.mkstemp(prefix=".fractalc-", suffix=os.path.splitext(path)[1], dir=directory)
    try:
        with os.fdopen(handle, "w") as f:
            f.write(text)
        publish(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)


def command_render(args) -> int:
    if not args.output.lower().endswith(IMAGE_EXTENSIONS):
        raise UsageError(f"-o {args.output}: the output must end in one of {', '.join(IMAGE_EXTENSIONS)}")
    scene = _load(args)
    overrides = {"width": args.width, "height": args.height, "samples": args.samples}
    try:
        start = time.perf_counter()
        image = scene.render(seed=args.seed, progress=not args.quiet, **overrides)
    except ValueError as error:
        raise UsageError(str(error)) from None
    image.save(args.output)
    if not args.quiet:
        height, width = image.depth.shape
        print(f"wrote {args.output} ({width}x{height}, {time.perf_counter() - start:.2f} s)",
              file=sys.stderr)
    return 0


def command_compile(args) -> int:
    scene = _load(args)
    _write_text_atomically(args.output, scene.kernel_source(lanes=args.lanes))
    return 0


def command_check(args) -> int:
    from .check import check
    from .parse import parse
    _require_file(args.scene)
    try:
        with open(args.scene, "rb") as f:
            text = f.read(8 * 1024 * 1024 + 1).decode("utf-8", errors="replace")
    except OSError as error:
        raise RenderError(f"cannot read {args.scene}: {error.strerror}") from None
    check(parse(text, args.scene))
    return 0


def command_devices(args) -> int:
    from .build import list_devices
    devices = list_devices()
    if not devices:
        from .build import INSTALL_HINT
        raise RenderError(INSTALL_HINT)
    for d in devices:
        print(f"{d.index}: {d.name} [{d.kind}] on {d.platform}; {d.version}; "
              f"{d.compute_units} compute units; double: {'yes' if d.double else 'no'}")
    return 0


def command_bench(args) -> int:
    import json
    from .bench import RESOLUTIONS, bench, table
    width, height = args.width, args.height
    if args.resolution:
        key = args.resolution.lower()
        if key not in RESOLUTIONS:
            raise UsageError(f"--resolution {args.resolution}: choose one of {', '.join(RESOLUTIONS)}")
        width, height = RESOLUTIONS[key]
    for name, value in (("--frames", args.frames), ("--repeat", args.repeat), ("--width", width),
                        ("--height", height)):
        if value is not None and value < 1:
            raise UsageError(f"{name} must be at least 1")
    scene = _load(args)
    result = bench(scene, frames=args.frames, width=width, height=height, repeat=args.repeat,
                   use_cache=not args.no_cache)
    print(table(result))
    if args.json:
        _write_text_atomically(args.json, json.dumps(result.as_dict(), indent=2) + "\n")
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="fractalc", description="Compile and render .frac fractal scenes.")
    from . import __version__
    parser.add_argument("--version", action="version", version=f"fractalc {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def device_options(p):
        p.add_argument("--set", action="append", metavar="NAME=VALUE",
                       help="set a param (repeatable); no recompilation")
        p.add_argument("--precision", choices=("float", "double"),
                       help="arithmetic of the whole kernel (default: the file's, else float)")
        p.add_argument("--device", help="OpenCL device: index, name substring, 'cpu' or 'gpu' "
                                        "(see 'fractalc devices'; also $FRACTALC_DEVICE)")

    render = commands.add_parser("render", help="render a scene to EXR or PNG",
                                 description="Render a scene. EXR: linear float with Z, normals and "
                                             "steps; PNG: sRGB 8-bit.")
    render.add_argument("scene")
    render.add_argument("-o", "--output", required=True, help="output image (.exr, .png, ...)")
    render.add_argument("--width", type=int)
    render.add_argument("--height", type=int)
    render.add_argument("--samples", type=int, help="anti-aliasing samples per pixel")
    render.add_argument("--seed", type=int, default=0, help="jitter seed for samples > 1")
    render.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    device_options(render)
    render.set_defaults(run=command_render)

    compile_ = commands.add_parser("compile", help="write the standalone OpenCL kernel",
                                   description="Write the scene's kernel as one standalone .cl file "
                                               "(no includes; the kernel signature is documented at its top).")
    compile_.add_argument("scene")
    compile_.add_argument("-o", "--output", required=True, help="output .cl file")
    compile_.add_argument("--lanes", type=int, choices=(1, 2, 4, 8, 16),
                          help="rays per work-item (default: 8 on CPUs, 1 on GPUs)")
    device_options(compile_)
    compile_.set_defaults(run=command_compile)

    check_ = commands.add_parser("check", help="parse and type-check a scene",
                                 description="Parse and check a scene; print every error.")
    check_.add_argument("scene")
    check_.set_defaults(run=command_check)

    bench_ = commands.add_parser("bench", help="measure frame times along a camera orbit",
                                 description="The benchmark of seed 000: render --frames frames along an "
                                             "orbit of the camera about its target; report frame-time "
                                             "statistics, compile time and the machine.")
    bench_.add_argument("scene")
    bench_.add_argument("--frames", type=int, default=30)
    bench_.add_argument("--width", type=int)
    bench_.add_argument("--height", type=int)
    bench_.add_argument("--resolution", help="1366x768, 1920x1080, 2560x1440, 3840x2160 (or 720p, 1080p, 1440p, 4k)")
    bench_.add_argument("--repeat", type=int, default=1, help="runs of the whole path; figures are medians")
    bench_.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    bench_.add_argument("--no-cache", action="store_true", help="compile the kernel even if it is cached")
    device_options(bench_)
    bench_.set_defaults(run=command_bench)

    devices = commands.add_parser("devices", help="list OpenCL devices")
    devices.set_defaults(run=command_devices)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if getattr(args, "no_cache", False):
        # Before OpenCL loads: the driver's and pyopencl's binary caches.
        os.environ["POCL_KERNEL_CACHE"] = "0"
        os.environ["PYOPENCL_NO_CACHE"] = "1"
    try:
        return args.run(args)
    except SceneError as error:
        print(error, file=sys.stderr)
        return 2
    except UsageError as error:
        parser.print_usage(sys.stderr)
        print(f"fractalc: error: {error}", file=sys.stderr)
        return 2
    except RenderError as error:
        print(f"fractalc: error: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"fractalc: error: {error.strerror or error}: {error.filename or ''}".rstrip(": "),
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("fractalc: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
