"""Batch rendering on a dask.distributed cluster: ``rtreflect batch ... --scheduler tcp://HOST:PORT``.

Every scene is cut into pixel spans (`render.pixel_spans`, sized by `tiling.rays_per_tile`
for one tile per task); each span is a Dask task (`render_tile`) that a worker renders
with the same `Renderer.render_span` as a local render. Results come back to this
client, which writes them in image order with the same `ImageWriter` as `rtreflect
render`, so the files are byte-identical to a local run. A window of about two tasks
per worker thread is in flight or back and waiting for an earlier tile: the cluster
stays busy, and the client holds at most that many tiles, however slow one tile is.
Dask is imported only here, only when ``--scheduler`` is given.

Workers need rtreflect (the same version: a task refuses to run otherwise) but not
the scene files: the parsed scene, geometry included, is sent to the cluster. A cluster
with no worker is an error after `WORKER_TIMEOUT` seconds; a scheduler lost mid-batch
fails each scene not finished with one line, and the batch ends normally (its summary and
report written).
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from . import __version__
from .batch import FAILED, RENDERED, Job, SceneReport, failure_reason
from .errors import RtreflectError
from .output.imagefiles import ImageWriter, open_outputs, output_paths
from .integrator.autorig import resolve
from .integrator.renderer import Renderer, pixel_spans
from .exchange.scene import Scene
from .output.streaming import overlay_for
from .integrator.tiling import default_max_memory, rays_per_tile

#: Seconds to wait for the scheduler before giving up.
CONNECT_TIMEOUT = 20
#: Seconds to wait, once connected, for a first worker: a cluster without workers would queue the tiles forever.
WORKER_TIMEOUT = 20
#: Renderers a worker keeps built (tessellation + BVH), most recently used first.
CACHED_RENDERERS = 4
#: Characters of the lost connection's message kept in each failed scene's one line (Dask's are long).
LOST_DETAIL = 100
#: Tile tasks in flight per worker thread.
TASKS_PER_THREAD = 2

_cache_lock = threading.Lock()
_build_locks: dict[str, threading.Lock] = {}
_renderers: OrderedDict[str, Renderer] = OrderedDict()




def _renderer(scene: Scene, key: str) -> Renderer:
    """This worker's `Renderer` for the scene, built by the first of its tasks and shared by the others."""
    with _cache_lock:
        if key in _renderers:
            _renderers.move_to_end(key)
            return _renderers[key]
        build_lock = _build_locks.setdefault(key, threading.Lock())
    with build_lock:  # concurrent tiles of one scene wait for one build; other scenes build in parallel
        with _cache_lock:
            if key in _renderers:
                return _renderers[key]
        renderer = Renderer(scene)
        with _cache_lock:
            _renderers[key] = renderer
            _build_locks.pop(key, None)
            while len(_renderers) > CACHED_RENDERERS:
                _renderers.popitem(last=False)
        return renderer


def render_tile(scene: Scene, key: str, start: int, stop: int, client_version: str) -> tuple[np.ndarray, int, int]:
    """A Dask task: pixels [start, stop) of the scene as (P, 22) float32, with ray and Newton-fallback counts."""
    if client_version != __version__:
        raise RtreflectError(f"worker runs rtreflect {__version__} but the client {client_version}: "
                             "install the same version everywhere (outputs would differ)")
    try:
        tile = _renderer(scene, key).render_span(start, stop)
    except RtreflectError as exc:
        raise RtreflectError(str(exc)) from None  # a plain one-argument error travels back intact
    return tile.pixels, tile.rays, tile.fallbacks


def _task_error(future) -> BaseException:
    """Why a tile task did not finish: its exception, or the cancellation (worker or scheduler lost)."""
    try:
        return future.exception() or RuntimeError(f"task {future.status}")
    except Exception as exc:  # a cancelled future raises instead of returning its exception
        return exc


@dataclass
class _SceneRun:
    """The client's state of one scene: spans to submit, the open writer, tiles waiting for their turn."""

    job: Job
    spans: list[tuple[int, int]]
    submitted: int = 0
    written: int = 0
    waiting: dict[int, tuple[np.ndarray, int]] = field(default_factory=dict)  # span index → (pixels, rays)
    outputs: contextlib.ExitStack | None = None
    writer: ImageWriter | None = None
    scattered: Any = None
    futures: set = field(default_factory=set)
    started: float = 0.0
    rays: int = 0
    extra_files: dict[str, str] | None = None  # the contours JSON of an overlay


def run_on_cluster(address: str, jobs: list[Job], outdir: Path, *, max_memory: int | None,
                   on_progress: Callable[[int], None], on_done: Callable[[SceneReport], None]) -> None:
    """Render ``jobs`` on the Dask cluster at ``address``; ``on_done`` as each scene's files are in place.

    Raises `RtreflectError` when dask.distributed is missing or the scheduler cannot
    be reached; on Ctrl-C cancels the tasks, removes the files being written and
    re-raises KeyboardInterrupt.
    """
    try:
        import distributed
    except ImportError:
        raise RtreflectError("--scheduler needs dask.distributed: pip install 'rtreflect[dask]'") from None
    try:
        client = distributed.Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise RtreflectError(f"--scheduler {address}: cannot connect ({' '.join(str(exc).split()) or type(exc).__name__})") from None
    # Dask logs a lost scheduler with multi-line tracebacks on stderr (its loggers have their own levels, and
    # propagate to the handler on "distributed"); the batch reports it per scene instead.
    handlers = [h for h in logging.getLogger("distributed").handlers if h.level <= logging.CRITICAL]
    levels = [h.level for h in handlers]
    for handler in handlers:
        handler.setLevel(logging.CRITICAL + 1)
    try:
        try:
            client.wait_for_workers(1, timeout=WORKER_TIMEOUT)
        except Exception:  # TimeoutError, or the scheduler went away meanwhile
            raise RtreflectError(f"--scheduler {address}: no worker connected within {WORKER_TIMEOUT} s "
                                 f"(start workers with: dask worker {address})") from None
        _ClusterBatch(client, distributed, jobs, Path(outdir), max_memory or default_max_memory(),
                      on_progress, on_done, address).run()
    finally:
        with contextlib.suppress(Exception):  # a lost scheduler cannot be said goodbye to
            client.close(timeout=5)
        for handler, level in zip(handlers, levels):
            handler.setLevel(level)


class _ClusterLost(Exception):
    """The connection to the scheduler is gone: no scene can go on."""


class _ClusterBatch:
    def __init__(self, client, distributed, jobs, outdir, max_memory, on_progress, on_done, address=""):
        self.client, self.distributed, self.address = client, distributed, address
        self.outdir, self.max_memory = outdir, max_memory
        self.on_progress, self.on_done = on_progress, on_done
        self.queue = list(jobs)
        self.active: list[_SceneRun] = []
        self.owner: dict[Any, tuple[_SceneRun, int]] = {}
        threads = sum(client.nthreads().values()) or 1
        self.window = max(2, TASKS_PER_THREAD * threads)

    def run(self) -> None:
        """Every job to its files or a failed report; a lost cluster fails the scenes left, each with one line."""
        tasks = self.distributed.as_completed(loop=self.client.loop)
        try:
            self._fill(tasks)
            for future in tasks:
                owner = self.owner.pop(future, None)
                if owner is None:  # a tile of a scene that already failed
                    continue
                run, index = owner
                run.futures.discard(future)
                if future.status == "finished":
                    try:
                        pixels, rays, _ = future.result()
                    except self.distributed.comm.CommClosedError as exc:
                        # The scheduler died between the tile's end and the fetch of its result: the client may
                        # still say "running" for a moment, so this is the cluster lost, not a scene's failure.
                        raise _ClusterLost(exc) from exc
                    # Dask may hand back an array inside its message buffer, not aligned for float32, which
                    # OpenImageIO refuses ("buffer is wrong size"): copied then, else used as is.
                    run.waiting[index] = (np.require(pixels, np.float32, ["C", "A"]), rays)
                    self._write_ready(run)
                elif run in self.active:
                    error = _task_error(future)
                    if self.client.status != "running":
                        raise _ClusterLost(error)
                    self._fail(run, error)
                del future  # release the result on the cluster
                self._fill(tasks)
        except (KeyboardInterrupt, RtreflectError) as exc:
            self._abandon_all()
            raise
        except BaseException as exc:
            if isinstance(exc, Exception) and (isinstance(exc, _ClusterLost) or self.client.status != "running"):
                self._lost(exc.args[0] if isinstance(exc, _ClusterLost) else exc)
                return
            self._abandon_all()
            raise

    def _abandon_all(self) -> None:
        with contextlib.suppress(Exception):
            self.client.cancel(list(self.owner))
        for run in list(self.active):
            self._close(run, failed=True)

    def _lost(self, cause: BaseException) -> None:
        """The scheduler is gone: each scene not finished fails with one line (partial files removed); the batch
        then ends normally, so its summary and report are written."""
        detail = " ".join(str(cause).split())
        detail = f"{type(cause).__name__}: {detail[:LOST_DETAIL]}" if detail else type(cause).__name__
        error = RtreflectError(f"--scheduler {self.address}: lost the connection to the cluster ({detail})")
        self.owner.clear()
        for run in list(self.active):
            self._close(run, failed=True)
            self._report_failure(run, error)
        while self.queue:
            job = self.queue.pop(0)
            self._report_failure(_SceneRun(job, [], started=time.perf_counter()), error)

    def _fill(self, tasks) -> None:
        """Submit tiles, scene after scene, until the window is full.

        The window counts the tiles that came back but wait for an earlier one to be written, not only
        those in flight: with one slow tile first, the client would otherwise hold every other tile of
        the image. No deadlock: each scene's tiles are submitted in order, so its next tile to write is
        always in flight or back already.
        """
        while len(self.owner) + sum(len(run.waiting) for run in self.active) < self.window:
            run = next((r for r in self.active if r.submitted < len(r.spans)), None) or self._start_next()
            if run is None:
                return
            start, stop = run.spans[run.submitted]
            future = self.client.submit(render_tile, run.scattered, run.job.scene.output_key, start, stop,
                                        __version__, pure=False)
            self.owner[future] = (run, run.submitted)
            run.futures.add(future)
            run.submitted += 1
            tasks.add(future)

    def _start_next(self) -> _SceneRun | None:
        """The next scene whose tiles can be submitted: tiles planned, outputs opened, scene sent to the cluster."""
        while self.queue:
            job = self.queue.pop(0)
            run = _SceneRun(job, [], started=time.perf_counter())
            try:
                job.scene = resolve(job.scene)  # the automatic rig chosen once, here, for every worker's tiles
                run.spans = pixel_spans(job.scene.image, rays_per_tile(job.scene, self.max_memory, 1))
                run.outputs = contextlib.ExitStack()
                png_filter, run.extra_files = overlay_for(job.scene)  # drawn by the client, as locally
                run.writer = run.outputs.enter_context(open_outputs(job.scene, self.outdir, png_filter, run.extra_files))
            except RtreflectError as exc:
                self._report_failure(run, exc)
                continue
            self.active.append(run)  # before the scatter: a cluster lost during it fails this scene too
            run.scattered = self.client.scatter(job.scene, hash=False)
            return run
        return None

    def _write_ready(self, run: _SceneRun) -> None:
        """Write the tiles that are next in image order; finish the scene after its last."""
        try:
            while run.written in run.waiting:
                pixels, rays = run.waiting.pop(run.written)
                start = run.spans[run.written][0]
                run.writer.write(start, pixels)
                run.rays += rays
                run.written += 1
                self.on_progress(len(pixels))
            if run.written == len(run.spans):
                self._close(run, failed=False)
                scene = run.job.scene
                self.on_done(SceneReport(str(run.job.path), scene.output.name, RENDERED,
                                         seconds=time.perf_counter() - run.started,
                                         outputs=[str(p) for p in output_paths(scene, self.outdir, run.extra_files)],
                                         pixels=scene.image.width * scene.image.height, rays=run.rays,
                                         tiles=len(run.spans)))
        except RtreflectError as exc:
            self._fail(run, exc)

    def _fail(self, run: _SceneRun, exc: BaseException) -> None:
        """One scene failed: cancel its other tiles, remove its partial files, report; the batch goes on."""
        pending = [f for f in run.futures if f in self.owner]
        for future in pending:
            self.owner.pop(future, None)
        if pending:
            self.client.cancel(pending)
        self._close(run, failed=True)
        self._report_failure(run, exc)

    def _report_failure(self, run: _SceneRun, exc: BaseException) -> None:
        self.on_done(SceneReport(str(run.job.path), run.job.scene.output.name, FAILED,
                                 seconds=time.perf_counter() - run.started, error=failure_reason(exc)))

    def _close(self, run: _SceneRun, failed: bool) -> None:
        """Rename the finished files into place, or (failed) remove the temporaries."""
        if run in self.active:
            self.active.remove(run)
        outputs, run.outputs, run.scattered, run.waiting = run.outputs, None, None, {}
        if outputs is None:
            return
        if failed:
            with contextlib.suppress(BaseException):
                outputs.__exit__(RtreflectError, RtreflectError("scene failed"), None)
        else:
            outputs.close()
