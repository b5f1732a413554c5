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

from ..kernels.pixels import aov_columns, coverage_color_one

COLOR_CHANNELS = ("R", "G", "B", "A")
#: The mode's φ and the curvatures (geometry/curvature.py) come after the reflection AOVs, so the channel
#: indices of the older ones do not move.
AOV_CHANNELS = ("P.X", "P.Y", "P.Z", "N.X", "N.Y", "N.Z", "u", "v", "patch", "Z", "f", "line.id", "line.dist",
                "phi", "K", "H", "k1", "k2")
CHANNELS = COLOR_CHANNELS + AOV_CHANNELS


#: The per-pixel arrays behind `AOV_CHANNELS`, in order, with their widths (P and N are (N, 3)).
AOV_ARRAYS = (("P", 3), ("N", 3), ("u", 1), ("v", 1), ("patch", 1), ("Z", 1), ("f", 1), ("line.id", 1),
              ("line.dist", 1), ("phi", 1), ("K", 1), ("H", 1), ("k1", 1), ("k2", 1))


def aov_planes(aovs: dict[str, np.ndarray], out: np.ndarray | None = None) -> np.ndarray:
    """(N, 18) AOV values in channel order from the named per-pixel arrays (P and N are (N, 3)).

    ``out``: the (N, 18) block to fill (a tile's float32 AOV columns), written array by array with no
    float64 (N, 18) temporary in between; each value is rounded to out's type once, as before.
    """
    if out is None:
        out = np.empty((len(aovs["u"]), len(AOV_CHANNELS)))
    elif out.dtype == np.float32 and len(out):  # a tile's channels: one compiled pass (`kernels.pixels.aov_columns`)
        aov_columns(*(np.asarray(aovs[name], dtype=np.float64) for name, _ in AOV_ARRAYS), out)
        return out
    column = 0
    for name, width in AOV_ARRAYS:
        if width == 1:
            out[:, column] = aovs[name]
        else:
            out[:, column:column + width] = aovs[name]
        column += width
    return out


def coverage_color(hit: np.ndarray, lit: np.ndarray, surface_color, line_color, background,
                   shade: np.ndarray | None = None) -> np.ndarray:
    """(P, 4) linear RGBA from per-sample (P, s²) hit flags and line weights ``lit`` (flags, or weights in [0, 1]).

    ``shade``: per-sample (P, s²) factors k of the surface colour (None: flat, k = 1).
    With flags and no shade the sums are whole sample counts, as they always were.
    Pixels none of whose samples hit all get the one value the sums give for them (the background, A = 0),
    computed once: the sums run over the pixels that see the surface only.
    """
    if hit.shape[1] == 1:  # one sample per pixel: one compiled pass (`kernels.pixels.coverage_color_one`)
        out = np.empty((len(hit), 4))
        colours = (np.asarray(x, dtype=np.float64) for x in (surface_color, line_color, background))
        coverage_color_one(np.ascontiguousarray(hit[:, 0]), np.ascontiguousarray(lit[:, 0], dtype=np.float64),
                           np.ones(0) if shade is None else np.ascontiguousarray(shade[:, 0], dtype=np.float64),
                           shade is not None, *colours, out)
        return out
    seen = np.flatnonzero(hit.any(axis=1))
    if len(seen) == len(hit):
        return _coverage_sums(hit, lit, surface_color, line_color, background, shade)
    # The same sums over one all-miss pixel: every miss row's value, bit for bit.
    empty = np.zeros((1, hit.shape[1]), dtype=bool)
    out = np.empty((len(hit), 4))
    out[:] = _coverage_sums(empty, np.zeros((1, hit.shape[1]), dtype=np.asarray(lit).dtype), surface_color,
                            line_color, background, None if shade is None else np.ones((1, hit.shape[1])))
    if len(seen):
        out[seen] = _coverage_sums(hit[seen], lit[seen], surface_color, line_color, background,
                                   None if shade is None else shade[seen])
    return out


def _coverage_sums(hit: np.ndarray, lit: np.ndarray, surface_color, line_color, background,
                   shade: np.ndarray | None) -> np.ndarray:
    """`coverage_color`'s sums over every pixel given."""
    samples = hit.shape[1]
    n_hit = hit.sum(axis=1)
    weight = np.where(hit, lit, 0)
    n_lit = weight.sum(axis=1)
    unlit = np.where(hit, 1 - weight, 0) if shade is None else np.where(hit, (1 - weight) * shade, 0.0)
    n_unlit, n_missed = unlit.sum(axis=1), samples - n_hit
    line, surface, back = np.asarray(line_color), np.asarray(surface_color), np.asarray(background)
    # Channel by channel: the same operations as the (P, 1) × (3,) broadcast, whose length-3 inner loops cost
    # ~6× more (numpy calls them once per pixel).
    out = np.empty((len(hit), 4))
    for c in range(3):
        out[:, c] = (n_lit * line[c] + n_unlit * surface[c] + n_missed * back[c]) / samples
    out[:, 3] = n_hit / samples
    return out


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
