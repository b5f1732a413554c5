"""Draft analysis: the angle between the surface normal and the mould's pull direction, in bands.

φ = angle(n, d) in degrees (0° where n ∥ d), n as written to the EXR (facing the camera), d
the unit pull direction ``[render] pull``. The draft angle is δ = 90° − φ: the angle between
the surface and the pull direction, positive where the face opens towards d. A cone of
half-angle α about d has φ = 90° − α (δ = α) everywhere. The ``thresholds`` t_1 < … < t_m
(draft angles) cut the surface into bands coloured from a sequential map (`BANDS_MAP`), δ < 0 (undercut:
the face hides from the pull direction and locks the part in the mould) flagged in
`UNDERCUT_RGB`; the band edges are the levels φ = 90° − t_k, drawn as lines `EDGE_WIDTH`
degrees of φ wide.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import Mode, SurfacePoints
from .colormaps import linear_rgb
from .isophote import angle_to
from .lights import TubeLights
from .regions import FaceRegions

#: The bands' map: Crameri's oslo, sequential black-blue-white with no red in it, so the undercut flag stands out.
BANDS_MAP = "crameri:oslo"
#: Part of the map the bands use: from 0.3 up, so the least-draft band is not lost on a black background.
BANDS_FROM = 0.3
#: Undercut flag colour (linear RGB): saturated red, a hue the bands' map never takes.
UNDERCUT_RGB = np.array([0.8, 0.0, 0.0])
#: Width of the lines at the band edges, degrees of φ: thin against the usual 1°–3° thresholds.
EDGE_WIDTH = 0.1
#: Draft angles this close to a threshold (or to 0°) are on it, degrees: a face drafted exactly at a threshold (a 0°
#: wall, a 1° wall) has δ = t ± rounding (1e-14° on the sweep's huge_inch.step), and its samples fell on either side:
#: a wall speckled red and band colour (4 colour mismatches at 160×90). Far below any drafting tolerance (0.01°).
ON_THRESHOLD = 1e-9


@dataclass(frozen=True)
class DraftMode(FaceRegions, Mode):
    surfaces: object  # SurfaceSet
    pull: np.ndarray
    thresholds: tuple
    name: str = "draft"
    stage: str = "draft angles"

    @property
    def levels(self) -> np.ndarray:
        """φ at the band edges, ascending: 90° − t_k."""
        return np.sort(90.0 - np.asarray(self.thresholds, dtype=np.float64))

    @property
    def half_width(self) -> float:
        """Half a band edge's width in φ (degrees)."""
        return 0.5 * EDGE_WIDTH

    def phi(self, p: SurfacePoints) -> np.ndarray:
        return angle_to(p.n, self.pull)

    def band(self, draft: np.ndarray) -> np.ndarray:
        """Band index of draft angles δ: 0 below t_1, …, m at or above t_m."""
        return np.searchsorted(np.asarray(self.thresholds), draft, side="right")

    def surface_rgb(self, p: SurfacePoints) -> np.ndarray:
        return self.colors(90.0 - self.phi(p))

    def colors(self, draft: np.ndarray) -> np.ndarray:
        """Linear RGB of draft angles δ (degrees): their band's colour, `UNDERCUT_RGB` where δ < 0; δ within
        `ON_THRESHOLD` of a threshold or of 0° is on it (the band above it, no undercut)."""
        draft = np.asarray(draft, dtype=np.float64)
        for t in (0.0, *self.thresholds):
            draft = np.where(np.abs(draft - t) <= ON_THRESHOLD, t, draft)
        bands = len(self.thresholds) + 1
        # Darker for less draft, lighter for more.
        rgb = linear_rgb(BANDS_MAP, BANDS_FROM + (1.0 - BANDS_FROM) * (self.band(draft) + 0.5) / bands)
        return np.where((draft < 0)[:, None], UNDERCUT_RGB, rgb)


def draft_mode(scene, lights: TubeLights, surfaces) -> DraftMode:
    return DraftMode(surfaces, np.asarray(scene.render.pull, dtype=np.float64), tuple(scene.render.thresholds))
