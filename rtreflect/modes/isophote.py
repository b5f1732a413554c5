"""Isophotes (Poeschl 1984): curves of constant angle between the surface normal and a light direction.

φ = angle(n, L) in degrees, 0° where n ∥ L (DESIGN.md, "Other interrogation modes"), with
levels every ``step`` degrees from 0° to 180° and stripes `base.STRIPE_SHARE` of a step wide.
n is the normal as written to the EXR (facing the camera). Isophotes inherit one order of
continuity less than the surface: a G1 join with a curvature jump kinks them. L is
``[render] light``, or the light plane's normal m when not given. On a face where φ is constant (a
plane, or a cylinder or cone about L) a level is an area, not a line: none is drawn there (`regions`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import STRIPE_SHARE, Mode, SurfacePoints
from .lights import TubeLights
from .regions import FaceRegions


def angle_to(n: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Angle in degrees between unit vectors n (N, 3) and one unit direction: arccos(n·d), clipped to [0°, 180°]."""
    return np.degrees(np.arccos(np.clip(n @ direction, -1.0, 1.0)))


@dataclass(frozen=True)
class IsophoteMode(FaceRegions, Mode):
    surfaces: object  # SurfaceSet
    L: np.ndarray
    step: float
    name: str = "isophote"
    stage: str = "isophotes"

    @property
    def levels(self) -> np.ndarray:
        return np.arange(0.0, 180.0 + 0.5 * self.step, self.step)

    @property
    def half_width(self) -> float:
        """Half a stripe's width in φ (degrees)."""
        return 0.5 * STRIPE_SHARE * self.step

    def phi(self, p: SurfacePoints) -> np.ndarray:
        return angle_to(p.n, self.L)

    def surface_rgb(self, p: SurfacePoints) -> None:
        return None


def isophote_mode(scene, lights: TubeLights, surfaces) -> IsophoteMode:
    L = scene.render.light if scene.render.light is not None else lights.m
    return IsophoteMode(surfaces, np.asarray(L, dtype=np.float64), float(scene.render.step))
