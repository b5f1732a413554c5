"""Reflection lines (Ulmet, sections 3–4): φ = Ulmet's f, the light-plane coordinate of the reflected ray.

φ(u, v) = f = e·(R + t s − Q) with t = m·(Q − R)/(m·s) (paper eq. 5–6, general form); the
levels are the tube positions c_k. A point lies in a stripe when its reflected ray passes
within the radius of a tube ahead (eq. 4), and is lit if the surface does not occlude that
ray before the tube (the renderer's Embree test along s up to `Stripes.occlusion_t`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .base import Mode, Stripes, SurfacePoints
from .circles import circle_mode
from .lights import TubeLights


@dataclass(frozen=True)
class ReflectionMode(Mode):
    lights: TubeLights
    name: str = "reflection"
    stage: str = "tubes (eq. 3, 4)"
    along_ray: ClassVar[bool] = True

    @property
    def levels(self) -> np.ndarray:
        """The tube positions c_k (`Stripes.level_id` indexes them)."""
        return self.lights.c_k

    def phi(self, p: SurfacePoints) -> np.ndarray:
        return self.lights.ulmet_f(p.R, p.s)

    def offset(self, p: SurfacePoints, level: np.ndarray) -> np.ndarray:
        """Signed skew-line distance of the reflected ray to tube ``level[i]`` (`base.level_offset`)."""
        return self.lights.signed_distance(p.R, p.s, level)

    def stripes(self, p: SurfacePoints) -> Stripes:
        tubes = self.lights.reach(p.R, p.s)
        return Stripes(tubes.line_id, tubes.line_dist, tubes.candidate, tubes.t_candidate, tubes.line_sigma,
                       tubes.line_t, phi=tubes.f)

    def surface_rgb(self, p: SurfacePoints) -> None:
        return None


def reflection_mode(scene, lights: TubeLights, surfaces):
    """Reflection lines of the scene's tubes, or of its circles (`circles.CircleMode`) with ``[lights] shape``."""
    if scene.lights.shape == "circles":
        return circle_mode(scene, lights, "reflection")
    return ReflectionMode(lights)
