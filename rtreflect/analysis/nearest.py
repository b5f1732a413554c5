"""Nearest segment to each point in the image: the distance of traced centres to analytic lines, and of lines to lines."""

from __future__ import annotations

import numpy as np


def nearest_segment(points: np.ndarray, a: np.ndarray, b: np.ndarray, radius: float,
                    chunk: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each point to the nearest segment [a, b] within ``radius`` (inf beyond), and that segment's index.

    Points are taken in chunks sorted by y; each chunk is compared only with the segments
    whose y-range comes within ``radius`` of the chunk's, so the work stays near-linear.
    """
    n = len(points)
    best = np.full(n, np.inf)
    best_seg = np.full(n, -1)
    if n == 0 or len(a) == 0:
        return best, best_seg
    seg_lo = np.minimum(a[:, 1], b[:, 1])
    seg_hi = np.maximum(a[:, 1], b[:, 1])
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    order = np.argsort(points[:, 1])
    for lo in range(0, n, chunk):
        rows = order[lo:lo + chunk]
        p = points[rows]
        near = np.flatnonzero((seg_hi >= p[:, 1].min() - radius) & (seg_lo <= p[:, 1].max() + radius))
        if len(near) == 0:
            continue
        rel = p[:, None, :] - a[near][None]  # (c, s, 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(np.einsum("csj,sj->cs", rel, d[near]) / dd[near], 0.0, 1.0)
        t = np.where(dd[near] > 0, t, 0.0)
        gap = rel - t[..., None] * d[near][None]
        dist = np.hypot(gap[..., 0], gap[..., 1])
        j = np.argmin(dist, axis=1)
        dmin = dist[np.arange(len(rows)), j]
        within = dmin <= radius
        best[rows[within]] = dmin[within]
        best_seg[rows[within]] = near[j[within]]
    return best, best_seg
