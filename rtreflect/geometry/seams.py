"""Shared edges (seams) between patches: from the B-rep topology for CAD faces, found geometrically otherwise.

CAD faces carry their B-rep edges (`rtreflect.geometry.topology`): two faces sharing an edge
are a seam along the whole edge, each side given by its own pcurve at the same edge
parameters (`topology_seams`); `scene_seams` uses that and the geometric finder below for the
faces that have no topology.

Inline NURBS and .bpt patches carry no topology: two patches share an edge where their
boundary curves coincide, within a tolerance, over a common stretch. A boundary curve is
the image C(t) = S(γ(t)) of a polyline γ in the patch's (u, v) domain: the four sides of
an untrimmed patch are one straight segment each (u = u0, u = u1, v = v0, v = v1); a trimmed
face's loop, cut at its vertices, gives one curve per B-rep edge. Along a stretch of
curve a of patch A the partner curve b of patch B is matched point by point by Newton on
the distance |C_b(s) − P| (the foot point, Piegl & Tiller, *The NURBS Book*, section 6.1),
so partial overlaps and T-junctions (a long side against a short one, a side against
part of another) come out as the stretch of a where b lies within the tolerance, its ends
exactly at b's end points (projected onto a) or a's own.

Every shared stretch is reported once, parametrised along the curve of the lower
(patch, side) of the pair — or of the other when only that one is exact: a side of a
domain or an iso-line is the exact edge at every t, a trim loop sampled by the CAD reader
only at its vertices (the (u, v) chords between them leave the edge by their sagitta). On
a trim loop the figures are taken at its vertices, and the matched point on the other face
is the closest point of its surface near its boundary (Newton from the polyline's foot).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .surfaces import NurbsSurface

#: Boundary-curve samples per Bézier span of the running parameter, to find candidate pairs.
SAMPLES_PER_SPAN = 16
#: Pieces per span of a trim loop's polyline (its vertices are already close together).
LOOP_PIECES_PER_SPAN = 2
#: Newton steps for a foot point on a boundary curve (quadratic convergence: 8 is plenty from a sample).
FOOT_NEWTON_STEPS = 12
#: Points of a candidate stretch that must all lie within the tolerance of the partner curve.
STRETCH_CHECKS = 9
#: A curve whose end points lie within this fraction of the patch's reach of each other is closed (periodic). Not
#: `surfaces.CLOSED_FRACTION` (1e-6, an exporter's open seam): a boundary curve taken as open only ends its shared
#: stretches at its ends (the partner is matched up to there all the same), where a face taken as open stopped Newton.
CLOSED_FRACTION = 1e-12
#: A trim loop turning by more than this at a vertex (in (u, v)) has a corner there: a B-rep vertex.
CORNER_DEG = 20.0
#: Default tolerance for "the boundary curves coincide", as a fraction of the part's size (bounding-box
#: diagonal): well above any gap a CAD exchange leaves (1e-7..1e-4 of a part) yet far below a patch's size, so
#: seams with a visible gap are still found (and reported "open") while distinct edges are not confused.
FIND_FRACTION = 1e-3


@dataclass(frozen=True)
class Boundary:
    """One boundary curve of patch ``patch``: the image of the (u, v) polyline ``uv`` (m ≥ 2 vertices).

    ``inward`` is the (u, v) direction pointing into the face across the curve: one (2,) vector for a
    side of the domain, or one per segment (m − 1, 2) for a trim loop. The curve parameter t runs from
    0 to m − 1: segment i is t ∈ [i, i + 1]. A ``closed`` curve (a whole trim loop) has no ends, so a
    stretch shared along it ends where the partner curve leaves the tolerance.
    """

    patch: int
    side: str
    uv: np.ndarray
    inward: np.ndarray
    closed: bool = False

    def inward_at(self, t: np.ndarray) -> np.ndarray:
        """The inward (u, v) direction at parameters t, (n, 2)."""
        if self.inward.ndim == 1:
            return np.broadcast_to(self.inward, (len(t), 2))
        return self.inward[np.clip(np.floor(t).astype(np.int64), 0, len(self.uv) - 2)]

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u, v) points (n, 2) and their derivative d(u, v)/dt (n, 2) at parameters t."""
        t = np.asarray(t, dtype=np.float64)
        seg = np.clip(np.floor(t).astype(np.int64), 0, len(self.uv) - 2)
        d = self.uv[seg + 1] - self.uv[seg]
        return self.uv[seg] + (t - seg)[:, None] * d, d

    @property
    def t_max(self) -> float:
        return float(len(self.uv) - 1)

    @property
    def exact(self) -> bool:
        """True when the (u, v) polyline is one straight line (a side of the domain, an iso-line): C(t) is then
        the exact edge everywhere; a sampled trim loop is exact only at its vertices (chords between them)."""
        d = self.uv - self.uv[0]
        far = d[np.argmax(np.hypot(d[:, 0], d[:, 1]))]  # not the last vertex: a closed piece ends where it starts
        span = float(np.hypot(*far))
        return bool(np.all(np.abs(d[:, 0] * far[1] - d[:, 1] * far[0]) <= 1e-12 * max(span, 1e-300) ** 2))


def patch_sides(patch: int, surface: NurbsSurface) -> list[Boundary]:
    """The four sides of an untrimmed patch's domain, each a straight (u, v) segment."""
    (u0, u1), (v0, v1) = surface.domain
    return [
        Boundary(patch, "u0", np.array([[u0, v0], [u0, v1]]), np.array([1.0, 0.0])),
        Boundary(patch, "u1", np.array([[u1, v0], [u1, v1]]), np.array([-1.0, 0.0])),
        Boundary(patch, "v0", np.array([[u0, v0], [u1, v0]]), np.array([0.0, 1.0])),
        Boundary(patch, "v1", np.array([[u0, v1], [u1, v1]]), np.array([0.0, -1.0])),
    ]


def _signed_area(loop: np.ndarray) -> float:
    x, y = loop[:, 0], loop[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def loop_boundaries(patch: int, surface: NurbsSurface) -> list[Boundary]:
    """A trimmed face's loops as closed curves: the outer loop and each hole, the face on their inner side.

    Inward is the left of each segment of the outer loop when it runs counter-clockwise in (u, v)
    (its signed area > 0), the right otherwise; the other way round for a hole.
    """
    trim = surface.trim
    out = []
    for k, loop in enumerate([trim.outer, *trim.holes]):
        loop = np.asarray(loop, dtype=np.float64)
        if np.all(loop[0] == loop[-1]):
            loop = loop[:-1]
        uv = np.vstack([loop, loop[:1]])
        d = np.diff(uv, axis=0)
        left = np.stack([-d[:, 1], d[:, 0]], axis=1)
        ccw = _signed_area(loop) > 0
        inward = left if (ccw == (k == 0)) else -left
        name = "outer" if k == 0 else f"hole{k}"
        # Corners (a B-rep vertex where edges meet at an angle) cut the loop into open curves, whose ends
        # then bound the shared stretches exactly; a loop without corners stays one closed curve.
        heading = np.arctan2(d[:, 1], d[:, 0])
        turn = np.abs(np.angle(np.exp(1j * (heading - np.roll(heading, 1)))))
        corners = np.flatnonzero(turn > np.radians(CORNER_DEG))
        if len(corners) == 0:
            out.append(Boundary(patch, name, uv, inward, closed=True))
            continue
        m = len(loop)
        for i, c in enumerate(corners):
            end = corners[(i + 1) % len(corners)] + (m if i + 1 == len(corners) else 0)
            idx = np.arange(c, end + 1) % m
            seg = np.arange(c, end) % m
            out.append(Boundary(patch, f"{name}[{i}]", loop[idx], inward[seg]))
    return out


def face_boundaries(patch: int, surface: NurbsSurface) -> list[Boundary]:
    """The boundary curves of a face: its trim loops when trimmed, else the four sides of its domain."""
    return loop_boundaries(patch, surface) if surface.trim is not None else patch_sides(patch, surface)


def curve(surface: NurbsSurface, boundary: Boundary, t: np.ndarray, order: int = 1):
    """C(t) = S(γ(t)), C'(t) and (order 2) C''(t), with the surface's derivatives (chain rule, γ'' = 0 per segment)."""
    uv, d = boundary.at(t)
    der = surface.evaluate(uv[:, 0], uv[:, 1], order=order)
    du, dv = d[:, :1], d[:, 1:]
    C1 = der.Su * du + der.Sv * dv
    if order == 1:
        return der.S, C1, None, uv, der
    C2 = der.Suu * du * du + 2.0 * der.Suv * du * dv + der.Svv * dv * dv
    return der.S, C1, C2, uv, der


def sample_parameters(surface: NurbsSurface, boundary: Boundary, lo: float = 0.0, hi: float | None = None,
                      per_span: int = SAMPLES_PER_SPAN) -> np.ndarray:
    """Parameters in [lo, hi] of ``boundary``: its vertices and knot-span breaks, each span cut in ``per_span``.

    A trim loop's polyline is already dense (the reader samples it finely): its pieces are cut in
    `LOOP_PIECES_PER_SPAN` at most.
    """
    hi = boundary.t_max if hi is None else hi
    if not boundary.exact:
        per_span = min(per_span, LOOP_PIECES_PER_SPAN)
    breaks_u, breaks_v = surface.span_breaks()
    ts = [np.arange(len(boundary.uv), dtype=np.float64)]
    for i in range(len(boundary.uv) - 1):  # where a segment crosses a knot line, a span of C ends
        a, b = boundary.uv[i], boundary.uv[i + 1]
        for axis, breaks in ((0, breaks_u), (1, breaks_v)):
            if b[axis] != a[axis]:
                f = (breaks - a[axis]) / (b[axis] - a[axis])
                ts.append(i + f[(f > 0) & (f < 1)])
    t = np.unique(np.concatenate(ts))
    t = np.unique(np.concatenate([t, [lo, hi]]))
    t = t[(t >= lo) & (t <= hi)]
    fine = (t[:-1, None] + (t[1:] - t[:-1])[:, None] * np.arange(per_span)[None, :] / per_span).ravel()
    return np.r_[fine, t[-1]]


def foot_points(surface: NurbsSurface, boundary: Boundary, P: np.ndarray, t_start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameters t of the points of ``boundary`` closest to points P, by Newton from ``t_start``; and the distances.

    Minimises ½|C(t) − P|²: t ← t − C'·(C − P) / (C''·(C − P) + |C'|²) (Piegl & Tiller eq. 6.3), kept
    within the curve's ends; a step may cross a vertex of the (u, v) polyline into the next segment.
    """
    t = np.asarray(t_start, dtype=np.float64).copy()
    # A curve whose ends meet in space (a closed loop, an iso-line of a periodic face) is periodic in t: a foot
    # just before its end is reached from a start just after its beginning.
    ends = curve(surface, boundary, np.array([0.0, boundary.t_max]))[0]
    periodic = boundary.closed or np.linalg.norm(ends[1] - ends[0]) <= CLOSED_FRACTION * surface.reach
    for _ in range(FOOT_NEWTON_STEPS):
        C, C1, C2, _, _ = curve(surface, boundary, t, order=2)
        r = C - P
        g = np.einsum("ij,ij->i", C1, r)
        h = np.einsum("ij,ij->i", C2, r) + np.einsum("ij,ij->i", C1, C1)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(h > 0, g / h, 0.0)
        t_new = t - np.nan_to_num(step)
        t_new = np.mod(t_new, boundary.t_max) if periodic else np.clip(t_new, 0.0, boundary.t_max)
        moved = np.max(np.abs(np.nan_to_num(step)), initial=0.0)
        t = t_new
        if moved <= 1e-15 * boundary.t_max:  # converged to rounding everywhere
            break
    C = curve(surface, boundary, t)[0]
    return t, np.linalg.norm(C - P, axis=1)


@dataclass(frozen=True)
class Seam:
    """A stretch t ∈ [t0, t1] of boundary ``a`` (patch A) along which boundary ``b`` (patch B) coincides."""

    a: Boundary
    b: Boundary
    t0: float
    t1: float
    length: float  # 3D length of the stretch, model units
    #: From B-rep topology (`topology_seams`): a's and b's curves run over the same edge parameters, so the
    #: point of b matching a's point at t is b's at t (no geometric matching).
    paired: bool = False

    @property
    def patches(self) -> tuple[int, int]:
        return self.a.patch, self.b.patch


def match_points(surface: NurbsSurface, boundary: Boundary, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Foot points on ``boundary`` of points P (parameters, distances): Newton from the nearest of its samples.

    Always from the nearest sample, never from a neighbour's foot: a closed curve's parameter jumps where it
    starts and ends, and a start between two feet there would land on the far side.
    """
    tb = sample_parameters(surface, boundary)
    return foot_points(surface, boundary, P, _nearest_start(curve(surface, boundary, tb)[0], tb, P))


#: Newton steps for the closest point on a surface (from a foot point on its boundary polyline, already close).
SURFACE_NEWTON_STEPS = 8


def closest_on_surface(surface: NurbsSurface, P: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(u, v) of the points of ``surface`` closest to P, by Newton from ``uv``, kept within the domain.

    Minimises ½|S − P|²: gradient (S_u·r, S_v·r), Hessian [[S_u·S_u + S_uu·r, S_u·S_v + S_uv·r],
    [·, S_v·S_v + S_vv·r]] with r = S − P (Piegl & Tiller eq. 6.6–6.7).
    """
    (u0, u1), (v0, v1) = surface.domain
    u, v = uv[:, 0].copy(), uv[:, 1].copy()
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    for _ in range(SURFACE_NEWTON_STEPS):
        d = surface.evaluate(u, v, order=2)
        r = d.S - P
        gu, gv = dot(d.Su, r), dot(d.Sv, r)
        a, b, c = dot(d.Su, d.Su) + dot(d.Suu, r), dot(d.Su, d.Sv) + dot(d.Suv, r), dot(d.Sv, d.Sv) + dot(d.Svv, r)
        det = a * c - b * b
        ok = det > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            du = np.where(ok, (c * gu - b * gv) / det, 0.0)
            dv = np.where(ok, (a * gv - b * gu) / det, 0.0)
        u = np.clip(u - du, u0, u1)
        v = np.clip(v - dv, v0, v1)
    return np.stack([u, v], axis=1)


def _nearest_start(Cb: np.ndarray, tb: np.ndarray, P: np.ndarray) -> np.ndarray:
    """For each point P, the parameter of the nearest of the sampled points Cb (start for Newton)."""
    d2 = np.sum(P * P, axis=1)[:, None] - 2.0 * P @ Cb.T + np.sum(Cb * Cb, axis=1)[None, :]
    return tb[np.argmin(d2, axis=1)]


def _length(surface: NurbsSurface, boundary: Boundary, t0: float, t1: float) -> float:
    """Arc length of C over [t0, t1]: Gauss–Legendre on |C'| per sampled piece (exact to rounding for smooth C)."""
    t = sample_parameters(surface, boundary, t0, t1, per_span=4)
    x, w = np.polynomial.legendre.leggauss(8)
    a, b = t[:-1, None], t[1:, None]
    tt = (0.5 * (a + b) + 0.5 * (b - a) * x).ravel()
    speed = np.linalg.norm(curve(surface, boundary, tt)[1], axis=1).reshape(len(a), -1)
    return float(np.sum(0.5 * (b - a)[:, 0] * (speed @ w)))


def _stretches(sa: NurbsSurface, a: Boundary, sb: NurbsSurface, b: Boundary, tol: float,
               samples: dict) -> list[tuple[float, float]]:
    """The parameter intervals of ``a`` along which ``b`` lies within ``tol``.

    Breakpoints on a: its ends and the foot points of b's ends (where a T-junction or a partial
    overlap stops); a piece between breakpoints is shared when `STRETCH_CHECKS` points of it all lie
    within ``tol`` of b. Adjacent shared pieces merge.
    """
    ta, Ca = samples[id(a)]
    tb, Cb = samples[id(b)]
    if b.closed:
        cuts = np.r_[0.0, a.t_max, _leave_points(sa, a, sb, b, tol, ta, Ca, Cb, tb)]
    else:
        ends_b = Cb[[0, -1]]
        t_ends, d_ends = foot_points(sa, a, ends_b, _nearest_start(Ca, ta, ends_b))
        cuts = np.r_[0.0, a.t_max, t_ends[d_ends <= tol]]
    cuts = np.unique(cuts)
    pieces = []
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        if hi - lo <= 1e-12 * a.t_max:
            continue
        t = lo + (hi - lo) * (np.arange(STRETCH_CHECKS) + 0.5) / STRETCH_CHECKS
        P = curve(sa, a, t)[0]
        _, dist = foot_points(sb, b, P, _nearest_start(Cb, tb, P))
        if np.all(dist <= tol):
            if pieces and pieces[-1][1] == lo:
                pieces[-1] = (pieces[-1][0], hi)
            else:
                pieces.append((lo, hi))
    return pieces


#: Bisection steps locating where a closed partner curve leaves the tolerance: 2^-30 of a sample spacing.
LEAVE_STEPS = 30


def _distance_to(sa, a, sb, b, t, Cb, tb) -> np.ndarray:
    P = curve(sa, a, t)[0]
    return foot_points(sb, b, P, _nearest_start(Cb, tb, P))[1]


def _leave_points(sa, a, sb, b, tol, ta, Ca, Cb, tb) -> np.ndarray:
    """Parameters of a where its distance to the closed curve b crosses ``tol`` (bisection between samples)."""
    inside = _distance_to(sa, a, sb, b, ta, Cb, tb) <= tol
    # A lone sample within tol is a curve touching b at a point (a corner on the loop), not a shared stretch.
    lone = inside & ~np.r_[False, inside[:-1]] & ~np.r_[inside[1:], False]
    inside &= ~lone
    idx = np.flatnonzero(inside[:-1] != inside[1:])
    if len(idx) == 0:
        return np.zeros(0)
    lo, hi = ta[idx].copy(), ta[idx + 1].copy()
    lo_in = inside[idx]
    for _ in range(LEAVE_STEPS):
        mid = 0.5 * (lo + hi)
        mid_in = _distance_to(sa, a, sb, b, mid, Cb, tb) <= tol
        same = mid_in == lo_in
        lo, hi = np.where(same, mid, lo), np.where(same, hi, mid)
    # The inside end of each bracket, so the pieces' checks stay within the tolerance.
    return np.where(lo_in, lo, hi)


def part_size(surfaces: list[NurbsSurface]) -> float:
    """Bounding-box diagonal of all control nets: the part's size, the scale of the default tolerances."""
    net = np.concatenate([s.points.reshape(-1, 3) for s in surfaces])
    return float(np.linalg.norm(np.ptp(net, axis=0)))


def find_seams(surfaces: list[NurbsSurface], tol: float | None = None,
               boundaries: list[Boundary] | None = None) -> list[Seam]:
    """Every stretch where boundary curves of two faces (or two sides of one closed face) coincide within ``tol``.

    ``tol`` defaults to `FIND_FRACTION` of the part's size. ``boundaries`` defaults to every face's
    `face_boundaries` (trim loops, or the four sides of an untrimmed patch). Degenerate curves (a side collapsed to a point, a pole) share nothing and are skipped.
    """
    if tol is None:
        tol = FIND_FRACTION * part_size(surfaces)
    if boundaries is None:
        boundaries = [bd for k, s in enumerate(surfaces) for bd in face_boundaries(k, s)]
    samples, boxes, keep = {}, [], []
    for bd in boundaries:
        t = sample_parameters(surfaces[bd.patch], bd)
        C = curve(surfaces[bd.patch], bd, t)[0]
        samples[id(bd)] = (t, C)
        if np.sum(np.linalg.norm(np.diff(C, axis=0), axis=1)) > 2.0 * tol:
            keep.append(bd)
            boxes.append((C.min(axis=0) - tol, C.max(axis=0) + tol))
    seams = []
    lo = np.array([box[0] for box in boxes]).reshape(-1, 3)
    hi = np.array([box[1] for box in boxes]).reshape(-1, 3)
    # Candidate pairs: bounding boxes (grown by tol) that overlap, each pair once (i < j).
    overlap = np.all((lo[:, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[:, None, :]), axis=2)
    for i, j in zip(*np.nonzero(np.triu(overlap, k=1))):
        a, b = keep[i], keep[j]
        if a.patch == b.patch and a.side == b.side:
            continue
        if b.exact and not a.exact:  # measure along the exact curve of the two (module doc)
            a, b = b, a
        sa, sb = surfaces[a.patch], surfaces[b.patch]
        for t0, t1 in _stretches(sa, a, sb, b, tol, samples):
            length = _length(sa, a, t0, t1)
            if length > 2.0 * tol:  # corners touching at a point share no edge
                seams.append(Seam(a, b, t0, t1, length))
    return seams


@dataclass(frozen=True)
class EdgeBoundary(Boundary):
    """A B-rep edge's pcurve on one face (`FaceEdge`), as a `Boundary`: its vertices are the pcurve's exact points at
    the edge's sampled parameters, ``duv`` (m, 2) the pcurve's tangents there; t = vertex index."""

    duv: np.ndarray = None

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u, v) linear between vertices (exact at them) and the tangent γ' interpolated likewise (exact at them)."""
        uv, _ = super().at(t)
        t = np.asarray(t, dtype=np.float64)
        seg = np.clip(np.floor(t).astype(np.int64), 0, len(self.uv) - 2)
        f = (t - seg)[:, None]
        return uv, (1.0 - f) * self.duv[seg] + f * self.duv[seg + 1]

    @property
    def exact(self) -> bool:
        """Exact at its vertices only (the pcurve between them is a chord): the figures are measured there."""
        return False


def _inward(surface: NurbsSurface, uv: np.ndarray) -> np.ndarray:
    """The (u, v) direction into the face across an edge's polyline ``uv``, one per segment: the side of the edge
    (left or right, one for the whole edge) on which points a quarter chord off the segments' midpoints lie in
    the face's trim, by majority (a point may fall outside where the face is thinner than that, at a corner)."""
    d = np.diff(uv, axis=0)
    left = np.stack([-d[:, 1], d[:, 0]], axis=1)
    probe = 0.5 * (uv[:-1] + uv[1:]) + 0.25 * left
    inside = surface.trim.contains(probe[:, 0], probe[:, 1])
    return left if 2 * np.count_nonzero(inside) >= len(inside) else -left


def topology_seams(surfaces: list[NurbsSurface]) -> list[Seam]:
    """One seam per B-rep edge two faces share (`topology.shared_edges`), along the whole edge, paired by parameter.

    Faces without topology (``trim.edges`` empty: inline and .bpt patches) take no part; a periodic face's own
    seam edge and a pole are no seam (see `topology.shared_edges`).
    """
    from .topology import edge_record, shared_edges

    edges = [s.trim.edges if s.trim is not None else () for s in surfaces]
    seams = []
    for key, ia, ib in shared_edges(edges):
        ra, rb = edge_record(edges[ia], key), edge_record(edges[ib], key)
        side = f"edge {key.rsplit('#', 1)[-1]}"
        a = EdgeBoundary(ia, side, ra.uv, _inward(surfaces[ia], ra.uv), duv=ra.duv)
        b = EdgeBoundary(ib, side, rb.uv, _inward(surfaces[ib], rb.uv), duv=rb.duv)
        seams.append(Seam(a, b, 0.0, a.t_max, ra.length, paired=True))
    return seams


def scene_seams(surfaces: list[NurbsSurface], tol: float | None = None) -> list[Seam]:
    """Every seam of a scene: `topology_seams` among the faces that carry B-rep edges, `find_seams` (geometric,
    within ``tol``) among the others. A CAD face and an inline patch are never paired."""
    topo = [k for k, s in enumerate(surfaces) if s.trim is not None and s.trim.edges]
    others = [bd for k, s in enumerate(surfaces) if k not in set(topo) for bd in face_boundaries(k, s)]
    seams = topology_seams(surfaces) if topo else []
    if others:
        seams += find_seams(surfaces, tol, boundaries=others)
    return seams
