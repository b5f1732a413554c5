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
