"""Regions of a map: faces on which φ is constant, so a level there is an area, not a line.

A map's iso-lines (curvature bands, draft thresholds, isophotes) are the level sets φ = c_k, drawn as stripes
|φ − c_k| ≤ w. On a face where φ is constant (K = 0 on planes, cylinders and cones; draft 0° on a
wall or a vertical cylinder; H = 1/2r on a cylinder) the level set of a level at that value is the
whole face: its stripe would paint the face in the line colour and hide the map's colour, which is
what the designer asked to see (the filleted block's Gaussian map came out all white, a mould's
0° walls in the line colour instead of their band's, and with the light straight down its isophotes
0° and 90° painted the top and every wall white, the fillets' lines the only ones left). So a map
(or the isophotes) draws no line on such a face: it shows the map's colour (the shading) there, the
renderer's stripes (`base.even_stripes`) and the analytic contours (`analysis.contours`) alike, and
`validate` compares nothing there.

A face is constant where φ, sampled on a grid over its whole domain (the centres of `CONSTANT_GRID` cells a
side and every knot span's midpoint, at most `CONSTANT_MAX_SIDE` a side: interior points, as a pole on a
domain edge leaves the curvatures there to rounding), seen from each side in turn (its own normals, then turned:
κ1 and κ2 trade places with the normal's sign), varies by
at most `CONSTANT_SHARE` of a line's half width: its whole visible part lies within a stripe then,
or outside every one, never crossed by a level with room for a line.

A region can also lie inside a face: on a ruled face K = 0, one principal curvature is 0 all over and κ1 is exactly
that 0 wherever the other is negative (the sweep's kink.step, bspline_prism.step). Where the mode has a rounding floor
(`region_floor`: an "auto" curvature range's), a point whose φ lies within it of a level is in a region, wherever
it lies: no stripe there (`base.even_stripes`), and its edge, where φ leaves the level without crossing it, is no
line `validate` traces. A level crossed transversally loses a band floor/|∇φ| wide, far below a pixel.
"""

from __future__ import annotations

from functools import cached_property
from typing import Callable

import numpy as np

from .base import Stripes, SurfacePoints, even_stripes

#: Cells per side of each face's domain whose centres are sampled. Not its edges: on a sphere's collapsed side
#: (a pole) the fundamental forms degenerate and K came out anywhere from −5e14 to 3e16 for 1/r² = 0.0625.
CONSTANT_GRID = 8
#: With the knot spans' midpoints the side's samples are thinned to at most this many (evenly by index).
CONSTANT_MAX_SIDE = 33
#: Largest variation of φ over a face, in line half widths, for it to count as constant: a thousandth of a line's
#: width, far above the rounding of a constant φ (K on a plane ~1e-32 of 1/size², a draft angle ~1e-14°).
CONSTANT_SHARE = 1e-3
#: Sample points evaluated at once (bounds memory on models of thousands of faces).
CHUNK = 1 << 16


def _side(lo: float, hi: float, breaks: np.ndarray) -> np.ndarray:
    """One side's sample parameters: the grid's cell centres over [lo, hi] and the spans' midpoints, thinned to the
    cap."""
    centres = lo + (hi - lo) * (np.arange(CONSTANT_GRID) + 0.5) / CONSTANT_GRID
    values = np.union1d(centres, 0.5 * (breaks[1:] + breaks[:-1]))
    if len(values) > CONSTANT_MAX_SIDE:
        values = values[np.round(np.linspace(0, len(values) - 1, CONSTANT_MAX_SIDE)).astype(int)]
    return values


def constant_faces(surfaces, phi: Callable[[SurfacePoints], np.ndarray], half_width: float,
                   floor: float = 0.0) -> np.ndarray:
    """Per face of a `SurfaceSet`, (P, 2): True where φ (``phi`` of `SurfacePoints`) is constant over it (module doc),
    seen from the side its own normal points to (column 0) and from the other (column 1): varies by at most
    `CONSTANT_SHARE` of ``half_width``, or by at most ``floor`` (the map's rounding of a φ that is 0).

    The sides differ where φ depends on the normal's sign beyond a sign of its own: κ2 on a torus is its tube's
    curvature −1/r all over seen from outside, and −κ1 seen from inside (OCCT's data/step/trj4_k1_geo-tc-214.stp, a
    key's ring whose own normals point inside, seen from outside: κ2 ≡ −0.3937 lay on a level and the face was
    taken for one whose κ2 varies).
    Points where φ is NaN (a degenerate normal at a pole) are passed over; a face with none left is not constant.
    """
    patch, u, v = [], [], []
    for k, surface in enumerate(surfaces.patches):
        (u0, u1), (v0, v1) = surface.domain
        breaks_u, breaks_v = surface.span_breaks()
        uu, vv = np.meshgrid(_side(u0, u1, breaks_u), _side(v0, v1, breaks_v), indexing="ij")
        patch.append(np.full(uu.size, k))
        u.append(uu.ravel())
        v.append(vv.ravel())
    faces = len(surfaces.patches)
    lo, hi = np.full((2, faces), np.inf), np.full((2, faces), -np.inf)
    count = np.zeros((2, faces), dtype=np.int64)
    if faces == 0:
        return np.zeros((0, 2), dtype=bool)
    patch, u, v = np.concatenate(patch), np.concatenate(u), np.concatenate(v)
    for start in range(0, len(patch), CHUNK):
        rows = slice(start, start + CHUNK)
        pk, pu, pv = patch[rows], u[rows], v[rows]
        derivs = surfaces.evaluate(pk, pu, pv)
        n = surfaces.normals(pk, pu, pv, derivs)
        for side, normal in enumerate((n, -n)):
            values = phi(SurfacePoints(derivs.S, normal, np.zeros_like(n), pk, pu, pv))
            known = ~np.isnan(values)
            np.minimum.at(lo[side], pk[known], values[known])
            np.maximum.at(hi[side], pk[known], values[known])
            count[side] += np.bincount(pk[known], minlength=faces)
    with np.errstate(invalid="ignore"):  # inf − inf: a radius of curvature infinite all over (a plane), lo == hi
        return ((count > 0) & ((hi == lo) | (hi - lo <= max(CONSTANT_SHARE * half_width, floor)))).T


class FaceRegions:
    """A level-set mode's faces where φ is constant and their stripes (module doc): mixed into a mode dataclass with
    ``surfaces`` (its `SurfaceSet`), ``phi``, ``levels`` and ``half_width``. ``region_floor`` is the variation below
    which φ counts as constant whatever the half width (a map's rounding floor; 0 here)."""

    @property
    def region_floor(self) -> float:
        return 0.0

    @cached_property
    def constant_sides(self) -> np.ndarray:
        """Per face (P, 2): φ constant over it seen from its own normal's side, from the other (`constant_faces`): a
        region where no line is drawn (a plane in a Gaussian map or facing the isophotes' light, a 0° wall in a draft
        map, a torus's tube curvature in a κ2 map seen from outside)."""
        if len(self.levels) == 0:
            return np.zeros((len(self.surfaces.patches), 2), dtype=bool)
        return constant_faces(self.surfaces, self.phi, self.half_width, self.region_floor)

    @cached_property
    def constant_faces(self) -> np.ndarray:
        """Per face: φ constant over it from both sides (a region wherever it is seen). The analytic contours skip
        these faces; on a face constant from the side seen only, φ on their grid is that constant, and no level
        crosses it (within Newton's tolerance of a level it is snapped onto it, `contours._snapped`: no crossing)."""
        return self.constant_sides.all(axis=1)

    def lined_at(self, p: SurfacePoints) -> np.ndarray:
        """Per point: its face draws lines where it is seen from (not a region: `constant_sides`, the side its
        facing normal ``p.n`` is on)."""
        sides = self.constant_sides[p.patch]
        constant = sides[:, 0].copy()
        one = np.flatnonzero(sides[:, 0] != sides[:, 1])  # a face constant from one side only: which side is seen
        if len(one):
            own = self.surfaces.normals(p.patch[one], p.u[one], p.v[one])
            constant[one] = np.where(np.einsum("ij,ij->i", own, p.n[one]) >= 0, sides[one, 0], sides[one, 1])
        return ~constant

    def stripes(self, p: SurfacePoints) -> Stripes:
        return even_stripes(self.phi(p), self.levels, self.half_width, self.lined_at(p), self.region_floor)
