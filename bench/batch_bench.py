"""Batch benchmark (issue: batch rendering): local parallelism and peak memory of tiled renders.

    python bench/batch_bench.py jobs   [--scenes 8 --width 480 --height 270 --samples 2]
    python bench/batch_bench.py memory [--sizes 3840x2160 7680x4320 --samples 1 --max-memory SIZE]

``jobs`` writes N scenes (the shipped ones, cycled, at the given size) to a temporary
folder and times ``rtreflect batch -j 1`` against ``-j 2`` (``--force``), alternating,
printing every wall time and the ratio of the best of each. ``memory`` renders the benchmark surface of
``render_bench.py`` at each size through ``/usr/bin/time -v rtreflect render`` and prints
the peak resident memory next to what an in-memory film of 22 float32 planes would need.
Timings on a shared machine are approximate: compare ratios, not seconds.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RTREFLECT = Path(sys.executable).parent / "rtreflect"
sys.path.insert(0, str(Path(__file__).resolve().parent))


def write_scenes(folder: Path, count: int, width: int, height: int, samples: int) -> None:
    shipped = sorted((ROOT / "scenes").glob("*.toml"))
    shutil.copy(ROOT / "scenes" / "teapot.bpt", folder)
    for i in range(count):
        text = shipped[i % len(shipped)].read_text()
        for key, value in (("width", width), ("height", height), ("samples", samples)):
            text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", text, count=1)
        (folder / f"scene{i:02d}_{shipped[i % len(shipped)].stem}.toml").write_text(text)


def bench_jobs(args) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "scenes"
        folder.mkdir()
        write_scenes(folder, args.scenes, args.width, args.height, args.samples)
        seconds: dict[int, list[float]] = {1: [], 2: []}
        for _ in range(args.repeat):  # alternate, so a burst of load from elsewhere hits both alike
            for jobs in (1, 2):
                start = time.perf_counter()
                subprocess.run([str(RTREFLECT), "batch", str(folder), "-o", str(Path(tmp) / f"out{jobs}"),
                                "-j", str(jobs), "--force"], check=True, stdout=subprocess.DEVNULL)
                seconds[jobs].append(time.perf_counter() - start)
        for jobs in (1, 2):
            runs = ", ".join(f"{s:.1f}" for s in seconds[jobs])
            print(f"-j {jobs}: best {min(seconds[jobs]):.1f} s ({runs}) for {args.scenes} scenes "
                  f"{args.width}×{args.height}, {args.samples}×{args.samples} samples")
        seconds = {jobs: min(runs) for jobs, runs in seconds.items()}
        print(f"speed-up -j 2 / -j 1: {seconds[1] / seconds[2]:.2f}×")


def bench_memory(args) -> None:
    from render_bench import bench_scene_text

    with tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            width, height = map(int, size.lower().split("x"))
            scene = Path(tmp) / f"bench_{width}x{height}.toml"
            scene.write_text(bench_scene_text(width, height).replace("samples = 1", f"samples = {args.samples}"))
            command = ["/usr/bin/time", "-v", str(RTREFLECT), "render", str(scene), "-o", str(Path(tmp) / "out")]
            if args.max_memory:
                command += ["--max-memory", args.max_memory]
            run = subprocess.run(command, capture_output=True, text=True, check=True)
            rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", run.stderr).group(1))
            wall = re.search(r"Elapsed \(wall clock\) time.*: (\S+)", run.stderr).group(1)
            film_mb = width * height * 17 * 4 / 2**20
            print(f"{width}×{height}, {args.samples}×{args.samples} samples: peak RSS {rss_kb / 1024:.0f} MiB "
                  f"(an in-memory film alone: {film_mb:.0f} MiB), wall {wall}")
            for path in (Path(tmp) / "out").iterdir():
                path.unlink()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    jobs = sub.add_parser("jobs", help="wall time of N scenes with -j 1 and -j 2")
    jobs.add_argument("--scenes", type=int, default=8)
    jobs.add_argument("--width", type=int, default=480)
    jobs.add_argument("--height", type=int, default=270)
    jobs.add_argument("--samples", type=int, default=2)
    jobs.add_argument("--repeat", type=int, default=3, help="runs of each, alternating; best is compared")
    memory = sub.add_parser("memory", help="peak memory of tiled renders of big images")
    memory.add_argument("--sizes", nargs="+", default=["3840x2160", "7680x4320"])
    memory.add_argument("--samples", type=int, default=1)
    memory.add_argument("--max-memory", default=None)
    args = parser.parse_args()
    bench_jobs(args) if args.what == "jobs" else bench_memory(args)


if __name__ == "__main__":
    main()
