"""One-thread cProfile of a render of the peer scene (bench/peer.toml, issue 14): where its time goes.

Renders once to warm up (kernels loaded, the second look's fine mesh built), times a second render,
then profiles a third and prints its `RenderStats` (stage times) and the 25 functions with the most
time of their own. SAMPLES is ``analytic`` (the default path) or an integer s (s×s samples per pixel).

    python bench/prof_peer.py analytic
    python bench/prof_peer.py 1
"""

from __future__ import annotations

import cProfile
import dataclasses
import pstats
import sys
import time
from pathlib import Path

from rtreflect.exchange.scene import ANALYTIC, load_scene
from rtreflect.integrator.renderer import Renderer

SCENE = Path(__file__).resolve().parent / "peer.toml"


def main() -> None:
    samples = sys.argv[1] if len(sys.argv) > 1 else ANALYTIC
    samples = samples if samples == ANALYTIC else int(samples)
    scene = load_scene(SCENE)
    renderer = Renderer(dataclasses.replace(scene, image=dataclasses.replace(scene.image, samples=samples)))
    renderer.render(threads=1)
    t0 = time.perf_counter()
    renderer.render(threads=1)
    print("render", time.perf_counter() - t0)
    profile = cProfile.Profile()
    profile.enable()
    result = renderer.render(threads=1)
    profile.disable()
    print(result.stats)
    pstats.Stats(profile).sort_stats("tottime").print_stats(25)


if __name__ == "__main__":
    main()
