"""Compiled kernels of the clearance cones (`trace.clearance`): the per-triangle slope and the per-ray proof.

- `ball_slopes`: for pairs (T, T') of triangles within reach (found through a uniform grid), the slope ρ with
  |h| ≤ ρ·δ on T', h the height over T's plane and δ the signed distance, in that plane, from a line through T's
  edge or vertex with T on its inner side (the least ρ over T's three edges and three vertices); per T the
  largest over its pairs.
- `clear_past`: per ray, whether the segment past its mesh hit on T keeps out of T's cone of that slope by more
  than Embree's rounding (then the any-hit query there finds nothing).

Argument types (for an ahead-of-time signature) are given in each docstring; all arrays C-contiguous.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import njit

from . import JIT


@njit(**JIT, aot=("void(f8[:, ::1], i8[:, ::1], i8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], i8[::1], f8, f8, "
                   "f8[::1], f8, i8[::1], i8[::1], i8[::1], f8, f8, i8, i8, f8[::1])",))
def ball_slopes(vertices, faces, canon, normal, centre, radius, size_class, reach, pad, low, cell, cells, start,
                members, widest, margin, lo, hi, slope):
    """``slope[T] = max(slope[T], ρ(T, T'))`` for T in ``lo`` … ``hi`` − 1 and every T' ≠ T of one grid with
    |c_T − c_T'| ≤ (r_T + ``reach`` + r_T')(1 + ``pad``) (module doc).

    The grid: ``cells`` (nx, ny, nz) cubes of side ``cell`` from ``low``, cube (x, y, z) numbered (x·ny + y)·nz + z,
    its triangles ``members[start[g]:start[g + 1]]`` (filed by their centre), none with r_T' > ``widest``. T meets
    those of the cubes its box c_T ± ((r_T + reach + widest)(1 + pad) + ``margin``) spans: a superset of its pairs
    (their L∞ distance is at most their distance; ``margin``: the float64 rounding of the cube numbers). A pair's
    distance test is the same float64 expression for either order, taken from its member of the lower
    (``size_class``, index), as the k-d trees that found them before took it (the same slopes, bit for bit).

    With h = n·(X − a₀) (n T's unit normal) and, for a line in T's plane through its anchor p with outward unit
    normal o (T on the side o·(X − p) ≤ 0: an edge's outward normal, or at a vertex minus the bisector of its
    angle), δ = o·(X − p):
    on T' (convex; h and δ affine) |h| ≤ ρ δ with ρ = max |h_k|/δ_k over its vertices wherever every δ_k ≥ 0 and
    δ_k > 0 where h_k ≠ 0. A vertex T' shares with T (``canon``: the same float32 point) has h = 0 exactly, and
    δ = 0 exactly when it lies on the line (the anchor, or the edge's other end). Lines for which T' is not so
    placed do not bound it; none: ρ = ∞. A degenerate T (slope already ∞) keeps ∞. The slope is the largest ρ
    over the pairs, whatever their order.

    Types: vertices float64[:, :] (V, 3); faces, canon int64[:, :] (F, 3) (canon: a vertex's first copy);
    normal, centre float64[:, :] (F, 3); radius float64[:] (F); size_class int64[:] (F); reach, pad float64;
    low float64[:] (3); cell float64; cells int64[:] (3); start int64[:] (G + 1); members int64[:]; widest,
    margin float64; lo, hi int64; slope float64[:] (F), updated.
    """
    h = np.empty(3)
    shared = np.empty(3, dtype=np.int64)  # T's corner (0..2) a vertex of T' coincides with, −1 if none
    lines = np.empty((6, 3))  # T's six lines' outward unit normals: the same for all its pairs
    anchor = np.empty((6, 3))  # their points p
    other = np.empty((3, 3))  # T' corners
    valid = np.empty(6, dtype=np.bool_)
    first = np.empty(3, dtype=np.int64)  # the cubes T's box spans
    last = np.empty(3, dtype=np.int64)
    for i in range(lo, hi):
        if slope[i] == math.inf:
            continue
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        for line in range(6):
            # Lines 0..2: the edge from corner e to e+1; 3..5: the vertex v = line − 3.
            e = line % 3
            p = faces[i, e]
            anchor[line, 0], anchor[line, 1], anchor[line, 2] = vertices[p, 0], vertices[p, 1], vertices[p, 2]
            if line < 3:
                q1 = faces[i, (e + 1) % 3]
                x0 = vertices[q1, 0] - vertices[p, 0]
                x1 = vertices[q1, 1] - vertices[p, 1]
                x2 = vertices[q1, 2] - vertices[p, 2]
                o0, o1, o2 = x1 * n2 - x2 * n1, x2 * n0 - x0 * n2, x0 * n1 - x1 * n0  # edge × n: in the plane
            else:
                q1 = faces[i, (e + 1) % 3]
                q2 = faces[i, (e + 2) % 3]
                o0 = o1 = o2 = 0.0
                for q in (q1, q2):
                    x0 = vertices[q, 0] - vertices[p, 0]
                    x1 = vertices[q, 1] - vertices[p, 1]
                    x2 = vertices[q, 2] - vertices[p, 2]
                    size = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
                    o0 -= x0 / size
                    o1 -= x1 / size
                    o2 -= x2 / size
            size = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
            valid[line] = size > 0.0
            if not valid[line]:
                continue
            o0, o1, o2 = o0 / size, o1 / size, o2 / size
            # Outward: T's corner off the line lies on the inner side (an edge's orientation is not known).
            r = faces[i, (e + 2) % 3] if line < 3 else faces[i, (e + 1) % 3]
            inner = (o0 * (vertices[r, 0] - vertices[p, 0]) + o1 * (vertices[r, 1] - vertices[p, 1])
                     + o2 * (vertices[r, 2] - vertices[p, 2]))
            if line < 3 and inner > 0.0:
                o0, o1, o2, inner = -o0, -o1, -o2, -inner
            valid[line] = inner < 0.0
            lines[line, 0], lines[line, 1], lines[line, 2] = o0, o1, o2
        half = (radius[i] + reach + widest) * (1.0 + pad) + margin
        for axis in range(3):
            first[axis] = int(max(math.floor((centre[i, axis] - half - low[axis]) / cell), 0.0))
            last[axis] = int(min(math.floor((centre[i, axis] + half - low[axis]) / cell), cells[axis] - 1.0))
        for gx in range(first[0], last[0] + 1):
            for gy in range(first[1], last[1] + 1):
                for gz in range(first[2], last[2] + 1):
                    g = (gx * cells[1] + gy) * cells[2] + gz
                    for slot in range(start[g], start[g + 1]):
                        j = members[slot]
                        if j == i:
                            continue
                        # The pair's test as one expression whichever T is: the distance's squares do not depend
                        # on the order, the radii's sum is taken from the lower (size class, index).
                        y0 = centre[i, 0] - centre[j, 0]
                        y1 = centre[i, 1] - centre[j, 1]
                        y2 = centre[i, 2] - centre[j, 2]
                        lower = size_class[i] < size_class[j] or (size_class[i] == size_class[j] and i < j)
                        rf = radius[i] if lower else radius[j]
                        rs = radius[j] if lower else radius[i]
                        if not math.sqrt(y0 * y0 + y1 * y1 + y2 * y2) <= (rf + reach + rs) * (1.0 + pad):
                            continue
                        _pair_slope(vertices, faces, canon, i, j, n0, n1, n2, lines, anchor, valid, h, shared,
                                    other, slope)


@njit(**JIT, inline="always")
def _pair_slope(vertices, faces, canon, i, j, n0, n1, n2, lines, anchor, valid, h, shared, other, slope):
    """``slope[i] = max(slope[i], ρ(T, T'))`` for T = i, T' = j (`ball_slopes`), T's lines given: ``anchor`` holds
    their points p (the first, T's corner a₀)."""
    for m in range(3):
        shared[m] = -1
        for q in range(3):
            if canon[j, m] == canon[i, q]:
                shared[m] = q
        b = faces[j, m]
        other[m, 0], other[m, 1], other[m, 2] = vertices[b, 0], vertices[b, 1], vertices[b, 2]
        if shared[m] >= 0:
            h[m] = 0.0
        else:
            h[m] = (n0 * (other[m, 0] - anchor[0, 0]) + n1 * (other[m, 1] - anchor[0, 1])
                    + n2 * (other[m, 2] - anchor[0, 2]))
    # Every line's ρ in full, without early exits (the least over the lines is the same): fewer mispredicted branches.
    best = math.inf
    for line in range(6):
        if not valid[line]:
            continue
        e = line % 3
        p0, p1, p2 = anchor[line, 0], anchor[line, 1], anchor[line, 2]
        o0, o1, o2 = lines[line, 0], lines[line, 1], lines[line, 2]
        rho = 0.0
        ok = True
        for m in range(3):
            d = o0 * (other[m, 0] - p0) + o1 * (other[m, 1] - p1) + o2 * (other[m, 2] - p2)
            on_line = shared[m] == e or (line < 3 and shared[m] == (e + 1) % 3)  # h = δ = 0 there
            if shared[m] >= 0:
                ok &= on_line or d >= 0.0
            else:
                ok &= d > 0.0
                rho = max(rho, abs(h[m]) / d)
        if ok:
            best = min(best, rho)
    if best > slope[i]:
        slope[i] = best


@njit(**JIT, aot=(
    "void(f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], f8[::1], i8[::1], f8[::1], "
    "f8[::1], f8, f8, b1[::1])",))
def clear_past(corners, normal, centre, radius, slope, origins, directions, offset, prim, start, limit, rounding,
               reach, go):
    """``go[k] = False`` where ray k's segment from ``start`` to ``limit`` provably meets no triangle (module doc).

    In the BVH's coordinates X₀ = O + start·D − ``offset``, T = prim[k]: the depth past T's plane g (along the
    ray's side of it), its rates c = |D·n| (deeper) and w = |D − (D·n) n| (sideways), λ₀ the distance in T's
    plane from X₀'s foot to T, L = limit − start. Clear when the segment and its ``rounding`` neighbourhood lie in
    T's ball (|X₀ − c_T| + L|D| + rounding ≤ r_T + reach) and g + cs − rounding > τ (λ₀ + ws + rounding) at
    s = 0 and s = L (so for every s between: both sides are affine in s).

    Types: corners float64[:, :] (F, 9) (T's three vertices); normal, centre float64[:, :] (F, 3); radius,
    slope float64[:] (F); origins, directions float64[:, :] (N, 3); offset float64[:] (3); prim int64[:] (N);
    start, limit float64[:] (N); rounding, reach float64; go bool[:] (N), updated where True.
    """
    for k in range(origins.shape[0]):
        if not go[k]:
            continue
        i = prim[k]
        tau = slope[i]
        if not tau < math.inf:
            continue
        s0 = start[k]
        length = limit[k] - s0
        d0, d1, d2 = directions[k, 0], directions[k, 1], directions[k, 2]
        x0 = origins[k, 0] + s0 * d0 - offset[0]
        x1 = origins[k, 1] + s0 * d1 - offset[1]
        x2 = origins[k, 2] + s0 * d2 - offset[2]
        norm_d = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        y0, y1, y2 = x0 - centre[i, 0], x1 - centre[i, 1], x2 - centre[i, 2]
        if not math.sqrt(y0 * y0 + y1 * y1 + y2 * y2) + length * norm_d + rounding <= radius[i] + reach:
            continue  # beyond the triangles the slope was taken over (or L infinite, NaN)
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        dn = d0 * n0 + d1 * n1 + d2 * n2
        c = abs(dn)
        if not c > 0.0:
            continue
        height = n0 * (x0 - corners[i, 0]) + n1 * (x1 - corners[i, 1]) + n2 * (x2 - corners[i, 2])
        depth = height if dn > 0.0 else -height
        l0, l1, l2 = d0 - dn * n0, d1 - dn * n1, d2 - dn * n2
        w = math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        # X₀'s foot in T's plane, and its distance to T.
        f0, f1, f2 = x0 - height * n0, x1 - height * n1, x2 - height * n2
        lateral = _to_triangle(corners[i], n0, n1, n2, f0, f1, f2)
        if (depth - rounding > tau * (lateral + rounding)
                and depth + c * length - rounding > tau * (lateral + w * length + rounding)):
            go[k] = False


@njit(**JIT, inline="always")
def _to_triangle(corner, n0, n1, n2, p0, p1, p2):
    """Distance from the point p in the plane of the triangle ``corner`` (9 coordinates) with unit normal n to it:
    0 inside (p on the inner side of every edge), else the least distance to an edge segment (an upper bound where
    an edge's side test and its segment disagree by rounding: the segment's distance is always at least the true one)."""
    # The side tests first: the point just past a ray's mesh hit on the triangle is nearly always inside it.
    inside = True
    for e in range(3):
        a0, a1, a2 = corner[3 * e], corner[3 * e + 1], corner[3 * e + 2]
        q = (e + 1) % 3
        r = (e + 2) % 3
        e0, e1, e2 = corner[3 * q] - a0, corner[3 * q + 1] - a1, corner[3 * q + 2] - a2
        # Inner side: the same side of the edge as the third corner.
        o0, o1, o2 = e1 * n2 - e2 * n1, e2 * n0 - e0 * n2, e0 * n1 - e1 * n0
        third = o0 * (corner[3 * r] - a0) + o1 * (corner[3 * r + 1] - a1) + o2 * (corner[3 * r + 2] - a2)
        side = o0 * (p0 - a0) + o1 * (p1 - a1) + o2 * (p2 - a2)
        if not side * third >= 0.0:
            inside = False
            break
    if inside:
        return 0.0
    best = math.inf
    for e in range(3):
        a0, a1, a2 = corner[3 * e], corner[3 * e + 1], corner[3 * e + 2]
        q = (e + 1) % 3
        e0, e1, e2 = corner[3 * q] - a0, corner[3 * q + 1] - a1, corner[3 * q + 2] - a2
        ee = e0 * e0 + e1 * e1 + e2 * e2
        s = ((p0 - a0) * e0 + (p1 - a1) * e1 + (p2 - a2) * e2) / ee if ee > 0.0 else 0.0
        s = min(max(s, 0.0), 1.0)
        g0, g1, g2 = p0 - a0 - s * e0, p1 - a1 - s * e1, p2 - a2 - s * e2
        best = min(best, math.sqrt(g0 * g0 + g1 * g1 + g2 * g2))
    return best
