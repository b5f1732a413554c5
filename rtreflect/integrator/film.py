"""Film: the supersampled colour image and the per-pixel AOVs (DESIGN.md, "EXR channels").

``R G B A`` come from the s×s samples of each pixel: a sample that hits shows
``line_color`` with its stripe weight w (1 or 0 for the hard tube, `modes.profile`)
over the surface colour scaled by its shading factor k (`modes.shading`), i.e.
w·line_color + (1 − w)·k·surface_color; a sample that hits nothing shows ``background``.
The pixel is their mean (so with a black background RGB is premultiplied by A). With
``samples = "analytic"`` a pixel is its centre sample alone, w the stripe's covered share of the
pixel (`analytic`). The AOVs come from the ray through the pixel centre.
"""

from __future__ import annotations

import numpy as np

COLOR_CHANNELS = ("R", "G", "B", "A")
#: The mode's φ and the curvatures (geometry/curvature.py) come after the reflection AOVs, so the channel
#: indices of the older ones do not move.
AOV_CHANNELS = ("P.X", "P.Y", "P.Z", "N.X", "N.Y", "N.Z", "u", "v", "patch", "Z", "f", "line.id", "line.dist",
                "phi", "K", "H", "k1", "k2")
CHANNELS = COLOR_CHANNELS + AOV_CHANNELS


def aov_planes(aovs: dict[str, np.ndarray]) -> np.ndarray:
    """(N, 18) AOV values in channel order from the named per-pixel arrays (P and N are (N, 3))."""
    return np.column_stack([aovs["P"], aovs["N"], aovs["u"], aovs["v"], aovs["patch"], aovs["Z"], aovs["f"],
                            aovs["line.id"], aovs["line.dist"], aovs["phi"], aovs["K"], aovs["H"], aovs["k1"],
                            aovs["k2"]])


def coverage_color(hit: np.ndarray, lit: np.ndarray, surface_color, line_color, background,
                   shade: np.ndarray | None = None) -> np.ndarray:
    """(P, 4) linear RGBA from per-sample (P, s²) hit flags and line weights ``lit`` (flags, or weights in [0, 1]).

    ``shade``: per-sample (P, s²) factors k of the surface colour (None: flat, k = 1).
    With flags and no shade the sums are whole sample counts, as they always were.
    """
    samples = hit.shape[1]
    n_hit = hit.sum(axis=1)
    weight = np.where(hit, lit, 0)
    n_lit = weight.sum(axis=1)
    unlit = np.where(hit, 1 - weight, 0) if shade is None else np.where(hit, (1 - weight) * shade, 0.0)
    rgb = (n_lit[:, None] * np.asarray(line_color) + unlit.sum(axis=1)[:, None] * np.asarray(surface_color)
           + (samples - n_hit)[:, None] * np.asarray(background)) / samples
    return np.column_stack([rgb, n_hit / samples])


def map_color(hit: np.ndarray, weight: np.ndarray, surface_rgb: np.ndarray, line_color, background) -> np.ndarray:
    """(P, 4) linear RGBA from per-sample (P, s²) hit flags, line weights w in [0, 1] (lit flags: 0 or 1) and
    (P, s², 3) surface colours (map modes): a hit shows w·line_color + (1 − w)·its surface colour."""
    samples = hit.shape[1]
    w = np.where(hit, weight, 0.0)
    rgb = ((np.nan_to_num(surface_rgb) * np.where(hit, 1.0 - w, 0.0)[..., None]).sum(axis=1)
           + w.sum(axis=1)[:, None] * np.asarray(line_color)
           + (samples - hit.sum(axis=1))[:, None] * np.asarray(background)) / samples
    return np.column_stack([rgb, hit.sum(axis=1) / samples])


class Film:
    def __init__(self, width: int, height: int):
        self.width = width
        self.height = height
        self.pixels = np.empty((height, width, len(CHANNELS)), dtype=np.float32)

    def put_span(self, start: int, stop: int, pixels: np.ndarray) -> None:
        """Store pixels [start, stop) in row-major order: (stop − start, 22) values in `CHANNELS` order."""
        self.pixels.reshape(-1, len(CHANNELS))[start:stop] = pixels

    def channel(self, name: str) -> np.ndarray:
        return self.pixels[..., CHANNELS.index(name)]
