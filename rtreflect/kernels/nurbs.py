"""Compiled per-point NURBS evaluation: the one implementation of S and its derivatives (order <= 2).

A NURBS surface (Piegl & Tiller, *The NURBS Book*, eq. 4.15; Ulmet, section 2.6) is evaluated
point by point, in registers, with no (N, …) temporaries:

* the knot span by binary search (Piegl & Tiller A2.1);
* the non-zero basis functions and their derivatives (Piegl & Tiller A2.3, eq. 2.9–2.10);
* the homogeneous derivatives A^(k,l), w^(k,l) as Σ_i Σ_j N_i^(k)(u) N_j^(l)(v) P^w_ij; up to
  degree `POWER_FORM_MAX_DEGREE` from each span's power (Taylor) form instead, Σ_kl C_kl τ_u^k τ_v^l
  with τ the local parameter in [0, 1]: no divisions, about 3× fewer operations than A2.3; up to
  bicubic written out in registers (`bicubic_contract`: the same sums, the same bits), a lower degree's
  form padded with zero coefficients to bicubic (planes, and the cylinders, cones and tori of CAD parts);
* the rational derivatives by Piegl & Tiller eq. 4.20 (algorithm A4.4), for k + l <= 2;
* the unit normal (S_u × S_v)/|S_u × S_v| and its degenerate test, and Newton's iteration onto
  the exact ray–surface hit (`newton_lanes`);
* the exact hit's common case fused per ray (`refine_mesh_hits`: the start from a mesh hit's
  barycentrics, Newton, the near-mesh-hit test, t, the unit normal, and the curvatures where Newton
  converges at its one order-2 evaluation, `CURVATURE_EVALUATION`, or one last short step after it, which
  that evaluation's Taylor polynomials finish, `taylor_finish_lanes`), and the Levenberg–Marquardt
  search where Newton fails (`rescue`): `trace.tracing` keeps only the rare paths in numpy;
* Newton and the curvature AOVs in lane blocks ("Lane blocks" below): LANES points per pass, the
  evaluation, the Newton step and the curvature as vector loops across points (AVX-512 or AVX2),
  the same operations per point as the scalar `point_at`, so the same bits.

The patches of a scene live in one flat table (`PatchTable`): degrees, control-point counts,
knot vectors and homogeneous control points concatenated, so one kernel call serves points on
any mix of patches. Every kernel is ``nogil``: the renderer's tile threads run them side by
side, and a point's value depends on its own inputs only (bit-identical whatever the tiling).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from .compiled import njit

from . import JIT

#: Highest derivative order the evaluator serves (curvature needs 2; eq. 4.20 is written out up to it).
MAX_ORDER = 2
#: Power (Taylor) form per span up to this degree and table size; beyond, the B-spline recurrences (A2.3).
#: Its rounding error grows with degree: ~1e-13 of the net's size at degree 5, 4e-12 at 7 (tests/test_surfaces.py).
POWER_FORM_MAX_DEGREE = 5
POWER_FORM_MAX_BYTES = 64 << 20

#: AOT signatures (`kernels.compiled`): `PatchTable.args`, and the arrays of points, rays and their outputs.
TABLE = "i8[:, ::1], i8[:, ::1], i8[:, ::1], f8[::1], i8[::1], f8[:, ::1], f8[:, ::1], i8[::1], f8[:, ::1], i8"
I1, F1, B1, F2 = "i8[::1]", "f8[::1]", "b1[::1]", "f8[:, ::1]"


@dataclass(frozen=True)
class PatchTable:
    """Patches 0..K−1 side by side (K = len(degree)); the arrays the kernels take, in `args` order.

    ``knots[knot_offset[k, d]:]`` is patch k's full knot vector in direction d (u: 0, v: 1);
    ``pw[pw_offset[k] + i·nv + j]`` its homogeneous control point (w·P, w) (i, j);
    ``domain[k]`` = (u0, u1, v0, v1); ``scale[k]`` = (size, reach) of its control net (see
    `geometry.surfaces.VANISHING_PARTIAL`).
    """

    degree: np.ndarray  # (K, 2) int64
    count: np.ndarray  # (K, 2) int64: control points per direction
    knot_offset: np.ndarray  # (K, 2) int64
    knots: np.ndarray  # float64, concatenated
    pw_offset: np.ndarray  # (K,) int64
    pw: np.ndarray  # (Σ nu·nv, 4) float64
    domain: np.ndarray  # (K, 4) float64
    scale: np.ndarray  # (K, 2) float64
    power_offset: np.ndarray  # (K,) int64: first row of patch k's power form in ``power``, −1 where it has none
    power: np.ndarray  # (rows, 4) float64: per span (a, b) of a patch, rows (k, l) of C_kl (`power_form`)
    max_degree: int

    @classmethod
    def of(cls, patches) -> "PatchTable":
        degree = np.array([[p.degree_u, p.degree_v] for p in patches], dtype=np.int64).reshape(-1, 2)
        count = np.array([p.weights.shape for p in patches], dtype=np.int64).reshape(-1, 2)
        knot_list = [k for p in patches for k in (p.knots_u, p.knots_v)]
        lengths = np.array([len(k) for k in knot_list], dtype=np.int64)
        knot_offset = (np.cumsum(lengths) - lengths).reshape(-1, 2)
        sizes = count[:, 0] * count[:, 1]
        pw_offset = np.cumsum(sizes) - sizes
        pw = np.concatenate([p._pw.reshape(-1, 4) for p in patches]) if patches else np.zeros((0, 4))
        domain = np.array([[*p.domain[0], *p.domain[1]] for p in patches], dtype=np.float64).reshape(-1, 4)
        scale = np.array([[p.size, p.reach] for p in patches], dtype=np.float64).reshape(-1, 2)
        knots = np.concatenate(knot_list).astype(np.float64) if knot_list else np.zeros(0)
        forms = [power_form(p) for p in patches]
        rows = np.array([0 if f is None else len(f) for f in forms], dtype=np.int64)
        power_offset = np.where([f is None for f in forms], -1, np.cumsum(rows) - rows).astype(np.int64)
        power = np.concatenate([f for f in forms if f is not None] + [np.zeros((0, 4))])
        return cls(degree, count, knot_offset, np.ascontiguousarray(knots), pw_offset.astype(np.int64),
                   np.ascontiguousarray(pw, dtype=np.float64), domain, scale, power_offset,
                   np.ascontiguousarray(power), int(degree.max(initial=0)))

    @property
    def args(self) -> tuple:
        return (self.degree, self.count, self.knot_offset, self.knots, self.pw_offset, self.pw, self.domain,
                self.power_offset, self.power, self.max_degree)


def power_form(patch) -> np.ndarray | None:
    """Each span's homogeneous polynomial in local τ ∈ [0, 1], from its Taylor expansion at the span start.

    S_w(u, v) = Σ_kl C_kl τ_u^k τ_v^l on span (a, b), with C_kl = Σ_ij M^u_ki M^v_lj P^w_ij and
    M_kr = h^k/k! N_r^(k)(span start) (h the span's length). Rows: span a·(spans in v) + b, then k, l;
    empty spans (repeated knots), which `find_span_at` never returns, hold zeros. Up to bicubic, k and l
    run to 3 whatever the degree, C_kl = 0 beyond it (a polynomial of lower degree is a cubic): every such
    patch is evaluated by the written-out bicubic code (`is_bicubic_power`). None beyond
    `POWER_FORM_MAX_DEGREE` or `POWER_FORM_MAX_BYTES`.
    """
    p, q = patch.degree_u, patch.degree_v
    nu, nv = patch.weights.shape
    padded = max(p, q) <= WRITTEN_OUT_DEGREE  # stored as bicubic, the higher coefficients 0 (`is_bicubic_power`)
    rows = (WRITTEN_OUT_DEGREE + 1) ** 2 if padded else (p + 1) * (q + 1)
    if max(p, q) > POWER_FORM_MAX_DEGREE or (nu - p) * (nv - q) * rows * 4 * 8 > POWER_FORM_MAX_BYTES:
        return None

    def taylor(knots: np.ndarray, degree: int, n_ctrl: int) -> np.ndarray:
        knots = np.ascontiguousarray(knots, dtype=np.float64)
        spans = np.arange(degree, n_ctrl)
        length = knots[spans + 1] - knots[spans]
        full = length > 0
        ders = np.zeros((len(spans), degree + 1, degree + 1))  # (span, k, r)
        some = np.empty((int(full.sum()), degree + 1, degree + 1))
        basis_ders_many(knots, degree, spans[full], knots[spans[full]], degree, some)
        ders[full] = some
        k = np.arange(degree + 1)
        scale = np.where(full, length, 1.0)[:, None] ** k / np.cumprod(np.r_[1, k[1:]])
        return ders * scale[:, :, None]

    Mu, Mv = taylor(patch.knots_u, p, nu), taylor(patch.knots_v, q, nv)
    windows = np.lib.stride_tricks.sliding_window_view(patch._pw, (p + 1, q + 1), axis=(0, 1))  # (a, b, 4, i, j)
    coef = np.einsum("aki,blj,abcij->abklc", Mu, Mv, windows, optimize=True)
    if padded:
        coef = np.pad(coef, ((0, 0), (0, 0), (0, WRITTEN_OUT_DEGREE - p), (0, WRITTEN_OUT_DEGREE - q), (0, 0)))
    return np.ascontiguousarray(coef.reshape(-1, 4))


@njit(inline="always", **JIT)
def find_span_at(knots, lo, p, n_ctrl, t):
    """Knot span i with knots[i] <= t < knots[i+1], clamped to [p, n_ctrl − 1] (Piegl & Tiller A2.1).

    The largest i in [p, n_ctrl − 1] with knots[lo + i] <= t (p where none is): the upper end of
    the domain belongs to the last non-empty span.
    """
    if knots[lo + n_ctrl - 1] <= t:
        return n_ctrl - 1
    low, high = p, n_ctrl - 1
    while high - low > 1:
        mid = (low + high) // 2
        if knots[lo + mid] <= t:
            low = mid
        else:
            high = mid
    return low


@njit(inline="always", **JIT)
def basis_ders_at(knots, lo, span, t, p, n, ders, ndu, a, left, right):
    """Non-zero basis functions N_{span−p+r}^p and derivatives up to n at t (Piegl & Tiller A2.3).

    Writes ders[k, r] for k <= n, r <= p (derivatives beyond p are 0). Every knot difference
    divided by spans the non-empty span [u_span, u_span+1]: never 0, even at repeated knots.
    Scratch: ndu (p+1, p+1), a (2, p+1), left and right (p+1,).
    """
    ndu[0, 0] = 1.0
    for j in range(1, p + 1):
        left[j] = t - knots[lo + span + 1 - j]
        right[j] = knots[lo + span + j] - t
        saved = 0.0
        for r in range(j):
            ndu[j, r] = right[r + 1] + left[j - r]  # lower triangle: knot differences
            temp = ndu[r, j - 1] / ndu[j, r]
            ndu[r, j] = saved + right[r + 1] * temp  # upper triangle: basis functions
            saved = left[j - r] * temp
        ndu[j, j] = saved
    for j in range(p + 1):
        ders[0, j] = ndu[j, p]
    top = min(n, p)
    for r in range(p + 1):
        s1, s2 = 0, 1
        a[0, 0] = 1.0
        for k in range(1, top + 1):
            d = 0.0
            rk, pk = r - k, p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d = a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                d += a[s2, j] * ndu[rk + j, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d += a[s2, k] * ndu[r, pk]
            ders[k, r] = d
            s1, s2 = s2, s1
    factor = float(p)
    for k in range(1, top + 1):
        for j in range(p + 1):
            ders[k, j] *= factor
        factor *= p - k
    for k in range(top + 1, n + 1):
        for j in range(p + 1):
            ders[k, j] = 0.0


@njit(**JIT, aot=(f"void({F1}, i8, {I1}, {F1}, i8, f8[:, :, ::1])",))
def basis_ders_many(knots, p, span, t, n, out):
    """`basis_ders_at` for arrays span, t: out (N, n+1, p+1)."""
    ndu = np.empty((p + 1, p + 1))
    a = np.empty((2, p + 1))
    left = np.empty(p + 1)
    right = np.empty(p + 1)
    for i in range(t.shape[0]):
        basis_ders_at(knots, 0, span[i], t[i], p, n, out[i], ndu, a, left, right)


@njit(**JIT, aot=(f"void({F1}, i8, i8, {F1}, {I1})",))
def find_span_many(knots, p, n_ctrl, t, out):
    for i in range(t.shape[0]):
        out[i] = find_span_at(knots, 0, p, n_ctrl, t[i])


@njit(**JIT)
def new_scratch(max_degree):
    m = max_degree + 1
    return (np.empty((MAX_ORDER + 1, m)), np.empty((MAX_ORDER + 1, m)), np.empty((m, m)), np.empty((2, m)),
            np.empty(m), np.empty(m))



@njit(inline="always", **JIT)
def power_rows(tau, inv_len, degree, order, out):
    """out[m, k] = d^m/dt^m τ^k = k!/(k−m)! τ^(k−m) / h^m for t = start + τ h, m <= order (the power form's basis)."""
    out[0, 0] = 1.0
    for k in range(1, degree + 1):
        out[0, k] = out[0, k - 1] * tau
    scale = 1.0
    for m in range(1, order + 1):
        scale *= inv_len
        for k in range(m):
            out[m, k] = 0.0
        for k in range(m, degree + 1):
            falling = 1.0
            for f in range(k - m + 1, k + 1):
                falling *= f
            out[m, k] = falling * out[0, k - m] * scale


@njit(inline="always", **JIT)
def contract(Nu, Nv, points, base, stride, p, q, order):
    """H_kl = Σ_i Σ_j Nu[k, i] Nv[l, j] points[base + i·stride + j], k + l <= order: A^(k,l), w^(k,l), returned as
    4-tuples (H_00, H_01, H_10, H_02, H_11, H_20) (zeros beyond order).

    The sums over j (v) and then i (u) in scalar accumulators, so they stay in registers; the four
    homogeneous coordinates side by side (one control point's row at a time: SIMD-friendly, ~15%
    faster than one coordinate at a time, the same sums in the same order).
    """
    h00_0 = h00_1 = h00_2 = h00_3 = 0.0
    h01_0 = h01_1 = h01_2 = h01_3 = 0.0
    h10_0 = h10_1 = h10_2 = h10_3 = 0.0
    h02_0 = h02_1 = h02_2 = h02_3 = 0.0
    h11_0 = h11_1 = h11_2 = h11_3 = 0.0
    h20_0 = h20_1 = h20_2 = h20_3 = 0.0
    for i in range(p + 1):
        first = base + i * stride
        r0_0 = r0_1 = r0_2 = r0_3 = 0.0
        r1_0 = r1_1 = r1_2 = r1_3 = 0.0
        r2_0 = r2_1 = r2_2 = r2_3 = 0.0
        if order == 1:
            for j in range(q + 1):
                n0, n1 = Nv[0, j], Nv[1, j]
                x0, x1, x2, x3 = points[first + j, 0], points[first + j, 1], points[first + j, 2], points[first + j, 3]
                r0_0, r0_1, r0_2, r0_3 = r0_0 + n0 * x0, r0_1 + n0 * x1, r0_2 + n0 * x2, r0_3 + n0 * x3
                r1_0, r1_1, r1_2, r1_3 = r1_0 + n1 * x0, r1_1 + n1 * x1, r1_2 + n1 * x2, r1_3 + n1 * x3
        else:
            for j in range(q + 1):
                n0, n1, n2 = Nv[0, j], Nv[1, j], Nv[2, j]
                x0, x1, x2, x3 = points[first + j, 0], points[first + j, 1], points[first + j, 2], points[first + j, 3]
                r0_0, r0_1, r0_2, r0_3 = r0_0 + n0 * x0, r0_1 + n0 * x1, r0_2 + n0 * x2, r0_3 + n0 * x3
                r1_0, r1_1, r1_2, r1_3 = r1_0 + n1 * x0, r1_1 + n1 * x1, r1_2 + n1 * x2, r1_3 + n1 * x3
                r2_0, r2_1, r2_2, r2_3 = r2_0 + n2 * x0, r2_1 + n2 * x1, r2_2 + n2 * x2, r2_3 + n2 * x3
            a0, a1, a2 = Nu[0, i], Nu[1, i], Nu[2, i]
            h02_0, h02_1, h02_2, h02_3 = h02_0 + a0 * r2_0, h02_1 + a0 * r2_1, h02_2 + a0 * r2_2, h02_3 + a0 * r2_3
            h11_0, h11_1, h11_2, h11_3 = h11_0 + a1 * r1_0, h11_1 + a1 * r1_1, h11_2 + a1 * r1_2, h11_3 + a1 * r1_3
            h20_0, h20_1, h20_2, h20_3 = h20_0 + a2 * r0_0, h20_1 + a2 * r0_1, h20_2 + a2 * r0_2, h20_3 + a2 * r0_3
        a0, a1 = Nu[0, i], Nu[1, i]
        h00_0, h00_1, h00_2, h00_3 = h00_0 + a0 * r0_0, h00_1 + a0 * r0_1, h00_2 + a0 * r0_2, h00_3 + a0 * r0_3
        h01_0, h01_1, h01_2, h01_3 = h01_0 + a0 * r1_0, h01_1 + a0 * r1_1, h01_2 + a0 * r1_2, h01_3 + a0 * r1_3
        h10_0, h10_1, h10_2, h10_3 = h10_0 + a1 * r0_0, h10_1 + a1 * r0_1, h10_2 + a1 * r0_2, h10_3 + a1 * r0_3
    return ((h00_0, h00_1, h00_2, h00_3), (h01_0, h01_1, h01_2, h01_3), (h10_0, h10_1, h10_2, h10_3),
            (h02_0, h02_1, h02_2, h02_3), (h11_0, h11_1, h11_2, h11_3), (h20_0, h20_1, h20_2, h20_3))


#: The degree whose power-form evaluation is written out as scalars (`bicubic_contract`): bicubic patches are
#: what the inline scenes, the teapot and the benches are made of. The generic loops over degree-sized scratch
#: arrays cost ~30 % more per evaluation there (S, S_u, S_v on one thread at the render bench's hits: 0.128 µs
#: generic, 0.099 µs written out). Lower degrees are padded to it (`power_form`): CAD parts are mostly planes
#: (1, 1) and rational (2, 1) or (2, 2) cylinders, cones and tori, whose points otherwise took the scalar path
#: one by one (parts/plate.step: Newton's fused pass 1.14 µs a ray against the bicubic patch's 0.20).
WRITTEN_OUT_DEGREE = 3
_ZERO4 = (0.0, 0.0, 0.0, 0.0)


@njit(inline="always", **JIT)
def _madd4(h, a, x):
    """h + a·x of homogeneous 4-tuples h, x (a scalar), coordinate by coordinate."""
    return h[0] + a * x[0], h[1] + a * x[1], h[2] + a * x[2], h[3] + a * x[3]


@njit(inline="always", **JIT)
def _row4(power, first):
    """Homogeneous control coefficient ``power[first]`` as a 4-tuple."""
    return power[first, 0], power[first, 1], power[first, 2], power[first, 3]


@njit(inline="always", **JIT)
def bicubic_net(power, base):
    """The 16 power-form coefficients C_ij of one bicubic span (rows i of four j), as 4-tuples: loaded once, they serve
    every point of the span (`eval_lanes`)."""
    return ((_row4(power, base), _row4(power, base + 1), _row4(power, base + 2), _row4(power, base + 3)),
            (_row4(power, base + 4), _row4(power, base + 5), _row4(power, base + 6), _row4(power, base + 7)),
            (_row4(power, base + 8), _row4(power, base + 9), _row4(power, base + 10), _row4(power, base + 11)),
            (_row4(power, base + 12), _row4(power, base + 13), _row4(power, base + 14), _row4(power, base + 15)))


@njit(inline="always", **JIT)
def _bicubic_row(x, t1, t2, t3, d1, d2, d3, e2, e3, order):
    """Σ_j Nv[m, j] C_ij for m = 0, 1 (and 2): one u-row x of `contract` for q = 3, the zero terms of Nv left out."""
    x0, x1, x2, x3 = x
    r0 = _madd4(_madd4(_madd4(_madd4(_ZERO4, 1.0, x0), t1, x1), t2, x2), t3, x3)
    r1 = _madd4(_madd4(_madd4(_ZERO4, d1, x1), d2, x2), d3, x3)
    r2 = _madd4(_madd4(_ZERO4, e2, x2), e3, x3) if order >= 2 else _ZERO4
    return r0, r1, r2


@njit(inline="always", **JIT)
def _cubic_rows(tau, inv_len):
    """`power_rows` for degree 3, order 2, as scalars: τ, τ², τ³; d/dt of τ, τ², τ³; d²/dt² of τ², τ³ (the same products)."""
    t2 = tau * tau
    s2 = inv_len * inv_len
    return tau, t2, t2 * tau, inv_len, 2.0 * tau * inv_len, 3.0 * t2 * inv_len, 2.0 * s2, 6.0 * tau * s2


@njit(inline="always", **JIT)
def bicubic_contract(power, base, tau_u, inv_u, tau_v, inv_v, order):
    """`contract` of the power form for p = q = 3 (`power_rows`' τ_u, τ_v rows by the C_ij), as `contract` returns it:
    `bicubic_contract_net` of the span's coefficients at ``power[base:base + 16]``."""
    return bicubic_contract_net(bicubic_net(power, base), tau_u, inv_u, tau_v, inv_v, order)


@njit(inline="always", **JIT)
def bicubic_contract_net(net, tau_u, inv_u, tau_v, inv_v, order):
    """`bicubic_contract` of a span's coefficients already loaded (`bicubic_net`).

    The same sums as `power_rows` and `contract` in the same order, so the same bits, but in registers
    (4-tuples, the bases as scalars, the loops unrolled) and without the terms whose basis value is an
    exact 0 (d/dt τ⁰, d²/dt² τ⁰ and τ¹): an accumulator that starts at 0.0 and skips a term 0·x (x finite)
    holds what it would have held after adding it. Straight-line code: across the points of one span it
    vectorises (`eval_lanes`).
    """
    u1, u2, u3, du1, du2, du3, eu2, eu3 = _cubic_rows(tau_u, inv_u)
    v1, v2, v3, dv1, dv2, dv3, ev2, ev3 = _cubic_rows(tau_v, inv_v)
    h00 = h01 = h10 = h02 = h11 = h20 = _ZERO4
    # row i = 0: d^m/dt^m τ⁰ = (1, 0, 0)
    r0, r1, r2 = _bicubic_row(net[0], v1, v2, v3, dv1, dv2, dv3, ev2, ev3, order)
    if order >= 2:
        h02 = _madd4(h02, 1.0, r2)
    h00, h01 = _madd4(h00, 1.0, r0), _madd4(h01, 1.0, r1)
    # row 1: (τ, 1/h, 0)
    r0, r1, r2 = _bicubic_row(net[1], v1, v2, v3, dv1, dv2, dv3, ev2, ev3, order)
    if order >= 2:
        h02, h11 = _madd4(h02, u1, r2), _madd4(h11, du1, r1)
    h00, h01, h10 = _madd4(h00, u1, r0), _madd4(h01, u1, r1), _madd4(h10, du1, r0)
    # rows 2 and 3: every term
    r0, r1, r2 = _bicubic_row(net[2], v1, v2, v3, dv1, dv2, dv3, ev2, ev3, order)
    if order >= 2:
        h02, h11, h20 = _madd4(h02, u2, r2), _madd4(h11, du2, r1), _madd4(h20, eu2, r0)
    h00, h01, h10 = _madd4(h00, u2, r0), _madd4(h01, u2, r1), _madd4(h10, du2, r0)
    r0, r1, r2 = _bicubic_row(net[3], v1, v2, v3, dv1, dv2, dv3, ev2, ev3, order)
    if order >= 2:
        h02, h11, h20 = _madd4(h02, u3, r2), _madd4(h11, du3, r1), _madd4(h20, eu3, r0)
    h00, h01, h10 = _madd4(h00, u3, r0), _madd4(h01, u3, r1), _madd4(h10, du3, r0)
    return h00, h01, h10, h02, h11, h20


@njit(inline="always", **JIT)
def rational_at(A, Au, Av, Auu, Auv, Avv, H, order):
    """One coordinate of S, S_u, S_v, S_uu, S_uv, S_vv from that coordinate's homogeneous derivatives A… and the
    weight's in H (`contract`'s 6 4-tuples) by Piegl & Tiller eq. 4.20: S = A/w, S_u = (A_u − w_u S)/w,
    S_uu = (A_uu − 2 w_u S_u − w_uu S)/w, S_uv = (A_uv − w_uv S − w_u S_v − w_v S_u)/w (the second derivatives
    0.0 for order 1). The coordinate picked by the caller: a constant index into a tuple keeps vector loops
    vectorisable, a variable one (numba's dynamic tuple getitem) does not."""
    h00, h01, h10, h02, h11, h20 = H
    w = h00[3]
    S = A / w
    Su = (Au - h10[3] * S) / w
    Sv = (Av - h01[3] * S) / w
    Suu = Suv = Svv = 0.0
    if order >= 2:
        Suu = (Auu - 2 * h10[3] * Su - h20[3] * S) / w
        Suv = (Auv - h11[3] * S - h10[3] * Sv - h01[3] * Su) / w
        Svv = (Avv - 2 * h01[3] * Sv - h02[3] * S) / w
    return S, Su, Sv, Suu, Suv, Svv


@njit(inline="always", **JIT)
def clamp_to_domain(domain, k, u, v):
    """(u, v) clamped to patch k's parameter domain."""
    if u < domain[k, 0]:
        u = domain[k, 0]
    elif u > domain[k, 1]:
        u = domain[k, 1]
    if v < domain[k, 2]:
        v = domain[k, 2]
    elif v > domain[k, 3]:
        v = domain[k, 3]
    return u, v


@njit(inline="always", **JIT)
def is_bicubic_power(degree, power_offset, k):
    """Whether patch k is evaluated by `bicubic_contract` (at most bicubic, with a power form padded to bicubic)."""
    return power_offset[k] >= 0 and degree[k, 0] <= WRITTEN_OUT_DEGREE and degree[k, 1] <= WRITTEN_OUT_DEGREE


@njit(inline="always", **JIT)
def find_span_near(knots, lo, p, n_ctrl, t, guess):
    """`find_span_at`, answered without the search where t lies in span ``guess`` (the span of the point's previous
    Newton iterate, mostly the same; −1: none): knots[guess] <= t < knots[guess + 1], or the last span and beyond."""
    if guess >= p and knots[lo + guess] <= t and (guess == n_ctrl - 1 or t < knots[lo + guess + 1]):
        return guess
    return find_span_at(knots, lo, p, n_ctrl, t)


@njit(inline="always", **JIT)
def bicubic_span_at(degree, knots, count, knot_offset, power_offset, k, u, v, guess_u, guess_v):
    """Where (u, v) (inside the domain) lies in patch k's power form padded to bicubic (`is_bicubic_power`): (first
    row of its span's 16 C_ij in ``power``, the span indices, each span's start and length h); guesses of the spans
    as `find_span_near`'s."""
    p, q = degree[k, 0], degree[k, 1]
    nu, nv = count[k, 0], count[k, 1]
    ku, kv = knot_offset[k, 0], knot_offset[k, 1]
    su = find_span_near(knots, ku, p, nu, u, guess_u)
    sv = find_span_near(knots, kv, q, nv, v, guess_v)
    start_u, start_v = knots[ku + su], knots[kv + sv]
    len_u, len_v = knots[ku + su + 1] - start_u, knots[kv + sv + 1] - start_v
    span = (su - p) * (nv - q) + (sv - q)
    return power_offset[k] + span * 16, su, sv, start_u, len_u, start_v, len_v


@njit(inline="always", **JIT)
def span_local(t, start, length):
    """(τ, 1/h) of parameter t on the span (start, h): τ = (t − start)/h the power form's local parameter."""
    return (t - start) / length, 1.0 / length


@njit(inline="always", **JIT)
def point_at(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, k, u, v, order, out,
             scratch):
    """S, S_u, S_v (and S_uu, S_uv, S_vv for order 2) of patch k at (u, v), clamped to its domain, into out (6, 3).

    Homogeneous derivatives from the span's power form or the basis (A2.3), then Piegl & Tiller
    eq. 4.20: S = A/w, S_u = (A_u − w_u S)/w, S_uu = (A_uu − 2 w_u S_u − w_uu S)/w,
    S_uv = (A_uv − w_uv S − w_u S_v − w_v S_u)/w (`rational_at`).
    """
    Nu, Nv, ndu, a, left, right = scratch
    p, q = degree[k, 0], degree[k, 1]
    nu, nv = count[k, 0], count[k, 1]
    u, v = clamp_to_domain(domain, k, u, v)
    if is_bicubic_power(degree, power_offset, k):
        base, _, _, start_u, len_u, start_v, len_v = bicubic_span_at(degree, knots, count, knot_offset, power_offset,
                                                                     k, u, v, -1, -1)
        tau_u, inv_u = span_local(u, start_u, len_u)
        tau_v, inv_v = span_local(v, start_v, len_v)
        H = bicubic_contract(power, base, tau_u, inv_u, tau_v, inv_v, order)
    else:
        ku, kv = knot_offset[k, 0], knot_offset[k, 1]
        su = find_span_at(knots, ku, p, nu, u)
        sv = find_span_at(knots, kv, q, nv, v)
        if power_offset[k] >= 0:
            start_u, start_v = knots[ku + su], knots[kv + sv]
            len_u, len_v = knots[ku + su + 1] - start_u, knots[kv + sv + 1] - start_v
            span = (su - p) * (nv - q) + (sv - q)
            power_rows((u - start_u) / len_u, 1.0 / len_u, p, order, Nu)
            power_rows((v - start_v) / len_v, 1.0 / len_v, q, order, Nv)
            H = contract(Nu, Nv, power, power_offset[k] + span * (p + 1) * (q + 1), q + 1, p, q, order)
        else:
            basis_ders_at(knots, ku, su, u, p, order, Nu, ndu, a, left, right)
            basis_ders_at(knots, kv, sv, v, q, order, Nv, ndu, a, left, right)
            H = contract(Nu, Nv, pw, pw_offset[k] + (su - p) * nv + (sv - q), nv, p, q, order)
    h00, h01, h10, h02, h11, h20 = H
    for c in range(3):
        S, Su, Sv, Suu, Suv, Svv = rational_at(h00[c], h10[c], h01[c], h20[c], h11[c], h02[c], H, order)
        out[0, c], out[1, c], out[2, c] = S, Su, Sv
        if order >= 2:
            out[3, c], out[4, c], out[5, c] = Suu, Suv, Svv


@njit(**JIT, aot=(f"void({TABLE}, {I1}, {F1}, {F1}, i8, f8[:, :, ::1])",))
def evaluate(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, max_degree, patch, u, v,
             order, outs):
    """`point_at` for arrays (patch, u, v); outs (3 or 6, N, 3). Rows with patch < 0 are left untouched.

    `LANES` points at a time (`eval_lanes`, as `curvatures_at`): a run of points on one bicubic span in one vector
    loop, the same bits as `point_at` one by one and ~1.4× faster (the analytic path's gradient ends, 80 000 points
    on the peer scene: 25 → 16 ms, JIT against JIT).
    """
    scratch = new_scratch(max_degree)
    d = np.empty((6, 3))
    buf, row, lane_patch, base, span_u, span_v = new_lanes()
    m = outs.shape[0]
    for first in range(0, patch.shape[0], LANES):
        filled = 0
        for i in range(first, min(first + LANES, patch.shape[0])):
            k = patch[i]
            if k < 0:
                continue
            row[filled], lane_patch[filled] = i, k
            buf[LANE_U * LANES + filled], buf[LANE_V * LANES + filled] = u[i], v[i]
            filled += 1
        span_u[:filled] = -1
        span_v[:filled] = -1
        eval_lanes(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, lane_patch, base,
                   span_u, span_v, buf, filled, order, d, scratch)
        for j in range(filled):
            for r in range(m):
                for c in range(3):
                    outs[r, row[j], c] = buf[(LANE_D + 3 * r + c) * LANES + j]


@njit(inline="always", **JIT)
def across_at(D, i, e):
    """Two unit vectors e[0], e[1] spanning the plane normal to direction D[i] (e1 = D × axis / |…|, e2 = D × e1).

    The axis is the coordinate axis along D's smallest component (the first such), so e1 is never tiny.
    """
    x, y, z = D[i, 0], D[i, 1], D[i, 2]
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax <= ay and ax <= az:  # helper (1, 0, 0)
        c0, c1, c2 = 0.0, z, -y
    elif ay <= az:  # helper (0, 1, 0)
        c0, c1, c2 = -z, 0.0, x
    else:  # helper (0, 0, 1)
        c0, c1, c2 = y, -x, 0.0
    norm = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    c0, c1, c2 = c0 / norm, c1 / norm, c2 / norm
    e[0, 0], e[0, 1], e[0, 2] = c0, c1, c2
    e[1, 0], e[1, 1], e[1, 2] = y * c2 - z * c1, z * c0 - x * c2, x * c1 - y * c0


@njit(inline="always", **JIT)
def dot3(a0, a1, a2, b0, b1, b2):
    """a·b of two 3-vectors, summed in coordinate order."""
    return a0 * b0 + a1 * b1 + a2 * b2


@njit(inline="always", **JIT)
def unit_cross(a0, a1, a2, b0, b1, b2):
    """(a × b)/|a × b| and |a × b|: the unit normal's one formula (`normal_at`, `facing_normal_lanes`); NaN where the
    cross vanishes."""
    x0, x1, x2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    norm = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    return x0 / norm, x1 / norm, x2 / norm, norm


@njit(inline="always", **JIT)
def normal_at(domain, scale, k, Su, Sv, i, sine, vanishing):
    """(S_u × S_v)/|S_u × S_v| of row i as (n0, n1, n2, degenerate) (`unit_normals`); n is NaN where the cross vanishes."""
    a0, a1, a2 = Su[i, 0], Su[i, 1], Su[i, 2]
    b0, b1, b2 = Sv[i, 0], Sv[i, 1], Sv[i, 2]
    n0, n1, n2, norm = unit_cross(a0, a1, a2, b0, b1, b2)
    len_u = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    len_v = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
    floor = vanishing * math.sqrt(scale[k, 0] * scale[k, 1])
    bad = not ((norm > sine * len_u * len_v) and (len_u * (domain[k, 1] - domain[k, 0]) > floor)
               and (len_v * (domain[k, 3] - domain[k, 2]) > floor))
    return n0, n1, n2, bad


@njit(**JIT, aot=(f"void({F2}, {F2}, {I1}, {F2}, {F2}, f8, f8, {F2}, {B1})",))
def unit_normals(domain, scale, patch, Su, Sv, sine, vanishing, out, degenerate):
    """n = (S_u × S_v)/|S_u × S_v| per point into out; degenerate[i] where that does not define the normal.

    Degenerate (`geometry.surfaces.NurbsSurface.degenerate`): |S_u × S_v| <= sine·|S_u||S_v|, or a
    partial that vanishes, |S_u|(u1 − u0) or |S_v|(v1 − v0) <= vanishing·√(size · reach). Such rows
    of out are left untouched (the caller takes the limit from the interior). Rows with patch < 0: NaN.
    """
    for i in range(patch.shape[0]):
        k = patch[i]
        if k < 0:
            degenerate[i] = False
            out[i, 0] = out[i, 1] = out[i, 2] = np.nan
            continue
        n0, n1, n2, bad = normal_at(domain, scale, k, Su, Sv, i, sine, vanishing)
        degenerate[i] = bad
        if not bad:
            out[i, 0], out[i, 1], out[i, 2] = n0, n1, n2


@njit(**JIT, aot=(f"void({F2}, {F2}, {I1}, {F2}, {F2}, {F2}, f8, f8, {F2}, {F1}, {B1})",))
def normals_and_cosines(domain, scale, patch, Su, Sv, D, sine, vanishing, out, cosine, degenerate):
    """`normal_at` for every row, written whether degenerate or not, and cosine = n·D (n not turned to the ray)."""
    for i in range(patch.shape[0]):
        n0, n1, n2, bad = normal_at(domain, scale, patch[i], Su, Sv, i, sine, vanishing)
        out[i, 0], out[i, 1], out[i, 2], degenerate[i] = n0, n1, n2, bad
        cosine[i] = dot3(n0, n1, n2, D[i, 0], D[i, 1], D[i, 2])


@njit(inline="always", **JIT)
def barycentric_uv(faces, vertex_uv, f, b1, b2):
    """(u, v) of the point with Embree's barycentrics (b1, b2) on triangle f, from its vertices' (u, v)."""
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    w = 1.0 - b1 - b2
    return (w * vertex_uv[a, 0] + b1 * vertex_uv[b, 0] + b2 * vertex_uv[c, 0],
            w * vertex_uv[a, 1] + b1 * vertex_uv[b, 1] + b2 * vertex_uv[c, 1])


@njit(**JIT, aot=(f"void(i8[:, ::1], {F2}, {I1}, {F1}, {F1}, {F1}, {F1})",))
def start_parameters(faces, vertex_uv, prim, b1, b2, u, v):
    """`barycentric_uv` for every mesh hit (prim, b1, b2): the start of Newton (`geometry.tessellation`)."""
    for i in range(prim.shape[0]):
        u[i], v[i] = barycentric_uv(faces, vertex_uv, prim[i], b1[i], b2[i])


# -- Lane blocks: one pass per stage over a block of points, so the arithmetic vectorises across points ----------
# (issue 14 goal 2). Scalar code per point leaves SIMD units idle and waits on each division's latency; a loop over
# a block's points of straight-line arithmetic, every operand at buf[field·LANES + j], compiles to AVX-512 (or
# AVX2) arithmetic on 8 (4) points at a time. Each point's operations and their order are those of the scalar code
# (numba contracts no a·b + c into an FMA without fastmath), so the bits are the same; only where the work is
# irregular (the knot span's binary search, non-bicubic patches) a scalar pass per point remains.

#: Points per block: the fields of a block (`LANE_FIELDS` × LANES doubles, 52 KB) stay in the L2 cache, and the
#: runs of points on one span (`eval_lanes`) are long enough for the vector loop (adjacent pixels share spans).
LANES = 128
#: Fields of a lane block, each LANES doubles at field·LANES in one flat buffer: constant offsets from one base,
#: so LLVM proves the loads and stores of a vector loop independent without runtime checks.
LANE_SPAN = 0  # u, span start, span length, then the same for v: where the point lies (`bicubic_span_at`)
LANE_D = 6  # S, S_u, S_v, S_uu, S_uv, S_vv: 18 fields, coordinate by coordinate (`rational_at`)
LANE_U, LANE_V, LANE_TOL = 24, 25, 26  # Newton's (u, v) and tolerance
LANE_E = 27  # e1, e2 (6 fields, `across_at`); the unit normal n for the curvature (3)
LANE_O = 33  # the ray's origin (3 fields)
LANE_DOMAIN = 36  # u0, u1, v0, v1 of the point's patch (4 fields)
LANE_STATE = 40  # Newton's state after a step: `STEPPING`, `CONVERGED` or `STOPPED`
LANE_DIR = 41  # the ray's direction D (3 fields), which the normal for Newton's curvatures faces
LANE_N = 44  # that unit normal (3 fields, `facing_normal_lanes`)
LANE_CURVATURE = 47  # K, H, κ1, κ2 (4 fields)
LANE_FIELDS = 51
STEPPING, CONVERGED, STOPPED = 0.0, 1.0, 2.0


@njit(inline="always", **JIT)
def new_lanes():
    """A lane block's buffers (`eval_lanes`): the LANE_FIELDS × LANES field buffer, and per lane its row, patch,
    span base and spans in u and v (`find_span_near`'s guesses)."""
    return (np.empty(LANE_FIELDS * LANES), np.empty(LANES, dtype=np.int64), np.empty(LANES, dtype=np.int64),
            np.empty(LANES, dtype=np.int64), np.empty(LANES, dtype=np.int64), np.empty(LANES, dtype=np.int64))


@njit(inline="always", **JIT)
def _store_coordinate(lane, j, c, derivatives, order):
    """Coordinate c of S and its derivatives (`rational_at`) into the lane fields `LANE_D`… of point j."""
    S, Su, Sv, Suu, Suv, Svv = derivatives
    lane[(LANE_D + c) * LANES + j] = S
    lane[(LANE_D + 3 + c) * LANES + j] = Su
    lane[(LANE_D + 6 + c) * LANES + j] = Sv
    if order >= 2:
        lane[(LANE_D + 9 + c) * LANES + j] = Suu
        lane[(LANE_D + 12 + c) * LANES + j] = Suv
        lane[(LANE_D + 15 + c) * LANES + j] = Svv


@njit(inline="always", **JIT)
def _eval_run(net, buf, a, b, order):
    """S and its derivatives (`bicubic_contract_net`, `rational_at`) at points a..b−1 of a block, all on the span
    whose coefficients are net: the vector loop."""
    lane = buf[a:]  # indices from 0: numba's negative-index wrap-around folds away, the accesses stay affine
    for j in range(b - a):
        u, start_u, len_u = _field3(lane, LANE_SPAN, j)
        v, start_v, len_v = _field3(lane, LANE_SPAN + 3, j)
        tau_u, inv_u = span_local(u, start_u, len_u)  # here, not in the span pass: the divisions vectorise
        tau_v, inv_v = span_local(v, start_v, len_v)
        H = bicubic_contract_net(net, tau_u, inv_u, tau_v, inv_v, order)
        h00, h01, h10, h02, h11, h20 = H
        _store_coordinate(lane, j, 0, rational_at(h00[0], h10[0], h01[0], h20[0], h11[0], h02[0], H, order), order)
        _store_coordinate(lane, j, 1, rational_at(h00[1], h10[1], h01[1], h20[1], h11[1], h02[1], H, order), order)
        _store_coordinate(lane, j, 2, rational_at(h00[2], h10[2], h01[2], h20[2], h11[2], h02[2], H, order), order)


@njit(inline="always", **JIT)
def eval_lanes(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, patch, base, span_u,
               span_v, buf, n, order, d, scratch):
    """`point_at` at points 0..n−1 of a lane block (patch[j], (u, v) in `LANE_U`, `LANE_V`) into the fields `LANE_D`….

    A scalar pass finds each point's span (`bicubic_span_at`, from the guesses span_u[j], span_v[j] (−1: none),
    which it updates; other patches: `point_at` itself); then each run of
    consecutive points on one bicubic span is evaluated by one vector loop (`_eval_run`), its 16 coefficients
    loaded once (no gathers).
    """
    for j in range(n):
        k = patch[j]
        u, v = clamp_to_domain(domain, k, buf[LANE_U * LANES + j], buf[LANE_V * LANES + j])
        if is_bicubic_power(degree, power_offset, k):
            first, span_u[j], span_v[j], start_u, len_u, start_v, len_v = bicubic_span_at(
                degree, knots, count, knot_offset, power_offset, k, u, v, span_u[j], span_v[j])
            base[j] = first
            buf[LANE_SPAN * LANES + j], buf[(LANE_SPAN + 1) * LANES + j] = u, start_u
            buf[(LANE_SPAN + 2) * LANES + j], buf[(LANE_SPAN + 3) * LANES + j] = len_u, v
            buf[(LANE_SPAN + 4) * LANES + j], buf[(LANE_SPAN + 5) * LANES + j] = start_v, len_v
        else:
            base[j] = -1
            point_at(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, k, u, v, order, d,
                     scratch)
            for r in range(3 * order):
                for c in range(3):
                    buf[(LANE_D + 3 * r + c) * LANES + j] = d[r, c]
    a = 0
    while a < n:
        b = a + 1
        while b < n and base[b] == base[a]:
            b += 1
        if base[a] >= 0:
            _eval_run(bicubic_net(power, base[a]), buf, a, b, order)
        a = b


@njit(inline="always", **JIT)
def _field3(buf, field, j):
    return buf[field * LANES + j], buf[(field + 1) * LANES + j], buf[(field + 2) * LANES + j]


@njit(inline="always", **JIT)
def _ray_residual(buf, j, P0, P1, P2):
    """The ray condition's residual at a point P of lane j: (r1, r2) = (e1·(P − O), e2·(P − O)) (`newton_lanes`)."""
    O0, O1, O2 = _field3(buf, LANE_O, j)
    e00, e01, e02 = _field3(buf, LANE_E, j)
    e10, e11, e12 = _field3(buf, LANE_E + 3, j)
    r0, r1, r2 = P0 - O0, P1 - O1, P2 - O2
    return e00 * r0 + e01 * r1 + e02 * r2, e10 * r0 + e11 * r1 + e12 * r2


@njit(inline="always", **JIT)
def _on_ray(f1, f2, tol):
    """Newton's convergence test |(r1, r2)| <= tol, squared: math.hypot is a libm call; without it the fused pass takes
    4–10 % less CPU (the verdict differs only within an ulp of tol)."""
    return f1 * f1 + f2 * f2 <= tol * tol


# -- Newton onto the exact hit (`trace.tracing`) ---------------------------------------------
# In this file, not one of its own: numba's cache watches only the file that defines a kernel, and a
# cached caller of a changed callee in another file ran stale machine code (a segmentation fault).

#: A step is refused where |det J| <= this × |S_u| |S_v| (det J = D·(S_u × S_v), a sine of the incidence).
SINGULAR_SINE = 1e-12


@njit(inline="always", **JIT)
def newton_lanes(buf, n, last):
    """One step of Newton on S(u, v) = O + tD at points 0..n−1 of a lane block (S, S_u, S_v evaluated at (u, v)):
    the vector loop; `LANE_STATE` says which points are done.

    DESIGN.md, "Exact hit": the ray condition as two equations across the ray, r1 = e1·(S − O) = 0
    and r2 = e2·(S − O) = 0 with e1, e2 ⊥ D (`across_at`), Jacobian J = [[e1·S_u, e1·S_v],
    [e2·S_u, e2·S_v]]; each step solves J (δu, δv) = (r1, r2) by Cramer's rule and clamps (u, v)
    to the patch's domain. det J = D·(S_u × S_v): tiny at grazing rays and degenerate points,
    where Newton is not to be trusted (`SINGULAR_SINE`).

    `CONVERGED` once |(r1, r2)| <= tol, checked after each evaluation (at most max_steps steps,
    max_steps + 1 evaluations: ``last`` on the last); `STOPPED` unconverged at the last evaluation,
    a singular Jacobian or a non-finite step. Every quantity is computed for every point and the
    verdict selected (branch-free: the loop vectorises); a done point keeps its (u, v).
    """
    for j in range(n):
        S0, S1, S2 = _field3(buf, LANE_D, j)
        Su0, Su1, Su2 = _field3(buf, LANE_D + 3, j)
        Sv0, Sv1, Sv2 = _field3(buf, LANE_D + 6, j)
        e00, e01, e02 = _field3(buf, LANE_E, j)
        e10, e11, e12 = _field3(buf, LANE_E + 3, j)
        ui, vi, tol = buf[LANE_U * LANES + j], buf[LANE_V * LANES + j], buf[LANE_TOL * LANES + j]
        f1, f2 = _ray_residual(buf, j, S0, S1, S2)
        converged = _on_ray(f1, f2, tol)
        a = e00 * Su0 + e01 * Su1 + e02 * Su2
        b = e00 * Sv0 + e01 * Sv1 + e02 * Sv2
        c = e10 * Su0 + e11 * Su1 + e12 * Su2
        dd = e10 * Sv0 + e11 * Sv1 + e12 * Sv2
        det = a * dd - b * c
        len_u = math.sqrt(Su0 ** 2 + Su1 ** 2 + Su2 ** 2)
        len_v = math.sqrt(Sv0 ** 2 + Sv1 ** 2 + Sv2 ** 2)
        regular = abs(det) > SINGULAR_SINE * len_u * len_v
        du = (dd * f1 - b * f2) / det
        dv = (a * f2 - c * f1) / det
        # derivatives ~1e-296 pass the singular test, then overflow
        finite = (abs(du) < math.inf) & (abs(dv) < math.inf)
        step = (not converged) & (not last) & regular & finite
        u0, u1 = buf[LANE_DOMAIN * LANES + j], buf[(LANE_DOMAIN + 1) * LANES + j]
        v0, v1 = buf[(LANE_DOMAIN + 2) * LANES + j], buf[(LANE_DOMAIN + 3) * LANES + j]
        un = min(max(ui - du, u0), u1)
        vn = min(max(vi - dv, v0), v1)
        buf[LANE_U * LANES + j] = un if step else ui
        buf[LANE_V * LANES + j] = vn if step else vi
        buf[LANE_STATE * LANES + j] = CONVERGED if converged else (STEPPING if step else STOPPED)


@njit(inline="always", **JIT)
def taylor_finish_lanes(buf, base, n):
    """Newton's step just taken (`newton_lanes`) finished without another evaluation, at points 0..n−1 of a lane block
    evaluated to order 2 on a bicubic span (base[j] ≥ 0; `LANE_SPAN` holds the evaluated (u, v) and the spans): with
    (δu, δv) = the new (u, v) − the evaluated one, the second-order Taylor polynomials

        S' = S + S_u δu + S_v δv + ½ (S_uu δu² + 2 S_uv δu δv + S_vv δv²),
        S_u' = S_u + (S_uu δu + S_uv δv),    S_v' = S_v + (S_uv δu + S_vv δv)

    replace S, S_u, S_v, and the point is `CONVERGED` where its residual |(e1·(S' − O), e2·(S' − O))| is within the
    tolerance (`newton_lanes`' test), the step at most `TAYLOR_SPAN_SHARE` of its span along u and v and strictly
    inside the span and the domain (no clamp, no knot crossed: the span's one polynomial), S_u and S_v turn by at
    most `TAYLOR_TURN` of their length (not by a pole), and |n·D| is above `TAYLOR_MIN_COSINE`. Elsewhere nothing
    changes (the next evaluation at the new (u, v) follows). The curvatures (`curvature_lanes`) stay those of the
    evaluated point, ≤ 1e-6 of a span away. The vector loop, branch-free."""
    for j in range(n):
        u0, start_u, len_u = _field3(buf, LANE_SPAN, j)
        v0, start_v, len_v = _field3(buf, LANE_SPAN + 3, j)
        un, vn = buf[LANE_U * LANES + j], buf[LANE_V * LANES + j]
        du, dv = un - u0, vn - v0
        S0, S1, S2 = _field3(buf, LANE_D, j)
        Su0, Su1, Su2 = _field3(buf, LANE_D + 3, j)
        Sv0, Sv1, Sv2 = _field3(buf, LANE_D + 6, j)
        Suu0, Suu1, Suu2 = _field3(buf, LANE_D + 9, j)
        Suv0, Suv1, Suv2 = _field3(buf, LANE_D + 12, j)
        Svv0, Svv1, Svv2 = _field3(buf, LANE_D + 15, j)
        uu, uv, vv = 0.5 * du * du, du * dv, 0.5 * dv * dv
        P0 = S0 + Su0 * du + Sv0 * dv + (Suu0 * uu + Suv0 * uv + Svv0 * vv)
        P1 = S1 + Su1 * du + Sv1 * dv + (Suu1 * uu + Suv1 * uv + Svv1 * vv)
        P2 = S2 + Su2 * du + Sv2 * dv + (Suu2 * uu + Suv2 * uv + Svv2 * vv)
        f1, f2 = _ray_residual(buf, j, P0, P1, P2)
        tol = buf[LANE_TOL * LANES + j]
        n0, n1, n2 = _field3(buf, LANE_N, j)
        D0, D1, D2 = _field3(buf, LANE_DIR, j)
        lo_u, hi_u = buf[LANE_DOMAIN * LANES + j], buf[(LANE_DOMAIN + 1) * LANES + j]
        lo_v, hi_v = buf[(LANE_DOMAIN + 2) * LANES + j], buf[(LANE_DOMAIN + 3) * LANES + j]
        inside = ((max(start_u, lo_u) < un) & (un < min(start_u + len_u, hi_u))
                  & (max(start_v, lo_v) < vn) & (vn < min(start_v + len_v, hi_v)))
        short = (abs(du) <= TAYLOR_SPAN_SHARE * len_u) & (abs(dv) <= TAYLOR_SPAN_SHARE * len_v)
        cu0, cu1, cu2 = Suu0 * du + Suv0 * dv, Suu1 * du + Suv1 * dv, Suu2 * du + Suv2 * dv  # S_u's turn
        cv0, cv1, cv2 = Suv0 * du + Svv0 * dv, Suv1 * du + Svv1 * dv, Suv2 * du + Svv2 * dv
        turn = TAYLOR_TURN * TAYLOR_TURN
        steady = ((dot3(cu0, cu1, cu2, cu0, cu1, cu2) <= turn * dot3(Su0, Su1, Su2, Su0, Su1, Su2))
                  & (dot3(cv0, cv1, cv2, cv0, cv1, cv2) <= turn * dot3(Sv0, Sv1, Sv2, Sv0, Sv1, Sv2)))
        done = ((buf[LANE_STATE * LANES + j] == STEPPING) & (base[j] >= 0) & inside & short & steady
                & _on_ray(f1, f2, tol) & (abs(dot3(n0, n1, n2, D0, D1, D2)) > TAYLOR_MIN_COSINE))
        buf[LANE_D * LANES + j] = P0 if done else S0
        buf[(LANE_D + 1) * LANES + j] = P1 if done else S1
        buf[(LANE_D + 2) * LANES + j] = P2 if done else S2
        buf[(LANE_D + 3) * LANES + j] = (Su0 + cu0) if done else Su0
        buf[(LANE_D + 4) * LANES + j] = (Su1 + cu1) if done else Su1
        buf[(LANE_D + 5) * LANES + j] = (Su2 + cu2) if done else Su2
        buf[(LANE_D + 6) * LANES + j] = (Sv0 + cv0) if done else Sv0
        buf[(LANE_D + 7) * LANES + j] = (Sv1 + cv1) if done else Sv1
        buf[(LANE_D + 8) * LANES + j] = (Sv2 + cv2) if done else Sv2
        buf[LANE_STATE * LANES + j] = CONVERGED if done else buf[LANE_STATE * LANES + j]


@njit(inline="always", **JIT)
def jump_reach(chord, cos, jump_limit, grazing_allowance):
    """How far a refined hit may lie from its mesh hit and still be that mesh hit's (`near_at`), the one formula.

    jump_limit · chord, grown as 1/cos θ (θ the ray's incidence, cos θ = |D·(S_u × S_v)| / |S_u × S_v|; no growth
    where cos is NaN) up to grazing_allowance times: the mesh-to-surface gap along a ray grows so
    (`trace.tracing.JUMP_LIMIT`). At cos θ = 1 the plain limit. Largest at cos θ = 0 (a grazing ray): what a filter
    needs that must keep every point some normal could let pass (`jump_reaches`, `trace.tracing._may_win_restart`).
    """
    allowance = 1.0 / cos
    if math.isnan(allowance):
        allowance = 1.0
    allowance = min(max(allowance, 1.0), grazing_allowance)
    return jump_limit * chord * allowance


@njit(**JIT, aot=(f"void({F1}, f8, f8, f8, {F1})",))
def jump_reaches(chord, cos, jump_limit, grazing_allowance, out):
    """`jump_reach` of each chord error (one per patch) at one incidence cosine: cos = 0 gives the largest."""
    for k in range(chord.shape[0]):
        out[k] = jump_reach(chord[k], cos, jump_limit, grazing_allowance)


@njit(inline="always", **JIT)
def near_at(S, Su, Sv, O, D, i, t_mesh, chord, jump_limit, grazing_allowance):
    """Whether the refined hit of ray i lies ahead and within reach of its mesh hit at t_mesh, and t = (S − O)·D.

    Within reach (not on another sheet): |S − (O + t_mesh D)| <= `jump_reach` at the hit's incidence. The normal
    only for hits beyond the plain limit (cos θ = 1).
    """
    t = dot3(S[i, 0] - O[i, 0], S[i, 1] - O[i, 1], S[i, 2] - O[i, 2], D[i, 0], D[i, 1], D[i, 2])
    j0 = S[i, 0] - (O[i, 0] + t_mesh * D[i, 0])
    j1 = S[i, 1] - (O[i, 1] + t_mesh * D[i, 1])
    j2 = S[i, 2] - (O[i, 2] + t_mesh * D[i, 2])
    jump = math.sqrt(j0 * j0 + j1 * j1 + j2 * j2)
    near = jump <= jump_reach(chord, 1.0, jump_limit, grazing_allowance)
    if not near:
        a0, a1, a2 = Su[i, 0], Su[i, 1], Su[i, 2]
        b0, b1, b2 = Sv[i, 0], Sv[i, 1], Sv[i, 2]
        x0, x1, x2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
        cos = abs(dot3(x0, x1, x2, D[i, 0], D[i, 1], D[i, 2])) / math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        near = jump <= jump_reach(chord, cos, jump_limit, grazing_allowance)
    return (t > 0) and near, t


@njit(**JIT, aot=(f"void({I1}, {F2}, {F2}, {F2}, {F2}, {F2}, {F1}, {F1}, f8, f8, {B1}, {F1})",))
def near_mesh_hits(patch, S, Su, Sv, O, D, t_mesh, band, jump_limit, grazing_allowance, near, t):
    """`near_at` for each ray (patch k's reach: band[k] chord errors)."""
    for i in range(patch.shape[0]):
        near[i], t[i] = near_at(S, Su, Sv, O, D, i, t_mesh[i], band[patch[i]], jump_limit, grazing_allowance)


@njit(inline="always", **JIT)
def on_domain_edge(domain, k, u, v):
    """Whether (u, v) lies on an edge of patch k's parameter domain (where Newton's clamping stopped it)."""
    return u == domain[k, 0] or u == domain[k, 1] or v == domain[k, 2] or v == domain[k, 3]


#: Newton's evaluation of this index (0: at the start) is of order 2 (`refine_mesh_hits`), so that where it converges
#: the curvatures there come from the same pass: every hit needs them (the AOVs K, H, κ1, κ2, and
#: `trace.tracing._other_root`'s prefilter), and the separate order-2 pass (`curvatures_at`) evaluated the patch again
#: at the same (u, v). The second evaluation (after one step from the mesh hit): there 11 % of the full-HD bench
#: scene's hits have converged, and nearly all others take their last step, which the order-2 derivatives finish
#: without evaluating again (`taylor_finish_lanes`). One evaluation only, so a ray that goes on pays for one order-2
#: evaluation at most.
CURVATURE_EVALUATION = 1
#: `taylor_finish_lanes` takes a step of at most this share of the knot span it lies in, along u and along v: the
#: Taylor remainders are then those of the span's polynomial at |δ|/h ≤ 1e-6, (|δ|/h)³ ~ 1e-18 of S's coefficients
#: for S and (|δ|/h)² ~ 1e-12 for S_u, S_v: S to rounding, the unit normal to 1e-12 rad, as Newton's tolerance
#: places the point. On the bench scene the last step is ~1e-8 of a span (the residual it cancels ~1e-9 of the
#: scene's size).
TAYLOR_SPAN_SHARE = 1e-6
#: ... where S_u and S_v turn over the step by at most this share of their length (|S_uu δu + S_uv δv| ≤ this · |S_u|,
#: likewise S_v): the remainder's bound above is of the span's coefficients, and near a pole or a collapsed edge S_u
#: or S_v is far shorter than they are.
TAYLOR_TURN = 1e-6
#: ... where the ray meets the surface at |n·D| above this: the curvatures taken before the step keep the sign of
#: the normal facing the ray after it (which turns by ≤ ~1e-6 rad).
TAYLOR_MIN_COSINE = 1e-3


@njit(**JIT, aot=(f"void({TABLE}, {F2}, i8[:, ::1], {F2}, {I1}, {F1}, {I1}, {F1}, {F1}, {F2}, {F2}, {F1}, "
                        f"f8, f8, i8, f8, f8, f8, f8, {I1}, {F1}, {F1}, {F1}, {F1}, {F2}, {F2}, {F2}, {F1}, {F2}, {F1}, "
                        f"{B1}, {B1}, {B1}, {B1}, {F2})",))
def refine_mesh_hits(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, max_degree,
                     scale, faces, vertex_uv, face_patch, band, prim, b1, b2, O, D, t_mesh, extent, tolerance,
                     max_steps, jump_limit, grazing_allowance, sine, vanishing,
                     patch, u_start, v_start, u, v, S, Su, Sv, t, normal, cosine, converged, near, edge, degenerate,
                     curvature):
    """The common case of the exact hit, fused per ray (`trace.tracing._candidates`): no (N, 3) temporaries.

    For each mesh hit (triangle prim, Embree's barycentrics b1, b2, distance t_mesh): the start
    (u, v) on the triangle's patch (`barycentric_uv`), written to patch, u_start, v_start; where
    prim < 0, the start is read from them instead (`trace.tracing.refine`: Newton from a given
    (u, v), the one compiled copy of Newton). Then Newton (`newton_lanes`) to the tolerance
    tolerance · max(t_mesh, extent, |mesh point|_∞) (S's coordinates are not computed more finely), LANES
    rays at a time (`eval_lanes`, `newton_lanes`; the step after the order-2 evaluation, `CURVATURE_EVALUATION`,
    finished by its Taylor polynomials where it is short, `taylor_finish_lanes`);
    whether the hit is ahead and near its mesh hit, and its t (`near_at`); whether an unconverged
    Newton stopped on the domain's edge (`on_domain_edge`); the unit normal n = (S_u × S_v)/|S_u × S_v|
    (not yet turned to the ray), cosine = n·D, and whether n is degenerate (`normal_at`); where Newton converged at
    its evaluation of order 2 (`CURVATURE_EVALUATION`) or Taylor finished the step after it, K, H, κ1, κ2 at that
    evaluation for its n turned to face the ray (`facing_normal_lanes`, `curvature_lanes`: `curvatures_at`'s values
    there for that normal) into curvature (N, 4), elsewhere NaN.
    """
    scratch = new_scratch(max_degree)
    d = np.empty((6, 3))
    e = np.empty((2, 3))
    buf, ray, lane_patch, base, span_u, span_v = new_lanes()
    for first in range(0, prim.shape[0], LANES):
        m = min(LANES, prim.shape[0] - first)
        for j in range(m):  # the starts, tolerances and the planes across the rays
            i = first + j
            f = prim[i]
            if f >= 0:
                k = face_patch[f]
                us, vs = barycentric_uv(faces, vertex_uv, f, b1[i], b2[i])
            else:
                k, us, vs = patch[i], u_start[i], v_start[i]
            tm = t_mesh[i]
            magnitude = max(abs(O[i, 0] + tm * D[i, 0]), abs(O[i, 1] + tm * D[i, 1]), abs(O[i, 2] + tm * D[i, 2]))
            patch[i], u_start[i], v_start[i] = k, us, vs
            ray[j], lane_patch[j], span_u[j], span_v[j] = i, k, -1, -1
            buf[LANE_U * LANES + j], buf[LANE_V * LANES + j] = us, vs
            buf[LANE_TOL * LANES + j] = tolerance * max(max(tm, extent), magnitude)
            across_at(D, i, e)
            for c in range(3):
                buf[(LANE_E + c) * LANES + j], buf[(LANE_E + 3 + c) * LANES + j] = e[0, c], e[1, c]
                buf[(LANE_O + c) * LANES + j] = O[i, c]
                buf[(LANE_DIR + c) * LANES + j] = D[i, c]
            for c in range(4):
                buf[(LANE_DOMAIN + c) * LANES + j] = domain[k, c]
        active = m
        for step in range(max_steps + 1):  # Newton on the rays not yet done, which stay packed at the front
            second = step == CURVATURE_EVALUATION
            if second:  # two calls, each with its order a constant: the vector loops keep no branch on it
                eval_lanes(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, lane_patch,
                           base, span_u, span_v, buf, active, 2, d, scratch)
            else:
                eval_lanes(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, lane_patch,
                           base, span_u, span_v, buf, active, 1, d, scratch)
            newton_lanes(buf, active, step == max_steps)
            if second:  # for every point, as vector loops: cheaper than for the converged ones one by one
                facing_normal_lanes(buf, active)
                curvature_lanes(buf, active, LANE_N)
                taylor_finish_lanes(buf, base, active)
            kept = 0
            for j in range(active):
                state = buf[LANE_STATE * LANES + j]
                if state != STEPPING:
                    i = ray[j]
                    u[i], v[i], converged[i] = buf[LANE_U * LANES + j], buf[LANE_V * LANES + j], state == CONVERGED
                    for c in range(3):
                        S[i, c] = buf[(LANE_D + c) * LANES + j]
                        Su[i, c] = buf[(LANE_D + 3 + c) * LANES + j]
                        Sv[i, c] = buf[(LANE_D + 6 + c) * LANES + j]
                    taken = second and state == CONVERGED
                    for r in range(4):
                        curvature[i, r] = buf[(LANE_CURVATURE + r) * LANES + j] if taken else np.nan
                    continue
                if kept != j:
                    ray[kept], lane_patch[kept], span_u[kept], span_v[kept] = ray[j], lane_patch[j], span_u[j], span_v[j]
                    for field in range(LANE_U, LANE_DIR + 3):
                        buf[field * LANES + kept] = buf[field * LANES + j]
                kept += 1
            active = kept
            if active == 0:
                break
        for i in range(first, first + m):
            k, ok = patch[i], converged[i]
            near[i], t[i] = near_at(S, Su, Sv, O, D, i, t_mesh[i], band[k], jump_limit, grazing_allowance)
            edge[i] = (not ok) and on_domain_edge(domain, k, u[i], v[i])
            n0, n1, n2, bad = normal_at(domain, scale, k, Su, Sv, i, sine, vanishing)
            normal[i, 0], normal[i, 1], normal[i, 2], degenerate[i] = n0, n1, n2, bad
            cosine[i] = dot3(n0, n1, n2, D[i, 0], D[i, 1], D[i, 2])


@njit(inline="always", **JIT)
def stationary_at(g1, g2, jacobian_square, rn, stationary_cosine):
    """Whether |r|² is stationary: r normal to the tangent plane, the cosine of the gradient Jᵀr = (g1, g2) against
    |J| |r| (|J|² = jacobian_square, the Frobenius norm's square) not above stationary_cosine (NaN counts as
    stationary: Jᵀr = 0 with J = 0). The one test of `rescue` and of `passes_by` (`trace.tracing._passes_by`)."""
    return not (math.hypot(g1, g2) / (math.sqrt(jacobian_square) * rn) > stationary_cosine)


@njit(**JIT, aot=(f"void({TABLE}, {I1}, {F1}, {F1}, {F2}, {F2}, {F1}, i8, f8, {B1})",))
def passes_by(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, max_degree,
              patch, u, v, O, D, tol, steps, stationary_cosine, passes):
    """Newton on f = ½|r|², r = (S − O) − ((S − O)·D) D, from (u, v), ``steps`` steps, then the positive-minimum test
    at the last point (`trace.tracing._passes_by`, whose docstring gives the gradient and the full Hessian): per ray,
    passes where the Hessian is positive definite, |r| > tol and the point is stationary (`stationary_at`). A step
    with a non-finite component is no step along it; each step is clamped to the domain (`clamp_to_domain`)."""
    scratch = new_scratch(max_degree)
    d = np.empty((6, 3))
    for i in range(patch.shape[0]):
        k = patch[i]
        ui, vi = u[i], v[i]
        O0, O1, O2, D0, D1, D2 = O[i, 0], O[i, 1], O[i, 2], D[i, 0], D[i, 1], D[i, 2]
        step = 0
        while True:
            point_at(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, k, ui, vi, 2, d,
                     scratch)
            q0, q1, q2 = d[0, 0] - O0, d[0, 1] - O1, d[0, 2] - O2
            qD = dot3(q0, q1, q2, D0, D1, D2)
            r0, r1, r2 = q0 - qD * D0, q1 - qD * D1, q2 - qD * D2
            uD = dot3(d[1, 0], d[1, 1], d[1, 2], D0, D1, D2)
            vD = dot3(d[2, 0], d[2, 1], d[2, 2], D0, D1, D2)
            pu0, pu1, pu2 = d[1, 0] - uD * D0, d[1, 1] - uD * D1, d[1, 2] - uD * D2  # S_u⊥
            pv0, pv1, pv2 = d[2, 0] - vD * D0, d[2, 1] - vD * D1, d[2, 2] - vD * D2  # S_v⊥
            gu = dot3(r0, r1, r2, d[1, 0], d[1, 1], d[1, 2])
            gv = dot3(r0, r1, r2, d[2, 0], d[2, 1], d[2, 2])
            uu, uv, vv = dot3(pu0, pu1, pu2, pu0, pu1, pu2), dot3(pu0, pu1, pu2, pv0, pv1, pv2), dot3(pv0, pv1, pv2,
                                                                                                      pv0, pv1, pv2)
            a = uu + dot3(r0, r1, r2, d[3, 0], d[3, 1], d[3, 2])
            b = uv + dot3(r0, r1, r2, d[4, 0], d[4, 1], d[4, 2])
            c = vv + dot3(r0, r1, r2, d[5, 0], d[5, 1], d[5, 2])
            det = a * c - b * b
            if step == steps:
                rn = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
                passes[i] = a > 0 and det > 0 and rn > tol[i] and stationary_at(gu, gv, uu + vv, rn, stationary_cosine)
                break
            step += 1
            du, dv = (c * gu - b * gv) / det, (a * gv - b * gu) / det
            ui, vi = clamp_to_domain(domain, k, ui - (du if math.isfinite(du) else 0.0),
                                     vi - (dv if math.isfinite(dv) else 0.0))


#: `walk_past_minimum`'s verdicts per row: left the band (or its steps) without crossing; crossed between its last
#: two points; stopped at a foot whose normal is degenerate, for the caller's limit normal (`geometry.surfaces`).
WALK_DROPPED, WALK_CROSSED, WALK_PAUSED = 0, 1, 2


@njit(inline="always", **JIT)
def tangent_step(a0, a1, a2, b0, b1, b2, w0, w1, w2):
    """(du, dv) whose tangent step du S_u + dv S_v (S_u = a, S_v = b) is nearest the vector w, in least squares: the
    normal equations of the first fundamental form, [[E, F], [F, G]] (du, dv) = (S_u·w, S_v·w) with E = S_u·S_u,
    F = S_u·S_v, G = S_v·S_v, by Cramer's rule (inf or NaN where EG − F² = 0)."""
    E, F, G = dot3(a0, a1, a2, a0, a1, a2), dot3(a0, a1, a2, b0, b1, b2), dot3(b0, b1, b2, b0, b1, b2)
    su, sv = dot3(a0, a1, a2, w0, w1, w2), dot3(b0, b1, b2, w0, w1, w2)
    det = E * G - F * F
    return (G * su - F * sv) / det, (E * sv - F * su) / det


@njit(**JIT, aot=(f"void({F2}, {F2}, {F2}, {F1}, {F1})",))
def tangent_steps(Su, Sv, w, du, dv):
    """`tangent_step` per row into du, dv (`geometry.surfaces.parameter_steps`)."""
    for i in range(Su.shape[0]):
        du[i], dv[i] = tangent_step(Su[i, 0], Su[i, 1], Su[i, 2], Sv[i, 0], Sv[i, 1], Sv[i, 2], w[i, 0], w[i, 1], w[i, 2])


@njit(inline="always", **JIT)
def into_domain_at(domain, closed, k, u, v):
    """(u, v) moved into patch k's domain: wrapped one period round in a direction the patch is closed in
    (``closed[k]``: its two edges coincide, the surface goes on across the seam), clamped in an open one; a point
    inside keeps its bits, NaN stays NaN (`trace.tracing._into_domain` for arrays)."""
    u0, u1, v0, v1 = domain[k, 0], domain[k, 1], domain[k, 2], domain[k, 3]
    if closed[k, 0] and (u < u0 or u > u1):
        u = u0 + (u - u0) % (u1 - u0)
    if closed[k, 1] and (v < v0 or v > v1):
        v = v0 + (v - v0) % (v1 - v0)
    return clamp_to_domain(domain, k, u, v)


@njit(**JIT, aot=(f"void({F2}, b1[:, ::1], {I1}, {F1}, {F1}, {F1}, {F1})",))
def into_domains(domain, closed, patch, u, v, u_out, v_out):
    """`into_domain_at` per row into u_out, v_out (`trace.tracing._into_domain`)."""
    for i in range(patch.shape[0]):
        u_out[i], v_out[i] = into_domain_at(domain, closed, patch[i], u[i], v[i])


@njit(**JIT, aot=(f"void({TABLE}, {F2}, b1[:, ::1], {I1}, {I1}, {F2}, {F2}, {F1}, {F1}, i8, f8, f8, {B1}, {F1}, {F1}, "
                  f"{F1}, {F1}, {I1}, {F1}, {F1}, {F1}, {I1})",))
def walk_past_minimum(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, max_degree,
                      scale, closed, rows, patch, O, D, reach, step, foot_iterations, sine, vanishing, pending,
                      u, v, t, g, steps_left, u1, v1, g1, state):
    """The walk of `trace.tracing._past_minimum` past a positive minimum of the ray's distance to its face, per row
    i in ``rows``, in place.

    From the last point X(t) = O + tD, whose foot on the surface is (u, v) and height g = n·(X − S), the ray point
    moves on by step[i] (at most steps_left[i] times): its foot from the previous one by ``foot_iterations``
    Gauss–Newton steps (`tangent_step` towards X − S; a step undefined is not taken; `into_domain_at`), its height
    g₁ along the unit normal. Where g·g₁ <= 0 the ray crossed the surface between the two points: ``state``
    `WALK_CROSSED`, (u, v, t, g) the point before, (u1, v1, g1) the one after. Where |g₁| > reach[i] (or NaN) the ray
    left the band: `WALK_DROPPED`, as when its steps run out. Where the normal at a foot is degenerate (`normal_at`),
    `WALK_PAUSED` with that foot in (u1, v1): the caller takes the limit normal there, sets g1 and ``pending``, and
    calls again; the walk goes on from the verdict on that point.
    """
    scratch = new_scratch(max_degree)
    d = np.empty((6, 3))
    for i in rows:
        k = patch[i]
        ui, vi, ti, gi, left = u[i], v[i], t[i], g[i], steps_left[i]
        a, b, h = u1[i], v1[i], g1[i]
        have = pending[i]  # (a, b, h) already known: the caller's, at a paused foot
        fresh = True  # d not yet at (ui, vi)
        verdict = WALK_DROPPED
        while True:
            if not have:
                if left == 0:
                    break
                x0, x1, x2 = O[i, 0] + (ti + step[i]) * D[i, 0], O[i, 1] + (ti + step[i]) * D[i, 1], \
                    O[i, 2] + (ti + step[i]) * D[i, 2]
                a, b = ui, vi
                for e in range(foot_iterations + (1 if fresh else 0)):
                    if e > 0 or not fresh:  # a Gauss–Newton step from d, which holds S, S_u, S_v at (a, b)
                        du, dv = tangent_step(d[1, 0], d[1, 1], d[1, 2], d[2, 0], d[2, 1], d[2, 2], x0 - d[0, 0],
                                              x1 - d[0, 1], x2 - d[0, 2])
                        if not (math.isfinite(du) and math.isfinite(dv)):
                            du = dv = 0.0
                        a, b = into_domain_at(domain, closed, k, a + du, b + dv)
                    point_at(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, k, a, b, 1,
                             d, scratch)
                fresh = False
                n0, n1, n2, bad = normal_at(domain, scale, k, d[1:2], d[2:3], 0, sine, vanishing)
                if bad:
                    verdict = WALK_PAUSED
                    break
                h = dot3(n0, n1, n2, x0 - d[0, 0], x1 - d[0, 1], x2 - d[0, 2])
            if have:
                have, fresh = False, True  # d is not at the paused foot
            if gi * h <= 0.0:
                verdict = WALK_CROSSED
                break
            if not abs(h) <= reach[i]:
                break
            ui, vi, ti, gi, left = a, b, ti + step[i], h, left - 1
        u[i], v[i], t[i], g[i], steps_left[i] = ui, vi, ti, gi, left
        u1[i], v1[i], g1[i], state[i], pending[i] = a, b, h, verdict, False


@njit(**JIT, aot=(f"void({TABLE}, {I1}, {F1}, {F1}, {F2}, {F2}, {F1}, i8, f8, f8, i8, f8, {F2}, {F2}, {F2}, {B1}, {B1}, {B1})",))
def rescue(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, max_degree,
           patch, u, v, O, D, tol, steps, stationary_cosine, stalled_damping, crawl_steps, crawl_gain, S, Su, Sv,
           converged, stationary, edge):
    """Levenberg–Marquardt on the ray residual r = (e1·(S − O), e2·(S − O)) where Newton failed (`trace.tracing._rescue`).

    Per ray from (u, v), in place: damping λ = 1e-3; each step solves (JᵀJ + λ diag JᵀJ) δ = −Jᵀr
    (Marquardt's scaling: invariant under rescaling u or v), clamps to the domain and keeps the trial
    point where it lowers |r| (λ /= 3), else λ *= 4. Stops converged at |r| <= tol, stationary where
    r is normal to the tangent plane (cosine of Jᵀr against |J||r| not above stationary_cosine) or
    λ > stalled_damping; at most ``steps`` steps. Stops undecided (neither) where the search crawls:
    ``crawl_steps`` accepted steps in a row lowered |r| by less than the fraction ``crawl_gain`` (checked at
    every crawl_steps-th accepted point, after the two tests; crawl_steps = 0: never). S, S_u, S_v at the final
    (u, v); edge: not converged and on the domain's edge (then not stationary).
    """
    scratch = new_scratch(max_degree)
    d = np.empty((6, 3))
    trial = np.empty((6, 3))
    e = np.empty((2, 3))
    for i in range(patch.shape[0]):
        k = patch[i]
        across_at(D, i, e)
        u0, u1, v0, v1 = domain[k, 0], domain[k, 1], domain[k, 2], domain[k, 3]
        ui, vi = u[i], v[i]
        lam = 1e-3
        ok = flat = False
        tu, tv, rn = ui, vi, 0.0
        step, start = 0, True
        accepted, mark = 0, 0.0  # accepted points so far, |r| at the last crawl check
        while True:  # one evaluation site (the start, then each trial point): each copy of point_at costs seconds to compile
            point_at(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, k, tu, tv, 1, trial,
                     scratch)
            if start:
                better, start = True, False
            else:
                q0, q1, q2 = trial[0, 0] - O[i, 0], trial[0, 1] - O[i, 1], trial[0, 2] - O[i, 2]
                trial_r = math.hypot(dot3(e[0, 0], e[0, 1], e[0, 2], q0, q1, q2),
                                     dot3(e[1, 0], e[1, 1], e[1, 2], q0, q1, q2))
                better = trial_r < rn
                lam = lam / 3.0 if better else lam * 4.0
            if better:
                accepted += 1
                ui, vi = tu, tv
                for r in range(3):
                    for c in range(3):
                        d[r, c] = trial[r, c]
            evaluate = False
            while step < steps and not evaluate:  # steps from (ui, vi) until a trial point is to be evaluated
                step += 1
                r0, r1_, r2_ = d[0, 0] - O[i, 0], d[0, 1] - O[i, 1], d[0, 2] - O[i, 2]
                r1 = dot3(e[0, 0], e[0, 1], e[0, 2], r0, r1_, r2_)
                r2 = dot3(e[1, 0], e[1, 1], e[1, 2], r0, r1_, r2_)
                a = dot3(e[0, 0], e[0, 1], e[0, 2], d[1, 0], d[1, 1], d[1, 2])
                b = dot3(e[0, 0], e[0, 1], e[0, 2], d[2, 0], d[2, 1], d[2, 2])
                c = dot3(e[1, 0], e[1, 1], e[1, 2], d[1, 0], d[1, 1], d[1, 2])
                dd = dot3(e[1, 0], e[1, 1], e[1, 2], d[2, 0], d[2, 1], d[2, 2])
                rn = math.hypot(r1, r2)
                if rn <= tol[i]:
                    ok = True
                    break
                g1, g2 = a * r1 + c * r2, b * r1 + dd * r2  # Jᵀ r
                if stationary_at(g1, g2, a * a + b * b + c * c + dd * dd, rn, stationary_cosine) or lam > stalled_damping:
                    flat = True
                    break
                if crawl_steps > 0 and accepted % crawl_steps == 1 % crawl_steps and better:
                    if accepted > 1 and rn > (1.0 - crawl_gain) * mark:
                        break  # crawling: undecided, for `_passes_by`
                    mark = rn
                better = False  # checked once per accepted point
                A11, A12, A22 = a * a + c * c, a * b + c * dd, b * b + dd * dd
                M11, M22 = A11 * (1.0 + lam), A22 * (1.0 + lam)
                det = M11 * M22 - A12 * A12
                du = -(M22 * g1 - A12 * g2) / det
                dv = -(M11 * g2 - A12 * g1) / det
                if math.isfinite(du) and math.isfinite(dv):
                    tu, tv = min(max(ui + du, u0), u1), min(max(vi + dv, v0), v1)
                    evaluate = True
                else:  # no step: as one that does not lower |r|
                    lam = lam * 4.0
            if not evaluate:
                break
        u[i], v[i], converged[i] = ui, vi, ok
        on_edge = (not ok) and on_domain_edge(domain, k, ui, vi)
        edge[i], stationary[i] = on_edge, flat and not on_edge
        for c in range(3):
            S[i, c], Su[i, c], Sv[i, c] = d[0, c], d[1, c], d[2, c]


# -- Curvature from the fundamental forms (`geometry.curvature`) -----------------------------------
# In this file for the same reason as `newton`: the fused kernel inlines `point_at`.


@njit(inline="always", **JIT)
def fundamental_forms_at(Su, Sv, Suu, Suv, Svv, n):
    """I = (E, F, G) = (S_u·S_u, S_u·S_v, S_v·S_v) and II = (L, M, N) = (S_uu·n, S_uv·n, S_vv·n) (do Carmo 3-3)."""
    E = Su[0] * Su[0] + Su[1] * Su[1] + Su[2] * Su[2]
    F = Su[0] * Sv[0] + Su[1] * Sv[1] + Su[2] * Sv[2]
    G = Sv[0] * Sv[0] + Sv[1] * Sv[1] + Sv[2] * Sv[2]
    L = Suu[0] * n[0] + Suu[1] * n[1] + Suu[2] * n[2]
    M = Suv[0] * n[0] + Suv[1] * n[1] + Suv[2] * n[2]
    N = Svv[0] * n[0] + Svv[1] * n[1] + Svv[2] * n[2]
    return E, F, G, L, M, N


@njit(inline="always", **JIT)
def curvature_of(E, F, G, L, M, N):
    """(K, H, κ1, κ2) from the fundamental forms; NaN where EG − F² is not > 0 (`geometry.curvature`).

    K = (LN − M²)/(EG − F²), H = (EN − 2FM + GL)/(2(EG − F²)), κ1,2 = H ± √(H² − K), the root's
    argument clamped at 0 (rounding makes it slightly negative at umbilics).
    """
    det = E * G - F * F
    if not det > 0:
        return np.nan, np.nan, np.nan, np.nan
    K = (L * N - M * M) / det
    H = (E * N - 2.0 * F * M + G * L) / (2.0 * det)
    spread = H * H - K
    root = math.sqrt(spread) if spread > 0 else 0.0
    if spread != spread:  # NaN in, NaN out (as numpy's maximum)
        root = np.nan
    return K, H, H + root, H - root


@njit(**JIT, aot=(f"void({F2}, {F2}, {F2}, {F2}, {F2}, {F2}, {F2})",))
def curvatures(Su, Sv, Suu, Suv, Svv, n, out):
    """`curvature_of` at every row of the (N, 3) derivatives and unit normals n; out (4, N): K, H, κ1, κ2."""
    for i in range(n.shape[0]):
        E, F, G, L, M, N = fundamental_forms_at(Su[i], Sv[i], Suu[i], Suv[i], Svv[i], n[i])
        out[0, i], out[1, i], out[2, i], out[3, i] = curvature_of(E, F, G, L, M, N)


@njit(**JIT, aot=(f"void({F2}, {F2}, {F2}, {F2}, {F2}, {F2}, {F2}, {F1})",))
def normal_curvatures(Su, Sv, Suu, Suv, Svv, n, w, out):
    """κ(w) = II(w, w)/I(w, w) per row, w a tangent vector written as a S_u + b S_v (do Carmo 3-2): (a, b) from
    w·S_u = aE + bF, w·S_v = aF + bG by Cramer's rule."""
    for i in range(n.shape[0]):
        E, F, G, L, M, N = fundamental_forms_at(Su[i], Sv[i], Suu[i], Suv[i], Svv[i], n[i])
        wu = w[i, 0] * Su[i, 0] + w[i, 1] * Su[i, 1] + w[i, 2] * Su[i, 2]
        wv = w[i, 0] * Sv[i, 0] + w[i, 1] * Sv[i, 1] + w[i, 2] * Sv[i, 2]
        det = E * G - F * F
        a = (G * wu - F * wv) / det
        b = (E * wv - F * wu) / det
        first = E * a * a + 2.0 * F * a * b + G * b * b
        out[i] = (L * a * a + 2.0 * M * a * b + N * b * b) / first


@njit(inline="always", **JIT)
def curvature_lanes(buf, n, normal_field):
    """`fundamental_forms_at` and `curvature_of` at points 0..n−1 of a lane block (derivatives in `LANE_D`…, unit
    normal in the three fields from ``normal_field``) into `LANE_CURVATURE`…: the vector loop."""
    for j in range(n):
        E, F, G, L, M, N = fundamental_forms_at(_field3(buf, LANE_D + 3, j), _field3(buf, LANE_D + 6, j),
                                                _field3(buf, LANE_D + 9, j), _field3(buf, LANE_D + 12, j),
                                                _field3(buf, LANE_D + 15, j), _field3(buf, normal_field, j))
        K, H, k1, k2 = curvature_of(E, F, G, L, M, N)
        buf[LANE_CURVATURE * LANES + j], buf[(LANE_CURVATURE + 1) * LANES + j] = K, H
        buf[(LANE_CURVATURE + 2) * LANES + j], buf[(LANE_CURVATURE + 3) * LANES + j] = k1, k2


@njit(inline="always", **JIT)
def facing_normal_lanes(buf, n):
    """The unit normal (S_u × S_v)/|S_u × S_v| at points 0..n−1 of a lane block (`LANE_D`…), turned to face the ray
    (`LANE_DIR`; where n·D > 0, −n, as `trace.tracing.facing` turns it), into `LANE_N`…: `normal_at`'s formula
    (`unit_cross`), so its bits, as a vector loop."""
    for j in range(n):
        a0, a1, a2 = _field3(buf, LANE_D + 3, j)
        b0, b1, b2 = _field3(buf, LANE_D + 6, j)
        n0, n1, n2, _ = unit_cross(a0, a1, a2, b0, b1, b2)
        D0, D1, D2 = _field3(buf, LANE_DIR, j)
        sign = -1.0 if dot3(n0, n1, n2, D0, D1, D2) > 0 else 1.0
        buf[LANE_N * LANES + j], buf[(LANE_N + 1) * LANES + j] = sign * n0, sign * n1
        buf[(LANE_N + 2) * LANES + j] = sign * n2


@njit(**JIT, aot=(f"void({TABLE}, {I1}, {F1}, {F1}, {F2}, {F2})",))
def curvatures_at(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, max_degree,
                  patch, u, v, n, out):
    """K, H, κ1, κ2 of points (patch, u, v) with unit normals n into out (4, N), fused: `point_at` of order 2
    and `curvature_of` per point, LANES points at a time (`eval_lanes`, `curvature_lanes`), no (N, 3) derivative
    arrays. Rows with patch < 0: NaN."""
    scratch = new_scratch(max_degree)
    d = np.empty((6, 3))
    buf, row, lane_patch, base, span_u, span_v = new_lanes()
    for first in range(0, patch.shape[0], LANES):
        filled = 0
        for i in range(first, min(first + LANES, patch.shape[0])):
            k = patch[i]
            if k < 0:
                out[0, i] = out[1, i] = out[2, i] = out[3, i] = np.nan
                continue
            row[filled], lane_patch[filled] = i, k
            buf[LANE_U * LANES + filled], buf[LANE_V * LANES + filled] = u[i], v[i]
            for c in range(3):
                buf[(LANE_E + c) * LANES + filled] = n[i, c]
            filled += 1
        span_u[:filled] = -1
        span_v[:filled] = -1
        eval_lanes(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, lane_patch, base,
                   span_u, span_v, buf, filled, 2, d, scratch)
        curvature_lanes(buf, filled, LANE_E)
        for j in range(filled):
            for r in range(4):
                out[r, row[j]] = buf[(LANE_CURVATURE + r) * LANES + j]
