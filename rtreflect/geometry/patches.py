"""What a NURBS patch's numbers must be for it to render, whichever reader made it.

One home for the rules (the TOML scene reader, `.bpt` files and CAD readers apply the same), as
`knots.py` is for knot vectors: coordinates finite and within float32 tracing's range, and an
area to reflect in.
"""

from __future__ import annotations

import numpy as np

from .surfaces import NurbsSurface

#: Largest magnitude of any number in a scene. Embree intersects in float32 and forms
#: products of up to three coordinates (a triangle's plane offset); beyond this they
#: overflow float32's 3.4e38 and the image turns to noise without any error.
MAX_MAGNITUDE = 1e12

ZERO_AREA = "the control points lie on a point or a line: the patch has zero area"


def has_area(surface: NurbsSurface) -> bool:
    """False when the control points all lie on a point or a line: no area to reflect in."""
    pts = surface.points.reshape(-1, 3)
    centred = pts - pts.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    return bool(sv[1] > 1e-12 * max(sv[0], 1e-300))


def patch_problem(surface: NurbsSurface) -> str | None:
    """Why ``surface`` cannot render (a phrase for a user; the caller names the file and field), or None."""
    if not np.all(np.isfinite(surface.points)):
        return "coordinates must be finite"
    largest = float(np.max(np.abs(surface.points)))
    if largest > MAX_MAGNITUDE:
        return (f"coordinates must be at most {MAX_MAGNITUDE:g} in magnitude (float32 tracing overflows beyond it), "
                f"got {largest:g}")
    if not has_area(surface):
        return ZERO_AREA
    return None
