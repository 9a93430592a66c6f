"""Render farms: an animation's frames, or the row tiles of one large still,
rendered by the workers of a Dask cluster (docs/cluster.md).

Only the scene's text and settings travel (`SceneSpec`): each worker
process loads the scene, opens its OpenCL device and builds the kernel
once, and keeps them for the tasks after (`_worker_scene`). A task renders
through the scene's public seam (`Scene.renderer`); an animation's frame
tasks are fractalc/animate.py's, run by `Job` and `on_worker`. Workers
return pixels; the client alone writes files, each frame atomically, as
its task finishes, so a frame is written once even when Dask reruns the
tasks of a worker that died, and an interrupted client leaves only whole
frames.
Frames and tiles equal a local render of them bit for bit on the same
kind of device: sampling is seeded per pixel of the whole frame.

Dask (the `cluster` extra) is imported only here, and only when a
cluster is used.
"""
from __future__ import annotations

import contextlib
import itertools
import logging
import os
import signal
import sys
import threading
import time
import uuid
import warnings
from collections import defaultdict
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Iterable, Iterator

import numpy as np

from .arguments import checked
from .check import check
from .drivers import building_marker
from .errors import RenderError
from .image import Image, image_from_pixels, require_image_memory
from .lanes import ENVIRONMENT, parse_lanes
from .memory import require_memory
from .parse import parse
from .passes import channels

MISSING_EXTRA = "--workers and --cluster need Dask's distributed: pip install 'fractalc[cluster]'"
# A local worker's memory before it renders: its process (145 MB resident
# after building a Mandelbulb's kernel) and its nanny's (68 MB), measured
# on Linux with PoCL; the image's memory comes on top
WORKER_BYTES = 210 * 2 ** 20
SCHEMES = ("tcp",)      # the transports fractalc reaches a scheduler by (TLS and UCX need their own setup)
TILE_ROWS = 64          # rows of a still's tile at most: a few MB per tile of a wide image
BLOCK_ROWS = 4          # tiles start on whole lane blocks (the tallest, 16 lanes, is 4 rows)
TASKS_PER_WORKER = 2    # in flight: each worker has the next task while it renders one


def installed() -> bool:
    """Whether the `cluster` extra (dask's distributed) can be imported."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


def scheduler_address(address: str) -> str:
    """`address` as Dask takes it, tcp://HOST:PORT (HOST:PORT alone is
    tcp); ValueError for another scheme or no port."""
    if not isinstance(address, str):
        raise TypeError(f"address must be a string, tcp://HOST:PORT, not {address!r}")
    scheme, separator, rest = address.partition("://")
    if not separator:
        scheme, rest = "tcp", address
    if scheme.lower() not in SCHEMES:
        raise ValueError(f"fractalc reaches a Dask scheduler by {', '.join(s + '://' for s in SCHEMES)} "
                         f"only, not {scheme}:// (give tcp://HOST:PORT)")
    host, colon, port = rest.rpartition(":")
    if not colon or not host or not (port.isascii() and port.isdigit()) or not 0 < int(port) < 65536:
        raise ValueError("the scheduler's address must be tcp://HOST:PORT, with a port from 1 to 65535")
    return f"tcp://{rest}"


def require_workers_memory(workers: int | None) -> None:
    """Refuse a local cluster whose worker processes alone need more memory
    than the machine has (RenderError naming `workers`)."""
    if workers is not None:
        require_memory(checked("workers", workers) * WORKER_BYTES, f"a local cluster of {workers} workers")


@contextlib.contextmanager
def connect(workers: int | None = None, address: str | None = None):
    """A Dask client: of a local cluster of `workers` processes (one thread
    each: a worker renders one task at a time on its device), or of the
    scheduler at `address` (tcp://HOST:PORT)."""
    if not installed():
        raise RenderError(MISSING_EXTRA)
    import distributed
    if address is not None:
        address = scheduler_address(address)
    require_workers_memory(workers)
    if address is None:
        with _ctrl_c_ignored(), warnings.catch_warnings():
            # the scheduler's HTTP routes move to a free port: no dashboard is shown anyway
            warnings.filterwarnings("ignore", message="Port 8787 is already in use")
            try:
                cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                   dashboard_address=None, silence_logs=logging.ERROR)
            except (RuntimeError, OSError, TimeoutError) as error:     # a worker that did not start
                raise RenderError(f"cannot start a local Dask cluster of {workers or 'the default'} workers: "
                                  f"{_first_line(_root_cause(error))}") from None
        with cluster, distributed.Client(cluster) as client:
            yield client
        return
    try:
        client = distributed.Client(address, timeout="10s")
    except (OSError, TimeoutError) as error:
        raise RenderError(f"cannot reach the Dask scheduler at {address}: {_first_line(error)}") from None
    with client:
        yield client


def _root_cause(error: BaseException) -> BaseException:
    """The exception at the bottom of `error`'s chain, through the causes and
    what they were raised while handling (Dask's own says 'Nanny failed to start')."""
    while (error.__cause__ or error.__context__) is not None:
        error = error.__cause__ or error.__context__
    return error


def _first_line(error: BaseException) -> str:
    """Dask's connection errors run over several lines; the first says it."""
    return (str(error).strip().splitlines() or [type(error).__name__])[0]


@contextlib.contextmanager
def _ctrl_c_ignored():
    """Worker processes started in here ignore SIGINT: Ctrl-C reaches the
    terminal's whole process group, and it is the client that stops the
    job (cancelling its tasks and closing the cluster), not each worker
    with a traceback of its own."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


# ---- what travels ----------------------------------------------------------

@dataclass(frozen=True)
class SceneSpec:
    """A scene as it travels to workers: its class (fractalc.Scene, made
    there from the checked text), text, path (for messages), params,
    precision, device choice and render settings."""
    scene_class: type
    text: str
    path: str
    params: tuple[tuple[str, float], ...]
    precision: str
    device: str | None        # None: each worker's own ($FRACTALC_DEVICE, else its first GPU)
    lanes: int | None
    render_keys: tuple[tuple[str, object], ...]


def scene_spec(scene, render_keys: dict) -> SceneSpec:
    """`scene` (a fractalc.Scene) and the render settings to send; the
    settings are checked here, before any work is sent."""
    scene.render_settings(**render_keys)
    keys = tuple((k, tuple(v) if isinstance(v, list) else v) for k, v in sorted(render_keys.items()))
    # lanes given here ($FRACTALC_LANES too) travel; otherwise each worker's device chooses
    lanes = scene.lanes or (parse_lanes(os.environ[ENVIRONMENT], ENVIRONMENT)
                            if os.environ.get(ENVIRONMENT) else None)
    return SceneSpec(type(scene), scene.checked.source, scene.checked.file, tuple(scene.params.items()),
                     scene.precision, scene.device_spec, lanes, keys)


@dataclass(frozen=True)
class Done:
    """A task's result: its value, the worker that computed it and the
    seconds it took there."""
    value: object
    worker: str
    seconds: float


# ---- on the workers ----------------------------------------------------------

_device_lock = threading.Lock()     # one render at a time per worker process: one device, one queue


@lru_cache(maxsize=8)
def _worker_scene(scene_class: type, text: str, path: str, precision: str, device: str | None, lanes: int | None):
    """The scene loaded once per worker process; it keeps its built kernels."""
    _unmark_at_exit()
    return scene_class(check(parse(text, path)), precision=precision, device=device, lanes=lanes)


@lru_cache(maxsize=1)
def _unmark_at_exit() -> None:
    """Dask's worker processes end without running atexit (multiprocessing
    children leave by os._exit), so build.py's marker of a process that
    built kernels would outlive a worker that closed normally, and the
    next fractalc process would clear the kernel cache as after a crash:
    remove it at the worker's normal exit instead."""
    from multiprocessing.util import Finalize
    marker = building_marker(os.getpid())
    Finalize(None, marker.unlink, kwargs={"missing_ok": True}, exitpriority=0)


def on_worker(spec: SceneSpec, work: Callable[[object, dict], object]) -> Done:
    """On a worker: `work(scene, render_keys)` on the spec's scene, loaded
    once per process, with the spec's params; a RenderError names the
    worker."""
    from distributed import get_worker
    with _device_lock:
        start = time.perf_counter()
        try:
            scene = _worker_scene(spec.scene_class, spec.text, spec.path, spec.precision, spec.device, spec.lanes)
            scene.set_params(dict(spec.params))
            value = work(scene, dict(spec.render_keys))
        except RenderError as error:
            message = f"{error} (on the worker at {get_worker().address})"
        else:
            return Done(value, get_worker().address, time.perf_counter() - start)
    # raised afresh, outside the handler: the OpenCL error it would chain to does not pickle
    raise RenderError(message)


def _tile_task(spec: SceneSpec, seed: int, camera, first: int, count: int) -> Done:
    """Rows `first` .. `first + count - 1` of the still, and the image's
    metadata with the first tile."""
    return on_worker(spec, lambda scene, keys: _render_tile(scene.renderer(seed, camera, **keys), first, count))


def _render_tile(renderer, first: int, count: int):
    return renderer.rows(first, count), (renderer.metadata(0.0) if first == 0 else None)


# ---- on the client -------------------------------------------------------------

def _count(n: int, unit: str) -> str:
    return f"{n} {unit}{'' if n == 1 else 's'}"


def worker_count(client) -> int:
    return max(1, len(client.nthreads()))     # worker address -> its threads


class Job:
    """Tasks sent with a bounded number in flight (so the client holds only
    a few results beyond its output), taken as they finish; one progress
    bar, and per-worker times for the summary."""

    def __init__(self, client, total: int, done_before: int, unit: str, progress: bool):
        from tqdm import tqdm
        self.client, self.unit, self.progress = client, unit, progress
        self.workers = worker_count(client)
        if progress and not client.nthreads():     # Dask holds the tasks until one joins
            print("cluster: no workers yet; waiting for one to join the scheduler", file=sys.stderr)
        self.limit = TASKS_PER_WORKER * self.workers
        self.times: dict[str, list[float]] = defaultdict(list)
        self.start = time.perf_counter()
        self.bar = tqdm(total=total, initial=done_before, unit=unit, leave=False, desc="cluster",
                        disable=not (progress and sys.stderr.isatty()))

    def run(self, tasks: Iterable[tuple[object, Callable, tuple]], take: Callable[[object, object], None]) -> None:
        """Send (tag, function, args) `tasks`; `take(tag, value)` each result
        here, in the order they finish. A task's error (a failed kernel
        build, say) cancels the rest and is raised here."""
        from distributed import as_completed
        from distributed.scheduler import KilledWorker
        pending: Iterator = iter(tasks)
        running, tags, job = as_completed(), {}, uuid.uuid4().hex

        def send_next() -> None:
            for tag, function, args in itertools.islice(pending, 1):
                future = self.client.submit(function, *args, key=f"fractalc-{tag}-{job}")
                tags[future.key] = (tag, future)
                running.add(future)

        for _ in range(self.limit):
            send_next()
        try:
            for future in running:
                tag, _ = tags.pop(future.key)
                try:
                    done = future.result()
                except KilledWorker:
                    raise RenderError(f"{self.unit} {tag}: the workers running it died each time "
                                      "(see the workers' logs)") from None
                take(tag, done.value)
                self.times[done.worker].append(done.seconds)
                self.bar.update(1)
                self.bar.set_postfix(busy=f"{min(len(tags), self.workers)}/{self.workers} workers", refresh=False)
                send_next()
        finally:
            self.client.cancel([future for _, future in tags.values()])
            self.bar.close()

    def summary(self) -> str:
        """Time per task overall and per worker."""
        elapsed = time.perf_counter() - self.start
        count = sum(len(t) for t in self.times.values())
        lines = [f"cluster: {_count(count, self.unit)} on {_count(len(self.times), 'worker')} in {elapsed:.2f} s "
                 f"({elapsed / max(count, 1):.3f} s per {self.unit})"]
        for worker, seconds in sorted(self.times.items()):
            lines.append(f"  {worker}: {_count(len(seconds), self.unit)}, {sum(seconds) / len(seconds):.3f} s each")
        return "\n".join(lines)

    def report(self) -> None:
        if self.progress:
            print(self.summary(), file=sys.stderr)


def render_still(scene, client, seed: int = 0, camera=None, progress: bool = False,
                 tile_rows: int | None = None, **render_keys) -> Image:
    """`Scene.render` of `scene` (a fractalc.Scene) on the cluster of
    `client`: tiles of `tile_rows` rows
    (default: enough tiles for 4 per worker, whole lane blocks, at most
    TILE_ROWS) rendered by its workers, assembled here into the image as
    they arrive (the client holds the image and a few tiles)."""
    if tile_rows is not None:
        tile_rows = checked("tile_rows", tile_rows)
    spec = scene_spec(scene, render_keys)
    settings = scene.render_settings(**render_keys)
    height, width = settings.height, settings.width
    require_image_memory(width, height, len(channels(settings.aovs)), path_traced=False)   # tiles arrive summed
    if tile_rows is None:
        share = -(-height // (4 * worker_count(client)))
        tile_rows = min(TILE_ROWS, -(-share // BLOCK_ROWS) * BLOCK_ROWS)
    starts = range(0, height, tile_rows)
    job = Job(client, len(starts), 0, "tile", progress)
    assembled: dict = {}

    def take(first: int, value) -> None:
        rows, metadata = value
        if "pixels" not in assembled:
            try:
                assembled["pixels"] = np.empty((height, width, rows.shape[2]), dtype=np.float32)
            except MemoryError:
                raise RenderError(f"out of memory for a {width}x{height} image") from None
        assembled["pixels"][first:first + len(rows)] = rows
        if metadata is not None:
            assembled["metadata"] = metadata

    job.run(((first, _tile_task, (spec, seed, camera, first, min(tile_rows, height - first))) for first in starts),
            take)
    job.report()
    metadata = {**assembled["metadata"], "render_seconds": f"{time.perf_counter() - job.start:.6f}"}
    return image_from_pixels(assembled["pixels"], settings.aovs, metadata)
