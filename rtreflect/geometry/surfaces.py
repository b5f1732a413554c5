"""NURBS surfaces: vectorised evaluation of points, derivatives and exact normals.

A NURBS surface (Ulmet, section 2.6; Piegl & Tiller, *The NURBS Book*, eq. 4.15)

    S(u, v) = Σ_i Σ_j N_i^p(u) N_j^q(v) w_ij D_ij / Σ_i Σ_j N_i^p(u) N_j^q(v) w_ij

is evaluated for whole arrays of (u, v) at once: the B-spline basis functions and
their derivatives come from a vectorised form of Piegl & Tiller's algorithm A2.3,
the rational derivatives from their eq. 4.20 (algorithm A4.4). Work is done in
chunks so memory stays bounded however many points are asked for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from .trims import Trim

#: Points evaluated per chunk: bounds the (chunk, p+1, q+1, 4) gather of control points and keeps it in cache.
CHUNK = 1 << 12

#: Power (Taylor) form per span is used up to this degree and table size; beyond, the B-spline recurrences.
#: Its rounding error grows with degree: ~1e-13 of the net's size at degree 5, 4e-12 at 7 (tests/test_surfaces.py).
POWER_FORM_MAX_DEGREE = 5
POWER_FORM_MAX_BYTES = 64 << 20

#: Most spans per direction of a patch evaluated with others of its degrees in one batch (`SurfaceSet`).
GROUP_MAX_SPANS = 64
#: A patch with at least this many points in one call is evaluated alone: per point, the batch's
#: padded span search and gathers cost ~0.37 µs against its own ~0.22 µs, while the per-call
#: overhead of ~0.1 ms a patch dominates below ~700 points (300 points on 206 faces: 0.3 vs 10.7 ms).
GROUP_MAX_POINTS = 768

#: A degenerate point (collapsed edge, pole, parallel partials), where the normal is taken as the limit
#: from the interior: the sine of the angle between S_u and S_v, |S_u × S_v| / (|S_u| |S_v|), below this.
#: A ratio of like quantities, so rescaling u or v (knots in mm or in m) cannot change the verdict.
DEGENERATE_SINE = 1e-10
#: ... or a partial that vanishes: |S_u| (u1 − u0) below this fraction of √(size · reach), the net's size and
#: its reach (size plus distance from the origin, which sets the rounding floor of S_u). At a pole rounding
#: leaves S_v a random vector of ε·reach (ε ~ 1e-15, up to 1e-12 at degree 7), whose angle with S_u means
#: nothing; with |S_v| (v1 − v0) = x·size that turns the normal by ε·reach/(x·size), while the limit normal
#: used instead is off by about x: the bound balances the two (√ε, times √(reach/size) far from the origin).
#: Also unchanged by rescaling u or v.
VANISHING_PARTIAL = 1e-8


class SurfaceDerivatives(NamedTuple):
    """S and its partial derivatives at N points; second derivatives when asked for."""

    S: np.ndarray
    Su: np.ndarray
    Sv: np.ndarray
    Suu: np.ndarray | None = None
    Suv: np.ndarray | None = None
    Svv: np.ndarray | None = None


def find_span(knots: np.ndarray, degree: int, n_ctrl: int, t: np.ndarray) -> np.ndarray:
    """Knot span index i with knots[i] <= t < knots[i+1] (Piegl & Tiller A2.1), vectorised.

    The upper end of the domain belongs to the last non-empty span.
    """
    span = np.searchsorted(knots, t, side="right") - 1
    return np.clip(span, degree, n_ctrl - 1)


def basis_derivatives(knots: np.ndarray, degree: int, span: np.ndarray, t: np.ndarray, order: int) -> np.ndarray:
    """Non-zero B-spline basis functions and their derivatives, vectorised over points and indices.

    Returns (N, order+1, degree+1): ``[:, k, r]`` is the k-th derivative of N_{span−degree+r}^degree at t.
    Values by the triangular Cox–de Boor scheme (Piegl & Tiller A2.2), one whole degree per step;
    derivatives by N'_{i,p} = p (N_{i,p−1}/(u_{i+p} − u_i) − N_{i+1,p−1}/(u_{i+p+1} − u_{i+1}))
    (Piegl & Tiller eq. 2.7), applied k times.
    """
    p = degree
    n = t.shape[0]
    offsets = np.arange(1, p + 1)
    left = t[:, None] - knots[span[:, None] + 1 - offsets]  # left[:, j-1] = t − u_{span+1−j}
    right = knots[span[:, None] + offsets] - t[:, None]  # right[:, j-1] = u_{span+j} − t
    levels = [np.ones((n, 1))]  # levels[j]: the j+1 non-zero basis functions of degree j
    for j in range(1, p + 1):
        lower = levels[-1]
        R = right[:, :j]  # u_{span+r+1} − t, r = 0..j−1
        L = left[:, j - 1::-1]  # t − u_{span+r+1−j}, r = 0..j−1
        temp = lower / (R + L)  # R + L is a knot difference spanning the non-empty span: never 0
        level = np.zeros((n, j + 1))
        level[:, :j] += R * temp
        level[:, 1:] += L * temp
        levels.append(level)

    def derivative(k: int, j: int) -> np.ndarray:
        if k == 0:
            return levels[j]
        if j == 0:
            return np.zeros((n, 1))
        lower = derivative(k - 1, j - 1)  # (n, j): functions i = span−j+1 .. span
        r = np.arange(1, j + 1)
        delta = knots[span[:, None] + r] - knots[span[:, None] - j + r]
        a = np.zeros((n, j + 2))
        np.divide(lower, delta, out=a[:, 1:j + 1], where=delta > 0)  # 0/0 := 0 at repeated knots
        return j * (a[:, :j + 1] - a[:, 1:])

    return np.stack([derivative(k, p) for k in range(order + 1)], axis=1)


def _power_rows(tau: np.ndarray, length: np.ndarray, degree: int, order: int) -> np.ndarray:
    """(order+1, degree+1, N): d^m/dt^m of τ^k for t = start + τ·length, m = 0..order.

    Points run along the last axis (structure of arrays), so every arithmetic step below and
    in `NurbsSurface._power_homogeneous` is one long contiguous vector operation.
    """
    n = tau.shape[0]
    powers = np.empty((degree + 1, n))
    powers[0] = 1.0
    for k in range(1, degree + 1):
        np.multiply(powers[k - 1], tau, out=powers[k])
    rows = np.zeros((order + 1, degree + 1, n))
    rows[0] = powers
    inv_len = 1.0 / length
    for m in range(1, order + 1):
        for k in range(m, degree + 1):
            falling = math.perm(k, m)  # k (k−1) … (k−m+1)
            rows[m, k] = falling * powers[k - m]
        rows[m, m:] *= inv_len**m
    return rows


def _power_combine(table: np.ndarray, column: np.ndarray, tau_u, len_u, tau_v, len_v, p: int, q: int,
                   order: int) -> list[list[np.ndarray]]:
    """H[k][l] (N, 4) from power-form coefficients: each point's span column of ``table`` and its local τ."""
    a = _power_rows(tau_u, len_u, p, order)  # (order+1, p+1, N)
    b = _power_rows(tau_v, len_v, q, order)
    C = np.take(table, column, axis=1).reshape(p + 1, q + 1, 4, -1)  # (k, l, c, N)
    T = [np.einsum("kn,klcn->lcn", a[i], C) for i in range(order + 1)]  # u-derivative i, contracted over k
    return [[np.einsum("ln,lcn->nc", b[j], T[i]) for j in range(order + 1 - i)] for i in range(order + 1)]


def _rational_derivatives(H: list[list[np.ndarray]], order: int) -> tuple[np.ndarray, ...]:
    """S and its derivatives from the homogeneous ones H[k][l] = (A, w) (Piegl & Tiller eq. 4.20, k + l <= 2)."""
    A = [[h[:, :3] for h in row] for row in H]
    w = [[h[:, 3:] for h in row] for row in H]
    w00 = w[0][0]
    S = A[0][0] / w00
    Su = (A[1][0] - w[1][0] * S) / w00
    Sv = (A[0][1] - w[0][1] * S) / w00
    if order == 1:
        return S, Su, Sv
    Suu = (A[2][0] - 2 * w[1][0] * Su - w[2][0] * S) / w00
    Suv = (A[1][1] - w[1][1] * S - w[1][0] * Sv - w[0][1] * Su) / w00
    Svv = (A[0][2] - 2 * w[0][1] * Sv - w[0][2] * S) / w00
    return S, Su, Sv, Suu, Suv, Svv


@dataclass(frozen=True, eq=False)
class NurbsSurface:
    """A tensor-product NURBS surface with full (clamped) knot vectors.

    ``points`` is (nu, nv, 3): row i is u index i. ``weights`` is (nu, nv), all > 0.
    A CAD face also carries its ``trim`` (the face is the part of the surface inside it) and may
    carry ``mesh_uv``, a triangulation of the trimmed face in (u, v) from its reader
    (nodes (m, 2), triangles (k, 3)); the tessellation then maps those nodes onto the surface.
    """

    degree_u: int
    degree_v: int
    knots_u: np.ndarray
    knots_v: np.ndarray
    points: np.ndarray
    weights: np.ndarray
    name: str = ""
    trim: "Trim | None" = None
    mesh_uv: tuple[np.ndarray, np.ndarray] | None = None
    _pw: np.ndarray = field(init=False, repr=False)
    size: float = field(init=False, repr=False)  # the control net's bounding-box diagonal
    reach: float = field(init=False, repr=False)  # size + the net's largest |coordinate|

    _power: tuple | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        pw = np.ascontiguousarray(
            np.concatenate([self.points * self.weights[..., None], self.weights[..., None]], axis=-1), dtype=np.float64)
        object.__setattr__(self, "_pw", pw)
        net = self.points.reshape(-1, 3)
        with np.errstate(over="ignore"):  # inf for coordinates beyond ~1e154, which the readers refuse anyway
            object.__setattr__(self, "size", float(np.linalg.norm(np.ptp(net, axis=0))))
        object.__setattr__(self, "reach", self.size + float(np.abs(net).max()))
        object.__setattr__(self, "_power", self._power_form(pw))

    def _power_form(self, pw: np.ndarray) -> tuple | None:
        """Each span's homogeneous polynomial in local τ ∈ [0, 1], from its Taylor expansion at the span start.

        S_w(u, v) = Σ_kl coef[k, l] τ_u^k τ_v^l on span (span_u, span_v). With the coefficients
        precomputed, a point needs powers of τ instead of the Cox–de Boor recurrences, and one
        contiguous gather: about 3× faster. Kept for moderate degrees (the power basis loses
        accuracy as degree grows) and moderate nets (the table grows with the span count).
        """
        p, q = self.degree_u, self.degree_v
        nu, nv = self.weights.shape
        table_bytes = (nu - p) * (nv - q) * (p + 1) * (q + 1) * 4 * 8
        if max(p, q) > POWER_FORM_MAX_DEGREE or table_bytes > POWER_FORM_MAX_BYTES:
            return None

        def taylor(knots: np.ndarray, degree: int, n_ctrl: int):
            spans = np.arange(degree, n_ctrl)
            start = knots[spans]
            length = knots[spans + 1] - start
            with np.errstate(divide="ignore", invalid="ignore"):  # empty spans (repeated knots) are never used
                ders = np.nan_to_num(basis_derivatives(knots, degree, spans, start, degree))  # (S, k, r)
            k = np.arange(degree + 1)
            scale = np.where(length > 0, length, 1.0)[:, None] ** k / np.cumprod(np.r_[1, k[1:]])
            return start, np.where(length > 0, length, 1.0), ders * scale[:, :, None]  # M[s, k, r]

        start_u, len_u, Mu = taylor(self.knots_u, p, nu)
        start_v, len_v, Mv = taylor(self.knots_v, q, nv)
        windows = np.lib.stride_tricks.sliding_window_view(pw, (p + 1, q + 1), axis=(0, 1))  # (Su, Sv, 4, p+1, q+1)
        coef = np.einsum("aki,blj,abcij->abklc", Mu, Mv, windows, optimize=True)
        # One column per span (span_u · n_spans_v + span_v), rows (k, l, c): a gather of columns
        # gives the structure-of-arrays layout `_power_homogeneous` computes in.
        table = coef.reshape(coef.shape[0] * coef.shape[1], -1).T
        return start_u, len_u, start_v, len_v, np.ascontiguousarray(table)

    @classmethod
    def bezier(cls, points: np.ndarray, weights: np.ndarray | None = None, name: str = "") -> "NurbsSurface":
        """A single (rational) Bézier patch on [0, 1]²."""
        points = np.asarray(points, dtype=np.float64)
        nu, nv = points.shape[:2]
        return cls(
            nu - 1,
            nv - 1,
            np.r_[np.zeros(nu), np.ones(nu)],
            np.r_[np.zeros(nv), np.ones(nv)],
            points,
            np.ones((nu, nv)) if weights is None else np.asarray(weights, dtype=np.float64),
            name,
        )

    @property
    def rational(self) -> bool:
        return bool(np.any(self.weights != self.weights.flat[0]))

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        nu, nv = self.weights.shape
        return (
            (float(self.knots_u[self.degree_u]), float(self.knots_u[nu])),
            (float(self.knots_v[self.degree_v]), float(self.knots_v[nv])),
        )

    def span_breaks(self) -> tuple[np.ndarray, np.ndarray]:
        """Distinct knot values inside the domain, ends included (the Bézier span limits)."""
        (u0, u1), (v0, v1) = self.domain
        ku, kv = self.knots_u, self.knots_v
        return np.unique(ku[(ku >= u0) & (ku <= u1)]), np.unique(kv[(kv >= v0) & (kv <= v1)])

    def evaluate(self, u: np.ndarray, v: np.ndarray, order: int = 1) -> SurfaceDerivatives:
        """S and its partial derivatives up to ``order`` (1 or 2) at arrays u, v."""
        u = np.asarray(u, dtype=np.float64).ravel()
        v = np.asarray(v, dtype=np.float64).ravel()
        n = u.shape[0]
        outs = [np.empty((n, 3)) for _ in range(3 if order == 1 else 6)]
        for lo in range(0, n, CHUNK):
            hi = min(lo + CHUNK, n)
            for out, part in zip(outs, self._evaluate_chunk(u[lo:hi], v[lo:hi], order)):
                out[lo:hi] = part
        return SurfaceDerivatives(*outs)

    def _evaluate_chunk(self, u: np.ndarray, v: np.ndarray, order: int) -> tuple[np.ndarray, ...]:
        (u0, u1), (v0, v1) = self.domain
        u = np.clip(u, u0, u1)
        v = np.clip(v, v0, v1)
        homogeneous = self._power_homogeneous if self._power is not None else self._basis_homogeneous
        return _rational_derivatives(homogeneous(u, v, order), order)

    def _power_homogeneous(self, u: np.ndarray, v: np.ndarray, order: int) -> list[list[np.ndarray]]:
        """H[k][l] (N, 4) = ∂^(k+l) S_w / ∂u^k ∂v^l, for k + l <= order, from the per-span power form."""
        column, tau_u, len_u, tau_v, len_v = self._power_locate(u, v)
        return _power_combine(self._power[4], column, tau_u, len_u, tau_v, len_v, self.degree_u, self.degree_v, order)

    def _power_locate(self, u: np.ndarray, v: np.ndarray):
        """Per point (already clipped to the domain): its span's column in the power table, local τ and span lengths."""
        p, q = self.degree_u, self.degree_v
        start_u, len_u, start_v, len_v, _ = self._power
        su = find_span(self.knots_u, p, self.weights.shape[0], u) - p
        sv = find_span(self.knots_v, q, self.weights.shape[1], v) - q
        return (su * len(start_v) + sv, (u - start_u[su]) / len_u[su], len_u[su], (v - start_v[sv]) / len_v[sv],
                len_v[sv])

    def _basis_homogeneous(self, u: np.ndarray, v: np.ndarray, order: int) -> list[list[np.ndarray]]:
        """H[k][l] as `_power_homogeneous`, from the B-spline basis functions (any degree)."""
        p, q = self.degree_u, self.degree_v
        nu, nv = self.weights.shape
        span_u = find_span(self.knots_u, p, nu, u)
        span_v = find_span(self.knots_v, q, nv, v)
        Nu = basis_derivatives(self.knots_u, p, span_u, u, order)  # (n, order+1, p+1)
        Nv = basis_derivatives(self.knots_v, q, span_v, v, order)  # (n, order+1, q+1)
        iu = span_u[:, None] - p + np.arange(p + 1)
        iv = span_v[:, None] - q + np.arange(q + 1)
        flat = (iu[:, :, None] * nv + iv[:, None, :]).reshape(len(u), -1)
        C = np.take(self._pw.reshape(-1, 4), flat, axis=0).reshape(len(u), p + 1, q + 1, 4)
        n = u.shape[0]
        # Aw[n, k, l, c] = Σ_ij Nu[n,k,i] Nv[n,l,j] C[n,i,j,c]: two batched matrix products.
        tmp = np.matmul(Nu, C.reshape(n, p + 1, (q + 1) * 4)).reshape(n, order + 1, q + 1, 4)
        Aw = np.matmul(tmp.transpose(0, 1, 3, 2), Nv.transpose(0, 2, 1)[:, None]).transpose(0, 1, 3, 2)
        return [[Aw[:, k, l] for l in range(order + 1 - k)] for k in range(order + 1)]

    def normals(self, u: np.ndarray, v: np.ndarray, derivs: SurfaceDerivatives | None = None) -> np.ndarray:
        """Unit normals n = (S_u × S_v)/|S_u × S_v| at arrays u, v.

        Where S_u × S_v vanishes (a collapsed edge, a pole) the normal is the limit
        from the interior along the line towards the domain centre: the first
        non-vanishing term of the Taylor expansion of S_u × S_v. Never NaN.
        Whether it vanishes is decided by scale-free ratios (`DEGENERATE_SINE`,
        `VANISHING_PARTIAL`), so the normals do not depend on how u and v are scaled.
        """
        u = np.asarray(u, dtype=np.float64).ravel()
        v = np.asarray(v, dtype=np.float64).ravel()
        d = derivs if derivs is not None else self.evaluate(u, v, order=1)
        cross = np.cross(d.Su, d.Sv)
        norm = np.linalg.norm(cross, axis=1)
        degenerate = self.degenerate(d, norm)
        if np.any(degenerate):
            cross[degenerate] = self._limit_cross(u[degenerate], v[degenerate])
            norm[degenerate] = np.linalg.norm(cross[degenerate], axis=1)
        still = ~(norm > 0)
        if np.any(still):  # a fully flat point in every direction: fall back to the patch's mean normal
            cross[still] = self._mean_normal()
            norm[still] = np.linalg.norm(cross[still], axis=1)
        return cross / norm[:, None]

    def degenerate(self, d: SurfaceDerivatives, cross_norm: np.ndarray | None = None) -> np.ndarray:
        """True where S_u × S_v is too small to define the normal: `DEGENERATE_SINE`, `VANISHING_PARTIAL`."""
        norm = np.linalg.norm(np.cross(d.Su, d.Sv), axis=1) if cross_norm is None else cross_norm
        len_u, len_v = np.linalg.norm(d.Su, axis=1), np.linalg.norm(d.Sv, axis=1)
        (u0, u1), (v0, v1) = self.domain
        floor = VANISHING_PARTIAL * math.sqrt(self.size * self.reach)
        return ~((norm > DEGENERATE_SINE * len_u * len_v)
                 & (len_u * (u1 - u0) > floor) & (len_v * (v1 - v0) > floor))

    def _limit_cross(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Leading Taylor term of S_u × S_v at (u + h δu, v + h δv) as h → 0+.

        (δu, δv) points to the domain centre in the parameters' own units (not normalised
        across u and v, which would mix their scales): the same path on the surface however
        u and v are scaled. Then ∂_h S_u scales like S_u and ∂_h S_v like S_v, so the test
        whether the first-order term vanishes is a scale-free ratio, as in `normals`.
        """
        (u0, u1), (v0, v1) = self.domain
        du = 0.5 * (u0 + u1) - u
        dv = 0.5 * (v0 + v1) - v
        d = self.evaluate(u, v, order=2)
        Su_h = d.Suu * du[:, None] + d.Suv * dv[:, None]  # d/dh of S_u along (δu, δv)
        Sv_h = d.Suv * du[:, None] + d.Svv * dv[:, None]
        first = np.cross(Su_h, d.Sv) + np.cross(d.Su, Sv_h)
        second = np.cross(Su_h, Sv_h)
        ref = ((np.linalg.norm(d.Su, axis=1) + np.linalg.norm(Su_h, axis=1))
               * (np.linalg.norm(d.Sv, axis=1) + np.linalg.norm(Sv_h, axis=1)))
        use_first = np.linalg.norm(first, axis=1) > DEGENERATE_SINE * ref
        return np.where(use_first[:, None], first, second)

    def _mean_normal(self) -> np.ndarray:
        P = self.points
        n = np.cross(P[-1, -1] - P[0, 0], P[0, -1] - P[-1, 0])
        return n if np.linalg.norm(n) > 0 else np.array([0.0, 0.0, 1.0])


class SurfaceSet:
    """All patches of a scene, numbered from 0; evaluation by (patch, u, v) arrays."""

    def __init__(self, patches: list[NurbsSurface]):
        self.patches = list(patches)

    def __len__(self) -> int:
        return len(self.patches)

    def _by_patch(self, patch: np.ndarray):
        """(k, rows of patch k) for every patch index ≥ 0 present: one stable sort, not a scan per patch."""
        patch = np.asarray(patch).ravel()
        order = np.argsort(patch, kind="stable")
        keys, starts = np.unique(patch[order], return_index=True)
        for k, rows in zip(keys, np.split(order, starts[1:])):
            if k >= 0:
                yield int(k), rows

    def evaluate(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray, order: int = 1) -> SurfaceDerivatives:
        """S and derivatives for points given by patch index and (u, v); rows with patch < 0 stay NaN.

        Patches in power form with few points each are evaluated together, one group per degree
        pair (`_evaluate_group`): a part of hundreds of faces then costs about what one patch does,
        not hundreds of small calls. Values are bit-identical to each patch's own `evaluate`.
        """
        patch = np.asarray(patch).ravel()
        u, v = np.asarray(u, dtype=np.float64).ravel(), np.asarray(v, dtype=np.float64).ravel()
        n = patch.size
        outs = [np.full((n, 3), np.nan) for _ in range(3 if order == 1 else 6)]
        if len(self.patches) == 1 and n and patch.min() >= 0:  # one patch: no grouping to do
            return self.patches[0].evaluate(u, v, order)
        groups = self._power_groups
        batched: dict[int, list[np.ndarray]] = {}
        for k, rows in self._by_patch(patch):
            g = int(groups.of[k])
            if g and len(rows) < GROUP_MAX_POINTS:  # few points: with the group (a patch with many is faster alone)
                batched.setdefault(g, []).append(rows)
                continue
            for out, part in zip(outs, self.patches[k].evaluate(u[rows], v[rows], order)):
                out[rows] = part
        for g, parts in batched.items():
            idx = np.concatenate(parts)
            for out, part in zip(outs, self._evaluate_group(groups.members[g - 1], groups.offset, patch[idx], u[idx],
                                                            v[idx], order)):
                out[idx] = part
        return SurfaceDerivatives(*outs)

    @cached_property
    def _domain_table(self) -> np.ndarray:
        return np.array([[*p.domain[0], *p.domain[1]] for p in self.patches])

    @cached_property
    def _power_groups(self) -> "_PowerGroups":
        return _PowerGroups.of_patches(self.patches)

    def _evaluate_group(self, members: np.ndarray, offset: np.ndarray, patch, u, v, order: int):
        """`evaluate` for points on patches of one power-form group (same degrees, one concatenated table).

        The span lookup too is vectorised over the group's patches, with their span starts side by
        side in a padded table: span = the number of span starts after the first that are ≤ t,
        which is `find_span`'s answer (the last non-empty span holding t, the upper end included).
        """
        first = self.patches[int(members[0])]
        p, q = first.degree_u, first.degree_v
        g = self._power_groups
        table, lookup = g.tables[(p, q)], g.lookups[(p, q)]
        outs = [np.empty((len(u), 3)) for _ in range(3 if order == 1 else 6)]
        for lo in range(0, len(u), CHUNK):
            part = slice(lo, lo + CHUNK)
            local = g.local[patch[part]]
            su, tau_u, len_u = lookup.u.locate(local, u[part])
            sv, tau_v, len_v = lookup.v.locate(local, v[part])
            column = offset[patch[part]] + su * lookup.v.count[local] + sv
            H = _power_combine(table, column, tau_u, len_u, tau_v, len_v, p, q, order)
            for out, value in zip(outs, _rational_derivatives(H, order)):
                out[part] = value
        return outs

    def normals(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray, derivs: SurfaceDerivatives | None = None) -> np.ndarray:
        n = np.asarray(patch).size
        out = np.full((n, 3), np.nan)
        for k, idx in self._by_patch(patch):
            sub = None if derivs is None else SurfaceDerivatives(derivs.S[idx], derivs.Su[idx], derivs.Sv[idx])
            out[idx] = self.patches[k].normals(u[idx], v[idx], sub)
        return out

    @property
    def trimmed(self) -> bool:
        """Whether any patch is a trimmed face (then hits, occlusions and contours are tested against trims)."""
        return any(p.trim is not None for p in self.patches)

    def on_face(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """True where (u, v) lies on the face of ``patch``: inside its trim, anywhere on an untrimmed patch."""
        patch = np.asarray(patch).ravel()
        inside = np.ones(len(patch), dtype=bool)
        for k, idx in self._by_patch(patch):
            trim = self.patches[k].trim
            if trim is not None:
                inside[idx] = trim.contains(np.asarray(u)[idx], np.asarray(v)[idx])
        return inside

    def domains(self, patch: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-point parameter domain bounds (u0, u1, v0, v1)."""
        rows = self._domain_table[np.asarray(patch)]
        return rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]


@dataclass(frozen=True)
class _SpanTable:
    """One direction's spans of a group's patches, padded side by side: starts, lengths, domain ends."""

    starts: np.ndarray  # (members, most spans): span starts, +inf beyond a patch's own spans
    lengths: np.ndarray  # (members, most spans)
    count: np.ndarray  # (members,) spans per patch
    lo: np.ndarray  # (members,) domain ends
    hi: np.ndarray

    @classmethod
    def of(cls, columns: list[tuple[np.ndarray, np.ndarray]], ends: list[tuple[float, float]]) -> "_SpanTable":
        width = max(len(start) for start, _ in columns)
        starts, lengths = np.full((len(columns), width), np.inf), np.ones((len(columns), width))
        for j, (start, length) in enumerate(columns):
            starts[j, :len(start)], lengths[j, :len(start)] = start, length
        lo, hi = np.array(ends).T
        return cls(starts, lengths, np.array([len(start) for start, _ in columns]), lo, hi)

    def locate(self, local: np.ndarray, t: np.ndarray):
        """Span index, local τ ∈ [0, 1] and span length of each parameter (clipped to its patch's domain)."""
        t = np.clip(t, self.lo[local], self.hi[local])
        span = np.count_nonzero(t[:, None] >= self.starts[local, 1:], axis=1)
        start, length = self.starts[local, span], self.lengths[local, span]
        return span, (t - start) / length, length


@dataclass(frozen=True)
class _SpanLookup:
    u: _SpanTable
    v: _SpanTable


@dataclass(frozen=True)
class _PowerGroups:
    """Patches in power form grouped by degree pair, each group's span tables side by side.

    ``of[k]`` is patch k's group number from 1 (0: not grouped); ``members[g − 1]`` the group's patches;
    ``local[k]`` patch k's row in its group's span tables; ``offset[k]`` where its columns start in
    its group's coefficient table. Patches with more than `GROUP_MAX_SPANS` spans in a direction
    stay alone (the padded span search compares each point with every span start).
    """

    of: np.ndarray
    members: list
    local: np.ndarray
    offset: np.ndarray
    tables: dict
    lookups: dict

    @classmethod
    def of_patches(cls, patches) -> "_PowerGroups":
        n = len(patches)
        of, local, offset = (np.zeros(n, dtype=np.int64) for _ in range(3))
        by_degree: dict[tuple[int, int], list[int]] = {}
        for k, surface in enumerate(patches):
            power = surface._power
            if power is not None and max(len(power[0]), len(power[2])) <= GROUP_MAX_SPANS:
                by_degree.setdefault((surface.degree_u, surface.degree_v), []).append(k)
        members, tables, lookups = [], {}, {}
        for g, (degrees, ks) in enumerate(by_degree.items(), start=1):
            of[ks], local[ks] = g, np.arange(len(ks))
            widths = [patches[k]._power[4].shape[1] for k in ks]
            offset[ks] = np.cumsum([0] + widths[:-1])
            tables[degrees] = np.ascontiguousarray(np.concatenate([patches[k]._power[4] for k in ks], axis=1))
            lookups[degrees] = _SpanLookup(
                _SpanTable.of([patches[k]._power[0:2] for k in ks], [patches[k].domain[0] for k in ks]),
                _SpanTable.of([patches[k]._power[2:4] for k in ks], [patches[k].domain[1] for k in ks]))
            members.append(np.asarray(ks))
        return cls(of, members, local, offset, tables, lookups)
