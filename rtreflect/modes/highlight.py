"""Highlight lines (Beier and Chen 1994): where the surface's normal line meets a light tube; view-independent.

The normal line R + λn (λ of either sign) replaces the reflected ray of Ulmet's reflection
lines: φ = e·(R + λ n − Q) with λ = m·(Q − R)/(m·n), the light-plane coordinate where the
normal line crosses the plane (DESIGN.md, "Other interrogation modes"); the levels are the tube
positions c_k, and a point lies in the highlight band of tube k when the normal line passes
within the tube's radius (the skew-line distance of eq. 4 with s replaced by ±n). The normal
line is a construction, not light, so nothing occludes it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Mode, Stripes, SurfacePoints
from .circles import circle_mode
from .lights import TubeLights


@dataclass(frozen=True)
class HighlightMode(Mode):
    lights: TubeLights
    name: str = "highlight"
    stage: str = "highlight lines (normal line, eq. 4)"

    @property
    def levels(self) -> np.ndarray:
        """The tube positions c_k."""
        return self.lights.c_k

    @property
    def half_width(self) -> float:
        """A band's half width: the tube radius, in the skew-line distance of eq. (4)."""
        return self.lights.radius

    def phi(self, p: SurfacePoints) -> np.ndarray:
        return self.lights.normal_line_f(p.R, p.n)

    def offset(self, p: SurfacePoints, level: np.ndarray) -> np.ndarray:
        """Signed skew-line distance of the normal line to tube ``level[i]`` (`base.level_offset`; the same for ±n)."""
        return self.lights.signed_distance(p.R, p.n, level)

    def stripes(self, p: SurfacePoints) -> Stripes:
        # Both halves of the normal line: `reach` looks ahead only, so ask along n and along −n.
        front, back = self.lights.reach(p.R, p.n), self.lights.reach(p.R, -p.n)
        use_back = np.nan_to_num(back.line_dist, nan=np.inf) < np.nan_to_num(front.line_dist, nan=np.inf)
        level = np.where(use_back, back.line_id, front.line_id)
        dist = np.where(use_back, back.line_dist, front.line_dist)
        return Stripes(level, dist, front.candidate | back.candidate)

    def surface_rgb(self, p: SurfacePoints) -> None:
        return None


def highlight_mode(scene, lights: TubeLights, surfaces):
    """Highlight lines of the scene's tubes, or of its circles (`circles.CircleMode`) with ``[lights] shape``."""
    if scene.lights.shape == "circles":
        return circle_mode(scene, lights, "highlight")
    return HighlightMode(lights)
