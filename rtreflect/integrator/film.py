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

import mmap
import threading

import numpy as np

from ..kernels.pixels import aov_columns, coverage_rgba

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
    """(N, 18) AOV values in channel order from the named per-pixel arrays (P and N are (N, 3)), by one compiled
    pass (`kernels.pixels.aov_columns`): each float64 value rounded to out's type once.

    ``out``: the (N, 18) block to fill (a tile's float32 AOV columns), else a new float64 one.
    """
    if out is None:
        out = np.empty((len(aovs["u"]), len(AOV_CHANNELS)))
    # Strided inputs (the curvature columns are views, `Renderer.aovs`) have a compiled signature for a float32 block
    # only: a float64 one takes contiguous copies.
    arrays = (np.asarray(aovs[name], dtype=np.float64) for name, _ in AOV_ARRAYS)
    aov_columns(*(arrays if out.dtype == np.float32 else map(np.ascontiguousarray, arrays)), out)
    return out


def coverage_color(hit: np.ndarray, lit: np.ndarray, surface_color, line_color, background,
                   shade: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """(P, 4) linear RGBA from per-sample (P, s²) hit flags and line weights ``lit`` (flags, or weights in [0, 1]).

    ``shade``: per-sample (P, s²) factors k of the surface colour (None: flat, k = 1). Per pixel, the line weights'
    sum L, the surface's U = Σ (1 − w)·k and the hits' count H over its s² samples give
    RGB = (L·line_color + U·surface_color + (s² − H)·background)/s² and A = H/s², by one compiled pass
    (`kernels.pixels.coverage_rgba`, which sums as numpy sums a row). ``out``: the (P, 4) block to fill (a tile's
    float32 colour columns, each value rounded once), else a new float64 one.
    """
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    return _rgba(hit, lit, np.ones((0, 0)) if shade is None else f64(shade), shade is not None, f64(surface_color),
                 np.zeros((0, 0, 3)), line_color, background, out)


def map_color(hit: np.ndarray, weight: np.ndarray, surface_rgb: np.ndarray, line_color, background,
              out: np.ndarray | None = None) -> np.ndarray:
    """(P, 4) linear RGBA from per-sample (P, s²) hit flags, line weights w in [0, 1] (lit flags: 0 or 1) and
    (P, s², 3) surface colours (map modes): a hit shows w·line_color + (1 − w)·its surface colour (NaN as 0), by
    the same compiled pass as `coverage_color`, each sample's colour in place of k·surface_color. ``out`` as there."""
    return _rgba(hit, weight, np.ones((0, 0)), False, np.zeros(3), np.ascontiguousarray(surface_rgb, dtype=np.float64),
                 line_color, background, out)


def _rgba(hit, weight, shade, shaded, surface, colours, line_color, background, out):
    """`kernels.pixels.coverage_rgba`'s arrays marshalled, into ``out`` or a new (P, 4) float64 block."""
    if out is None:
        out = np.empty((len(hit), 4))
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    coverage_rgba(np.ascontiguousarray(hit, dtype=bool), f64(weight), shade, shaded, surface, colours, f64(line_color),
                  f64(background), out)
    return out


#: numpy's switch for its MADV_HUGEPAGE advice on arrays of 4 MiB and more (a private call, in numpy._core from 2.0,
#: numpy.core before: None where this numpy has none), and a lock so that two threads setting and restoring it cannot
#: leave it off.
_SET_MADVISE_HUGEPAGE = getattr(getattr(getattr(np, "_core", None) or getattr(np, "core", None), "multiarray", None),
                                "_set_madvise_hugepage", None)
_MADVISE_LOCK = threading.Lock()


def plain_pages(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised array (as np.empty) in memory not advised MADV_HUGEPAGE: for a big array written once.

    numpy advises huge pages on every array of 4 MiB and more. Where transparent huge pages are ``madvise`` (with
    defrag ``madvise``, the kernel's default) that advice makes the first touch of each 2 MiB page compact memory
    when none is free: a full-HD film's 182 MB then costs 0.02–0.47 s of system time per render (0.02 when huge
    pages happen to be free, measured back to back on the loaded 2-core machine), against a steady 0.07–0.11 s for
    its 44 500 faults of 4 KiB pages: the plain pages are the steady choice. Where THP is ``always`` the kernel
    still gives huge pages where free, without compacting for them; where it is ``never`` nothing changes. The
    advice is turned off around this allocation alone (numpy's switch is process-wide), else the memory is an
    anonymous private mapping, which nobody advises; else np.empty.
    """
    dtype = np.dtype(dtype)
    if _SET_MADVISE_HUGEPAGE is not None:
        with _MADVISE_LOCK:
            advised = _SET_MADVISE_HUGEPAGE(False)
            try:
                return np.empty(shape, dtype=dtype)
            finally:
                _SET_MADVISE_HUGEPAGE(advised)
    size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if size and hasattr(mmap, "MAP_PRIVATE") and hasattr(mmap, "MAP_ANONYMOUS"):
        pages = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
        return np.frombuffer(pages, dtype=dtype).reshape(shape)
    return np.empty(shape, dtype=dtype)


class Film:
    def __init__(self, width: int, height: int):
        self.width = width
        self.height = height
        # Written once, tile by tile, by the render threads (which take its page faults): plain pages (`plain_pages`).
        self.pixels = plain_pages((height, width, len(CHANNELS)), np.float32)

    def put_span(self, start: int, stop: int, pixels: np.ndarray) -> None:
        """Store pixels [start, stop) in row-major order: (stop − start, 22) values in `CHANNELS` order."""
        self.span(start, stop)[:] = pixels

    def span(self, start: int, stop: int) -> np.ndarray:
        """Pixels [start, stop) in row-major order, (stop − start, 22) in `CHANNELS` order: a view to render into."""
        return self.pixels.reshape(-1, len(CHANNELS))[start:stop]

    def channel(self, name: str) -> np.ndarray:
        return self.pixels[..., CHANNELS.index(name)]
