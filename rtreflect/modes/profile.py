"""Stripe profile: how much of the line colour a sample shows at skew-line distance d from a tube's axis.

Paper eq. (4) draws a hard tube: a reflected ray passing within the radius r of a light
line sees it (weight 1), one passing farther does not (0). CAD zebra tools soften the
stripe's edge; ``blur`` b does it here from d alone, with no extra samples: the weight
falls from 1 at d = r(1 − b) to 0 at d = r(1 + b) along the smoothstep polynomial
x²(3 − 2x). The profile is symmetric about d = r, where the weight is ½, so the stripe's
width at half weight stays 2r whatever the blur, and the weight is C¹ in d (no visible
edge of its own). Every line-drawing mode weighs its samples by this one function.
"""

from __future__ import annotations

import numpy as np


def stripe_weight(dist: np.ndarray, radius: float, blur: float) -> np.ndarray:
    """Weight in [0, 1] of the line colour at distance ``dist`` (NaN: no line ahead, weight 0) from a tube of ``radius``.

    ``blur`` = 0: the hard tube of eq. (4), 1 where d ≤ r. Otherwise the smoothstep over
    [r(1 − blur), r(1 + blur)] (module doc).

    >>> stripe_weight(np.array([0.0, 0.05, 0.1, 0.2, np.nan]), 0.1, 0.5).round(6).tolist()
    [1.0, 1.0, 0.5, 0.0, 0.0]
    """
    dist = np.asarray(dist, dtype=np.float64)
    if blur == 0:
        with np.errstate(invalid="ignore"):
            return (dist <= radius).astype(np.float64)
    x = np.clip((radius * (1.0 + blur) - np.nan_to_num(dist, nan=np.inf)) / (2.0 * radius * blur), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def stripe_reach(radius: float, blur: float) -> float:
    """The largest distance d with a non-zero weight: the radius the occlusion test must serve (r(1 + blur))."""
    return radius * (1.0 + blur)
