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
domain edge leaves the curvatures there to rounding) with its own normals, varies by
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
    """Per face of a `SurfaceSet`: True where φ (``phi`` of `SurfacePoints`) is constant over it (module doc): varies
    by at most `CONSTANT_SHARE` of ``half_width``, or by at most ``floor`` (the map's rounding of a φ that is 0).

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
    lo, hi = np.full(faces, np.inf), np.full(faces, -np.inf)
    count = np.zeros(faces, dtype=np.int64)
    if faces == 0:
        return np.zeros(0, dtype=bool)
    patch, u, v = np.concatenate(patch), np.concatenate(u), np.concatenate(v)
    for start in range(0, len(patch), CHUNK):
        rows = slice(start, start + CHUNK)
        pk, pu, pv = patch[rows], u[rows], v[rows]
        derivs = surfaces.evaluate(pk, pu, pv)
        n = surfaces.normals(pk, pu, pv, derivs)
        values = phi(SurfacePoints(derivs.S, n, np.zeros_like(n), pk, pu, pv))
        known = ~np.isnan(values)
        np.minimum.at(lo, pk[known], values[known])
        np.maximum.at(hi, pk[known], values[known])
        count += np.bincount(pk[known], minlength=faces)
    with np.errstate(invalid="ignore"):  # inf − inf: a radius of curvature infinite all over (a plane), lo == hi
        return (count > 0) & ((hi == lo) | (hi - lo <= max(CONSTANT_SHARE * half_width, floor)))


class FaceRegions:
    """A level-set mode's faces where φ is constant and their stripes (module doc): mixed into a mode dataclass with
    ``surfaces`` (its `SurfaceSet`), ``phi``, ``levels`` and ``half_width``. ``region_floor`` is the variation below
    which φ counts as constant whatever the half width (a map's rounding floor; 0 here)."""

    @property
    def region_floor(self) -> float:
        return 0.0

    @cached_property
    def constant_faces(self) -> np.ndarray:
        """Per face: φ constant over it, a region where no line is drawn (a plane in a Gaussian map or facing the
        isophotes' light, a 0° wall in a draft map)."""
        if len(self.levels) == 0:
            return np.zeros(len(self.surfaces.patches), dtype=bool)
        return constant_faces(self.surfaces, self.phi, self.half_width, self.region_floor)

    def stripes(self, p: SurfacePoints) -> Stripes:
        return even_stripes(self.phi(p), self.levels, self.half_width, ~self.constant_faces[p.patch], self.region_floor)
