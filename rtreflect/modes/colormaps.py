"""Colour maps of the map modes (curvature, draft): perceptually uniform maps from the `cmap` library.

`cmap` (pyapp-kit) ships the published maps as data, with no dependencies; we take Crameri's
scientific colour maps (Crameri, Shephard and Heron 2020, "The misuse of colour in science
communication"): perceptually uniform and readable by colour-blind viewers. The maps give sRGB
values; the film is linear, so they are decoded with colour-science's sRGB transfer function.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np

#: Signed quantities (K, H, κ1, κ2, draft): diverging, white at the middle of the range (zero).
DIVERGING = "crameri:vik"
#: Non-negative quantities (max |κ|, radius): sequential, dark to light.
SEQUENTIAL = "crameri:batlow"
#: Entries of the sampled map: finer than 8-bit output can show.
TABLE_SIZE = 1024


@functools.lru_cache(maxsize=8)
def _table(name: str) -> np.ndarray:
    """(TABLE_SIZE, 3) linear RGB of the named map at evenly spaced t in [0, 1]."""
    import cmap  # the map data; imported here so the reflection mode never loads it
    with warnings.catch_warnings():
        # colour-science warns at import about optional SciPy/Matplotlib features we do not use; imported here
        # (as cmap) so that start-up does not pay for it (tests/test_startup.py).
        warnings.simplefilter("ignore")
        import colour

    srgb = np.asarray(cmap.Colormap(name)(np.linspace(0.0, 1.0, TABLE_SIZE)), dtype=np.float64)[:, :3]
    return np.asarray(colour.cctf_decoding(srgb, function="sRGB"), dtype=np.float64)


def linear_rgb(name: str, t: np.ndarray) -> np.ndarray:
    """(N, 3) linear RGB of map ``name`` at t in [0, 1] (clipped; NaN gives NaN)."""
    t = np.asarray(t, dtype=np.float64)
    table = _table(name)
    index = np.round(np.clip(np.nan_to_num(t), 0.0, 1.0) * (TABLE_SIZE - 1)).astype(int)
    return np.where(np.isfinite(t)[:, None], table[index], np.nan)
