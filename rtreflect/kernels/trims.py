"""Compiled point-in-face test of trimmed faces (`rtreflect.geometry.trims.TrimTable`): crossing parity, against
each loop segment's cubic Hermite piece where it is known and its chord (with exact signs) elsewhere.

A point (u, v) lies inside a region whose boundary is the face's closed loops when a ray from it towards +u
crosses them an odd number of times (Jordan; the even–odd rule of O'Rourke, *Computational Geometry in C*,
§7.4, "point in polygon"). Each loop is a chain of segments between samples of its edges' pcurves. A point
counts as **high** when its v exceeds the point's, low otherwise; a segment's ends are classed so at every
sample, so neighbouring segments agree about a crossing exactly at a shared sample (it counts once), and a
segment crosses the ray as often as its class changes along it, at a u right of the point.

**Chords** (rows without a curve). A segment a→b counts when it straddles the ray half-open, a_v ≤ v < b_v
(or b_v ≤ v < a_v), and the point lies left of a→b (right of it for a downward segment): the sign of
orient(a, b, p) = (a_u − p_u)(b_v − p_v) − (a_v − p_v)(b_u − p_u). That sign is taken only where floating
point proves it (a segment along u or v needs none: whether the point lies on it, or which side, is a
comparison; a point on a loop is on the face, as GEOS counts the boundary): Shewchuk's filter (*Adaptive precision floating-point arithmetic and fast robust geometric
predicates*, 1997, ``orient2dfast`` with ``ccwerrboundA`` = (3 + 16ε)ε) bounds the rounding error of the
computed value, differences included. A point whose sign against some segment it may touch is below that
bound (on or within rounding of a chord) is flagged ``unsure``: the caller asks GEOS (robust, boundary
counted inside).

**Hermite pieces.** A chord lies up to the reader's tolerance inside a convex edge, so a point between them
would be off the face (and, if the face across the edge rejects it by its own chord, a ray slips through the
part). Where the reader knows the pcurve's tangents the segment carries the cubic Hermite piece
H(s) = a + c₁s + c₂s² + c₃s³, s ∈ [0, 1], with H(0) = a, H(1) = b, H'(0) = Δt·γ'(t_a), H'(1) = Δt·γ'(t_b),
which follows the pcurve γ to O(Δt⁴) (de Boor, *A Practical Guide to Splines*, ch. IV) where the chord is
O(Δt²) off, and a box holding it (`rtreflect.geometry.trims.segment_table`). A point outside the box is
decided as by the chord (which lies in the box: right of it, no crossing; left of it, a crossing when the ends'
classes differ). Inside it, the crossings are the roots of v(s) = p_v: s ∈ [0, 1] is split at the roots of
v'(s) (a quadratic) into at most three monotone pieces; a piece whose ends' classes differ holds exactly one
class change, found by bisection until the u of the bracket is provably on one side of p_u (|u(s) − p_u| beyond
the bracket's width times a bound of |u'|), and counted where it lies right of the point. A point within
rounding of the curve (at such a root, a v-extremum or an end) is on the loop: inside. No sign goes to GEOS here (its
answer is the polygon's).

Segments are bucketed into equal bands of v per face; a point tests only its band's segments (every segment
whose box's v-range contains the point's v lies in it).
"""

from __future__ import annotations

from .compiled import njit

from . import JIT

#: Shewchuk's ccwerrboundA: |computed orient − exact| ≤ this × (|detleft| + |detright|), ε = 2⁻⁵³.
_EPS = 2.0 ** -53
CCW_ERRBOUND = (3.0 + 16.0 * _EPS) * _EPS
#: Below this |detleft| + |detright| the products may have underflowed: the sign is not trusted.
UNDERFLOW = 1e-290
#: Columns of a segment row: a_u, a_v, b_u, b_v; from `CURVE` the Hermite piece's c₁, c₂, c₃ in u then in v (NaN:
#: the chord); from `BOX` the box holding the segment's curve: u_lo, u_hi, v_lo, v_hi.
CURVE = 4
BOX = 10
COLUMNS = 14
#: Bisection steps of a crossing at most (float64's s resolves ~53 halvings of [0, 1]).
BISECTIONS = 64
#: A point within this many units of rounding (ε times the piece's coefficient sizes) of the curve is on it.
ON_ROUNDING = 16.0


@njit(inline="always", **JIT)
def _band(v, vlo, inv_height, bands):
    """Band of v in a face's [vlo, vhi] cut into ``bands`` equal bands (monotone in v: segments use the same formula)."""
    b = int((v - vlo) * inv_height)
    return min(max(b, 0), bands - 1)


@njit(inline="always", **JIT)
def _cubic(c0, c1, c2, c3, s):
    return c0 + s * (c1 + s * (c2 + s * c3))


@njit(inline="always", **JIT)
def _crossing(s0, s1, v0, au, c1u, c2u, c3u, av, c1v, c2v, c3v, pu, pv, slope, tol_u):
    """The one class change of v(s) on the monotone piece [s0, s1] (v(s0) = ``v0``): 1 where it lies right of p_u,
    0 left, 2 on the curve (within ``tol_u``). ``slope`` bounds |u'| on [0, 1]."""
    high = v0 > pv
    lo, hi = s0, s1
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        um = _cubic(au, c1u, c2u, c3u, mid)
        reach = slope * (hi - lo) + tol_u  # the change lies in [lo, hi]: its u within this of u(mid)
        if um - pu > reach:
            return 1
        if pu - um > reach:
            return 0
        if mid <= lo or mid >= hi:
            return 2  # the bracket is as narrow as float64 makes it and its u is p_u's: on the curve
        if (_cubic(av, c1v, c2v, c3v, mid) > pv) == high:
            lo = mid
        else:
            hi = mid
    return 2


@njit(inline="always", **JIT)
def _curve_crossings(au, av, bu, bv, c1u, c2u, c3u, c1v, c2v, c3v, pu, pv):
    """Crossings right of (p_u, p_v) of the Hermite piece a → b (module doc): 0 or 1 for their parity, 2 on it."""
    tol_u = ON_ROUNDING * _EPS * (abs(au) + abs(c1u) + abs(c2u) + abs(c3u) + abs(pu))
    tol_v = ON_ROUNDING * _EPS * (abs(av) + abs(c1v) + abs(c2v) + abs(c3v) + abs(pv))
    slope = abs(c1u) + 2.0 * abs(c2u) + 3.0 * abs(c3u)
    if (abs(pu - au) <= tol_u and abs(pv - av) <= tol_v) or (abs(pu - bu) <= tol_u and abs(pv - bv) <= tol_v):
        return 2  # at an end (where the loop may turn back in v: no class change to find it by)
    # Roots of v'(s) = c₁ + 2c₂ s + 3c₃ s² in (0, 1), ascending (the numerically stable quadratic formula).
    qa, qb, qc = 3.0 * c3v, 2.0 * c2v, c1v
    r0 = r1 = 2.0
    if qa != 0.0:
        disc = qb * qb - 4.0 * qa * qc
        if disc >= 0.0:
            root = disc ** 0.5
            q = -0.5 * (qb + root) if qb >= 0.0 else -0.5 * (qb - root)
            x0 = q / qa
            x1 = qc / q if q != 0.0 else x0
            r0, r1 = min(x0, x1), max(x0, x1)
    elif qb != 0.0:
        r0 = -qc / qb
    count = 0
    s_prev, v_prev = 0.0, av
    for k in range(3):
        if k == 0:
            s_next = r0
        elif k == 1:
            s_next = r1
        else:
            s_next = 1.0
        if k < 2:
            if not (s_prev < s_next < 1.0):  # outside (0, 1), or the root before it
                continue
            v_next = _cubic(av, c1v, c2v, c3v, s_next)
            if abs(v_next - pv) <= tol_v and abs(_cubic(au, c1u, c2u, c3u, s_next) - pu) <= tol_u:
                return 2  # at a v-extremum of the curve
        else:
            v_next = bv
        if (v_prev > pv) != (v_next > pv):
            c = _crossing(s_prev, s_next, v_prev, au, c1u, c2u, c3u, av, c1v, c2v, c3v, pu, pv, slope, tol_u)
            if c == 2:
                return 2
            count += c
        s_prev, v_prev = s_next, v_next
    return count & 1


@njit(**JIT, aot=(
    "void(i8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], i8[::1], i8[::1], i8[::1], i8[::1], f8[:, ::1], b1[::1], b1[::1])",
))
def inside_faces(row, u, v, vlo, vhi, inv_height, band_first, band_count, band_ptr, band_seg, segments,
                 inside, unsure):
    """Per point i on face table row ``row[i]`` (−1: an untrimmed face, inside): ``inside[i]`` by crossing parity,
    ``unsure[i]`` where a chord's sign was not proven (module doc). ``segments`` (S, `COLUMNS`): the ends a, b, the
    Hermite piece (NaN: the chord) and its box; the face's bands are band_first[f] … band_first[f] + band_count[f] − 1
    of the CSR ``band_ptr`` / ``band_seg``."""
    for i in range(row.shape[0]):
        f = row[i]
        unsure[i] = False
        if f < 0:
            inside[i] = True
            continue
        pu, pv = u[i], v[i]
        if not (vlo[f] <= pv <= vhi[f]) or pu != pu:  # also NaN: outside every loop, on none
            inside[i] = False
            continue
        b = band_first[f] + _band(pv, vlo[f], inv_height[f], band_count[f])
        odd = on = False
        for j in range(band_ptr[b], band_ptr[b + 1]):
            s = band_seg[j]
            au, av, bu, bv = segments[s, 0], segments[s, 1], segments[s, 2], segments[s, 3]
            if not (segments[s, BOX + 2] <= pv <= segments[s, BOX + 3]):
                continue
            crosses = (av > pv) != (bv > pv)  # the ends' classes differ (module doc): a_v ≤ v < b_v or b_v ≤ v < a_v
            c1u = segments[s, CURVE]
            if c1u == c1u:  # a Hermite piece (not NaN)
                if pu > segments[s, BOX + 1]:
                    continue
                if pu < segments[s, BOX]:
                    if crosses:
                        odd = not odd
                    continue
                c = _curve_crossings(au, av, bu, bv, c1u, segments[s, CURVE + 1], segments[s, CURVE + 2],
                                     segments[s, CURVE + 3], segments[s, CURVE + 4], segments[s, CURVE + 5], pu, pv)
                if c == 2:
                    on = True
                    break
                if c == 1:
                    odd = not odd
                continue
            ulo, uhi = min(au, bu), max(au, bu)
            if av == bv or au == bu:  # along u or v (a loop on the domain's edge): on it, or not, by comparisons
                if ulo <= pu <= uhi:  # (and v within the segment's, above): on the loop, which counts as inside
                    on = True
                    break
                if crosses and pu < ulo:
                    odd = not odd
                continue
            if pu < ulo or pu > uhi:  # off the segment's box: no sign needed
                if crosses and pu < ulo:
                    odd = not odd
                continue
            detleft = (au - pu) * (bv - pv)
            detright = (av - pv) * (bu - pu)
            det = detleft - detright
            bound = CCW_ERRBOUND * (abs(detleft) + abs(detright))
            if abs(det) <= bound or abs(detleft) + abs(detright) < UNDERFLOW:
                unsure[i] = True
                break
            up = av <= pv < bv
            if (up and det > 0.0) or (not up and crosses and det < 0.0):
                odd = not odd
        inside[i] = odd or on
