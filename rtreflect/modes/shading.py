"""Surface shading under the stripes: the part's form readable at a glance (issue 13).

``lambert``: a headlight, Lambert's cosine law with the light at the eye, plus an ambient
floor, k = a + (1 − a)|N·D| for the unit normal N and the ray direction D, scaling
``surface_color``. Faces turned to the viewer keep the surface colour, flanks darken towards
a·surface_color at the silhouette. The stripes are not shaded: a sample on a tube shows
``line_color`` (weighted by `profile.stripe_weight`), so the lines stay exact and dominant.
``flat``: k = 1, the surface colour everywhere (the picture before shading existed).
"""

from __future__ import annotations

import numpy as np

#: Ambient share a of the Lambert term: at 0.5 the darkest flank keeps half the surface colour, so a dark
#: surface never reaches the background and the shading stays a hint under the stripes, not a rendering.
LAMBERT_AMBIENT = 0.5


def shade_factor(N: np.ndarray, D: np.ndarray, shading: str) -> np.ndarray:
    """Per ray the factor k scaling ``surface_color``: a + (1 − a)|N·D| for ``"lambert"``, 1 for ``"flat"`` (module doc)."""
    if shading == "flat":
        return np.ones(len(N))
    return LAMBERT_AMBIENT + (1.0 - LAMBERT_AMBIENT) * np.abs(np.einsum("ij,ij->i", N, D))
