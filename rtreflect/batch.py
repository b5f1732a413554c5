"""Batch rendering: folders of scenes, each to ``OUTDIR/NAME.exr|.png``, in parallel, resumable.

The flow is one way: `discover` scene files → `load_jobs` (a scene that cannot be read
becomes a failed job, not an abort) → `check_collisions` (two scenes writing the same
NAME stop the batch before anything renders) → `plan` (skip scenes whose outputs are up
to date) → a runner: `run_local` (a process pool on this machine) or
`rtreflect.cluster.run_on_cluster` (a Dask cluster). Runners report each scene as it
finishes through callbacks; `summary_table` and `write_report` turn the reports into
the closing table and the ``--json`` file.

Up to date means: every output the scene asks for exists and records, in its header
(EXR attribute or PNG text chunk), the same `rtreflect:inputs_sha256` (scene file plus
geometry files) and `rtreflect:version` as this run would write.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing
import multiprocessing.connection
import os
import queue
import signal
import time
import traceback
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

from . import __version__
from .errors import RtreflectError, error_lines
from .output.imagefiles import (OUTPUT_KEY_ATTRIBUTE, VERSION_ATTRIBUTE, check_distinct_outputs, output_paths, read_provenance,
                         write_json)
from .analysis.overlay import contours_file_name
from .exchange.cad import CAD_SUFFIXES
from .output.sharing import remove_dead_temporaries
from .exchange.load import load_scene
from .exchange.partscene import format_qualified_name
from .exchange.scene import Scene
from .integrator.tiling import default_max_memory

#: What a folder is searched for: scene files, and CAD files (each rendered in the default scene around the part).
SCENE_SUFFIXES = (".toml", *CAD_SUFFIXES)
RENDERED, SKIPPED, FAILED, INTERRUPTED = "rendered", "skipped", "failed", "interrupted"
#: A pool worker's message that it started a scene: (STARTED, pid, scene path).
STARTED = "started"


@dataclass
class Job:
    """One scene file of the batch: its parsed scene, or the one-line reason it could not be read."""

    path: Path
    scene: Scene | None = None
    error: str | None = None


@dataclass
class SceneReport:
    """One row of the summary (and of the ``--json`` report)."""

    scene: str  # the scene file
    name: str | None  # [output] name (None if the file could not be read)
    status: str  # rendered | skipped | failed | interrupted
    seconds: float = 0.0
    outputs: list[str] = field(default_factory=list)
    error: str | None = None
    pixels: int = 0
    rays: int = 0
    tiles: int = 0
    validate: dict | None = None  # `--validate`: rtreflect.ci.checks.validate_record
    golden: dict | None = None  # `--golden DIR`: rtreflect.ci.checks.golden_record
    warnings: list[str] = field(default_factory=list)  # `checks.ImageTally` warnings of the rendered picture
    rig: list[str] = field(default_factory=list)  # the automatic camera and tubes chosen (`Scene.rig`)
    continuity: dict | None = None  # `--continuity`: rtreflect.ci.checks.continuity_record


# -- discovery and planning -------------------------------------------------------------
def discover(paths: list[Path], recursive: bool = False) -> list[Path]:
    """Scene files named by ``paths``: files as given, folders searched for ``*.toml`` (sub-folders with ``recursive``).

    Each file appears once, in the order given (folders sorted); a path that does not
    exist, or no scene file at all, is an `RtreflectError`. "Once" is by the path as named
    (made absolute, symlinks not followed): outputs are named after each file's stem, so a
    symlink ``current.toml -> v3.toml`` is a scene of its own, writing ``current.*``.
    """
    found: list[Path] = []
    seen: set[Path] = set()
    for path in paths:
        path = Path(path)
        if path.is_dir():
            pattern = "**/*" if recursive else "*"
            files = sorted(p for p in path.glob(pattern) if p.suffix.lower() in SCENE_SUFFIXES and p.is_file())
        elif path.exists():
            files = [path]
        else:
            raise RtreflectError(f"{path}: no such file or folder")
        for file in files:
            key = Path(os.path.abspath(file))  # not resolve(): a symlink's stem names its own outputs
            if key not in seen:
                seen.add(key)
                found.append(file)
    if not found:
        where = ", ".join(str(p) for p in paths)
        raise RtreflectError(f"{where}: no scene or CAD files ({', '.join('*' + s for s in SCENE_SUFFIXES)}) found"
                             + ("" if recursive else "; use --recursive for sub-folders"))
    return found


def load_jobs(files: list[Path], skip_bad_faces: bool = False) -> list[Job]:
    jobs = []
    for file in files:
        try:
            jobs.append(Job(file, scene=load_scene(file, skip_bad_faces)))
        except RtreflectError as exc:
            jobs.append(Job(file, error="; ".join(error_lines(exc))))  # every problem of the file, on one line
    return name_parts_apart(jobs)


def name_parts_apart(jobs: list[Job]) -> list[Job]:
    """CAD files rendered in their default scene whose stems coincide (``block.step`` beside ``block.igs``): each
    named with its format (``block_step``, `format_qualified_name`) rather than refused as colliding outputs.

    Only names nobody chose change: a scene file's ``[output] name`` (or stem) stays, and still collides.
    """
    stems: dict[str, int] = {}
    for job in jobs:
        if job.scene is not None:
            stems[job.scene.output.name] = stems.get(job.scene.output.name, 0) + 1
    for job in jobs:
        scene = job.scene
        if scene is not None and Path(job.path).suffix.lower() in CAD_SUFFIXES and stems[scene.output.name] > 1:
            job.scene = replace(scene, output=replace(scene.output, name=format_qualified_name(Path(job.path))))
    return jobs


def check_collisions(jobs: list[Job], outdir: Path) -> None:
    """Scenes that load and share an `[output] name`: an `RtreflectError` naming them (`check_distinct_outputs`)."""
    check_distinct_outputs([job.scene for job in jobs if job.scene is not None], outdir)


def up_to_date(scene: Scene, outdir: Path) -> bool:
    """Every output exists and was rendered from the same inputs (scene and geometry files) with the same size,
    samples, normals and overlay, by this version."""
    for path in output_paths(scene, outdir):
        if not path.is_file():
            return False
        header = read_provenance(path)
        if header.get(OUTPUT_KEY_ATTRIBUTE) != scene.output_key or header.get(VERSION_ATTRIBUTE) != __version__:
            return False
    return not scene.render.overlay or (Path(outdir) / contours_file_name(scene)).is_file()


def plan(jobs: list[Job], outdir: Path, force: bool = False) -> tuple[list[Job], list[SceneReport]]:
    """Jobs to render, and reports for the rest: unreadable scenes (failed) and up-to-date ones (skipped)."""
    todo, settled = [], []
    for job in jobs:
        if job.scene is None:
            settled.append(SceneReport(str(job.path), None, FAILED, error=job.error))
        elif not force and up_to_date(job.scene, outdir):
            settled.append(SceneReport(str(job.path), job.scene.output.name, SKIPPED,
                                       outputs=[str(p) for p in output_paths(job.scene, outdir)]))
        else:
            todo.append(job)
    return todo, settled


def failure_reason(exc: BaseException) -> str:
    """One line for the summary: the user's error as is, anything else as an internal error with its type."""
    if isinstance(exc, RtreflectError):
        return str(exc)
    text = " ".join(str(exc).split()) or "no message"
    return f"internal error: {type(exc).__name__}: {text}"


# -- one scene (this process or a pool worker) -------------------------------------------
def render_job(scene: Scene, outdir: Path, threads: int | None, max_memory: int | None,
               progress: Callable[[int], None] | None = None, remove_dead: bool = True) -> SceneReport:
    """Render one scene to its files (`streaming.render_to_files`); failures become a failed report, not an exception.

    ``remove_dead``: as in `imagefiles.prepare_output_folder`.
    """
    from .output.streaming import render_to_files

    start = time.perf_counter()
    report = SceneReport(str(scene.path), scene.output.name, RENDERED)
    try:
        done = render_to_files(scene, outdir, threads=threads, max_memory=max_memory, progress=progress,
                               remove_dead=remove_dead)
    except Exception as exc:  # failure isolation: one scene's error must not stop the batch
        report.status, report.error = FAILED, failure_reason(exc)
        if not isinstance(exc, RtreflectError) and os.environ.get("RTREFLECT_DEBUG"):
            traceback.print_exc()
    else:
        report.outputs = [str(p) for p in done.files]
        report.pixels = scene.image.width * scene.image.height
        report.rays, report.tiles = done.stats.rays, done.stats.tiles
        report.warnings = list(done.warnings)
        report.rig = list(done.scene.rig)
    report.seconds = time.perf_counter() - start
    return report


# Pool workers: progress goes back through a queue; SIGTERM (sent by the parent on Ctrl-C)
# unwinds the render so its temporary files are removed, then ends the process.
_progress_queue = None
_busy = False


class _Terminated(BaseException):
    """Raised in a worker by SIGTERM while it renders (BaseException: no `except Exception` swallows it)."""


def _on_sigterm(signum, frame) -> None:
    if _busy:
        raise _Terminated
    os._exit(128 + signum)


def _worker_init(progress_queue) -> None:
    global _progress_queue
    _progress_queue = progress_queue
    # A worker killed while its queue thread wrote a message holds the queue's write lock for good: every other
    # worker's messages then wait in its buffer, and at exit it would wait for them (joining that thread) for ever,
    # and the pool's shutdown with it (a -j 2 batch hung after a SIGKILL, its results printed). Messages still
    # buffered at exit are dropped instead: they are progress, and the STARTED one went out long before.
    progress_queue.cancel_join_thread()
    # One core per worker: without this each worker's OpenImageIO/OpenEXR pool would compress
    # on every core too, and the -j workers would crowd each other.
    import OpenImageIO as oiio

    oiio.attribute("threads", 1)
    oiio.attribute("exr_threads", 1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    signal.signal(signal.SIGTERM, _on_sigterm)


def _worker_render(scene: Scene, outdir: Path, max_memory: int | None) -> SceneReport:
    global _busy
    _busy = True
    # Which process renders which scene: if this one dies, the parent knows the scene it took along.
    _progress_queue.put((STARTED, os.getpid(), str(scene.path)))
    try:
        # No sweep of dead runs' temporaries here: the parent swept the folder before the pool started, and a
        # sibling worker killed just now is the parent's to clean up and report (`settle`). A worker that swept
        # it first (a zombie counts as dead) would leave the parent nothing to remove and the removal unsaid.
        return render_job(scene, outdir, 1, max_memory, progress=_progress_queue.put, remove_dead=False)
    except _Terminated:
        os._exit(128 + signal.SIGTERM)  # the temporaries were removed while unwinding
    finally:
        _busy = False


# -- the local runner --------------------------------------------------------------------
#: How long to wait for a dead worker's exit code to be stored: the executor's thread stores it right after
#: reaping the process; a worker still running after this is reported as such (None).
EXIT_CODE_WAIT = 5.0


def exit_code(process: multiprocessing.Process, timeout: float = EXIT_CODE_WAIT) -> int | None:
    """The exit code of a pool worker that has ended, None while it runs (after ``timeout`` seconds).

    The executor's own thread reaps a dead worker too (it joins every worker of a broken pool). When it
    wins that race, our waitpid fails (ECHILD) and `Process.exitcode` reads None until that thread has
    stored the code in the same process object, a moment later; read as None, a SIGKILLed worker's scene
    was retried like a bystander's. So: wait for the process's sentinel (readable once it has ended, who
    ever reaps it), then for the code.
    """
    deadline = time.monotonic() + timeout
    if not multiprocessing.connection.wait([process.sentinel], timeout):
        return None  # still running
    while (code := process.exitcode) is None and time.monotonic() < deadline:
        time.sleep(0.01)
    return code


def default_jobs() -> int:
    """The cores this process may run on (its CPU affinity where the system tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0)) or 1
    return os.cpu_count() or 1


def run_local(jobs: list[Job], outdir: Path, *, workers: int, max_memory: int | None,
              on_progress: Callable[[int], None], on_done: Callable[[SceneReport], None]) -> None:
    """Render ``jobs`` on this machine, ``workers`` scenes at a time, calling ``on_done`` as each finishes.

    One worker (or one scene): rendered here, with the usual render threads. More:
    a pool of spawned processes, each rendering one scene at a time with one thread and
    ``max_memory / workers`` of working memory. On Ctrl-C the workers are terminated
    (their temporary files removed) and KeyboardInterrupt propagates.
    """
    workers = max(1, min(workers, len(jobs)))
    if workers == 1:
        for job in jobs:
            on_done(render_job(job.scene, outdir, None, max_memory, progress=on_progress))
        return
    per_worker = (max_memory or default_max_memory()) // workers
    # Spawned, not forked: workers start clean (no inherited threads or Embree state) and behave alike on all systems.
    context = multiprocessing.get_context("spawn")
    waiting = list(reversed(jobs))  # popped from the end: scenes start in the given order
    attempts: dict[int, int] = {}
    started: dict[str, int] = {}  # scene path → PID of the worker that took it
    processes: dict[int, multiprocessing.Process] = {}  # every worker seen, by PID, for its exit code

    def died(job: Job) -> str | None:
        """How the worker that rendered ``job`` ended, when it died on its own (a signal, not the pool's SIGTERM)."""
        process = processes.get(started.get(str(job.path), -1))
        if process is None:
            return None
        code = exit_code(process)
        if code is None or code >= 0 or code == -signal.SIGTERM:
            return None  # still running, exited, or stopped by the pool after another worker died
        with contextlib.suppress(ValueError):
            return signal.Signals(-code).name
        return f"signal {-code}"

    def settle(job: Job, future: cf.Future) -> bool:
        """Report a finished scene; True when its worker died (the pool is then broken)."""
        try:
            on_done(future.result())
            return False
        except cf.process.BrokenProcessPool:
            _drain(progress_queue, on_progress, started)
            # A worker died (killed, out of memory, crashed) and took every scene in flight with it.
            # The scene whose own worker was killed fails (it may well kill the next one too); the others
            # are tried again once in a fresh pool, and a scene in flight at two deaths is reported failed.
            how = died(job)
            attempts[id(job)] = attempts.get(id(job), 0) + 1
            # Its worker's temporaries, once that worker is dead (workers leave each other's alone: _worker_render).
            pid = started.get(str(job.path))
            removed = remove_dead_temporaries(outdir, pid) if pid is not None else []
            if how is not None or attempts[id(job)] >= 2:
                cleanup = f"; removed its {len(removed)} temporary file{'s' * (len(removed) != 1)}" if removed else ""
                cause = f" (PID {pid}) was killed by {how}" if how else " died"
                on_done(SceneReport(str(job.path), job.scene.output.name, FAILED,
                                    error=f"{job.path}: the worker process rendering it{cause} "
                                          f"(out of memory? see --max-memory){cleanup}"))
            else:
                waiting.append(job)
            return True

    while waiting:
        # A queue per pool: one whose write lock a killed worker took along (`_worker_init`) passes no more messages.
        progress_queue = context.Queue()
        pool = cf.ProcessPoolExecutor(workers, mp_context=context, initializer=_worker_init, initargs=(progress_queue,))
        running: dict[cf.Future, Job] = {}
        broken = False
        try:
            while (waiting or running) and not broken:
                while waiting and len(running) < workers and not broken:
                    job = waiting.pop()
                    try:
                        running[pool.submit(_worker_render, job.scene, outdir, per_worker)] = job
                    except cf.process.BrokenProcessPool:
                        waiting.append(job)
                        broken = True
                processes.update(getattr(pool, "_processes", None) or {})  # no public API before Python 3.14
                finished, _ = cf.wait(running, timeout=0.2, return_when=cf.FIRST_COMPLETED)
                _drain(progress_queue, on_progress, started)
                for future in finished:
                    broken |= settle(running.pop(future), future)
            if broken:  # a broken pool fails all its futures at once
                for future in cf.wait(running)[0]:
                    settle(running.pop(future), future)
        except BaseException:  # Ctrl-C (or a failing callback): stop the workers, their temporaries removed
            _terminate(pool)
            # Joined, not left running (the workers are gone, so it ends at once): a manager thread still alive at
            # exit made the interpreter's shutdown write to its closed wake-up pipe ("Bad file descriptor" traceback).
            pool.shutdown(wait=True, cancel_futures=True)
            # A worker that SIGTERM found inside a C call (an image being written) may not unwind before it is killed:
            # its temporaries are removed here, now that it is dead (a full test run left a worker's .exr and .png).
            processes.update(getattr(pool, "_processes", None) or {})
            for pid in processes:
                remove_dead_temporaries(outdir, pid)
            raise
        pool.shutdown(wait=True)
        _drain(progress_queue, on_progress, started)


def _drain(progress_queue, on_progress: Callable[[int], None], started: dict[str, int]) -> None:
    """Hand the workers' messages on: pixels done to ``on_progress``, (STARTED, pid, scene) into ``started``."""
    while True:
        try:
            message = progress_queue.get_nowait()
        except queue.Empty:
            return
        if isinstance(message, tuple) and message[0] == STARTED:
            started[message[2]] = message[1]
        else:
            on_progress(message)


def _terminate(pool: cf.ProcessPoolExecutor) -> None:
    """SIGTERM every worker and wait for it: each removes its temporary files and exits."""
    processes = list(getattr(pool, "_processes", {}).values())  # no public API before Python 3.14
    for process in processes:
        if process.is_alive():
            process.terminate()
    for process in processes:
        process.join(timeout=10)
        if process.is_alive():
            process.kill()


# -- summary -----------------------------------------------------------------------------
def summary_table(reports: list[SceneReport]) -> str:
    """A plain-text table: scene, status, seconds, output files (or the failure reason)."""
    rows = [("scene", "status", "seconds", "outputs")]
    for r in reports:
        detail = r.error if r.status == FAILED else ", ".join(r.outputs)
        seconds = f"{r.seconds:.2f}" if r.status in (RENDERED, FAILED) and r.seconds else "-"
        rows.append((r.scene, r.status, seconds, detail or "-"))
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    return "\n".join(f"{a:<{widths[0]}}  {b:<{widths[1]}}  {c:>{widths[2]}}  {d}".rstrip() for a, b, c, d in rows)


def counts(reports: list[SceneReport]) -> dict[str, int]:
    return {status: sum(r.status == status for r in reports) for status in (RENDERED, SKIPPED, FAILED, INTERRUPTED)}


def write_report(path: Path, reports: list[SceneReport], outdir: Path, seconds: float, where: str) -> None:
    """The summary as JSON (written atomically): totals and one record per scene."""
    document = {"rtreflect_version": __version__, "outdir": str(outdir), "where": where,
                "seconds": round(seconds, 3), "counts": counts(reports), "scenes": [asdict(r) for r in reports]}
    write_json(path, document)
