"""Compiled distances from mesh hits to their face's mesh boundary (`trace.tracing._rim_corner`).

For a point p on triangle (c₀, c₁, c₂) and a boundary edge from corner c to w, the distance is
|p − c − s(w − c)| with s = clamp((p − c)·(w − c)/|w − c|², 0, 1), the foot on the segment.
"""

from __future__ import annotations

import math

from numba import njit

from . import JIT


@njit(**JIT)
def rim_distances(faces, vertices, on_rim, path, prim, points, dist, corner):
    """Per point i on triangle prim[i]: ``dist[i]`` the least distance to the boundary edges (corner, path[corner, k])
    from its triangle's corners (inf where none), ``corner[i]`` its corner on the rim nearest the point (−1: none;
    the first of equals)."""
    for i in range(prim.shape[0]):
        best, near, near_d = math.inf, -1, math.inf
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        for j in range(3):
            c = faces[prim[i], j]
            if not on_rim[c]:
                continue
            r0, r1, r2 = p0 - vertices[c, 0], p1 - vertices[c, 1], p2 - vertices[c, 2]
            d = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            if d < near_d:
                near, near_d = c, d
            for k in range(path.shape[1]):
                w = path[c, k]
                if w < 0:
                    continue
                a0, a1, a2 = vertices[w, 0] - vertices[c, 0], vertices[w, 1] - vertices[c, 1], vertices[w, 2] - vertices[c, 2]
                aa = a0 * a0 + a1 * a1 + a2 * a2
                s = (r0 * a0 + r1 * a1 + r2 * a2) / aa if aa > 0.0 else 0.0
                s = min(max(s, 0.0), 1.0)
                e0, e1, e2 = r0 - s * a0, r1 - s * a1, r2 - s * a2
                best = min(best, math.sqrt(e0 * e0 + e1 * e1 + e2 * e2))
        dist[i], corner[i] = best, near
