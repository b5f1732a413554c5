"""Compiled distances from mesh hits to their face's mesh boundary (`trace.tracing._rim_corner`).

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
