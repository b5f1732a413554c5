"""Circular reflection and highlight lines (Maekawa et al.): concentric circles of light in the light plane.

φ = |X − C|, the distance from the centre C (``[lights] centre``, on the plane; Q by default)
to the point X where the ray meets the light plane: the reflected ray R + t s (t > 0, the
plane's t of the tubes, paper eq. 5–6) for reflection lines, the normal line R + λ n (λ of
either sign, Beier and Chen's construction) for highlight lines. The levels are the radii r_k
(``[lights] positions``, or ``spacing``·1, …, ``spacing``·``count``). A point lies in the stripe
of circle k where X lies within the light's ``radius`` of it in the plane, |φ − r_k| ≤ radius
(a flat ring, not the torus of a tube bent round: the light is the plane's ring). Reflection
lines are lit where the reflected ray reaches the plane unblocked; the normal line is a
construction, and nothing occludes it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Mode, Stripes, SurfacePoints, even_stripes
from .lights import TubeLights


@dataclass(frozen=True)
class CircleMode(Mode):
    lights: TubeLights  # the light plane (Q, m), the radii as c_k and the ring's half width as radius
    centre: np.ndarray  # C
    name: str  # "reflection" (along s) or "highlight" (along the normal line)
    stage: str = "circles (light plane)"

    @property
    def along_ray(self) -> bool:
        """Seen along the reflected ray (reflection lines), so occluded by the surface on the way."""
        return self.name == "reflection"

    @property
    def levels(self) -> np.ndarray:
        return np.sort(self.lights.c_k)

    @property
    def half_width(self) -> float:
        return self.lights.radius

    def plane_point(self, p: SurfacePoints) -> tuple[np.ndarray, np.ndarray]:
        """X, where the mode's ray meets the light plane, and its ray parameter (NaN where it does not)."""
        ray = p.s if self.along_ray else p.n
        t = self.lights.plane_t(p.R, ray)
        meets = np.isfinite(t) & ((t > 0) if self.along_ray else True)
        t = np.where(meets, t, np.nan)
        return p.R + t[:, None] * ray, t

    def phi(self, p: SurfacePoints) -> np.ndarray:
        X, _ = self.plane_point(p)
        return np.linalg.norm(X - self.centre, axis=1)

    def stripes(self, p: SurfacePoints) -> Stripes:
        X, t = self.plane_point(p)
        found = even_stripes(np.linalg.norm(X - self.centre, axis=1), self.levels, self.half_width)
        if not self.along_ray:
            return found
        # Along the reflected ray the occlusion test runs to where it meets the light plane.
        return Stripes(found.level_id, found.level_dist, found.candidate, np.where(found.candidate, t, np.inf),
                       found.offset, t)

    def surface_rgb(self, p: SurfacePoints) -> None:
        return None


def circle_mode(scene, lights: TubeLights, name: str) -> CircleMode:
    """The circles of ``scene.lights`` seen by mode ``name`` (reflection or highlight)."""
    return CircleMode(lights, np.asarray(scene.lights.centre, dtype=np.float64), name)
