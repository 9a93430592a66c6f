"""The `fractalc` command line (LANGUAGE.md, "Command line").

Exit codes: 0 success; 2 a scene or usage error (`FILE:LINE:COL: error:`
with the source line and a caret); 1 a runtime failure, in one line
(an output that cannot be written included); 130 interrupted; 128 + the signal's
number for SIGTERM (143) and SIGHUP (129). Never a traceback for any of these.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from contextlib import contextmanager, nullcontext

from .errors import NoSceneFile, RenderError, SceneError
from .passes import PASSES
from .write import COMPRESSIONS, output_problem, replacing

IMAGE_EXTENSIONS = (".exr", ".png", ".jpg", ".jpeg", ".tif", ".tiff")


class UsageError(Exception):
    pass


def _parse_set(values: list[str]) -> dict[str, float]:
    from .arguments import parse_number
    params = {}
    for item in values or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise UsageError(f"--set takes NAME=VALUE, not '{item}'")
        from .types import in_float_range
        try:
            number = parse_number(value)
        except ValueError as error:
            raise UsageError(f"--set {name.strip()}: {error}") from None
        if not in_float_range(number):
            raise UsageError(f"--set {name.strip()}: '{value}' is not a finite number within float's range")
        params[name.strip()] = number
    return params


def _option(name: str):
    """The argparse type of a numeric option: its text read by
    arguments.parse_number and checked against the argument `name`'s
    range (arguments.ARGUMENTS, or a render key's), as the API checks it.
    Tests find every numeric option by the function's `argument`."""
    from .arguments import checked, parse_number

    def parse(text: str):
        try:
            return checked(name, parse_number(text), subject="")
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
    parse.argument = name
    return parse


def _device(text: str) -> str:
    """--device: an index in ASCII digits, or a name; '٣' is neither."""
    if any(c.isdigit() for c in text) and not text.isascii():
        raise argparse.ArgumentTypeError(f"'{text}': a device index is written in the digits 0-9")
    return text


def _require_file(path: str) -> str:
    """The scene file's text; no file there (or a directory, FIFO, device) is a usage mistake."""
    from .source import read_scene_file
    try:
        return read_scene_file(path)
    except NoSceneFile as error:
        raise UsageError(str(error)) from None


# why --aov refuses other formats than EXR
_AOV_IN_EXR = " (passes are EXR channels; PNG and other formats hold R G B A only)"


def _passes(text: str) -> list[str]:
    """--aov's value: pass names, comma-separated."""
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in PASSES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"unknown pass '{unknown[0] if unknown else text}' "
                                         f"(known: {', '.join(PASSES)})")
    return names


def _key_value(text: str):
    """A --render or --camera value: numbers, a vector (x,y,z), or a word."""
    from .arguments import parse_number
    parts = [part.strip() for part in text.strip().strip("()").split(",")]
    try:
        numbers = tuple(parse_number(part) for part in parts)
    except ValueError:
        return text.strip()
    return numbers if len(numbers) > 1 else numbers[0]


def _keys_given(args) -> tuple[dict, dict]:
    """--render and --camera KEY=VALUE items, each checked as in a file's
    block (before any work): (render keys, camera keys). A block key is
    given by its parts (`--render fog.density=0.2`) or turned off (`fog=off`)."""
    from .check import check_value
    from .program import CAMERA_KEYS, RENDER_KEYS
    from .types import Type
    found = {"--render": {}, "--camera": {}}
    for option, keys, items in (("--render", RENDER_KEYS, args.render), ("--camera", CAMERA_KEYS, args.camera)):
        owner = option[2:]
        for item in items or ():
            key, sep, text = (part.strip() for part in item.partition("="))
            name, _, part = key.partition(".")
            if not sep or not key:
                raise UsageError(f"{option} takes KEY=VALUE, not '{item}'")
            if name not in keys:
                raise UsageError(f"{option} {item}: '{owner}' has no key '{name}' (known: {', '.join(keys)})")
            value = _key_value(text)
            try:
                if keys[name].type is Type.BLOCK:
                    block = found[option].get(name) or {}
                    value = False if value == "off" else {**block, **({part: value} if part else {})}
                check_value(keys[name], name, value)
            except ValueError as error:
                raise UsageError(f"{option} {item}: {str(error).replace(' of ' + repr('render'), ' of ' + repr(owner))}") from None
            found[option][name] = value
    return found["--render"], found["--camera"]


def _configure(scene, keys: tuple[dict, dict]) -> None:
    """Make the --render and --camera keys the scene's own."""
    from dataclasses import asdict
    from .api import Camera
    render, camera = keys
    try:
        scene.set_defaults(Camera(**{**asdict(scene.checked.camera), **camera}) if camera else None, **render)
    except ValueError as error:    # keys wrong together: the camera looks nowhere
        raise UsageError(f"--camera: {error}") from None


def _require_params(items: list[str] | None, checked) -> dict[str, float]:
    """--set's values, each naming a param the scene declares."""
    from .check import unknown_param
    params = _parse_set(items)
    for item in items or ():
        mistake = unknown_param(item.partition("=")[0].strip(), checked)
        if mistake:
            raise UsageError(f"--set {item}: {mistake}")
    return params


def _print_notes(checked) -> None:
    for note in checked.notes:
        print(note, file=sys.stderr)


def _load(args):
    from .api import loads
    text = _require_file(args.scene)
    _parse_set(getattr(args, "set", None))          # its syntax before any work
    keys = _keys_given(args) if hasattr(args, "render") else None
    scene = loads(text, precision=getattr(args, "precision", None), device=getattr(args, "device", None),
                  path=args.scene)
    params = _require_params(getattr(args, "set", None), scene.checked)
    if getattr(args, "preset", None):
        try:
            scene.apply_preset(args.preset)
        except ValueError as error:
            raise UsageError(f"--preset {args.preset}: {error}") from None
    scene.set_params(params)      # --set wins over the preset
    _print_notes(scene.checked)
    if keys:
        _configure(scene, keys)
    return scene


def _write_text_atomically(path: str, text: str) -> None:
    with replacing(path) as temporary, open(temporary, "w") as f:
        f.write(text)


def _require_writable(*options, folders_made: bool = False) -> None:
    """Outputs that cannot be written fail before any build or render,
    as runtime failures (the file system's state, as when a disk fills
    while writing): (option, as given, file to write) triples
    (`folders_made`: missing folders will be made)."""
    for name, given, path in options:
        problem = path and output_problem(path, folders_made)
        if problem:
            raise RenderError(f"{name} {given}: {problem}")


def _cluster(args):
    """--workers N / --cluster ADDRESS: a context that gives a Dask client
    (the extra is checked now, before any work; the cluster is reached on
    entering), else one that gives None."""
    if args.workers is None and args.cluster is None:
        return nullcontext()
    from .cluster import MISSING_EXTRA, connect, installed, require_workers_memory, scheduler_address
    if not installed():
        raise UsageError(MISSING_EXTRA)
    if args.cluster is not None:
        try:
            scheduler_address(args.cluster)
        except ValueError as error:
            raise UsageError(f"--cluster {args.cluster}: {error}") from None
    else:
        require_workers_memory(args.workers)
    return connect(args.workers, args.cluster)


def command_render(args) -> int:
    cluster = _cluster(args)
    if not args.output.lower().endswith(IMAGE_EXTENSIONS):
        raise UsageError(f"-o {args.output}: the output must end in one of {', '.join(IMAGE_EXTENSIONS)}")
    exr = args.output.lower().endswith(".exr")
    for option, given in (("--half", args.half), ("--compression", args.compression)):
        if given and not exr:
            raise UsageError(f"{option} is for EXR output, not {args.output}")
    if args.aov and not exr:
        raise UsageError(f"--aov is for EXR output, not {args.output}{_AOV_IN_EXR}")
    if args.bits != 8 and exr:
        raise UsageError(f"--bits is for PNG (and other integer) output, not {args.output}")
    _require_writable(("-o", args.output, args.output))
    if args.environment_map is not None:
        from .pathtrace import environment_map
        try:
            environment_map(os.path.abspath(args.environment_map))
        except ValueError as error:
            raise UsageError(f"--environment-map {args.environment_map}: {error}") from None
    scene = _load(args)
    overrides = {"width": args.width, "height": args.height, "samples": args.samples, "aovs": args.aov}
    try:
        start = time.perf_counter()
        with cluster as client:
            image = scene.render(seed=args.seed, progress=not args.quiet, cluster=client, denoise=args.denoise,
                                 environment_map=args.environment_map, **overrides)
    except ValueError as error:
        raise UsageError(str(error)) from None
    image.save(args.output, half=args.half, compression=args.compression or "zip", bits=args.bits)
    if not args.quiet:
        height, width = image.depth.shape
        print(f"wrote {args.output} ({width}x{height}, {time.perf_counter() - start:.2f} s)",
              file=sys.stderr)
    return 0


def command_compile(args) -> int:
    _require_writable(("-o", args.output, args.output))
    scene = _load(args)
    _write_text_atomically(args.output, scene.kernel_source())
    return 0


def _count(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _checked_summary(scene) -> tuple[str, list]:
    """`check`'s line for a scene that checks (its parts, formulas, params,
    lights and the optional features its kernel will have) and its notes of
    the estimate each fractal gets, in source order."""
    from .emit import features
    from .errors import Severity, diagnostic
    from .lower import lower
    from .program import Combination, Fractal, Primitive, Transformed, WithMaterial, fold_shape
    checked = scene.checked
    kinds: dict[str, int] = {}
    formulas: list[str] = []
    notes: list = []        # which estimate each fractal's kind chose, and why

    def parts(shape, _):
        kind = "fractal" if isinstance(shape, Fractal) or (
            isinstance(shape, Primitive) and shape.signature.kind == "fractal") else \
            "shape" if isinstance(shape, Primitive) else \
            "combination" if isinstance(shape, Combination) else "transform"
        kinds[kind] = kinds.get(kind, 0) + 1
        names = [u.formula.name for u in shape.sequence] if isinstance(shape, Fractal) else \
            [shape.signature.name] if kind == "fractal" else []
        formulas.extend(name for name in names if name not in formulas)
        if isinstance(shape, Fractal) and shape.estimate_reason:
            notes.append(diagnostic(checked.file, checked.source, shape.span,
                                    f"the fractal gets {shape.estimate_reason}", Severity.NOTE))
        if isinstance(shape, Combination):
            return tuple((part, None) for part in shape.shapes)
        return ((shape.shape, None),) if isinstance(shape, (Transformed, WithMaterial)) else ()

    fold_shape(checked.shape, None, parts, lambda *_: None)
    shown = ", ".join(_count(kinds[k], k) for k in ("shape", "fractal", "combination", "transform") if k in kinds)
    on = [name.lower().replace("_", " ") for name, enabled in features(lower(checked)).items() if enabled]
    line = "; ".join((
        f"{scene.checked.file}: ok: {_count(sum(kinds.values()), 'part')} ({shown})",
        f"formulas: {', '.join(formulas)}" if formulas else "no formulas",
        f"{_count(len(checked.params), 'param')}" + (f" ({', '.join(p.name for p in checked.params)})"
                                                      if checked.params else ""),
        _count(len(checked.lights), "light") if checked.lights else "the headlight",
        f"kernel features: {', '.join(on) or 'none'}"))
    return line, sorted(notes, key=lambda d: (d.line, d.column))


def command_check(args) -> int:
    if not args.de:
        line, notes = _checked_summary(_load(args))
        for note in notes:
            print(note, file=sys.stderr)
        print(line)
        return 0
    from .overstep import Against, has_escape_time_set, measure
    scene = _load(args)
    # against the estimate's own surface, then (fractals with a bailout) the escape-time set
    for against in (Against.ESTIMATE, Against.ESCAPE_TIME_SET)[:1 + has_escape_time_set(scene)]:
        try:
            result = measure(scene, rays=args.rays, seed=args.seed, surface=args.surface, against=against)
        except ValueError as error:
            raise UsageError(f"--de: {error}") from None
        print(f"{args.scene}: {result.report()}", flush=True)
    return 0


def command_devices(args) -> int:
    from . import devices as found
    from .drivers import SWITCH_ENVIRONMENT, bundled_enabled, bundled_libraries
    from .lanes import UnusableDevice, choose, describe
    infos = found.list_devices()
    if not infos:
        raise RenderError(found.INSTALL_HINT)
    verdicts = {}
    for d in infos:
        try:
            verdicts[d.index] = f"builds: yes; rays per work-item: {describe(choose(d, refresh=args.probe))}"
        except UnusableDevice as unusable:
            verdicts[d.index] = f"builds: no: {found.cannot_build(d, unusable.failures)}"
    try:
        default = found.default_device(infos).index if not os.environ.get(found.DEVICE_ENVIRONMENT) else None
    except RenderError:
        default = None
    ranks = {d.index: rank for rank, d in enumerate(sorted(infos, key=found.speed_rank), 1)}
    for d in infos:
        print(f"{'*' if d.index == default else ' '} {d.index}: {d.name} [{d.kind}] on {d.driver_label}; "
              f"{d.version}; {d.compute_units} compute units; double: {'yes' if d.double else 'no'}; "
              f"{verdicts[d.index]}; speed rank {ranks[d.index]} of {len(infos)}")
    if default is not None:
        print("* the default: the fastest device that builds (GPU, then Intel's CPU runtime, then PoCL; "
              "docs/drivers.md); --device N or FRACTALC_DEVICE=N chooses another")
    for driver, library in bundled_libraries():
        state = "registered" if bundled_enabled() else f"left out ({SWITCH_ENVIRONMENT}=0)"
        print(f"bundled driver {driver.distribution}: {library} {state}")
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
    _require_writable(*((name, path, path) for name, path in
                        (("--json", args.json), ("--csv", args.csv), ("--plot", args.plot))))
    if args.count:
        if args.sweep or args.still:
            raise UsageError("--count counts one render of the file's view; it goes without --sweep and --still")
    if not args.sweep:
        for name, value in (("--csv", args.csv), ("--plot", args.plot), ("--vary", args.vary)):
            if value:
                raise UsageError(f"{name} goes with --sweep")
        if args.count:
            from .count import count, table as count_table
            counts = count(_load(args), width, height)
            print(count_table(counts))
            if args.json:
                _write_text_atomically(args.json, json.dumps(counts.as_dict(), indent=2) + "\n")
            return 0
        scene = _load(args)
        result = bench(scene, frames=args.frames, width=width, height=height, repeat=args.repeat or 1,
                       use_cache=not args.no_cache, still=args.still)
        print(table(result))
        if args.json:
            _write_text_atomically(args.json, json.dumps(result.as_dict(), indent=2) + "\n")
        return 0
    from . import sweep
    if args.still:
        raise UsageError("--still is for the frame benchmark; --sweep renders the file's view already")
    if args.json:
        raise UsageError("--json is for the orbit benchmark; --sweep writes --csv FILE")
    if args.plot and not args.plot.lower().endswith(".png"):
        raise UsageError(f"--plot {args.plot}: the plot is a PNG, its name must end in .png")
    try:
        changes = sweep.parse_changes(args.vary) if args.vary else None
    except ValueError as error:
        raise UsageError(str(error)) from None
    if args.plot:
        sweep.require_matplotlib()     # before minutes of rendering, not after
    scene = _load(args)
    result = sweep.sweep(scene, width=width, height=height, repeat=args.repeat or sweep.DEFAULT_REPEAT,
                         changes=changes, combine=changes is None, use_cache=not args.no_cache,
                         progress=lambda message: print(f"sweep: {message}", file=sys.stderr, flush=True))
    print(sweep.table(result))
    if args.csv:
        _write_text_atomically(args.csv, sweep.csv_text(result))
    if args.plot:
        sweep.save_plot(result, args.plot)
    return 0


def command_view(args) -> int:
    text = _require_file(args.scene)
    keys = _keys_given(args)
    if args.set:        # each a param of the file's, before a window opens
        from .check import check
        from .parse import parse
        _require_params(args.set, check(parse(text, args.scene)))
    from .view import Viewer, measure, show
    viewer = Viewer(args.scene, args.width, args.height, params=_parse_set(args.set),
                    precision=args.precision, device=args.device, preview_scale=args.preview_scale,
                    max_samples=args.max_samples, output_dir=args.output_dir)
    _configure(viewer.scene, keys)     # the file's own keys come back when it is edited and reloaded
    _print_notes(viewer.scene.checked)
    viewer.look_from(viewer.scene.checked.camera)
    if args.benchmark:
        fps = measure(viewer, args.benchmark)
        print(f"{args.scene}: {fps:.1f} FPS while moving ({args.benchmark} frames at "
              f"{max(1, viewer.width // viewer.preview_scale)}x{max(1, viewer.height // viewer.preview_scale)} "
              f"in a {viewer.width}x{viewer.height} window)")
    else:
        show(viewer)
    return 0


def _size(text: str) -> tuple[int, int]:
    """WIDTHxHEIGHT, each in the range of a render's width and height."""
    from .arguments import checked
    width, x, height = text.lower().partition("x")
    if not (x and width.isascii() and width.isdigit() and height.isascii() and height.isdigit()):
        raise argparse.ArgumentTypeError(f"'{text}' is not a size WIDTHxHEIGHT such as 320x180")
    try:
        return checked("width", int(width)), checked("height", int(height))
    except ValueError as error:
        raise argparse.ArgumentTypeError(f"'{text}': {error}") from None


def command_studio(args) -> int:
    _require_file(args.scene)
    from .studio import MISSING_EXTRA, installed
    if not installed():
        raise RenderError(MISSING_EXTRA)
    from .studio.server import serve
    from .studio.session import Options
    options = Options(args.device, args.precision, args.preview_scale, args.max_samples, args.live_size,
                      _parse_set(args.set))
    serve(args.scene, options, args.host, args.port, open_browser=not args.no_browser)
    return 0


def _frame_range(text: str) -> tuple[int, int | None]:
    from .animate import parse_frame_range
    try:
        return parse_frame_range(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def command_animate(args) -> int:
    cluster = _cluster(args)
    from .animate import check_pattern, frame_file
    try:
        check_pattern(args.output)
    except ValueError as error:
        raise UsageError(f"-o {error}") from None
    first = frame_file(args.output, 0)
    if args.aov and not first.lower().endswith(".exr"):
        raise UsageError(f"--aov is for EXR frames, not {args.output}{_AOV_IN_EXR}")
    if args.mp4 and not args.mp4.lower().endswith(".mp4"):
        raise UsageError(f"--mp4 {args.mp4}: the name must end in .mp4")
    if args.mp4 and args.frames:
        raise UsageError("--mp4 needs every frame: render the ranges with --frames, then run again without "
                         "--frames to encode them (frames on disk are kept)")
    _require_writable(("-o", args.output, first), folders_made=True)
    _require_writable(("--mp4", args.mp4, args.mp4))
    from .animate import render_frames, require_mp4_writer, write_mp4
    if args.mp4:
        require_mp4_writer()
    scene = _load(args)
    if scene.checked.path is None:
        raise UsageError(f"{args.scene} has no 'path' to animate (see docs/animation.md)")
    overrides = {"width": args.width, "height": args.height, "samples": args.samples, "aovs": args.aov}
    start = time.perf_counter()
    try:
        with cluster as client:
            files, rendered = render_frames(scene, args.output, args.fps, seed=args.seed, overwrite=args.overwrite,
                                            progress=not args.quiet, cluster=client, frames=args.frames,
                                            **overrides)
    except ValueError as error:
        raise UsageError(str(error)) from None
    if args.mp4:
        write_mp4(files, args.mp4, args.fps)
    if not args.quiet:
        kept = len(files) - rendered
        print(f"wrote {rendered} of {len(files)} frames ({kept} already there) to "
              f"{os.path.dirname(args.output) or '.'}{', and ' + args.mp4 if args.mp4 else ''} "
              f"({time.perf_counter() - start:.2f} s)", file=sys.stderr)
    return 0


def _bounds(text: str) -> tuple[float, ...]:
    """--bounds: six numbers XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX, checked as
    mesh.check_bounds checks them at the finest resolution and precision
    (again with the command's resolution and precision once they are known)."""
    from .arguments import MAX_RESOLUTION, parse_number
    from .mesh import check_bounds
    try:
        values = tuple(parse_number(x) for x in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 6:
        raise argparse.ArgumentTypeError(f"'{text}' is not six numbers XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX")
    try:
        check_bounds(values, MAX_RESOLUTION, True, f"'{text}'")
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return values


def command_mesh(args) -> int:
    from .mesh import FORMATS, Shells, require_scikit_image
    if not args.output.lower().endswith(FORMATS):
        raise UsageError(f"-o {args.output}: the output must end in one of {', '.join(FORMATS)}")
    shells = Shells(args.shells) if args.shells else Shells.default_for(args.output)
    if args.min_volume is not None and shells is not Shells.SOLID:
        raise UsageError("--min-volume is for --shells solid (the default for .stl): it chooses the bodies kept")
    try:
        require_scikit_image()
    except ImportError as error:
        raise UsageError(str(error)) from None
    _require_writable(("-o", args.output, args.output))
    scene = _load(args)
    from .mesh import bounds_of
    try:
        bounds_of(scene, args.bounds, args.resolution, "--bounds")
    except ValueError as error:
        raise UsageError(str(error) if args.bounds else
                         f"{error} with --bounds=XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX") from None
    start = time.perf_counter()
    try:
        mesh = scene.mesh(resolution=args.resolution, bounds=args.bounds, progress=not args.quiet)
    except ValueError as error:     # no surface inside the bounds
        raise RenderError(str(error)) from None
    removed = None
    if shells is Shells.SOLID:
        mesh, removed = mesh.solid(args.min_volume)
    mesh.save(args.output)
    if not args.quiet:
        print(f"wrote {args.output} ({len(mesh.vertices)} vertices, {len(mesh.faces)} triangles, "
              f"{time.perf_counter() - start:.2f} s)", file=sys.stderr)
        if removed is not None:
            print(f"{args.output}: {removed.summary()}", file=sys.stderr)
    return 0


def _parser() -> argparse.ArgumentParser:
    from .mesh import Shells
    parser = argparse.ArgumentParser(prog="fractalc", description="Compile and render .frac fractal scenes.")
    from . import __version__
    parser.add_argument("--version", action="version", version=f"fractalc {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def device_options(p):
        p.add_argument("--set", action="append", metavar="NAME=VALUE",
                       help="set a param (repeatable); no recompilation")
        p.add_argument("--precision", choices=("float", "double"),
                       help="arithmetic of the whole kernel (default: the file's, else float)")
        p.add_argument("--device", type=_device, help="OpenCL device: index, name substring, 'cpu' or 'gpu' "
                                        "(see 'fractalc devices'; also $FRACTALC_DEVICE)")
        p.add_argument("--lanes", help="rays per work-item: 1, 2, 4, 8 or 16 (default: the widest the "
                                       "device builds and runs, see 'fractalc devices'; also $FRACTALC_LANES)")
        p.add_argument("--verbose", action="store_true",
                       help="show the OpenCL compiler's warnings (also $FRACTALC_VERBOSE=1)")

    def key_options(p):
        p.add_argument("--render", action="append", metavar="KEY=VALUE",
                       help="a render key as in the file's render block (repeatable): ao=0.5, "
                            "max_steps=512, background=0,0,0, fog.density=0.1, glow=off")
        p.add_argument("--camera", action="append", metavar="KEY=VALUE",
                       help="a camera key (repeatable): fov=30, position=1,2,3")

    def image_options(p):
        key_options(p)
        p.add_argument("--preset", metavar="NAME", help="the param values of the file's 'preset NAME' "
                                                       "(--set still wins)")
        p.add_argument("--width", type=_option("width"))
        p.add_argument("--height", type=_option("height"))
        p.add_argument("--samples", type=_option("samples"), help="anti-aliasing samples per pixel")
        p.add_argument("--seed", type=_option("seed"), default=0, help="jitter seed for samples > 1")
        p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
        p.add_argument("--aov", type=_passes, action="extend", metavar="PASS[,PASS...]",
                       help=f"add passes to the EXR (repeatable; EXR output only): {', '.join(PASSES)} "
                            "(see docs/compositing.md)")
        farm = p.add_mutually_exclusive_group()
        farm.add_argument("--workers", type=_option("workers"), metavar="N",
                          help="render on a local Dask cluster of N processes (the 'cluster' extra; "
                               "see docs/cluster.md)")
        farm.add_argument("--cluster", metavar="ADDRESS",
                          help="render on the workers of the Dask scheduler at ADDRESS (tcp://HOST:8786)")
        device_options(p)

    render = commands.add_parser("render", help="render a scene to EXR or PNG",
                                 description="Render a scene. EXR: linear float with Z, normals and "
                                             "steps; PNG: sRGB 8-bit.")
    render.add_argument("scene")
    render.add_argument("--environment-map", metavar="FILE",
                        help="an equirectangular image (EXR, HDR, ...) as the sky: background, and light for "
                             "integrator: path (see docs/looks.md)")
    render.add_argument("--denoise", action="store_true",
                        help="denoise the colour with Intel Open Image Denoise (the 'denoise' extra; "
                             "for path-traced images, see docs/looks.md)")
    render.add_argument("-o", "--output", required=True, help="output image (.exr, .png, ...)")
    render.add_argument("--half", action="store_true", help="EXR: half-float channels (Z and P stay float)")
    render.add_argument("--compression", choices=COMPRESSIONS, help="EXR compression (default zip)")
    render.add_argument("--bits", type=_option("bits"), choices=(8, 16), default=8,
                        help="PNG: bits per channel (default 8)")
    image_options(render)
    render.set_defaults(run=command_render)

    compile_ = commands.add_parser("compile", help="write the standalone OpenCL kernel",
                                   description="Write the scene's kernel as one standalone .cl file "
                                               "(no includes; the kernel signature is documented at its top).")
    compile_.add_argument("scene")
    compile_.add_argument("-o", "--output", required=True, help="output .cl file")
    device_options(compile_)
    compile_.set_defaults(run=command_compile)

    check_ = commands.add_parser("check", help="parse and type-check a scene",
                                 description="Parse and check a scene; print every error. With --de: "
                                             "also measure how far its distance estimate can overstep "
                                             "(estimate / distance to the surface along seeded rays) and "
                                             "the step factor that is safe.")
    check_.add_argument("scene")
    check_.add_argument("--de", action="store_true",
                        help="measure the distance estimate against the surface found by fine marching")
    check_.add_argument("--rays", type=_option("rays"), default=400, help="with --de: seeded rays (default 400)")
    check_.add_argument("--seed", type=_option("seed"), default=0, help="with --de: the rays' seed")
    check_.add_argument("--surface", type=_option("surface"), default=1e-5,
                        help="with --de: the estimate, in bound radii, below which a point is on the surface "
                             "(default 1e-5; raise it for thin sets whose estimate stays above it)")
    device_options(check_)
    check_.set_defaults(run=command_check)

    bench_ = commands.add_parser("bench", help="measure frame times along a camera orbit",
                                 description="The dissertation plan's benchmark (its section 5.2): render --frames frames along an "
                                             "orbit of the camera about its target; report frame-time "
                                             "statistics, compile time and the machine. With --sweep: "
                                             "render time against error over the quality knobs "
                                             "(docs/performance.md).")
    bench_.add_argument("scene")
    bench_.add_argument("--frames", type=_option("frames"), default=30)
    bench_.add_argument("--width", type=_option("width"))
    bench_.add_argument("--height", type=_option("height"))
    bench_.add_argument("--resolution", help="1366x768, 1920x1080, 2560x1440, 3840x2160 (or 720p, 1080p, 1440p, 4k)")
    bench_.add_argument("--repeat", type=_option("repeat"),
                        help="runs of the whole path; figures are medians (default 1); "
                             "with --sweep, timed renders per row (default 5)")
    bench_.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    bench_.add_argument("--still", action="store_true",
                        help="render the file's own camera view every frame (no path, no orbit)")
    bench_.add_argument("--sweep", action="store_true",
                        help="speed against error: vary the quality knobs one at a time (and a few "
                             "combinations) and compare each render with a reference render")
    bench_.add_argument("--vary", action="append", metavar="KNOB=V[,V...]",
                        help="with --sweep: only these one-knob changes (repeatable; knobs: epsilon_scale, "
                             "max_steps, precision, fast_math, normals, overrelax, samples)")
    bench_.add_argument("--csv", metavar="FILE", help="with --sweep: also write the rows as CSV")
    bench_.add_argument("--plot", metavar="FILE.png", help="with --sweep: also plot time against error "
                                                          "(needs matplotlib)")
    bench_.add_argument("--count", action="store_true",
                        help="count distance evaluations per pixel by purpose in one render of the file's "
                             "view (an instrumented kernel), and formula iterations per evaluation")
    bench_.add_argument("--no-cache", action="store_true", help="compile the kernel even if it is cached")
    key_options(bench_)
    device_options(bench_)
    bench_.set_defaults(run=command_bench)

    view = commands.add_parser("view", help="explore a scene in a window",
                               description="Open a window on the scene: fly with W A S D Q E, drag to "
                                           "look, Tab and [ ] change params, C prints the camera, P saves "
                                           "the view, H shows every key. Saving the file reloads it. "
                                           "Needs a display and pygame (the 'view' extra).")
    view.add_argument("scene")
    view.add_argument("--width", type=_option("width"), help="window width (default: the file's render width)")
    view.add_argument("--height", type=_option("height"), help="window height (default: the file's render height)")
    view.add_argument("--preview-scale", type=_option("preview_scale"), default=2, metavar="N",
                      help="while moving, render at 1/N of the window's width and height (default 2)")
    view.add_argument("--max-samples", type=_option("max_samples"), default=64, metavar="N",
                      help="refine a still view up to this many samples per pixel (default 64)")
    view.add_argument("--output-dir", default=".", metavar="DIR", help="where P saves the view (default: here)")
    view.add_argument("--benchmark", type=_option("frames"), metavar="FRAMES",
                      help="orbit the camera for FRAMES frames, print the frame rate and exit "
                           "(SDL_VIDEODRIVER=dummy runs it without a display)")
    key_options(view)
    device_options(view)
    view.set_defaults(run=command_view)

    studio = commands.add_parser("studio", help="edit a scene beside its live image, in a web browser",
                                 description="Serve a page with the scene's text, a control for every param "
                                             "and key, its live image, presets, a timeline of keyframes and "
                                             "final renders; saving writes them into the file. Prints the "
                                             "page's address (with its token) on one line. Needs the "
                                             "'studio' extra; see docs/studio.md (and its SSH-tunnel recipe).")
    studio.add_argument("scene")
    studio.add_argument("--host", default="127.0.0.1",
                        help="the address to listen on (default 127.0.0.1: this machine only)")
    studio.add_argument("--port", type=_option("port"), help="the port (default 8765, or the next free one; 0: any)")
    studio.add_argument("--no-browser", action="store_true", help="do not open the page in a browser")
    studio.add_argument("--live-size", type=_size, metavar="WxH",
                        help="the live image's size (default: as large as the page shows it)")
    studio.add_argument("--preview-scale", type=_option("preview_scale"), default=2, metavar="N",
                        help="while anything moves, render at 1/N of the live size (default 2)")
    studio.add_argument("--max-samples", type=_option("max_samples"), default=64, metavar="N",
                        help="refine a still view up to this many samples per pixel (default 64)")
    device_options(studio)
    studio.set_defaults(run=command_studio)

    animate = commands.add_parser("animate", help="render the scene's camera path to frames",
                                  description="Render the frames of the scene's 'path' (first keyframe "
                                              "to last, at --fps). Frames already on disk are kept, so "
                                              "running it again resumes.")
    animate.add_argument("scene")
    animate.add_argument("-o", "--output", required=True,
                         help="frame files with the frame number, e.g. frames/frame_%%04d.png (.exr or .png)")
    animate.add_argument("--fps", type=_option("fps"), default=30.0, help="frames per second (default 30)")
    animate.add_argument("--mp4", metavar="FILE", help="also encode the frames as an MP4 (the 'mp4' extra)")
    animate.add_argument("--overwrite", action="store_true", help="render every frame, even those on disk")
    animate.add_argument("--frames", type=_frame_range, metavar="FIRST-LAST",
                         help="render only these frames, counted from 0: 100-199, 10- (to the end) or 5; "
                              "machines can share an animation (see docs/animation.md)")
    image_options(animate)
    animate.set_defaults(run=command_animate)

    mesh = commands.add_parser("mesh", help="export the surface as a triangle mesh (STL, PLY, OBJ)",
                               description="Sample the distance estimate on a grid over the scene's bound "
                                           "and write the surface as a watertight triangle mesh with "
                                           "vertex normals (docs/meshes.md). Needs scikit-image (the "
                                           "'mesh' extra).")
    mesh.add_argument("scene")
    mesh.add_argument("-o", "--output", required=True, help="output mesh (.stl, .ply or .obj)")
    mesh.add_argument("--resolution", type=_option("resolution"), default=256, metavar="N",
                      help="grid cells along the longest side of the bounds (default 256)")
    mesh.add_argument("--bounds", type=_bounds, metavar="XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
                      help="the box to mesh, written --bounds=-1,-1,-1,1,1,1 when it starts with a "
                           "minus (default: around the scene's bound; required for unbounded scenes)")
    mesh.add_argument("--shells", choices=[shells.value for shells in Shells],
                      help="solid: the largest body alone, its internal voids filled and loose specks "
                           "removed (the default for .stl, which printers read); all: every closed surface "
                           "(the default for .ply and .obj)")
    mesh.add_argument("--min-volume", type=_option("min_volume"), metavar="V",
                      help="with --shells solid: keep every separate body of at least this volume "
                           "(scene units cubed), not only the largest")
    mesh.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    device_options(mesh)
    mesh.set_defaults(run=command_mesh)

    devices = commands.add_parser("devices", help="list OpenCL devices, whether each builds, its lanes and speed rank",
                                  description="List the OpenCL devices with their drivers. For each CPU "
                                              "device, whether its driver builds fractalc's kernels (if "
                                              "not, the driver's first error and the fix) and the rays "
                                              "per work-item (vector lanes): the widest width its driver "
                                              "builds and runs, found by a probe in a child process and "
                                              "remembered. The default device (*) is the fastest that "
                                              "builds.")
    devices.add_argument("--probe", action="store_true", help="probe every device again")
    devices.set_defaults(run=command_devices)
    return parser


def _apply_environment_options(args) -> None:
    """--lanes and --verbose act through their environment variables (so
    that every stage, and the viewer's reloads, see them); both checked
    here, before any work."""
    from .build import VERBOSE_ENVIRONMENT
    from .lanes import ENVIRONMENT, parse_lanes
    try:
        if getattr(args, "lanes", None) is not None:
            os.environ[ENVIRONMENT] = str(parse_lanes(args.lanes, "--lanes"))
        elif os.environ.get(ENVIRONMENT):
            parse_lanes(os.environ[ENVIRONMENT], ENVIRONMENT)
    except ValueError as error:
        raise UsageError(str(error)) from None
    if getattr(args, "verbose", False):
        os.environ[VERBOSE_ENVIRONMENT] = "1"


class Terminated(BaseException):
    """SIGTERM or SIGHUP, raised wherever the program is, so that it
    unwinds through every cleanup (temporary files) as Ctrl-C does."""

    def __init__(self, number: int):
        super().__init__(number)
        self.number = number


_TERMINATING_SIGNALS = [getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n)]
# What the launcher passes on to the process doing the work (`entry`)
_FORWARDED_SIGNALS = [signal.SIGINT, *_TERMINATING_SIGNALS]


def _raise_terminated(number, frame):
    for other in _TERMINATING_SIGNALS:     # a second signal must not cut the cleanup short
        signal.signal(other, signal.SIG_IGN)
    raise Terminated(number)


def _raise_interrupted(number, frame):
    # Ctrl-C reaches this process from the terminal and again from the
    # launcher, which passes on the SIGINT sent to it: one interrupt
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise KeyboardInterrupt


@contextmanager
def _terminating_signals_raise():
    """While the command runs, SIGTERM and SIGHUP raise Terminated (a
    signal the caller ignores, as under nohup, stays ignored); under the
    launcher, SIGINT raises KeyboardInterrupt once, and the signals it
    blocked while starting this process are let in (one that came
    meanwhile is raised here)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    supervised = bool(os.environ.get(SUPERVISED_ENVIRONMENT))
    raising = {n: _raise_terminated for n in _TERMINATING_SIGNALS}
    if supervised:
        raising[signal.SIGINT] = _raise_interrupted
    previous = {n: signal.getsignal(n) for n in raising}
    for number, handler in previous.items():
        if handler in (signal.SIG_DFL, signal.default_int_handler):
            signal.signal(number, raising[number])
    try:
        if supervised and hasattr(signal, "pthread_sigmask"):
            signal.pthread_sigmask(signal.SIG_UNBLOCK, _FORWARDED_SIGNALS)
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    argv = sys.argv[1:] if argv is None else argv
    for item in argv:
        option, equals, value = item.partition("=")
        if equals and option.startswith("-") and value == "--":
            # argparse takes '--' for the end of options and gives the option an empty list
            parser.error(f"{option}=--: '--' is not a value for {option}")
    args = parser.parse_args(argv)
    if getattr(args, "no_cache", False):
        # Before OpenCL loads: the driver's and pyopencl's binary caches.
        os.environ["POCL_KERNEL_CACHE"] = "0"
        os.environ["PYOPENCL_NO_CACHE"] = "1"
    try:
        _apply_environment_options(args)
        with _terminating_signals_raise():
            return args.run(args)
    except SceneError as error:
        print(error, file=sys.stderr)
        return 2
    except UsageError as error:
        # one line: argparse's own syntax errors (an unknown option, a missing
        # -o) print its usage block; a mistake in a value or a file does not
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
    except Terminated as stop:
        print(f"fractalc: stopped by {signal.Signals(stop.number).name}", file=sys.stderr)
        return 128 + stop.number
    except Exception as error:
        from .memory import is_out_of_memory
        if not is_out_of_memory(error):
            raise
        detail = (str(error).strip().splitlines() or [""])[0]
        print(f"fractalc: error: out of memory in 'fractalc {args.command}'{': ' + detail if detail else ''}",
              file=sys.stderr)
        return 1


SUPERVISED_ENVIRONMENT = "FRACTALC_SUPERVISED"
LAUNCHER_ENVIRONMENT = "FRACTALC_LAUNCHER_PID"    # the process doing the work exits with this one
_CRASH_SIGNALS = ("SIGSEGV", "SIGBUS", "SIGILL", "SIGABRT", "SIGFPE")
PR_SET_PDEATHSIG = 1          # prctl(2): a signal for this process when its parent exits
PARENT_POLL_SECONDS = 1.0     # where prctl is missing, how often a watchdog looks for the parent


def _child_command(argv: list[str]) -> list[str]:
    return [sys.executable, "-m", "fractalc", *argv]


def _exit_with_launcher() -> None:
    """The process doing the work exits when its launcher does, even by
    kill -9 (which no handler sees): on Linux the kernel sends it SIGTERM
    then (prctl PR_SET_PDEATHSIG; SIGKILL where SIGTERM is ignored), which
    unwinds through every cleanup; elsewhere a watchdog thread polls the
    parent's pid and sends the same."""
    try:     # read once: a process this one starts has another parent
        launcher = int(os.environ.pop(LAUNCHER_ENVIRONMENT, ""))
    except ValueError:
        return
    stop = signal.SIGKILL if signal.getsignal(signal.SIGTERM) == signal.SIG_IGN else signal.SIGTERM
    if sys.platform.startswith("linux") and _parent_death_signal(stop):
        if os.getppid() != launcher:      # it exited before prctl
            os.kill(os.getpid(), stop)
        return

    def watch() -> None:
        while os.getppid() == launcher:
            time.sleep(PARENT_POLL_SECONDS)
        os.kill(os.getpid(), stop)
    threading.Thread(target=watch, name="fractalc-launcher-watchdog", daemon=True).start()


def _parent_death_signal(number: int) -> bool:
    """prctl(PR_SET_PDEATHSIG, number) through the C library; False where
    it cannot be called."""
    import ctypes
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(number), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def entry() -> int:
    """The `fractalc` command: `main` in a child process, so that a crash
    inside the OpenCL driver, which no Python code can catch, still ends in
    a one-line error that says what to do. SIGINT, SIGTERM and SIGHUP sent
    to this process (a script's `kill -INT PID`) are passed on to the
    child, which stops as at Ctrl-C; the child exits if this process is
    killed (`_exit_with_launcher`)."""
    import subprocess
    if os.environ.get(SUPERVISED_ENVIRONMENT):
        _exit_with_launcher()
        return main()
    launched: list = []

    def forward(number, frame):
        if launched and launched[0].poll() is None:
            launched[0].send_signal(number)
    # a signal this process ignores (SIGHUP under nohup) stays ignored, in the child too
    forwarded = [n for n in _FORWARDED_SIGNALS if signal.getsignal(n) != signal.SIG_IGN]
    previous = {n: signal.signal(n, forward) for n in forwarded}
    blocking = hasattr(signal, "pthread_sigmask")
    try:
        # the child starts with these blocked, and lets them in once it
        # handles them: a signal in between is neither lost nor a traceback
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, forwarded) if blocking else None
        try:
            child = subprocess.Popen(_child_command(sys.argv[1:]),
                                     env=dict(os.environ, **{SUPERVISED_ENVIRONMENT: "1",
                                                             LAUNCHER_ENVIRONMENT: str(os.getpid())}))
            launched.append(child)
        finally:
            if blocking:
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        code = child.wait()
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
    if code >= 0:
        return code
    name = signal.Signals(-code).name
    if name in _CRASH_SIGNALS:
        print(f"fractalc: error: the OpenCL driver crashed ({name}); run 'fractalc devices --probe', or set "
              "FRACTALC_LANES=8 (or 4, 1) and try again", file=sys.stderr)
        return 1
    return 128 - code


if __name__ == "__main__":
    sys.exit(main())
