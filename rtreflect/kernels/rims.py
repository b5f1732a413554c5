"""Compiled distances from mesh hits to their face's mesh boundary (`trace.tracing._rim_corner`), and the boundary
vertex across a face's edge (`geometry.tessellation.Tessellation.across_seam`): the nearest that qualifies, by a
k-d tree over the boundary vertices (`kd_build`, `nearest_across`), or the first that qualifies among a k-d query's
nearest (`first_across`).

For a point p and a segment from vertex a to b, the distance is |p − a − s(b − a)| with
s = clamp((p − a)·(b − a)/|b − a|², 0, 1), the foot on the segment.

The k-d tree (Bentley 1975; Friedman, Bentley and Finkel 1977: split each box at the median of its widest
coordinate, search the nearer child first and skip a box farther than the best found) ranks vertices by the
squared distance ((x₀ − y₀)² + (x₁ − y₁)²) + (x₂ − y₂)², summed in that order, as scipy's cKDTree does: the same
float64 values, so the nearest qualifying vertex and its distance are those of the k-d query and `first_across`.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import njit

from . import JIT

#: Boundary vertices per leaf of `kd_build`'s tree: distance tests per leaf against box tests per node (8, 16, 32:
#: 0.048, 0.047, 0.048 s for the plate's 79,000 seam queries at 960×540).
KD_LEAF = 16
#: Depth of the tree walks' node stacks: a median split halves a box's vertices, so a tree over 2⁶⁰ vertices is
#: 60 deep, and a depth-first walk holds at most one pending sibling per level.
KD_STACK = 128


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


@njit(inline="always", **JIT)
def _other_face(c, i, cand_patch, boundary_uv, patch, uv, half_span, tried, with_uv):
    """Boundary vertex c qualifies for point i, its distance aside: its face ``cand_patch[c]`` is not ``patch[i]``
    (or, ``with_uv``, its (u, v) lies more than half the face's span from ``uv[i]``: the far side of a closed face's
    seam), and is none of ``tried[i]``."""
    p, q = patch[i], cand_patch[c]
    other = q != p
    if with_uv and not other:
        other = abs(boundary_uv[c, 0] - uv[i, 0]) > half_span[p, 0] or abs(boundary_uv[c, 1] - uv[i, 1]) > half_span[p, 1]
    if other:
        for m in range(tried.shape[1]):
            if q == tried[i, m]:
                return False
    return other


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
        for j in range(nearest.shape[1]):
            if (_other_face(nearest[i, j], i, cand_patch, boundary_uv, patch, uv, half_span, tried, with_uv)
                    and (not with_reach or dist[i, j] <= reach[i])):
                first[i] = j
                break


@njit(**JIT, aot=("i8(f8[:, ::1], i8, i8[::1], f8[:, ::1], f8[:, ::1], i8[::1], i8[::1], i8[::1])",))
def kd_build(points, leaf, order, lo, hi, start, end, left):
    """A k-d tree over ``points`` (n, 3) (module doc); returns its node count. ``order`` (n,) the points' indices,
    each node's a run order[start:end]; per node its tight box ``lo``, ``hi`` (rows ≥ 4n/leaf + 2) and its first child
    ``left`` (the second is left + 1; −1: a leaf, at most ``leaf`` points). A box splits at the median of its widest
    coordinate (a stable sort: ties keep their index order)."""
    n = points.shape[0]
    for j in range(n):
        order[j] = j
    start[0], end[0] = 0, n
    stack = np.empty(KD_STACK, dtype=np.int64)
    stack[0], top, count = 0, 1, 1
    while top > 0:
        top -= 1
        node = stack[top]
        s, e = start[node], end[node]
        for d in range(3):
            lo[node, d], hi[node, d] = math.inf, -math.inf
        for j in range(s, e):
            for d in range(3):
                lo[node, d] = min(lo[node, d], points[order[j], d])
                hi[node, d] = max(hi[node, d], points[order[j], d])
        left[node] = -1
        if e - s <= leaf:
            continue
        dim = 0
        for d in range(1, 3):
            if hi[node, d] - lo[node, d] > hi[node, dim] - lo[node, dim]:
                dim = d
        keys = np.empty(e - s)
        for j in range(s, e):
            keys[j - s] = points[order[j], dim]
        run = order[s:e][np.argsort(keys, kind="mergesort")]
        order[s:e] = run
        mid = (s + e) // 2
        left[node] = count
        start[count], end[count], start[count + 1], end[count + 1] = s, mid, mid, e
        stack[top], stack[top + 1] = count + 1, count  # the first child is walked first
        top += 2
        count += 2
    return count


@njit(inline="always", **JIT)
def _box_distance2(lo, hi, node, x0, x1, x2):
    """Squared distance from x to the node's box, as `_distance2` sums it: at most that of any point inside (each
    term's float64 operations are monotonic), so a box farther than the best is skipped without losing a tie."""
    g0 = max(lo[node, 0] - x0, x0 - hi[node, 0], 0.0)
    g1 = max(lo[node, 1] - x1, x1 - hi[node, 1], 0.0)
    g2 = max(lo[node, 2] - x2, x2 - hi[node, 2], 0.0)
    return g0 * g0 + g1 * g1 + g2 * g2


@njit(**JIT, aot=(
    "void(f8[:, ::1], f8[:, ::1], i8[::1], i8[::1], i8[::1], i8[::1], f8[:, ::1], i8[::1], f8[:, ::1], f8[:, ::1], "
    "i8[::1], f8[:, ::1], f8[:, ::1], i8[:, ::1], f8[::1], i8[::1], f8[::1], b1[::1])",
))
def nearest_across(lo, hi, start, end, left, order, vertices, cand_patch, boundary_uv, points, patch, uv, half_span,
                   tried, reach, best, dist, tie):
    """Per point i: ``best[i]`` the boundary vertex (row of ``vertices``, in `kd_build`'s tree) nearest the point
    among those that qualify as in `first_across` (its face, the far side of a closed face's seam, ``tried``,
    within ``reach``), −1 where none does; ``dist[i]`` its distance (inf: none); ``tie[i]`` True where another
    qualifying vertex lies at exactly the same squared distance with another face or (u, v): which of them a k-d
    query lists first is its heap's choice, not the geometry's (`Tessellation.across_seam` asks the query then)."""
    with_uv, with_reach = uv.shape[0] > 0, reach.shape[0] > 0
    stack, box = np.empty(KD_STACK, dtype=np.int64), np.empty(KD_STACK)  # pending nodes and their boxes' distances
    for i in range(points.shape[0]):
        x0, x1, x2 = points[i, 0], points[i, 1], points[i, 2]
        b, b2, tied = -1, math.inf, False
        stack[0], box[0], top = 0, _box_distance2(lo, hi, 0, x0, x1, x2), 1
        while top > 0:
            top -= 1
            node, g = stack[top], box[top]
            if g > b2 or (with_reach and math.sqrt(g) > reach[i]):
                continue
            first = left[node]
            if first >= 0:  # the nearer child on top of the stack
                g0, g1 = _box_distance2(lo, hi, first, x0, x1, x2), _box_distance2(lo, hi, first + 1, x0, x1, x2)
                if g0 <= g1:
                    stack[top], box[top], stack[top + 1], box[top + 1] = first + 1, g1, first, g0
                else:
                    stack[top], box[top], stack[top + 1], box[top + 1] = first, g0, first + 1, g1
                top += 2
                continue
            for j in range(start[node], end[node]):
                c = order[j]
                e0, e1, e2 = vertices[c, 0] - x0, vertices[c, 1] - x1, vertices[c, 2] - x2
                d2 = e0 * e0 + e1 * e1 + e2 * e2
                if d2 > b2 or (with_reach and not math.sqrt(d2) <= reach[i]):
                    continue
                if not _other_face(c, i, cand_patch, boundary_uv, patch, uv, half_span, tried, with_uv):
                    continue
                if b < 0 or d2 < b2:
                    b, b2, tied = c, d2, False
                elif (cand_patch[c] != cand_patch[b] or boundary_uv[c, 0] != boundary_uv[b, 0]
                      or boundary_uv[c, 1] != boundary_uv[b, 1]):
                    tied = True
        best[i], dist[i], tie[i] = b, math.sqrt(b2) if b >= 0 else math.inf, tied


@njit(**JIT, aot=(
    "void(i8[::1], i8[::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], "
    "f8[::1], f8[::1], b1[::1], f8, f8, f8, b1[::1])",
))
def clear_of_hulls(rays, patch, O, D, t_mesh, t_kept, reach, lo, hi, normal, low, high, hull, tolerance, extent, slack,
                   clear):
    """Per row j (ray i = rays[j], face k = patch[j] with ``hull[k]``: weights > 0): ``clear[j]`` True where the ray's
    segment t ∈ [max(t_mesh − reach[k], 0), min(t_mesh + reach[k], t_kept − slack)] (empty: clear too), widened by
    tol + 1000 tol (tol = tolerance · max(t_mesh, extent, |O + t_mesh D|)), misses face k's control net's slabs: its
    box lo[k], hi[k] along the axes, or [low[k], high[k]] along the unit normal[k] (`trace.tracing._may_win_in_hull`).
    The segment's range along a direction is that of its two ends; NaN compares False: not clear."""
    for j in range(rays.shape[0]):
        i, k = rays[j], patch[j]
        clear[j] = False
        if not hull[k]:
            continue
        tm = t_mesh[i]
        m0, m1, m2 = O[i, 0] + tm * D[i, 0], O[i, 1] + tm * D[i, 1], O[i, 2] + tm * D[i, 2]
        tol = tolerance * max(max(tm, extent), math.sqrt(m0 * m0 + m1 * m1 + m2 * m2))
        margin = tol + 1000.0 * tol
        t0, t1 = max(tm - reach[k], 0.0), min(tm + reach[k], t_kept[i] - slack)
        if t0 > t1:
            clear[j] = True
            continue
        a_n = b_n = 0.0
        for c in range(3):
            a, b = O[i, c] + t0 * D[i, c], O[i, c] + t1 * D[i, c]
            if min(a, b) - margin > hi[k, c] or max(a, b) + margin < lo[k, c]:
                clear[j] = True
            a_n += a * normal[k, c]
            b_n += b * normal[k, c]
        if min(a_n, b_n) - margin > high[k] or max(a_n, b_n) + margin < low[k]:
            clear[j] = True
