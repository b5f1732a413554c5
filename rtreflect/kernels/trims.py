"""Compiled point-in-face test of trimmed faces (`rtreflect.geometry.trims.TrimTable`): crossing parity with exact signs.

A point (u, v) lies inside a polygon whose rings are the face's loops when a ray from it towards +u crosses
its segments an odd number of times (Jordan; the even–odd rule of O'Rourke, *Computational Geometry in C*,
§7.4, "point in polygon"). A segment a→b counts when it straddles the ray half-open, a_v ≤ v < b_v
(or b_v ≤ v < a_v), and the point lies left of a→b (right of it for a downward segment): the sign of
orient(a, b, p) = (a_u − p_u)(b_v − p_v) − (a_v − p_v)(b_u − p_u). That sign is taken only where floating
point proves it (a segment along u or v needs none: whether the point lies on it, or which side, is a
comparison; a point on a loop is on the face, as GEOS counts the boundary): Shewchuk's filter (*Adaptive precision floating-point arithmetic and fast robust geometric
predicates*, 1997, ``orient2dfast`` with ``ccwerrboundA`` = (3 + 16ε)ε) bounds the rounding error of the
computed value, differences included. A point whose sign against some segment it may touch is below that
bound (on or within rounding of a loop) is flagged ``unsure``: the caller asks GEOS (robust, boundary
counted inside), so the answer is GEOS's everywhere, bit for bit.

Segments are bucketed into equal bands of v per face; a point tests only its band's segments (every segment
whose v-range contains the point's v lies in it).
"""

from __future__ import annotations

from .compiled import njit

from . import JIT

#: Shewchuk's ccwerrboundA: |computed orient − exact| ≤ this × (|detleft| + |detright|), ε = 2⁻⁵³.
_EPS = 2.0 ** -53
CCW_ERRBOUND = (3.0 + 16.0 * _EPS) * _EPS
#: Below this |detleft| + |detright| the products may have underflowed: the sign is not trusted.
UNDERFLOW = 1e-290


@njit(inline="always", **JIT)
def _band(v, vlo, inv_height, bands):
    """Band of v in a face's [vlo, vhi] cut into ``bands`` equal bands (monotone in v: segments use the same formula)."""
    b = int((v - vlo) * inv_height)
    return min(max(b, 0), bands - 1)


@njit(**JIT, aot=(
    "void(i8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], i8[::1], i8[::1], i8[::1], i8[::1], f8[:, ::1], b1[::1], b1[::1])",
))
def inside_faces(row, u, v, vlo, vhi, inv_height, band_first, band_count, band_ptr, band_seg, segments,
                 inside, unsure):
    """Per point i on face table row ``row[i]`` (−1: an untrimmed face, inside): ``inside[i]`` by crossing parity,
    ``unsure[i]`` where a sign was not proven (module doc). ``segments`` (S, 4): a_u, a_v, b_u, b_v; the face's
    bands are band_first[f] … band_first[f] + band_count[f] − 1 of the CSR ``band_ptr`` / ``band_seg``."""
    for i in range(row.shape[0]):
        f = row[i]
        unsure[i] = False
        if f < 0:
            inside[i] = True
            continue
        pu, pv = u[i], v[i]
        if not (vlo[f] <= pv <= vhi[f]):  # also NaN: outside every loop, on none
            inside[i] = False
            continue
        b = band_first[f] + _band(pv, vlo[f], inv_height[f], band_count[f])
        odd = on = False
        for j in range(band_ptr[b], band_ptr[b + 1]):
            s = band_seg[j]
            au, av, bu, bv = segments[s, 0], segments[s, 1], segments[s, 2], segments[s, 3]
            if not (min(av, bv) <= pv <= max(av, bv)):
                continue
            up = av <= pv < bv
            down = bv <= pv < av
            ulo, uhi = min(au, bu), max(au, bu)
            if av == bv or au == bu:  # along u or v (a loop on the domain's edge): on it, or not, by comparisons
                if ulo <= pu <= uhi:  # (and v within the segment's, above): on the loop, which counts as inside
                    on = True
                    break
                if (up or down) and pu < ulo:
                    odd = not odd
                continue
            if pu < ulo or pu > uhi:  # off the segment's box: no sign needed
                if (up or down) and pu < ulo:
                    odd = not odd
                continue
            detleft = (au - pu) * (bv - pv)
            detright = (av - pv) * (bu - pu)
            det = detleft - detright
            bound = CCW_ERRBOUND * (abs(detleft) + abs(detright))
            if abs(det) <= bound or abs(detleft) + abs(detright) < UNDERFLOW:
                unsure[i] = True
                break
            if (up and det > 0.0) or (down and det < 0.0):
                odd = not odd
        inside[i] = odd or on
