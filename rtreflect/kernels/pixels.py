"""Compiled per-pixel kernels of the renderer's fixed costs: camera rays, the ray-box cull, AOV planes (issue 14).

Each kernel does in one pass over the rays, with no temporaries, what the numpy form did in a dozen
passes over (N,) and (N, 3) arrays, and with the same floating-point operations in the same order, so
the same bits (numba compiles without fast-math, so no reassociation or fused multiply-add).

- `pixel_rays`: the camera contract of `trace.camera` (DESIGN.md): x = 2(j + o_x)/W − 1, y = 1 − 2(i + o_y)/H,
  a pinhole ray's direction w + x·h_w·r + y·h_h·q normalised, or an orthographic ray from
  eye + x·h_w·r + y·h_h·q along w.
- `box_keep`: the slab test of Kay and Kajiya ("Ray tracing complex scenes", SIGGRAPH 1986) against a
  box [low, high] (`integrator.cull`).
- `aov_columns`: the AOV arrays written into a tile's float32 channels (`integrator.film.aov_planes`), each
  value rounded to float32 once.
- `coverage_rgba`: a pixel's colour from its samples (`integrator.film.coverage_color`), summed as numpy sums.
- `footprint_ends`: the ends of a pixel's footprint in (u, v), held in the patch's domain (`integrator.analytic`).

Argument types (for an ahead-of-time signature) are given in each docstring; all arrays C-contiguous.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import njit

from . import JIT


@njit(**JIT, aot=(
    "void(f8[::1], f8[::1], f8[::1], f8[::1], i8, f8[::1], f8[::1], f8[::1], f8[::1], f8, f8, f8, f8, b1, f8[:, ::1], f8[:, ::1])",
))
def pixel_rays(rows, cols, oy, ox, repeat, eye, w, r, q, half_w, half_h, width, height, ortho, origins, directions):
    """Camera rays (module doc) into ``origins`` and ``directions`` (N, 3), N = len(rows)·repeat.

    Ray k = p·repeat + j is of pixel (rows[p], cols[p]) at sub-pixel offset (oy[m], ox[m]), m = j where
    len(oy) = repeat, else m = k (len(oy) = N): repeat = 1 and one offset for the pixel centres, repeat = s² and the
    s² offsets for each pixel's samples, repeat = 1 and N offsets for one offset per ray.

    Types: rows, cols, oy, ox float64[:]; repeat int64; eye, w, r, q float64[:] (3); half_w, half_h float64;
    width, height float64; ortho bool; origins, directions float64[:, :] (N, 3), written.
    """
    per_sample = oy.shape[0] == repeat
    for k in range(origins.shape[0]):
        p, j = (k // repeat, k - (k // repeat) * repeat) if repeat > 1 else (k, 0)
        m = j if per_sample else k
        x = 2.0 * (cols[p] + ox[m]) / width - 1.0
        y = 1.0 - 2.0 * (rows[p] + oy[m]) / height
        a = x * half_w
        b = y * half_h
        if ortho:
            for c in range(3):
                origins[k, c] = eye[c] + a * r[c] + b * q[c]
                directions[k, c] = w[c]
        else:
            c0 = w[0] + a * r[0] + b * q[0]
            c1 = w[1] + a * r[1] + b * q[1]
            c2 = w[2] + a * r[2] + b * q[2]
            length = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
            directions[k, 0] = c0 / length
            directions[k, 1] = c1 / length
            directions[k, 2] = c2 / length
            for c in range(3):
                origins[k, c] = eye[c]


@njit(inline="always", **JIT)
def _nan_min(a, b):
    """numpy.minimum: NaN if either is."""
    if a != a or b != b:
        return math.nan
    return a if a < b else b


@njit(inline="always", **JIT)
def _nan_max(a, b):
    """numpy.maximum: NaN if either is."""
    if a != a or b != b:
        return math.nan
    return a if a > b else b


@njit(inline="always", **JIT)
def _fmax(a, b):
    """numpy.fmax: the other where one is NaN."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a > b else b


@njit(inline="always", **JIT)
def _fmin(a, b):
    """numpy.fmin: the other where one is NaN."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a < b else b


@njit(**JIT, aot=("f8(f8[:, ::1], f8[::1])",))
def origin_reach(origins, centre):
    """max |origins − centre| over every coordinate (NaN if any is NaN, as numpy's max).

    Types: origins float64[:, :] (N, 3); centre float64[:] (3). Returns float64.
    """
    reach = -math.inf
    for k in range(origins.shape[0]):
        for c in range(3):
            reach = _nan_max(reach, abs(origins[k, c] - centre[c]))
    return reach


@njit(**JIT, aot=("void(f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8, b1[::1])",))
def box_keep(origins, directions, low, high, tiny, keep):
    """``keep[k]``: ray k meets the box [low, high] ahead of its origin, or is NaN (module doc; `integrator.cull`).

    Per axis t₁, t₂ = (low − o)/d, (high − o)/d with d = 0 replaced by ``tiny``; near = fmax over the axes of
    min(t₁, t₂) from −∞, far = fmin of max(t₁, t₂) from +∞; culled where far < near or far < 0.

    Types: origins, directions float64[:, :] (N, 3); low, high float64[:] (3); tiny float64; keep bool[:] (N), written.
    """
    for k in range(origins.shape[0]):
        near = -math.inf
        far = math.inf
        for c in range(3):
            d = directions[k, c]
            inv = 1.0 / (tiny if d == 0.0 else d)
            t1 = (low[c] - origins[k, c]) * inv
            t2 = (high[c] - origins[k, c]) * inv
            near = _fmax(near, _nan_min(t1, t2))
            far = _fmin(far, _nan_max(t1, t2))
        keep[k] = not (far < near or far < 0.0)


@njit(**JIT, aot=(
    "void(f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f4[:, :])",
    "void(f8[:, :], f8[:, :], f8[:], f8[:], f8[:], f8[:], f8[:], f8[:], f8[:], f8[:], f8[:], f8[:], f8[:], f8[:], f4[:, :])",
    "void(f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[:, ::1])",
    # One pixel's float32 columns (the analytic path's miss pixel, a one-pixel block): numpy flags a one-row view
    # contiguous.
    "void(f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f4[:, ::1])",
))
def aov_columns(P, N, u, v, patch, Z, f, line_id, line_dist, phi, K, H, k1, k2, out):
    """The AOV channels of a tile in `integrator.film.AOV_CHANNELS` order (P and N three columns each, then one
    per array), each float64 value rounded to ``out``'s type once.

    Types: P, N float64[:, :] (n, 3); u ... k2 float64[:] (n), any stride (the odd-s path passes every s²-th
    sample); out float32[:, :] (n, 18), written (a view of a tile's pixels: its rows strided), or float64[:, :].
    """
    for i in range(out.shape[0]):
        for c in range(3):
            out[i, c] = P[i, c]
            out[i, 3 + c] = N[i, c]
        out[i, 6] = u[i]
        out[i, 7] = v[i]
        out[i, 8] = patch[i]
        out[i, 9] = Z[i]
        out[i, 10] = f[i]
        out[i, 11] = line_id[i]
        out[i, 12] = line_dist[i]
        out[i, 13] = phi[i]
        out[i, 14] = K[i]
        out[i, 15] = H[i]
        out[i, 16] = k1[i]
        out[i, 17] = k2[i]


# -- the analytic path's neighbour tests (`integrator.analytic`, `Renderer._render_analytic`) ----------------------
# Over a (rows, columns) crop of a tile's centre rays; any row stride. A neighbour beyond the crop is the pixel's own
# row or column repeated (`analytic.neighbours`: numpy's edge padding), so the crop's border is no edge.


@njit(inline="always", **JIT)
def _clamp(i, n):
    """Index i held inside [0, n)."""
    return 0 if i < 0 else (n - 1 if i >= n else i)


@njit(inline="always", **JIT)
def _moved(move, s_n, s0):
    """The largest |σ_n − σ| so far, ``move``, with neighbour σ_n's (numpy.fmax: a NaN σ_n passed over)."""
    return _fmax(move, abs(s_n - s0))


@njit(inline="always", **JIT)
def _may_reach(s0, move, reach):
    """The pixel's footprint may reach its stripe: |σ| − m ≤ ``reach``, m = ``move`` the most σ moves to a neighbour's
    centre (about |g_x| + |g_y|, twice what it moves within the pixel: `Renderer._render_analytic`). False for σ NaN."""
    return abs(s0) - move <= reach


@njit(**JIT, aot=(
    "void(i8[:, :], f8[:, :], f8, b1[:, :])",
    "void(i8[:, ::1], f8[:, ::1], f8, b1[:, ::1])",
    "void(i8[:, ::1], f8[:, ::1], f8, b1[:, :])",
))
def stripe_candidates(level, sigma, reach, want):
    """``want``: the pixel is on a level (≥ 0) and its footprint may reach the stripe: a neighbour is on another
    level, or |σ| − m ≤ ``reach`` with m the largest |σ_n − σ| over the 8 neighbours (NaN ones passed over, as
    numpy.fmax does; σ NaN: False).

    Types: level int64[:, :]; sigma float64[:, :]; reach float64; want bool[:, :], written (crop-shaped).
    """
    rows, cols = level.shape
    for i in range(rows):
        for j in range(cols):
            k0, s0 = level[i, j], sigma[i, j]
            mixed, move = False, 0.0
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    if dr == 0 and dc == 0:
                        continue
                    a, b = _clamp(i + dr, rows), _clamp(j + dc, cols)
                    mixed = mixed or level[a, b] != k0
                    move = _moved(move, sigma[a, b], s0)
            want[i, j] = k0 >= 0 and (mixed or _may_reach(s0, move, reach))


@njit(**JIT, aot=(
    "void(f8[:, ::1], f8[::1], b1[::1], f8, i8[:], b1[::1])",
))
def clear_far(sigma_n, sigma, unknown, reach, at, want):
    """``want[at[p]]`` cleared where pixel p is bounded away from its stripe: `stripe_candidates`' bound, not
    |σ| − m ≤ ``reach`` with m the largest |σ_n − σ| over its 8 neighbours (column p of ``sigma_n``; NaN ones passed
    over), unless ``unknown[p]`` or its σ is NaN (`Renderer._across_levels`).

    Types: sigma_n float64[:, ::1] (8, P); sigma float64[::1] (P); unknown bool[::1] (P); reach float64;
    at int64[:] (P); want bool[::1], written (the window's pixels).
    """
    for p in range(sigma.shape[0]):
        s0 = sigma[p]
        if unknown[p] or s0 != s0:
            continue
        move = 0.0
        for n in range(sigma_n.shape[0]):
            move = _moved(move, sigma_n[n, p], s0)
        if not _may_reach(s0, move, reach):
            want[at[p]] = False


@njit(**JIT, aot=(
    "i8(i8[:, :], b1[:, :], i8[:, ::1])",
    "i8(i8[:, ::1], b1[:, :], i8[:, ::1])",
))
def level_crossings(level, want, out):
    """The ``want`` pixels with a neighbour on another level, and their 8 neighbours (`stripe_candidates`' grid):
    row m of ``out`` = (i·columns + j, then the 8 neighbours' indices in `analytic.NEIGHBOURS` order, each beyond
    the grid the pixel's own row or column); returns how many rows are written.

    Types: level int64[:, :]; want bool[:, :] (same shape); out int64[:, ::1] (at least the wanted count, 9).
    """
    rows, cols = level.shape
    m = 0
    for i in range(rows):
        for j in range(cols):
            if not want[i, j]:
                continue
            mixed = False
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    mixed = mixed or level[_clamp(i + dr, rows), _clamp(j + dc, cols)] != level[i, j]
            if not mixed:
                continue
            out[m, 0] = i * cols + j
            c = 1
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    if dr == 0 and dc == 0:
                        continue
                    out[m, c] = _clamp(i + dr, rows) * cols + _clamp(j + dc, cols)
                    c += 1
            m += 1
    return m


@njit(**JIT, aot=(
    "void(i8[:, :], f8[:, :], f8[:, :], f8[:, :], b1[:, :], f8, b1[:, :])",
    "void(i8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], b1[:, ::1], f8, b1[:, ::1])",
))
def bent_flags(level, sigma, gx, gy, near, limit, untrusted):
    """``untrusted`` set (in place) where the pixel is ``near`` a stripe and a neighbour inside the crop, on the same
    level, strays from the plane σ + g·(Δx, Δy) by more than ``limit``: |σ_n − σ − g_x Δx − g_y Δy| > limit
    (Δx a column step, Δy a row step).

    Types: level int64[:, :]; sigma, gx, gy float64[:, :]; near bool[:, :]; limit float64; untrusted bool[:, :].
    """
    rows, cols = level.shape
    for i in range(rows):
        for j in range(cols):
            if not near[i, j]:
                continue
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    a, b = i + dr, j + dc
                    if (dr == 0 and dc == 0) or a < 0 or a >= rows or b < 0 or b >= cols or level[a, b] != level[i, j]:
                        continue
                    if abs(sigma[a, b] - sigma[i, j] - gx[i, j] * dc - gy[i, j] * dr) > limit:
                        untrusted[i, j] = True


@njit(inline="always", **JIT)
def _joined(P, N, shade, i, j, a, b, join_sine, shade_step):
    """Whether the hits of pixels (i, j) and (a, b), on two faces, continue one sheet at the pixel's scale: each lies
    within ``join_sine``·|ΔP| of the other's tangent plane (across an occlusion edge the farther hit lies off the
    nearer's plane by about the depth step·|N·D|), and their shades k differ by at most ``shade_step``."""
    d0, d1, d2 = P[a, b, 0] - P[i, j, 0], P[a, b, 1] - P[i, j, 1], P[a, b, 2] - P[i, j, 2]
    limit = join_sine * join_sine * (d0 * d0 + d1 * d1 + d2 * d2)
    here = N[i, j, 0] * d0 + N[i, j, 1] * d1 + N[i, j, 2] * d2
    there = N[a, b, 0] * d0 + N[a, b, 1] * d1 + N[a, b, 2] * d2
    return here * here <= limit and there * there <= limit and abs(shade[a, b] - shade[i, j]) <= shade_step


@njit(**JIT, aot=(
    "void(b1[:, :], i8[:, :], i8[:, :], b1[:, :], b1[:, :], b1[:, :], b1[:, :], f8[:, :, :], f8[:, :, :], f8[:, :], "
    "f8, f8, b1[:, ::1])",
    "void(b1[:, ::1], i8[:, ::1], i8[:, ::1], b1[:, ::1], b1[:, ::1], b1[:, ::1], b1[:, :], f8[:, :, :], f8[:, :, :], "
    "f8[:, :], f8, f8, b1[:, ::1])",
))
def edge_flags(hit, patch, level, near, blocked, untrusted, candidate, P, N, shade, join_sine, shade_step, edge):
    """``edge``: ``untrusted``, or a neighbour differs on hit or miss, on the patch (both hit; either a stripe
    candidate, or the two hits not one sheet continued, `_joined`), on the level (either near a stripe) or on the
    occlusion (both near): `analytic.edge_pixels`.

    A stripe candidate (`stripe_candidates`: its neighbours' σ do not bound it away from a stripe) rather than near
    one (its own footprint reaches it): across a crease σ jumps, and the other face's part of the pixel lies beyond
    either centre's footprint, within the neighbours' reach.

    Types: hit bool[:, :]; patch, level int64[:, :]; near, blocked, untrusted, candidate bool[:, :]; P, N
    float64[:, :, :] (rows, columns, 3): the hit points and unit normals; shade float64[:, :]; join_sine, shade_step
    float64; edge bool[:, :], written.
    """
    rows, cols = hit.shape
    for i in range(rows):
        for j in range(cols):
            e = untrusted[i, j]
            h0, n0 = hit[i, j], near[i, j]
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    if e:
                        break
                    if dr == 0 and dc == 0:
                        continue
                    a, b = _clamp(i + dr, rows), _clamp(j + dc, cols)
                    e = (hit[a, b] != h0
                         or (h0 and patch[a, b] != patch[i, j]
                             and (candidate[i, j] or candidate[a, b]
                                  or not _joined(P, N, shade, i, j, a, b, join_sine, shade_step)))
                         or ((n0 or near[a, b]) and level[a, b] != level[i, j])
                         or (n0 and near[a, b] and blocked[a, b] != blocked[i, j]))
            edge[i, j] = e


# -- the analytic path's closed-form coverage (`integrator.analytic`) ---------------------------------------------


@njit(inline="always", **JIT)
def _clip(x, low, high):
    """numpy.clip: NaN stays NaN."""
    if x != x:
        return x
    return high if x > high else (low if x < low else x)


@njit(inline="always", **JIT)
def _trapezoid_cdf(z, a, b):
    """P(X + Y ≤ z), X ~ U[−a/2, a/2], Y ~ U[−b/2, b/2] (`analytic.trapezoid_cdf`): with hi = max(a, b),
    lo = min(a, b) and t = clip(z + (hi + lo)/2, 0, hi + lo), t²/(2·hi·lo) up to lo, (t − lo/2)/hi up to hi,
    1 − (hi + lo − t)²/(2·hi·lo) up to hi + lo; a step at 0 where hi = 0. The operations and their order are the
    former numpy form's (same bits)."""
    hi = _nan_max(a, b)
    lo = _nan_min(a, b)
    t = _clip(z + 0.5 * (hi + lo), 0.0, hi + lo)
    if not hi > 0:
        return 1.0 if z >= 0 else 0.0
    if t <= lo:
        return t * t / (2.0 * hi * lo) if lo > 0 else 0.0
    if t >= hi:
        if lo > 0:
            gap = hi + lo - t
            return 1.0 - gap * gap / (2.0 * hi * lo)
        return 1.0
    return (t - 0.5 * lo) / hi


@njit(**JIT, aot=("void(f8[::1], f8[::1], f8[::1], f8[::1])",))
def trapezoid_cdf(z, a, b, out):
    """``out`` = the trapezoid's CDF (`_trapezoid_cdf`) per element.

    Types: z, a, b float64[:] (n); out float64[:] (n), written.
    """
    for i in range(out.shape[0]):
        out[i] = _trapezoid_cdf(z[i], a[i], b[i])


@njit(**JIT, aot=("void(f8[::1], f8[::1], f8[::1], f8, f8[::1])",))
def hard_coverage(sigma, a, b, half_width, out):
    """``out`` = the hard stripe's share of the box pixel, F(w − σ) − F(−w − σ) (`analytic.hard_coverage`).

    Types: sigma, a, b float64[:] (n); half_width float64; out float64[:] (n), written.
    """
    for i in range(out.shape[0]):
        out[i] = _trapezoid_cdf(half_width - sigma[i], a[i], b[i]) - _trapezoid_cdf(-half_width - sigma[i], a[i], b[i])


# -- colour of pixels from their samples (`integrator.film.coverage_color`) -----------------------------------------

#: numpy's pairwise summation works in blocks of this many values (its PW_BLOCKSIZE), split in halves beyond.
PAIRWISE_BLOCK = 128


#: Depth of `_pairwise_sum`'s stack: the halves' tree of n values is about log2(n / 8) deep.
PAIRWISE_DEPTH = 64


@njit(inline="always", **JIT)
def _block_sum(a, first, n):
    """numpy's ``pairwise_sum`` of a[first:first + n] for n ≤ `PAIRWISE_BLOCK` (`_pairwise_sum`)."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[first + i]
        return res
    r0, r1, r2, r3 = a[first], a[first + 1], a[first + 2], a[first + 3]
    r4, r5, r6, r7 = a[first + 4], a[first + 5], a[first + 6], a[first + 7]
    i = 8
    while i < n - n % 8:
        r0 += a[first + i]
        r1 += a[first + i + 1]
        r2 += a[first + i + 2]
        r3 += a[first + i + 3]
        r4 += a[first + i + 4]
        r5 += a[first + i + 5]
        r6 += a[first + i + 6]
        r7 += a[first + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[first + i]
        i += 1
    return res


@njit(**JIT)
def _pairwise_sum(a, n, stack):
    """numpy's sum of a[:n] (a float64 row reduced along its contiguous axis), term for term: 0.0 (numpy's initial
    value of an add reduction) plus its pairwise summation (numpy/_core/src/umath/loops_utils.h, ``pairwise_sum``):
    below 8 values in turn, up to `PAIRWISE_BLOCK` in 8 running sums combined as
    ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)) then the rest in turn, beyond that the two halves (the first
    n/2 rounded down to a multiple of 8) summed apart and added. The halves by an explicit stack (``stack``: int64
    (`PAIRWISE_DEPTH`, 3) rows first, n, state; numba's on-disk cache of a recursive function crashes on load).
    """
    if n <= PAIRWISE_BLOCK:
        return 0.0 + _block_sum(a, 0, n)
    sums = np.empty(PAIRWISE_DEPTH)
    top, done = 0, 0
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, n, 0
    while top >= 0:
        first, m = stack[top, 0], stack[top, 1]
        if m <= PAIRWISE_BLOCK:
            sums[done] = _block_sum(a, first, m)
            done += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if stack[top, 2] < 2:  # its left half, then its right half
            stack[top, 2] += 1
            top += 1
            stack[top, 0] = first if stack[top - 1, 2] == 1 else first + half
            stack[top, 1] = half if stack[top - 1, 2] == 1 else m - half
            stack[top, 2] = 0
        else:  # both halves summed: left + right
            sums[done - 2] = sums[done - 2] + sums[done - 1]
            done -= 1
            top -= 1
    return 0.0 + sums[0]


#: The largest finite float64 (`_finite_or_limit`, numpy's ``nan_to_num`` of +inf).
FLOAT64_MAX = 1.7976931348623157e308


@njit(inline="always", **JIT)
def _finite_or_limit(x):
    """numpy's ``nan_to_num`` of one value: NaN → 0, ±inf → ± the largest float64."""
    if x != x:
        return 0.0
    if x == math.inf:
        return FLOAT64_MAX
    if x == -math.inf:
        return -FLOAT64_MAX
    return x


@njit(**JIT, aot=(
    "void(b1[:, ::1], f8[:, ::1], f8[:, ::1], b1, f8[::1], f8[:, :, ::1], f8[::1], f8[::1], f8[:, ::1])",
    "void(b1[:, ::1], f8[:, ::1], f8[:, ::1], b1, f8[::1], f8[:, :, ::1], f8[::1], f8[::1], f4[:, :])",
    # one pixel's float32 colour columns (a one-row view is flagged contiguous)
    "void(b1[:, ::1], f8[:, ::1], f8[:, ::1], b1, f8[::1], f8[:, :, ::1], f8[::1], f8[::1], f4[:, ::1])"))
def coverage_rgba(hit, weight, shade, shaded, surface, colours, line, background, out):
    """``out`` (P, 4) linear RGBA of pixels from their (P, s²) samples (`film.coverage_color`, `film.map_color`):
    per pixel the line weights' sum L = Σ w, the surface's U = Σ (1 − w)·k·surface (a map mode: Σ (1 − w)·colour
    of each sample's own colour) and the hits' count H over its samples (a miss adds 0), then
    RGB = (L·line + U + (s² − H)·background)/s², A = H/s². L and Σ (1 − w)·k are summed as numpy sums a row
    (`_pairwise_sum`), a map mode's U in sample order (as numpy sums (P, s², 3) over its middle axis, each colour
    as ``nan_to_num`` makes it), so the same bits as the sums of numpy arrays; with one sample they are the
    sample's own values. Each value is rounded to ``out``'s type once.

    Types: hit bool[:, :] (P, s²); weight float64[:, :] (P, s²) (line weights, or lit flags as 0/1); shade
    float64[:, :] (P, s², read where ``shaded``); shaded bool; surface, line, background float64[:] (3); colours
    float64[:, :, :] (P, s², 3) per-sample surface colours of a map mode (in place of surface and shade), or
    (0, 0, 3); out float64[:, :] or float32[:, :] (P, 4), written (a float32 view of a tile's pixels: its rows
    strided).
    """
    samples = hit.shape[1]
    mapped = colours.shape[0] > 0
    # Below 8 values numpy adds them in turn (`_block_sum`): running sums here, no call per pixel (the call to
    # `_pairwise_sum` cost 12× the rest of a one-sample pixel, 1.6 ms per 65536 pixels).
    in_turn = samples < 8
    lit = np.zeros(samples)
    unlit = np.zeros(samples)
    mapped_sum = np.zeros(3)
    stack = np.empty((PAIRWISE_DEPTH, 3), dtype=np.int64)
    for i in range(out.shape[0]):
        n_hit = 0
        n_lit = 0.0
        n_unlit = 0.0
        for c in range(3):
            mapped_sum[c] = 0.0
        for j in range(samples):
            if hit[i, j]:
                w = weight[i, j]
                x, y = w, (1.0 - w) * shade[i, j] if shaded else 1.0 - w
                n_hit += 1
            else:
                x, y = 0.0, 0.0
            if mapped:
                for c in range(3):
                    mapped_sum[c] += _finite_or_limit(colours[i, j, c]) * y
            if in_turn:
                n_lit += x
                n_unlit += y
            else:
                lit[j], unlit[j] = x, y
        if in_turn:  # numpy's 0.0 + the block's sum, as `_pairwise_sum` returns it
            n_lit, n_unlit = 0.0 + n_lit, 0.0 + n_unlit
        else:
            n_lit = _pairwise_sum(lit, samples, stack)
            n_unlit = 0.0 if mapped else _pairwise_sum(unlit, samples, stack)
        n_missed = float(samples - n_hit)
        for c in range(3):
            u = mapped_sum[c] if mapped else n_unlit * surface[c]
            out[i, c] = (n_lit * line[c] + u + n_missed * background[c]) / samples
        out[i, 3] = n_hit / samples


# -- the analytic path's pixel footprint ----------------------------------------------------------------------------


@njit(inline="always", **JIT)
def _room(x, step, low, high):
    """Largest λ in [0, 1] with x + λ·step inside [low, high] (0 where that is NaN), as numpy's
    ``clip(nan_to_num(where(step > 0, (high − x)/step, where(step < 0, (low − x)/step, 1)), nan=0), 0, 1)``:
    clip keeps −0.0 (a step from the low end), as numpy's does."""
    room = (high - x) / step if step > 0 else ((low - x) / step if step < 0 else 1.0)
    if room != room:
        return 0.0
    room = 0.0 if room < 0.0 else room
    return 1.0 if room > 1.0 else room


@njit(**JIT, aot=(
    "void(f8[::1], f8[::1], f8[:, :, ::1], f8[:], f8[:], f8[:], f8[:], f8[::1], f8[::1], f8[::1])",
))
def footprint_ends(u, v, steps, u0, u1, v0, v1, ends_u, ends_v, shares):
    """The four ends (u, v) ± ½λ (du, dv) of a pixel's footprint along x and along y (`integrator.analytic`), each
    step shortened by the share λ of it that stays in the patch's domain [u0, u1] × [v0, v1] (`_room` in u and in
    v, the smaller): ends m·N + i for point i, m = 2·axis + (0 for +, 1 for −).

    Types: u, v float64[:] (N); steps float64[:, :, :] (N, 2, 2), [[du/dx, dv/dx], [du/dy, dv/dy]]; u0, u1, v0, v1
    float64[:] (N, any stride); ends_u, ends_v, shares float64[:] (4N), written.
    """
    n = u.shape[0]
    for axis in range(2):
        for half in range(2):
            sign = 1.0 if half == 0 else -1.0
            m = (2 * axis + half) * n
            for i in range(n):
                du = 0.5 * steps[i, axis, 0]
                dv = 0.5 * steps[i, axis, 1]
                lam = _nan_min(_room(u[i], sign * du, u0[i], u1[i]), _room(v[i], sign * dv, v0[i], v1[i]))
                shares[m + i] = lam
                ends_u[m + i] = u[i] + sign * lam * du
                ends_v[m + i] = v[i] + sign * lam * dv


# -- rays handed to Embree (`trace.accelerator`) ------------------------------------------------------------------


@njit(**JIT, aot=("void(f8[:, :], f8[:, :], f8[::1], f4[:, ::1], f4[:, ::1])",))
def bvh_rays(origins, directions, centre, local, directions32):
    """Rays in a BVH's centred float32 coordinates (`Accelerator`): ``local`` = origins − centre, subtracted in float64
    then rounded to float32, and ``directions32`` the directions rounded to float32, as numpy's subtraction and casts
    (the same bits) in one pass and no float64 temporary.

    Types: origins, directions float64[:, :] (N, 3), any stride; centre float64[:] (3); local, directions32
    float32[:, :] (N, 3), written.
    """
    for k in range(origins.shape[0]):
        for c in range(3):
            local[k, c] = origins[k, c] - centre[c]
            directions32[k, c] = directions[k, c]


# -- rows of (N, 3) arrays ------------------------------------------------------------------------------------------


@njit(**JIT, aot=("void(f8[:, ::1], i8[::1], f8[:, ::1], i8[::1])",))
def scatter_picked(dst, rows, src, pick):
    """``dst[rows[k]] = src[pick[k]]`` for every k, row by row: numpy's fancy assignment of (N, 3) rows (~4× slower,
    it copies element by element through its general index machinery) of the rows ``pick`` of ``src`` with no
    gathered copy of them in between (``pick`` an arange: ``dst[rows] = src``). The values are copied, not computed.

    Types: dst float64[:, :] (N, m), written; rows int64[:] (K); src float64[:, :] (M, m); pick int64[:] (K).
    """
    for k in range(rows.shape[0]):
        for c in range(dst.shape[1]):
            dst[rows[k], c] = src[pick[k], c]


@njit(**JIT, aot=("void(f8[:, ::1], i8[::1], f8[:, ::1], i8[::1], f8)",))
def spread_rows(dst, rows, src, pick, fill):
    """``dst[rows[k]] = src[pick[k]]`` for every k and ``fill`` in every other row: a full-size array from the rows of
    some of its rays (``rows`` ascending), each row written once (``np.full`` then `scatter_picked` wrote the kept rows
    twice). The values are copied, not computed.

    Types: dst float64[:, :] (N, m), written; rows int64[:] (K, ascending, < N); src float64[:, :] (M, m); pick
    int64[:] (K); fill float64.
    """
    k = 0
    for i in range(dst.shape[0]):
        if k < rows.shape[0] and rows[k] == i:
            for c in range(dst.shape[1]):
                dst[i, c] = src[pick[k], c]
            k += 1
        else:
            for c in range(dst.shape[1]):
                dst[i, c] = fill
