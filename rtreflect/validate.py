"""Validation: traced reflection lines against the analytic contours f = c_k (paper section 4).

The render's `f` AOV (from the ray through each pixel centre) and the analytic level
sets must agree: the traced line of tube k is centred where f = c_k.

**Traced centres.** Between two neighbouring pixel centres (horizontal or vertical)
where f − c_k changes sign, the centre is placed on the cubic through f at the four
pixel centres around the crossing (linear interpolation would err by up to
|f''|/(8|f'|) px where lines bend tightly). A pair counts only when it lies inside one
smooth, visible piece of surface where the pixels resolve the lines, and tube k is
really seen there: the pair and the pairs before and after it hit the same patch with
converged exact hits (no Newton fallback) and finite f, neighbouring hit points are no
farther apart than `JUMP_FOOTPRINTS` pixel footprints (so no silhouette or occlusion
edge lies between them), f changes by less than 1/`MIN_LINE_GAP_PX` of the tube spacing
per pixel (lines at least that many pixels apart), both pixels have ``line.id == k``
(tube k, or one at the same position, is the nearest tube ahead, within its length) and
neither pixel's reflected ray is blocked before the light plane.

**Deviation.** Each traced centre's distance in pixels to the nearest segment of tube
k's projected analytic polylines. A centre whose nearest contour point is the open end
of a polyline (where visibility, a patch edge or the tube's end cuts the contour), and
lies within `END_MARGIN_PX` of it, sits beyond the analytic line's end and is left out.

**Misses** (both directions): analytic contour points with no traced centre of the same
tube within `MISS_RADIUS_PX`, counted only away from silhouettes, patch edges, occlusion
boundaries and the image border (the pixel is `CLEAN_MARGIN_PX` from any such pixel, and
the point is `END_MARGIN_PX` along the contour from a polyline end); plus traced centres
with no analytic contour of their tube within `SEARCH_RADIUS_PX`.

A scene passes when the maximum deviation is within the tolerance and there are no misses.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .contours import ContourLines, UlmetField, analytic_contours
from .render import RAYS_PER_TILE, Renderer
from .scene import Scene

DEFAULT_TOLERANCE_PX = 0.5
#: Neighbouring hit points farther apart than this many pixel footprints straddle an edge (or graze).
JUMP_FOOTPRINTS = 8.0
#: Lines closer together than this in the image are not resolved by the pixel grid: no centres, no misses there.
MIN_LINE_GAP_PX = 3.0
#: Traced centres with no analytic contour within this distance are misses.
SEARCH_RADIUS_PX = 16.0
#: An analytic point with no traced centre within this distance is a miss.
MISS_RADIUS_PX = 1.5
#: Contour points this close (along the contour) to a polyline end are not checked for misses,
#: and traced centres this close beyond an end are left out.
END_MARGIN_PX = 2.0
#: Contour points are checked for misses only this many pixels from unusable pixels and the border.
CLEAN_MARGIN_PX = 2


@dataclass
class PixelAOVs:
    """Float64 pixel-centre AOVs of a whole image, (H, W) or (H, W, 3)."""

    f: np.ndarray
    patch: np.ndarray
    P: np.ndarray
    N: np.ndarray
    s: np.ndarray
    Z: np.ndarray
    line_id: np.ndarray
    fallback: np.ndarray


def pixel_aovs(renderer: Renderer, progress: Callable[[int], None] | None = None,
               threads: int | None = None) -> PixelAOVs:
    """The renderer's AOVs of every pixel centre, in float64 (the EXR stores float32), tile by tile."""
    width, height = renderer.camera.width, renderer.camera.height
    out = PixelAOVs(*(np.full((height, width), np.nan) for _ in range(2)), *(np.full((height, width, 3), np.nan)
                                                                           for _ in range(3)),
                    np.full((height, width), np.nan), np.full((height, width), -1.0),
                    np.zeros((height, width), dtype=bool))
    rows_per_tile = max(1, RAYS_PER_TILE // width)
    tiles = [(r, min(r + rows_per_tile, height)) for r in range(0, height, rows_per_tile)]

    def work(tile: tuple[int, int]) -> int:
        r0, r1 = tile
        rows, cols = np.divmod(np.arange(r0 * width, r1 * width), width)
        aovs = renderer.pixel_aovs(rows, cols)
        shading = aovs["shading"]
        shape = (r1 - r0, width)
        out.f[r0:r1] = aovs["f"].reshape(shape)
        out.patch[r0:r1] = aovs["patch"].reshape(shape)
        out.P[r0:r1] = aovs["P"].reshape(*shape, 3)
        out.N[r0:r1] = aovs["N"].reshape(*shape, 3)
        out.s[r0:r1] = shading.s.reshape(*shape, 3)
        out.Z[r0:r1] = aovs["Z"].reshape(shape)
        out.line_id[r0:r1] = aovs["line.id"].reshape(shape)
        out.fallback[r0:r1] = shading.hits.fallback.reshape(shape)
        return (r1 - r0) * width

    with ThreadPoolExecutor(max_workers=threads or min(2, os.cpu_count() or 1)) as pool:
        for done in pool.map(work, tiles):
            if progress:
                progress(done)
    return out


def pixel_footprint(renderer: Renderer, Z: np.ndarray) -> np.ndarray:
    """Size in model units of one pixel at ray distance Z."""
    camera = renderer.camera
    if camera.orthographic:
        return np.full_like(Z, camera.spec.view_height / camera.height)
    return Z * 2.0 * math.tan(math.radians(camera.spec.fov) / 2) / camera.height


@dataclass
class TracedCentres:
    """Sub-pixel centres of the traced lines: image positions (n, 2) and tube index per centre."""

    px: np.ndarray
    light: np.ndarray


def tube_gap(c_k: np.ndarray) -> float:
    """Smallest distance between two tubes' positions c_k (inf for one tube)."""
    gaps = np.diff(np.sort(c_k))
    gaps = gaps[gaps > 0]
    return float(gaps.min()) if len(gaps) else math.inf


def _smooth_pairs(aovs: PixelAOVs, footprint: np.ndarray, axis: int,
                  gap: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices (a, b) of neighbouring pixels along ``axis`` inside one smooth visible piece of a patch.

    With ``gap`` (the smallest tube spacing), also where f changes by less than gap / MIN_LINE_GAP_PX
    between them: there neighbouring lines are resolved by the pixel grid.
    """
    height, width = aovs.f.shape
    index = np.arange(height * width).reshape(height, width)
    a = index[:, :-1] if axis == 1 else index[:-1, :]
    b = index[:, 1:] if axis == 1 else index[1:, :]
    a, b = a.ravel(), b.ravel()
    patch, f, fallback = aovs.patch.ravel(), aovs.f.ravel(), aovs.fallback.ravel()
    P, fp = aovs.P.reshape(-1, 3), footprint.ravel()
    ok = (patch[a] >= 0) & (patch[a] == patch[b]) & ~fallback[a] & ~fallback[b]
    ok &= np.isfinite(f[a]) & np.isfinite(f[b])
    with np.errstate(invalid="ignore"):
        ok &= np.linalg.norm(P[a] - P[b], axis=1) <= JUMP_FOOTPRINTS * np.fmax(fp[a], fp[b])
        ok &= np.abs(f[b] - f[a]) <= gap / MIN_LINE_GAP_PX
    return a[ok], b[ok]


def _unblocked(renderer: Renderer, aovs: PixelAOVs, pixels: np.ndarray) -> np.ndarray:
    """True where the pixel's reflected ray reaches the light plane without meeting the surface."""
    P, n, s = aovs.P.reshape(-1, 3)[pixels], aovs.N.reshape(-1, 3)[pixels], aovs.s.reshape(-1, 3)[pixels]
    lights = renderer.lights
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((lights.Q - P) @ lights.m) / (s @ lights.m)
    patch = aovs.patch.ravel()[pixels].astype(int)
    tess = renderer.tessellation
    eps = 2.0 * tess.chord_error[patch] + 1e-6 * (tess.extent + np.abs(P).max(axis=1))
    return (t > 0) & ~renderer.accelerator.occluded(P + eps[:, None] * n, s, np.where(t > 0, t, 0.0))


def _crossing(f: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, smooth_next: np.ndarray,
              step: int) -> tuple[np.ndarray, np.ndarray]:
    """Fraction δ in [0, 1] from pixel a to b where f = c, and whether f is resolved there.

    f is resolved when the pairs before and after (a − 1, a) and (b, b + 1) are smooth too;
    δ is then the root of the cubic through f at a − 1, a, b, b + 1. Linear interpolation
    alone errs by up to |f''| / (8 |f'|) pixels, a visible fraction of a pixel where lines
    bend tightly; the cubic leaves an error of the order of the fourth derivative.
    """
    fa, fb = f[a], f[b]
    delta = (c - fa) / (fb - fa)
    prev, after = a - step, b + step
    ok = (prev >= 0) & (after < f.size)
    ok[ok] &= smooth_next[prev[ok]] & smooth_next[b[ok]]
    # No wrapping across rows: smooth_next is False at a row's last pixel, where a pair would wrap.
    if not ok.any():
        return delta, ok
    idx = np.flatnonzero(ok)
    y0, y1, y2, y3 = f[prev[idx]], fa[idx], fb[idx], f[after[idx]]
    # Lagrange cubic through x = -1, 0, 1, 2 written as y1 + p1 x + p2 x^2 + p3 x^3.
    p1 = -y0 / 3 - y1 / 2 + y2 - y3 / 6
    p2 = y0 / 2 - y1 + y2 / 2
    p3 = -y0 / 6 + y1 / 2 - y2 / 2 + y3 / 6
    x = delta[idx].copy()
    target = c[idx] - y1
    for _ in range(6):
        g = ((p3 * x + p2) * x + p1) * x - target
        dg = (3 * p3 * x + 2 * p2) * x + p1
        with np.errstate(divide="ignore", invalid="ignore"):
            x = x - g / dg
    good = np.isfinite(x) & (x >= 0) & (x <= 1)
    delta[idx[good]] = x[good]
    ok[idx[~good]] = False
    return delta, ok


def traced_centres(renderer: Renderer, aovs: PixelAOVs) -> TracedCentres:
    """Where f − c_k changes sign between neighbouring pixel centres, by linear interpolation (see module doc)."""
    height, width = aovs.f.shape
    footprint = pixel_footprint(renderer, aovs.Z)
    c_k = renderer.lights.c_k
    order = np.argsort(c_k)
    c_sorted = c_k[order]
    f, line_id = aovs.f.ravel(), aovs.line_id.ravel()
    pos, light = [], []
    for axis in (1, 0):
        a, b = _smooth_pairs(aovs, footprint, axis, tube_gap(c_k))
        smooth_next = np.zeros(f.size, dtype=bool)  # pair (p, p + step) is smooth, keyed by p
        smooth_next[a] = True
        lo_f, hi_f = np.fmin(f[a], f[b]), np.fmax(f[a], f[b])
        first = np.searchsorted(c_sorted, lo_f, side="right")  # c > lo_f
        last = np.searchsorted(c_sorted, hi_f, side="right")  # c <= hi_f
        count = last - first
        pair = np.repeat(np.arange(len(a)), count)
        which = np.arange(len(pair)) - np.repeat(np.cumsum(count) - count, count) + first[pair]
        k = order[which]
        a, b = a[pair], b[pair]
        # line.id names the nearest tube ahead; a tube at the same position as k counts as k.
        pos_a = np.where(line_id[a] >= 0, c_k[np.maximum(line_id[a], 0).astype(int)], np.nan)
        pos_b = np.where(line_id[b] >= 0, c_k[np.maximum(line_id[b], 0).astype(int)], np.nan)
        keep = (pos_a == c_k[k]) & (pos_b == c_k[k])
        a, b, k = a[keep], b[keep], k[keep]
        delta, resolved = _crossing(f, a, b, c_k[k], smooth_next, step=1 if axis == 1 else width)
        a, k, delta = a[resolved], k[resolved], delta[resolved]
        row, col = np.divmod(a, width)
        x = col + 0.5 + (delta if axis == 1 else 0.0)
        y = row + 0.5 + (delta if axis == 0 else 0.0)
        pos.append(np.column_stack([x, y]))
        light.append(k)
    return TracedCentres(np.concatenate(pos), np.concatenate(light))


def _filter_unblocked(renderer: Renderer, aovs: PixelAOVs, centres: TracedCentres) -> TracedCentres:
    """The centres whose two pixels see the tube: reflected rays unblocked (line.id already says it is ahead)."""
    width = aovs.f.shape[1]
    x, y = centres.px[:, 0], centres.px[:, 1]
    # The two pixels of each pair: the centre lies between them, so floor/ceil of (pos − ½) give them.
    ca, ra = np.floor(x - 0.5).astype(int), np.floor(y - 0.5).astype(int)
    cb, rb = np.ceil(x - 0.5).astype(int), np.ceil(y - 0.5).astype(int)
    pixels = np.unique(np.concatenate([ra * width + ca, rb * width + cb]))
    clear = np.zeros(aovs.f.size, dtype=bool)
    clear[pixels] = _unblocked(renderer, aovs, pixels)
    keep = clear[ra * width + ca] & clear[rb * width + cb]
    return TracedCentres(centres.px[keep], centres.light[keep])


# -- nearest distances ------------------------------------------------------------------------


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


@dataclass
class _Segments:
    a: np.ndarray
    b: np.ndarray
    open_start: np.ndarray  # a is the first point of an open polyline
    open_end: np.ndarray  # b is the last point of an open polyline


def _segments(contours: ContourLines, light: int) -> _Segments:
    a, b, s0, s1 = [], [], [], []
    for poly in contours.lines[light].polylines:
        px = poly.px
        closed = bool(np.all(px[0] == px[-1]))
        n = len(px) - 1
        a.append(px[:-1])
        b.append(px[1:])
        start = np.zeros(n, bool)
        end = np.zeros(n, bool)
        if not closed:
            start[0] = True
            end[-1] = True
        s0.append(start)
        s1.append(end)
    if not a:
        z = np.zeros((0, 2))
        return _Segments(z, z, np.zeros(0, bool), np.zeros(0, bool))
    return _Segments(np.concatenate(a), np.concatenate(b), np.concatenate(s0), np.concatenate(s1))


def _checkable_points(contours: ContourLines, light: int, clean: np.ndarray) -> np.ndarray:
    """Analytic contour points of one tube that must have a traced centre nearby (see module doc)."""
    height, width = clean.shape
    out = []
    for poly in contours.lines[light].polylines:
        px = poly.px
        step = np.linalg.norm(np.diff(px, axis=0), axis=1)
        along = np.concatenate([[0.0], np.cumsum(step)])
        ok = np.isfinite(along)
        if not np.all(px[0] == px[-1]):
            ok &= (along >= END_MARGIN_PX) & (along[-1] - along >= END_MARGIN_PX)
        inside = (px[:, 0] >= CLEAN_MARGIN_PX) & (px[:, 0] <= width - CLEAN_MARGIN_PX) & \
                 (px[:, 1] >= CLEAN_MARGIN_PX) & (px[:, 1] <= height - CLEAN_MARGIN_PX)
        ok &= inside
        idx = np.flatnonzero(ok)
        col = np.clip(np.floor(px[idx, 0]).astype(int), 0, width - 1)
        row = np.clip(np.floor(px[idx, 1]).astype(int), 0, height - 1)
        ok[idx] &= clean[row, col]
        out.append(px[ok])
    return np.concatenate(out) if out else np.zeros((0, 2))


def clean_pixels(renderer: Renderer, aovs: PixelAOVs) -> np.ndarray:
    """(H, W) True where every pixel within CLEAN_MARGIN_PX hits one smooth piece of one patch (see module doc)."""
    height, width = aovs.f.shape
    footprint = pixel_footprint(renderer, aovs.Z)
    bad = ~(aovs.patch >= 0) | aovs.fallback
    flat_bad = bad.ravel().copy()
    for axis in (1, 0):
        index = np.arange(height * width).reshape(height, width)
        a = (index[:, :-1] if axis == 1 else index[:-1, :]).ravel()
        b = (index[:, 1:] if axis == 1 else index[1:, :]).ravel()
        good_a, good_b = _smooth_pairs(aovs, footprint, axis, tube_gap(renderer.lights.c_k))
        smooth = np.zeros(height * width, dtype=bool)
        smooth[good_a] = True  # pair (a, a + step) is smooth, keyed by a
        edge = ~smooth[a]
        flat_bad[a[edge]] = True
        flat_bad[b[edge]] = True
    bad = flat_bad.reshape(height, width)
    grown = bad.copy()
    r = CLEAN_MARGIN_PX
    padded = np.pad(bad, r, constant_values=True)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            grown |= padded[r + dy:r + dy + height, r + dx:r + dx + width]
    return ~grown


# -- reports ----------------------------------------------------------------------------------


@dataclass
class LineReport:
    light: int
    position: float
    points: int
    max_px: float | None
    p95_px: float | None
    mean_px: float | None
    misses: int

    def to_json(self) -> dict:
        return dict(vars(self))


def _stats(dev: np.ndarray) -> tuple[float | None, float | None, float | None]:
    if len(dev) == 0:
        return None, None, None
    return float(dev.max()), float(np.percentile(dev, 95)), float(dev.mean())


@dataclass
class SceneReport:
    name: str
    path: str
    width: int
    height: int
    normals: str
    tolerance: float
    lines: list[LineReport]
    deviations: np.ndarray = field(repr=False)  # every compared point's deviation, px
    contours: ContourLines | None = field(default=None, repr=False)
    centres: TracedCentres | None = field(default=None, repr=False)

    @property
    def points(self) -> int:
        return int(len(self.deviations))

    @property
    def misses(self) -> int:
        return sum(line.misses for line in self.lines)

    @property
    def max_px(self) -> float | None:
        return _stats(self.deviations)[0]

    @property
    def p95_px(self) -> float | None:
        return _stats(self.deviations)[1]

    @property
    def mean_px(self) -> float | None:
        return _stats(self.deviations)[2]

    @property
    def passed(self) -> bool:
        return self.misses == 0 and (self.max_px is None or self.max_px <= self.tolerance)

    def to_json(self) -> dict:
        return {"max_px": self.max_px, "p95_px": self.p95_px, "mean_px": self.mean_px, "points": self.points,
                "misses": self.misses, "lines": [line.to_json() for line in self.lines]}


def compare(renderer: Renderer, aovs: PixelAOVs, contours: ContourLines, tolerance: float) -> SceneReport:
    """Deviation of traced centres from the analytic contours, and misses both ways, per light line."""
    centres = _filter_unblocked(renderer, aovs, traced_centres(renderer, aovs))
    clean = clean_pixels(renderer, aovs)
    reports, all_dev = [], []
    for line in contours.lines:
        k = line.light
        segs = _segments(contours, k)
        pts = centres.px[centres.light == k]
        dist, seg = nearest_segment(pts, segs.a, segs.b, SEARCH_RADIUS_PX)
        unmatched = ~np.isfinite(dist)
        # Beyond an open end of the analytic polyline: the traced line runs on where the contour was cut.
        found = np.flatnonzero(~unmatched)
        at_end = np.zeros(len(pts), dtype=bool)
        if len(found):
            sa, sb = segs.a[seg[found]], segs.b[seg[found]]
            near_start = segs.open_start[seg[found]] & (np.linalg.norm(pts[found] - sa, axis=1) <= dist[found] + 1e-9)
            near_end = segs.open_end[seg[found]] & (np.linalg.norm(pts[found] - sb, axis=1) <= dist[found] + 1e-9)
            at_end[found] = (near_start | near_end) & (dist[found] <= END_MARGIN_PX)
        dev = dist[~unmatched & ~at_end]
        # Analytic points with no traced centre nearby.
        check = _checkable_points(contours, k, clean)
        gap, _ = nearest_segment(check, pts, pts, MISS_RADIUS_PX)
        misses = int(np.count_nonzero(~np.isfinite(gap))) + int(np.count_nonzero(unmatched))
        reports.append(LineReport(k, line.position, int(len(dev)), *_stats(dev), misses))
        all_dev.append(dev)
    camera = renderer.camera
    scene = renderer.scene
    return SceneReport(scene.output.name, str(scene.path), camera.width, camera.height, scene.render.normals,
                       tolerance, reports, np.concatenate(all_dev) if all_dev else np.zeros(0), contours, centres)


def validate_scene(scene: Scene, tolerance: float = DEFAULT_TOLERANCE_PX, progress: Callable[[int], None] | None = None,
                   threads: int | None = None, renderer: Renderer | None = None) -> SceneReport:
    """Render the scene's pixel-centre AOVs in memory and compare them with the analytic contours."""
    renderer = renderer or Renderer(scene)
    aovs = pixel_aovs(renderer, progress, threads)
    contours = analytic_contours(UlmetField.of(renderer))
    return compare(renderer, aovs, contours, tolerance)
