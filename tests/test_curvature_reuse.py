"""The tracer's curvatures reused by the AOV stage (issue 14, goal 2): the Newton kernel's order-2 evaluation
(`kernels.nurbs.CURVATURE_EVALUATION`) and `tracing._other_root`'s prefilter give K, H, κ1, κ2 at most hits, with
the normal facing the ray as the tracer stores it; they travel in `Hits.curvature` so the AOV stage computes only
the others. The reference is one fresh kernel pass (`curvatures_at`): at the point the Newton kernel evaluated (bit
for bit), which is the hit or one last short step from it (`kernels.nurbs.taylor_finish_lanes`).
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
def test_curvature_aovs_are_the_tracers_or_one_fresh_kernel_pass(name):
    """Where the tracer had no curvatures the AOVs are one fresh kernel pass at the hit, bit for bit; where it had
    them (the Newton kernel's, taken before its last step: `kernels.nurbs.taylor_finish_lanes`) they are the
    curvatures of a point ≤ 1e-6 of a knot span from the hit: within 1e-4 of the largest |κ| there of a fresh pass."""
    renderer = Renderer(resolve(load_scene(name).with_image(96, 54, 1)))
    rows, cols = np.divmod(np.arange(96 * 54), 96)
    shading = renderer.shade(*renderer.camera.rays(rows, cols))
    hits = shading.hits
    assert hits.hit.sum() > 500
    # What the tracer hands over, before the AOV stage fills in the rest (in place).
    from_tracer = ~np.isnan(hits.curvature[:, 0]) & hits.hit
    aovs = renderer.aovs(shading)
    fresh = curvatures_at(renderer.surfaces, np.where(hits.hit, hits.patch, -1), hits.u, hits.v, hits.N)
    scale = np.maximum(np.abs(fresh[2]), np.abs(fresh[3]))
    for power, got, want in zip((2, 1, 1, 1), (aovs["K"], aovs["H"], aovs["k1"], aovs["k2"]), fresh):
        assert np.array_equal(bits(got[~from_tracer]), bits(want[~from_tracer]))
        assert np.all(np.abs(got - want)[from_tracer] <= 1e-4 * scale[from_tracer] ** power + 1e-300)
    # Newton's order-2 evaluation (or `_other_root`'s prefilter) serves most hits: plate 0.99, teapot 0.96, hood 1.0
    # (the plate's planes converge there since it is Newton's second evaluation)
    assert np.mean(from_tracer[hits.hit]) > 0.9


@pytest.mark.parametrize("name", ["scenes/teapot.toml", "scenes/hood_curvature.toml"])
def test_newton_kernel_finishes_its_last_step_by_taylor_and_gives_the_curvatures_of_its_order_2_evaluation(name):
    """`kernels.nurbs.refine_mesh_hits` evaluates to order 2 at `CURVATURE_EVALUATION` and writes K, H, κ1, κ2 there
    for the normal turned to face the ray: the same bits as `curvatures_at` at that evaluation's (u, v) (found by
    re-running Newton with no step allowed past it), at the rows converged there and those whose last step
    `taylor_finish_lanes` finished, NaN at every other row. A finished row's step is ≤ `TAYLOR_SPAN_SHARE` of the
    domain, and its S, S_u, S_v (Taylor polynomials) are a fresh evaluation's at its (u, v) to 1e-12 of the scene."""
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
    at = newton(nurbs.CURVATURE_EVALUATION)  # stopped at that evaluation: its (u, v), S_u, S_v
    before = newton(nurbs.CURVATURE_EVALUATION - 1)["converged"]
    curvature = out["curvature"]
    taken = ~np.isnan(curvature[:, 0])
    assert not np.any(curvature == 7.0)  # every row written
    assert taken.mean() > 0.4  # teapot 0.46 (its coarse mesh: 40 % take 3 steps or more), hood 1.0
    assert not np.any(taken & before)
    assert np.all(out["converged"][taken])
    finished = taken & ~at["converged"]  # stepped once more, by the Taylor polynomials
    assert finished.mean() > 0.4
    turned = at["normal"] * np.where(at["cosine"] > 0, -1.0, 1.0)[:, None]
    fresh = curvatures_at(renderer.surfaces, at["patch"], at["u"], at["v"], turned)
    for k in range(4):
        assert np.array_equal(bits(curvature[taken, k]), bits(fresh[k][taken]))
    # Converged there: the same point; finished: one short step on.
    for name_ in ("u", "v", "S", "Su", "Sv"):
        assert np.array_equal(bits(out[name_][taken & ~finished]), bits(at[name_][taken & ~finished]))
    domain = renderer.surfaces.domains(out["patch"][finished])
    assert np.all(np.abs(out["u"] - at["u"])[finished] <= nurbs.TAYLOR_SPAN_SHARE * (domain[1] - domain[0]))
    assert np.all(np.abs(out["v"] - at["v"])[finished] <= nurbs.TAYLOR_SPAN_SHARE * (domain[3] - domain[2]))
    assert np.any(out["u"][finished] != at["u"][finished])
    exact = renderer.surfaces.evaluate(out["patch"][finished], out["u"][finished], out["v"][finished])
    size = 1e-12 * tess.extent
    assert np.abs(out["S"][finished] - exact.S).max() <= size
    for got, want in ((out["Su"][finished], exact.Su), (out["Sv"][finished], exact.Sv)):
        assert np.all(np.linalg.norm(got - want, axis=1) <= 1e-10 * np.linalg.norm(want, axis=1))
