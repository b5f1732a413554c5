"""Batch rendering and streamed (tiled) output.

The references are independent of the code under test: outputs are compared byte for
byte with an in-memory render (`Renderer.render` → one `Film` → `save_render`), which
shares no tiling, scheduling or streaming with `batch`, the process pool or the Dask
path. Resumability is judged by file modification times and the JSON report; an
interrupt by what is left in the output folder.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from rtreflect import batch as batching
from rtreflect.cli import cli
from rtreflect.integrator.film import CHANNELS
from rtreflect.output.imagefiles import ImageWriter, open_outputs, read_image, read_provenance, save_render
from rtreflect.integrator.renderer import Renderer
from rtreflect.exchange.scene import load_scene
from rtreflect.output.streaming import render_to_files

SCENES = Path(__file__).resolve().parent.parent / "scenes"
RTREFLECT = Path(sys.executable).parent / "rtreflect"


def small_scene(source: str, dest: Path, width: int = 160, height: int = 90, samples: int = 1, **output) -> Path:
    """A copy of a shipped scene with its [image] table set (and [output] values appended)."""
    text = (SCENES / f"{source}.toml").read_text()
    for key, value in (("width", width), ("height", height), ("samples", samples)):
        text, n = re.subn(rf"(?m)^{key} = .*$", f"{key} = {value}", text, count=1)
        assert n == 1, f"{source}.toml has no [image] {key}"
    if output:
        assert "[output]" not in text
        text += "\n[output]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in output.items())
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(text)
    if "teapot.bpt" in text:
        shutil.copy(SCENES / "teapot.bpt", dest.parent / "teapot.bpt")
    return dest


def reference_files(scene_path: Path, outdir: Path) -> dict[str, bytes]:
    """The scene rendered in memory, untiled (one tile), and saved: the bytes every other path must reproduce."""
    scene = load_scene(scene_path)
    result = Renderer(scene).render(rays_per_tile=1 << 40)
    return {p.name: p.read_bytes() for p in save_render(result, outdir)}


def folder_bytes(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.suffix in (".exr", ".png")}


@pytest.fixture(scope="module")
def scene_folder(tmp_path_factory) -> Path:
    """Three small scenes and a broken one."""
    folder = tmp_path_factory.mktemp("scenes")
    small_scene("hood", folder / "hood.toml")
    small_scene("cylinder", folder / "cylinder.toml", samples=2)
    small_scene("teapot", folder / "teapot.toml")
    (folder / "broken.toml").write_text((SCENES / "hood.toml").read_text().replace("radius", "radios", 1))
    return folder


@pytest.fixture(scope="module")
def references(scene_folder, tmp_path_factory) -> dict[str, bytes]:
    outdir = tmp_path_factory.mktemp("reference")
    files = {}
    for name in ("hood", "cylinder", "teapot"):
        files.update(reference_files(scene_folder / f"{name}.toml", outdir))
    return files


def run_batch(*args) -> tuple[int, str, dict | None]:
    report = None
    result = CliRunner().invoke(cli, ["batch", *map(str, args)])
    if "--json" in args:
        path = Path(args[list(args).index("--json") + 1])
        report = json.loads(path.read_text()) if path.exists() else None
    return result.exit_code, result.output, report


def by_name(report: dict) -> dict[str, dict]:
    return {Path(s["scene"]).stem: s for s in report["scenes"]}


# -- streaming ---------------------------------------------------------------------------------
@pytest.mark.parametrize("samples", [1, 2])
def test_streamed_render_equals_in_memory_render(tmp_path, samples):
    """Tiles of a few dozen pixels (starting and ending mid-row) written as they finish give the same bytes."""
    scene_path = small_scene("g1_join", tmp_path / "g1.toml", width=97, height=31, samples=samples)
    expected = reference_files(scene_path, tmp_path / "memory")
    # About 1 MB when pixels had 17 channels; scaled with the channel count so the budget cuts as many tiles.
    budget = 1_000_000 * len(CHANNELS) // 17
    done = render_to_files(load_scene(scene_path), tmp_path / "streamed", threads=2, max_memory=budget)
    assert done.stats.tiles > 10  # the budget really cut the image into many spans
    assert folder_bytes(tmp_path / "streamed") == expected
    pixels, channels, attrs = read_image(tmp_path / "streamed" / "g1.exr")
    assert sorted(channels) == sorted(CHANNELS) and attrs["rtreflect:inputs_sha256"] == load_scene(scene_path).inputs_sha256


def test_writer_refuses_incomplete_image_and_leaves_nothing(tmp_path):
    scene = load_scene(small_scene("hood", tmp_path / "hood.toml", width=20, height=10))
    with pytest.raises(Exception, match="stopped at pixel 150 of 200"):
        with open_outputs(scene, tmp_path / "out") as writer:
            writer.write(0, np.zeros((150, len(CHANNELS)), dtype=np.float32))
    with pytest.raises(ValueError, match="in order"):
        with open_outputs(scene, tmp_path / "out") as writer:
            assert isinstance(writer, ImageWriter)
            writer.write(10, np.zeros((5, len(CHANNELS)), dtype=np.float32))
    assert list((tmp_path / "out").iterdir()) == []


def test_memory_budget_too_small_is_bad_input(tmp_path):
    scene_path = small_scene("hood", tmp_path / "hood.toml")
    result = CliRunner().invoke(cli, ["render", str(scene_path), "-o", str(tmp_path / "out"), "--max-memory", "4K"])
    assert result.exit_code == 2
    assert result.output.count("\n") == 1 and "hood.toml: image:" in result.output and "--max-memory" in result.output
    assert not (tmp_path / "out").exists() or list((tmp_path / "out").iterdir()) == []
    assert CliRunner().invoke(cli, ["render", str(scene_path), "--max-memory", "lots"]).exit_code == 2


# -- batch on this machine ---------------------------------------------------------------------
def test_batch_isolates_failures_skips_up_to_date_and_rerenders_changes(scene_folder, references, tmp_path):
    folder = tmp_path / "scenes"
    shutil.copytree(scene_folder, folder)
    out, report_path = tmp_path / "out", tmp_path / "report.json"

    code, output, report = run_batch(folder, "-o", out, "-j", "2", "--json", report_path)
    assert code == 1, output
    assert report["counts"] == {"rendered": 3, "skipped": 0, "failed": 1, "interrupted": 0}
    broken = by_name(report)["broken"]
    assert broken["status"] == "failed" and "broken.toml: lights.radios: unknown key" in broken["error"]
    assert folder_bytes(out) == references  # the pool's outputs are the in-memory renders, byte for byte
    assert re.search(r"broken.toml +failed", output) and "3 rendered, 0 up to date, 1 failed" in output

    stamps = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    code, output, report = run_batch(folder, "-o", out, "--json", report_path)
    assert code == 1
    assert report["counts"]["skipped"] == 3 and report["counts"]["rendered"] == 0
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == stamps  # nothing rewritten

    # A changed scene file and a changed geometry file each make their scene render again.
    hood = folder / "hood.toml"
    hood.write_text(hood.read_text() + "\n# edited\n")
    with (folder / "teapot.bpt").open("a") as bpt:
        bpt.write("\n")
    (folder / "broken.toml").unlink()
    code, output, report = run_batch(folder, "-o", out, "--json", report_path)
    assert code == 0, output
    status = {name: s["status"] for name, s in by_name(report).items()}
    assert status == {"hood": "rendered", "teapot": "rendered", "cylinder": "skipped"}
    assert read_provenance(out / "hood.png")["rtreflect:inputs_sha256"] == load_scene(hood).inputs_sha256

    code, _, report = run_batch(folder, "-o", out, "--json", report_path, "--force")
    assert code == 0 and report["counts"]["rendered"] == 3


def test_up_to_date_needs_every_output_and_the_same_version(tmp_path, monkeypatch):
    scene_path = small_scene("hood", tmp_path / "pngonly.toml", width=32, height=18, exr=False)
    scene = load_scene(scene_path)
    out = tmp_path / "out"
    assert not batching.up_to_date(scene, out)
    render_to_files(scene, out)
    assert [p.name for p in out.iterdir()] == ["pngonly.png"]
    assert batching.up_to_date(scene, out)  # the hash travels in the PNG's text chunks
    monkeypatch.setattr(batching, "__version__", "999.0")
    assert not batching.up_to_date(scene, out)
    monkeypatch.undo()
    (out / "pngonly.png").write_bytes(b"not a png")
    assert not batching.up_to_date(scene, out)


def test_colliding_names_stop_the_batch_before_rendering(tmp_path):
    small_scene("hood", tmp_path / "a" / "part.toml")
    small_scene("cylinder", tmp_path / "b" / "other.toml", name="part")
    small_scene("g1_join", tmp_path / "c.toml")
    code, output, _ = run_batch(tmp_path, "-o", tmp_path / "out", "--recursive")
    assert code == 2 and output.count("\n") == 1
    assert "part.toml" in output and "other.toml" in output and "collide" in output
    assert not (tmp_path / "out").exists()
    # Without --recursive only c.toml is found: no collision.
    code, output, _ = run_batch(tmp_path, "-o", tmp_path / "out")
    assert code == 0 and sorted(p.name for p in (tmp_path / "out").iterdir()) == ["c.exr", "c.png"]
    code, output, _ = run_batch(tmp_path / "missing", "-o", tmp_path / "out")
    assert code == 2 and "missing: no such file or folder" in output


def test_interrupted_batch_leaves_only_complete_files_and_resumes(tmp_path):
    """SIGINT mid-render (as Ctrl-C): exit 130, no temporary or partial file; a rerun renders only what is missing."""
    folder = tmp_path / "scenes"
    for name in ("a", "b", "c", "d"):
        small_scene("hood", folder / f"{name}.toml", width=480, height=270, samples=3)
    out, report_path = tmp_path / "out", tmp_path / "report.json"
    batch = subprocess.Popen([str(RTREFLECT), "batch", str(folder), "-o", str(out), "-j", "2",
                              "--json", str(report_path)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    # Interrupt once the workers are writing (their temporary files exist).
    while not (out.is_dir() and any(p.name.startswith(".") and p.suffix in (".exr", ".png") for p in out.iterdir())):
        assert batch.poll() is None and time.monotonic() < deadline, batch.communicate()
        time.sleep(0.02)
    batch.send_signal(signal.SIGINT)
    stdout, stderr = batch.communicate(timeout=60)
    assert batch.returncode == 130, stderr
    assert "interrupted by SIGINT" in stderr and "run again to resume" in stderr and "Traceback" not in stderr
    interrupted = json.loads(report_path.read_text())  # the batch's own report, written on the way out
    assert interrupted["counts"]["interrupted"] >= 1
    left = sorted(p.name for p in out.iterdir())
    assert not [name for name in left if name.startswith(".")], left
    for name in left:  # whatever is there is complete: it reads back whole
        read_image(out / name)
    finished = {Path(name).stem for name in left}
    assert all(f"{stem}.exr" in left and f"{stem}.png" in left for stem in finished)

    code, _, report = run_batch(folder, "-o", out, "--json", report_path)
    assert code == 0
    assert {Path(s["scene"]).stem for s in report["scenes"] if s["status"] == "skipped"} == finished
    assert report["counts"]["rendered"] == 4 - len(finished)


@pytest.mark.parametrize("where", ["local", "cluster"])
def test_render_error_is_isolated(where, tmp_path, request):
    """A scene that fails while rendering (here: its 10,000 tubes at 16×16 samples do not fit the memory budget)."""
    heavy = small_scene("hood", tmp_path / "heavy.toml", samples=16)
    text, n = re.subn(r"(?m)^positions = .*$", "spacing = 0.001\ncount = 10000", heavy.read_text())
    assert n == 1
    heavy.write_text(text)
    small_scene("hood", tmp_path / "light.toml")
    options = ["--scheduler", request.getfixturevalue("cluster")] if where == "cluster" else ["-j", "2"]
    code, output, report = run_batch(tmp_path, "-o", tmp_path / "out", "--max-memory", "40M",
                                     "--json", tmp_path / "r.json", *options)
    assert code == 1, output
    scenes = by_name(report)
    assert scenes["light"]["status"] == "rendered"
    assert scenes["heavy"]["status"] == "failed" and "heavy.toml: image: needs about" in scenes["heavy"]["error"]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["light.exr", "light.png"]


# -- batch on a Dask cluster -------------------------------------------------------------------
@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=":0") as local:
        yield local.scheduler_address


def test_cluster_batch_equals_local_batch(cluster, scene_folder, references, tmp_path):
    code, output, report = run_batch(scene_folder, "-o", tmp_path / "out", "--scheduler", cluster,
                                     "--json", tmp_path / "r.json")
    assert code == 1, output
    assert report["where"] == cluster and report["counts"]["rendered"] == 3
    assert "broken.toml: lights.radios: unknown key" in by_name(report)["broken"]["error"]
    assert folder_bytes(tmp_path / "out") == references


def test_tiled_cluster_render_equals_untiled_local_render(cluster, tmp_path):
    scene_path = small_scene("teapot", tmp_path / "scenes" / "tea.toml", width=320, height=180, samples=2)
    expected = reference_files(scene_path, tmp_path / "local")
    code, output, report = run_batch(scene_path, "-o", tmp_path / "out", "--scheduler", cluster,
                                     "--max-memory", "12M", "--json", tmp_path / "r.json")
    assert code == 0, output
    assert by_name(report)["tea"]["tiles"] >= 8  # the image went to the cluster as many tile tasks
    assert folder_bytes(tmp_path / "out") == expected


def overlaid_scene_rendered_locally(tmp_path, overlay: str):
    """A small g1_join scene ``g.toml`` with ``[render] overlay = OVERLAY``, rendered by `rtreflect render` into
    tmp_path/local (the bytes a batch must reproduce)."""
    scene_path = small_scene("g1_join", tmp_path / "scenes" / "g.toml")
    scene_path.write_text(scene_path.read_text().replace("[render]\n", f"[render]\noverlay = {overlay}\n", 1))
    local = subprocess.run([str(RTREFLECT), "render", str(scene_path), "-o", str(tmp_path / "local")],
                           capture_output=True, text=True)
    assert local.returncode == 0, local.stderr
    return scene_path


def test_overlay_through_the_cluster_equals_a_local_render(cluster, tmp_path):
    """The client draws the analytic contours over the PNG and writes NAME.contours.json, as `render` does."""
    scene_path = overlaid_scene_rendered_locally(tmp_path, "true")
    code, output, _ = run_batch(scene_path, "-o", tmp_path / "out", "--scheduler", cluster)
    assert code == 0, output
    names = ["g.contours.json", "g.exr", "g.png"]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == names
    assert all((tmp_path / "out" / n).read_bytes() == (tmp_path / "local" / n).read_bytes() for n in names)
    code, output, report = run_batch(scene_path, "-o", tmp_path / "out", "--json", tmp_path / "r.json")
    assert report["counts"]["skipped"] == 1  # up to date: images and contours all there
    (tmp_path / "out" / "g.contours.json").unlink()
    code, output, report = run_batch(scene_path, "-o", tmp_path / "out", "--json", tmp_path / "r.json")
    assert report["counts"]["rendered"] == 1  # a missing contours file is not up to date


def test_side_overlay_through_the_cluster_and_locally_equals_render(cluster, tmp_path):
    """`overlay = "side"`: NAME.png plain and NAME.side.png, the same bytes from `render`, a local and a Dask batch."""
    scene_path = overlaid_scene_rendered_locally(tmp_path, '"side"')
    names = ["g.contours.json", "g.exr", "g.png", "g.side.png"]
    for where in ([], ["--scheduler", cluster]):
        out = tmp_path / ("cluster" if where else "pool")
        code, output, _ = run_batch(scene_path, "-o", out, *where)
        assert code == 0, output
        assert sorted(p.name for p in out.iterdir()) == names
        assert all((out / n).read_bytes() == (tmp_path / "local" / n).read_bytes() for n in names)
    code, output, report = run_batch(scene_path, "-o", tmp_path / "pool", "--json", tmp_path / "r.json")
    assert report["counts"]["skipped"] == 1  # up to date: both PNGs there
    (tmp_path / "pool" / "g.side.png").unlink()
    code, output, report = run_batch(scene_path, "-o", tmp_path / "pool", "--json", tmp_path / "r.json")
    assert report["counts"]["rendered"] == 1  # a missing side picture is not up to date


def test_unreachable_scheduler_is_bad_input(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    from rtreflect import cluster as clustering

    monkeypatch.setattr(clustering, "CONNECT_TIMEOUT", 2)
    scene_path = small_scene("hood", tmp_path / "hood.toml")
    code, output, _ = run_batch(scene_path, "-o", tmp_path / "out", "--scheduler", "tcp://127.0.0.1:9")
    assert code == 2 and "--scheduler tcp://127.0.0.1:9: cannot connect" in output


def test_outputs_rendered_with_other_settings_are_not_up_to_date(tmp_path):
    """`render --width/--samples/--normals` writes the same scene's files with other settings: batch renders again."""
    scene_path = small_scene("hood", tmp_path / "scenes" / "hood.toml")
    out = tmp_path / "out"
    run = subprocess.run([str(RTREFLECT), "render", str(scene_path), "-o", str(out), "--width", "80", "--height",
                          "45", "--normals", "mesh"], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    code, output, report = run_batch(scene_path, "-o", out, "--json", tmp_path / "r.json")
    assert code == 0 and report["counts"]["rendered"] == 1, output
    assert read_image(out / "hood.exr")[0].shape[:2] == (90, 160)  # the scene's own size now
    code, output, report = run_batch(scene_path, "-o", out, "--json", tmp_path / "r.json")
    assert report["counts"]["skipped"] == 1


@pytest.mark.parametrize("budget_mb", [64, 128, 1024])
def test_tiles_fit_the_budget_and_tube_pairs_stop_growing_at_a_chunk(tmp_path, budget_mb):
    """Tiles of the estimate fit the budget; past one chunk of tube pairs (eq. 4), more tubes do not shrink them."""
    from dataclasses import replace

    from rtreflect.trace.camera import rays_per_pixel
    from rtreflect.integrator.renderer import TILES_AHEAD
    from rtreflect.integrator.tiling import WRITER_ROWS, rays_per_tile, tile_bytes

    base = load_scene(small_scene("hood", tmp_path / "hood.toml", samples=4))
    budget = budget_mb << 20
    sizes = {}
    for tubes in (1, 20, 2000, 10000):
        scene = replace(base, lights=replace(base.lights, positions=np.linspace(-2, 2, tubes)))
        rays = rays_per_tile(scene, budget, 2)
        rows = (2 + WRITER_ROWS) * scene.image.width * len(CHANNELS) * 4
        pixels = -(-rays // rays_per_pixel(scene.image.samples))
        # Two tiles in flight, each with its pixels and those of a finished tile waiting to be taken (TILES_AHEAD).
        assert rows + 2 * (tile_bytes(scene, rays) + (1 + TILES_AHEAD) * pixels * len(CHANNELS) * 4) <= budget
        sizes[tubes] = rays
    assert sizes[1] >= sizes[20] >= sizes[2000] >= sizes[10000] > 0
    if budget_mb >= 128:  # room for a whole chunk per tile: past it, more tubes cost nothing more
        assert sizes[2000] == sizes[10000] > 1000



@pytest.mark.parametrize("budget_mb", [40, 96])
def test_analytic_spans_of_a_narrow_window_fit_the_budget(budget_mb):
    """samples = "analytic": a span of the pixel window holds more pixels than rays (the columns outside the window
    are film, not rays); its film rows count in the budget, with the tiles in flight (the peer scene: a window of
    about half the width)."""
    from rtreflect.integrator.renderer import TILES_AHEAD
    from rtreflect.integrator.tiling import WRITER_ROWS, rays_per_tile, tile_bytes

    from dataclasses import replace

    from rtreflect.exchange.scene import ANALYTIC

    scene = load_scene(Path(__file__).resolve().parents[1] / "bench" / "peer.toml")
    scene = replace(scene, image=replace(scene.image, samples=ANALYTIC))
    budget = budget_mb << 20
    rays = rays_per_tile(scene, budget, 2)
    spans = Renderer(scene).spans(rays, threads=2)
    pixel_bytes = len(CHANNELS) * 4
    rows = (2 + WRITER_ROWS) * scene.image.width * pixel_bytes
    widest = max(stop - start for start, stop in spans)
    assert widest > rays  # the case: a span of more pixels than rays
    assert rows + 2 * (tile_bytes(scene, rays) + (1 + TILES_AHEAD) * widest * pixel_bytes) <= budget

# -- issue 11: files, workers and the cluster ---------------------------------------------------
def test_symlinked_scene_renders_under_its_own_name(tmp_path):
    """`current.toml -> v3.toml`: outputs are named by each file's stem, so both scenes render (not deduplicated)."""
    folder = tmp_path / "scenes"
    small_scene("hood", folder / "v3.toml", width=32, height=18)
    (folder / "current.toml").symlink_to("v3.toml")
    code, output, report = run_batch(folder, "-o", tmp_path / "out", "-j", "1", "--json", tmp_path / "r.json")
    assert code == 0, output
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["current.exr", "current.png", "v3.exr", "v3.png"]
    assert sorted(by_name(report)) == ["current", "v3"] and report["counts"]["rendered"] == 2
    # The same file named twice is still one scene.
    code, output, report = run_batch(folder / "v3.toml", folder, "-o", tmp_path / "out", "--json", tmp_path / "r.json")
    assert code == 0 and len(report["scenes"]) == 2, output


def test_batch_echoes_the_workers_that_run(tmp_path):
    """`-j 64` with two scenes runs two workers: the summary and the report say -j 2 (issue 11)."""
    for name in ("a", "b"):
        small_scene("hood", tmp_path / "scenes" / f"{name}.toml", width=24, height=14)
    code, output, report = run_batch(tmp_path / "scenes", "-o", tmp_path / "out", "-j", "64",
                                     "--json", tmp_path / "r.json")
    assert code == 0, output
    assert report["where"] == "local, -j 2" and "(local, -j 2)" in output


def test_worker_killed_by_sigkill_fails_its_scene_and_leaves_no_temporaries(tmp_path):
    """The OOM killer's way: SIGKILL to a `-j` worker while it writes. Its scene is reported failed (exit 1),
    its hidden temporaries are removed and the removal is said; the other scene renders."""
    folder = tmp_path / "scenes"
    small_scene("hood", folder / "big.toml", width=960, height=540, samples=3)
    small_scene("hood", folder / "small.toml", width=48, height=27)
    out, report_path = tmp_path / "out", tmp_path / "report.json"
    batch = subprocess.Popen([str(RTREFLECT), "batch", str(folder), "-o", str(out), "-j", "2",
                              "--json", str(report_path)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    victim = None
    while victim is None:
        assert batch.poll() is None and time.monotonic() < deadline, batch.communicate()
        for path in out.glob(".big.*.exr") if out.is_dir() else ():
            match = re.search(r"\.rtreflect-.*-(\d+)\.[a-z0-9_]{8}\.exr$", path.name)
            assert match, path.name  # temporaries name their writer
            victim = int(match[1])
        time.sleep(0.02)
    os.kill(victim, signal.SIGKILL)
    stdout, stderr = batch.communicate(timeout=300)
    report = by_name(json.loads(report_path.read_text()))
    assert report["small"]["status"] == "rendered"
    # One outcome: the killed worker's exit code is read even when the executor's thread reaps it first
    # (`batching.exit_code`; the race is constructed in the next test).
    assert batch.returncode == 1, (stdout, stderr)
    assert report["big"]["status"] == "failed" and "killed by SIGKILL" in report["big"]["error"], report["big"]
    assert "removed its" in report["big"]["error"] and "temporary file" in report["big"]["error"]
    assert sorted(p.name for p in out.iterdir()) == ["small.exr", "small.png"]


def _hold_write_lock(queue, holding) -> None:
    """A worker's queue thread caught writing a message when the worker is killed: the write lock, held for good."""
    queue._wlock.acquire()
    holding.set()
    time.sleep(120)


def _report_and_exit(queue) -> None:
    """A batch worker (`_worker_init`) that sends a message and exits, as after its scene."""
    batching._worker_init(queue)
    queue.put(("progress", 1))


def test_a_worker_exits_though_a_killed_sibling_held_the_progress_queues_lock():
    """A -j 2 batch hung after the SIGKILL test's kill, its results printed (once in a CI run): the killed worker
    may die while its queue thread holds the progress queue's write lock (a semaphore shared by the workers), and
    a worker with a message still buffered then waited for it at exit for ever, the pool's shutdown with it. A
    worker drops its buffered messages at exit (`_worker_init`): it exits."""
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    queue, holding = context.Queue(), context.Event()
    holder = context.Process(target=_hold_write_lock, args=(queue, holding))
    holder.start()
    assert holding.wait(60)
    os.kill(holder.pid, signal.SIGKILL)
    holder.join()
    worker = context.Process(target=_report_and_exit, args=(queue,))
    worker.start()
    worker.join(timeout=60)
    try:
        assert not worker.is_alive(), "the worker hangs at exit on the dead sibling's lock"
        assert worker.exitcode == 0
    finally:
        if worker.is_alive():
            worker.kill()
            worker.join()


def test_a_killed_workers_exit_code_is_read_when_another_thread_reaped_it_first():
    """The race behind a SIGKILLed worker's scene being retried: the executor's thread reaps the dead worker
    (waitpid) and stores its code a moment later; a waitpid of ours in between fails (ECHILD) and
    `Process.exitcode` reads None, as if the worker still ran. `exit_code` waits for the stored code."""
    import multiprocessing
    import threading

    process = multiprocessing.get_context("spawn").Process(target=time.sleep, args=(60,))
    process.start()
    os.kill(process.pid, signal.SIGKILL)
    _, status = os.waitpid(process.pid, 0)  # the executor's thread wins the race: the process is reaped...
    assert process.exitcode is None  # ...and until it stores the code, a read of ours finds nothing (the old bug)
    store = threading.Timer(0.2, setattr, (process._popen, "returncode", os.waitstatus_to_exitcode(status)))
    store.start()
    try:
        assert batching.exit_code(process) == -signal.SIGKILL
    finally:
        store.join()


def test_pool_worker_leaves_a_dead_siblings_temporaries_to_the_parent(tmp_path, monkeypatch):
    """The cause of a CI flake of the SIGKILL test above: on a loaded machine the other `-j` worker, starting
    its scene just after its sibling was killed (a zombie counts as dead), swept the sibling's temporary
    before the parent could, so the failure did not say "removed its". A pool worker sweeps nothing; the
    parent removes (and reports) a dead worker's temporaries."""
    import queue

    from rtreflect.output import sharing

    scene_path = small_scene("hood", tmp_path / "hood.toml", width=24, height=14)
    out = tmp_path / "out"
    out.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    sibling = out / f".big.rtreflect-{sharing._host()}-{dead.pid}.abcd_123.exr"
    sibling.write_bytes(b"partial")
    monkeypatch.setattr(batching, "_progress_queue", queue.Queue())  # what _worker_init gives a pool worker
    report = batching._worker_render(load_scene(scene_path), out, None)
    assert report.status == "rendered", report.error
    assert sorted(p.name for p in out.iterdir()) == sorted(["hood.exr", "hood.png", sibling.name])
    assert sharing.remove_dead_temporaries(out, dead.pid) == [sibling]  # the parent's `settle` still can


def test_temporaries_of_dead_runs_are_removed_and_said(tmp_path):
    """Leftovers of a killed run (this host, its PID gone) are removed by the next render; a live process's and
    another host's temporaries are not touched."""
    from rtreflect.output import sharing

    scene_path = small_scene("hood", tmp_path / "hood.toml", width=24, height=14)
    out = tmp_path / "out"
    out.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = sharing._host()
    stale = out / f".hood.rtreflect-{host}-{dead.pid}.abcd_123.exr"
    live = out / f".hood.rtreflect-{host}-1.abcd_123.png"  # PID 1 always runs
    remote = out / f".hood.rtreflect-elsewhere-{dead.pid}.abcd_123.exr"
    for path in (stale, live, remote):
        path.write_bytes(b"partial")
    result = CliRunner().invoke(cli, ["render", str(scene_path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "removed 1 temporary file left by dead runs" in result.output and stale.name in result.output
    assert sorted(p.name for p in out.iterdir()) == sorted(["hood.exr", "hood.png", live.name, remote.name])


def test_cluster_without_workers_is_one_line_after_a_bounded_wait(tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed")
    from rtreflect import cluster as clustering

    monkeypatch.setattr(clustering, "WORKER_TIMEOUT", 1)
    scene_path = small_scene("hood", tmp_path / "hood.toml", width=24, height=14)
    with distributed.LocalCluster(n_workers=0, processes=False, protocol="tcp://", dashboard_address=":0") as empty:
        result = CliRunner().invoke(cli, ["batch", str(scene_path), "-o", str(tmp_path / "out"),
                                          "--scheduler", empty.scheduler_address])
    assert result.exit_code == 2, result.output
    assert result.stderr.count("\n") == 1 and "no worker connected within 1 s" in result.stderr, result.stderr
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_scheduler_killed_mid_batch_fails_the_scenes_left_and_writes_the_report(tmp_path):
    """The scheduler dies after the first scene: each scene left fails with one line, the table and the JSON report
    are still written, nothing half-written stays, exit 1; no traceback on stderr."""
    pytest.importorskip("distributed")
    import socket

    folder = tmp_path / "scenes"
    for name in ("a", "b", "c"):
        small_scene("hood", folder / f"{name}.toml", width=480, height=270, samples=2)
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", str(port), "--no-dashboard"], **quiet)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                               "--no-dashboard"], **quiet)
    out, report_path = tmp_path / "out", tmp_path / "report.json"
    try:
        batch = subprocess.Popen([str(RTREFLECT), "batch", str(folder), "-o", str(out), "--scheduler", address,
                                  "--max-memory", "16M", "--json", str(report_path)],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 120
        while not (out / "a.png").exists():
            assert batch.poll() is None and time.monotonic() < deadline, batch.communicate()
            time.sleep(0.02)
        scheduler.kill()
        stdout, stderr = batch.communicate(timeout=120)
    finally:
        for process in (scheduler, worker):
            process.kill()
            process.wait()
    assert batch.returncode == 1, (stdout, stderr)
    assert stderr.strip() == "", stderr
    report = by_name(json.loads(report_path.read_text()))
    assert report["a"]["status"] == "rendered"
    for name in ("b", "c"):
        assert report[name]["status"] == "failed", report[name]
        assert "lost the connection to the cluster" in report[name]["error"] and "\n" not in report[name]["error"]
    assert re.search(r"b\.toml +failed", stdout) and "1 rendered, 0 up to date, 2 failed" in stdout
    assert sorted(p.name for p in out.iterdir()) == ["a.exr", "a.png"]


@pytest.fixture(scope="module")
def real_cluster():
    """A `dask scheduler` and two `dask worker` processes on 127.0.0.1, as the README tells users to start them
    (arrays come back over TCP, not through LocalCluster's shortcuts); stopped after the module."""
    pytest.importorskip("distributed")
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    processes = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                   "--port", str(port), "--no-dashboard"], **quiet)]
    try:
        processes += [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                                        "--no-dashboard", "--host", "127.0.0.1"], **quiet) for _ in range(2)]
        yield address
    finally:
        for process in processes:
            process.terminate()
        for process in processes:
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


@pytest.mark.parametrize("tiles", ["one", "many"])
def test_real_scheduler_and_workers_write_the_bytes_of_a_local_render(real_cluster, tmp_path, tiles):
    """Issue 17: on real `dask scheduler`/`dask worker` processes a one-tile scene failed ("buffer is wrong size"):
    a tile arriving over TCP may be unaligned in its frame and OpenImageIO refuses it. One-tile and many-tile
    scenes must write byte-identical files to a local render."""
    scene_path = small_scene("hood", tmp_path / "scenes" / f"{tiles}.toml", width=256, height=256, samples=1)
    expected = reference_files(scene_path, tmp_path / "local")
    memory = ["--max-memory", "12M"] if tiles == "many" else []
    code, output, report = run_batch(scene_path, "-o", tmp_path / "out", "--scheduler", real_cluster, *memory,
                                     "--json", tmp_path / "r.json")
    assert code == 0, output
    count = by_name(report)[tiles]["tiles"]
    assert count == 1 if tiles == "one" else count >= 8, count
    assert folder_bytes(tmp_path / "out") == expected


def test_cluster_client_holds_a_bounded_number_of_tiles_behind_a_slow_one(tmp_path, monkeypatch):
    """The first tile is slow: the tiles after it come back and must wait to be written in order. What waits
    counts against the window, so the client never holds more than the window's tiles (not the whole image)."""
    distributed = pytest.importorskip("distributed")
    from rtreflect import cluster as clustering

    scene_path = small_scene("teapot", tmp_path / "scenes" / "tea.toml", width=320, height=180, samples=2)
    expected = reference_files(scene_path, tmp_path / "local")
    render_tile = clustering.render_tile

    def slow_first(scene, key, start, stop, version):
        if start == 0:
            time.sleep(3.0)
        return render_tile(scene, key, start, stop, version)

    monkeypatch.setattr(clustering, "render_tile", slow_first)
    held, write_ready = [], clustering._ClusterBatch._write_ready

    def watch(self, run):
        held.append((sum(len(r.waiting) for r in self.active) + len(self.owner), self.window))
        write_ready(self, run)

    monkeypatch.setattr(clustering._ClusterBatch, "_write_ready", watch)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp://",
                                  dashboard_address=":0") as local:
        code, output, report = run_batch(scene_path, "-o", tmp_path / "out", "--scheduler", local.scheduler_address,
                                         "--max-memory", "12M", "--json", tmp_path / "r.json")
    assert code == 0, output
    assert by_name(report)["tea"]["tiles"] >= 8
    assert max(count for count, _ in held) <= held[0][1], held  # tiles waiting + in flight ≤ the window
    assert folder_bytes(tmp_path / "out") == expected
