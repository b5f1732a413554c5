"""Mesh normals, for comparison only: the classic CAD analysis-mesh shading (`[render] normals = "mesh"`).

The hit point is Embree's point on the triangle and the normal is interpolated from the
triangle's three vertex normals with the hit's barycentrics (Phong normals). The vertex
normals are the exact NURBS normals at the vertices, which is how CAD tools build an
analysis mesh; the (u, v) AOVs are the barycentric interpolation of the vertices' (u, v).
Between the vertices neither the point nor the normal is the surface's, and the
reflection lines show it: `rtreflect validate` measures the difference.
"""

from __future__ import annotations

import numpy as np

from .accelerator import Accelerator
from ..clock import NULL_CLOCK, StageClock
from ..geometry.surfaces import SurfaceSet
from ..geometry.tessellation import Tessellation
from .tracing import Hits, facing


def vertex_normals(tessellation: Tessellation, surfaces: SurfaceSet) -> np.ndarray:
    """(V, 3) exact unit normals at the mesh vertices (each vertex belongs to one patch)."""
    return surfaces.normals(tessellation.vertex_patch.astype(np.int64), tessellation.vertex_uv[:, 0],
                            tessellation.vertex_uv[:, 1])


def trace_mesh(accelerator: Accelerator, tessellation: Tessellation, normals_at_vertices: np.ndarray,
               origins: np.ndarray, directions: np.ndarray, clock: StageClock = NULL_CLOCK) -> Hits:
    """Hits on the mesh with interpolated vertex normals; same fields as `tracing.trace` (never a fallback)."""
    n = len(origins)
    with clock.stage("intersect (Embree)"):
        mesh = accelerator.intersect(origins, directions)
    hits = Hits.blank(n, mesh.prim >= 0)
    idx = np.flatnonzero(hits.hit)
    if len(idx):
        prim, b1, b2 = mesh.prim[idx], mesh.b1[idx], mesh.b2[idx]
        hits.patch[idx], hits.u[idx], hits.v[idx] = tessellation.start_parameters(prim, b1, b2)
        hits.t[idx] = mesh.t[idx]
        hits.P[idx] = origins[idx] + mesh.t[idx, None] * directions[idx]
        with clock.stage("mesh normals"):
            corners = normals_at_vertices[tessellation.faces[prim]]  # (N, 3, 3)
            nrm = (1.0 - b1 - b2)[:, None] * corners[:, 0] + b1[:, None] * corners[:, 1] + b2[:, None] * corners[:, 2]
            hits.N[idx] = facing(nrm / np.linalg.norm(nrm, axis=1, keepdims=True), directions[idx])
            hits.cos[idx] = np.abs(np.einsum("ij,ij->i", hits.N[idx], directions[idx]))
    return hits
