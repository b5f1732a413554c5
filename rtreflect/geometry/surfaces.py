"""NURBS surfaces: points, derivatives and exact normals for arrays of (u, v).

A NURBS surface (Ulmet, section 2.6; Piegl & Tiller, *The NURBS Book*, eq. 4.15)

    S(u, v) = Σ_i Σ_j N_i^p(u) N_j^q(v) w_ij D_ij / Σ_i Σ_j N_i^p(u) N_j^q(v) w_ij

is evaluated point by point by the compiled kernel `rtreflect.kernels.nurbs` (the basis and its
derivatives by Piegl & Tiller's algorithm A2.3, the rational derivatives by their eq. 4.20,
algorithm A4.4); this module marshals the arrays and holds the normals' degenerate cases.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..kernels import nurbs as kernel

if TYPE_CHECKING:
    from .trims import Trim

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
#: A knot line is a crease (`NurbsSurface.creases`) where the normals either side of it differ by more than this angle
#: (radians) at one of `CREASE_SAMPLES` points along it, each `CREASE_STEP` of the domain off the knot: far above the
#: rounding of a G1 join (a rational circle's arcs, ~1e-9), far below a modelled crease.
CREASE_ANGLE = 1e-6
CREASE_SAMPLES = 9
CREASE_STEP = 1e-9
#: A patch is closed in u (v) where its edges u = u₀ and u = u₁ (v₀, v₁) coincide to this fraction of its reach: a
#: periodic face's seam, whose two sides' control rows agree to float64 rounding (~1e-15 of the reach) when Open
#: CASCADE made it, but only to the exporter's tolerance from other CAD systems (pythonocc-demos' surf114.igs, an
#: apple: 2.4e-5 over a reach of 251, 1e-7). At 1e-12 that seam counted as an edge: Newton from a mesh hit on one
#: side stopped at the domain's edge and the ray kept the far side (the apple showed its inside near the seam). A
#: gap of 1e-6 of the reach is ~1/500 of a pixel with the part filling 1920 pixels.
CLOSED_FRACTION = 1e-6
#: A side of a patch's domain is collapsed (a pole: a sphere's, a cone's apex, a revolved profile ending on or next
#: to its axis) where its control row spans at most this fraction of the net's size: the side's image lies in the
#: row's convex hull (clamped knots, weights > 0), so within that of one point. Exact poles span ~1e-16 of the size
#: (float rounding), the sides of the shipped and sweep parts' faces at least 0.04; revolved_seam.step's profile
#: ends 0.001 off the axis, 1.7e-6 of its net. The tracer re-decides Newton's stops on such a side by the
#: Levenberg–Marquardt search (`trace.tracing._candidates`), never worse than the stop itself: the fraction only
#: bounds how often the search runs.
COLLAPSED_FRACTION = 1e-4
#: Meridians `SurfaceSet.apexes` takes the directions of, along a collapsed side.
APEX_MERIDIANS = 17
#: A pole is an apex where those directions stray from a plane by more than this (rms sine): a smooth pole's lie in its
#: tangent plane to rounding, a cone of half-angle α's at cos α.
APEX_SINE = 1e-6
#: (u, v) closer than this fraction of the domain to one of its sides lies on that side: a CAD reader's pcurves and
#: mesh nodes meet the domain's sides only to Open CASCADE's tolerances (1e-16 on seams, 1e-9 at cut corners). The
#: CAD reader snaps trim loops so (`exchange.occt`), the tracer reads a mesh node so near a collapsed side as on the
#: pole (`trace.tracing._meridian_towards`): one figure for both, here upstream of both.
SIDE_SNAP = 1e-9


class SurfaceDerivatives(NamedTuple):
    """S and its partial derivatives at N points; second derivatives when asked for."""

    S: np.ndarray
    Su: np.ndarray
    Sv: np.ndarray
    Suu: np.ndarray | None = None
    Suv: np.ndarray | None = None
    Svv: np.ndarray | None = None


def parameter_steps(Su: np.ndarray, Sv: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(du, dv) per point whose tangent step du S_u + dv S_v is nearest the vector w (N, 3), in least squares.

    The normal equations are those of the first fundamental form, [[E, F], [F, G]] (du, dv) = (S_u·w, S_v·w)
    with E = S_u·S_u, F = S_u·S_v, G = S_v·S_v, solved by Cramer's rule: inf or NaN where EG − F² = 0
    (`kernels.nurbs.tangent_step`).
    """
    Su, Sv, w = (np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3) for x in (Su, Sv, w))
    du, dv = np.empty(len(Su)), np.empty(len(Su))
    kernel.tangent_steps(Su, Sv, w, du, dv)
    return du, dv


def find_span(knots: np.ndarray, degree: int, n_ctrl: int, t: np.ndarray) -> np.ndarray:
    """Knot span index i with knots[i] <= t < knots[i+1] (Piegl & Tiller A2.1), for an array t.

    The upper end of the domain belongs to the last non-empty span (`kernels.nurbs.find_span_at`).
    """
    t = np.ascontiguousarray(t, dtype=np.float64)
    out = np.empty(t.shape[0], dtype=np.int64)
    kernel.find_span_many(np.ascontiguousarray(knots, dtype=np.float64), int(degree), int(n_ctrl), t, out)
    return out


def basis_derivatives(knots: np.ndarray, degree: int, span: np.ndarray, t: np.ndarray, order: int) -> np.ndarray:
    """Non-zero B-spline basis functions and their derivatives (Piegl & Tiller A2.3), for arrays span, t.

    Returns (N, order+1, degree+1): ``[:, k, r]`` is the k-th derivative of N_{span−degree+r}^degree at t
    (0 for k > degree). The kernel `kernels.nurbs.basis_ders_at` does the work.
    """
    t = np.ascontiguousarray(t, dtype=np.float64)
    out = np.empty((t.shape[0], order + 1, degree + 1))
    kernel.basis_ders_many(np.ascontiguousarray(knots, dtype=np.float64), int(degree),
                           np.ascontiguousarray(span, dtype=np.int64), t, int(order), out)
    return out


def _evaluate(table: "kernel.PatchTable", patch: np.ndarray, u: np.ndarray, v: np.ndarray,
              order: int) -> SurfaceDerivatives:
    """S and derivatives up to ``order`` (1 or 2) by the kernel; rows with patch < 0 stay NaN."""
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, not {order}")
    n = patch.shape[0]
    outs = np.full((3 if order == 1 else 6, n, 3), np.nan)
    kernel.evaluate(*table.args, np.ascontiguousarray(patch, dtype=np.int64),
                    np.ascontiguousarray(u, dtype=np.float64), np.ascontiguousarray(v, dtype=np.float64), order, outs)
    return SurfaceDerivatives(*outs)


def _unit_normals(table: "kernel.PatchTable", patch: np.ndarray, d: SurfaceDerivatives):
    """(S_u × S_v)/|S_u × S_v| by the kernel and where that is degenerate (those rows not yet filled)."""
    n = patch.shape[0]
    out, degenerate = np.empty((n, 3)), np.empty(n, dtype=bool)
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    kernel.unit_normals(table.domain, table.scale, np.ascontiguousarray(patch, dtype=np.int64), f64(d.Su), f64(d.Sv),
                        DEGENERATE_SINE, VANISHING_PARTIAL, out, degenerate)
    return out, degenerate


def _normals(patches: list, table: "kernel.PatchTable", patch: np.ndarray, u: np.ndarray, v: np.ndarray,
             derivs: SurfaceDerivatives | None) -> np.ndarray:
    """Unit normals of points on ``patches`` (numbered as in ``table``); degenerate points by their patch's limit."""
    d = derivs if derivs is not None else _evaluate(table, patch, u, v, 1)
    out, degenerate = _unit_normals(table, patch, d)
    bad = np.flatnonzero(degenerate)
    if len(bad) == 0:
        return out
    for k in np.unique(patch[bad]):
        rows = bad[patch[bad] == k]
        out[rows] = patches[k]._limit_normal(u[rows], v[rows])
    return out


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

    def __post_init__(self) -> None:
        pw = np.ascontiguousarray(
            np.concatenate([self.points * self.weights[..., None], self.weights[..., None]], axis=-1), dtype=np.float64)
        object.__setattr__(self, "_pw", pw)
        net = self.points.reshape(-1, 3)
        with np.errstate(over="ignore"):  # inf for coordinates beyond ~1e154, which the readers refuse anyway
            object.__setattr__(self, "size", float(np.linalg.norm(np.ptp(net, axis=0))))
        object.__setattr__(self, "reach", self.size + float(np.abs(net).max()))

    @cached_property
    def table(self) -> "kernel.PatchTable":
        """This patch alone as the kernels' flat table (patch index 0)."""
        return kernel.PatchTable.of([self])

    @cached_property
    def collapsed(self) -> np.ndarray:
        """(4,): whether the sides u = u₀, u = u₁, v = v₀, v = v₁ are collapsed to a point (a pole), to
        `COLLAPSED_FRACTION` of the net's size (the bounding-box diagonal of the side's control row: the side's image
        lies in the row's convex hull); `SurfaceSet.collapsed` of every patch."""
        P = self.points
        return np.array([np.linalg.norm(np.ptp(row, axis=0)) <= COLLAPSED_FRACTION * self.size
                         for row in (P[0], P[-1], P[:, 0], P[:, -1])])

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

    @cached_property
    def creases(self) -> tuple[np.ndarray, np.ndarray]:
        """The knot lines inside the domain where the normal jumps, in u and in v: knots repeated at least the degree's
        times (the surface is only C⁰ there, P&T section 2.5) whose normals either side differ by more than
        `CREASE_ANGLE` at one of `CREASE_SAMPLES` points along the line (a rational circle's arcs meet at double knots
        with one normal: no crease)."""
        (u0, u1), (v0, v1) = self.domain
        out = []
        for knots, degree, lo, hi, other, along in ((self.knots_u, self.degree_u, u0, u1, (v0, v1), 0),
                                                    (self.knots_v, self.degree_v, v0, v1, (u0, u1), 1)):
            values, counts = np.unique(knots[(knots > lo) & (knots < hi)], return_counts=True)
            across = np.linspace(*other, CREASE_SAMPLES + 2)[1:-1]
            creases = []
            for knot in values[counts >= degree]:
                sides = []
                for at in (knot - CREASE_STEP * (hi - lo), knot + CREASE_STEP * (hi - lo)):
                    at = np.full(CREASE_SAMPLES, at)
                    sides.append(self.normals(at, across) if along == 0 else self.normals(across, at))
                if np.any(np.arccos(np.clip(np.einsum("ij,ij->i", *sides), -1.0, 1.0)) > CREASE_ANGLE):
                    creases.append(knot)
            out.append(np.array(creases, dtype=np.float64))
        return out[0], out[1]

    def loop_uv(self) -> np.ndarray:
        """(n, 2) the points of every trim loop (outer, then holes) in the surface's own parameters: a periodic trim's
        moved from the period its loops were sampled in into the domain (`Trim.wrap`); none when untrimmed. With the
        mesh vertices on the face, what bounds the face (`exchange.occt.faces_bounds`, `integrator.autorig.part_points`)."""
        if self.trim is None:
            return np.zeros((0, 2))
        uv = np.concatenate([np.asarray(loop, dtype=np.float64).reshape(-1, 2)
                             for loop in (self.trim.outer, *self.trim.holes)])
        (u0, _), (v0, _) = self.domain
        return np.column_stack(self.trim.wrap(uv[:, 0], uv[:, 1], start=(u0, v0)))

    def evaluate(self, u: np.ndarray, v: np.ndarray, order: int = 1) -> SurfaceDerivatives:
        """S and its partial derivatives up to ``order`` (1 or 2) at arrays u, v (clamped to the domain)."""
        u = np.asarray(u, dtype=np.float64).ravel()
        v = np.asarray(v, dtype=np.float64).ravel()
        return _evaluate(self.table, np.zeros(u.shape[0], dtype=np.int64), u, v, order)

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
        return _normals([self], self.table, np.zeros(u.shape[0], dtype=np.int64), u, v, derivs)

    def degenerate(self, d: SurfaceDerivatives) -> np.ndarray:
        """True where S_u × S_v is too small to define the normal: `DEGENERATE_SINE`, `VANISHING_PARTIAL`."""
        return _unit_normals(self.table, np.zeros(len(d.Su), dtype=np.int64), d)[1]

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

    def _limit_normal(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The unit normal at degenerate points: `_limit_cross` normalised, the mean normal where even that is 0."""
        cross = self._limit_cross(u, v)
        norm = np.linalg.norm(cross, axis=1)
        still = ~(norm > 0)
        if np.any(still):  # a fully flat point in every direction: fall back to the patch's mean normal
            cross[still] = self._mean_normal()
            norm[still] = np.linalg.norm(cross[still], axis=1)
        return cross / norm[:, None]

    def _mean_normal(self) -> np.ndarray:
        P = self.points
        n = np.cross(P[-1, -1] - P[0, 0], P[0, -1] - P[-1, 0])
        return n if np.linalg.norm(n) > 0 else np.array([0.0, 0.0, 1.0])


def net_plane(surface: NurbsSurface) -> tuple[np.ndarray, np.ndarray, float]:
    """The plane best fitting a patch's control net (least squares: the SVD's last right singular vector): a point on
    it (the net's centroid), its unit normal, and the net's largest distance from it. With weights > 0 the surface lies
    in the net's convex hull, so within that distance of the plane."""
    net = surface.points.reshape(-1, 3)
    centre = net.mean(axis=0)
    normal = np.linalg.svd(net - centre, full_matrices=False)[2][-1]
    return centre, normal, float(np.abs((net - centre) @ normal).max(initial=0.0))


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

        One kernel call over all points, whatever mix of patches they lie on (`table`); each
        point's values are those of its patch's own `NurbsSurface.evaluate`, bit for bit.
        """
        patch = np.asarray(patch).ravel()
        u, v = np.asarray(u, dtype=np.float64).ravel(), np.asarray(v, dtype=np.float64).ravel()
        return _evaluate(self.table, patch, u, v, order)

    @cached_property
    def table(self) -> "kernel.PatchTable":
        """All patches as the kernels' flat table (patch k of the set is row k)."""
        return kernel.PatchTable.of(self.patches)

    @cached_property
    def net_planes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per patch its control net's plane (`net_plane`): a point on it (P, 3), its unit normal (P, 3), the
        net's largest distance from it (P,); and (P,) whether its weights are all > 0 (then the surface lies in the
        net's convex hull, so within that distance of the plane). Fitted once per patch, on first use (the tracer's
        planar neighbours and the second look's flat faces and supporting planes read it)."""
        planes = [net_plane(s) for s in self.patches]
        return (np.array([p[0] for p in planes]).reshape(-1, 3), np.array([p[1] for p in planes]).reshape(-1, 3),
                np.array([p[2] for p in planes]), np.array([bool(np.all(s.weights > 0)) for s in self.patches], dtype=bool))

    @cached_property
    def _domain_table(self) -> np.ndarray:
        return np.array([[*p.domain[0], *p.domain[1]] for p in self.patches])

    def normals(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray,
                derivs: SurfaceDerivatives | None = None) -> np.ndarray:
        """`NurbsSurface.normals` for points given by patch index and (u, v); rows with patch < 0 are NaN."""
        patch = np.asarray(patch).ravel()
        u, v = np.asarray(u, dtype=np.float64).ravel(), np.asarray(v, dtype=np.float64).ravel()
        return _normals(self.patches, self.table, patch, u, v, derivs)

    @property
    def trimmed(self) -> bool:
        """Whether any patch is a trimmed face (then hits, occlusions and contours are tested against trims)."""
        return any(p.trim is not None for p in self.patches)

    def on_face(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """True where (u, v) lies on the face of ``patch``: inside its trim, anywhere on an untrimmed patch
        (every face's trim in one compiled pass, `trims.TrimTable`: its loops' Hermite pieces where known, else
        `Trim.contains`'s polylines)."""
        patch = np.asarray(patch).ravel()
        if not self.trimmed:
            return np.ones(len(patch), dtype=bool)
        return self._trim_table.contains(patch, u, v)

    @cached_property
    def _trim_table(self):
        from .trims import TrimTable  # shapely with it: only where a face is trimmed (the [cad] extra)

        return TrimTable([surface.trim for surface in self.patches])

    def domains(self, patch: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-point parameter domain bounds (u0, u1, v0, v1)."""
        rows = self._domain_table[np.asarray(patch)]
        return rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]

    @cached_property
    def collapsed(self) -> np.ndarray:
        """Per patch (P, 4): whether its sides u = u₀, u = u₁, v = v₀, v = v₁ are collapsed to a point, to
        `COLLAPSED_FRACTION` of its net's size (the bounding-box diagonal of the side's control row: the side's
        image lies in the row's convex hull). Newton that runs onto such a side has not left the face through it."""
        return np.array([surface.collapsed for surface in self.patches], dtype=bool).reshape(-1, 4)

    @cached_property
    def poles(self) -> np.ndarray:
        """Per patch (P, 4, 3): the point its side u = u₀, u = u₁, v = v₀, v = v₁ collapses to where it does
        (`collapsed`: S at the side's middle), NaN elsewhere; all patches' in one evaluation."""
        out = np.full((len(self.patches), 4, 3), np.nan)
        patch, side = np.nonzero(self.collapsed)
        if len(patch):
            u0, u1, v0, v1 = self.domains(patch)
            mid_u, mid_v = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
            u = np.choose(side, [u0, u1, mid_u, mid_u])
            v = np.choose(side, [mid_v, mid_v, v0, v1])
            out[patch, side] = self.evaluate(patch, u, v).S
        return out

    @cached_property
    def apexes(self) -> np.ndarray:
        """Per patch (P, 4): whether its side u = u₀, u = u₁, v = v₀, v = v₁ collapses to an apex, a pole whose tangent
        cone is no plane (a cone's tip; not a sphere's pole): the directions S_v (S_u) in which its `APEX_MERIDIANS`
        meridians leave it, as unit vectors, stray from their best plane by more than `APEX_SINE` (the least singular
        value over the root of their count); all sides in one evaluation."""
        out = np.zeros(self.collapsed.shape, dtype=bool)
        patch, side = np.nonzero(self.collapsed)
        if len(patch) == 0:
            return out
        u0, u1, v0, v1 = self.domains(patch)
        w = np.linspace(0.0, 1.0, APEX_MERIDIANS)
        along_u = (u0[:, None] + w * (u1 - u0)[:, None])  # the meridians of a side v = v_p
        along_v = (v0[:, None] + w * (v1 - v0)[:, None])  # ... of a side u = u_p
        on_u = (side < 2)[:, None]
        u = np.where(on_u, np.choose(side, [u0, u1, u0, u0])[:, None], along_u).ravel()
        v = np.where(on_u, along_v, np.choose(side, [v0, v0, v0, v1])[:, None]).ravel()
        d = self.evaluate(np.repeat(patch, APEX_MERIDIANS), u, v)
        leave = np.where(np.repeat(on_u.ravel(), APEX_MERIDIANS)[:, None], d.Su, d.Sv).reshape(len(patch), -1, 3)
        length = np.linalg.norm(leave, axis=2, keepdims=True)
        unit = np.divide(leave, length, out=np.zeros_like(leave), where=length > 0)
        least = np.linalg.svd(unit, compute_uv=False)[:, -1] / np.sqrt(APEX_MERIDIANS)
        out[patch, side] = least > APEX_SINE
        return out

    @cached_property
    def closed(self) -> np.ndarray:
        """Per patch (P, 2), C-contiguous bool as the kernels take it: whether it is closed in u, in v: S(u₀, v) = S(u₁, v) for every v (S(u, v₀) = S(u, v₁)),
        to `CLOSED_FRACTION` of its reach, tested at the other direction's span breaks and span midpoints (the two
        edges are B-spline curves over those spans), all patches' in one evaluation. There a point of the seam has
        two parameter pairs, one on each side.
        """
        patch, axis, a_uv, b_uv = [], [], [], []
        for k, surface in enumerate(self.patches):
            (u0, u1), (v0, v1) = surface.domain
            for direction, breaks in enumerate(surface.span_breaks()[::-1]):  # along v for the u edges, u for the v ones
                s = np.union1d(breaks, 0.5 * (breaks[1:] + breaks[:-1]))
                ends = ((u0, u1), (v0, v1))[direction]
                for end, out in zip(ends, (a_uv, b_uv)):
                    e = np.full(len(s), end)
                    out.append(np.column_stack([e, s] if direction == 0 else [s, e]))
                patch.append(np.full(len(s), k))
                axis.append(np.full(len(s), direction))
        closed = np.zeros((len(self.patches), 2), dtype=bool)
        if not patch:
            return closed
        patch, axis, a_uv, b_uv = (np.concatenate(x) for x in (patch, axis, a_uv, b_uv))
        uv = np.concatenate([a_uv, b_uv])
        S = self.evaluate(np.concatenate([patch, patch]), uv[:, 0], uv[:, 1]).S
        gap = np.linalg.norm(S[:len(patch)] - S[len(patch):], axis=1)
        reach = np.array([surface.reach for surface in self.patches])
        worst = np.zeros((len(self.patches), 2))
        np.maximum.at(worst, (patch, axis), gap)
        return worst <= CLOSED_FRACTION * reach[:, None]
