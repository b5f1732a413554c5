"""The tracer's curvatures reused by the AOV stage (issue 14, goal 2): `tracing._other_root`'s prefilter computes
K, H, κ1, κ2 at most hits; they travel in `Hits.curvature` (turned with N, `tracing.turned_curvatures`) so the AOV
stage computes only the others. The AOVs must be the same bits as one fresh kernel pass at every hit
(`curvatures_at` with N as stored), which is the reference here.
"""

from __future__ import annotations

import numpy as np
import pytest

from rtreflect import NurbsSurface
from rtreflect.exchange.load import load_scene
from rtreflect.geometry.curvature import curvatures_at
from rtreflect.geometry.surfaces import SurfaceSet
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace.tracing import turned_curvatures

from test_curvature import SQRT_HALF, revolve


def bits(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64).view(np.uint64)


def test_turned_curvatures_are_the_kernels_at_the_opposite_normal_bit_for_bit_and_zeros_are_left_to_compute():
    torus = revolve([(4.0, 0.0, 1.0), (4.0, 1.0, SQRT_HALF), (3.0, 1.0, 1.0)])
    corners = np.array([[[x, y, 0.3 + 0.2 * x - 0.1 * y] for y in (0.0, 1.0)] for x in (0.0, 1.0)])  # a tilted plane
    plane = NurbsSurface(1, 1, [0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0], corners, np.ones((2, 2)))
    surfaces = SurfaceSet([torus, plane])
    rng = np.random.default_rng(21)
    patch = rng.integers(0, 2, 600)
    u, v = rng.uniform(0.05, 0.95, (2, len(patch)))
    n = surfaces.normals(patch, u, v, surfaces.evaluate(patch, u, v, order=1))
    mine = np.column_stack(curvatures_at(surfaces, patch, u, v, n))
    turned = np.column_stack(curvatures_at(surfaces, patch, u, v, -n))
    rows = np.flatnonzero(rng.random(len(patch)) < 0.7)
    have = mine.copy()
    turned_curvatures(have, rows)
    flipped = np.zeros(len(patch), dtype=bool)
    flipped[rows] = True
    known = ~np.isnan(have[:, 0])
    # Every curved point turned is the kernel's value at −n, to the bit; the plane's zeros are left to compute.
    assert np.array_equal(bits(have[flipped & known]), bits(turned[flipped & known]))
    assert np.all(known[flipped & (patch == 0)])
    # A zero (a plane's H, κ1, κ2) may come out −0 from one normal and +0 from the other: left to compute.
    zeros = np.array([[0.0, 0.0, 0.0, 0.0], [-1.0, 0.5, 0.0, -2.0], [np.nan] * 4, [1.0, 2.0, 3.0, 1.0]])
    turned_curvatures(zeros, np.arange(4))
    assert np.isnan(zeros[:3]).all() and np.array_equal(zeros[3], [1.0, -2.0, -1.0, -3.0])
    assert np.array_equal(bits(have[~flipped]), bits(mine[~flipped]))  # rows not turned: untouched


@pytest.mark.parametrize("name", ["scenes/teapot.toml", "scenes/hood_curvature.toml", "parts/plate.step"])
def test_curvature_aovs_equal_one_fresh_kernel_pass_at_every_hit(name):
    renderer = Renderer(resolve(load_scene(name).with_image(96, 54, 1)))
    rows, cols = np.divmod(np.arange(96 * 54), 96)
    aovs = renderer.pixel_aovs(rows, cols)
    hits = aovs["shading"].hits
    assert hits.hit.sum() > 500
    fresh = curvatures_at(renderer.surfaces, np.where(hits.hit, hits.patch, -1), hits.u, hits.v, hits.N)
    for got, want in zip((aovs["K"], aovs["H"], aovs["k1"], aovs["k2"]), fresh):
        assert np.array_equal(bits(got), bits(want))
    if name != "parts/plate.step":  # curved faces: the tracer's curvatures serve most hits (the plate: planes, zeros)
        assert np.mean(~np.isnan(hits.curvature[hits.hit, 0])) > 0.5
