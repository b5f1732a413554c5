"""Tessellation: each patch to a trimesh mesh whose vertices carry (u, v) and the patch index.

The mesh only *finds* hits (DESIGN.md); the exact point and normal come from the
NURBS evaluator afterwards. Each knot span gets ``tessellation`` segments per
direction, so the mesh follows the surface's own pieces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from .surfaces import NurbsSurface


def span_samples(breaks: np.ndarray, per_span: int) -> np.ndarray:
    """Parameter values: ``per_span`` equal segments inside every span between distinct knots."""
    parts = [np.linspace(a, b, per_span + 1)[:-1] for a, b in zip(breaks[:-1], breaks[1:])]
    return np.concatenate([*parts, breaks[-1:]])


def grid_faces(nu: int, nv: int) -> np.ndarray:
    """Two triangles per cell of an nu×nv vertex grid (vertex (i, j) has index i·nv + j)."""
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    b, c, d = a + nv, a + nv + 1, a + 1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


def tessellate_patch(surface: NurbsSurface, patch_index: int, per_span: int) -> trimesh.Trimesh:
    """A mesh of one patch; ``vertex_attributes`` hold ``uv`` (V, 2) and ``patch`` (V,)."""
    breaks_u, breaks_v = surface.span_breaks()
    us, vs = span_samples(breaks_u, per_span), span_samples(breaks_v, per_span)
    uu, vv = np.meshgrid(us, vs, indexing="ij")
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1)
    points = surface.evaluate(uv[:, 0], uv[:, 1]).S
    return trimesh.Trimesh(
        vertices=points,
        faces=grid_faces(len(us), len(vs)),
        vertex_attributes={"uv": uv, "patch": np.full(len(uv), patch_index)},
        process=False,  # keep the grid as built: merging would mix vertices of different (u, v)
        validate=False,
    )


@dataclass(frozen=True)
class Tessellation:
    """All patches' meshes in one vertex/face array, as Embree wants them."""

    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3)
    vertex_uv: np.ndarray  # (V, 2)
    vertex_patch: np.ndarray  # (V,)
    face_patch: np.ndarray  # (F,)
    chord_error: np.ndarray  # per patch: largest mesh-to-surface distance found at edge midpoints
    meshes: tuple[trimesh.Trimesh, ...]
    boundary: np.ndarray  # indices of the vertices on a patch's domain boundary (where a neighbour may join)
    edge_length: np.ndarray  # per patch: its longest mesh edge

    @property
    def extent(self) -> float:
        """Diagonal of the bounding box of all patches."""
        return float(np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)))

    def start_parameters(self, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(patch, u, v) interpolated from a triangle's vertices with Embree's barycentrics."""
        corners = self.vertex_uv[self.faces[prim]]  # (N, 3, 2)
        uv = (1.0 - b1 - b2)[:, None] * corners[:, 0] + b1[:, None] * corners[:, 1] + b2[:, None] * corners[:, 2]
        return self.face_patch[prim], uv[:, 0], uv[:, 1]

    def across_seam(self, points: np.ndarray, patch: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For points on the boundary of ``patch``: the nearest boundary vertex of another patch.

        Returns (patch, u, v) of that vertex, where a hit that ran off one patch's edge
        can restart on its neighbour, and the distance to it (patch −1 and inf where there
        is no other patch).
        Brute force over boundary vertices, in row chunks: it serves the few hits at seams.
        """
        patch_out = np.full(len(points), -1)
        uv_out = np.full((len(points), 2), np.nan)
        dist_out = np.full(len(points), np.inf)
        candidates = self.boundary
        if len(candidates) == 0:
            return patch_out, uv_out[:, 0], uv_out[:, 1], dist_out
        cand_xyz, cand_patch = self.vertices[candidates], self.vertex_patch[candidates]
        cand_sq = np.einsum("ij,ij->i", cand_xyz, cand_xyz)
        rows = max(1, (1 << 20) // len(candidates))  # bounds the (rows, candidates) distance table
        for lo in range(0, len(points), rows):
            hi = min(lo + rows, len(points))
            pts = points[lo:hi]
            d2 = np.maximum(np.einsum("ij,ij->i", pts, pts)[:, None] - 2.0 * pts @ cand_xyz.T + cand_sq, 0.0)
            d2[cand_patch[None, :] == patch[lo:hi, None]] = np.inf
            best = np.argmin(d2, axis=1)
            dist_out[lo:hi] = np.sqrt(d2[np.arange(hi - lo), best])
            found = np.isfinite(dist_out[lo:hi])
            patch_out[lo:hi] = np.where(found, cand_patch[best], -1)
            uv_out[lo:hi] = self.vertex_uv[candidates[best]]
        return patch_out, uv_out[:, 0], uv_out[:, 1], dist_out


def _chord_error(surface: NurbsSurface, mesh: trimesh.Trimesh) -> float:
    """Largest distance between the mesh and the surface, sampled at the midpoints of every triangle edge.

    Edge midpoints, not centroids: a chord strays farthest from the surface at its middle.
    """
    edges = mesh.edges_unique
    uv = mesh.vertex_attributes["uv"][edges].mean(axis=1)
    exact = surface.evaluate(uv[:, 0], uv[:, 1]).S
    chord_mid = mesh.vertices[edges].mean(axis=1)
    return float(np.max(np.linalg.norm(exact - chord_mid, axis=1)))


def tessellate(surfaces: list[NurbsSurface] | tuple[NurbsSurface, ...], per_span: int) -> Tessellation:
    meshes = tuple(tessellate_patch(s, k, per_span) for k, s in enumerate(surfaces))
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    return Tessellation(
        vertices=np.concatenate([m.vertices for m in meshes]),
        faces=np.concatenate([m.faces + off for m, off in zip(meshes, offsets)]),
        vertex_uv=np.concatenate([m.vertex_attributes["uv"] for m in meshes]),
        vertex_patch=np.concatenate([m.vertex_attributes["patch"] for m in meshes]),
        face_patch=np.concatenate([np.full(len(m.faces), k) for k, m in enumerate(meshes)]),
        chord_error=np.array([_chord_error(s, m) for s, m in zip(surfaces, meshes)]),
        meshes=meshes,
        boundary=np.concatenate([_boundary_vertices(m) + off for m, off in zip(meshes, offsets)]),
        edge_length=np.array([float(m.edges_unique_length.max()) for m in meshes]),
    )


def _boundary_vertices(mesh: trimesh.Trimesh) -> np.ndarray:
    """Indices of the grid vertices on the patch's parameter-domain boundary."""
    uv = mesh.vertex_attributes["uv"]
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    return np.flatnonzero(np.any((uv == lo) | (uv == hi), axis=1))
