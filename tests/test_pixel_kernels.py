"""Compiled per-pixel kernels (kernels/pixels.py): the same bits as the numpy forms they replace (issue 14).

The renderer's output at samples = 1..N must not move by a bit when its fixed per-pixel costs are compiled:
each kernel is held here against the numpy form it replaced (kept in this file only, as the reference),
over random inputs with the awkward values (zeros, NaN, ties, infinities), and against a geometric witness
where one exists (camera rays project back to their pixel positions; a culled ray meets no triangle).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rtreflect.exchange.scene import load_scene
from rtreflect.integrator import film
from rtreflect.integrator.analytic import hard_coverage, neighbours, trapezoid_cdf
from rtreflect.integrator.cull import BOX_MARGIN, ORIGIN_MARGIN, TINY, RayBox
from rtreflect.kernels.pixels import (bent_flags, bvh_rays, clear_far, edge_flags, footprint_ends, level_crossings,
                                      scatter_picked, spread_rows, stripe_candidates)
from rtreflect.trace.camera import Camera, sample_offsets

ROOT = Path(__file__).resolve().parent.parent
NEIGHBOURS = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc)


# -- the numpy forms replaced (references) --------------------------------------------------------------------------

def numpy_rays(camera: Camera, rows, cols, offsets=None):
    rows, cols = np.asarray(rows, dtype=np.float64), np.asarray(cols, dtype=np.float64)
    oy, ox = (0.5, 0.5) if offsets is None else (offsets[..., 0], offsets[..., 1])
    x = 2.0 * (cols + ox) / camera.width - 1.0
    y = 1.0 - 2.0 * (rows + oy) / camera.height
    w, r, q = camera.basis
    half_w, half_h = camera._half_extents()
    x, y = (np.ravel(a) for a in np.broadcast_arrays(x, y))
    if camera.orthographic:
        origins = camera.spec.eye + (x * half_w)[:, None] * r + (y * half_h)[:, None] * q
        return origins, np.broadcast_to(w, origins.shape).copy()
    a, b = x * half_w, y * half_h
    c = [w[k] + a * r[k] + b * q[k] for k in range(3)]
    length = np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
    origins = np.empty((len(a), 3))
    origins[:] = camera.spec.eye
    return origins, np.stack([c[k] / length for k in range(3)], axis=1)


def numpy_may_hit(box: RayBox, origins, directions):
    centre = 0.5 * (box.low + box.high)
    grow = BOX_MARGIN * float(np.linalg.norm(box.high - box.low)) + ORIGIN_MARGIN * float(np.abs(origins - centre).max())
    low, high = box.low - grow, box.high + grow
    near, far = np.full(len(origins), -np.inf), np.full(len(origins), np.inf)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for k in range(3):
            d = directions[:, k]
            inv = 1.0 / np.where(d == 0.0, TINY, d)
            t1, t2 = (low[k] - origins[:, k]) * inv, (high[k] - origins[:, k]) * inv
            np.fmax(near, np.minimum(t1, t2), out=near)
            np.fmin(far, np.maximum(t1, t2), out=far)
        return np.flatnonzero(~((far < near) | (far < 0.0)))


def numpy_cdf(z, a, b):
    hi, lo = np.maximum(a, b), np.minimum(a, b)
    t = np.clip(z + 0.5 * (hi + lo), 0.0, hi + lo)
    with np.errstate(divide="ignore", invalid="ignore"):
        rise = t * t / (2.0 * hi * lo)
        fall = 1.0 - (hi + lo - t) ** 2 / (2.0 * hi * lo)
        middle = (t - 0.5 * lo) / hi
    cdf = np.where(t <= lo, np.where(lo > 0, rise, 0.0), np.where(t >= hi, np.where(lo > 0, fall, 1.0), middle))
    return np.where(hi > 0, cdf, (z >= 0).astype(np.float64))


def inside(shape):
    padded = np.pad(np.ones(shape, dtype=bool), 1, constant_values=False)
    for dr, dc in NEIGHBOURS:
        yield padded[1 + dr:1 + dr + shape[0], 1 + dc:1 + dc + shape[1]]


# -- camera rays ----------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_camera_rays_are_the_numpy_contract_to_the_bit_and_project_back_to_their_pixel(projection):
    # a camera along no axis: every term of w + x·h_w·r + y·h_h·q counts in every coordinate
    spec = replace(load_scene(ROOT / "bench" / "peer.toml").camera, projection=projection, view_height=2.5,
                   eye=np.array([1.3, -3.2, 2.4]), look_at=np.array([0.2, 0.1, -0.3]), up=np.array([0.1, 0.0, 1.0]))
    camera = Camera(spec, 97, 61)
    rows, cols = np.divmod(np.arange(97 * 61), 97)
    rng = np.random.default_rng(5)
    for offsets in (None, np.array([0.25, 0.75]), rng.uniform(size=(len(rows), 2))):
        got, want = camera.rays(rows, cols, offsets), numpy_rays(camera, rows, cols, offsets)
        assert all(np.array_equal(g, w) for g, w in zip(got, want))
        o = np.full((len(rows), 2), 0.5) if offsets is None else np.broadcast_to(offsets, (len(rows), 2))
        points = got[0] + 2.0 * got[1]  # a point on each ray projects to the pixel position it was cast through
        np.testing.assert_allclose(camera.project(points), np.column_stack([cols + o[:, 1], rows + o[:, 0]]), atol=1e-9)
    offsets = sample_offsets(4)
    got = camera.sample_rays(rows[::7], cols[::7], offsets)
    want = numpy_rays(camera, np.repeat(rows[::7], 16), np.repeat(cols[::7], 16), np.tile(offsets, (len(rows[::7]), 1)))
    assert all(np.array_equal(g, w) for g, w in zip(got, want))


# -- ray-box cull ---------------------------------------------------------------------------------------------------

def test_cull_keeps_the_rays_the_numpy_slab_test_keeps_with_zeros_and_nan():
    rng = np.random.default_rng(7)
    box = RayBox(rng.uniform(size=(40, 3)))
    origins = rng.normal(size=(50000, 3)) * 3.0
    directions = rng.normal(size=(50000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[rng.uniform(size=directions.shape) < 0.1] = 0.0  # axis-parallel rays: a slab all or nothing
    origins[rng.uniform(size=origins.shape) < 0.3] = 0.5  # origins on the box's planes
    directions[::997] = np.nan
    kept = box.may_hit(origins, directions)
    assert np.array_equal(kept, numpy_may_hit(box, origins, directions))
    assert set(range(0, 50000, 997)) <= set(kept.tolist())  # a NaN ray is kept, for the tracer to answer
    assert 0 < len(kept) < len(origins)


# -- analytic coverage ----------------------------------------------------------------------------------------------

def test_trapezoid_cdf_and_hard_coverage_are_the_numpy_forms_to_the_bit():
    rng = np.random.default_rng(11)
    for scale in (1e-6, 0.05, 1.0, 30.0):
        z, a, b = rng.normal(size=30000) * scale, np.abs(rng.normal(size=30000)) * scale, np.abs(rng.normal(size=30000)) * scale
        a[::7], b[::11], z[::13], a[::17], z[::19], b[::23] = 0.0, 0.0, np.nan, np.nan, 0.0, a[::23]
        assert np.array_equal(trapezoid_cdf(z, a, b), numpy_cdf(z, a, b), equal_nan=True)
        assert np.array_equal(hard_coverage(z, a, b, 0.05), numpy_cdf(0.05 - z, a, b) - numpy_cdf(-0.05 - z, a, b),
                              equal_nan=True)
    # a closed form: z uniform on [−a/2, a/2] alone (b = 0) is a ramp
    assert trapezoid_cdf(np.array([-1.0, -0.25, 0.0, 0.25, 1.0]), np.ones(5), np.zeros(5)).tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]


# -- the analytic path's neighbour tests ----------------------------------------------------------------------------

def random_grids(rng, shape):
    level = rng.integers(-1, 3, size=shape)
    level[rng.uniform(size=shape) < 0.6] = 1  # mostly one level, so the σ tests decide
    sigma = rng.normal(size=shape) * 0.05
    sigma[rng.uniform(size=shape) < 0.05] = np.nan
    return level, sigma


def test_stripe_candidates_are_the_shifted_grid_form():
    rng = np.random.default_rng(13)
    for shape in ((1, 1), (1, 9), (7, 1), (23, 31)):
        level, sigma = random_grids(rng, shape)
        move, mixed = np.zeros(shape), np.zeros(shape, dtype=bool)
        for k, sg in zip(neighbours(level), neighbours(sigma)):
            mixed |= k != level
            with np.errstate(invalid="ignore"):
                move = np.fmax(move, np.abs(sg - sigma))
        with np.errstate(invalid="ignore"):
            want = (level >= 0) & (mixed | (np.abs(sigma) - move <= 0.06))
        got = np.zeros((shape[0] + 2, shape[1] + 4), dtype=bool)  # written into a strided view, as in the renderer
        stripe_candidates(level, sigma, 0.06, got[1:-1, 2:-2])
        assert np.array_equal(got[1:-1, 2:-2], want) and not got[0].any() and not got[:, :2].any()


def test_level_crossings_are_the_shifted_grid_form():
    rng = np.random.default_rng(29)
    for shape in ((1, 1), (1, 9), (7, 1), (23, 31)):
        level, _ = random_grids(rng, shape)
        want = rng.uniform(size=shape) < 0.7
        mixed = np.zeros(shape, dtype=bool)
        for k in neighbours(level):
            mixed |= k != level
        places = np.arange(level.size).reshape(shape)
        expect = [[p, *(n.ravel()[p] for n in neighbours(places))] for p in np.flatnonzero(want & mixed)]
        padded = np.zeros((shape[0] + 2, shape[1] + 4), dtype=bool)  # a strided view, as in the renderer
        padded[1:-1, 2:-2] = want
        out = np.full((int(want.sum()), 9), -1, dtype=np.int64)
        count = level_crossings(level, padded[1:-1, 2:-2], out)
        assert count == len(expect) and out[:count].tolist() == expect
        assert (out[count:] == -1).all()


def test_clear_far_is_the_numpy_bound_over_the_neighbours():
    """`Renderer._across_levels`' bound as numpy had it: fmax.reduce of |σ_n − σ| (NaN passed over), then
    |σ| − m > reach clears the pixel unless it is unknown (a NaN σ keeps it)."""
    rng = np.random.default_rng(31)
    for count in (0, 1, 57):
        sigma = rng.uniform(-0.3, 0.3, size=count)
        sigma_n = sigma + rng.uniform(-0.1, 0.1, size=(8, count))
        sigma_n[rng.uniform(size=sigma_n.shape) < 0.2] = np.nan
        sigma[rng.uniform(size=count) < 0.1] = np.nan
        unknown = rng.uniform(size=count) < 0.2
        at = rng.permutation(2 * count + 1)[:count]
        with np.errstate(invalid="ignore"):
            move = np.fmax.reduce(np.abs(sigma_n - sigma), axis=0, initial=0.0)
            far = ~unknown & (np.abs(sigma) - move > 0.06)
        want = np.ones(2 * count + 1, dtype=bool)
        want[at[far]] = False
        got = np.ones(2 * count + 1, dtype=bool)
        places = np.stack([at, at], axis=1)[:, 0]  # a strided column, as the renderer passes its pixels
        clear_far(sigma_n, sigma, unknown, 0.06, places, got)
        assert np.array_equal(got, want)
        assert count < 57 or 0 < far.sum() < count  # both outcomes exercised


def test_bent_and_edge_flags_are_the_shifted_grid_form():
    rng = np.random.default_rng(17)
    for shape in ((1, 1), (2, 5), (19, 27)):
        level, sigma = random_grids(rng, shape)
        gx, gy = rng.normal(size=shape) * 0.05, rng.normal(size=shape) * 0.05
        gx[rng.uniform(size=shape) < 0.05] = np.nan
        near, untrusted = rng.uniform(size=shape) < 0.7, rng.uniform(size=shape) < 0.05
        bent = np.zeros(shape, dtype=bool)
        for (dr, dc), ins, k, sg in zip(NEIGHBOURS, inside(shape), neighbours(level), neighbours(sigma)):
            with np.errstate(invalid="ignore"):
                strays = np.abs(sg - sigma - gx * dc - gy * dr) > 0.025
            bent |= ins & near & (k == level) & strays
        got = untrusted.copy()
        bent_flags(level, sigma, gx, gy, near, 0.025, got)
        assert np.array_equal(got, untrusted | bent)

        hit = rng.uniform(size=shape) < 0.8
        patch, blocked = rng.integers(0, 2, size=shape), rng.uniform(size=shape) < 0.3
        # Hits on the plane z = 0 (normal +z), some lifted off it (an occlusion edge's nearer face), some shaded apart;
        # the misses' point, normal and shade NaN (never read: only two hits are compared).
        candidate = near | (rng.uniform(size=shape) < 0.3)
        rows, cols = np.indices(shape, dtype=np.float64)
        P = np.stack([cols, rows, np.where(rng.uniform(size=shape) < 0.2, 3.0, 0.0)], axis=-1)
        N = np.broadcast_to([0.0, 0.0, 1.0], shape + (3,)).copy()
        shade = np.where(rng.uniform(size=shape) < 0.2, 0.9, 0.5)
        P[~hit], N[~hit], shade[~hit] = np.nan, np.nan, np.nan
        edge = got.copy()
        seen = set()
        for h, p, k, c, o, a, q, m, w in zip(*(neighbours(x) for x in (hit, patch, level, near, blocked, candidate, P,
                                                                      N, shade))):
            step = q - P
            length = np.linalg.norm(step, axis=-1)
            with np.errstate(invalid="ignore"):
                joined = ((np.abs(np.einsum("ijk,ijk->ij", N, step)) <= 0.1 * length)
                          & (np.abs(np.einsum("ijk,ijk->ij", m, step)) <= 0.1 * length) & (np.abs(w - shade) <= 0.2))
            across = hit & h & (p != patch) & ~candidate & ~a
            seen |= set(joined[across].tolist())
            edge |= (h != hit) | (hit & (p != patch) & (candidate | a | ~joined))
            edge |= (near | c) & (k != level)
            edge |= near & c & (o != blocked)
        out = np.empty(shape, dtype=bool)
        edge_flags(hit, patch, level, near, blocked, got, candidate, P, N, shade, 0.1, 0.2, out)
        assert np.array_equal(out, edge)
        if shape == (19, 27):
            assert seen == {False, True}  # faces joined and not, away from the stripes


# -- colour and AOV channels ----------------------------------------------------------------------------------------

def _numpy_coverage_sums(hit, lit, surface_color, line_color, background, shade):
    """The colour sums as film.py wrote them in numpy before the compiled pass served every case (the reference)."""
    samples = hit.shape[1]
    n_hit = hit.sum(axis=1)
    weight = np.where(hit, lit, 0)
    n_lit = weight.sum(axis=1)
    unlit = np.where(hit, 1 - weight, 0) if shade is None else np.where(hit, (1 - weight) * shade, 0.0)
    n_unlit, n_missed = unlit.sum(axis=1), samples - n_hit
    line, surface, back = np.asarray(line_color), np.asarray(surface_color), np.asarray(background)
    out = np.empty((len(hit), 4))
    for c in range(3):
        out[:, c] = (n_lit * line[c] + n_unlit * surface[c] + n_missed * back[c]) / samples
    out[:, 3] = n_hit / samples
    return out


@pytest.mark.parametrize("samples", [1, 4, 9, 16, 25, 64, 144, 256])
@pytest.mark.parametrize("weights", ["flags", "fractions"])
@pytest.mark.parametrize("shaded", [False, True])
def test_one_sample_colour_is_the_general_sums_to_the_bit(weights, shaded, samples):
    """The compiled colour pass (`kernels.pixels.coverage_rgba`) is numpy's sums of the samples to the bit, for every
    s² up to 256 (numpy's pairwise summation: 8 running sums from 8 values, halves beyond 128)."""
    rng = np.random.default_rng(19)
    n = 20000 // samples + 50
    hit = rng.uniform(size=(n, samples)) < 0.4
    hit[:5] = False  # whole pixels missing
    lit = rng.uniform(size=(n, samples)) < 0.5 if weights == "flags" else rng.uniform(size=(n, samples))
    shade = rng.uniform(size=(n, samples)) if shaded else None
    colours = ((0.2, 0.3, 0.4), (1.0, 0.9, 0.1), (0.3, 0.2, 0.1))
    got = film.coverage_color(hit, lit, *colours, shade)
    want = _numpy_coverage_sums(hit, lit, *colours, shade)
    assert np.array_equal(got, want)
    # Into a tile's float32 colour columns: each value rounded once.
    pixels = np.zeros((n, len(film.CHANNELS)), dtype=np.float32)
    film.coverage_color(hit, lit, *colours, shade, out=pixels[:, :4])
    assert np.array_equal(pixels[:, :4], want.astype(np.float32)) and not pixels[:, 4:].any()


def _numpy_map_sums(hit, weight, surface_rgb, line_color, background):
    """The map modes' colour as numpy computed it (`film.map_color` before it shared the compiled pass)."""
    samples = hit.shape[1]
    w = np.where(hit, weight, 0.0)
    rgb = ((np.nan_to_num(surface_rgb) * np.where(hit, 1.0 - w, 0.0)[..., None]).sum(axis=1)
           + w.sum(axis=1)[:, None] * np.asarray(line_color)
           + (samples - hit.sum(axis=1))[:, None] * np.asarray(background)) / samples
    return np.column_stack([rgb, hit.sum(axis=1) / samples])


@pytest.mark.parametrize("samples", [1, 4, 9, 16, 25, 64, 144, 256])
def test_map_colour_is_the_numpy_sums_to_the_bit(samples):
    """`film.map_color` (a map mode's per-sample surface colours) by the compiled colour pass is numpy's sums to the
    bit: its line weights summed pairwise, its colours in sample order, NaN colours as 0 and ±inf as ±max."""
    rng = np.random.default_rng(37)
    n = 20000 // samples + 50
    hit = rng.uniform(size=(n, samples)) < 0.6
    hit[:5] = False
    weight = rng.uniform(size=(n, samples))
    surface_rgb = rng.uniform(size=(n, samples, 3)) * np.exp(rng.normal(size=(n, samples, 3)) * 3)
    surface_rgb[rng.uniform(size=(n, samples)) < 0.1] = np.nan
    surface_rgb[7, 0] = (np.inf, -np.inf, np.nan)
    line, back = (1.0, 0.9, 0.1), (0.05, 0.1, 0.2)
    want = _numpy_map_sums(hit, weight, surface_rgb, line, back)
    assert np.array_equal(film.map_color(hit, weight, surface_rgb, line, back), want, equal_nan=True)
    pixels = np.zeros((n, len(film.CHANNELS)), dtype=np.float32)
    film.map_color(hit, weight, surface_rgb, line, back, out=pixels[:, :4])
    with np.errstate(over="ignore"):  # ±max rounds to ±inf in float32, as the tile's copy rounded it
        want32 = want.astype(np.float32)
    assert np.array_equal(pixels[:, :4], want32, equal_nan=True) and not pixels[:, 4:].any()


def test_aov_channels_of_a_tile_are_each_array_rounded_once():
    rng = np.random.default_rng(23)
    n = 5000
    aovs = {name: rng.normal(size=(n, 3) if width == 3 else n) * 1e3 for name, width in film.AOV_ARRAYS}
    aovs["u"][::5] = np.nan
    pixels = np.zeros((n, len(film.CHANNELS)), dtype=np.float32)
    film.aov_planes(aovs, pixels[:, 4:])
    want = np.column_stack([aovs[name] for name, _ in film.AOV_ARRAYS]).astype(np.float32)
    assert np.array_equal(pixels[:, 4:], want, equal_nan=True) and not pixels[:, :4].any()


@pytest.mark.parametrize("picked", [False, True])
def test_scatter_picked_is_numpy_fancy_assignment_of_the_picked_rows(picked):
    """``dst[rows] = src[pick]``; with pick an arange, ``dst[rows] = src`` (the renderer's scatter of traced rows)."""
    rng = np.random.default_rng(31 if picked else 29)
    dst = np.full((1000, 3), np.nan)
    want = dst.copy()
    rows = rng.choice(1000, size=400, replace=False)
    src = rng.normal(size=(700 if picked else 400, 3))
    src[::9] = np.nan
    pick = rng.choice(700, size=400, replace=False) if picked else np.arange(len(rows))
    want[rows] = src[pick]
    scatter_picked(dst, rows, src, pick)
    assert np.array_equal(dst, want, equal_nan=True)


@pytest.mark.parametrize("picked", [False, True])
def test_spread_rows_is_numpy_full_then_fancy_assignment(picked):
    """``np.full(fill)`` then ``dst[rows] = src[pick]`` (rows ascending), into an uninitialised array whose every row
    it writes: the tracer's first query and the renderer's merge of culled and traced rays (`Renderer.trace`)."""
    rng = np.random.default_rng(41 if picked else 43)
    rows = np.sort(rng.choice(1000, size=400, replace=False))
    rows[:50] = np.arange(50)  # a run from the first row, as a tile's kept rays are
    rows.sort()
    rows = np.unique(rows)
    src = rng.normal(size=(700 if picked else len(rows), 4))
    src[::9] = np.nan
    pick = rng.choice(700, size=len(rows), replace=False) if picked else np.arange(len(rows))
    want = np.full((1000, 4), np.nan)
    want[rows] = src[pick]
    dst = np.full((1000, 4), 7.0)  # not NaN: every row must be written
    spread_rows(dst, rows, src, pick, np.nan)
    assert np.array_equal(dst, want, equal_nan=True)
    spread_rows(dst, np.zeros(0, dtype=np.int64), src, np.zeros(0, dtype=np.int64), -1.0)
    assert (dst == -1.0).all()


@pytest.mark.parametrize("strided", [False, True])
def test_bvh_rays_are_numpy_subtraction_and_casts_to_the_bit(strided):
    """The rays Embree is given (`Accelerator`): float32 of (origins − centre) in float64, and float32 of the
    directions, against the numpy form they replaced, NaN, ±inf and values float32 rounds either way included."""
    rng = np.random.default_rng(47)
    origins = rng.normal(size=(2000, 3)) * 1e5 + 0.1
    directions = rng.normal(size=(2000, 3))
    origins[::13], directions[::17], origins[5, 1], directions[7, 2] = np.nan, np.nan, np.inf, -np.inf
    if strided:
        origins, directions = origins[::2], directions[1::2]
    centre = np.array([12345.678, -0.001, 3e4])
    local, directions32 = np.empty(origins.shape, dtype=np.float32), np.empty(directions.shape, dtype=np.float32)
    bvh_rays(origins, directions, centre, local, directions32)
    assert np.array_equal(local.view(np.uint32), (origins - centre).astype(np.float32).view(np.uint32))
    assert np.array_equal(directions32.view(np.uint32), directions.astype(np.float32).view(np.uint32))


# -- the analytic path's footprint ----------------------------------------------------------------------------------

def numpy_room(x, step, low, high):
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where(step > 0, (high - x) / step, np.where(step < 0, (low - x) / step, 1.0))
    return np.clip(np.nan_to_num(room, nan=0.0), 0.0, 1.0)


def test_footprint_ends_are_the_numpy_form_to_the_bit_and_stay_in_the_domain():
    """The four half-pixel ends (u, v) ± ½λ(du, dv) held in the patch's domain (`Renderer.centre_stripes`), against
    the numpy form they replaced, signs of zero included (a step from the low end gives λ = −0.0 in both); and the
    witness: every end lies in the domain, and a step that fits is not shortened."""
    rng = np.random.default_rng(37)
    n = 20000
    u0, v0 = rng.uniform(-1, 0, size=n), rng.uniform(0, 2, size=n)
    u1, v1 = u0 + rng.uniform(0.1, 2, size=n), v0 + rng.uniform(0.1, 2, size=n)
    u, v = rng.uniform(u0, u1), rng.uniform(v0, v1)
    u[::7], v[::11], u[::13], v[::17] = u0[::7], v1[::11], u1[::13], v0[::17]  # on the domain's sides
    steps = rng.normal(size=(n, 2, 2)) * rng.choice([1e-4, 0.05, 3.0], size=(n, 1, 1))
    steps[::5, 0, 0], steps[::9, 1, 1], steps[::19, 1, 0], steps[::23, 0, 1] = 0.0, -0.0, np.nan, np.inf
    want_u, want_v, want_share = [], [], []
    for axis in range(2):
        du, dv = 0.5 * steps[:, axis, 0], 0.5 * steps[:, axis, 1]
        for sign in (1.0, -1.0):
            lam = np.minimum(numpy_room(u, sign * du, u0, u1), numpy_room(v, sign * dv, v0, v1))
            want_share.append(lam)
            with np.errstate(invalid="ignore"):  # 0·∞
                want_u.append(u + sign * lam * du)
                want_v.append(v + sign * lam * dv)
    domains = np.stack([u0, u1, v0, v1], axis=1)  # strided columns, as `SurfaceSet.domains` gives them
    ends_u, ends_v, shares = np.empty((3, 4 * n))
    footprint_ends(u, v, steps, domains[:, 0], domains[:, 1], domains[:, 2], domains[:, 3], ends_u, ends_v, shares)
    for got, want in ((ends_u, want_u), (ends_v, want_v), (shares, want_share)):
        want = np.concatenate(want)
        assert np.array_equal(got, want, equal_nan=True) and np.array_equal(np.signbit(got), np.signbit(want))
    assert (-0.0 == shares).any() and np.signbit(shares).any()  # the −0.0 case is met
    ok = np.isfinite(ends_u) & np.isfinite(ends_v)
    assert ok.mean() > 0.8
    rounding = 1e-14  # u + λ·du with λ = (u1 − u)/du lands on u1 up to the rounding of the two operations
    assert np.all((np.tile(u0, 4) - rounding <= ends_u)[ok] & (ends_u <= np.tile(u1, 4) + rounding)[ok])
    assert np.all((np.tile(v0, 4) - rounding <= ends_v)[ok] & (ends_v <= np.tile(v1, 4) + rounding)[ok])
    inside = (np.abs(u - 0.5 * (u0 + u1)) + np.abs(steps[:, 0, 0]) < 0.5 * (u1 - u0)) & \
        (np.abs(v - 0.5 * (v0 + v1)) + np.abs(steps[:, 0, 1]) < 0.5 * (v1 - v0))
    assert inside.any() and np.all(shares[:n][inside] == 1.0) and np.all(shares[n:2 * n][inside] == 1.0)
