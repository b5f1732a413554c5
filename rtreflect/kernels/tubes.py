"""Compiled skew-line distances to the light tubes (Ulmet, paper eq. 4; `modes.lights.TubeLights`).

Notation of the paper: surface point R, reflected direction s, light line k through
B_k = Q + c_k e with unit direction c. With ρ = R − Q (so b = B_k − R = c_k e − ρ):

    d_k = |(s × c)·b| / |s × c| = |(s × c)·ρ − c_k (s × c)·e| / |s × c|,
    t_k = ((s·c)(c·ρ) − s·ρ)/|s × c|² + c_k (s·e)/|s × c|²   (closest approach on R + t s),
    τ_k = ((c·ρ) − (s·c)(s·ρ))/|s × c|² + c_k (s·c)(s·e)/|s × c|²   (on the tube's axis),

using 1 − (s·c)² = |s × c|² for unit s and c. Where s ∥ c (|s × c| <= `PARALLEL`), d_k = |b × c|,
the point-to-line distance, and the ray runs along the tube: t = ∞, ahead only if the tube is
infinite. A tube is *ahead* where t > 0 and |τ| <= length/2.

Ulmet's function (paper eq. 5, general form) reads the same reflected ray where it meets the tubes'
plane (through Q, unit normal m): t = m·(Q − R)/(m·s), f = e·(R + t s − Q), NaN where t <= 0.
`reach` writes it beside the nearest tube (the renderer's f AOV), so the ray is read once; `plane_t` gives
that t alone (`TubeLights.plane_t`: the highlight and circles modes, the contours), from the same expression.
"""

from __future__ import annotations

import math

import numpy as np
from .compiled import njit

from . import JIT

#: |s × c| below this: the reflected ray runs along the tubes (unit vectors: a sine).
PARALLEL = 1e-12


@njit(inline="always", **JIT)
def _prepare(Q, c, e, R, s, i):
    """Per-point scalars of eq. (4): (parallel, g, h, 1/|s×c|, α, β, α_τ, β_τ) with d = |g − c_k h|/|s×c|."""
    rho0, rho1, rho2 = R[i, 0] - Q[0], R[i, 1] - Q[1], R[i, 2] - Q[2]
    s0, s1, s2 = s[i, 0], s[i, 1], s[i, 2]
    x0, x1, x2 = s1 * c[2] - s2 * c[1], s2 * c[0] - s0 * c[2], s0 * c[1] - s1 * c[0]  # s × c
    norm = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    sc = s0 * c[0] + s1 * c[1] + s2 * c[2]
    se = s0 * e[0] + s1 * e[1] + s2 * e[2]
    s_rho = s0 * rho0 + s1 * rho1 + s2 * rho2
    c_rho = rho0 * c[0] + rho1 * c[1] + rho2 * c[2]
    inv = 1.0 / norm
    inv_denom = inv * inv
    return (norm <= PARALLEL, x0 * rho0 + x1 * rho1 + x2 * rho2, x0 * e[0] + x1 * e[1] + x2 * e[2], inv,
            (sc * c_rho - s_rho) * inv_denom, se * inv_denom, (c_rho - sc * s_rho) * inv_denom, sc * se * inv_denom)


@njit(inline="always", **JIT)
def _pair(Q, c, e, R, i, ck, half_length, pre):
    """(d, t, ahead) of point i and the tube at c_k, from `_prepare`'s scalars."""
    parallel, g, h, inv, alpha, beta, alpha_tau, beta_tau = pre
    if not parallel:
        t = alpha + ck * beta
        ahead = t > 0
        if half_length < np.inf:
            ahead = ahead and abs(alpha_tau + ck * beta_tau) <= half_length
        return abs(g - ck * h) * inv, t, ahead
    w0, w1, w2 = R[i, 0] - Q[0] - ck * e[0], R[i, 1] - Q[1] - ck * e[1], R[i, 2] - Q[2] - ck * e[2]
    y0, y1, y2 = w1 * c[2] - w2 * c[1], w2 * c[0] - w0 * c[2], w0 * c[1] - w1 * c[0]
    return math.sqrt(y0 * y0 + y1 * y1 + y2 * y2), np.inf, not half_length < np.inf


@njit(inline="always", **JIT)
def _reflect_at(a0, a1, a2, n, i, out, j):
    """Paper eq. (3), s = 2 (a·n) n − a, of unit a and row i of n into out[j]; a·n summed in `numpy.einsum`'s
    order (terms 0, 2, then 1), as the former array form, so s is the same to the bit."""
    twice = 2.0 * ((a0 * n[i, 0] + a2 * n[i, 2]) + a1 * n[i, 1])
    out[j, 0] = twice * n[i, 0] - a0
    out[j, 1] = twice * n[i, 1] - a1
    out[j, 2] = twice * n[i, 2] - a2


@njit(**JIT, aot=("void(f8[:, ::1], f8[:, ::1], f8[:, ::1])",))
def reflect(a, n, out):
    """Reflected directions (`_reflect_at`) of every row a, n."""
    for i in range(a.shape[0]):
        _reflect_at(a[i, 0], a[i, 1], a[i, 2], n, i, out, i)


@njit(**JIT, aot=("void(f8[:, ::1], i8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1])",))
def reflect_rays(D, rows, n, s_rows, s):
    """Reflected directions of the rays D[rows] (a = −D towards the eye) at unit normals n (one per row): into
    s_rows and into the rows of s, without the gathered, negated and scattered (N, 3) copies."""
    for j in range(rows.shape[0]):
        i = rows[j]
        _reflect_at(-D[i, 0], -D[i, 1], -D[i, 2], n, j, s_rows, j)
        s[i, 0], s[i, 1], s[i, 2] = s_rows[j, 0], s_rows[j, 1], s_rows[j, 2]


@njit(inline="always", **JIT)
def _signed_at(pre, ck):
    """Eq. (4) without the absolute value, (g − c_k h)/|s × c|, of a ray not parallel to c (`_prepare`'s pre)."""
    return (pre[1] - ck * pre[2]) * pre[3]


@njit(inline="always", **JIT)
def _plane_t_at(Q, m, R, s, i):
    """Ray parameter where R + t s of point i meets the light plane (module doc), t = m·(Q − R)/(m·s); ±inf or NaN
    where s ∥ plane. The operations in the order of the former numpy form (`numpy.einsum`'s 3-term dot of C-ordered
    rows sums terms 0, 2, then 1), so t is the same to the bit."""
    return (((Q[0] - R[i, 0]) * m[0] + (Q[2] - R[i, 2]) * m[2]) + (Q[1] - R[i, 1]) * m[1]) / (
        (s[i, 0] * m[0] + s[i, 2] * m[2]) + s[i, 1] * m[1])


@njit(**JIT, aot=("void(f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], f8[::1])",))
def plane_t(Q, m, R, s, out):
    """The light plane's ray parameter t (`_plane_t_at`) of every point."""
    for i in range(R.shape[0]):
        out[i] = _plane_t_at(Q, m, R, s, i)


@njit(inline="always", **JIT)
def _ulmet_at(Q, m, e, R, s, i):
    """Ulmet's f of point i (module doc): the e-coordinate of R + t s in the light plane, NaN where t <= 0.

    The operations in the order of the former numpy form (`numpy.einsum`'s 3-term dot sums terms 0, 2, then 1),
    so f is the same to the bit."""
    t = _plane_t_at(Q, m, R, s, i)
    if not t > 0:
        return np.nan
    return (((R[i, 0] + t * s[i, 0]) - Q[0]) * e[0] + ((R[i, 2] + t * s[i, 2]) - Q[2]) * e[2]) + (
        (R[i, 1] + t * s[i, 1]) - Q[1]) * e[1]


@njit(**JIT, aot=("void(f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], f8[::1])",))
def ulmet_f(Q, m, e, R, s, out):
    """Ulmet's f (eq. 5) of every point (`_ulmet_at`)."""
    for i in range(R.shape[0]):
        out[i] = _ulmet_at(Q, m, e, R, s, i)


@njit(**JIT, aot=("void(f8[::1], f8[::1], f8[::1], f8[::1], f8, f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], b1[:, ::1])",))
def distances(Q, c, e, c_k, half_length, R, s, d, t, ahead):
    """d, t, ahead (N, K) of every point and tube (eq. 4)."""
    for i in range(R.shape[0]):
        pre = _prepare(Q, c, e, R, s, i)
        for k in range(c_k.shape[0]):
            d[i, k], t[i, k], ahead[i, k] = _pair(Q, c, e, R, i, c_k[k], half_length, pre)


@njit(inline="always", **JIT)
def _scan(Q, c, e, c_k, radius, half_length, R, i, pre):
    """(best, best_d, best_t, hit, t_hit) of point i over every tube: the nearest tube ahead (first of equals; −1,
    ∞, NaN where none is), and whether a tube ahead lies within the radius and the least t of those (∞ where none)."""
    best, best_d, best_t, hit, t_hit = -1, np.inf, np.nan, False, np.inf
    for k in range(c_k.shape[0]):
        dk, tk, ahead = _pair(Q, c, e, R, i, c_k[k], half_length, pre)
        if not ahead:
            continue
        if dk < best_d:
            best, best_d, best_t = k, dk, tk
        if dk <= radius:
            hit = True
            if tk < t_hit:
                t_hit = tk
    return best, best_d, best_t, hit, t_hit


@njit(inline="always", **JIT)
def _guess(x, c0, per_unit, last):
    """An index in [0, last + 1] near where the ascending c_k cross x (linear between the first and last; 0 for NaN):
    where `_nearest`'s exact walks start, so any value is correct, a near one quick."""
    at = (x - c0) * per_unit
    if not at > 0:
        return 0
    if at >= last + 1:
        return last + 1
    return int(at + 0.5)


@njit(inline="always", **JIT)
def _nearest(c_k, radius, pre, per_unit):
    """`_scan`'s answer for infinite tubes at ascending c_k and a ray not parallel to them (finite scalars), from a
    few tubes about the nearest.

    t_k = α + c_k β and y_k = g − c_k h (d_k = |y_k|/|s × c|) are each one rounded product and one rounded sum of
    c_k, as `_pair` computes them: monotone in c_k (β's and −h's sign), so in k. The tubes ahead (t > 0) are then a
    suffix (β ≥ 0) or a prefix of k; over them d_k falls and then rises (weakly: equal runs), least at one of the two
    tubes about y's change of sign; the least d's equal run and the tubes within the radius are runs about it; t over
    a run is least at one of its ends. Walks from an interpolated guess find each end by the comparisons the scan
    makes, on the values it computes: the same tube (first of equals), d, t and flags, to the bit.
    """
    g, h, inv, alpha, beta = pre[1], pre[2], pre[3], pre[4], pre[5]
    last = c_k.shape[0] - 1
    lo, hi = 0, last
    if beta >= 0:  # ahead: a suffix
        if not alpha + c_k[last] * beta > 0:
            return -1, np.inf, np.nan, False, np.inf
        if not alpha + c_k[0] * beta > 0:
            lo = min(max(_guess(-alpha / beta, c_k[0], per_unit, last), 1), last)
            while lo > 1 and alpha + c_k[lo - 1] * beta > 0:
                lo -= 1
            while not alpha + c_k[lo] * beta > 0:
                lo += 1
    else:  # a prefix
        if not alpha + c_k[0] * beta > 0:
            return -1, np.inf, np.nan, False, np.inf
        if not alpha + c_k[last] * beta > 0:
            hi = min(max(_guess(-alpha / beta, c_k[0], per_unit, last) - 1, 0), last - 1)
            while hi < last - 1 and alpha + c_k[hi + 1] * beta > 0:
                hi += 1
            while not alpha + c_k[hi] * beta > 0:
                hi -= 1
    # j: the first k in [lo, hi + 1] past y's change of sign (y ≥ 0 where y rises with k, h ≤ 0; else y ≤ 0).
    j = min(max(_guess(g / h, c_k[0], per_unit, last), lo), hi + 1)
    if h <= 0:
        while j > lo and g - c_k[j - 1] * h >= 0:
            j -= 1
        while j <= hi and not g - c_k[j] * h >= 0:
            j += 1
    else:
        while j > lo and g - c_k[j - 1] * h <= 0:
            j -= 1
        while j <= hi and not g - c_k[j] * h <= 0:
            j += 1
    if j > lo:
        best = j - 1
        best_d = abs(g - c_k[best] * h) * inv
        if j <= hi:
            dj = abs(g - c_k[j] * h) * inv
            if dj < best_d:
                best, best_d = j, dj
    else:
        best = j
        best_d = abs(g - c_k[best] * h) * inv
    while best > lo and abs(g - c_k[best - 1] * h) * inv == best_d:  # the first of an equal run
        best -= 1
    if not best_d < np.inf:  # d overflowed: the scan keeps none
        return -1, np.inf, np.nan, False, np.inf
    best_t = alpha + c_k[best] * beta
    if not best_d <= radius:
        return best, best_d, best_t, False, np.inf
    a, b = best, best
    while a > lo and abs(g - c_k[a - 1] * h) * inv <= radius:
        a -= 1
    while b < hi and abs(g - c_k[b + 1] * h) * inv <= radius:
        b += 1
    return best, best_d, best_t, True, min(alpha + c_k[a] * beta, alpha + c_k[b] * beta)


@njit(**JIT, aot=("void(f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8, f8, f8[:, ::1], f8[:, ::1], i8[::1], i8[::1], f8[::1], "
                  "f8[::1], f8[::1], b1[::1], f8[::1], f8[::1], f8[::1])",))
def reach(Q, m, c, e, c_k, radius, half_length, R, s, tube, line_id, line_dist, line_sigma, line_t, candidate,
          t_candidate, t_of, f):
    """Per point, without the (N, K) tables: the nearest tube ahead (index, d, the signed distance as `signed`
    and its t; first of equals; −1 and NaN where none is), whether a tube ahead lies within the radius and
    the t of the nearest such (∞ where none), where tube.shape[0] > 0 the t of tube[i], and Ulmet's f
    (`_ulmet_at`). Infinite tubes at ascending c_k (a bank's): a few tubes about the nearest (`_nearest`), the
    scan's values (`_scan`, which the others take)."""
    want = tube.shape[0] > 0
    K = c_k.shape[0]
    ordered = K > 1 and not half_length < np.inf and np.isfinite(c_k[0]) and np.isfinite(c_k[K - 1])
    for k in range(1, K):
        ordered = ordered and c_k[k - 1] < c_k[k]
    per_unit = (K - 1) / (c_k[K - 1] - c_k[0]) if ordered else 0.0
    for i in range(R.shape[0]):
        f[i] = _ulmet_at(Q, m, e, R, s, i)
        pre = _prepare(Q, c, e, R, s, i)
        if ordered and not pre[0] and np.isfinite(pre[1]) and np.isfinite(pre[2]) and np.isfinite(pre[4]) and \
                np.isfinite(pre[5]):
            best, best_d, best_t, hit, t_hit = _nearest(c_k, radius, pre, per_unit)
        else:
            best, best_d, best_t, hit, t_hit = _scan(Q, c, e, c_k, radius, half_length, R, i, pre)
        if want and 0 <= tube[i] < K:
            t_of[i] = _pair(Q, c, e, R, i, c_k[tube[i]], half_length, pre)[1]
        line_id[i] = best
        line_dist[i] = best_d if best >= 0 else np.nan
        # The sign as `signed` gives it (the same expression, so the same bits); s ∥ c: the unsigned d.
        line_sigma[i] = np.nan if best < 0 else (best_d if pre[0] else _signed_at(pre, c_k[best]))
        line_t[i] = best_t
        candidate[i] = hit
        t_candidate[i] = t_hit


@njit(**JIT, aot=("void(f8[::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], i8[::1], f8[::1])",))
def signed(Q, c, e, c_k, R, s, tube, out):
    """Signed skew-line distance (g − c_k h)/|s × c| of point i's ray to tube[i] (eq. 4 without the absolute
    value: continuous across the tube's axis, so a stripe is |σ| ≤ r); where s ∥ c, the unsigned |b × c|."""
    for i in range(R.shape[0]):
        pre = _prepare(Q, c, e, R, s, i)
        ck = c_k[tube[i]]
        if not pre[0]:
            out[i] = _signed_at(pre, ck)
        else:
            out[i] = _pair(Q, c, e, R, i, ck, np.inf, pre)[0]
