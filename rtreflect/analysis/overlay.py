"""Overlay: the analytic contours drawn over the rendered image, anti-aliased.

Each polyline is cut into pieces of at most half a pixel; every pixel near a piece gets
the coverage of a line of width w (`[render] overlay_width`, 2 px by default so the
lines read at 100 %: 1 − distance beyond the half-width, clipped to [0, 1], a box filter
of the pixel), and the overlay colour is blended over the linear image with the largest
coverage of any piece. On a correct render the overlay runs down the middle of every
traced line. With ``overlay = "side"`` the same drawing goes to ``NAME.side.png``, beside
the plain picture (`imagefiles.ImageWriter`), and NAME.png stays plain.
"""

from __future__ import annotations

import json
from typing import Callable

import numpy as np

from .contours import ContourLines, analytic_contours, field_of

#: `coverage`'s default line width, in pixels (the seam picture's thin guides); the overlay's is the scene's.
LINE_WIDTH_PX = 1.0
#: Longest straight piece drawn at once, in pixels; the pixel block around each piece covers it.
PIECE_PX = 0.5
#: Pieces per chunk: bounds the (pieces × block) distance arrays.
CHUNK = 1 << 15


def clip_segments(a: np.ndarray, b: np.ndarray, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The parts of segments (a, b) inside the box [low, high] (Liang–Barsky); segments outside are dropped."""
    d = b - a
    t0 = np.zeros(len(a))
    t1 = np.ones(len(a))
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis in (0, 1):
            ta = (low[axis] - a[:, axis]) / d[:, axis]
            tb = (high[axis] - a[:, axis]) / d[:, axis]
            parallel = d[:, axis] == 0
            inside = (a[:, axis] >= low[axis]) & (a[:, axis] <= high[axis])
            t0 = np.where(parallel, np.where(inside, t0, 1.0), np.maximum(t0, np.minimum(ta, tb)))
            t1 = np.where(parallel, np.where(inside, t1, 0.0), np.minimum(t1, np.maximum(ta, tb)))
    keep = t0 <= t1
    return a[keep] + t0[keep, None] * d[keep], a[keep] + t1[keep, None] * d[keep]


def _pieces(contours: ContourLines, line_width: float = LINE_WIDTH_PX) -> tuple[np.ndarray, np.ndarray]:
    """Segments (a, b) in pixels, clipped to just beyond the image (by the line's width), each at most PIECE_PX long."""
    margin = 2.0 + line_width
    low = np.array([-margin, -margin])
    high = np.array([contours.width + margin, contours.height + margin])
    polys = [poly.px for line in contours.lines for poly in line.polylines if len(poly.px)]
    if not polys:
        return np.zeros((0, 2)), np.zeros((0, 2))
    # Every polyline's segments at once (a teapot has ~1,600 polylines): the pairs across two polylines dropped.
    px = np.concatenate(polys)
    within = np.ones(len(px) - 1, dtype=bool)
    within[np.cumsum([len(p) for p in polys])[:-1] - 1] = False
    a, b = px[:-1][within], px[1:][within]
    ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    a, b = clip_segments(a[ok], b[ok], low, high)
    parts = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / PIECE_PX)).astype(int)
    seg = np.repeat(np.arange(len(a)), parts)
    first = np.arange(len(seg)) - np.repeat(np.cumsum(parts) - parts, parts)
    t0 = (first / parts[seg])[:, None]
    t1 = ((first + 1) / parts[seg])[:, None]
    d = b[seg] - a[seg]
    return a[seg] + t0 * d, a[seg] + t1 * d


def coverage(contours: ContourLines, width: int, height: int, line_width: float = LINE_WIDTH_PX) -> np.ndarray:
    """(H, W) anti-aliased coverage in [0, 1] of the contour polylines."""
    cover = np.zeros(height * width)
    a, b = _pieces(contours, line_width)
    # A pixel is covered when its centre (col + 0.5) lies within ρ = w/2 + 1/2 of the piece, so within
    # ρ + PIECE_PX/2 of the piece's midpoint m: col − floor(m) lies strictly between ∓(ρ + PIECE_PX/2 + 1/2).
    reach = int(np.floor(0.5 * line_width + 0.5 + 0.5 * PIECE_PX + 0.5))
    offs = np.arange(-reach, reach + 1)
    dy, dx = (g.ravel() for g in np.meshgrid(offs, offs, indexing="ij"))
    for lo in range(0, len(a), CHUNK):
        pa, pb = a[lo:lo + CHUNK], b[lo:lo + CHUNK]
        mid = 0.5 * (pa + pb)
        col = np.floor(mid[:, 0]).astype(np.int64)[:, None] + dx
        row = np.floor(mid[:, 1]).astype(np.int64)[:, None] + dy
        centre = np.stack([col + 0.5, row + 0.5], axis=-1)  # (n, block, 2)
        d = (pb - pa)[:, None, :]
        rel = centre - pa[:, None, :]
        dd = np.maximum(np.sum(d * d, axis=-1), 1e-300)
        t = np.clip(np.sum(rel * d, axis=-1) / dd, 0.0, 1.0)
        dist = np.linalg.norm(rel - t[..., None] * d, axis=-1)
        alpha = np.clip(0.5 * line_width + 0.5 - dist, 0.0, 1.0)
        inside = (col >= 0) & (col < width) & (row >= 0) & (row < height) & (alpha > 0)
        np.maximum.at(cover, (row * width + col)[inside], alpha[inside])
    return cover.reshape(height, width)


def blend(rgba: np.ndarray, alpha: np.ndarray, color) -> np.ndarray:
    """A copy of linear RGBA pixels (..., 4) with ``color`` blended over them at coverage ``alpha`` (...)."""
    alpha = alpha[..., None]
    out = np.array(rgba, dtype=np.float32, copy=True)
    out[..., :3] = (1.0 - alpha) * out[..., :3] + alpha * np.asarray(color, dtype=np.float32)
    out[..., 3:4] = np.maximum(out[..., 3:4], alpha)
    return out


def contours_file_name(scene) -> str:
    """``NAME.contours.json``: where a render with the overlay keeps its contours, beside the images."""
    return f"{scene.output.name}.contours.json"


def overlay_outputs(renderer) -> tuple[Callable[[int, np.ndarray], np.ndarray] | None, dict[str, str]]:
    """For a scene about to render: the PNG filter that draws its contours, and `NAME.contours.json`'s text.

    The contours depend on the scene alone, so they are found before rendering and the
    PNG's rows are blended as they stream out (see `rtreflect.imagefiles.open_outputs`).
    With ``[output] png = false`` nothing is drawn (the EXR never shows the overlay): the
    filter is None and only the JSON is written.
    """
    scene = renderer.scene
    contours = analytic_contours(field_of(renderer))
    document = {"scene": str(scene.path), "normals": scene.render.normals, **contours.to_json()}
    files = {contours_file_name(scene): json.dumps(document, separators=(",", ":")) + "\n"}
    if not scene.output.png:
        return None, files
    alpha = coverage(contours, scene.image.width, scene.image.height, scene.render.overlay_width).astype(np.float32)
    color = scene.render.overlay_color

    def draw(row0: int, rgba_rows: np.ndarray) -> np.ndarray:
        return blend(rgba_rows, alpha[row0:row0 + len(rgba_rows)], color)

    return draw, files
