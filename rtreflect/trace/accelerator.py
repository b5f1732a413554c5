"""Accelerator: one Embree BVH over every patch's triangles (embreex, used directly).

trimesh's own ray wrapper drops the barycentrics, which are what turn a triangle
hit into a starting (u, v) for the exact hit; so the Embree scene is built here.
Embree works in float32; everything around it stays float64. Float32 keeps 24 bits
of a coordinate's magnitude, so the BVH holds the mesh moved to its own centre
(bounding-box centre) and every ray origin is moved likewise before conversion:
a part 10⁵ units from the origin then intersects as precisely as one at the origin
(in world coordinates, hits were 0.01 off on a 3-unit part and Newton gave up).
Ray distances do not change under the move, so callers never see it. Rays whose
origins lie far from the mesh (more than `FAR_RADII` of its bounding radii: a camera
1e4 parts away) are moved along themselves, in float64, to just before the mesh's
bounding sphere first: from 5e5 away float32 rounds a ray by 0.03–0.06 mm, and hits
within that of a face's edge landed on the face behind (the seventeenth sweep, a block
seen from 1e4 times its size: 7.99 mm behind Open CASCADE's first hit). Their distances
are given back from the true origins.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from ..geometry.tessellation import Tessellation
from ..kernels.pixels import bvh_rays


#: Rays whose origins all lie farther than this many of the mesh's bounding radii from its centre are moved along
#: themselves to 2 radii before its bounding sphere (`Accelerator._local`): nearer, their float32 rounding is that of
#: the part's own size times this at most (float32 keeps ~1e-7 of a magnitude: 1e-5 of the part).
FAR_RADII = 100.0


class MeshHits(NamedTuple):
    prim: np.ndarray  # triangle index, −1 where the ray misses
    b1: np.ndarray  # Embree barycentrics: point = (1 − b1 − b2)·v0 + b1·v1 + b2·v2
    b2: np.ndarray
    t: np.ndarray  # ray distance (float64 of Embree's float32)


def bvh_centre(vertices: np.ndarray) -> np.ndarray:
    """The centre of the vertices' bounding box: the origin of the BVH's float32 coordinates."""
    return 0.5 * (vertices.min(axis=0) + vertices.max(axis=0)) if len(vertices) else np.zeros(3)


class Accelerator:
    def __init__(self, tessellation: Tessellation):
        self.scene = rtcore_scene.EmbreeScene()
        vertices = tessellation.vertices
        self.centre = bvh_centre(vertices)  # the BVH's origin, in world coordinates (float64)
        # Keep references: embreex shares these buffers with Embree.
        self._vertices = np.ascontiguousarray(vertices - self.centre, dtype=np.float32)
        self._faces = np.ascontiguousarray(tessellation.faces, dtype=np.int32)
        self._mesh = TriangleMesh(self.scene, self._vertices, self._faces)
        self._chord_error = tessellation.chord_error
        self._extent = tessellation.extent
        # The bounding sphere about the centre, for rays from far away (`_local`).
        self._radius = float(np.sqrt(np.max(np.einsum("ij,ij->i", vertices - self.centre, vertices - self.centre),
                                            initial=0.0)))

    def surface_origins(self, R: np.ndarray, n: np.ndarray, patch: np.ndarray) -> np.ndarray:
        """Origins for rays leaving the surface at R on ``patch``'s side n (unit normal facing the ray's side).

        Offset along n by more than the mesh's chord error (twice it, plus a relative 1e-6 for
        float32 in the BVH's centred coordinates), so the mesh standing in for the surface does not
        shadow the point it approximates.
        """
        eps = 2.0 * self._chord_error[patch] + 1e-6 * (self._extent + np.abs(R - self.centre).max(axis=1))
        return R + eps[:, None] * n

    def _local(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Rays in the BVH's centred float32 coordinates: the origins moved in float64, then converted, and the
        directions converted (one compiled pass, `kernels.pixels.bvh_rays`); and where the first origin lies farther
        than `FAR_RADII` bounding radii from the centre, each ray's move along itself (in its own distance unit) to 2
        radii before the bounding sphere (none for a ray that starts nearer), else None (module doc)."""
        origins, directions = np.asarray(origins, dtype=np.float64), np.asarray(directions, dtype=np.float64)
        shift = None
        # Decided by the first origin (a camera's rays share their eye, or its plane): a per-ray test cost 2.5 ms a
        # tile of 65,536 rays, 4 % of a full-HD render. The move itself is safe for any ray (the mesh lies beyond it).
        if self._radius > 0 and len(origins):
            if np.linalg.norm(origins[0] - self.centre) > FAR_RADII * self._radius:
                speed = np.sqrt(np.einsum("ij,ij->i", directions, directions))
                along = np.einsum("ij,ij->i", self.centre - origins, directions) / speed  # to the centre's foot
                shift = np.maximum(along - 2.0 * self._radius, 0.0) / speed
                origins = origins + shift[:, None] * directions
        local, directions32 = np.empty(origins.shape, dtype=np.float32), np.empty(directions.shape, dtype=np.float32)
        bvh_rays(origins, directions, np.ascontiguousarray(self.centre, dtype=np.float64), local, directions32)
        return local, directions32, shift

    def intersect(self, origins: np.ndarray, directions: np.ndarray, max_distance: np.ndarray | None = None) -> MeshHits:
        """Nearest triangle hit of each ray (within ``max_distance`` along it, when given)."""
        if len(origins) == 0:
            empty = np.zeros(0)
            return MeshHits(np.zeros(0, dtype=np.int64), empty, empty, empty)
        local, directions32, shift = self._local(origins, directions)
        extra = {}
        if max_distance is not None:
            extra["dists"] = self._dists(max_distance, shift)
        result = self.scene.run(local, directions32, query="INTERSECT", output=1, **extra)
        prim = np.where(result["geomID"] >= 0, result["primID"], -1).astype(np.int64)
        t = result["tfar"].astype(np.float64)
        if shift is not None:  # from the true origins (a miss: its segment's end, as without the move)
            t = t + shift
        return MeshHits(prim, result["u"].astype(np.float64), result["v"].astype(np.float64), t)

    @staticmethod
    def _dists(max_distance: np.ndarray, shift: np.ndarray | None) -> np.ndarray:
        """Embree's float32 segment ends: ``max_distance`` from the rays' moved origins (`_local`), at least 0 (a ray
        moved past its end meets nothing there: the mesh lies beyond the move)."""
        if shift is not None:
            max_distance = np.maximum(max_distance - shift, 0.0)
        return np.ascontiguousarray(np.minimum(max_distance, np.finfo(np.float32).max), dtype=np.float32)

    def occluded(self, origins: np.ndarray, directions: np.ndarray, max_distance: np.ndarray) -> np.ndarray:
        """True where a triangle lies on the segment from each origin to max_distance along its direction."""
        if len(origins) == 0:
            return np.zeros(0, dtype=bool)
        local, directions32, shift = self._local(origins, directions)
        result = self.scene.run(local, directions32, dists=self._dists(max_distance, shift), query="OCCLUDED")
        return np.asarray(result) >= 0
