"""Trim loops of a CAD face in its surface's (u, v) parameter space, and the point-in-face test.

A trimmed face is the part of its (untrimmed) NURBS surface inside the **outer loop** and
inside no **hole** (DESIGN.md, CAD input). CAD readers (``rtreflect.exchange``) sample each
loop's pcurves into a closed polyline in (u, v) of the NURBS surface the face was converted to
(never of the original analytic surface: conversion moves the parameters).

The polylines are within the reader's tolerance of the edges, but a point between a convex loop's chord
and its edge is off the polygon: a ray there can slip between two faces that share the edge, each rejecting
it by its own chord. So readers also give each segment the end tangents of a cubic Hermite piece following
the edge's pcurve (`Trim.tangents`: O(h⁴) from it where the chord is O(h²)), and the test decides points
near a segment against that curve.

`Trim.contains` is GEOS's prepared point-in-polygon (shapely, installed with the ``[cad]`` extra,
which is the only source of trimmed faces): the polylines. For many points on many faces at once (the
tracer's every candidate) `TrimTable` answers in one compiled pass (`kernels.trims.inside_faces`: crossing
parity, against the Hermite pieces where known and the chords with proven signs elsewhere), asking GEOS
only about the points it cannot prove (on or within float rounding of a chord) and on faces whose loops
GEOS had to repair.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from ..kernels import trims as kernel

#: `TrimTable` cuts each face's v-range into bands holding about this many loop segments each, so a point
#: tests a few segments (those of its band) rather than the whole loop (the plate's top face: 12,832).
SEGMENTS_PER_BAND = 2
#: A segment along u or v keeps its chord unless its Hermite piece bends off it by more than this fraction of its
#: length (`segment_table`): a reader's pcurve along a domain side is straight to OCCT's tolerances (~1e-9), a curve
#: whose chord happens to run along u (a circle's top between two samples) bends off by the chord error (1e-3 here).
ALIGNED_BEND = 1e-6
#: Held around every GEOS query of a `Trim`'s polygon. GEOS's prepared geometries are not thread-safe (libgeos/geos
#: issue 825: their indexes are built on first use, and queries keep state) and shapely lets go of the GIL inside
#: them: two render threads asking about one face at once corrupted the heap (build123d's M6 countersunk screw,
#: 2 of 12 renders of a curvature map crashed). The tracer asks GEOS only about the few points its kernel cannot
#: prove, so one lock costs nothing measurable.
GEOS_LOCK = threading.Lock()


def into_period(x: np.ndarray, x0, period) -> np.ndarray:
    """A periodic parameter moved into [x0, x0 + period), the period the trim loops were sampled in."""
    return x0 + np.mod(x - x0, period)


@dataclass(frozen=True, eq=False)
class Trim:
    """One face's loops: ``outer`` (n, 2) and ``holes`` (m_k, 2), closed polylines in (u, v).

    The last point of a loop need not repeat the first. ``u_period`` / ``v_period`` are set for
    a periodic direction whose loops were sampled in one period starting at ``u0`` / ``v0``:
    parameters are wrapped into ``[u0, u0 + period)`` before the test. ``edges``: the face's B-rep
    edges with their pcurves (`rtreflect.geometry.topology.FaceEdge`), when its reader knows them.
    ``tangents``: per loop (outer, then holes), where its reader knows them, (n, 4) per segment i → i + 1 (the
    last closing the loop): the end tangents T₀, T₁ (u, v each) of the cubic Hermite piece between its points that
    follows the edge's pcurve (`TrimTable`); a NaN row (or no array) keeps that segment's chord.

    `contains` (GEOS) tests the polylines; `TrimTable` tests the Hermite pieces where they are known.
    """

    outer: np.ndarray
    holes: tuple[np.ndarray, ...] = ()
    u_period: float | None = None
    v_period: float | None = None
    u0: float = 0.0
    v0: float = 0.0
    edges: tuple = ()
    tangents: tuple = ()
    _polygon: object = field(init=False, repr=False)

    def __post_init__(self) -> None:
        import shapely

        polygon = shapely.Polygon(np.asarray(self.outer, dtype=np.float64),
                                  [np.asarray(h, dtype=np.float64) for h in self.holes])
        if not polygon.is_valid:
            polygon = shapely.make_valid(polygon)
        shapely.prepare(polygon)
        object.__setattr__(self, "_polygon", polygon)

    def wrap(self, u: np.ndarray, v: np.ndarray, start: tuple[float, float] | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
        """Periodic parameters moved into the period the loops were sampled in (from (u0, v0)), or into the one from
        ``start`` (a surface's domain start: the loops' points in the surface's own parameters, `NurbsSurface.loop_uv`)."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        u_start, v_start = (self.u0, self.v0) if start is None else start
        if self.u_period:
            u = into_period(u, u_start, self.u_period)
        if self.v_period:
            v = into_period(v, v_start, self.v_period)
        return u, v

    def contains(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """True where (u, v) lies on the face: inside the outer loop and inside no hole (boundary counts as inside)."""
        import shapely

        u, v = self.wrap(u, v)
        with GEOS_LOCK:
            return shapely.intersects_xy(self._polygon, u, v)

    def roundness(self, domain) -> float:
        """4πA/P² of the face's region in its domain's unit square ((u − u0)/(u1 − u0), (v − v0)/(v1 − v0)): 1 for a
        disc, about 0.8 for a square, the strip's width over its length times π for a long strip; 0 where the loops
        enclose nothing (a loop that runs out along a curve and back)."""
        import shapely

        (u0, u1), (v0, v1) = domain
        unit = shapely.affinity.affine_transform(self._polygon, [1.0 / (u1 - u0), 0.0, 0.0, 1.0 / (v1 - v0),
                                                                 -u0 / (u1 - u0), -v0 / (v1 - v0)])
        return 4.0 * np.pi * unit.area / unit.length ** 2 if unit.length > 0 else 0.0

    def boundary_distance(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Per point (u, v) (in the loops' period), its distance in (u, v) to the nearest of the face's loops: the
        loops themselves (a polygon GEOS repaired may be a collection, which has no boundary to measure from)."""
        import shapely

        loops = shapely.MultiLineString([np.concatenate([loop, loop[:1]]) for loop in (self.outer, *self.holes)])
        with GEOS_LOCK:
            return shapely.distance(loops, shapely.points(np.column_stack([u, v])))

    def overlaps(self, polygons: np.ndarray) -> np.ndarray:
        """Per shapely polygon (in the loops' period), whether it meets the face: boundary contact counts."""
        import shapely

        with GEOS_LOCK:
            return shapely.intersects(polygons, self._polygon)


class TrimTable:
    """The point-in-face test of many faces at once: ``contains(patch, u, v)`` is, per point, its face's
    `Trim.contains` (True on an untrimmed face), in one compiled pass (`kernels.trims.inside_faces`), except
    between a segment's chord and its edge: there the segment's cubic Hermite piece (`Trim.tangents`, which follows
    the edge's pcurve to O(h⁴)) decides instead of the chord.

    Per trimmed face a table row: its loops' segments (outer loop and holes, each closed) bucketed into
    equal bands of v (`SEGMENTS_PER_BAND`), each segment in every band its curve's box meets. A face whose polygon
    GEOS had to repair (``make_valid``: no longer the loops' even–odd region) has no row: its points go to GEOS
    (the polygon's answer), as do the points the kernel flags unsure.
    """

    def __init__(self, trims: list[Trim | None]):
        self.trims = list(trims)
        n = len(self.trims)
        self.row = np.full(n, -1, dtype=np.int64)  # −1: untrimmed; −2: GEOS only
        self.u0, self.u_period, self.v0, self.v_period = (np.zeros(n) for _ in range(4))
        vlo, vhi, inv, first, count, ptr, seg, segments = [], [], [], [], [], [np.zeros(1, dtype=np.int64)], [], []
        bands = n_seg = 0
        for k, trim in enumerate(self.trims):
            if trim is None:
                continue
            self.u0[k], self.u_period[k] = trim.u0, trim.u_period or 0.0
            self.v0[k], self.v_period[k] = trim.v0, trim.v_period or 0.0
            if trim._polygon.geom_type != "Polygon" or not _same_rings(trim):
                self.row[k] = -2
                continue
            rings = [np.asarray(r, dtype=np.float64).reshape(-1, 2) for r in (trim.outer, *trim.holes)]
            table = segment_table(np.concatenate(rings), np.concatenate([np.roll(r, -1, axis=0) for r in rings]),
                                  np.concatenate([_ring_tangents(trim, i, len(r)) for i, r in enumerate(rings)]))
            ylo, yhi = table[:, kernel.BOX + 2], table[:, kernel.BOX + 3]  # each segment's curve's v-range
            lo, hi = float(ylo.min()), float(yhi.max())
            nb = max(1, -(-len(table) // SEGMENTS_PER_BAND))
            scale = nb / (hi - lo) if hi > lo else 0.0
            # Each segment in every band its v-range meets: the kernel's band index (`kernels.trims._band`, the same
            # float64 operations, monotone in v) of its lowest and highest v and those between.
            b0 = np.clip(np.floor((ylo - lo) * scale).astype(np.int64), 0, nb - 1)
            b1 = np.clip(np.floor((yhi - lo) * scale).astype(np.int64), 0, nb - 1)
            reps = b1 - b0 + 1
            which = np.repeat(np.arange(len(table)), reps)
            band = np.repeat(b0, reps) + (np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps))
            order = np.argsort(band, kind="stable")
            ptr.append(ptr[-1][-1] + np.cumsum(np.bincount(band, minlength=nb)))
            seg.append(which[order] + n_seg)
            segments.append(table)
            self.row[k] = len(vlo)
            vlo.append(lo), vhi.append(hi), inv.append(scale), first.append(bands), count.append(nb)
            bands, n_seg = bands + nb, n_seg + len(table)
        ptr = np.concatenate(ptr)
        self._args = (np.array(vlo, dtype=np.float64), np.array(vhi, dtype=np.float64), np.array(inv, dtype=np.float64),
                      np.array(first, dtype=np.int64), np.array(count, dtype=np.int64), ptr.astype(np.int64),
                      np.concatenate(seg).astype(np.int64) if seg else np.zeros(0, dtype=np.int64),
                      np.concatenate(segments) if segments else np.zeros((0, kernel.COLUMNS)))
        self.wraps = bool(np.any(self.u_period > 0) or np.any(self.v_period > 0))

    def contains(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """True where (u, v) lies on the face of ``patch`` (module doc): inside its trim, anywhere on an untrimmed one."""
        given = np.asarray(patch, dtype=np.int64).ravel()
        patch = np.maximum(given, 0)  # −1 (no face): True, as `SurfaceSet.on_face` always answered there
        u0 = u = np.asarray(u, dtype=np.float64).ravel()
        v0 = v = np.asarray(v, dtype=np.float64).ravel()
        if self.wraps:  # `Trim.wrap`, per point's face
            u, v = u.copy(), v.copy()
            for x, x0, period in ((u, self.u0[patch], self.u_period[patch]), (v, self.v0[patch], self.v_period[patch])):
                at = np.flatnonzero(period > 0)
                x[at] = into_period(x[at], x0[at], period[at])
        row = np.where(given >= 0, self.row[patch], -1)
        inside, unsure = np.empty(len(patch), dtype=bool), np.empty(len(patch), dtype=bool)
        kernel.inside_faces(np.maximum(row, -1), u, v, *self._args, inside, unsure)
        ask = np.flatnonzero(unsure | (row == -2))
        if len(ask):  # GEOS (`Trim.contains`), per face: the few points the kernel cannot prove
            for k in np.unique(patch[ask]):
                at = ask[patch[ask] == k]
                inside[at] = self.trims[k].contains(u0[at], v0[at])  # as given: it wraps them itself
        return inside


def segment_table(a: np.ndarray, b: np.ndarray, tangents: np.ndarray) -> np.ndarray:
    """The kernel's segment rows (`kernels.trims.COLUMNS`) of segments a → b (S, 2 each) with their Hermite end
    tangents (S, 4; NaN: the chord): the ends, the piece's power form H(s) = a + c₁s + c₂s² + c₃s³ per coordinate
    (NaN: the chord) and the box holding the piece.

    With d = b − a: c₁ = T₀, c₂ = 3d − 2T₀ − T₁, c₃ = T₀ + T₁ − 2d. The piece minus the chord is
    h₁₀(s)(T₀ − d) + h₁₁(s)(T₁ − d) with |h₁₀|, |h₁₁| ≤ 4/27 on [0, 1] (the Hermite basis), so the chord's box
    widened per coordinate by 4/27 (|T₀ − d| + |T₁ − d|) holds it. A segment along u or v (a domain side, a seam)
    whose piece hardly leaves it, and one whose piece stays within rounding of its chord, keep the chord (its
    comparisons and proven signs).
    """
    table = np.full((len(a), kernel.COLUMNS), np.nan)
    table[:, 0:2], table[:, 2:4] = a, b
    d = b - a
    t0, t1 = tangents[:, 0:2], tangents[:, 2:4]
    c1, c2, c3 = t0, 3.0 * d - 2.0 * t0 - t1, t0 + t1 - 2.0 * d
    deviation = (4.0 / 27.0) * (np.abs(t0 - d) + np.abs(t1 - d))
    scale = np.maximum(np.abs(a), np.abs(b)).max(axis=1)
    rounding = 64.0 * np.finfo(np.float64).eps * scale
    # A chord along u or v (a domain side, a seam, snapped there by the reader) stays one unless its piece bends
    # off it by more than `ALIGNED_BEND` of its length: its comparisons keep points on the side on the face.
    length = np.abs(d).max(axis=1)
    across = np.where(d[:, 0] == 0.0, deviation[:, 0], np.where(d[:, 1] == 0.0, deviation[:, 1], np.inf))
    curved = (np.isfinite(tangents).all(axis=1) & (deviation.max(axis=1) > rounding)
              & (across > ALIGNED_BEND * length))
    slack = deviation * (1.0 + 1e-9) + rounding[:, None]  # the bound's own rounding
    deviation = np.where(curved[:, None], slack, 0.0)
    for axis in (0, 1):
        table[curved, kernel.CURVE + 3 * axis:kernel.CURVE + 3 * axis + 3] = np.column_stack(
            [c1[curved, axis], c2[curved, axis], c3[curved, axis]])
        table[:, kernel.BOX + 2 * axis] = np.minimum(a[:, axis], b[:, axis]) - deviation[:, axis]
        table[:, kernel.BOX + 2 * axis + 1] = np.maximum(a[:, axis], b[:, axis]) + deviation[:, axis]
    return table


def _ring_tangents(trim: Trim, ring: int, n: int) -> np.ndarray:
    """Loop ``ring``'s Hermite tangents (n, 4): `Trim.tangents`, or NaN (chords) where its reader gave none."""
    if ring < len(trim.tangents) and trim.tangents[ring] is not None and len(trim.tangents[ring]) == n:
        return np.asarray(trim.tangents[ring], dtype=np.float64).reshape(n, 4)
    return np.full((n, 4), np.nan)


def _same_rings(trim: Trim) -> bool:
    """Whether GEOS's polygon has the loops as given (its shell and holes; their point counts, one closing point more)."""
    polygon = trim._polygon
    rings = [polygon.exterior, *polygon.interiors]
    loops = [trim.outer, *trim.holes]
    if len(rings) != len(loops):
        return False
    for ring, loop in zip(rings, loops):
        loop = np.asarray(loop, dtype=np.float64).reshape(-1, 2)
        coords = np.asarray(ring.coords)
        closed = np.array_equal(loop[0], loop[-1])
        if not np.array_equal(coords[: len(loop) - closed], loop[: len(loop) - closed]) or len(coords) != len(loop) + (not closed):
            return False
    return True
