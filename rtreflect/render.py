"""The reflection-line integrator: scene → film, tile by tile (DESIGN.md, "The pipeline").

Per tile of pixel rows: camera rays for the s×s samples → exact hits → reflected
directions → light tubes and the occlusion test → coverage colour; plus the
pixel-centre rays → AOVs. Tiles are independent, so two threads (Embree and most
numpy kernels release the GIL) render them side by side, deterministically.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .accelerator import Accelerator
from .camera import Camera, sample_offsets
from .film import Film, aov_planes, coverage_color
from .lights import TubeLights, reflect
from .scene import Scene
from .surfaces import SurfaceSet
from .tessellation import tessellate
from .tracing import Hits, trace

#: Rays per tile: bounds memory (a few hundred bytes a ray) while keeping numpy's per-call overhead small.
RAYS_PER_TILE = 1 << 16


@dataclass
class RenderStats:
    width: int
    height: int
    samples: int
    rays: int = 0
    fallbacks: int = 0  # samples whose Newton refinement failed (mesh hit kept)
    seconds: float = 0.0
    stages: dict[str, float] = field(default_factory=dict)

    @property
    def mrays_per_second(self) -> float:
        return self.rays / self.seconds / 1e6 if self.seconds > 0 else 0.0


@dataclass
class RenderResult:
    scene: Scene
    film: Film
    stats: RenderStats


class Renderer:
    """Everything built once per scene: patches, tessellation, BVH, camera, tubes."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.surfaces = SurfaceSet(list(scene.surfaces))
        self.tessellation = tessellate(scene.surfaces, scene.render.tessellation)
        self.accelerator = Accelerator(self.tessellation)
        self.camera = Camera(scene.camera, scene.image.width, scene.image.height)
        self.lights = TubeLights.from_spec(scene.lights)

    # -- one batch of rays ---------------------------------------------------------------
    def shade(self, origins: np.ndarray, directions: np.ndarray) -> tuple[Hits, np.ndarray, np.ndarray]:
        """Exact hits, reflected directions s and 'lit' flags (some tube within its radius, unoccluded)."""
        hits = trace(self.accelerator, self.tessellation, self.surfaces, origins, directions)
        s = np.full_like(directions, np.nan)
        lit = np.zeros(len(origins), dtype=bool)
        idx = np.flatnonzero(hits.hit)
        if len(idx) == 0:
            return hits, s, lit
        R, n = hits.P[idx], hits.N[idx]
        # a, the unit vector towards the eye, is the reversed ray direction for either camera.
        s[idx] = reflect(-directions[idx], n)
        candidate, t_tube = self.lights.candidates(self.lights.distances(R, s[idx]))
        cand = np.flatnonzero(candidate)
        if len(cand):
            # Start the occlusion ray off the surface by more than the mesh's chord error, so the
            # mesh standing in for the surface does not shadow the point it approximates.
            eps = (2.0 * self.tessellation.chord_error[hits.patch[idx[cand]]]
                   + 1e-6 * (self.tessellation.extent + np.abs(R[cand]).max(axis=1)))
            blocked = self.accelerator.occluded(R[cand] + eps[:, None] * n[cand], s[idx[cand]], t_tube[cand])
            lit[idx[cand]] = ~blocked
        return hits, s, lit

    def pixel_aovs(self, rows: np.ndarray, cols: np.ndarray) -> dict[str, np.ndarray]:
        """Float64 AOVs of the pixel-centre rays (DESIGN.md channel list), plus the hits themselves."""
        origins, directions = self.camera.rays(rows, cols)
        hits, s, lit = self.shade(origins, directions)
        return self._aovs(hits, s, lit, origins, directions)

    def _aovs(self, hits: Hits, s, lit, origins, directions) -> dict[str, np.ndarray]:
        n = len(hits.hit)
        f = np.full(n, np.nan)
        line_id = np.full(n, -1.0)
        line_dist = np.full(n, np.nan)
        idx = np.flatnonzero(hits.hit)
        if len(idx):
            R, si = hits.P[idx], s[idx]
            f[idx] = self.lights.ulmet_f(R, si)
            k, d = self.lights.nearest(self.lights.distances(R, si))
            line_id[idx], line_dist[idx] = k, d
        return {"P": hits.P, "N": hits.N, "u": hits.u, "v": hits.v, "patch": hits.patch.astype(np.float64),
                "Z": hits.t, "f": f, "line.id": line_id, "line.dist": line_dist, "s": s, "lit": lit,
                "hit": hits.hit, "fallback": hits.fallback, "origins": origins, "directions": directions}

    # -- tiles ---------------------------------------------------------------------------
    def render_rows(self, row0: int, row1: int) -> tuple[np.ndarray, np.ndarray, int, int]:
        """RGBA (P, 4) and AOVs (P, 13) of pixel rows [row0, row1), with ray and fallback counts."""
        width, s = self.scene.image.width, self.scene.image.samples
        rows, cols = np.divmod(np.arange(row0 * width, row1 * width), width)
        offsets = sample_offsets(s)
        ns = len(offsets)
        centre = ns // 2 if s % 2 == 1 else None  # for odd s the centre sample is the pixel centre
        origins, directions = self.camera.rays(np.repeat(rows, ns), np.repeat(cols, ns), np.tile(offsets, (len(rows), 1)))
        hits, refl, lit = self.shade(origins, directions)
        rgba = coverage_color(hits.hit.reshape(-1, ns), lit.reshape(-1, ns), self.scene.render.surface_color,
                              self.scene.render.line_color, self.scene.render.background)
        fallbacks = int(hits.fallback.sum())
        rays = len(origins)
        if centre is not None:
            pick = np.arange(len(rows)) * ns + centre
            sub = Hits(*(getattr(hits, k)[pick] for k in Hits.__dataclass_fields__))
            aovs = self._aovs(sub, refl[pick], lit[pick], origins[pick], directions[pick])
        else:
            aovs = self.pixel_aovs(rows, cols)
            rays += len(rows)
        return rgba, aov_planes(aovs), rays, fallbacks

    def tiles(self) -> list[tuple[int, int]]:
        width, height, s = self.scene.image.width, self.scene.image.height, self.scene.image.samples
        rows_per_tile = max(1, RAYS_PER_TILE // (width * (s * s + 1)))
        return [(r, min(r + rows_per_tile, height)) for r in range(0, height, rows_per_tile)]

    def render(self, progress: Callable[[int], None] | None = None, threads: int | None = None) -> RenderResult:
        """Render the whole image; ``progress(pixels)`` is called as tiles finish."""
        start = time.perf_counter()
        image = self.scene.image
        film = Film(image.width, image.height)
        stats = RenderStats(image.width, image.height, image.samples)
        threads = threads or min(2, os.cpu_count() or 1)

        def work(tile: tuple[int, int]) -> tuple[int, int]:
            rgba, aovs, rays, fallbacks = self.render_rows(*tile)
            film.put(tile[0], tile[1], rgba, aovs)  # tiles own disjoint rows: no lock needed
            return rays, fallbacks

        with ThreadPoolExecutor(max_workers=threads) as pool:
            tiles = self.tiles()
            for tile, (rays, fallbacks) in zip(tiles, pool.map(work, tiles)):
                stats.rays += rays
                stats.fallbacks += fallbacks
                if progress:
                    progress((tile[1] - tile[0]) * image.width)
        stats.seconds = time.perf_counter() - start
        return RenderResult(self.scene, film, stats)


def render_scene(scene: Scene, progress: Callable[[int], None] | None = None, threads: int | None = None) -> RenderResult:
    return Renderer(scene).render(progress, threads)
