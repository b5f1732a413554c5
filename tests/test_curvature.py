"""Curvature from the fundamental forms (geometry/curvature.py) against closed forms, on exact RATIONAL NURBS.

A sphere of radius r has κ1 = κ2 = ±1/r; a cylinder ±1/r and 0; a torus (tube radius r about a
circle of radius R) K = cos t / (r (R + r cos t)) at tube angle t. Sphere and torus are
surfaces of revolution of a rational quadratic arc about the z axis (weights w_i w_j), so their
second derivatives are those of rational surfaces, where the quotient rule's terms must all be
right. Points come from a seeded generator, away from the sphere's pole (a degenerate point).
"""

from __future__ import annotations

import numpy as np
import pytest

from rtreflect import NurbsSurface
from rtreflect.geometry.curvature import curvatures, normal_curvature

SQRT_HALF = np.sqrt(0.5)
KNOTS = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])


def revolve(profile: list[tuple[float, float, float]]) -> NurbsSurface:
    """The quarter turn about z of a rational quadratic profile [(x, z, w)]: u along the profile, v around z."""
    turn = [((1.0, 0.0), 1.0), ((1.0, 1.0), SQRT_HALF), ((0.0, 1.0), 1.0)]  # (cos, sin) control of a quarter circle
    points = [[[x * cx, x * cy, z] for (cx, cy), _ in turn] for x, z, _ in profile]
    weights = [[w * wv for _, wv in turn] for _, _, w in profile]
    return NurbsSurface(2, 2, KNOTS, KNOTS, np.array(points), np.array(weights))


def sample(surface: NurbsSurface, count: int = 200, margin: float = 0.05, seed: int = 7):
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(margin, 1 - margin, (2, count))
    d = surface.evaluate(u, v, order=2)
    return d, surface.normals(u, v, d)


def outward_sign(n: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """+1 where n points along ``towards`` (away from the centre of curvature), −1 where it points back."""
    return np.sign(np.einsum("ij,ij->i", n, towards))


def test_rational_sphere_has_both_principal_curvatures_one_over_r():
    r = 2.5
    sphere = revolve([(r, 0.0, 1.0), (r, r, SQRT_HALF), (0.0, r, 1.0)])
    d, n = sample(sphere)
    assert np.allclose(np.linalg.norm(d.S, axis=1), r, rtol=1e-12)  # the net really is the sphere
    sign = outward_sign(n, d.S)
    c = curvatures(d, n)
    # Bending away from an outward normal: −1/r (positive where the surface bends towards n).
    np.testing.assert_allclose(c.k1, -sign / r, atol=1e-10)
    np.testing.assert_allclose(c.k2, -sign / r, atol=1e-10)
    np.testing.assert_allclose(c.K, 1 / r**2, rtol=1e-10)
    np.testing.assert_allclose(c.H, -sign / r, rtol=1e-10)


def test_rational_cylinder_has_curvatures_one_over_r_and_zero():
    r = 1.5
    arc = [(r, 0.0, 1.0), (r, r, SQRT_HALF), (0.0, r, 1.0)]  # (x, z, w) about the y axis
    ys = np.array([-1.0, 0.0, 1.0])
    points = np.array([[[x, y, z] for y in ys] for x, z, _ in arc])
    weights = np.array([[w] * 3 for _, _, w in arc])
    cylinder = NurbsSurface(2, 2, KNOTS, KNOTS, points, weights)
    d, n = sample(cylinder)
    radial = d.S * [1.0, 0.0, 1.0]
    assert np.allclose(np.linalg.norm(radial, axis=1), r, rtol=1e-12)
    sign = outward_sign(n, radial)
    c = curvatures(d, n)
    np.testing.assert_allclose(c.K, 0.0, atol=1e-10)
    np.testing.assert_allclose(np.where(sign > 0, c.k2, c.k1), -sign / r, atol=1e-10)
    np.testing.assert_allclose(np.where(sign > 0, c.k1, c.k2), 0.0, atol=1e-10)
    # Along the axis (w = y) the normal curvature is 0; around it, ∓1/r.
    along, around = np.tile([0.0, 1.0, 0.0], (len(n), 1)), np.cross([0.0, 1.0, 0.0], n)
    np.testing.assert_allclose(normal_curvature(d, n, along), 0.0, atol=1e-10)
    np.testing.assert_allclose(normal_curvature(d, n, around), -sign / r, atol=1e-10)


@pytest.mark.parametrize("quarter", ["outer", "inner"])
def test_rational_torus_gaussian_curvature_is_cos_t_over_r_times_R_plus_r_cos_t(quarter):
    R, r = 3.0, 1.0
    # The tube's profile circle about (R, 0) in the xz plane: the outer quarter (t from 0 to 90°, K > 0)
    # or the inner one (t from 90° to 180°, K < 0).
    if quarter == "outer":
        profile = [(R + r, 0.0, 1.0), (R + r, r, SQRT_HALF), (R, r, 1.0)]
    else:
        profile = [(R, r, 1.0), (R - r, r, SQRT_HALF), (R - r, 0.0, 1.0)]
    torus = revolve(profile)
    d, n = sample(torus)
    rho = np.hypot(d.S[:, 0], d.S[:, 1])
    cos_t = (rho - R) / r
    assert np.allclose((rho - R) ** 2 + d.S[:, 2] ** 2, r * r, rtol=1e-12)  # on the torus
    c = curvatures(d, n)
    expected = cos_t / (r * (R + r * cos_t))
    assert np.ptp(np.sign(expected)) == 0 and abs(expected).min() > 1e-3  # the quarter asked for, clear of K = 0
    np.testing.assert_allclose(c.K, expected, rtol=1e-9)
    # Principal curvatures, outward normal: −1/r around the tube, −cos t/(R + r cos t) around the z axis.
    centre = np.column_stack([R * d.S[:, 0] / rho, R * d.S[:, 1] / rho, np.zeros(len(rho))])
    sign = outward_sign(n, d.S - centre)
    pair = np.sort(np.column_stack([-sign / r, -sign * cos_t / (R + r * cos_t)]), axis=1)
    np.testing.assert_allclose(np.column_stack([c.k2, c.k1]), pair, atol=1e-10)


def test_flipping_the_normal_negates_the_mean_and_principal_curvatures_but_not_K():
    torus = revolve([(4.0, 0.0, 1.0), (4.0, 1.0, SQRT_HALF), (3.0, 1.0, 1.0)])
    d, n = sample(torus, seed=3)
    a, b = curvatures(d, n), curvatures(d, -n)
    np.testing.assert_allclose(b.K, a.K, rtol=1e-12)
    np.testing.assert_allclose(b.H, -a.H, rtol=1e-12)
    np.testing.assert_allclose(b.k1, -a.k2, atol=1e-12)
    np.testing.assert_allclose(b.k2, -a.k1, atol=1e-12)
    assert np.all(a.k1 >= a.k2)


# -- The compiled kernel against the numpy formulas it replaced (kept here as the reference) ----------

def reference_curvatures(d, n):
    """K, H, κ1, κ2 by the module doc's formulas in numpy (the implementation before the kernel)."""
    dot = lambda a, b: np.einsum("ij,ij->i", a, b)  # noqa: E731
    E, F, G = dot(d.Su, d.Su), dot(d.Su, d.Sv), dot(d.Sv, d.Sv)
    L, M, N = dot(d.Suu, n), dot(d.Suv, n), dot(d.Svv, n)
    det = E * G - F * F
    K = (L * N - M * M) / det
    H = (E * N - 2 * F * M + G * L) / (2 * det)
    root = np.sqrt(np.maximum(H * H - K, 0.0))
    return K, H, H + root, H - root, (E, F, G, L, M, N)


def two_patches():
    sphere = revolve([(2.0, 0.0, 1.0), (2.0, 2.0, SQRT_HALF), (0.0, 2.0, 1.0)])
    torus = revolve([(3.0, 1.0, 1.0), (2.0, 1.0, SQRT_HALF), (2.0, 0.0, 1.0)])
    return sphere, torus


def test_kernel_curvatures_match_the_numpy_formulas_to_rounding():
    for surface in two_patches():
        d, n = sample(surface, count=300, seed=11)
        got = curvatures(d, n)
        *want, _ = reference_curvatures(d, n)
        np.testing.assert_allclose(got.K, want[0], rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(got.H, want[1], rtol=1e-11, atol=1e-12)
        # κ1,2 = H ± √(H² − K): at the sphere's umbilics the root of a rounding-sized H² − K is ~1e-8.
        np.testing.assert_allclose(got.k1, want[2], atol=1e-7)
        np.testing.assert_allclose(got.k2, want[3], atol=1e-7)


def test_fused_curvatures_at_equal_evaluate_then_curvatures_bit_for_bit_on_a_mix_of_patches():
    from rtreflect.geometry.curvature import curvatures_at
    from rtreflect.geometry.surfaces import SurfaceSet

    surfaces = SurfaceSet(list(two_patches()))
    rng = np.random.default_rng(5)
    count = 400
    patch = rng.integers(-1, 2, count)  # −1: a ray that hit nothing
    u, v = rng.uniform(0.05, 0.95, (2, count))
    u[patch < 0] = np.nan
    d = surfaces.evaluate(patch, u, v, order=2)
    n = -surfaces.normals(patch, u, v, d)  # signed as the caller gives them (here: flipped)
    fused = curvatures_at(surfaces, patch, u, v, n)
    hit = patch >= 0
    assert 100 < hit.sum() < count
    two_pass = curvatures(type(d)(*(x[hit] for x in d)), n[hit])
    for a, b in zip(fused, two_pass):
        assert np.array_equal(a[hit], b)
        assert np.isnan(a[~hit]).all()
    # and both are the closed form: the sphere's |κ1| = |κ2| = 1/r.
    on_sphere = patch == 0
    np.testing.assert_allclose(np.abs(fused.k1[on_sphere]), 0.5, atol=1e-7)
    np.testing.assert_allclose(np.abs(fused.k2[on_sphere]), 0.5, atol=1e-7)


def test_kernel_normal_curvature_matches_the_numpy_formula():
    _, torus = two_patches()
    d, n = sample(torus, count=200, seed=2)
    rng = np.random.default_rng(4)
    w = np.cross(n, rng.normal(size=(len(n), 3)))  # a random tangent direction
    *_, (E, F, G, L, M, N) = reference_curvatures(d, n)
    wu, wv = np.einsum("ij,ij->i", w, d.Su), np.einsum("ij,ij->i", w, d.Sv)
    a, b = (G * wu - F * wv) / (E * G - F * F), (E * wv - F * wu) / (E * G - F * F)
    want = (L * a * a + 2 * M * a * b + N * b * b) / (E * a * a + 2 * F * a * b + G * b * b)
    np.testing.assert_allclose(normal_curvature(d, n, w), want, rtol=1e-10)


def test_curvatures_in_lane_blocks_equal_evaluate_then_curvatures_bit_for_bit_on_bicubic_spans():
    """`curvatures_at` evaluates LANES points at a time, one vector loop per run of points on one bicubic span
    (`kernels.nurbs`, "Lane blocks"): bit for bit the order-2 evaluation (`SurfaceSet.evaluate`) then `curvatures`,
    on a multi-span rational bicubic (runs on one span, span changes, an empty span, points clamped into the
    domain) beside the rational sphere (the scalar path) and misses, over several blocks, sorted and shuffled."""
    from test_kernels import wavy_bicubic

    from rtreflect.geometry.curvature import curvatures_at
    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.kernels.nurbs import LANES

    surfaces = SurfaceSet([wavy_bicubic(), *two_patches()])
    rng = np.random.default_rng(8)
    count = 5 * LANES + 31
    patch = rng.choice([-1, 0, 0, 0, 0, 1, 2], count)
    u, v = rng.uniform(-0.02, 1.02, (2, count))
    order = np.lexsort((u, np.round(v, 1), patch))
    patch, u, v = patch[order], u[order], v[order]
    d = surfaces.evaluate(patch, u, v, order=2)
    n = surfaces.normals(patch, u, v, d)
    hit = patch >= 0
    two_pass = curvatures(type(d)(*(x[hit] for x in d)), n[hit])
    for rows in (np.arange(count), rng.permutation(count)):
        fused = curvatures_at(surfaces, patch[rows], u[rows], v[rows], n[rows])
        for a, b in zip(fused, two_pass):
            got = np.full(count, np.nan)
            got[rows] = a
            assert np.array_equal(got[hit].view(np.int64), b.view(np.int64))
            assert np.isnan(got[~hit]).all()
    assert np.isfinite(two_pass[0]).mean() > 0.9
