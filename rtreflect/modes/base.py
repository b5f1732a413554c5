"""Interrogation modes: a scalar field φ on the surface, its levels, and the distance to the nearest level.

Every line-drawing tool of the paper's section 1 is the level sets φ(u, v) = c_k of a scalar
field, shaded by a stripe around each level (DESIGN.md, "Other interrogation modes"). A mode
computes φ from the exact hit (R, unit normal n, reflected direction s of eq. 3), and per
point the nearest level ahead, the distance to it (in φ's unit, or the skew-line distance of
eq. 4 for tubes) and whether the point lies in its stripe. A mode whose stripes are seen
along a physical ray (reflection lines) also names the ray's reach, which the renderer tests
for self-occlusion; the others are lit where the distance says so.

`registry.MODES` maps each ``[render] mode`` name to the function that builds it for a scene.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Stripes:
    """Per point: the nearest level, the distance to it, and whether the point lies in its stripe."""

    level_id: np.ndarray  # index of the nearest level (ahead, for tubes); −1 where none is
    level_dist: np.ndarray  # distance to it: skew-line distance d for tubes, |φ − c_k| otherwise; NaN where none is
    candidate: np.ndarray  # bool: within the stripe
    # Ray parameter along s to test for occlusion before a candidate counts as lit (reflection lines:
    # the nearest tube within its radius); None when the mode's stripes are not seen along a ray.
    occlusion_t: np.ndarray | None = None


class Mode(Protocol):
    """What the renderer, the EXR and the contours need of an interrogation mode."""

    name: str
    #: Stage name under which the renderer's clock counts the mode's time.
    stage: str

    def phi(self, R: np.ndarray, n: np.ndarray, s: np.ndarray) -> np.ndarray:
        """φ at points R with unit normals n and reflected directions s (NaN where undefined)."""

    def stripes(self, R: np.ndarray, n: np.ndarray, s: np.ndarray) -> Stripes:
        """The nearest level and the stripe test at each point."""

