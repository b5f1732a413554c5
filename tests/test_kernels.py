"""The compiled kernels (issue 14) against independent references, and their on-disk cache.

* tube distances (paper eq. 4) of finite tubes and rays parallel to the tubes, against a
  least-squares closest approach (tests/reference.py) and the point-to-line distance;
* a scene's patches evaluated in one kernel call, bit for bit each patch's own evaluation,
  whatever the mix or order of patches (what makes tiles independent of each other);
* Newton's converged hits lie on their rays and on the surface (rhino3dm's evaluator);
* a second process finds every kernel in numba's cache (no compilation).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from reference import closest_line_distance, to_rhino, xyz
from rtreflect.exchange.bpt import read_bpt
from rtreflect.geometry.surfaces import SurfaceSet
from rtreflect.modes.lights import TubeLights
from rtreflect.trace.tracing import refine

ROOT = Path(__file__).resolve().parents[1]
TEAPOT = ROOT / "scenes" / "teapot.bpt"


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


def test_second_process_loads_every_kernel_from_the_cache():
    code = """
import numpy as np
from pathlib import Path
from rtreflect.exchange.bpt import read_bpt
from rtreflect.geometry.surfaces import SurfaceSet
from rtreflect.trace.tracing import refine
from rtreflect.modes.lights import TubeLights
from rtreflect.kernels import nurbs, tubes
surfaces = SurfaceSet(read_bpt(Path("scenes/teapot.bpt")))
k, u = np.array([0, 3]), np.array([0.2, 0.7])
surfaces.normals(k, u, u)
refine(surfaces, k, u, u, np.zeros((2, 3)), np.eye(3)[:2], np.ones(2), 1.0)
c, m = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
lights = TubeLights(np.zeros(3), m, c, np.cross(c, m), np.array([0.0, 1.0]), 0.1, 4.0)
lights.reach(np.ones((2, 3)), np.eye(3)[:2]); lights.distances(np.ones((2, 3)), np.eye(3)[:2])
used = [nurbs.evaluate, nurbs.unit_normals, nurbs.newton, tubes.reach, tubes.distances]
print(sum(sum(f.stats.cache_misses.values()) for f in used), sum(sum(f.stats.cache_hits.values()) for f in used))
"""
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT,
                           env={"PYTHONPATH": str(ROOT), "PATH": ""}) for _ in range(2)]
    misses, hits = map(int, runs[1].stdout.split())
    assert misses == 0 and hits == 5, f"second process compiled {misses} kernels (cache hits {hits})"


def test_kernels_call_only_kernels_of_their_own_file():
    """numba's cache watches the file defining a kernel: a caller cached in another file than its
    callee kept running the callee's old machine code after the callee changed (a segmentation
    fault in Newton after an edit of the evaluator). So no kernel module imports another's functions."""
    for file in (ROOT / "rtreflect" / "kernels").glob("*.py"):
        for line in file.read_text().splitlines():
            if line.startswith("from .") or line.startswith("from rtreflect.kernels"):
                assert line == "from . import JIT", f"{file.name}: {line}"
