"""Zebra stripes: the environment-mapped stripes of CAD tools (paper section 3.2), a function of s alone.

φ = ψ, the angle in degrees of the reflected direction s about the stripe axis c (the tubes'
direction, ``[lights] direction``), measured from the light plane's normal m towards e:
ψ = atan2(s·e, s·m) in (−180°, 180°]. The levels are every ``step`` degrees, stripes
`base.STRIPE_SHARE` of a step wide. Only the direction of s enters, not the point R: the stripes
are those of tubes infinitely far away (no eye or surface parallax), which is what makes zebra
cheap and view-stable, and what sets it apart from Ulmet's reflection lines of tubes at a finite
distance (φ = f depends on R too). Nothing occludes an environment map's stripes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .base import STRIPE_SHARE, Mode, Stripes, SurfacePoints, even_stripes
from .lights import TubeLights


@dataclass(frozen=True)
class ZebraMode(Mode):
    m: np.ndarray  # ψ = 0 direction: the light plane's normal
    e: np.ndarray  # ψ = 90°: across the tubes
    step: float
    name: str = "zebra"
    stage: str = "zebra (reflected direction)"
    period: ClassVar[float] = 360.0  # ψ wraps at ±180°

    @property
    def levels(self) -> np.ndarray:
        k = np.arange(-np.floor(180.0 / self.step), np.floor(180.0 / self.step) + 1)
        return k * self.step

    @property
    def half_width(self) -> float:
        """Half a stripe's width in φ (degrees)."""
        return 0.5 * STRIPE_SHARE * self.step

    def phi(self, p: SurfacePoints) -> np.ndarray:
        return np.degrees(np.arctan2(p.s @ self.e, p.s @ self.m))

    def stripes(self, p: SurfacePoints) -> Stripes:
        return even_stripes(self.phi(p), self.levels, self.half_width)

    def surface_rgb(self, p: SurfacePoints) -> None:
        return None


def zebra_mode(scene, lights: TubeLights, surfaces) -> ZebraMode:
    return ZebraMode(np.asarray(lights.m, dtype=np.float64), np.asarray(lights.e, dtype=np.float64),
                     float(scene.render.step))
