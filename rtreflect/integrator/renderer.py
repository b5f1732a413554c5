"""The reflection-line integrator: scene → film, tile by tile (DESIGN.md, "The pipeline").

Per tile (a span of pixels in row-major order): camera rays for the s×s samples →
exact hits → reflected directions → light tubes and the occlusion test → coverage
colour; plus the pixel-centre rays → AOVs. With ``samples = "analytic"`` (the default,
`analytic`) only the centre rays are traced, the stripes' coverage follows in closed form,
and the edge pixels are supersampled 4×4. Tiles are independent, so two threads
(Embree and most numpy kernels release the GIL) render them side by side,
deterministically, and a pixel's value does not depend on the tile it falls in.
`Renderer.stream` hands tiles over in image order (to `streaming`, which writes them
to files as they come); `Renderer.render` collects them in an in-memory `Film`.
"""

from __future__ import annotations

import itertools
import os
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Callable, Iterator

import numpy as np

from ..trace import clearance
from ..trace.camera import Camera, rays_per_pixel, sample_offsets
from ..clock import StageClock
from .analytic import (BENDING, EDGE_SAMPLES, NEIGHBOURS, TRUSTED_SPAN, edge_pixels, neighbours, stripe_coverage,
                       uv_footprint)
from .cull import RayBox
from .scenegeometry import scene_geometry
from .film import CHANNELS, COLOR_CHANNELS, Film, aov_planes, coverage_color, map_color
from ..modes.lights import TubeLights, reflect, reflect_rays
from ..modes.profile import stripe_reach, stripe_weight
from ..modes.shading import shade_factor
from ..modes.base import SurfacePoints, level_offset, neighbour_levels, seen_at
from ..modes.reflection import ReflectionMode
from ..modes.registry import mode_of
from ..trace.meshnormals import trace_mesh
from ..exchange.scene import ANALYTIC, ImageSpec, Scene
from ..geometry.curvature import curvatures_at
from ..kernels.pixels import (bent_flags, clear_far, footprint_ends, level_crossings, spread_rows,
                              stripe_candidates)
from ..trace.tracing import Hits, occluded, trace

#: Most rays per tile (about 1.2 kB each in flight, see `tiling`): larger tiles buy no speed over numpy's overhead.
RAYS_PER_TILE = 1 << 16
#: Share of a batch's rays `RayBox` keeps above which the others are traced too (they miss every mesh's box, so
#: Embree and the second look reject them at the root): spreading the kept rays' hits into the batch costs more than
#: tracing them (the analytic path's edge samples keep 99.6 % of theirs, its centre rays on the peer scene 82 %).
TRACE_ALL = 0.75
#: Tiles queued per render thread besides the one it renders: a thread done with its tile starts the next while an
#: earlier one still renders (they are handed over in image order). A finished tile waiting for its turn holds only
#: its pixels (`tiling.rays_per_tile` counts them). On the peer scene at samples = 1 (row bands of unequal cost)
#: 0.090 → 0.084 s on two threads (best of 6, A/B in one process); no change where the tiles cost alike (its analytic
#: default's window spans, bench/render_bench.py).
TILES_AHEAD = 1
#: samples = "analytic": most pixels of a span of the pixel window's rows (`pixel_spans`), in tiles of rays_per_tile
#: pixels (each 88 B of film, against ~1.2 kB a ray in flight): a narrow window's span holds few rays, many pixels.
WINDOW_TILE_PIXELS = 4
#: samples = "analytic", map modes: a neighbour whose surface colour differs by more than this (linear RGB, any
#: channel) marks a band edge or the undercut flag's edge, and the pixel is supersampled; a curvature map's
#: smooth colours change by far less from one pixel to the next.
MAP_STEP = 0.05


@dataclass
class Shading:
    """Everything known about a batch of rays after shading: hits, s, the nearest tube ahead, lit flags."""

    hits: Hits
    origins: np.ndarray
    directions: np.ndarray
    s: np.ndarray  # reflected directions (NaN where no hit)
    # The nearest tube ahead and its distance d (−1 and NaN where none is, or no hit). Kept instead of
    # the (N, tubes) tables of eq. (4), so memory does not grow with the number of tubes.
    line_id: np.ndarray
    line_dist: np.ndarray
    lit: np.ndarray
    surface_rgb: np.ndarray | None = None  # (N, 3) linear RGB of a map mode's surface (NaN where no hit), else None
    # Another mode's distance to its nearest level (`Stripes.level_dist`) where `[render] blur` softens its stripes
    # (`Renderer.soft_stripes`), else None.
    stripe_dist: np.ndarray | None = None
    # The mode's nearest level (`Stripes.level_id`, −1 where none is or no hit), for the analytic path.
    level: np.ndarray | None = None
    # For the analytic path too, where the mode gives them with its stripes (NaN where no hit or no level), else
    # None: the signed offset σ from the nearest level (`Stripes.offset`) and the occlusion distance along s
    # (`Stripes.level_t`).
    offset: np.ndarray | None = None
    level_t: np.ndarray | None = None
    # Ulmet's f (the f AOV; NaN where no hit), from the tubes' pass over the reflected rays (`TubeReach.f`).
    f: np.ndarray | None = None

    @classmethod
    def unshaded(cls, hits: Hits, origins: np.ndarray, directions: np.ndarray) -> "Shading":
        """Every ray's shading as where it hit nothing (to be filled in where ``hits`` hit: `Renderer.shade`)."""
        n_rays = len(origins)
        return cls(hits, origins, directions, np.full_like(directions, np.nan), np.full(n_rays, -1),
                   np.full(n_rays, np.nan), np.zeros(n_rays, dtype=bool), level=np.full(n_rays, -1),
                   f=np.full(n_rays, np.nan))

    def take(self, rows: np.ndarray | slice) -> "Shading":
        """The rays ``rows`` (indices: copies, gathered by np.take, ~4× faster than fancy indexing of (N, 3) rows;
        a slice: views)."""
        if not isinstance(rows, slice) and rows.dtype == bool:
            rows = np.flatnonzero(rows)
        pick = (lambda x: x[rows]) if isinstance(rows, slice) else (lambda x: np.take(x, rows, axis=0))  # noqa: E731
        hits = Hits(**{k: pick(getattr(self.hits, k)) for k in Hits.__dataclass_fields__})
        some = lambda x: None if x is None else pick(x)  # noqa: E731
        return Shading(hits, pick(self.origins), pick(self.directions), pick(self.s), pick(self.line_id),
                       pick(self.line_dist), pick(self.lit), some(self.surface_rgb), some(self.stripe_dist),
                       some(self.level), some(self.offset), some(self.level_t),
                       some(self.f))


@dataclass
class RenderStats:
    width: int
    height: int
    samples: int
    rays: int = 0
    fallbacks: int = 0  # samples whose nearest exact hit could not be decided (tracing.py)
    fallback_pixels: int = 0  # pixels with at least one such sample
    supersampled: int = 0  # samples = "analytic": edge pixels rendered with s×s samples instead (analytic.py)
    tiles: int = 0
    seconds: float = 0.0
    stages: dict[str, float] = field(default_factory=dict)

    @property
    def mrays_per_second(self) -> float:
        return self.rays / self.seconds / 1e6 if self.seconds > 0 else 0.0


@dataclass
class Tile:
    """Rendered pixels [start, stop) of the image in row-major order: (stop − start, 22) float32 in `CHANNELS` order."""

    start: int
    stop: int
    pixels: np.ndarray
    rays: int
    fallbacks: int
    fallback_pixels: int
    supersampled: int = 0
    # Per pixel: its centre ray sees a tube within its radius (line.dist) but the part blocks the reflected ray before
    # it (reflection lines; None in another mode). The film has no channel for it: `checks.ImageTally` reads it here.
    blocked: np.ndarray | None = None


@dataclass
class RenderResult:
    """A render in memory: the scene rendered, its `Film` (every EXR channel) and its `RenderStats`."""

    scene: Scene
    film: Film
    stats: RenderStats

    @property
    def rgba(self) -> np.ndarray:
        """(H, W, 4) linear RGBA, float32: the supersampled colour the EXR's R G B A hold."""
        return self.film.pixels[..., :len(COLOR_CHANNELS)]

    def aov(self, name: str) -> np.ndarray:
        """(H, W) values of one EXR channel (``"f"``, ``"line.id"``, ``"N.Z"``, ...), or (H, W, 3) for ``"P"`` and ``"N"``."""
        if name in ("P", "N"):
            return self.film.pixels[..., [CHANNELS.index(f"{name}.{axis}") for axis in "XYZ"]]
        if name not in CHANNELS:
            raise ValueError(f"no channel {name!r}; the channels are {', '.join(CHANNELS)} (and P, N as vectors)")
        return self.film.channel(name)


@dataclass
class CentreStripes:
    """Per centre ray of the analytic path (`Renderer.centre_stripes`); NaN and False where no level is near."""

    sigma: np.ndarray  # signed offset σ from the nearest level's centre (`modes.base.level_offset`)
    grad: np.ndarray  # (N, 2) its gradient per pixel, (∂σ/∂x, ∂σ/∂y), x along a row, y down a column
    coverage: np.ndarray  # the stripe's weighted share of the box pixel (`analytic.stripe_coverage`)
    near: np.ndarray  # the footprint reaches the stripe (within the profile's reach)
    blocked: np.ndarray  # near, and the reflected ray occluded before the level (modes seen along a ray)
    untrusted: np.ndarray  # near, and the linear model is not (footprint ≥ `TRUSTED_SPAN` level spacings, or no g)


def default_threads() -> int:
    """Render threads when none are asked for: two (embreex and numpy release the GIL), or one on one core."""
    return min(2, os.cpu_count() or 1)


def pixel_spans(image: ImageSpec, rays_per_tile: int = RAYS_PER_TILE, window: tuple[slice, slice] | None = None,
                threads: int = 1) -> list[tuple[int, int]]:
    """The image cut into row-major pixel spans [start, stop) of at most ``rays_per_tile`` rays (at least one pixel).

    With ``samples = "analytic"`` a span that holds a row holds whole rows: its own pixels inside the pixel window
    are then one run of the window's rays (`Renderer._render_analytic` takes them as views, not gathered copies).
    Given that ``window`` (`Renderer.window`: only its rays are traced), its rows are cut by the window's rays instead:
    into equal spans of at most ``rays_per_tile`` of them, as many as a multiple of ``threads`` (the threads finish
    together), each at most `WINDOW_TILE_PIXELS` tiles' pixels; the rows outside it (misses, nothing traced) as before.
    On the peer scene (a window of 496 × 312 pixels) 4 spans of it instead of 5 (and 3 empty): a third fewer halo rows
    (`_render_analytic`) and tiles.
    """
    per_tile = max(1, rays_per_tile // rays_per_pixel(image.samples))
    width, total = image.width, image.width * image.height
    if image.samples != ANALYTIC or per_tile < width:
        return [(p, min(p + per_tile, total)) for p in range(0, total, per_tile)]
    rows = per_tile // width
    first, stop = (window[0].start, window[0].stop) if window is not None else (0, 0)
    if stop <= first:  # no window (or an empty one): every row cut as outside it
        first, stop = image.height, image.height
    wide = max(1, window[1].stop - window[1].start) if window is not None else width
    # Spans of at most as many rows as hold rays_per_tile of the window's rays, and WINDOW_TILE_PIXELS tiles' pixels.
    count = -(-(stop - first) // min(max(1, rays_per_tile // wide), WINDOW_TILE_PIXELS * rows))
    count = min(stop - first, -(-count // threads) * threads)
    cuts = [first + (stop - first) * i // count for i in range(count + 1)] if count else [first]
    spans = [(r, min(r + rows, first)) for r in range(0, first, rows)] + list(zip(cuts[:-1], cuts[1:])) + \
        [(r, min(r + rows, image.height)) for r in range(stop, image.height, rows)]
    return [(a * width, b * width) for a, b in spans]


class Renderer:
    """Everything built once per scene: patches, tessellation, BVH, camera, tubes."""

    def __init__(self, scene: Scene):
        self.scene = scene
        # Patches, meshes, BVHs, second look: the surfaces' alone, shared with the scene's last render (`scenegeometry`).
        geometry = scene_geometry(scene)
        self.surfaces, self.tessellation, self.accelerator = geometry.surfaces, geometry.tessellation, geometry.accelerator
        self.vertex_normals, self.second_look, self.ray_box = geometry.vertex_normals, geometry.second_look, geometry.ray_box
        self.camera = Camera(scene.camera, scene.image.width, scene.image.height)
        self.lights = TubeLights.from_spec(scene.lights)
        # The tubes as the stripes see them: out to where the soft edge's weight ends (`[render] blur`), so the
        # occlusion test serves every sample the profile lights; without blur, the tubes of eq. (4) themselves.
        reach = stripe_reach(self.lights.radius, scene.render.blur)
        self.stripe_lights = self.lights if reach == self.lights.radius else replace(self.lights, radius=reach)
        # `[render] mode`: φ, its levels and stripes (modes/base.py); reflection lines see the tubes out to the reach.
        tubes = scene.render.mode == "reflection" and scene.lights.shape == "tubes"
        self.mode = mode_of(scene, self.stripe_lights if tubes else self.lights,
                            self.surfaces)
        # Another mode's stripes seen where they are (not along a ray) are softened by `blur` about their half width:
        # lit out to the profile's reach, weighted by `stripe_weight` of their distance to the nearest level.
        self.soft_stripes = (scene.render.blur > 0 and not isinstance(self.mode, ReflectionMode)
                             and not self.mode.along_ray)
        # The analytic path's stripe (`analytic`): half width (the tubes' own radius, not the profile's reach) and blur
        # (circles seen along the reflected ray stay hard, as in `line_weight`).
        self.half_width = self.lights.radius if isinstance(self.mode, ReflectionMode) else getattr(self.mode, "half_width", 0.0)
        self.blur = scene.render.blur if isinstance(self.mode, ReflectionMode) or self.soft_stripes else 0.0
        self.stripe_reach = stripe_reach(self.half_width, self.blur)
        self.neighbour_level = neighbour_levels(getattr(self.mode, "levels", np.zeros(0)))
        self.clock = StageClock()
        self._window: tuple[RayBox | None, tuple[slice, slice]] = (None, (slice(0, 0), slice(0, 0)))  # `window`

    def trace(self, origins: np.ndarray, directions: np.ndarray, cull: bool = True) -> Hits:
        """Exact first hits of camera rays; rays that miss every mesh's box (`cull`) get the miss values, untraced unless
        the box keeps `TRACE_ALL` of the batch (then all are traced: they miss at Embree's root, the same bits).
        ``cull=False``: all traced without asking the box (the caller knows it keeps about that many: `supersample`)."""
        if not cull:
            return self._trace(origins, directions)
        with self.clock.stage("camera rays"):
            rays = self.ray_box.may_hit(origins, directions)
        if len(rays) >= TRACE_ALL * len(origins):  # few to cull: traced too (misses, as culled), nothing to spread
            return self._trace(origins, directions)
        if len(rays) == 0:
            return Hits.blank(len(origins), np.zeros(len(origins), dtype=bool))
        traced = self._trace(np.take(origins, rays, axis=0), np.take(directions, rays, axis=0))  # `shade`: np.take
        # The traced rows in place, a miss's values (`Hits.blank`) in the others: float rows in one compiled pass each
        # (`kernels.pixels.spread_rows`: the full-size array written once, not filled and then scattered into).
        n, miss, fields, order = len(origins), Hits.blank(1, np.zeros(1, dtype=bool)), {}, np.arange(len(rays))
        for name in Hits.__dataclass_fields__:
            new, blank = getattr(traced, name), getattr(miss, name)
            if blank.dtype == np.float64:
                fields[name] = np.empty((n,) + blank.shape[1:])
                src = np.ascontiguousarray(new, dtype=np.float64).reshape(len(rays), -1)
                spread_rows(fields[name].reshape(n, -1), rays, src, order, float(blank.flat[0]))
            else:
                fields[name] = np.full(n, blank[0])
                fields[name][rays] = new
        return Hits(**fields)

    def _trace(self, origins: np.ndarray, directions: np.ndarray) -> Hits:
        if self.vertex_normals is not None:
            return trace_mesh(self.accelerator, self.tessellation, self.vertex_normals, origins, directions, self.clock)
        hits = trace(self.accelerator, self.tessellation, self.surfaces, origins, directions, self.clock)
        return self.second_look.apply(hits, origins, directions, np.full(len(origins), np.inf), self.clock)

    # -- one batch of rays ---------------------------------------------------------------
    def shade(self, origins: np.ndarray, directions: np.ndarray, occlude: bool = True, cull: bool = True) -> Shading:
        """Exact hits, reflected directions s, the mode's nearest level and 'lit' flags.

        Lit: in the mode's stripe and, for a mode seen along the reflected ray (reflection lines:
        a tube within its radius), not occluded by the surface before it. With ``[render] blur`` the
        reflection mode's radius is the stripe profile's reach (`stripe_lights`): 'lit' then means the
        sample may show some of the line, by its weight `stripe_weight` of the nearest tube's d.
        ``occlude=False``: no occlusion test ('lit' is the stripe test alone); the analytic path tests its own.
        ``cull``: as `trace`'s.
        """
        hits = self.trace(origins, directions, cull)
        n_rays = len(origins)
        shading = Shading.unshaded(hits, origins, directions)
        s, lit, line_id, line_dist = shading.s, shading.lit, shading.line_id, shading.line_dist
        idx = np.flatnonzero(hits.hit)
        if len(idx) == 0:
            return shading
        # np.take: the same rows as hits.P[idx], gathered ~4× faster (numpy's fancy indexing of (N, 3) rows is slow).
        R, n = np.take(hits.P, idx, axis=0), np.take(hits.N, idx, axis=0)
        with self.clock.stage(self.mode.stage):
            # a, the unit vector towards the eye, is the reversed ray direction for either camera.
            s_hit = reflect_rays(directions, idx, n, s)  # the hits' rows of s, also kept on their own
            points = SurfacePoints(R, n, s_hit, hits.patch[idx], hits.u[idx], hits.v[idx])
            stripes = self.mode.stripes(points)
            shading.level[idx] = stripes.level_id
            for name in ("offset", "level_t"):
                if getattr(stripes, name) is not None:
                    setattr(shading, name, np.full(n_rays, np.nan))
                    getattr(shading, name)[idx] = getattr(stripes, name)
            # line.id and line.dist are the tubes' in every mode (the EXR contract): the reflection mode's stripes
            # are those; another mode's nearest level follows from its φ (channel phi) and levels. Ulmet's f comes
            # from the same pass over the reflected rays.
            if isinstance(self.mode, ReflectionMode):
                line_id[idx], line_dist[idx], shading.f[idx] = stripes.level_id, stripes.level_dist, stripes.phi
            else:
                tubes = self.lights.reach(R, s_hit)
                line_id[idx], line_dist[idx], shading.f[idx] = tubes.line_id, tubes.line_dist, tubes.f
            rgb = self.mode.surface_rgb(points)
            if rgb is not None:
                shading.surface_rgb = np.full((n_rays, 3), np.nan)
                shading.surface_rgb[idx] = rgb
            t_tube = stripes.occlusion_t
            candidate = stripes.candidate
            if self.soft_stripes:
                shading.stripe_dist = np.full(n_rays, np.nan)
                shading.stripe_dist[idx] = stripes.level_dist
                with np.errstate(invalid="ignore"):
                    candidate = stripes.level_dist <= stripe_reach(self.mode.half_width, self.scene.render.blur)
            cand = np.flatnonzero(candidate)
        if t_tube is None or not occlude:  # a mode not seen along a ray: its stripes are lit where they are
            lit[idx[cand]] = True
        elif len(cand):
            rows = idx[cand]
            # np.take: the rows of R[cand] (as above), gathered ~4× faster
            start = self.accelerator.surface_origins(np.take(R, cand, axis=0), np.take(n, cand, axis=0),
                                                     points.patch[cand])
            with self.clock.stage("occlusion (Embree)"):
                blocked = occluded(self.accelerator, self.tessellation, self.surfaces, start,
                                   np.take(s_hit, cand, axis=0), t_tube[cand])
            lit[rows] = ~blocked
        return shading

    def line_weight(self, shading: Shading) -> np.ndarray:
        """Per sample the weight of ``line_color`` (film.py): 'lit' times the stripe profile of the nearest tube's d.

        Without blur the profile is the hard tube that 'lit' already decided (d ≤ r): the flags themselves.
        """
        blur = self.scene.render.blur
        if blur == 0:
            return shading.lit
        if isinstance(self.mode, ReflectionMode):
            return np.where(shading.lit, stripe_weight(shading.line_dist, self.lights.radius, blur), 0.0)
        if shading.stripe_dist is None:  # circles seen along the reflected ray stay hard (`soft_stripes`)
            return shading.lit
        return np.where(shading.lit, stripe_weight(shading.stripe_dist, self.mode.half_width, blur), 0.0)

    def surface_shade(self, shading: Shading) -> np.ndarray | None:
        """Per sample the factor k of ``surface_color`` (`modes.shading`; 1 where no hit), or None when flat."""
        if self.scene.render.shading == "flat":
            return None
        k = np.ones(len(shading.directions))
        idx = np.flatnonzero(shading.hits.hit)
        k[idx] = shade_factor(np.take(shading.hits.N, idx, axis=0), np.take(shading.directions, idx, axis=0),
                              self.scene.render.shading)  # np.take: as in `shade`
        return k

    def pixel_aovs(self, rows: np.ndarray, cols: np.ndarray) -> dict[str, np.ndarray]:
        """Float64 AOVs of the pixel-centre rays (DESIGN.md channel list), plus the shading behind them."""
        return self.aovs(self.shade(*self.camera.rays(rows, cols)))

    def aovs(self, shading: Shading) -> dict[str, np.ndarray]:
        hits = shading.hits
        with self.clock.stage("AOVs"):
            idx = np.flatnonzero(hits.hit)
            if shading.f is not None:  # `shade` found it with the tubes
                f = shading.f
            else:
                f = np.full(len(hits.hit), np.nan)
                f[idx] = self.lights.ulmet_f(hits.P[idx], shading.s[idx])
            if isinstance(self.mode, ReflectionMode):  # its φ is Ulmet's f itself: not computed twice
                phi = f
            else:
                phi = np.full(len(hits.hit), np.nan)
                phi[idx] = self.mode.phi(SurfacePoints(hits.P[idx], hits.N[idx], shading.s[idx], hits.patch[idx],
                                                       hits.u[idx], hits.v[idx]))
            # K, H, κ1, κ2 from the fundamental forms at the exact hit, signed with N as written (facing the ray):
            # the tracer's where it had them (`Hits.curvature`, the same kernels' values at the hit or ≤ 1e-6 of a
            # knot span before it), one kernel pass over the other hits (NaN where none hit), stored in its rows. Its
            # columns are the AOVs (strided views: a transposed copy cost 1 % of a full-HD render).
            curv = hits.curvature
            rest = np.flatnonzero(hits.hit & np.isnan(curv[:, 0]))
            if len(rest):
                curv[rest] = np.column_stack(curvatures_at(self.surfaces, hits.patch[rest], hits.u[rest], hits.v[rest],
                                                           np.take(hits.N, rest, axis=0)))
        return {"P": hits.P, "N": hits.N, "u": hits.u, "v": hits.v, "patch": hits.patch.astype(np.float64),
                "Z": hits.t, "f": f, "line.id": shading.line_id.astype(np.float64), "line.dist": shading.line_dist,
                "phi": phi, "K": curv[:, 0], "H": curv[:, 1], "k1": curv[:, 2], "k2": curv[:, 3], "shading": shading}

    # -- tiles ---------------------------------------------------------------------------
    def render_span(self, start: int, stop: int, out: np.ndarray | None = None) -> Tile:
        """Pixels [start, stop) in row-major order (a tile may begin or end mid-row) as one `Tile`.

        Every pixel's value depends only on its own rays (and, with ``samples = "analytic"``, its
        8 neighbours' centre rays, traced as a halo around the span), so any cut of the image into
        spans gives the same bytes. ``out``: the (stop − start, 22) float32 block to write them into (a span
        of a `Film`, `Film.span`: no tile-sized array and no copy into the film), else a new one.
        """
        if out is None:
            out = np.empty((stop - start, len(CHANNELS)), dtype=np.float32)
        s = self.scene.image.samples
        if s == ANALYTIC:
            return self._render_analytic(start, stop, out)
        width = self.scene.image.width
        rows, cols = np.divmod(np.arange(start, stop), width)
        _, shading, rays = self.supersample(rows, cols, s, out[:, :4])
        ns = s * s
        fallbacks = int(shading.hits.fallback.sum())
        fell_back = shading.hits.fallback.reshape(-1, ns).any(axis=1)
        if s % 2 == 1:  # the middle sample of an odd s×s grid is the pixel-centre ray
            aovs = self.aovs(shading.take(slice(ns // 2, None, ns)))  # every ns-th sample: views, not copies
        else:
            del shading  # free the samples' shading before tracing the centre rays
            aovs = self.pixel_aovs(rows, cols)
            rays += len(rows)
            # The centre ray's hit is what the AOVs (P, N, f) store: its fallbacks count too.
            centre = aovs["shading"].hits.fallback
            fallbacks += int(centre.sum())
            fell_back |= centre
        fallback_pixels = int(fell_back.sum())
        aov_planes(aovs, out[:, 4:])
        return Tile(start, stop, out, rays, fallbacks, fallback_pixels, blocked=self._blocked_lines(aovs["shading"]))

    def _blocked_lines(self, shading: Shading, blocked: np.ndarray | None = None) -> np.ndarray | None:
        """`Tile.blocked` of pixel-centre rays: a tube within its radius and the reflected ray occluded (``blocked``
        where the caller tested it, else not lit: in reflection mode 'lit' is the tube test and no occlusion)."""
        if not isinstance(self.mode, ReflectionMode):
            return None
        with np.errstate(invalid="ignore"):
            near = shading.hits.hit & (shading.line_dist <= self.lights.radius)
        return near & (~shading.lit if blocked is None else blocked)

    def supersample(self, rows: np.ndarray, cols: np.ndarray, s: int,
                    out: np.ndarray | None = None) -> tuple[np.ndarray, Shading, int]:
        """(P, 4) RGBA of pixels (rows, cols) from their s×s samples, the samples' `Shading`, and the rays traced.
        ``out``: the (P, 4) block to write the RGBA into (`colour`)."""
        offsets = sample_offsets(s)
        ns = len(offsets)
        with self.clock.stage("camera rays"):
            origins, directions = self.camera.sample_rays(rows, cols, offsets)
            # Pixels in the box's picture (`window`, a few pixels wider): where they are `TRACE_ALL` of the batch, the
            # box would keep about as many of its rays and `trace` trace them all: so at once, not asked ray by ray
            # (the same bits either way; full HD: 3 % of a render's CPU). Not where the picture is unbounded (the
            # window is then the whole image, however little of it the part covers).
            (r0, r1), (c0, c1) = ((w.start, w.stop) for w in self.window)
            whole = (r1 - r0, c1 - c0) == (self.camera.height, self.camera.width)
            inside = 0 if whole else np.count_nonzero((rows >= r0) & (rows < r1) & (cols >= c0) & (cols < c1))
        shading = self.shade(origins, directions, cull=inside < TRACE_ALL * len(rows))
        rgba = self.colour(shading, self.line_weight(shading), ns, out)
        return rgba, shading, len(origins)

    def colour(self, shading: Shading, weight: np.ndarray, ns: int, out: np.ndarray | None = None) -> np.ndarray:
        """(P, 4) RGBA of pixels of ``ns`` samples each: hits, line weights (`film`) and the surface's shade or map.

        ``out``: the (P, 4) block to write them into (a tile's float32 colour columns: each value rounded once, as
        when a float64 RGBA is copied in), else a new float64 array."""
        settings = self.scene.render
        if shading.surface_rgb is None:
            shade = self.surface_shade(shading)
            return coverage_color(shading.hits.hit.reshape(-1, ns), weight.reshape(-1, ns),
                                  settings.surface_color, settings.line_color, settings.background,
                                  None if shade is None else shade.reshape(-1, ns), out)
        # a map mode: each sample's own surface colour
        rgba = map_color(shading.hits.hit.reshape(-1, ns), weight.reshape(-1, ns),
                         shading.surface_rgb.reshape(-1, ns, 3), settings.line_color, settings.background)
        if out is None:
            return rgba
        out[:] = rgba
        return out

    @property
    def window(self) -> tuple[slice, slice]:
        """(rows, columns) of the pixels whose centre rays `ray_box` may keep (`cull.RayBox.pixel_window`), for the
        analytic path and `supersample`; found once per box (a test may swap the box)."""
        box, window = self._window
        if box is not self.ray_box:
            self._window = self.ray_box, self.ray_box.pixel_window(self.camera)
        return self._window[1]

    @cached_property
    def _miss_pixel(self) -> np.ndarray:
        """The 22 float32 values of a pixel whose centre ray hits nothing (analytic path): its colour (line weight 0)
        and AOVs as `colour` and `aovs` give them for such a ray, so the same bits as when it is traced and culled."""
        pixel = np.empty((1, len(CHANNELS)), dtype=np.float32)
        origins, directions = np.zeros((1, 3)), np.zeros((1, 3))
        shading = Shading.unshaded(Hits.blank(1, np.zeros(1, dtype=bool)), origins, directions)
        self.colour(shading, np.zeros(1), 1, pixel[:, :4])
        aov_planes(self.aovs(shading), pixel[:, 4:])
        return pixel[0]

    def _render_analytic(self, start: int, stop: int, out: np.ndarray) -> Tile:
        """`render_span` for ``samples = "analytic"`` (`analytic`): centre rays with a halo, the stripes' coverage in
        closed form, and the edge pixels supersampled.

        The edge test reads each pixel's 8 neighbours, and whether a pixel's footprint reaches a stripe is first
        bounded by its own neighbours' σ (the gradient is then evaluated only where it may), so the centre rays
        of the span's rows and two rows on either side are traced: a pixel's value depends only on the rays of
        the pixels around it, never on where the span ends. Only those within the `window` of pixels whose rays
        may meet a mesh (`cull`) are formed and traced: every pixel outside it is a miss (`_miss_pixel`), and
        the window keeps a ring of such pixels around the hits, so the neighbour tests see the same pixels.
        """
        image = self.scene.image
        width, height = image.width, image.height
        first, last = start // width, (stop - 1) // width
        halo_rays = (min(height - 1, last + 2) - max(0, first - 2) + 1) * width  # counted as traced, culled or not
        window_rows, window_cols = self.window
        r0, r1 = max(0, first - 2, window_rows.start), min(height - 1, last + 2, window_rows.stop - 1)
        c0, c1 = window_cols.start, window_cols.stop
        out[:] = self._miss_pixel
        # The span's own pixels inside the window: per own row, the run of its columns there.
        own_rows = np.arange(max(first, r0), min(last, r1) + 1)
        low = np.maximum(own_rows * width + c0, start)
        high = np.minimum(own_rows * width + c1, stop)
        low, high = low[high > low], high[high > low]
        if len(low) == 0:
            return Tile(start, stop, out, halo_rays, 0, 0, 0)
        runs = high - low
        pixels = np.repeat(low - np.cumsum(runs) + runs, runs) + np.arange(runs.sum())  # the runs, concatenated
        shape = (r1 - r0 + 1, c1 - c0)
        rows = np.repeat(np.arange(r0, r1 + 1), shape[1])
        cols = np.tile(np.arange(c0, c1), shape[0])
        own_at = (pixels // width - r0) * shape[1] + pixels % width - c0  # own pixels' places in the window's rays
        # One run of the window's rays (whole rows of it: `pixel_spans`): the own rows' shading as views, not copies;
        # one run of the film's pixels too (the window spans the image's width, or one row): written in place.
        run = own_at[-1] - own_at[0] + 1 == len(own_at)
        whole = run and pixels[-1] - pixels[0] + 1 == len(pixels)
        own = slice(int(own_at[0]), int(own_at[-1]) + 1) if run else own_at
        block = out[pixels[0] - start:pixels[-1] + 1 - start] if whole else \
            np.empty((len(pixels), len(CHANNELS)), dtype=np.float32)
        with self.clock.stage("camera rays"):
            origins, directions = self.camera.rays(rows, cols)
        shading = self.shade(origins, directions, occlude=False)
        del origins, directions
        level = shading.level
        with self.clock.stage("analytic AA"):
            sigma = self.stripe_offsets(shading)
            # Where the footprint may reach a stripe: σ moves by at most about |g_x| + |g_y| to a neighbour's centre
            # (a diagonal one), twice what it moves within the pixel. The bound holds where all 8 neighbours are on
            # the pixel's level; a pixel with a neighbour on another level (between two stripes, or where the
            # stripes crowd) gets the same bound with its neighbours' σ taken to its own level (`_across_levels`).
            # Only the span's rows and one on either side need to know (the edge test's neighbours).
            # Only the rows and columns around the surface can hold a stripe or an edge: the neighbour tests run
            # there alone. (The crop's border rows and columns see no surface, nor do the pixels beyond them, so the
            # edge-repeating pad of `neighbours` stands for those outer neighbours exactly.)
            hit_grid = shading.hits.hit.reshape(shape)
            hit_cols = np.flatnonzero(hit_grid.any(axis=0))
            hit_rows = np.flatnonzero(hit_grid.any(axis=1))
            cs = slice(max(0, hit_cols[0] - 1), min(shape[1], hit_cols[-1] + 2)) if len(hit_cols) else slice(0, 0)
            rs = slice(max(0, hit_rows[0] - 1), min(shape[0], hit_rows[-1] + 2)) if len(hit_rows) else slice(0, 0)
            crop = (rs.stop - rs.start, cs.stop - cs.start)
            grid = lambda x: x.reshape(shape + x.shape[1:])[rs, cs]  # noqa: E731 (a (rows, columns) view of the crop)
            grid_level, grid_sigma = grid(level), grid(sigma)
            want = np.zeros(shape, dtype=bool)
            if crop[1]:  # one compiled pass over the crop (`kernels.pixels.stripe_candidates`)
                stripe_candidates(grid_level, grid_sigma, float(self.stripe_reach), want[rs, cs])
                # `edge_pixels`' stripe candidates, before `_across_levels` narrows them: which face joins are
                # supersampled does not depend on that refinement (its film is the same bytes without it).
                candidate = want[rs, cs].copy()
                self._across_levels(shading, sigma, (rs, cs), want)
            want[:max(0, first - 1 - r0)] = False
            want[last + 2 - r0:] = False
        centre = self.centre_stripes(shading, rows, cols, sigma, want.ravel())
        edge = np.zeros(shape, dtype=bool)
        with self.clock.stage("analytic AA"):
            if crop[1]:
                # σ bending within the pixel (a fold of φ, a tight turn of the line) is not linear: where a
                # neighbour's σ on the same level strays from the plane σ + g·(Δx, Δy) by `BENDING` half widths,
                # supersample.
                # (`kernels.pixels.bent_flags`, in place: the bend is read from σ, g and the levels alone)
                bent_flags(grid_level, grid_sigma, grid(centre.grad[:, 0]), grid(centre.grad[:, 1]), grid(centre.near),
                           float(BENDING * self.half_width), grid(centre.untrusted))
                hits = shading.hits
                # The surface colour's factor k, the pixel's colour away from the stripes (a map mode's colours are
                # compared below): a step in it across two faces is an edge (`analytic.JOIN_COLOUR_STEP`).
                shade = self.surface_shade(shading) if shading.surface_rgb is None else None
                shade = np.ones(len(level)) if shade is None else shade
                edge[rs, cs] = edge_pixels(*(grid(x) for x in (hits.hit, hits.patch, level, centre.near, centre.blocked,
                                                               centre.untrusted)), candidate,
                                           *(grid(x) for x in (hits.P, hits.N, shade)),
                                           float(np.max(self.scene.render.surface_color)))
                if shading.surface_rgb is not None:  # a map mode: where its colour jumps (a band edge), supersample
                    rgb = grid(np.nan_to_num(shading.surface_rgb))
                    for other in neighbours(rgb):
                        edge[rs, cs] |= np.abs(other - rgb).max(axis=2) > MAP_STEP
            edge = edge.ravel()[own]
        mine = shading.take(own)
        rgba = self.colour(mine, np.where(centre.blocked[own], 0.0, centre.coverage[own]), 1, block[:, :4])
        fell_back = mine.hits.fallback.copy()
        fallbacks = int(fell_back.sum())
        rays = halo_rays
        edges = np.flatnonzero(edge)
        # Edge pixels' samples in chunks of at most the span's own pixel count: no more rays at once than the tile
        # was sized for (`tiling`, one ray per pixel).
        chunk = max(1, (stop - start) // (EDGE_SAMPLES * EDGE_SAMPLES))
        for part in np.array_split(edges, max(1, -(-len(edges) // chunk))):
            if len(part) == 0:
                continue
            rgba[part], samples, traced = self.supersample(rows[own][part], cols[own][part], EDGE_SAMPLES)
            rays += traced
            fallbacks += int(samples.hits.fallback.sum())
            fell_back[part] |= samples.hits.fallback.reshape(len(part), -1).any(axis=1)
        aovs = self.aovs(mine)
        aov_planes(aovs, block[:, 4:])
        if not whole and start % width == 0 and (stop - start) % width == 0:
            # Whole rows (`pixel_spans`): the block's pixels are the columns [c0, c1) of consecutive rows, one strided
            # copy into the tile's (rows, columns) view instead of a scatter by index.
            at = (low[0] - start) // width
            out.reshape(-1, width, len(CHANNELS))[at:at + len(low), c0:c1] = block.reshape(len(low), c1 - c0, -1)
        elif not whole:
            out[pixels - start] = block
        blocked = self._blocked_lines(mine, centre.blocked[own])
        if blocked is not None:  # of the window's own pixels: to the tile's (none outside the window)
            tile_blocked = np.zeros(stop - start, dtype=bool)
            tile_blocked[pixels - start] = blocked
            blocked = tile_blocked
        return Tile(start, stop, out, rays, fallbacks, int(fell_back.sum()), len(edges), blocked)

    def _across_levels(self, shading: Shading, sigma: np.ndarray, crop: tuple[slice, slice], want: np.ndarray) -> None:
        """``want`` (a (rows, columns) grid of the window's pixels) cleared in place where a pixel that
        `stripe_candidates` kept for a neighbour on another level is bounded away from its own stripe after all.

        The bound is `stripe_candidates`' own (both kernels call `kernels.pixels._may_reach`; here `clear_far`), |σ| − m
        > reach with m the largest |σ_n − σ| over the 8 neighbours (NaN ones passed over), each neighbour's σ_n taken to
        the pixel's level k (`modes.base.level_offset` at the neighbour's hit): σ is smooth across the switch of the
        nearest level, so it moves to a neighbour on another level as to any other. Between two stripes, where the
        nearest level switches, a third of the peer scene's candidates were such pixels, each costing the gradient's
        four surface evaluations (`centre_stripes`); where the stripes crowd σ_k moves by about a spacing to the next
        pixel and the pixel stays. A neighbour without a hit (no σ_k there) keeps the pixel, as before.
        """
        rs, cs = crop
        crop_want = want[rs, cs]
        found = np.empty((int(np.count_nonzero(crop_want)), 1 + len(NEIGHBOURS)), dtype=np.int64)
        count = level_crossings(shading.level.reshape(want.shape)[rs, cs], crop_want, found)  # compiled
        if count == 0:
            return
        # Crop places (the pixel, then its 8 neighbours: `kernels.pixels.level_crossings`) as the window's rays.
        row, col = np.divmod(found[:count], cs.stop - cs.start)
        rays = (row + rs.start) * want.shape[1] + col + cs.start
        at, nb = rays[:, 0], np.ascontiguousarray(rays[:, 1:].T)  # (pixels), (8, pixels)
        k, s0 = shading.level[at], sigma[at]
        sn = sigma[nb]
        cross = shading.level[nb] != k
        hits = shading.hits
        unknown = (cross & ~hits.hit[nb]).any(axis=0)
        where = np.nonzero(cross & hits.hit[nb])
        other = nb[where]
        if len(other):  # σ to the pixel's level at the neighbours on another level, in one pass
            points = SurfacePoints(*(np.take(x, other, axis=0) for x in (hits.P, hits.N, shading.s)), hits.patch[other],
                                   hits.u[other], hits.v[other])
            sn[where] = level_offset(self.mode, points, k[where[1]])
        clear_far(sn, s0, unknown, float(self.stripe_reach), at, want.reshape(-1))  # the bound, compiled once

    def stripe_offsets(self, shading: Shading) -> np.ndarray:
        """Per ray the signed offset σ from its nearest level's centre (`modes.base.level_offset`), NaN where none is:
        as the mode's stripes gave it (`Stripes.offset`), else evaluated."""
        if shading.offset is not None:
            return shading.offset
        hits, level = shading.hits, shading.level
        sigma = np.full(len(level), np.nan)
        idx = np.flatnonzero(level >= 0)
        if len(idx):
            sigma[idx] = level_offset(self.mode, SurfacePoints(hits.P[idx], hits.N[idx], shading.s[idx], hits.patch[idx],
                                                               hits.u[idx], hits.v[idx]), level[idx])
        return sigma

    def centre_stripes(self, shading: Shading, rows: np.ndarray, cols: np.ndarray, sigma: np.ndarray,
                       want: np.ndarray) -> "CentreStripes":
        """Per centre ray where ``want``: the screen gradient g of its offset σ (`stripe_offsets`), the stripe's box
        coverage, and the flags the edge test needs (`analytic`); elsewhere no stripe is near.

        g is a central difference over the pixel of the real pipeline: the exact surface point and normal at
        (u, v) ± ½ (du, dv) (the footprint of `analytic.uv_footprint`), the eye ray to it, the reflected
        direction and the mode's `level_offset`.
        """
        n_rays = len(shading.hits.hit)
        grad = np.full((n_rays, 2), np.nan)
        level = shading.level
        idx = np.flatnonzero(want & (level >= 0))
        hits = shading.hits
        with self.clock.stage("analytic AA"):
            if len(idx):
                # np.take: the rows of x[idx], gathered ~4× faster for (N, 3) arrays (as in `shade`)
                rows3 = lambda x, at=idx: np.take(x, at, axis=0)  # noqa: E731
                patch, u, v, n = hits.patch[idx], hits.u[idx], hits.v[idx], rows3(hits.N)
                k = level[idx]
                # S_u, S_v as the tracer had them at the hit; the mesh-normals path has none (its P is on the mesh).
                Su, Sv = (rows3(hits.Su), rows3(hits.Sv)) if self.vertex_normals is None else \
                    self.surfaces.evaluate(patch, u, v)[1:3]
                steps = uv_footprint(self.camera, rows[idx], cols[idx], rows3(hits.P), n, Su, Sv)
                # The four ends (u, v) ± ½ (du, dv)/dx and /dy, each step shortened to the share of it that stays in
                # the patch's domain (it is clamped there): one compiled pass (`kernels.pixels.footprint_ends`); σ at
                # all of them in one pass (rows are independent).
                ends_u, ends_v, shares = np.empty((3, 4 * len(idx)))
                footprint_ends(u, v, steps, *self.surfaces.domains(patch), ends_u, ends_v, shares)
                shares = shares.reshape(4, -1)
                ends = self._offset_at(np.tile(patch, 4), ends_u, ends_v,
                                       np.tile(n, (4, 1)), np.tile(k, 4)).reshape(4, -1)
                with np.errstate(divide="ignore", invalid="ignore"):
                    for axis in range(2):
                        grad[idx, axis] = (ends[2 * axis] - ends[2 * axis + 1]) / \
                            (0.5 * (shares[2 * axis] + shares[2 * axis + 1]))
            span = np.abs(grad[:, 0]) + np.abs(grad[:, 1])
            with np.errstate(invalid="ignore"):
                known = np.isfinite(span)
                near = want & (level >= 0) & (~known | (np.abs(sigma) - 0.5 * span <= self.stripe_reach))
                untrusted = near & ~known
            # The spacing to the next level in σ's unit where a trusted stripe is near (none: a single level, nothing
            # to confuse it with); `untrusted` reads it nowhere else.
            ok = np.flatnonzero(near & known)
            if len(ok):
                k = level[ok]
                other = self.neighbour_level[k]
                points = SurfacePoints(*(np.take(x, ok, axis=0) for x in (hits.P, hits.N, shading.s)), hits.patch[ok],
                                       hits.u[ok], hits.v[ok])
                gap = np.where(other == k, np.inf, np.abs(sigma[ok] - level_offset(self.mode, points, other)))
                with np.errstate(invalid="ignore"):
                    untrusted[ok] = span[ok] > TRUSTED_SPAN * gap
            coverage = np.zeros(n_rays)
            coverage[ok] = stripe_coverage(sigma[ok], grad[ok, 0], grad[ok, 1], self.half_width, self.blur)
        blocked = np.zeros(n_rays, dtype=bool)
        if self.mode.along_ray:  # up to the nearest level along s (`Stripes.level_t`)
            test = np.flatnonzero(near)
            if len(test):
                R, n, s = (np.take(x, test, axis=0) for x in (hits.P, hits.N, shading.s))
                start = self.accelerator.surface_origins(R, n, hits.patch[test])
                with self.clock.stage("occlusion (Embree)"):
                    blocked[test] = occluded(self.accelerator, self.tessellation, self.surfaces, start, s,
                                             shading.level_t[test])
        return CentreStripes(sigma, grad, coverage, near, blocked, untrusted)

    def _offset_at(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray, n0: np.ndarray, level: np.ndarray) -> np.ndarray:
        """σ to ``level`` at surface points (patch, u, v) seen by the camera: the exact point and normal (turned to the
        side of the nearby normal ``n0``), the eye ray to the point, reflection (eq. 3) and the mode's offset."""
        R, n, _, s = seen_at(self.surfaces, self.camera, patch, u, v)
        n[np.einsum("ij,ij->i", n, n0) < 0] *= -1.0
        return level_offset(self.mode, SurfacePoints(R, n, s, patch, u, v), level)

    def spans(self, rays_per_tile: int = RAYS_PER_TILE, threads: int = 1) -> list[tuple[int, int]]:
        """`pixel_spans` of the image; with ``samples = "analytic"``, by the rays of its `window`."""
        window = self.window if self.scene.image.samples == ANALYTIC else None
        return pixel_spans(self.scene.image, rays_per_tile, window, threads)

    def stream(self, threads: int | None = None, rays_per_tile: int = RAYS_PER_TILE,
               stats: RenderStats | None = None, film: Film | None = None) -> Iterator[Tile]:
        """Tiles in image order, rendered ``threads`` at a time.

        At most ``threads`` tiles render at once and ``threads`` × (1 + `TILES_AHEAD`) are handed to the pool, the
        others queued or finished and waiting to be taken (their pixels only), so memory is bounded by the tile size,
        not the image size. ``stats`` (if given) counts rays
        and fallbacks as tiles are yielded. ``film``: each tile is rendered straight into its span of it
        (`Film.span`; the tile's pixels are that view), else into an array of its own.
        """
        image = self.scene.image
        threads = threads or default_threads()
        clearance.expect(self.accelerator, image.width * image.height * rays_per_pixel(image.samples), threads)
        for tile in self._tiles_in_order(threads, self.spans(rays_per_tile, threads), film):
            if stats is not None:
                stats.rays += tile.rays
                stats.fallbacks += tile.fallbacks
                stats.fallback_pixels += tile.fallback_pixels
                stats.supersampled += tile.supersampled
            yield tile

    def _tiles_in_order(self, threads: int, spans: list[tuple[int, int]], film: Film | None = None) -> Iterator[Tile]:
        # Each span's own block of the film (tiles write disjoint rows of it), or None: a new array per tile.
        into = (lambda start, stop: None) if film is None else film.span  # noqa: E731
        if threads == 1:  # one tile at a time, in this thread (batch workers)
            yield from (self.render_span(*span, into(*span)) for span in spans)
            return
        todo = iter(spans)
        with ThreadPoolExecutor(max_workers=threads) as pool:
            pending: deque[Future[Tile]] = deque(pool.submit(self.render_span, *span, into(*span))
                                                 for span in itertools.islice(todo, threads * (1 + TILES_AHEAD)))
            try:
                while pending:
                    tile = pending.popleft().result()
                    pending.extend(pool.submit(self.render_span, *span, into(*span))
                                   for span in itertools.islice(todo, 1))
                    yield tile
            finally:  # the consumer stopped early (error, Ctrl-C): do not render the rest
                for future in pending:
                    future.cancel()

    def new_stats(self) -> RenderStats:
        image = self.scene.image
        self.clock = StageClock()
        return RenderStats(image.width, image.height, image.samples)

    def run(self, sink: Callable[[Tile], None], threads: int | None = None, rays_per_tile: int = RAYS_PER_TILE,
            progress: Callable[[int], None] | None = None, film: Film | None = None) -> RenderStats:
        """Render the whole image, handing each tile to ``sink`` in image order; ``progress(pixels)`` after each.
        ``film``: the tiles are rendered straight into it (`stream`)."""
        start = time.perf_counter()
        stats = self.new_stats()
        for tile in self.stream(threads, rays_per_tile, stats, film):
            sink(tile)
            stats.tiles += 1
            if progress:
                progress(tile.stop - tile.start)
        stats.seconds = time.perf_counter() - start
        stats.stages = dict(self.clock.seconds)
        return stats

    def render(self, progress: Callable[[int], None] | None = None, threads: int | None = None,
               rays_per_tile: int = RAYS_PER_TILE) -> RenderResult:
        """Render the whole image into an in-memory `Film`; ``progress(pixels)`` is called as tiles finish."""
        film = Film(self.scene.image.width, self.scene.image.height)
        # Each tile is rendered into its span of the film: nothing left to copy when it comes.
        stats = self.run(lambda tile: None, threads, rays_per_tile, progress, film)
        return RenderResult(self.scene, film, stats)
