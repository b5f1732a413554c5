"""Reflection lines (Ulmet, sections 3–4): φ = Ulmet's f, the light-plane coordinate of the reflected ray.

φ(u, v) = f = e·(R + t s − Q) with t = m·(Q − R)/(m·s) (paper eq. 5–6, general form); the
levels are the tube positions c_k. A point lies in a stripe when its reflected ray passes
within the radius of a tube ahead (eq. 4), and is lit if the surface does not occlude that
ray before the tube (the renderer's Embree test along s up to `Stripes.occlusion_t`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Stripes
from .lights import TubeLights


@dataclass(frozen=True)
class ReflectionMode:
    lights: TubeLights
    name: str = "reflection"
    stage: str = "tubes (eq. 3, 4)"

    def phi(self, R: np.ndarray, n: np.ndarray, s: np.ndarray) -> np.ndarray:
        return self.lights.ulmet_f(R, s)

    def stripes(self, R: np.ndarray, n: np.ndarray, s: np.ndarray) -> Stripes:
        tubes = self.lights.reach(R, s)
        return Stripes(tubes.line_id, tubes.line_dist, tubes.candidate, tubes.t_candidate)


def reflection_mode(scene, lights: TubeLights) -> ReflectionMode:
    return ReflectionMode(lights)
