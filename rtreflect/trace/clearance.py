"""Clearance cones: a proof, per ray, that the any-hit test past a mesh hit (`tracing.trace`) would find nothing.

After a ray's mesh hit on triangle T, `trace` asks Embree whether any triangle lies on the segment from just past
it (t + skip) to its limit (the kept exact hit plus `tracing._band`): a nearer exact hit could be led by a later
mesh hit. Almost none does, yet the query costs ~90 ns a ray (bench/render_bench.py: 1.5M such queries a frame).
Where the mesh around T leaves that segment clear by a margin Embree's float32 rounding cannot close, the answer
is known to be "nothing" and the query is not asked: every ray's result stays the same, bit for bit.

**The cone** (per triangle T, unit normal n, a corner a, centroid c_T, r_T its farthest corner from c_T). With
h(X) = n·(X − a) the height over T's plane and λ(X) the distance in that plane from X's foot to T, the *slope*
τ_T bounds |h| ≤ τ_T λ on every other triangle that may meet the ball B(c_T, r_T + R) (R = `REACH_CHORDS` chord
errors + `REACH_ROUNDINGS` float32 roundings): there the mesh lies in a double cone opening away from T. A ray past
T's plane by g at the segment's start X₀ goes deeper at c = |D·n| while its foot moves at w = |D − (D·n)n|: at
length s its depth is g + cs, its foot within λ₀ + ws of T (λ₀: X₀'s foot). A mesh point within ε of it would have
|h| ≥ g + cs − ε and λ ≤ λ₀ + ws + ε; so where g + cs − ε > τ_T (λ₀ + ws + ε) for s = 0 and s = L (both sides
affine in s: then for every s between) and the segment's ε-neighbourhood stays in the ball, no triangle lies
within ε of the segment: T itself neither (its points have h = 0 < g − ε). ε = `EMBREE_ROUNDING`.

**The slope** of a pair (T, T'): a line in T's plane through an edge of T (or through a corner, across the bisector
of its angle) has T on its inner side, so its signed distance δ(X) = o·(X − p) ≤ λ(X); h and δ are affine on T',
so |h| ≤ ρ δ on all of T' with ρ the largest |h_k|/δ_k over its corners, wherever every δ_k ≥ 0 (a corner T'
shares with T has h = 0: the same float32 point, `canon`). The least ρ over T's six lines bounds the pair (none
placed so: ∞); τ_T is the largest over the pairs (`kernels.clearance.ball_slopes`). A neighbour across an edge
bent by β gives ρ = tan β–like values: rays steeper than the mesh's local bend are cleared, grazing ones asked.

The pairs come from a uniform grid of cubes per class of triangle size (radii within a factor 2, so a few large
triangles beside many small ones do not widen every search), searched and measured in one compiled pass on
the render's threads (`expect`; else `BUILD_THREADS`). Built once per BVH (thread-safe), used only in traces of at least `MIN_RAYS` rays (the
second look's finer mesh, traced for a few suspects, never pays), and only once the BVH has traced as many rays
without them as the build would have saved by then (`PAYBACK_RAYS_PER_TRIANGLE`), or at once where the render
under way will trace that many (`expect`).
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from .accelerator import Accelerator
from ..geometry.tessellation import Tessellation, unique_rows
from ..kernels import clearance as kernel

#: The ball's reach beyond T's corners, in chord errors (the scene's largest): a segment past a mesh hit is the
#: kept hit's distance from it (~ a chord error over |N·D|) plus the band (`BAND_CHORDS` chord errors over |N·D|):
#: 16 covers |N·D| down to ~0.2, below which the cone's slope rarely clears a ray anyway.
REACH_CHORDS = 16.0
#: ... plus this many float32 roundings of the scene (`tracing.float32_rounding`): the band's slack and the skip
#: past the mesh hit, which a flat scene's (zero chord error) segment still spans.
REACH_ROUNDINGS = 4.0
#: Embree's error in placing a triangle against a ray, as a fraction of `tracing.float32_rounding` (~17 float32
#: units in the last place of the scene's extent + largest coordinate): the query's origin is rounded to float32
#: (½ ulp a coordinate), its direction too (2⁻²⁴ over the segment, shorter than the extent), and Woop et al.'s
#: watertight test ("Watertight ray/triangle intersection", JCGT 2013) rounds each corner's offset from it (½ ulp)
#: before its exact edge tests: ~2 ulps in all. A quarter (~4 ulps) leaves twice that. (`float32_rounding` is 8.4–16.8
#: ulps across a binade.) The Accelerator does not ask Embree for its robust mode, so the margin is also checked
#: against Embree itself: over ~215,000 cleared segments of 11 shipped and sweep inputs (half the rays within 3° of
#: the plane of the triangle they aim at), none wrong at a quarter of this margin, a few (hood, g1_join) at none.
EMBREE_FRACTION = 0.25
#: The cones are built only where the reach is at most this many median triangle radii: the ball then holds about a
#: triangle's ring of neighbours (the bench scenes: 0.46 and 0.63); past it the pairs grow as the reach's cube and
#: the cones clear little (parts/plate.step at 2.6: 16.6M pairs, 1.5 s CPU, every slope ∞ where its faces' meshes
#: overlap along their seams; the teapot at 2.0: 55 % finite).
REACH_PER_RADIUS = 1.0
#: Traces of fewer rays do not use (or count towards) the cones: their BVH, such as the second look's finer mesh,
#: may never see enough rays to repay them.
MIN_RAYS = 4096
#: The cones are built once a BVH has traced this many rays per triangle without them, as many as their build
#: would have saved by then (ski rental: whatever the renders to come, at most twice the cheaper of never and at
#: once), or at a render's first trace where that render alone traces this many (`expect`: the rays to come are
#: known). Measured on `bench/render_bench.py`'s scene (25,088 triangles, one thread, CPU, a loaded machine,
#: A/B in one process): the build costs 0.145 s (0.142-0.149), ~5.8 µs a triangle; prebuilt, they save
#: 0.153 s (0.107-0.211) of a full-HD render's ~2.5 s, ~74 ns a ray (52-102): 78 rays a triangle, rounded to 80.
#: A full-HD render at one sample (83 a triangle) builds them first thing and about breaks even; the renders of
#: that scene after it save the whole 0.15 s. The saving is per ray that hits the mesh (72 % of these): the peer
#: scene (bench/peer.toml, 4,608 triangles, 17 % hit) builds them at 112 rays a triangle for 0.024 s and saves
#: 0.008-0.019 s a render, so its first render costs that much more (counting hits instead of rays would not).
PAYBACK_RAYS_PER_TRIANGLE = 80
#: Triangles whose corner angle at their first corner has a smaller sine get no cone (the normal's rounding).
SLIVER_SINE = 1e-9
#: Relative pad on the radii and distances the pairs are chosen by (float64 rounding: a superset is safe).
PAD = 1e-9
#: The grid's cube numbers are found with this relative pad on the scene's scale (`_slopes`): a superset is safe.
GRID_PAD = 4e-9
#: A grid's cube side, in a search's half-width (`_slopes`): finer cubes visit fewer far triangles, more cubes.
GRID_CELL = 0.5
#: Threads of the slopes' kernel: the build runs while a render's other tile threads wait for it (`cones`'s lock),
#: so on their cores: the render's thread count where it announced itself (`expect`), else this.
BUILD_THREADS = min(2, os.cpu_count() or 1)
#: A grid's cubes per triangle at most (`_slopes`).
GRID_CUBES_PER_TRIANGLE = 4.0

_lock = threading.Lock()


@dataclass(frozen=True)
class Cones:
    """Per triangle of a BVH (its float32 corners, in its centred coordinates): the data `clear_past` reads."""

    corners: np.ndarray  # (F, 9)
    normal: np.ndarray  # (F, 3) unit; zero where degenerate
    centre: np.ndarray  # (F, 3)
    radius: np.ndarray  # (F,)
    slope: np.ndarray  # (F,) τ_T, ∞ where no cone is known
    offset: np.ndarray  # (3,) the BVH's origin in world coordinates
    rounding: float  # ε: Embree's rounding
    reach: float  # R

    def drop(self, origins: np.ndarray, directions: np.ndarray, prim: np.ndarray, start: np.ndarray,
             limit: np.ndarray, go: np.ndarray) -> None:
        """``go`` False, in place, for the rays whose segment from ``start`` to ``limit`` past their mesh hit on
        triangle ``prim`` provably meets no triangle (module doc)."""
        f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
        kernel.clear_past(self.corners, self.normal, self.centre, self.radius, self.slope, f64(origins),
                          f64(directions), self.offset, np.ascontiguousarray(prim, dtype=np.int64), f64(start),
                          f64(limit), self.rounding, self.reach, go)


def cones(accelerator: Accelerator, tessellation: Tessellation, rounding: float, rays: int) -> Cones | None:
    """The BVH's clearance cones for a trace of ``rays`` rays (``rounding``: `tracing.float32_rounding` of the
    tessellation): None until the BVH has traced, or a render under way will have traced (`expect`),
    `PAYBACK_RAYS_PER_TRIANGLE` rays a triangle, then built once, or None for good where they would cost more than
    they clear (`REACH_PER_RADIUS`)."""
    state = accelerator.__dict__
    if "_cones" not in state:
        with _lock:
            if "_cones" not in state:
                traced = state.get("_traced_without_cones", 0) + rays
                state["_traced_without_cones"] = traced
                if max(traced, state.get("_expected_by", 0)) < PAYBACK_RAYS_PER_TRIANGLE * len(accelerator._faces):
                    return None
                state["_cones"] = build(accelerator, tessellation, rounding, REACH_PER_RADIUS,
                                        state.get("_build_threads", BUILD_THREADS))
    return state["_cones"]


def expect(accelerator: Accelerator, rays: int, threads: int = BUILD_THREADS) -> None:
    """A render about to trace at least ``rays`` rays on the BVH with ``threads`` threads: where they reach the
    payback, the cones are built at its first trace, on as many threads, rather than once that many are traced (the
    rays to come are known, not rented)."""
    state = accelerator.__dict__
    with _lock:
        state["_expected_by"] = state.get("_traced_without_cones", 0) + rays
        state["_build_threads"] = max(1, int(threads))


def build(accelerator: Accelerator, tessellation: Tessellation, rounding: float,
          reach_per_radius: float = np.inf, threads: int = BUILD_THREADS) -> Cones | None:
    """The cones of the BVH's triangles (module doc): slopes over every pair that may meet a triangle's ball (None
    where the reach exceeds ``reach_per_radius`` median triangle radii)."""
    vertices32 = accelerator._vertices  # the BVH's own float32 corners: the triangles Embree tests
    faces = np.ascontiguousarray(accelerator._faces, dtype=np.int64)
    vertices = vertices32.astype(np.float64)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    centre = (a + b + c) / 3.0
    radius = np.sqrt(np.max([np.einsum("ij,ij->i", x - centre, x - centre) for x in (a, b, c)], axis=0))
    radius = radius * (1.0 + PAD) + PAD * rounding
    chord = float(tessellation.chord_error.max(initial=0.0))
    reach = REACH_CHORDS * chord + REACH_ROUNDINGS * rounding
    if len(faces) == 0 or reach > reach_per_radius * float(np.median(radius)):
        return None
    normal = np.cross(b - a, c - a)
    size = np.linalg.norm(normal, axis=1)
    # A sliver's float64 normal is off by ~1e-16/sin θ, so its own corners would not lie at height 0: no cone.
    good = size > SLIVER_SINE * np.linalg.norm(b - a, axis=1) * np.linalg.norm(c - a, axis=1)
    normal = np.divide(normal, size[:, None], out=np.zeros_like(normal), where=good[:, None])
    good &= np.isfinite(normal).all(axis=1)
    normal = np.ascontiguousarray(normal)
    # A corner's first copy (by its float32 coordinates): faces meeting along a seam share points, not indices.
    first_copy = unique_rows(vertices32)
    canon = np.ascontiguousarray(first_copy.reshape(-1)[faces], dtype=np.int64)
    slope = np.where(good, 0.0, np.inf)
    _slopes(vertices, faces, canon, normal, np.ascontiguousarray(centre), radius, reach, slope, threads)
    corners = np.ascontiguousarray(vertices[faces].reshape(-1, 9))
    return Cones(corners, normal, np.ascontiguousarray(centre), radius, slope,
                 np.asarray(accelerator.centre, dtype=np.float64), EMBREE_FRACTION * rounding, reach)


def _slopes(vertices: np.ndarray, faces: np.ndarray, canon: np.ndarray, normal: np.ndarray, centre: np.ndarray,
            radius: np.ndarray, reach: float, slope: np.ndarray, threads: int = BUILD_THREADS) -> None:
    """τ_T into ``slope`` over every pair with |c_T − c_T'| ≤ (r_T + reach + r_T')(1 + `PAD`): per class of triangle
    size (radii within a factor 2, so a few large triangles beside many small ones do not widen every search) a
    uniform grid of cubes about a search's width files the class's triangles by centre, and every T meets those of
    the cubes within r_T + reach + the class's largest radius (`kernels.clearance.ball_slopes`)."""
    count = len(centre)
    if count == 0:
        return
    floor = max(float(radius.min()), 1e-300)
    size_class = np.floor(np.log2(radius / floor)).astype(np.int64)
    # The cube numbers' float64 rounding, as a distance: a superset of the cubes is safe.
    margin = GRID_PAD * (float(np.abs(centre).max()) + float(radius.max()) + reach)
    typical = float(np.median(radius))
    for k in np.unique(size_class):
        group = np.flatnonzero(size_class == k)
        widest = float(radius[group].max())
        low = centre[group].min(axis=0) - margin
        span = centre[group].max(axis=0) + margin - low
        cell = max(GRID_CELL * (typical + reach + widest), margin)
        # Not many more cubes than triangles: a class's few triangles scattered far apart need no fine grid.
        cell = max(cell, float(np.prod(span + cell)) ** (1.0 / 3.0) / (GRID_CUBES_PER_TRIANGLE * len(group)) ** (1.0 / 3.0))
        cells = np.floor(span / cell).astype(np.int64) + 1
        where = np.clip(np.floor((centre[group] - low) / cell).astype(np.int64), 0, cells - 1)
        number = (where[:, 0] * cells[1] + where[:, 1]) * cells[2] + where[:, 2]
        order = np.argsort(number, kind="stable")
        start = np.zeros(int(np.prod(cells)) + 1, dtype=np.int64)
        np.cumsum(np.bincount(number, minlength=len(start) - 1), out=start[1:])
        members = np.ascontiguousarray(group[order])
        grid = (low, cell, cells, start, members, widest, margin)
        # Each T's slope is its own: the threads take disjoint runs of T (the kernel releases the GIL).
        bounds = np.linspace(0, count, threads + 1).astype(np.int64)
        run = lambda lo, hi: kernel.ball_slopes(vertices, faces, canon, normal, centre, radius, size_class,  # noqa: E731
                                                reach, PAD, *grid, int(lo), int(hi), slope)
        if threads == 1:
            run(0, count)
        else:
            with ThreadPoolExecutor(threads) as pool:
                list(pool.map(run, bounds[:-1], bounds[1:]))
