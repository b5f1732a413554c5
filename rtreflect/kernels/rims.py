"""Compiled distances from mesh hits to their face's mesh boundary (`trace.tracing._rim_corner`), and the choice of
the boundary vertex across a face's edge among a k-d query's nearest (`geometry.tessellation.Tessellation.across_seam`).

For a point p and a segment from vertex a to b, the distance is |p − a − s(b − a)| with
s = clamp((p − a)·(b − a)/|b − a|², 0, 1), the foot on the segment.
"""

from __future__ import annotations

import math

from .compiled import njit

from . import JIT


@njit(inline="always", **JIT)
def _segment_distance(vertices, a, b, p0, p1, p2):
    """Distance from p to the segment from vertex a to vertex b."""
    r0, r1, r2 = p0 - vertices[a, 0], p1 - vertices[a, 1], p2 - vertices[a, 2]
    a0, a1, a2 = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
    aa = a0 * a0 + a1 * a1 + a2 * a2
    s = (r0 * a0 + r1 * a1 + r2 * a2) / aa if aa > 0.0 else 0.0
    s = min(max(s, 0.0), 1.0)
    e0, e1, e2 = r0 - s * a0, r1 - s * a1, r2 - s * a2
    return math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)


@njit(**JIT, aot=("void(i8[:, ::1], f8[:, ::1], b1[::1], i8[:, ::1], i8[::1], f8[:, ::1], f8[::1], f8[::1], i8[::1])",))
def rim_distances(faces, vertices, on_rim, path, prim, points, dist, chords, corner):
    """Per point i on triangle prim[i]: ``dist[i]`` the least distance to the boundary edges (c, path[c, k]) from its
    triangle's corners c on the rim and to the triangle's edges with one end on the rim; ``chords[i]`` to its
    triangle's edges with both ends on the rim (inf where none); ``corner[i]`` its corner on the rim nearest the
    point (−1: none; the first of equals)."""
    for i in range(prim.shape[0]):
        best, chord, near, near_d = math.inf, math.inf, -1, math.inf
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        for j in range(3):
            c, nxt = faces[prim[i], j], faces[prim[i], (j + 1) % 3]
            if on_rim[c] != on_rim[nxt]:
                best = min(best, _segment_distance(vertices, c, nxt, p0, p1, p2))
            elif on_rim[c]:
                chord = min(chord, _segment_distance(vertices, c, nxt, p0, p1, p2))
            if not on_rim[c]:
                continue
            r0, r1, r2 = p0 - vertices[c, 0], p1 - vertices[c, 1], p2 - vertices[c, 2]
            d = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            if d < near_d:
                near, near_d = c, d
            for k in range(path.shape[1]):
                if path[c, k] >= 0:
                    best = min(best, _segment_distance(vertices, c, path[c, k], p0, p1, p2))
        dist[i], chords[i], corner[i] = best, chord, near


@njit(**JIT, aot=(
    "void(i8[:, ::1], f8[:, ::1], i8[::1], f8[:, ::1], i8[::1], f8[:, ::1], f8[:, ::1], i8[:, ::1], f8[::1], i8[::1])",
))
def first_across(nearest, dist, cand_patch, boundary_uv, patch, uv, half_span, tried, reach, first):
    """Per row i of a k-d query (``nearest``, ``dist`` (n, k), by distance): ``first[i]`` the first column whose
    boundary vertex qualifies for `Tessellation.across_seam`, −1 where none does. It qualifies where its face
    ``cand_patch`` is not ``patch[i]`` (or, with ``uv`` (n, 2) given (else (0, 2)), its ``boundary_uv`` lies more than
    ``half_span[patch[i]]`` from ``uv[i]`` in u or v: the far side of a closed face's seam), is none of ``tried[i]``,
    and lies within ``reach[i]`` (``reach`` empty: any distance)."""
    with_uv, with_reach = uv.shape[0] > 0, reach.shape[0] > 0
    for i in range(nearest.shape[0]):
        first[i] = -1
        p = patch[i]
        for j in range(nearest.shape[1]):
            c = nearest[i, j]
            q = cand_patch[c]
            other = q != p
            if with_uv and not other:
                other = (abs(boundary_uv[c, 0] - uv[i, 0]) > half_span[p, 0]
                         or abs(boundary_uv[c, 1] - uv[i, 1]) > half_span[p, 1])
            if other:
                for m in range(tried.shape[1]):
                    if q == tried[i, m]:
                        other = False
                        break
            if other and with_reach:
                other = dist[i, j] <= reach[i]
            if other:
                first[i] = j
                break
