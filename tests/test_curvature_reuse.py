"""The tracer's curvatures reused by the AOV stage (issue 14, goal 2): the Newton kernel's order-2 evaluation
(`kernels.nurbs.CURVATURE_EVALUATION`) and `tracing._other_root`'s prefilter give K, H, κ1, κ2 at most hits, with
the normal facing the ray as the tracer stores it; they travel in `Hits.curvature` so the AOV stage computes only
the others. The AOVs must be the same bits as one fresh kernel pass at every hit
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

from test_curvature import SQRT_HALF, revolve


def bits(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64).view(np.uint64)


def test_opposite_normal_gives_minus_h_and_swapped_minus_kappas_bit_for_bit_so_the_prefilter_bound_is_the_same():
    """`_other_root` now takes its curvatures with the normal facing the ray (to hand them to the AOVs): its prefilter
    reads max(|κ1|, |κ2|), which must not change by a bit; the kernel's values at −n are (K, −H, −κ2, −κ1) exactly."""
    torus = revolve([(4.0, 0.0, 1.0), (4.0, 1.0, SQRT_HALF), (3.0, 1.0, 1.0)])
    corners = np.array([[[x, y, 0.3 + 0.2 * x - 0.1 * y] for y in (0.0, 1.0)] for x in (0.0, 1.0)])  # a tilted plane
    plane = NurbsSurface(1, 1, [0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 1.0, 1.0], corners, np.ones((2, 2)))
    surfaces = SurfaceSet([torus, plane])
    rng = np.random.default_rng(21)
    patch = rng.integers(0, 2, 600)
    u, v = rng.uniform(0.05, 0.95, (2, len(patch)))
    n = surfaces.normals(patch, u, v, surfaces.evaluate(patch, u, v, order=1))
    K, H, k1, k2 = curvatures_at(surfaces, patch, u, v, n)
    K2, H2, k12, k22 = curvatures_at(surfaces, patch, u, v, -n)
    assert np.array_equal(bits(np.maximum(np.abs(k1), np.abs(k2))), bits(np.maximum(np.abs(k12), np.abs(k22))))
    nonzero = (H != 0) & (k1 != 0) & (k2 != 0) & (K != 0)
    assert nonzero[patch == 0].all()
    assert np.array_equal(bits(K2[nonzero]), bits(K[nonzero]))
    for got, want in ((H2, -H), (k12, -k2), (k22, -k1)):
        assert np.array_equal(bits(got[nonzero]), bits(want[nonzero]))


@pytest.mark.parametrize("name", ["scenes/teapot.toml", "scenes/hood_curvature.toml", "parts/plate.step"])
def test_curvature_aovs_equal_one_fresh_kernel_pass_at_every_hit(name):
    renderer = Renderer(resolve(load_scene(name).with_image(96, 54, 1)))
    rows, cols = np.divmod(np.arange(96 * 54), 96)
    shading = renderer.shade(*renderer.camera.rays(rows, cols))
    hits = shading.hits
    assert hits.hit.sum() > 500
    # What the tracer hands over, before the AOV stage fills in the rest (in place).
    from_tracer = np.mean(~np.isnan(hits.curvature[hits.hit, 0]))
    aovs = renderer.aovs(shading)
    fresh = curvatures_at(renderer.surfaces, np.where(hits.hit, hits.patch, -1), hits.u, hits.v, hits.N)
    for got, want in zip((aovs["K"], aovs["H"], aovs["k1"], aovs["k2"]), fresh):
        assert np.array_equal(bits(got), bits(want))
    if name != "parts/plate.step":  # curved faces: Newton's order-2 evaluation serves most hits (the plate: planes)
        assert from_tracer > 0.75


@pytest.mark.parametrize("name", ["scenes/teapot.toml", "scenes/hood_curvature.toml"])
def test_newton_kernel_gives_the_curvatures_of_its_order_2_evaluation_bit_for_bit(name):
    """`kernels.nurbs.refine_mesh_hits` evaluates to order 2 at `CURVATURE_EVALUATION` and, exactly where Newton
    converges there (not before, not after: found by re-running it with fewer steps allowed), writes K, H, κ1, κ2 for
    the normal turned to face the ray: the same bits as `curvatures_at` at its (u, v) with that normal; NaN at every
    other row."""
    from rtreflect.geometry import surfaces as surface_module
    from rtreflect.kernels import nurbs
    from rtreflect.trace import tracing

    renderer = Renderer(resolve(load_scene(name).with_image(96, 54, 1)))
    rows, cols = np.divmod(np.arange(96 * 54), 96)
    O, D = renderer.camera.rays(rows, cols)
    mesh = renderer.accelerator.intersect(O, D)
    found = mesh.prim >= 0
    O, D = np.ascontiguousarray(O[found]), np.ascontiguousarray(D[found])
    prim, b1, b2, tm = mesh.prim[found], mesh.b1[found], mesh.b2[found], mesh.t[found]
    tess, table, n = renderer.tessellation, renderer.surfaces.table, len(prim)

    def newton(max_steps):
        out = dict(patch=np.empty(n, dtype=np.int64), u_start=np.empty(n), v_start=np.empty(n), u=np.empty(n),
                   v=np.empty(n), S=np.empty((n, 3)), Su=np.empty((n, 3)), Sv=np.empty((n, 3)), t=np.empty(n),
                   normal=np.empty((n, 3)), cosine=np.empty(n),
                   **{k: np.empty(n, dtype=bool) for k in ("converged", "near", "edge", "degenerate")},
                   curvature=np.full((n, 4), 7.0))
        nurbs.refine_mesh_hits(*table.args, table.scale, *tess.start_arrays, tess.chord_error, prim, b1, b2, O, D,
                               tm, tess.extent, tracing.NEWTON_TOLERANCE, max_steps, tracing.JUMP_LIMIT,
                               tracing.GRAZING_ALLOWANCE, surface_module.DEGENERATE_SINE,
                               surface_module.VANISHING_PARTIAL, *out.values())
        return out

    out = newton(tracing.NEWTON_MAX_STEPS)
    # Converged at evaluation k: within k steps, not within k − 1.
    at_second = newton(nurbs.CURVATURE_EVALUATION)["converged"] & ~newton(nurbs.CURVATURE_EVALUATION - 1)["converged"]
    curvature = out["curvature"]
    taken = ~np.isnan(curvature[:, 0])
    assert not np.any(curvature == 7.0)  # every row written
    assert at_second.mean() > 0.5  # teapot 0.60 (the rest converge after one step), hood 0.9
    assert np.array_equal(taken, at_second)
    turned = out["normal"] * np.where(out["cosine"] > 0, -1.0, 1.0)[:, None]
    fresh = curvatures_at(renderer.surfaces, out["patch"], out["u"], out["v"], turned)
    for k in range(4):
        assert np.array_equal(bits(curvature[taken, k]), bits(fresh[k][taken]))
