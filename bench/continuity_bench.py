"""`rtreflect continuity` benchmark (issue 16): the reflection lines' kinks as a ratio to the rest of the check.

    python bench/continuity_bench.py [SCENE ...] [--repeat 2]

For each scene (default: scenes/teapot.toml and parts/filleted_block.step) it times, in CPU
seconds of this process (the check is single-threaded numpy), the continuity check without the
line kinks (seams, exact G0/G1/G2), and `analysis.seamlines.attach_line_kinks` on its edges,
best of ``--repeat``; it prints both and the kinks as a fraction of the check. The kinks were
~7× the check on the teapot when each light's crossings were bisected apart; `batch --continuity`
includes them since they are bisected for all lights at once. A shared machine makes seconds
approximate: compare the ratios.
"""

from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SCENES = [ROOT / "scenes" / "teapot.toml", ROOT / "parts" / "filleted_block.step"]


def main() -> None:
    from rtreflect.analysis.contours import UlmetField
    from rtreflect.analysis.seamcheck import check_scene
    from rtreflect.analysis.seamlines import attach_line_kinks
    from rtreflect.exchange.load import load_scene
    from rtreflect.integrator.renderer import Renderer

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", type=Path, default=DEFAULT_SCENES)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    for path in args.scenes:
        scene = load_scene(path)
        check, kinks, crossings = float("inf"), float("inf"), 0
        for _ in range(args.repeat):
            start = time.process_time()
            result = check_scene(scene, lines=False)
            check = min(check, time.process_time() - start)
            edges = copy.deepcopy(result.edges)
            start = time.process_time()
            attach_line_kinks(UlmetField.of(Renderer(result.scene)), edges, result.size)
            kinks = min(kinks, time.process_time() - start)
            crossings = sum(e.line_crossings for e in edges)
        print(f"{path.name}: {len(result.edges)} edges, {crossings} line crossings seen; check {check:.2f} s CPU, "
              f"line kinks {kinks:.2f} s CPU = {kinks / check:.2f} x the check")


if __name__ == "__main__":
    main()
