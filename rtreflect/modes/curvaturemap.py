"""Curvature maps: K, H, κ1, κ2, max |κ| or the smallest radius of curvature, through a colour map.

φ is the ``[render] quantity`` at the exact hit, from the fundamental forms
(geometry/curvature.py; signed with the normal as written to the EXR, which faces the camera),
in 1/model unit (K in 1/model unit², radius in model units). The colour is the map
(`colormaps`) over ``range``: fixed [min, max], or "auto": `AUTO_PERCENTILE` of |φ| over every
patch sampled on an `AUTO_GRID` parameter grid, symmetric about 0 for signed quantities, so
values beyond it clip to the end colours (the percentage clipped is what `auto_range` reports).
With ``bands`` = b > 0, iso-curvature lines split the range into b equal bands (levels at the
b − 1 inner edges), `base.STRIPE_SHARE` of a band wide.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..geometry.curvature import curvatures
from ..geometry.seams import part_size
from .base import STRIPE_SHARE, Mode, SurfacePoints
from .colormaps import DIVERGING, SEQUENTIAL, linear_rgb
from .lights import TubeLights
from .regions import FaceRegions

#: "auto" range: the 98th percentile of |φ| (2 % of the sampled surface clips), so a few extreme
#: points (near a pole or a sharp fillet) do not wash out the map of the rest.
AUTO_PERCENTILE = 98.0
#: Parameter grid per patch for the "auto" range: 64 × 64 samples see every span of usual patches.
AUTO_GRID = 64
#: Units of each quantity, for the legend.
UNITS = {"gaussian": "1/unit²", "mean": "1/unit", "k1": "1/unit", "k2": "1/unit", "maxabs": "1/unit",
         "radius": "unit"}
SIGNED = ("gaussian", "mean", "k1", "k2")
#: An "auto" range is never narrower than this many of the quantity's natural unit (1/size, 1/size² for K, size for
#: the radius; size the part's bounding-box diagonal): below it the sampled values are the rounding of a quantity
#: that is 0 (as continuity's FLAT_CURVATURE). The sweep's kink.step, K = 0 exactly (z = f(x) + g(y), f piecewise
#: linear): its auto range was ±9e-17 and the map drew the rounding of K as full-range colour bands and lines.
FLAT_RANGE = 1e-8
#: Nor is the range of ``maxabs`` or ``radius`` narrower than this share of its middle value: κ1,2 = H ± √(H² − K) round
#: to about √ε·|H| where the surface is umbilic (H² − K, 0 on a sphere, rounds to ~ε·H², and its root to ~1.5e-8·|H|).
#: The sweep's sphere.3dm (r = 15): max |κ| over the 64 × 64 grid spread over [1/15, 1/15 + 1.3e-9] (2e-8 of the
#: value), the map drew that rounding as its whole range, and validate counted 398 colour mismatches at 160×90.
#: 50× the measured spread: a field constant to a millionth is shown as constant.
UMBILIC_RANGE = 1e-6


def quantity_of(name: str, derivs, n: np.ndarray) -> np.ndarray:
    """The curvature quantity ``name`` at points with `SurfaceDerivatives` of order 2 and unit normals n."""
    c = curvatures(derivs, n)
    if name == "gaussian":
        return c.K
    if name == "mean":
        return c.H
    if name in ("k1", "k2"):
        return getattr(c, name)
    largest = np.maximum(np.abs(c.k1), np.abs(c.k2))
    if name == "maxabs":
        return largest
    with np.errstate(divide="ignore"):
        return 1.0 / largest  # radius: inf where flat


def flat_floor(name: str, surfaces) -> float:
    """`FLAT_RANGE` of quantity ``name``'s natural unit on these surfaces (1/size, 1/size² for K, size for the radius;
    size the part's bounding-box diagonal): variations below it are rounding."""
    size = part_size(list(surfaces.patches))
    return FLAT_RANGE * (size if name == "radius" else size ** -2.0 if name == "gaussian" else 1.0 / size)


def auto_range(name: str, surfaces) -> tuple[float, float, float]:
    """(min, max, share clipped) of the "auto" range of quantity ``name`` over the patches (module doc)."""
    t = (np.arange(AUTO_GRID) + 0.5) / AUTO_GRID
    values = []
    for k, patch in enumerate(surfaces.patches):
        (u0, u1), (v0, v1) = patch.domain
        u, v = np.meshgrid(u0 + t * (u1 - u0), v0 + t * (v1 - v0), indexing="ij")
        u, v = u.ravel(), v.ravel()
        derivs = patch.evaluate(u, v, order=2)
        values.append(quantity_of(name, derivs, patch.normals(u, v, derivs)))
    q = np.concatenate(values)
    q = q[np.isfinite(q)]
    if len(q) == 0:
        return (-1.0, 1.0, 0.0)
    floor = flat_floor(name, surfaces)
    if name in SIGNED:
        top = max(float(np.percentile(np.abs(q), AUTO_PERCENTILE)), floor)
        low, high = -top, top
    else:
        low, high = float(np.percentile(q, 100.0 - AUTO_PERCENTILE)), float(np.percentile(q, AUTO_PERCENTILE))
        middle = 0.5 * (low + high)
        floor = max(floor, UMBILIC_RANGE * abs(middle))
        if high - low < floor:  # a constant field (to rounding): a range around its value, so the map is defined
            pad = max(abs(middle), floor)
            low, high = middle - pad, middle + pad
    clipped = float(np.mean((q < low) | (q > high)))
    return (low, high, clipped)


@dataclass(frozen=True)
class CurvatureMode(FaceRegions, Mode):
    surfaces: object  # SurfaceSet
    quantity: str
    low: float
    high: float
    bands: int
    clipped: float | None  # share of the sampled surface outside an "auto" range; None for a fixed range
    name: str = "curvature"
    stage: str = "curvature (fundamental forms)"

    @property
    def colormap(self) -> str:
        return DIVERGING if self.quantity in SIGNED else SEQUENTIAL

    @property
    def units(self) -> str:
        return UNITS[self.quantity]

    @property
    def levels(self) -> np.ndarray:
        """Iso-curvature levels: the inner edges of ``bands`` equal bands over the range (none without bands)."""
        if self.bands < 2:
            return np.zeros(0)
        return self.low + (self.high - self.low) * np.arange(1, self.bands) / self.bands

    @property
    def half_width(self) -> float:
        """Half an iso-curvature line's width in φ: `STRIPE_SHARE` of a band."""
        return 0.5 * STRIPE_SHARE * (self.high - self.low) / max(self.bands, 1)

    def phi(self, p: SurfacePoints) -> np.ndarray:
        derivs = self.surfaces.evaluate(p.patch, p.u, p.v, order=2)
        return quantity_of(self.quantity, derivs, p.n)

    @cached_property
    def region_floor(self) -> float:
        """At least the rounding floor of an "auto" range (`regions.FaceRegions`): a part whose K is 0 to rounding
        everywhere (the sweep's kink.step: ±9e-17 against a floor of 1.4e-12) has a map range at that floor, and its
        noise is no line. (An "auto" range's floor only: a range the user fixed below it asks for its variations.)"""
        return flat_floor(self.quantity, self.surfaces) if self.clipped is not None else 0.0

    def surface_rgb(self, p: SurfacePoints) -> np.ndarray:
        """The map's colour of φ at the points. A φ within `region_floor` of 0 is 0 (rounding): on a signed map 0 lies
        half-way between two table entries, and the rounding's sign picked one or the other, a blotch across
        kink.step's κ1 = 0 region (R 0.832 or 0.841). (The legend's ramp, `colors` alone, keeps every entry.)"""
        phi, floor = self.phi(p), self.region_floor
        return self.colors(np.where(np.abs(phi) <= floor, 0.0, phi) if floor > 0.0 else phi)

    def colors(self, phi: np.ndarray) -> np.ndarray:
        """Linear RGB of values φ on the map over [low, high] (clipped to the end colours)."""
        t = (np.clip(np.where(np.isposinf(phi), self.high, phi), self.low, self.high) - self.low) / (self.high - self.low)
        return linear_rgb(self.colormap, t)


def curvature_mode(scene, lights: TubeLights, surfaces) -> CurvatureMode:
    settings = scene.render
    if settings.range == "auto":
        low, high, clipped = auto_range(settings.quantity, surfaces)
    else:
        (low, high), clipped = settings.range, None
    return CurvatureMode(surfaces, settings.quantity, float(low), float(high), int(settings.bands), clipped)
