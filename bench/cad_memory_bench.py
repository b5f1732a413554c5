"""Memory of a CAD part from its read to its first trace, stage by stage (issue 12: "a 2000-face model in bounded memory").

    python bench/cad_memory_bench.py [PART]     # default: the ~2000-face plate of bench/cad_bench.py (built once)

In this one process: the read (`load_scene`), then the automatic scene's preview renderer (the enclosing
tessellation, Embree's BVH, the second look's shell), then its first trace of the preview's pixel rays (which
builds the second look's finer mesh and the rim caches). After each stage prints the resident memory
(``/proc/self/statm``) and the peak so far (``getrusage``), then the size of ``Tessellation.rim_path`` (vertices ×
the most boundary edges at one vertex) and how many vertices have how many boundary edges.
"""

from __future__ import annotations

import os
import resource
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))


def mark(label: str) -> None:
    current = int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{label:<44} resident {current:7.0f} MB   peak {peak:7.0f} MB", flush=True)


def main() -> None:
    import OCP  # noqa: F401  imported before the first mark: the imports are not the part's
    from rtreflect.exchange.load import load_scene
    from rtreflect.exchange.scene import CameraSpec, ImageSpec, LightSpec
    from rtreflect.integrator import autorig
    from rtreflect.integrator.renderer import Renderer
    from rtreflect.trace.camera import Camera

    if len(sys.argv) > 1:
        path = Path(sys.argv[1])
    else:
        import cad_bench

        path = cad_bench.big_plate(2000)
    mark("imports")
    scene = load_scene(path).with_image(64, 36, 1)
    mark(f"read {path.name} ({len(scene.surfaces)} faces)")
    width, height = autorig.preview_size(scene.image)
    preview = Renderer(replace(scene, image=ImageSpec(width, height, 1),  # as autorig.resolve builds it
                               camera=CameraSpec(eye=np.array([0.0, -1.0, 0.0]), look_at=np.zeros(3), view_height=1.0),
                               lights=LightSpec(np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]),
                                                np.zeros(1), 1.0)))
    mark(f"preview renderer ({len(preview.tessellation.vertices)} vertices)")
    camera, _ = autorig.best_iso(preview, scene.camera, autorig.part_points(preview.tessellation, preview.surfaces),
                                 scene.image.width / scene.image.height)
    preview.camera = Camera(camera, width, height)
    rows, cols = np.divmod(np.arange(width * height), width)
    preview.trace(*preview.camera.rays(rows, cols))
    mark(f"first trace ({width}×{height} rays)")
    rim = preview.tessellation.rim_path
    counts = np.bincount((rim >= 0).sum(axis=1))
    print(f"rim_path {rim.shape[0]}×{rim.shape[1]}, {rim.nbytes / 2**20:.1f} MB; vertices by boundary edges: "
          + ", ".join(f"{k}: {n}" for k, n in enumerate(counts) if n))


if __name__ == "__main__":
    main()
