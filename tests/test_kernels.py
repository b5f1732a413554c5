"""The compiled kernels (issue 14) against independent references, and their on-disk cache.

* tube distances (paper eq. 4) of finite tubes and rays parallel to the tubes, against a
  least-squares closest approach (tests/reference.py) and the point-to-line distance;
* a scene's patches evaluated in one kernel call, bit for bit each patch's own evaluation,
  whatever the mix or order of patches (what makes tiles independent of each other);
* the bicubic power form written out in registers, bit for bit the generic loops (orders 1 and 2);
* Newton's converged hits lie on their rays and on the surface (rhino3dm's evaluator);
* the fused first refinement of mesh hits (start, Newton, near test, t, normal) against its steps
  done separately: the triangle's barycentric (u, v), rhino3dm's points and normals, the numpy tests;
* the compiled Levenberg–Marquardt search, answer for answer its numpy implementation (tests/reference.py);
* Newton in lane blocks (vector loops across rays), bit for bit the same iteration written in numpy;
* the reflected direction (paper eq. 3) against the Householder matrix I − 2 n nᵀ, and Ulmet's f found in the tube
  search's pass, bit for bit `ulmet_f` and against the brute-force plane crossing; the renderer's f AOV is that f;
* a second process finds every kernel in numba's cache (no compilation).
"""

from __future__ import annotations

import subprocess
from dataclasses import replace
import sys
from pathlib import Path

import numpy as np
import pytest

from reference import angle_between, closest_line_distance, levenberg_marquardt, to_rhino, xyz
from rtreflect.exchange.bpt import read_bpt
from rtreflect.exchange.load import load_scene
from rtreflect.geometry.surfaces import SurfaceSet
from rtreflect.integrator.renderer import Renderer
from rtreflect.kernels import nurbs
from rtreflect.modes.lights import TubeLights, reflect, reflect_rays
from rtreflect.trace import tracing
from rtreflect.trace.tracing import refine

ROOT = Path(__file__).resolve().parents[1]
TEAPOT = ROOT / "scenes" / "teapot.bpt"

#: One xdist worker runs this file and test_kernels_aot.py one test after another (`--dist loadgroup`, pyproject's
#: addopts): their numba JIT compilations share its on-disk cache, so the JIT compiles once instead of in both
#: workers at once (CI's suite spent 511 + 198 s in two such tests side by side).
pytestmark = pytest.mark.xdist_group("numba-jit")


def tubes(length: float) -> TubeLights:
    c, m = np.array([0.0, 0.6, 0.8]), np.array([0.0, -0.8, 0.6])
    return TubeLights(np.array([0.3, 0.0, 5.0]), m, c, np.cross(c, m), np.array([-2.0, -0.5, 0.0, 1.0, 3.0]), 0.4,
                      length)


def test_finite_tubes_against_least_squares():
    """Only tubes whose closest approach lies ahead (t > 0) and within half the length count (τ measured from B_k)."""
    rng = np.random.default_rng(7)
    lights = tubes(6.0)
    R = rng.uniform(-3, 3, (300, 3))
    s = rng.normal(size=(300, 3))
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    reach = lights.reach(R, s)
    dist = lights.distances(R, s)
    seen = 0
    for row in range(len(R)):
        found = []
        for k, B in enumerate(lights.points):
            d, t = closest_line_distance(R[row], s[row], B, lights.c)
            tau = float(np.dot(R[row] + t * s[row] - B, lights.c))
            assert dist.d[row, k] == pytest.approx(d, rel=1e-9, abs=1e-12)
            assert dist.t[row, k] == pytest.approx(t, rel=1e-9, abs=1e-9)
            ahead = t > 0 and abs(tau) <= 3.0
            assert dist.ahead[row, k] == ahead or abs(abs(tau) - 3.0) < 1e-9
            if ahead:
                found.append((d, t, k))
        if found:
            seen += 1
            d_best, _, k_best = min(found)
            assert reach.line_id[row] == k_best and reach.line_dist[row] == pytest.approx(d_best, rel=1e-9)
        else:
            assert reach.line_id[row] == -1 and np.isnan(reach.line_dist[row])
        within = [t for d, t, _ in found if d <= lights.radius]
        assert reach.candidate[row] == bool(within)
        assert reach.t_candidate[row] == pytest.approx(min(within, default=np.inf), rel=1e-9)
    assert 50 < seen < 300, "the sample must mix rays with and without a tube ahead"


@pytest.mark.parametrize("radius", [0.4, 2.5])
def test_endless_bank_nearest_tube_is_the_full_tables(radius):
    """Endless tubes at ascending c_k: `reach` looks at a few tubes about the nearest (`kernels.tubes._nearest`);
    its answer is the full (N, K) table's, to the bit: the first of equal nearest tubes ahead (ties made on purpose:
    points midway between two tubes, reflected straight at the light plane), its d and t, the candidate flag and the
    least t within the radius; rays with the tubes ahead a prefix, a suffix, all or none of them."""
    rng = np.random.default_rng(5)
    c, m = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    lights = TubeLights(np.array([0.0, 0.0, 4.0]), m, c, np.cross(c, m), np.array([-3.0, -1.5, -0.25, 0.5, 0.75, 2.0, 3.5]),
                        radius, float("inf"))
    R = np.column_stack([rng.uniform(-4, 4, 3000), rng.uniform(-1, 1, 3000), rng.uniform(-0.5, 0.5, 3000)])
    s = rng.normal(size=(3000, 3))
    s[:1000, 0] *= 0.05  # nearly across the tubes: their closest approaches spread ahead of and behind the point
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    R[:200, 0] = 0.5 * (lights.c_k[:-1] + lights.c_k[1:])[rng.integers(0, 6, 200)]  # midway: equal distances
    s[:200] = m
    reach, table = lights.reach(R, s), lights.distances(R, s)
    d = np.where(table.ahead, table.d, np.inf)
    some = np.isfinite(d).any(axis=1)
    best = np.where(some, np.argmin(d, axis=1), -1)  # argmin: the first of equals, as the scan
    rows = np.flatnonzero(some)
    np.testing.assert_array_equal(reach.line_id, best)
    np.testing.assert_array_equal(reach.line_dist[rows], d[rows, best[rows]])
    np.testing.assert_array_equal(reach.line_t[rows], table.t[rows, best[rows]])
    assert np.isnan(reach.line_dist[~some]).all()
    within = table.ahead & (table.d <= radius)
    np.testing.assert_array_equal(reach.candidate, within.any(axis=1))
    np.testing.assert_array_equal(reach.t_candidate, np.where(within, table.t, np.inf).min(axis=1))
    ahead = table.ahead.sum(axis=1)
    assert (ahead == 0).any() and (ahead == 7).any() and ((ahead > 0) & (ahead < 7)).sum() > 100
    assert (table.d[np.arange(200), best[:200]] == table.d[np.arange(200), best[:200] + 1]).sum() > 100  # the ties
    assert 100 < reach.candidate.sum() < 3000


@pytest.mark.parametrize("length", [float("inf"), 6.0])
def test_rays_along_the_tubes(length):
    """s ∥ c: the point-to-line distance |b × c|; an endless tube is ahead, a finite one is never reached."""
    lights = tubes(length)
    R = np.array([[0.5, 1.0, 2.0], [-1.0, 0.0, 4.0]])
    s = np.array([lights.c, -lights.c])
    dist = lights.distances(R, s)
    for row in range(2):
        b = lights.points - R[row]
        np.testing.assert_allclose(dist.d[row], np.linalg.norm(np.cross(b, lights.c), axis=1), rtol=1e-12)
    assert (dist.ahead == np.isinf(length)).all() and np.isinf(dist.t).all()
    reach = lights.reach(R, s)
    assert (reach.line_id >= 0).all() == np.isinf(length)


def test_reflected_directions_are_the_householder_mirror_images():
    """Eq. (3), s = 2 (a·n) n − a: the mirror image (I − 2 n nᵀ) D of the ray direction D = −a. `reflect_rays`
    writes exactly the rows asked for, the same bits as `reflect`, and leaves every other row alone."""
    rng = np.random.default_rng(11)
    D = rng.normal(size=(400, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    n = rng.normal(size=(400, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    householder = np.eye(3) - 2.0 * n[:, :, None] * n[:, None, :]
    s = reflect(-D, n)
    np.testing.assert_allclose(s, np.einsum("nij,nj->ni", householder, D), rtol=0, atol=1e-14)
    rows = rng.choice(400, 150, replace=False)
    full = np.full((400, 3), 7.0)
    mine = reflect_rays(D, rows, n[rows], full)
    assert np.array_equal(mine.view(np.int64), reflect(-D[rows], n[rows]).view(np.int64))
    assert np.array_equal(full[rows], mine)
    assert (np.delete(full, rows, axis=0) == 7.0).all()


def test_tube_search_gives_ulmet_f_of_the_same_ray():
    """`reach`'s f is `ulmet_f` to the bit, and both are the plane crossing solved by brute force: R + t s =
    Q + α e + β c, f = α where t > 0 (NaN where the ray turns away from the plane)."""
    rng = np.random.default_rng(12)
    lights = tubes(6.0)
    R = rng.uniform(-3, 3, (300, 3))
    s = rng.normal(size=(300, 3))
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    f = lights.reach(R, s).f
    assert np.array_equal(f.view(np.int64), lights.ulmet_f(R, s).view(np.int64))
    ahead = 0
    for row in range(len(R)):
        t, alpha, _ = np.linalg.solve(np.column_stack([s[row], -lights.e, -lights.c]), lights.Q - R[row])
        if t > 1e-9:
            ahead += 1
            assert f[row] == pytest.approx(alpha, rel=1e-9, abs=1e-9)
        elif t < -1e-9:
            assert np.isnan(f[row])
    assert 50 < ahead < 250, "the sample must mix rays towards and away from the light plane"


def test_light_plane_parameter_is_the_one_ulmet_f_reads():
    """`TubeLights.plane_t` (the highlight and circles modes, the contours) is the kernel that Ulmet's f reads its
    plane crossing from, no second copy of t = m·(Q − R)/(m·s): bit for bit the former numpy form on C-ordered rows
    (einsum's dot), f = e·(R + t s − Q) from it bit for bit `ulmet_f` where t > 0, t against the brute-force plane
    crossing, and ±inf or NaN where s is parallel to the plane."""
    rng = np.random.default_rng(13)
    lights = tubes(6.0)
    R = rng.uniform(-3, 3, (300, 3)) * 10.0 ** rng.uniform(-3, 3, (300, 1))
    s = rng.normal(size=(300, 3))
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    t = lights.plane_t(R, s)
    numpy_t = np.einsum("...j,...j->...", lights.Q - R, lights.m) / np.einsum("...j,...j->...", s, lights.m)
    assert np.array_equal(t.view(np.int64), numpy_t.view(np.int64))
    ahead = t > 0
    f = np.einsum("...j,...j->...", R[ahead] + t[ahead, None] * s[ahead] - lights.Q, lights.e)
    assert np.array_equal(f.view(np.int64), lights.ulmet_f(R, s)[ahead].view(np.int64))
    for row in range(0, len(R), 7):
        crossing, _, _ = np.linalg.solve(np.column_stack([s[row], -lights.e, -lights.c]), lights.Q - R[row])
        assert t[row] == pytest.approx(crossing, rel=1e-9, abs=1e-12)
    along = np.array([1.0, 0.0, 0.0])  # in the plane: m = (0, −0.8, 0.6)
    off, on = lights.Q + 2.0 * lights.m, lights.Q + 3.0 * along  # beside the plane; in it
    assert np.isinf(lights.plane_t(off[None], along[None])).all()
    assert np.isnan(lights.plane_t(on[None], along[None])).all()


@pytest.mark.parametrize("name", ["hood", "hood_curvature"])
def test_f_aov_is_ulmet_f_of_the_stored_hit(name):
    """The renderer takes f from the tubes' pass: it is Ulmet's f of the pixel-centre ray's hit P and reflected
    direction s (recomputed here from the shading's own rows), NaN where no ray hit, in any mode (reflection lines,
    a curvature map)."""
    scene = load_scene(ROOT / "scenes" / f"{name}.toml")
    scene = replace(scene, image=replace(scene.image, width=48, height=27, samples=1))
    renderer = Renderer(scene)
    rows, cols = np.divmod(np.arange(48 * 27), 48)
    aovs = renderer.pixel_aovs(rows, cols)
    shading = aovs["shading"]
    hit = shading.hits.hit
    assert 100 < hit.sum() < len(hit)
    expected = renderer.lights.ulmet_f(shading.hits.P[hit], reflect(-shading.directions[hit], shading.hits.N[hit]))
    assert np.array_equal(aovs["f"][hit].view(np.int64), expected.view(np.int64))
    assert np.isnan(aovs["f"][~hit]).all()


def test_patch_mix_evaluates_bit_for_bit_as_each_patch():
    patches = read_bpt(TEAPOT)
    surfaces = SurfaceSet(patches)
    rng = np.random.default_rng(3)
    n = 5000
    k = rng.integers(-1, len(patches), n)
    u, v = rng.uniform(-0.1, 1.1, n), rng.uniform(-0.1, 1.1, n)
    mixed = surfaces.evaluate(k, u, v, order=2)
    shuffled = rng.permutation(n)
    again = surfaces.evaluate(k[shuffled], u[shuffled], v[shuffled], order=2)
    for got, other in zip(mixed, again):
        np.testing.assert_array_equal(got[shuffled], other)
    assert np.isnan(mixed.S[k < 0]).all()
    for p in range(len(patches)):
        rows = np.flatnonzero(k == p)
        for got, own in zip(mixed, patches[p].evaluate(u[rows], v[rows], order=2)):
            np.testing.assert_array_equal(got[rows], own)


def test_bicubic_written_out_evaluation_is_bit_for_bit_the_generic_loops():
    """`bicubic_contract` (the power form of a bicubic span in registers, zero terms left out) gives the very bits
    of `power_rows` + `contract` for orders 1 and 2: random spans (rational weights, exact zeros and −0.0 among
    the coefficients), τ at the span's ends and inside, short and long spans."""
    from numba import njit
    from rtreflect.kernels import compiled, nurbs

    # The helpers as numba's dispatchers whichever compiler serves the renders (with the AOT module fresh, the
    # module's own names are AOT `Kernel`s, which a jitted caller cannot call).
    jitted = compiled.jit_namespace(nurbs.__name__)
    power_rows, contract, bicubic_contract = jitted["power_rows"], jitted["contract"], jitted["bicubic_contract"]

    @njit
    def both(power, tau_u, inv_u, tau_v, inv_v, order, generic, written):
        Nu, Nv = np.empty((3, 4)), np.empty((3, 4))
        for i in range(tau_u.shape[0]):
            base = 16 * i
            power_rows(tau_u[i], inv_u[i], 3, order, Nu)
            power_rows(tau_v[i], inv_v[i], 3, order, Nv)
            a = contract(Nu, Nv, power, base, 4, 3, 3, order)
            b = bicubic_contract(power, base, tau_u[i], inv_u[i], tau_v[i], inv_v[i], order)
            for m in range(6):
                for c in range(4):
                    generic[i, m, c], written[i, m, c] = a[m][c], b[m][c]

    rng = np.random.default_rng(14)
    n = 4000
    power = rng.normal(scale=rng.choice([1e-3, 1.0, 1e3], (16 * n, 1)), size=(16 * n, 4))
    power[rng.random(power.shape) < 0.1] = 0.0
    power[rng.random(power.shape) < 0.05] = -0.0
    tau_u, tau_v = rng.random(n), rng.random(n)
    tau_u[:50], tau_v[50:100], tau_u[100:150] = 0.0, 1.0, np.nextafter(1.0, 0.0)
    inv_u, inv_v = 1.0 / rng.uniform(1e-3, 10.0, n), 1.0 / rng.uniform(1e-3, 10.0, n)
    for order in (1, 2):
        generic, written = np.empty((n, 6, 4)), np.empty((n, 6, 4))
        both(power, tau_u, inv_u, tau_v, inv_v, order, generic, written)
        np.testing.assert_array_equal(written.view(np.int64), generic.view(np.int64), err_msg=f"order {order}")
        assert np.count_nonzero(generic[:, 1:3]) > n, "the derivatives must be exercised"


def test_newton_lands_on_the_ray_and_on_rhinos_surface():
    patches = read_bpt(TEAPOT)
    surfaces = SurfaceSet(patches)
    rng = np.random.default_rng(5)
    n = 400
    k = rng.integers(0, len(patches), n)
    u0, v0 = rng.uniform(0.1, 0.9, n), rng.uniform(0.1, 0.9, n)
    target = surfaces.evaluate(k, u0, v0).S
    D = rng.normal(size=(n, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    O = target - 5.0 * D
    # Start a little off the answer, as a mesh hit does.
    u, v, derivs, converged = refine(surfaces, k, u0 + 0.01, v0 - 0.01, O, D, np.full(n, 5.0), 1.0)
    assert converged.mean() > 0.9
    off_ray = np.linalg.norm(np.cross(derivs.S[converged] - O[converged], D[converged]), axis=1)
    assert off_ray.max() < 1e-10
    for row in np.flatnonzero(converged)[:60]:
        rhino = to_rhino(patches[k[row]])
        np.testing.assert_allclose(xyz(rhino.PointAt(u[row], v[row])), derivs.S[row], rtol=0, atol=1e-12)


def test_fused_refinement_of_mesh_hits_against_its_steps():
    """`_candidates`' compiled pass (`refine_mesh_hits`) on the teapot's mesh hits, grazing rims included.

    The start is the triangle's barycentric combination of its vertices' (u, v) (closed form); converged
    hits lie on their rays and on rhino3dm's surface at (u, v); t = (S − O)·D; 'near' is the numpy test of
    `JUMP_LIMIT` (grown as 1/cos θ); normals are rhino3dm's up to orientation, cosine = n·D.
    """
    renderer = Renderer(load_scene(ROOT / "scenes" / "teapot.toml").with_image(200, 112, 1))
    w, h = renderer.scene.image.width, renderer.scene.image.height
    O, D = renderer.camera.rays(*np.divmod(np.arange(w * h), w))
    mesh = renderer.accelerator.intersect(O, D)
    found = mesh.prim >= 0
    O, D, prim, b1, b2, tm = O[found], D[found], mesh.prim[found], mesh.b1[found], mesh.b2[found], mesh.t[found]
    tess, surfaces = renderer.tessellation, renderer.surfaces
    c = tracing._candidates(tess, surfaces, O, D, prim, b1, b2, tm)
    corners = tess.vertex_uv[tess.faces[prim]]
    start = (1.0 - b1 - b2)[:, None] * corners[:, 0] + b1[:, None] * corners[:, 1] + b2[:, None] * corners[:, 2]
    np.testing.assert_allclose(np.column_stack([c.start_u, c.start_v]), start, rtol=0, atol=1e-15)
    first = ~c.aside  # the mesh hit's own refinement
    valid = np.flatnonzero(first & (c.status == tracing.VALID))
    assert len(valid) > 0.9 * len(prim)
    S = c.derivs.S[valid]
    np.testing.assert_allclose(c.t[valid], np.einsum("ij,ij->i", S - O[valid], D[valid]), rtol=1e-15, atol=0)
    assert np.linalg.norm(np.cross(S - O[valid], D[valid]), axis=1).max() < 1e-10
    jump = np.linalg.norm(S - (O[valid] + tm[valid, None] * D[valid]), axis=1)
    cos = np.abs(np.einsum("ij,ij->i", c.normal[valid], D[valid]))
    allowance = np.clip(1.0 / cos, 1.0, tracing.GRAZING_ALLOWANCE)
    band = tess.chord_error[c.patch[valid]] + 1e-6 * tess.extent
    assert (jump <= tracing.JUMP_LIMIT * band * allowance * (1 + 1e-12)).all()
    np.testing.assert_allclose(c.cosine[valid], np.einsum("ij,ij->i", c.normal[valid], D[valid]), rtol=0, atol=1e-15)
    sample = valid[np.linspace(0, len(valid) - 1, 80).astype(int)]
    for row in sample:
        rhino = to_rhino(surfaces.patches[c.patch[row]])
        np.testing.assert_allclose(xyz(rhino.PointAt(c.u[row], c.v[row])), c.derivs.S[row], rtol=0, atol=1e-12)
        n_rhino = xyz(rhino.NormalAt(c.u[row], c.v[row]))
        angle = angle_between(c.normal[row][None], n_rhino[None] * np.sign(n_rhino @ c.normal[row]))
        assert angle[0] < 1e-9, (row, angle)
    # Grazing hits are screened for the other root by the kernel's cosine; at least some exist here.
    assert (np.abs(c.cosine[valid]) < tracing.OTHER_ROOT_COS).any()


def test_restart_filter_reach_bounds_the_near_test_at_every_incidence():
    """`tracing._may_win_restart` skips seam restarts whose every winning point would lie beyond the largest reach of
    the near-mesh-hit test: that reach is the kernel's own formula (`nurbs.jump_reaches` at cos θ = 0), not a copy.
    Against the test itself (`nurbs.near_mesh_hits`): a refined point at distance r off its mesh hit, its tangent plane
    tilted to every incidence from facing the ray to grazing (and a degenerate normal), is near only for r within
    that largest reach, and at grazing incidence it is near all the way to it (closed form: 8 × 10 chord errors)."""
    band = np.array([1e-3, 0.3, 2.0])
    largest = np.empty(len(band))
    nurbs.jump_reaches(band, 0.0, tracing.JUMP_LIMIT, tracing.GRAZING_ALLOWANCE, largest)
    np.testing.assert_array_equal(largest, tracing.JUMP_LIMIT * tracing.GRAZING_ALLOWANCE * band)
    theta = np.r_[np.linspace(0.0, 0.5 * np.pi, 41), np.nan]  # NaN: S_u = 0, no normal
    fraction = np.r_[0.0, 0.5, 1.0 - 1e-9, 1.0 + 1e-9, 2.0]
    k, th, f = (x.ravel() for x in np.meshgrid(np.arange(len(band)), theta, fraction, indexing="ij"))
    n = len(k)
    t_mesh = 5.0
    O, D = np.zeros((n, 3)), np.tile([0.0, 0.0, 1.0], (n, 1))
    S = np.column_stack([f * largest[k], np.zeros(n), np.full(n, t_mesh)])  # off the mesh hit across the ray
    c, s = np.cos(np.nan_to_num(th)), np.sin(np.nan_to_num(th))
    Su = np.where(np.isnan(th)[:, None], 0.0, np.column_stack([c, np.zeros(n), -s]))  # S_u × S_v = (sin θ, 0, cos θ)
    Sv = np.tile([0.0, 1.0, 0.0], (n, 1))
    near, t = np.empty(n, dtype=bool), np.empty(n)
    nurbs.near_mesh_hits(k.astype(np.int64), S, Su, Sv, O, D, np.full(n, t_mesh), band, tracing.JUMP_LIMIT,
                         tracing.GRAZING_ALLOWANCE, near, t)
    assert not near[f > 1.0].any()  # nothing the filter drops could have passed
    grazing = (th == 0.5 * np.pi) & (f <= 1.0)
    assert near[grazing].all() and grazing.sum() == 3 * len(band)
    np.testing.assert_array_equal(t, t_mesh)


def test_compiled_rescue_answers_as_the_numpy_search():
    """Rays passing just above and below the teapot's surface at grazing incidence, the search started off the
    answer: the kernel's Levenberg–Marquardt reaches the same (u, v), S and verdicts (converged, stationary, on
    the domain edge) as its numpy implementation, ray for ray."""
    surfaces = SurfaceSet(read_bpt(TEAPOT))
    rng = np.random.default_rng(11)
    n = 600
    k = rng.integers(0, len(surfaces.patches), n)
    u0, v0 = rng.uniform(0.05, 0.95, n), rng.uniform(0.05, 0.95, n)
    d = surfaces.evaluate(k, u0, v0)
    normal = surfaces.normals(k, u0, v0, d)
    tangent = d.Su / np.linalg.norm(d.Su, axis=1, keepdims=True)
    D = tangent + rng.uniform(-0.05, 0.05, (n, 1)) * normal
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    O = d.S + rng.uniform(-0.02, 0.02, (n, 1)) * normal - 3.0 * D
    us, vs = np.clip(u0 + rng.uniform(-0.1, 0.1, n), 0, 1), np.clip(v0 + rng.uniform(-0.1, 0.1, n), 0, 1)
    tol = np.full(n, tracing.NEWTON_TOLERANCE * 3.0)
    got = tracing._rescue(surfaces, k, us, vs, O, D, tol)
    want = levenberg_marquardt(surfaces, k, us, vs, O, D, tol, tracing.RESCUE_STEPS, tracing.STATIONARY_COSINE,
                               tracing.STALLED_DAMPING, tracing.CRAWL_STEPS, tracing.CRAWL_GAIN)
    for name, a, b in (("u", got[0], want[0]), ("v", got[1], want[1]), ("S", got[2].S, want[2]),
                       ("converged", got[3], want[3]), ("stationary", got[4], want[4]), ("edge", got[5], want[5])):
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert got[3].sum() > 100 and got[4].sum() > 10, (got[3].sum(), got[4].sum())  # both verdicts exercised
    assert want[6].sum() > 0, "no ray crawls: the crawl stop is not exercised"


def test_second_process_loads_every_kernel_from_the_cache():
    code = """
import numpy as np
from pathlib import Path
from rtreflect.exchange.bpt import read_bpt
from rtreflect.geometry.surfaces import SurfaceSet
from rtreflect.trace.tracing import refine
from rtreflect.modes.lights import TubeLights, reflect, reflect_rays
from rtreflect.kernels import nurbs, tubes
surfaces = SurfaceSet(read_bpt(Path("scenes/teapot.bpt")))
k, u = np.array([0, 3]), np.array([0.2, 0.7])
surfaces.normals(k, u, u)
refine(surfaces, k, u, u, np.zeros((2, 3)), np.eye(3)[:2], np.ones(2), 1.0)
c, m = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
lights = TubeLights(np.zeros(3), m, c, np.cross(c, m), np.array([0.0, 1.0]), 0.1, 4.0)
lights.reach(np.ones((2, 3)), np.eye(3)[:2]); lights.distances(np.ones((2, 3)), np.eye(3)[:2])
used = [nurbs.evaluate, nurbs.unit_normals, nurbs.refine_mesh_hits, tubes.reach, tubes.distances]
print(sum(sum(f.stats.cache_misses.values()) for f in used), sum(sum(f.stats.cache_hits.values()) for f in used))
"""
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT,
                           env={"PYTHONPATH": str(ROOT), "PATH": "", "RTREFLECT_KERNELS": "jit"}) for _ in range(2)]
    misses, hits = map(int, runs[1].stdout.split())
    assert misses == 0 and hits == 5, f"second process compiled {misses} kernels (cache hits {hits})"


def test_kernels_call_only_kernels_of_their_own_file():
    """numba's cache watches the file defining a kernel: a caller cached in another file than its
    callee kept running the callee's old machine code after the callee changed (a segmentation
    fault in Newton after an edit of the evaluator). So no kernel module imports another's functions."""
    for file in (ROOT / "rtreflect" / "kernels").glob("*.py"):
        for line in file.read_text().splitlines():
            if file.stem in ("compiled", "build"):  # the loader and the AOT build, no kernels
                continue
            if line.startswith("from .") or line.startswith("from rtreflect.kernels"):
                # JIT's options and the decorator (`compiled.njit`: AOT or numba's JIT), no other file's kernel
                assert line in ("from . import JIT", "from .compiled import njit"), f"{file.name}: {line}"


def wavy_bicubic(seed: int = 2) -> "NurbsSurface":
    """A rational bicubic B-spline of 8×7 control points over several spans, an empty span (a double knot) in u."""
    from rtreflect import NurbsSurface

    rng = np.random.default_rng(seed)
    X, Y = np.meshgrid(np.linspace(-1.5, 1.5, 8), np.linspace(-1.0, 1.0, 7), indexing="ij")
    points = np.stack([X, Y, 0.2 * np.sin(2.0 * X) * np.cos(1.5 * Y) + 0.1 * X * Y], axis=-1)
    knots_u = np.array([0.0] * 4 + [0.3, 0.5, 0.5, 0.8] + [1.0] * 4)
    knots_v = np.array([0.0] * 4 + [0.25, 0.5, 0.75] + [1.0] * 4)
    return NurbsSurface(3, 3, knots_u, knots_v, points, rng.uniform(0.6, 1.4, (8, 7)))


def across_numpy(D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """e1, e2 ⊥ D as DESIGN.md's "Exact hit" defines them (helper axis along D's smallest component), in numpy."""
    x, y, z = D.T
    ax, ay, az = np.abs(D).T
    zero = np.zeros_like(x)
    first, second = (ax <= ay) & (ax <= az), ay <= az
    c = [np.where(first, zero, np.where(second, -z, y)), np.where(first, z, np.where(second, zero, -x)),
         np.where(first, -y, np.where(second, x, zero))]
    norm = np.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
    c0, c1, c2 = c[0] / norm, c[1] / norm, c[2] / norm
    return np.stack([c0, c1, c2], axis=1), np.stack([y * c2 - z * c1, z * c0 - x * c2, x * c1 - y * c0], axis=1)


def span_numpy(knots: np.ndarray, degree: int, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and length of the knot span `kernels.nurbs.find_span_at` gives t (the last non-empty one at the end)."""
    n_ctrl = len(knots) - degree - 1
    span = np.clip(np.searchsorted(knots, t, side="right") - 1, degree, n_ctrl - 1)
    return knots[span], knots[span + 1] - knots[span]


def taylor_finish_numpy(surfaces, k, d, u, v, un, vn, O, D, e1, e2, tol):
    """`kernels.nurbs.taylor_finish_lanes` in numpy: which of the points (patch k, evaluated to order 2 at (u, v) as
    d, Newton's step to (un, vn)) it finishes, and their S, S_u, S_v from the Taylor polynomials (the same
    operations in the same order, so the same bits)."""
    dot = lambda a, b: a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]  # noqa: E731 (coordinate order)
    du, dv = (un - u)[:, None], (vn - v)[:, None]
    uu, uv, vv = 0.5 * du * du, du * dv, 0.5 * dv * dv
    P = d.S + d.Su * du + d.Sv * dv + (d.Suu * uu + d.Suv * uv + d.Svv * vv)
    f1, f2 = dot(e1, P - O), dot(e2, P - O)
    cross = np.cross(d.Su, d.Sv)
    cosine = np.abs(dot(cross, D)) / np.sqrt(dot(cross, cross))
    u0, u1, v0, v1 = surfaces.domains(k)
    done = (f1 * f1 + f2 * f2 <= tol * tol) & (cosine > nurbs.TAYLOR_MIN_COSINE)
    turn = nurbs.TAYLOR_TURN * nurbs.TAYLOR_TURN
    done &= dot(d.Suu * du + d.Suv * dv, d.Suu * du + d.Suv * dv) <= turn * dot(d.Su, d.Su)
    done &= dot(d.Suv * du + d.Svv * dv, d.Suv * du + d.Svv * dv) <= turn * dot(d.Sv, d.Sv)
    for i in np.flatnonzero(done):
        patch = surfaces.patches[k[i]]
        if max(patch.degree_u, patch.degree_v) > nurbs.WRITTEN_OUT_DEGREE or nurbs.power_form(patch) is None:
            done[i] = False  # the scalar path: no span in the lane block
            continue
        for t, tn, lo, hi, knots, degree in ((u[i], un[i], u0[i], u1[i], patch.knots_u, patch.degree_u),
                                             (v[i], vn[i], v0[i], v1[i], patch.knots_v, patch.degree_v)):
            start, length = (x[0] for x in span_numpy(np.asarray(knots, dtype=np.float64), degree, np.array([t])))
            done[i] &= (max(start, lo) < tn < min(start + length, hi)) and abs(tn - t) <= nurbs.TAYLOR_SPAN_SHARE * length
    return done, P, d.Su + (d.Suu * du + d.Suv * dv), d.Sv + (d.Suv * du + d.Svv * dv)


def newton_numpy(surfaces, k, u, v, O, D, tol, max_steps):
    """Newton on the ray residual (DESIGN.md, "Exact hit") in numpy, all rays at once, one evaluation per step by
    `SurfaceSet.evaluate`, the step after the order-2 one (`kernels.nurbs.CURVATURE_EVALUATION`) finished without
    one where `taylor_finish_numpy` says so: (u, v, converged, S, S_u, S_v, finished)."""
    e1, e2 = across_numpy(D)
    u, v = u.copy(), v.copy()
    u0, u1, v0, v1 = surfaces.domains(k)
    S, Su, Sv = (np.empty((len(u), 3)) for _ in range(3))
    converged, live = np.zeros(len(u), dtype=bool), np.arange(len(u))
    finished = np.zeros(len(u), dtype=bool)
    dot = lambda a, b: a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]  # noqa: E731 (coordinate order)
    for step in range(max_steps + 1):
        d = surfaces.evaluate(k[live], u[live], v[live], order=2 if step == nurbs.CURVATURE_EVALUATION else 1)
        S[live], Su[live], Sv[live] = d.S, d.Su, d.Sv
        r = d.S - O[live]
        f1, f2 = dot(e1[live], r), dot(e2[live], r)
        ok = f1 * f1 + f2 * f2 <= tol[live] * tol[live]
        a, b, c, dd = dot(e1[live], d.Su), dot(e1[live], d.Sv), dot(e2[live], d.Su), dot(e2[live], d.Sv)
        det = a * dd - b * c
        regular = np.abs(det) > nurbs.SINGULAR_SINE * np.sqrt(dot(d.Su, d.Su)) * np.sqrt(dot(d.Sv, d.Sv))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            du, dv = (dd * f1 - b * f2) / det, (a * f2 - c * f1) / det
        go = ~ok & (step < max_steps) & regular & np.isfinite(du) & np.isfinite(dv)
        converged[live] = ok
        moving = live[go]
        u_at, v_at = u[moving], v[moving]
        u[moving] = np.minimum(np.maximum(u[moving] - du[go], u0[moving]), u1[moving])
        v[moving] = np.minimum(np.maximum(v[moving] - dv[go], v0[moving]), v1[moving])
        if step == nurbs.CURVATURE_EVALUATION and len(moving):
            done, P, Pu, Pv = taylor_finish_numpy(surfaces, k[moving], type(d)(*(x[go] for x in d)), u_at, v_at,
                                                  u[moving], v[moving], O[moving], D[moving], e1[moving], e2[moving],
                                                  tol[moving])
            rows = moving[done]
            S[rows], Su[rows], Sv[rows] = P[done], Pu[done], Pv[done]
            converged[rows] = finished[rows] = True
            moving = moving[~done]
        live = moving
    return u, v, converged, S, Su, Sv, finished


def test_newton_in_lane_blocks_is_bit_for_bit_the_iteration_in_numpy():
    """`refine_mesh_hits` runs Newton LANES rays at a time, vector loops over the rays of a block (`kernels.nurbs`,
    "Lane blocks"): each ray's (u, v), verdict and S, S_u, S_v are the bits of the same iteration written in numpy
    (one `SurfaceSet.evaluate` per step, the step after the order-2 one finished by Taylor polynomials where
    `taylor_finish_lanes` finishes it: `taylor_finish_numpy`), on a mix of bicubic spans (runs of rays on one span, spans left between
    steps, an empty span), a rational biquadratic patch (the scalar evaluation) and Bézier patches, over several
    blocks and a partial one, in sorted and in shuffled order."""
    from test_curvature import SQRT_HALF, revolve  # a rational biquadratic (the scalar path of a lane block)

    patches = [wavy_bicubic(), revolve([(2.0, 0.0, 1.0), (2.0, 2.0, SQRT_HALF), (0.0, 2.0, 1.0)])] + read_bpt(TEAPOT)[:4]
    surfaces = SurfaceSet(patches)
    rng = np.random.default_rng(21)
    n = 7 * nurbs.LANES + 57
    k = np.sort(rng.choice([0, 0, 0, 1, 2, 3, 4, 5], n))  # runs of rays on one patch, as a tile's pixels
    u0, v0 = rng.uniform(0.02, 0.98, (2, n))
    order = np.lexsort((u0, np.round(v0, 1), k))
    k, u0, v0 = k[order], u0[order], v0[order]
    target = surfaces.evaluate(k, u0, v0).S
    D = rng.normal(size=(n, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    O = target - 5.0 * D
    us, vs = u0 + rng.uniform(-0.08, 0.08, n), v0 + rng.uniform(-0.08, 0.08, n)  # some across a span's edge
    near = rng.random(n) < 0.3  # started close: their step after the order-2 evaluation is short (Taylor's)
    us[near], vs[near] = u0[near] + rng.uniform(-1e-4, 1e-4, near.sum()), v0[near] + rng.uniform(-1e-4, 1e-4, near.sum())
    t_mesh = np.full(n, 5.0)
    magnitude = np.abs(O + t_mesh[:, None] * D).max(axis=1)
    tol = tracing.NEWTON_TOLERANCE * np.maximum(np.maximum(t_mesh, 1.0), magnitude)
    want = newton_numpy(surfaces, k, us, vs, O, D, tol, tracing.NEWTON_MAX_STEPS)
    assert 0.5 * n < want[2].sum() < n, "both verdicts must be exercised"
    assert 0 < want[6].sum() < want[2].sum(), "Taylor's finish and the evaluations after it must be exercised"
    shuffled = rng.permutation(n)
    for rows in (np.arange(n), shuffled):
        u, v, d, converged, *_ = tracing.refine_all(surfaces, k[rows], us[rows], vs[rows], O[rows], D[rows],
                                                    t_mesh[rows], 1.0)
        for name, got, expected in (("u", u, want[0]), ("v", v, want[1]), ("converged", converged, want[2]),
                                    ("S", d.S, want[3]), ("Su", d.Su, want[4]), ("Sv", d.Sv, want[5])):
            assert np.array_equal(got.view(np.uint8), expected[rows].view(np.uint8)), name  # the bits, ±0 and NaN too
