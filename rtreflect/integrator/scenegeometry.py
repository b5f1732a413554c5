"""What a render builds from the surfaces alone: patches, tessellation, BVH, second look, ray box; built once, shared.

None of it depends on the camera, the tubes, the image or the mode, only on the surfaces and ``[render]
tessellation`` and ``normals``. A scene is often set up more than once in a row: the automatic rig
(`autorig.resolve`) renders a preview of a part before its camera and tubes are chosen, then the render itself,
`validate`'s, and the seam picture's (`--seams`) each build a `Renderer` of the same scene. Each built its own: on
the 206-face plate the preview's geometry (0.8 s) and its second look's finer mesh (1.2 s) were thrown away and
built again by the render: `rtreflect render parts/plate.step` took 16.4 s, 13.8 s with them shared.

`scene_geometry` keeps the last one built (one scene's worth of memory, until the next is built or `forget`) and
hands it to the next render of the same surfaces (the very tuple of the scene: `dataclasses.replace` keeps it) with
the same settings. Everything in it is read-only to a render, or built on first use under its own lock (the finer
mesh, the clearance cones), so renders may share it, in threads too; and a shared one gives the same pixels, bit
for bit, as a fresh one (the tracer's answer for a ray depends on the ray alone; `tests/test_render.py`).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from .cull import RayBox
from ..geometry.surfaces import SurfaceSet
from ..geometry.tessellation import Tessellation, tessellate
from ..trace.accelerator import Accelerator
from ..trace.meshnormals import vertex_normals
from ..trace.secondlook import SecondLook


@dataclass(frozen=True)
class SceneGeometry:
    surfaces: SurfaceSet
    tessellation: Tessellation
    accelerator: Accelerator
    vertex_normals: np.ndarray | None  # normals = "mesh": the analysis mesh's normals (meshnormals.py), else None
    second_look: SecondLook | None  # the exact path's (secondlook.py); None on the mesh-normals path
    ray_box: RayBox

    @classmethod
    def build(cls, scene) -> "SceneGeometry":
        surfaces = SurfaceSet(list(scene.surfaces))
        # The exact tracer's mesh encloses the surface (silhouettes exact); the mesh-normals path keeps S(nodes).
        tessellation = tessellate(scene.surfaces, scene.render.tessellation, enclose=scene.render.normals != "mesh")
        # normals = "mesh": the analysis-mesh comparison path (meshnormals.py); the exact path is untouched.
        normals = vertex_normals(tessellation, surfaces) if scene.render.normals == "mesh" else None
        # Rays that run close to a sheet are traced again on a finer mesh (secondlook.py): the nearest exact hit.
        second_look = None if normals is not None else SecondLook(scene.surfaces, scene.render.tessellation,
                                                                   tessellation, surfaces)
        # Camera rays are asked of the coarse mesh and the second look's shell (its finer mesh only for rays one of
        # those met): a ray missing both meshes' box is a miss without asking Embree (`cull`).
        ray_box = RayBox(tessellation.vertices, *(() if second_look is None else (second_look.shell_mesh.vertices,)))
        return cls(surfaces, tessellation, Accelerator(tessellation), normals, second_look, ray_box)


_lock = threading.Lock()
#: The last geometry built: (the scene's surfaces tuple, its settings, the geometry).
_last: tuple | None = None


def forget() -> None:
    """Let go of the geometry kept for the next render (its BVHs and meshes: a long-lived process, a notebook, a test
    that changes how geometry is built)."""
    global _last
    with _lock:
        _last = None


def scene_geometry(scene) -> SceneGeometry:
    """The `SceneGeometry` of ``scene``: the last one built where it was built of the same surfaces tuple with the same
    ``tessellation`` and ``normals`` (module doc), else a new one (built outside the lock: other scenes' go on)."""
    global _last
    settings = (scene.render.tessellation, scene.render.normals)
    with _lock:
        if _last is not None and _last[0] is scene.surfaces and _last[1] == settings:
            return _last[2]
        _last = None  # let go first: a batch holds one scene's geometry at a time, not the last one's and the next's
    geometry = SceneGeometry.build(scene)
    with _lock:
        _last = (scene.surfaces, settings, geometry)
    return geometry
