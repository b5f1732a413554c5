"""Tessellation: each patch to a triangle mesh (`PatchMesh`) whose vertices carry (u, v) and the patch index.

The mesh only *finds* hits (DESIGN.md); the exact point and normal come from the
NURBS evaluator afterwards. Each knot span gets ``tessellation`` segments per
direction, so the mesh follows the surface's own pieces.

A trimmed CAD face (``NurbsSurface.trim``, DESIGN.md "CAD input") is meshed from its reader's
triangulation in (u, v) when it has one that follows the face (``mesh_uv``, `reader_mesh`: vertices S(nodes)
by rtreflect's own evaluator), else from the span grid keeping the triangles that touch the face (a triangle
overlapping the trim polygon in (u, v)). Either way the mesh only finds hits: the tracer
tests each refined hit against the trim (tracing.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..kernels import nurbs as kernel
from ..kernels import rims as rims_kernel
from .surfaces import NurbsSurface


@dataclass(frozen=True)
class PatchMesh:
    """One patch's triangles: vertices (V, 3), faces (F, 3) and per vertex its (u, v), patch index and rim flag;
    ``rim_edges`` (B, 2): the vertex pairs of the face's mesh boundary edges (before a reader's skirt), whose
    polyline the rim flags lie on.

    Plain arrays (trimesh's `Trimesh` served only as this container and cost every process ~0.5 s of
    imports, scipy included).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    patch: np.ndarray
    rim: np.ndarray
    rim_edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))

    @cached_property
    def edges_unique(self) -> np.ndarray:
        """(E, 2) each edge once, its vertex indices sorted (`unique_edges`)."""
        return unique_edges(self.faces)

    @cached_property
    def edges_unique_length(self) -> np.ndarray:
        """(E,) the lengths of `edges_unique` (summed as trimesh's row norm did, so bit for bit its values)."""
        vector = self.vertices[self.edges_unique[:, 0]] - self.vertices[self.edges_unique[:, 1]]
        return np.sqrt(np.dot(vector**2, [1, 1, 1]))


def _edge_keys(pairs: np.ndarray, major: int) -> tuple[np.ndarray, int]:
    """One int64 per vertex pair, ordered by column ``major`` then the other: sorting keys sorts the pairs
    lexicographically, as ``np.unique(..., axis=0)`` does on its rows, but as one integer sort (~10× faster)."""
    base = int(pairs.max(initial=0)) + 1
    return pairs[:, major] * base + pairs[:, 1 - major], base


def distinct(values: np.ndarray) -> np.ndarray:
    """The sorted distinct values of an array, flattened: ``np.unique(values)`` by a sort and a mask. NumPy 2.4's
    np.unique without ``return_*`` takes a hash table, ~70× slower on millions of distinct values (8M int64 keys,
    4M distinct: 5.8 s against 0.08 s): the 45 × 45-span dense_net.step's validate mesh spent 106 s in it."""
    values = np.sort(np.ravel(values))
    return values[np.r_[True, values[1:] != values[:-1]]] if len(values) else values


def unique_rows(rows: np.ndarray) -> np.ndarray:
    """Per row of a 2-D array, the index of its value among the distinct rows sorted lexicographically: the
    ``return_inverse`` of ``np.unique(rows, axis=0)``, by one lexsort (that call views the rows as opaque records,
    6.4 s for 4M rows of 3 float32)."""
    order = np.lexsort(rows.T[::-1])
    ordered = rows[order]
    new = np.r_[True, (ordered[1:] != ordered[:-1]).any(axis=1)] if len(rows) else np.zeros(0, dtype=bool)
    inverse = np.empty(len(rows), dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return inverse


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """(E, 2) every edge of the triangles once, as (smaller, larger) vertex, in lexicographic order."""
    pairs = np.sort(np.asarray(faces, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    keys, base = _edge_keys(pairs, 0)
    keys = distinct(keys)
    return np.stack([keys // base, keys % base], axis=1)


def span_samples(breaks: np.ndarray, per_span: int) -> np.ndarray:
    """Parameter values: ``per_span`` equal segments inside every span between distinct knots."""
    parts = [np.linspace(a, b, per_span + 1)[:-1] for a, b in zip(breaks[:-1], breaks[1:])]
    return np.concatenate([*parts, breaks[-1:]])


def grid_vertex_count(surfaces, per_span: int) -> int:
    """Vertices of the span-grid meshes of ``surfaces`` at ``per_span`` segments per knot span (before trim clipping)."""
    spans = [tuple(len(b) - 1 for b in surface.span_breaks()) for surface in surfaces]
    return sum((su * per_span + 1) * (sv * per_span + 1) for su, sv in spans)


def largest_factor(surfaces, per_span: int, most: int, max_vertices: int) -> int:
    """The largest factor f ≤ ``most`` whose span grids at f·``per_span`` segments fit ``max_vertices`` (at least 1)."""
    for factor in range(most, 1, -1):
        if grid_vertex_count(surfaces, factor * per_span) <= max_vertices:
            return factor
    return 1


def grid_faces(nu: int, nv: int) -> np.ndarray:
    """Two triangles per cell of an nu×nv vertex grid (vertex (i, j) has index i·nv + j)."""
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    b, c, d = a + nv, a + nv + 1, a + 1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


#: A reader's triangulation is used only while it follows its face, which the second look's shell (the mesh moved
#: along the surface's normals) needs to enclose the surface: its triangles' 3D area is at least this fraction of the
#: surface's area over their own (u, v) footprint (each triangle's (u, v) area times |S_u × S_v| at its centroid: a
#: mesh that spans its footprint but lies flat across the surface's bend has little area, not a mesh that leaves part
#: of the face out), and those whose plane lies along a corner's normal (`COARSE_COS`) no more than this fraction of
#: its own.
#: Past either the shell no longer encloses the surface: tiny_on_huge.step's 0.02-radius pin, meshed at its 2000 mm
#: part's deflection, was one flat strip along its seam (u = 0..2π chords of no length, no area), its shell a sheet
#: of no thickness, and rays past its silhouette went on to the slab (a 160×90 close-up: 103 pixels up to 88 mm
#: behind Open CASCADE's first hit); a circle cut in two chords would be a strip through the axis, along its normals.
#: The span grid meshes such a face instead.
COARSE_AREA = 0.25
#: A reader's triangulation with a node farther than this fraction of the domain outside it was cut at another period
#: of a closed face (sphere_hole.step's sphere: its nodes at u 1.526-7.809, its domain 1.571-7.854): it leaves a strip
#: along the domain's seam side unmeshed, and rays there passed through the face. The span grid meshes such a face.
OFF_DOMAIN = 1e-6
#: A triangle lies along the surface when a corner's normal makes a cosine below this (60°) with its plane's normal
#: (BRepMesh at `occt.MESH_ANGLE` = 0.5 rad stays within ~0.25 rad). Weighed by area: slivers (a drilled sphere's
#: along its hole) and a cone's triangles at its apex (normals turning about a point) fail it on a sliver of area.
COARSE_COS = 0.5
#: A reader's triangulation must cover its face: each boundary edge of it (a side of one triangle) runs along the
#: trim, its midpoint within this share of its length from the face's loops in (u, v). A chord of a trim edge turning
#: by BRepMesh's angle (`occt.MESH_ANGLE`, 0.5 rad) strays tan(θ/4)/2 = 0.06 of its length from the edge, and the
#: second look's rim boxes enclose that band; a part of the face the triangulation leaves out has sides across the
#: face (OCCT's data/step/trj10_b2-oc-214.stp: a planar face's triangles missed a region 3 × 3.5 of its 16 × 13, and
#: rays there went on to faces up to 67 behind, 11 pixels at 320×180). The span grid meshes such a face.
UNCOVERED_SHARE = 0.25


def reader_mesh(surface: NurbsSurface) -> tuple[np.ndarray, np.ndarray] | None:
    """The face's reader triangulation (``mesh_uv``) as nodes (m, 2) and triangles (k, 3), or None where it has none
    or where it does not follow the face (`COARSE_AREA`, `COARSE_COS`), or where the face has a crease inside
    (`NurbsSurface.creases`): the span grid meshes the face then, its knot lines grid lines.

    A reader's triangles may span a crease (nothing makes its vertices lie on the knot line): they cut the crease's
    corner, and a ray clipping that corner meets the surface twice, close together, in front of the mesh. OCCT's
    data/iges/OCC17026-1.igs, a sweep of a rectangle (degree 1 across it, a crease at each corner): its reader's
    mesh strayed 4,456 from the surface over a part 65,732 across, and 3 pixels at 320×180 kept the far crossing 9
    behind the near one; the span grid's strays 85, and none does."""
    if surface.mesh_uv is None or any(len(lines) for lines in surface.creases):
        return None
    nodes, triangles = surface.mesh_uv
    uv, faces = np.asarray(nodes, dtype=np.float64).reshape(-1, 2), np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return uv, faces
    (u0, u1), (v0, v1) = surface.domain
    slack = OFF_DOMAIN * np.array([u1 - u0, v1 - v0])
    if np.any(uv < np.array([u0, v0]) - slack) or np.any(uv > np.array([u1, v1]) + slack):
        return None
    points = surface.evaluate(uv[:, 0], uv[:, 1]).S
    a, b, c = (points[faces[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    p, q, r = (uv[faces[:, k]] for k in range(3))
    uv_area = np.abs((q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0]))
    centre = (p + q + r) / 3.0
    d = surface.evaluate(centre[:, 0], centre[:, 1])
    expected = float(np.sum(uv_area * np.linalg.norm(np.cross(d.Su, d.Sv), axis=1)))
    total = float(np.sum(area))
    if total < COARSE_AREA * expected:
        return None
    normal = cross / np.maximum(area, np.finfo(float).tiny)[:, None]  # no area: no plane, and no weight below
    corners = surface.normals(uv[:, 0], uv[:, 1])
    cosine = np.min(np.abs(np.einsum("fkj,fj->fk", corners[faces], normal)), axis=1)
    if float(np.sum(area[cosine < COARSE_COS])) > COARSE_AREA * total:
        return None
    return (uv, faces) if _covers_trim(surface, uv, faces) else None


def _covers_trim(surface: NurbsSurface, uv: np.ndarray, faces: np.ndarray) -> bool:
    """Whether a reader's triangulation covers its trimmed face: no boundary edge of it runs across the face, its
    midpoint inside the face farther than `UNCOVERED_SHARE` of its length from the loops (one outside, where the mesh
    overhangs its trim, leaves nothing out: the sweep's bottle.step, its thread's tip 0.03 past it in (u, v)). A face
    without a trim: its domain, which a triangulation of it covers."""
    if surface.trim is None:
        return True
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges, count = np.unique(edges, axis=0, return_counts=True)
    a, b = uv[edges[count == 1, 0]], uv[edges[count == 1, 1]]
    mid_u, mid_v = surface.trim.wrap(0.5 * (a[:, 0] + b[:, 0]), 0.5 * (a[:, 1] + b[:, 1]))
    inside = surface.trim.contains(mid_u, mid_v)
    (u0, u1), (v0, v1) = surface.domain
    reach = UNCOVERED_SHARE * np.linalg.norm(b - a, axis=1) + OFF_DOMAIN * math.hypot(u1 - u0, v1 - v0)
    return not np.any(inside & (surface.trim.boundary_distance(mid_u, mid_v) > reach))


def tessellate_patch(surface: NurbsSurface, patch_index: int, per_span: int, enclose: bool = False,
                     widen: bool = False) -> PatchMesh:
    """A mesh of one patch (of its trimmed face, see the module doc).

    Per vertex ``uv`` (V, 2), ``patch`` (V,) and ``rim`` (V,): the vertices on the face's
    boundary (domain edge, or the trimmed mesh's boundary), where a neighbouring face may join.
    """
    mesh = reader_mesh(surface)
    if mesh is not None:
        uv, faces = mesh
        rim_edges = _boundary_edges(faces)  # on the trim: where a neighbouring face joins
        rim = distinct(rim_edges)
        uv, faces = _with_skirt(uv, faces, surface)
    else:
        breaks_u, breaks_v = surface.span_breaks()
        us, vs = span_samples(breaks_u, per_span), span_samples(breaks_v, per_span)
        uu, vv = np.meshgrid(us, vs, indexing="ij")
        uv = np.stack([uu.ravel(), vv.ravel()], axis=1)
        faces = grid_faces(len(us), len(vs))
        if surface.trim is not None:
            uv, faces = _clip_to_trim(uv, faces, surface.trim)
        rim_edges = _boundary_edges(faces)
        rim = distinct(rim_edges) if surface.trim is not None else _domain_boundary(uv)
    points = surface.evaluate(uv[:, 0], uv[:, 1]).S
    if enclose:
        points = _enclosing(surface, uv, points, faces, rim)
    if widen and mesh is None and surface.trim is None:
        points = _widened(surface, uv, points, faces, rim)
    # The grid as built, never merged: merging would mix vertices of different (u, v).
    return PatchMesh(np.ascontiguousarray(points, dtype=np.float64), np.asarray(faces, dtype=np.int64), uv,
                     np.full(len(uv), patch_index), np.isin(np.arange(len(uv)), rim), np.asarray(rim_edges, dtype=np.int64))


#: Boundary vertices `Tessellation._across_by_query` asks the k-d query for at first (more for points whose nearest do not qualify).
SEAM_NEIGHBOURS = 8


@dataclass(frozen=True)
class Tessellation:
    """All patches' meshes in one vertex/face array, as Embree wants them."""

    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3)
    vertex_uv: np.ndarray  # (V, 2)
    vertex_patch: np.ndarray  # (V,)
    face_patch: np.ndarray  # (F,)
    chord_error: np.ndarray  # per patch: largest mesh-to-surface distance found at edge midpoints
    meshes: tuple[PatchMesh, ...]
    boundary: np.ndarray  # indices of the vertices on a face's mesh boundary (where a neighbour may join)
    edge_length: np.ndarray  # per patch: its longest mesh edge

    @cached_property
    def extent(self) -> float:
        """Diagonal of the bounding box of all patches."""
        return float(np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)))

    def start_parameters(self, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(patch, u, v) interpolated from a triangle's vertices with Embree's barycentrics (`kernels.nurbs.barycentric_uv`)."""
        faces, vertex_uv, face_patch = self.start_arrays
        prim = np.ascontiguousarray(prim, dtype=np.int64)
        u, v = np.empty(len(prim)), np.empty(len(prim))
        kernel.start_parameters(faces, vertex_uv, prim, np.ascontiguousarray(b1, dtype=np.float64),
                                np.ascontiguousarray(b2, dtype=np.float64), u, v)
        return face_patch[prim], u, v

    @cached_property
    def start_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(faces, vertex_uv, face_patch) as the kernels take them (int64, float64, contiguous)."""
        return (np.ascontiguousarray(self.faces, dtype=np.int64), np.ascontiguousarray(self.vertex_uv, dtype=np.float64),
                np.ascontiguousarray(self.face_patch, dtype=np.int64))

    def across_seam(self, points: np.ndarray, patch: np.ndarray, tried: np.ndarray | None = None,
                    uv: np.ndarray | None = None, reach: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """For points on the boundary of ``patch``: the nearest boundary vertex of another patch.

        ``tried`` (N, m) lists patches to pass over as well (neighbours already tried: where
        several faces meet at a corner, their boundary vertices coincide). With the points' own
        ``uv`` (N, 2), a boundary vertex of the same patch counts too when its (u, v) lies more
        than half the patch's domain away: the other side of a closed face's seam (a revolved
        face's u = 0 and u = 2π), where the ray goes on on the same face; a NaN component never
        qualifies (the tracer passes NaN in a direction the face is not closed in, `tracing._seam_sides`).

        ``reach`` (N,): only vertices within that distance of their point count (across a large face
        the search would otherwise walk the face's whole boundary).

        Returns (patch, u, v) of that vertex, where a hit that ran off one face's edge
        can restart on its neighbour, and the distance to it (patch −1 and inf where there
        is no other patch, or where the point is not finite: a diverged Newton step has no vertex nearest it,
        and neither scipy's query nor the tree walk can rank one). A compiled walk of a k-d tree over the
        boundary vertices that skips the vertices that do not qualify (`kernels.rims.nearest_across`). Where two
        qualifying vertices tie (the same squared distance, another face or (u, v)), the order of scipy's k-d
        query decides, as it did when the query served every point (`_across_by_query`: the SEAM_NEIGHBOURS nearest,
        then more for the points whose nearest do not qualify); so every answer is the query's, bit for bit,
        at a fraction of its cost (each query sorted its k nearest whether they qualified or not).
        """
        patch_out = np.full(len(points), -1)
        uv_out = np.full((len(points), 2), np.nan)
        dist_out = np.full(len(points), np.inf)
        # One patch and no far side of its own seam to look for: no other vertex can qualify.
        if len(self.boundary) == 0 or len(points) == 0 or (uv is None and self.single_patch):
            return patch_out, uv_out[:, 0], uv_out[:, 1], dist_out
        finite_rows = np.isfinite(points).all(axis=1)
        if not finite_rows.all():  # the rows that are not finite: no neighbour (the answers above); the rest as ever
            ok = np.flatnonzero(finite_rows)
            patch_out[ok], uv_out[ok, 0], uv_out[ok, 1], dist_out[ok] = self.across_seam(
                points[ok], np.asarray(patch)[ok], None if tried is None else np.asarray(tried)[ok],
                None if uv is None else np.asarray(uv)[ok], None if reach is None else np.asarray(reach)[ok])
            return patch_out, uv_out[:, 0], uv_out[:, 1], dist_out
        lo, hi, start, end, left, order, vertices, finite = self._boundary_kd
        cand_patch = self.vertex_patch[self.boundary]
        boundary_uv, half_span = self._boundary_uv
        points = np.ascontiguousarray(points, dtype=np.float64)
        patch = np.ascontiguousarray(patch, dtype=np.int64)
        uv = np.zeros((0, 2)) if uv is None else np.ascontiguousarray(uv, dtype=np.float64)
        tried = np.zeros((len(points), 0), dtype=np.int64) if tried is None else np.ascontiguousarray(tried, dtype=np.int64)
        reach = np.zeros(0) if reach is None else np.ascontiguousarray(reach, dtype=np.float64)
        best, dist, tie = np.empty(len(points), dtype=np.int64), np.empty(len(points)), np.empty(len(points), dtype=bool)
        rims_kernel.nearest_across(lo, hi, start, end, left, order, vertices, cand_patch, boundary_uv, points, patch, uv,
                                   half_span, tried, reach, best, dist, tie)
        found = best >= 0
        patch_out[found] = cand_patch[best[found]]
        uv_out[found] = self.vertex_uv[self.boundary[best[found]]]
        dist_out[found] = dist[found]
        # Ties, and vertices the distances cannot rank (not finite): the k-d query's answer.
        ask = np.flatnonzero(tie) if finite else np.arange(len(points))
        if len(ask):
            patch_out[ask], uv_out[ask], dist_out[ask] = self._across_by_query(
                points[ask], patch[ask], tried[ask], uv[ask] if len(uv) else uv, reach[ask] if len(reach) else reach)
        return patch_out, uv_out[:, 0], uv_out[:, 1], dist_out

    def _across_by_query(self, points, patch, tried, uv, reach) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`across_seam`'s (patch, (N, 2) uv, distance) by scipy's k-d query (arguments as the kernel takes them): the
        SEAM_NEIGHBOURS nearest, then 8× more for the points whose nearest all fail to qualify
        (`kernels.rims.first_across`: its face, the far side of its own closed face's seam, the faces tried, the reach)."""
        patch_out = np.full(len(points), -1)
        uv_out = np.full((len(points), 2), np.nan)
        dist_out = np.full(len(points), np.inf)
        tree, cand_patch = self._boundary_tree
        boundary_uv, half_span = self._boundary_uv
        todo = np.arange(len(points))
        k = SEAM_NEIGHBOURS
        while len(todo):
            k = min(k, len(self.boundary))
            dist, nearest = tree.query(points[todo], k=k)
            dist, nearest = dist.reshape(len(todo), k), nearest.reshape(len(todo), k)
            first = np.empty(len(todo), dtype=np.int64)
            rims_kernel.first_across(nearest, dist, cand_patch, boundary_uv, patch[todo], uv[todo] if len(uv) else uv,
                                     half_span, tried[todo], reach[todo] if len(reach) else reach, first)
            found = first >= 0
            rows, best = todo[found], nearest[found, first[found]]
            patch_out[rows] = cand_patch[best]
            uv_out[rows] = self.vertex_uv[self.boundary[best]]
            dist_out[rows] = dist[found, first[found]]
            if k == len(self.boundary):
                break
            more = ~found if len(reach) == 0 else ~found & (dist[:, -1] <= reach[todo])  # some within reach not seen yet
            todo, k = todo[more], 8 * k
        return patch_out, uv_out, dist_out

    @cached_property
    def single_patch(self) -> bool:
        """Every vertex on one patch (no other face to look across to)."""
        return bool(len(self.vertex_patch) == 0 or np.all(self.vertex_patch == self.vertex_patch[0]))

    @cached_property
    def has_rim_neighbours(self) -> bool:
        """Some boundary vertex has another face's boundary vertex across its rim (`rim_neighbour`)."""
        return bool((self.rim_neighbour[0] >= 0).any())

    @cached_property
    def rim_face(self) -> np.ndarray:
        """(F,) bool: the triangles with a corner on their face's mesh boundary (where a neighbouring face may join)."""
        return self.on_rim[self.faces].any(axis=1)

    @cached_property
    def on_rim(self) -> np.ndarray:
        """(V,) bool: the vertices on their face's mesh boundary (`boundary`)."""
        on_rim = np.zeros(len(self.vertices), dtype=bool)
        on_rim[self.boundary] = True
        return on_rim

    @cached_property
    def rim_path(self) -> np.ndarray:
        """(V, k): per vertex the other ends of the mesh boundary edges (`PatchMesh.rim_edges`) it is an end of,
        −1 padded (two for a vertex on a simple loop; none off the rim): the face's boundary polyline near it."""
        offsets = np.cumsum([0] + [len(m.vertices) for m in self.meshes])
        edges = np.concatenate([np.zeros((0, 2), dtype=np.int64)]
                               + [m.rim_edges + off for m, off in zip(self.meshes, offsets)])
        ends = np.concatenate([edges, edges[:, ::-1]])
        ends = ends[np.argsort(ends[:, 0], kind="stable")]
        first = np.searchsorted(ends[:, 0], ends[:, 0])  # where each vertex's run of edges starts
        rank = np.arange(len(ends)) - first
        path = np.full((len(self.vertices), int(rank.max(initial=-1)) + 1), -1, dtype=np.int64)
        path[ends[:, 0], rank] = ends[:, 1]
        return path

    @cached_property
    def rim_neighbour(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per vertex (V,): the nearest boundary vertex of another face to each boundary vertex (`across_seam`),
        as (patch, (V, 2) uv, distance); patch −1 and distance inf elsewhere. Built once, on first use."""
        patch, uv, dist = np.full(len(self.vertices), -1), np.full((len(self.vertices), 2), np.nan), np.full(len(self.vertices), np.inf)
        pn, un, vn, gap = self.across_seam(self.vertices[self.boundary], self.vertex_patch[self.boundary])
        patch[self.boundary], uv[self.boundary, 0], uv[self.boundary, 1], dist[self.boundary] = pn, un, vn, gap
        return patch, uv, dist

    def patch_bounds(self, values: np.ndarray, patches: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per patch the least and the greatest of a per-vertex quantity (V, d), each (patches, d): ±inf for a patch
        with no vertex, NaN where one of its values is. One pass over the vertices (a mask per patch cost 2.1 s on
        pythonocc-demos' 11752.stp, 1,018 faces). ``patches``: the count (default: the highest patch index + 1)."""
        patches = int(self.vertex_patch.max(initial=-1)) + 1 if patches is None else patches
        low, high = np.full((patches, values.shape[1]), np.inf), np.full((patches, values.shape[1]), -np.inf)
        np.minimum.at(low, self.vertex_patch, values)
        np.maximum.at(high, self.vertex_patch, values)
        return low, high

    @cached_property
    def _domain_span(self) -> np.ndarray:
        """(patches, 2): the extent of each patch's vertices in u and in v."""
        low, high = self.patch_bounds(self.vertex_uv)  # NaN propagates, as through np.ptp
        return np.where((np.bincount(self.vertex_patch, minlength=len(low)) > 0)[:, None], high - low, 0.0)

    @cached_property
    def _boundary_uv(self) -> tuple[np.ndarray, np.ndarray]:
        """(the boundary vertices' (u, v) (B, 2), half of each patch's `_domain_span` (patches, 2)) for `across_seam`."""
        return np.ascontiguousarray(self.vertex_uv[self.boundary], dtype=np.float64), 0.5 * self._domain_span

    @cached_property
    def _boundary_tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.vertices[self.boundary]), self.vertex_patch[self.boundary]

    @cached_property
    def _boundary_kd(self) -> tuple[np.ndarray, ...]:
        """The boundary vertices' k-d tree for `across_seam` (`kernels.rims.kd_build`): its nodes' boxes (lo, hi),
        runs (start, end) and first children (left), the vertex order, the vertices (B, 3) and whether all are finite
        (else the k-d query answers every point)."""
        vertices = np.ascontiguousarray(self.vertices[self.boundary], dtype=np.float64)
        size = 4 * len(vertices) // rims_kernel.KD_LEAF + 2  # nodes: leaves hold over KD_LEAF / 2 vertices each
        lo, hi = np.empty((size, 3)), np.empty((size, 3))
        start, end, left = (np.empty(size, dtype=np.int64) for _ in range(3))
        order = np.empty(len(vertices), dtype=np.int64)
        count = rims_kernel.kd_build(vertices, rims_kernel.KD_LEAF, order, lo, hi, start, end, left) if len(vertices) else 0
        return lo[:count], hi[:count], start[:count], end[:count], left[:count], order, vertices, bool(np.isfinite(vertices).all())


#: `_chord_error` reports the parameter-midpoint measure |S(ū) − chord midpoint| unless the projected distances show it
#: overstates the mesh-to-surface distance by more than this factor (a parameterisation far from uniform or isotropic,
#: where S(ū) lies along the surface from the chord's nearest point: the revolved_seam sweep part read 6.3 for 0.27).
#: Within it the measure stands as it was (an upper bound at every sample), so ordinary faces' figures keep their bits.
CHORD_OVERSTATED = 2.0
#: Samples `_chord_error` projects per round, those with the largest parameter-midpoint bound first.
CHORD_CHUNK = 256


def _chord_error(surface: NurbsSurface, mesh: PatchMesh) -> float:
    """Largest distance between the mesh and the surface, sampled at the midpoints of every triangle edge and the
    triangles' centroids, and at the vertices (which `_enclosing` moves off the surface).

    Edge midpoints: a chord strays farthest from the surface at its middle. Each sample's distance is bounded
    from above by the surface point of its (u, v) midpoint, |S(ū) − chord midpoint|: the figure reported while
    that bound is within `CHORD_OVERSTATED` of the measured distance. Measured, not bounded, where it is not: each
    sample point p projected onto the surface (`seams.closest_on_surface`, Newton on ½|S − p|², Piegl & Tiller
    eq. 6.6–6.7, from ū; the nearer of S(ū) and the foot, so never below the true distance) and, the other way, the
    distance of S(ū) from its chord (a point of the surface to the mesh). The samples are taken largest bound
    first, in rounds of `CHORD_CHUNK`, until no bound left exceeds the largest distance measured.
    """
    from .seams import closest_on_surface

    edges = mesh.edges_unique
    uv = mesh.uv[edges].mean(axis=1)
    exact = surface.evaluate(uv[:, 0], uv[:, 1]).S
    chord_mid = mesh.vertices[edges].mean(axis=1)
    vertex_uv = mesh.uv
    at_vertices = np.max(np.linalg.norm(surface.evaluate(vertex_uv[:, 0], vertex_uv[:, 1]).S - mesh.vertices, axis=1),
                         initial=0.0)
    along_edges = np.linalg.norm(exact - chord_mid, axis=1)
    bound = float(max(np.max(along_edges, initial=0.0), at_vertices))
    found = at_vertices
    if bound <= found or len(mesh.faces) == 0:
        return bound
    centre_uv = mesh.uv[mesh.faces].mean(axis=1)
    centroid = mesh.vertices[mesh.faces].mean(axis=1)
    at_centre = surface.evaluate(centre_uv[:, 0], centre_uv[:, 1]).S
    points, starts, images = (np.concatenate(x) for x in ((chord_mid, centroid), (uv, centre_uv), (exact, at_centre)))
    cheap = np.concatenate([along_edges, np.linalg.norm(at_centre - centroid, axis=1)])
    order = np.argsort(-cheap, kind="stable")
    for first in range(0, len(order), CHORD_CHUNK):
        rows = order[first:first + CHORD_CHUNK]
        if cheap[rows[0]] <= found or CHORD_OVERSTATED * found >= bound:
            break
        foot = closest_on_surface(surface, points[rows], starts[rows])
        projected = np.linalg.norm(surface.evaluate(foot[:, 0], foot[:, 1]).S - points[rows], axis=1)
        distance = np.minimum(cheap[rows], projected)
        on_edge = rows < len(edges)  # S(ū) of an edge: its distance from the chord bounds the surface-to-mesh side
        ends = edges[rows[on_edge]]
        distance[on_edge] = np.maximum(distance[on_edge], _to_segment(images[rows[on_edge]], mesh.vertices[ends[:, 0]],
                                                                      mesh.vertices[ends[:, 1]]))
        found = max(found, float(distance.max()))
    return bound if CHORD_OVERSTATED * found >= bound else found


def _to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances of points p (N, 3) from the segments ab: to the foot a + s(b − a), s = clamp((p − a)·(b − a)/|b − a|², 0, 1)."""
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip(np.nan_to_num(np.einsum("ij,ij->i", p - a, ab) / length2), 0.0, 1.0)
    return np.linalg.norm(p - (a + s[:, None] * ab), axis=1)


#: `_enclosing` moves vertices by this many times the largest chord deviation of their edges: a
#: triangle's interior can stray a little farther from its plane than its edges' midpoints do.
ENCLOSE_MARGIN = 1.25
#: `_widened` divides by the sine of the angle between S_u and S_v (the reach across the edge): below this
#: (partials within 6° of each other, or a degenerate point) it does not grow further.
WIDEN_MIN_SINE = 0.1


def _enclosing(surface: NurbsSurface, uv: np.ndarray, points: np.ndarray, faces: np.ndarray, rim: np.ndarray) -> np.ndarray:
    """Vertices moved along the normal to the convex side of the surface, so the mesh encloses it there.

    A mesh with its vertices on the surface lies inside it where the surface is convex: rays near
    a silhouette pass outside the mesh but meet the surface, and would miss (a chord-approximate
    silhouette). Each vertex moves to the side its edges' chords fall short on (the sign of the
    deviation S(mid) − chord midpoint along its normal, the larger side where a saddle has both),
    by ENCLOSE_MARGIN times the largest such deviation: the mesh then covers the surface there and
    the refinement moves every hit back onto it. Planes do not move.
    """
    if len(faces) == 0:
        return points
    edges = unique_edges(faces)
    mid = uv[edges].mean(axis=1)
    deviation = surface.evaluate(mid[:, 0], mid[:, 1]).S - points[edges].mean(axis=1)
    normal = surface.normals(uv[:, 0], uv[:, 1])
    out = np.zeros(len(points))
    into = np.zeros(len(points))
    for end in (0, 1):
        along = np.einsum("ij,ij->i", deviation, normal[edges[:, end]])
        np.maximum.at(out, edges[:, end], along)
        np.minimum.at(into, edges[:, end], along)
    shift = np.where(out >= -into, out, into)
    shift[rim] = 0.0  # the face's edge stays where it is: moved along the normal it would slide across the view
    return points + ENCLOSE_MARGIN * shift[:, None] * normal


def _widened(surface: NurbsSurface, uv: np.ndarray, points: np.ndarray, faces: np.ndarray, rim: np.ndarray) -> np.ndarray:
    """A span grid's domain-edge vertices moved out past the edge in the tangent plane, so its chords cover the edge.

    The edge's chords cut inside the curved edge by their sagitta: a ray meeting the surface
    between chord and edge met no triangle (the cylinder scene at 320×180: 6e-5 inside v = 1, at
    |N·D| = 0.49). Each edge vertex moves along the outward parameter direction's image
    (u, v steps of ±1 at u₀/u₁, v₀/v₁, through S_u/|S_u| and S_v/|S_v|) by ENCLOSE_MARGIN times its edges'
    largest chord deviation over the sine of the partials' angle (at least `WIDEN_MIN_SINE`):
    the reach across the edge is then at least the sagitta. Rays there that miss the face are
    refined off its domain and restarted across the seam or missed (tracing.py), as on a reader's skirt.
    """
    (u0, u1), (v0, v1) = surface.domain
    wu = np.where(uv[rim, 0] == u0, -1.0, np.where(uv[rim, 0] == u1, 1.0, 0.0))
    wv = np.where(uv[rim, 1] == v0, -1.0, np.where(uv[rim, 1] == v1, 1.0, 0.0))
    edges = _boundary_edges(faces)
    mid = uv[edges].mean(axis=1)
    deviation = np.linalg.norm(surface.evaluate(mid[:, 0], mid[:, 1]).S - points[edges].mean(axis=1), axis=1)
    reach = np.zeros(len(points))
    for end in (0, 1):
        np.maximum.at(reach, edges[:, end], deviation)
    d = surface.evaluate(uv[rim, 0], uv[rim, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        eu = d.Su / np.linalg.norm(d.Su, axis=1, keepdims=True)
        ev = d.Sv / np.linalg.norm(d.Sv, axis=1, keepdims=True)
        out = wu[:, None] * eu + wv[:, None] * ev
        sine = np.maximum(np.linalg.norm(np.cross(eu, ev), axis=1), WIDEN_MIN_SINE)
    shift = np.nan_to_num(out * (ENCLOSE_MARGIN * reach[rim] / sine)[:, None])  # degenerate points: not moved
    moved = points.copy()
    moved[rim] += shift
    return moved


def tessellate(surfaces: list[NurbsSurface] | tuple[NurbsSurface, ...], per_span,
               enclose: bool = False, widen: bool = False) -> Tessellation:
    """All patches' meshes at ``per_span`` segments per knot span (one count, or one per patch); ``enclose``: vertices
    moved so the mesh covers the surface (`_enclosing`), for the exact tracer; ``widen``: a domain's edge vertices
    moved out past the edge too (`_widened`), for the second look."""
    counts = np.broadcast_to(np.asarray(per_span, dtype=np.int64), (len(surfaces),))
    meshes = tuple(tessellate_patch(s, k, int(n), enclose, widen) for k, (s, n) in enumerate(zip(surfaces, counts)))
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    return Tessellation(
        vertices=np.concatenate([m.vertices for m in meshes]),
        faces=np.concatenate([m.faces + off for m, off in zip(meshes, offsets)]),
        vertex_uv=np.concatenate([m.uv for m in meshes]),
        vertex_patch=np.concatenate([m.patch for m in meshes]),
        face_patch=np.concatenate([np.full(len(m.faces), k) for k, m in enumerate(meshes)]),
        chord_error=np.array([_chord_error(s, m) for s, m in zip(surfaces, meshes)]),
        meshes=meshes,
        boundary=np.concatenate([np.flatnonzero(m.rim) + off for m, off in zip(meshes, offsets)]),
        edge_length=np.array([float(m.edges_unique_length.max(initial=0.0)) for m in meshes]),
    )


#: Width of the skirt around a reader's mesh, in lengths of the boundary edge it hangs from.
#: A boundary chord cuts inside a face bulging beyond it by its sagitta, L·tan(θ/4)/2 ≈ Lθ/8 for a
#: loop turning by θ along the edge; the readers' meshes turn by at most 0.5 rad per boundary edge
#: (BRepMesh's angular deflection, `exchange.occt.MESH_ANGLE`), a sagitta of L/16 at most: a quarter
#: edge covers the face to its trim 4× over. Narrower is faster: every ray through a skirt is refined
#: onto its face, found off the trim and restarted on the neighbours before it goes on (on
#: parts/plate.step the top plane's skirts over its 64 holes took 44,000 of 293,000 candidates at
#: one edge wide). The pixel-centre first hits of the shipped and the 49 sweep parts at 320×180 are the
#: same at 1, 0.25 and 0.1 edges (`tests/test_cad_sweep_kinds.py` checks the cover).
SKIRT_EDGES = 0.25
#: `_with_skirt` steps in the surface's metric unless EG − F² ≤ this × EG, sin² of the angle between S_u and S_v
#: (scale-free): at a pole (S_u = 0) or where the partials are parallel the metric cannot size the step.
SKIRT_SINGULAR = 1e-6


def _with_skirt(uv: np.ndarray, faces: np.ndarray, surface: NurbsSurface) -> tuple[np.ndarray, np.ndarray]:
    """A reader's mesh with a strip of triangles outside every boundary edge, in (u, v) clamped to the domain.

    The reader's boundary nodes lie on the trim, its boundary edges are chords of it: rays between
    chord and trim would miss the mesh and never reach the exact face. The strip (SKIRT_EDGES wide)
    lies on the untrimmed surface beyond the face, so rays there are refined and tested against the
    trim like any other (tracing.py). The skirt's vertices come after the reader's.

    Perpendicular to the edge and as long as it on the surface, not in (u, v): with the first fundamental form
    I = [[E, F], [F, G]] at the edge's middle, the step w ∝ rot(I e) has eᵀ I w = 0, scaled to wᵀ I w = eᵀ I e.
    (u and v have their own units: on a cylinder u is an angle and v a length, and a perpendicular in (u, v)
    threw the skirt of a 10 m part's edge round the cylinder.) Where I is singular along the step (a pole),
    the (u, v) perpendicular stands in.
    """
    if len(faces) == 0:
        return uv, faces
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    third = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
    once = _once(edges)
    a, b, c = edges[once, 0], edges[once, 1], third[once]
    along = uv[b] - uv[a]
    middle = surface.evaluate(*(0.5 * (uv[a] + uv[b])).T)
    E = np.einsum("ij,ij->i", middle.Su, middle.Su)
    F = np.einsum("ij,ij->i", middle.Su, middle.Sv)
    G = np.einsum("ij,ij->i", middle.Sv, middle.Sv)
    Ie = np.column_stack([E * along[:, 0] + F * along[:, 1], F * along[:, 0] + G * along[:, 1]])
    length2 = np.einsum("ij,ij->i", along, Ie)  # eᵀ I e: the edge's squared length on the surface
    out = np.column_stack([Ie[:, 1], -Ie[:, 0]])
    out_length2 = E * out[:, 0] ** 2 + 2 * F * out[:, 0] * out[:, 1] + G * out[:, 1] ** 2
    metric = (E * G - F * F > SKIRT_SINGULAR * E * G) & (length2 > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(metric[:, None], out * np.sqrt(length2 / out_length2)[:, None], np.column_stack([along[:, 1], -along[:, 0]]))
    # Both steps lie right of a→b in (u, v) (cross(e, rot(I e)) = −eᵀIe < 0; cross(e, rot e) = −|e|²): turned where
    # the triangle's third vertex lies there too. A side test, not out·(c − a): a step perpendicular on the surface is
    # not perpendicular in (u, v), and the dot product put skirts over their own face (E/G = 100, diagonal edges).
    side = along[:, 0] * (uv[c] - uv[a])[:, 1] - along[:, 1] * (uv[c] - uv[a])[:, 0]
    out *= np.where(side < 0, -1.0, 1.0)[:, None]
    (u0, u1), (v0, v1) = surface.domain
    lo, hi = np.array([u0, v0]), np.array([u1, v1])
    a_out = np.clip(uv[a] + SKIRT_EDGES * out, lo, hi)
    b_out = np.clip(uv[b] + SKIRT_EDGES * out, lo, hi)
    k = len(uv) + 2 * np.arange(len(a))
    skirt = np.concatenate([np.column_stack([a, b, k + 1]), np.column_stack([a, k + 1, k])])
    return np.concatenate([uv, np.stack([a_out, b_out], axis=1).reshape(-1, 2)]), np.concatenate([faces, skirt])


def _clip_to_trim(uv: np.ndarray, faces: np.ndarray, trim) -> tuple[np.ndarray, np.ndarray]:
    """The grid's triangles that overlap the trimmed face in (u, v), and the vertices they use (renumbered).

    Overlap of each triangle with the trim polygon (GEOS, vectorised), not a vertex test: a
    triangle crossing a thin part of the face with all three corners outside still carries it. A triangle with a
    corner on the face overlaps it: only the others are built as polygons (on the 45 × 45-span dense_net.step's
    validate mesh, 9.3M triangles, 3 % of them off its one hole's edge: 38 s of GEOS polygons before).
    """
    import shapely

    on_face = trim.contains(uv[:, 0], uv[:, 1])  # per vertex (wrapped into the period, as below)
    keep = on_face[faces].any(axis=1)
    ask = np.flatnonzero(~keep)
    corners = uv[faces[ask]]  # (F', 3, 2)
    if trim.u_period or trim.v_period:  # a periodic face's loops live in one period: test wrapped corners
        wu, wv = trim.wrap(corners[..., 0], corners[..., 1])
        corners = np.stack([wu, wv], axis=-1)
    triangles = shapely.polygons(np.concatenate([corners, corners[:, :1]], axis=1))
    keep[ask] = trim.overlaps(triangles)
    if trim.u_period or trim.v_period:  # a wrapped triangle may straddle the period's cut: keep it too
        span = np.ptp(corners, axis=1)
        keep[ask] |= (span[:, 0] > 0.5 * (trim.u_period or np.inf)) | (span[:, 1] > 0.5 * (trim.v_period or np.inf))
    faces = faces[keep]
    used = distinct(faces)
    renumber = np.full(len(uv), -1)
    renumber[used] = np.arange(len(used))
    return uv[used], renumber[faces]


def _once(edges: np.ndarray) -> np.ndarray:
    """Rows of an (E, 2) edge list whose edge (either direction) occurs once: the mesh's boundary edges.

    In the order of the sorted pair (larger vertex, then smaller): trimesh's ``group_rows(..., require_count=1)``,
    which this replaces, gives that order, and the skirt's vertices (`_with_skirt`) are numbered by it.
    """
    if len(edges) == 0:
        return np.zeros(0, dtype=np.int64)
    keys, _ = _edge_keys(np.sort(edges, axis=1), 1)
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    first = np.r_[True, keys[1:] != keys[:-1]]  # first of a run of equal edges
    last = np.r_[first[1:], True]
    return order[first & last]


def _boundary_edges(faces: np.ndarray) -> np.ndarray:
    """(B, 2) vertex pairs of the edges used by one triangle only."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return edges[_once(edges)]


def _domain_boundary(uv: np.ndarray) -> np.ndarray:
    """Indices of the grid vertices on the patch's parameter-domain boundary."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    return np.flatnonzero(np.any((uv == lo) | (uv == hi), axis=1))
