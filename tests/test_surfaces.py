"""The NURBS evaluator checked against independent references.

* rhino3dm (OpenNURBS, a separate C++ implementation) for points, unit normals and
  the first and second derivatives along the parameter directions;
* central finite differences of the evaluator's own S for all derivatives;
* closed forms: a rational quarter cylinder, and the teapot's poles, where the
  normal must be the vertical limit from the interior;
* the partition of unity of the B-spline basis.

rhino3dm conventions these tests rely on (each pinned by a test of its own below):

* knot vectors are stored without the first and last knot of the full clamped
  vector: ``len(KnotsU) == count_u + degree_u - 1``;
* ``Points[i, j] = Point4d(x, y, z, w)`` takes *homogeneous* coordinates
  (w·P, w) on a rational surface;
* ``NormalAt`` is unit(S_u × S_v), the same orientation as ours, and at a pole it
  returns the limit from the interior.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import rhino3dm
from hypothesis import given, settings, strategies as st

from reference import angle_between, to_rhino, xyz
from rtreflect.exchange.bpt import read_bpt
from rtreflect.geometry.knots import knot_vector_problem
from rtreflect.geometry.surfaces import NurbsSurface, SurfaceSet, basis_derivatives, find_span

TEAPOT = Path(__file__).resolve().parents[1] / "scenes" / "teapot.bpt"
LID_APEX = np.array([0.0, 0.0, 3.15])
BOTTOM_CENTRE = np.array([0.0, 0.0, 0.0])

# Fixed example order keeps runs reproducible; no deadline because the first
# example pays for numpy/rhino3dm warm-up.
RANDOM_SURFACES = settings(max_examples=150, deadline=None, derandomize=True)


# --------------------------------------------------------------------------- helpers


def clamped_knots(rng: np.random.Generator, degree: int, multiplicities: list[int]) -> np.ndarray:
    """Full clamped knot vector on a random interval with the given interior multiplicities.

    Interior knots are kept at least 5 % of the domain apart, so no span is so
    short that the finite-difference tests below would straddle it.
    """
    lo = rng.uniform(-2.0, 2.0)
    hi = lo + rng.uniform(0.5, 3.0)
    while True:
        interior = np.sort(rng.uniform(lo, hi, len(multiplicities)))
        if np.diff(np.r_[lo, interior, hi]).min() > 0.05 * (hi - lo):
            break
    return np.r_[np.full(degree + 1, lo), np.repeat(interior, multiplicities), np.full(degree + 1, hi)]


@st.composite
def nurbs_surfaces(draw, min_degree: int = 1, max_degree: int = 5) -> tuple[NurbsSurface, np.random.Generator]:
    """A random NURBS surface, and an RNG (seeded by hypothesis) for sample parameters.

    The structure (degrees, interior knot multiplicities up to the degree, rational or
    not) is drawn by hypothesis so failures shrink to a small case; the floating-point
    values come from a seeded numpy RNG. The control net is a jittered grid with
    random heights, offset and scaled: a general surface, but one whose S_u and S_v
    stay clearly apart, so normals are well conditioned.
    """
    degree_u = draw(st.integers(min_degree, max_degree), label="degree_u")
    degree_v = draw(st.integers(min_degree, max_degree), label="degree_v")
    mult_u = draw(st.lists(st.integers(1, degree_u), max_size=3), label="multiplicities_u")
    mult_v = draw(st.lists(st.integers(1, degree_v), max_size=3), label="multiplicities_v")
    rational = draw(st.booleans(), label="rational")
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1), label="seed"))

    knots_u = clamped_knots(rng, degree_u, mult_u)
    knots_v = clamped_knots(rng, degree_v, mult_v)
    nu, nv = len(knots_u) - degree_u - 1, len(knots_v) - degree_v - 1
    grid_i, grid_j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    points = np.stack([grid_i, grid_j, np.zeros_like(grid_i)], axis=-1).astype(float)
    points[..., :2] += rng.uniform(-0.3, 0.3, (nu, nv, 2))
    points[..., 2] = rng.uniform(-1.5, 1.5, (nu, nv))
    points = points * 10.0 ** rng.uniform(-1, 2) + rng.uniform(-5, 5, 3)
    weights = rng.uniform(0.3, 3.0, (nu, nv)) if rational else np.ones((nu, nv))
    return NurbsSurface(degree_u, degree_v, knots_u, knots_v, points, weights), rng


def random_parameters(surface: NurbsSurface, rng: np.random.Generator, count: int) -> tuple[np.ndarray, np.ndarray]:
    (u0, u1), (v0, v1) = surface.domain
    return rng.uniform(u0, u1, count), rng.uniform(v0, v1, count)


def net_scale(surface: NurbsSurface) -> float:
    """Largest coordinate of the control net: the yardstick for point errors."""
    return float(np.abs(surface.points).max())


def net_size(surface: NurbsSurface) -> float:
    """Extent of the control net (offset-free): the yardstick for derivatives."""
    return float(np.ptp(surface.points.reshape(-1, 3), axis=0).max())


# --------------------------------------------------------------------------- rhino3dm conventions


def test_rhino_knot_vector_omits_the_end_knots():
    rh = rhino3dm.NurbsSurface.Create(3, False, 3, 2, 4, 2)  # orders 3 and 2, 4 × 2 points
    assert len(rh.KnotsU) == 4 + 2 - 1
    assert len(rh.KnotsV) == 2 + 1 - 1
    for k, t in enumerate([0.0, 0.0, 0.5, 1.0, 1.0]):  # full vector: [0, 0, 0, .5, 1, 1, 1]
        rh.KnotsU[k] = t
    for k, t in enumerate([2.0, 5.0]):  # full vector: [2, 2, 5, 5]
        rh.KnotsV[k] = t
    for i in range(4):
        for j in range(2):
            rh.Points[i, j] = rhino3dm.Point4d(i, j, 0.0, 1.0)
    assert rh.IsValid
    assert (rh.Domain(0).T0, rh.Domain(0).T1) == (0.0, 1.0)
    assert (rh.Domain(1).T0, rh.Domain(1).T1) == (2.0, 5.0)


def quarter_arc_surface_in_rhino(homogeneous: bool) -> rhino3dm.NurbsSurface:
    """The unit quarter circle (1,0) → (0,1) in x-z, extruded along y, set into rhino3dm
    either as homogeneous (w·P, w) or as euclidean (P, w) Point4d values."""
    arc = [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    arc_weights = [1.0, math.sqrt(0.5), 1.0]
    rh = rhino3dm.NurbsSurface.Create(3, True, 3, 2, 3, 2)
    for i, ((x, z), w) in enumerate(zip(arc, arc_weights)):
        for j, y in enumerate((-1.0, 1.0)):
            f = w if homogeneous else 1.0
            rh.Points[i, j] = rhino3dm.Point4d(x * f, y * f, z * f, w)
    for k, t in enumerate([0.0, 0.0, 1.0, 1.0]):
        rh.KnotsU[k] = t
    for k, t in enumerate([0.0, 1.0]):
        rh.KnotsV[k] = t
    return rh


def test_rhino_rational_control_points_are_homogeneous():
    """Only the homogeneous reading puts the rational quarter arc on the unit circle."""
    u = np.linspace(0.0, 1.0, 11)
    homogeneous = quarter_arc_surface_in_rhino(homogeneous=True)
    radius = [math.hypot(p.X, p.Z) for p in (homogeneous.PointAt(t, 0.4) for t in u)]
    np.testing.assert_allclose(radius, 1.0, rtol=0, atol=1e-14)
    assert xyz(homogeneous.Points.GetPoint(1, 0)) == pytest.approx([1.0, -1.0, 1.0], abs=1e-15)

    euclidean = quarter_arc_surface_in_rhino(homogeneous=False)
    mid = euclidean.PointAt(0.5, 0.4)
    assert math.hypot(mid.X, mid.Z) > 1.1, "euclidean (P, w) input would also give the circle: convention unclear"


def test_rhino_normal_is_su_cross_sv():
    """On the quarter cylinder S_u ≈ (-1, 0, 1), S_v = (0, 2, 0) mid-arc: S_u × S_v points to -(x, 0, z)."""
    rh = quarter_arc_surface_in_rhino(homogeneous=True)
    assert xyz(rh.NormalAt(0.5, 0.4)) == pytest.approx([-math.sqrt(0.5), 0.0, -math.sqrt(0.5)], abs=1e-15)


# --------------------------------------------------------------------------- against rhino3dm


def assert_points_agree_with_rhino(surface: NurbsSurface, rng: np.random.Generator, err_msg: str = "") -> None:
    rh = to_rhino(surface)
    u, v = random_parameters(surface, rng, 40)
    # Also the domain corners and every knot, where spans change and the basis has
    # its special cases (exact knot, end of domain).
    (u0, u1), (v0, v1) = surface.domain
    knots_u, knots_v = surface.span_breaks()
    u = np.r_[u, np.repeat(knots_u, 2), u0, u1, u1, u0, rng.uniform(u0, u1, len(knots_v))]
    v = np.r_[v, rng.uniform(v0, v1, 2 * len(knots_u)), v0, v1, v0, v1, knots_v]

    ours = surface.evaluate(u, v).S
    theirs = np.array([xyz(rh.PointAt(a, b)) for a, b in zip(u, v)])
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12 * net_scale(surface), err_msg=err_msg)


@RANDOM_SURFACES
@given(nurbs_surfaces())
def test_points_agree_with_rhino(case):
    assert_points_agree_with_rhino(*case)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(nurbs_surfaces(min_degree=6, max_degree=9))
def test_points_agree_with_rhino_at_high_degrees(case):
    """Degrees beyond the teapot's: the evaluator must not trade accuracy for speed there either."""
    surface, rng = case
    assert_points_agree_with_rhino(
        surface,
        rng,
        err_msg=f"degrees ({surface.degree_u}, {surface.degree_v}): points off by more than 1e-12 x the net's size. "
        "Known cause: the per-span power (Taylor) form that rtreflect uses up to degree 7 "
        "(POWER_FORM_MAX_DEGREE) is worse conditioned than the B-spline recurrences.",
    )


@RANDOM_SURFACES
@given(nurbs_surfaces())
def test_normals_agree_with_rhino_including_orientation(case):
    surface, rng = case
    rh = to_rhino(surface)
    u, v = random_parameters(surface, rng, 40)
    d = surface.evaluate(u, v)
    # The normal's direction is only as well determined as S_u and S_v are apart;
    # where they nearly align any two correct evaluators may disagree by more than
    # 1e-9 rad. The jittered-grid nets make that rare; the assertion keeps it so.
    sine = np.linalg.norm(np.cross(d.Su, d.Sv), axis=1) / (np.linalg.norm(d.Su, axis=1) * np.linalg.norm(d.Sv, axis=1))
    conditioned = sine > 1e-2
    assert conditioned.mean() > 0.8, "test set-up: too few well-conditioned sample points"
    u, v = u[conditioned], v[conditioned]

    ours = surface.normals(u, v)
    theirs = np.array([xyz(rh.NormalAt(a, b)) for a, b in zip(u, v)])
    assert not np.isnan(ours).any()
    np.testing.assert_allclose(np.linalg.norm(ours, axis=1), 1.0, rtol=0, atol=1e-14)
    # Signed angle: both must be unit(S_u × S_v), not merely parallel.
    assert angle_between(ours, theirs).max() <= 1e-9


@RANDOM_SURFACES
@given(nurbs_surfaces())
def test_directional_derivatives_agree_with_rhino_iso_curves(case):
    """S_u, S_uu from the iso-curve v = const, S_v, S_vv from u = const (rhino3dm has no
    surface derivative API); S_uv from central differences of rhino's S_u in v."""
    surface, rng = case
    rh = to_rhino(surface)
    u, v = random_parameters(surface, rng, 8)
    d = surface.evaluate(u, v, order=2)
    h = 1e-6 * (surface.domain[1][1] - surface.domain[1][0])
    along_u, along_v, rhino_suv = [], [], []
    for a, b in zip(u, v):
        along_u.append([xyz(p) for p in rh.IsoCurve(0, b).DerivativeAt(a, 2)])  # v fixed: S, S_u, S_uu
        along_v.append([xyz(p) for p in rh.IsoCurve(1, a).DerivativeAt(b, 2)])  # u fixed: S, S_v, S_vv
        su_above = xyz(rh.IsoCurve(0, b + h).DerivativeAt(a, 1)[1])
        su_below = xyz(rh.IsoCurve(0, b - h).DerivativeAt(a, 1)[1])
        rhino_suv.append((su_above - su_below) / (2 * h))
    along_u, along_v = np.array(along_u), np.array(along_v)

    def assert_close(ours, theirs, rtol, what):
        # Relative to the largest such derivative in the batch: components may be ~0.
        atol = rtol * np.abs(theirs).max() + 1e-12 * net_scale(surface)
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=atol, err_msg=what)

    assert_close(d.S, along_u[:, 0], 1e-12, "S (iso-curve in u)")
    assert_close(d.S, along_v[:, 0], 1e-12, "S (iso-curve in v)")
    assert_close(d.Su, along_u[:, 1], 1e-11, "S_u")
    assert_close(d.Sv, along_v[:, 1], 1e-11, "S_v")
    assert_close(d.Suu, along_u[:, 2], 1e-10, "S_uu")
    assert_close(d.Svv, along_v[:, 2], 1e-10, "S_vv")
    # Sample points may sit within h of an interior knot where S_uv jumps: skip those.
    knots_v = surface.span_breaks()[1]
    clear = np.abs(v[:, None] - knots_v[None, :]).min(axis=1) > 2 * h
    assert_close(d.Suv[clear], np.array(rhino_suv)[clear], 1e-5, "S_uv")


# --------------------------------------------------------------------------- finite differences


def points_clear_of_knots(surface: NurbsSurface, rng: np.random.Generator, count: int, margin_u: float, margin_v: float):
    """Random (u, v) clear of every knot by the margins: central differences must not
    straddle a knot, where derivatives may jump."""
    knots_u, knots_v = surface.span_breaks()
    u, v = random_parameters(surface, rng, 4 * count)
    clear = (np.abs(u[:, None] - knots_u).min(axis=1) > margin_u) & (np.abs(v[:, None] - knots_v).min(axis=1) > margin_v)
    return u[clear][:count], v[clear][:count]


@settings(max_examples=100, deadline=None, derandomize=True)
@given(nurbs_surfaces())
def test_derivatives_match_central_differences(case):
    surface, rng = case
    # Steps scale with the shortest knot span: the k-th derivative grows like
    # (net size) / span^k, and so does the truncation error of the differences.
    gap_u, gap_v = (np.diff(breaks).min() for breaks in surface.span_breaks())
    h1u, h1v = 1e-5 * gap_u, 1e-5 * gap_v
    # A larger step for second differences, whose rounding grows as eps·|S|/h²; its
    # O(h²) truncation error (large on rational nets with uneven weights) is removed
    # by Richardson extrapolation over steps h and 2h.
    h2u, h2v = 1e-3 * gap_u, 1e-3 * gap_v
    u, v = points_clear_of_knots(surface, rng, 20, 3 * h2u, 3 * h2v)
    d = surface.evaluate(u, v, order=2)

    def S(du, dv):
        return surface.evaluate(u + du, v + dv).S

    def second_differences(hu, hv):
        suu = (S(hu, 0) - 2 * S(0, 0) + S(-hu, 0)) / hu**2
        svv = (S(0, hv) - 2 * S(0, 0) + S(0, -hv)) / hv**2
        suv = (S(hu, hv) - S(hu, -hv) - S(-hu, hv) + S(-hu, -hv)) / (4 * hu * hv)
        return np.array([suu, svv, suv])

    fd_su = (S(h1u, 0) - S(-h1u, 0)) / (2 * h1u)
    fd_sv = (S(0, h1v) - S(0, -h1v)) / (2 * h1v)
    fd_suu, fd_svv, fd_suv = (4 * second_differences(h2u, h2v) - second_differences(2 * h2u, 2 * h2v)) / 3

    size = net_size(surface)
    for name, ours, fd, natural_size, rtol in [
        ("S_u", d.Su, fd_su, size / gap_u, 1e-7),
        ("S_v", d.Sv, fd_sv, size / gap_v, 1e-7),
        ("S_uu", d.Suu, fd_suu, size / gap_u**2, 1e-5),
        ("S_vv", d.Svv, fd_svv, size / gap_v**2, 1e-5),
        ("S_uv", d.Suv, fd_suv, size / (gap_u * gap_v), 1e-5),
    ]:
        # Relative to the batch's largest such derivative or, if larger, to the size
        # such a derivative has on this net and these spans: components may be ~0.
        atol = rtol * max(np.abs(fd).max(), natural_size)
        np.testing.assert_allclose(ours, fd, rtol=0, atol=atol, err_msg=name)


# --------------------------------------------------------------------------- closed form: quarter cylinder


def quarter_cylinder() -> NurbsSurface:
    """Radius 1 about the y axis, x-z arc from (1, ·, 0) to (0, ·, 1), y from -1 to 1."""
    points = np.array([[[1, -1, 0], [1, 1, 0]], [[1, -1, 1], [1, 1, 1]], [[0, -1, 1], [0, 1, 1]]], dtype=float)
    weights = np.array([[1.0, 1.0], [math.sqrt(0.5)] * 2, [1.0, 1.0]])
    return NurbsSurface(2, 1, np.array([0, 0, 0, 1, 1, 1.0]), np.array([0, 0, 1, 1.0]), points, weights)


def test_quarter_cylinder_points_lie_on_the_unit_cylinder():
    cylinder = quarter_cylinder()
    rng = np.random.default_rng(1)
    u = np.r_[rng.uniform(0, 1, 2000), 0.0, 1.0, 0.5]
    v = np.r_[rng.uniform(0, 1, 2000), 0.0, 1.0, 0.5]
    S = cylinder.evaluate(u, v).S
    np.testing.assert_allclose(S[:, 0] ** 2 + S[:, 2] ** 2, 1.0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(S[:, 1], 2 * v - 1, rtol=0, atol=1e-15)  # linear in v: weights equal along v
    assert (S[:, 0] >= 0).all() and (S[:, 2] >= 0).all()  # the first quadrant only
    np.testing.assert_allclose(S[-3:], [[1, -1, 0], [0, 1, 1], [math.sqrt(0.5), 0, math.sqrt(0.5)]], atol=1e-15)


def test_quarter_cylinder_normals_point_to_the_axis():
    """The normal is radial; S_u × S_v (u runs from x towards z, v along +y) points inwards."""
    cylinder = quarter_cylinder()
    rng = np.random.default_rng(2)
    u = np.r_[rng.uniform(0, 1, 2000), 0.0, 1.0]
    v = np.r_[rng.uniform(0, 1, 2000), 0.0, 1.0]
    S = cylinder.evaluate(u, v).S
    inward = -S * [1.0, 0.0, 1.0]
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    np.testing.assert_allclose(cylinder.normals(u, v), inward, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- closed sides: surfaces of revolution

#: The unit circle as a rational quadratic (Piegl & Tiller, section 7.5): 9 control points on the square's corners and
#: edge midpoints, u ∈ [0, 4], one quarter per span, from (1, 0) counter-clockwise.
CIRCLE_XY = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1], [1, 0]], dtype=float)
CIRCLE_W = np.array([1, math.sqrt(0.5)] * 4 + [1])
CIRCLE_KNOTS = np.array([0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 4], dtype=float)


def revolved(profile: np.ndarray, weights: np.ndarray, degree: int, knots: np.ndarray) -> NurbsSurface:
    """The profile (m, 2) of (radius, z) revolved about the z axis: u around the circle, v along the profile
    (the tensor product of the circle's and the profile's rational control nets)."""
    points = np.array([[[r * x, r * y, z] for r, z in profile] for x, y in CIRCLE_XY])
    return NurbsSurface(2, degree, CIRCLE_KNOTS, knots, points, np.outer(CIRCLE_W, weights))


def full_cylinder(radius: float = 1.0, height: float = 2.0) -> NurbsSurface:
    return revolved(np.array([[radius, 0.0], [radius, height]]), np.ones(2), 1, np.array([0, 0, 1, 1.0]))


def test_closed_sides_of_surfaces_of_revolution():
    """`SurfaceSet.closed` against the construction: a full cylinder and a sphere are closed around (u) only (the
    sphere's v ends are its two distinct poles), a torus in both directions, a quarter cylinder in neither; a full
    cylinder whose seam is opened by 1e-4 of its radius is not closed, one opened by 1e-8 (an exporter's
    tolerance, `CLOSED_FRACTION`) is."""
    c = math.sqrt(0.5)
    sphere = revolved(np.array([[0, -1], [1, -1], [1, 0], [1, 1], [0, 1]], dtype=float), np.array([1, c, 1, c, 1]), 2,
                      np.array([0, 0, 0, 1, 1, 2, 2, 2], dtype=float))
    torus = revolved(np.column_stack([2.0 + 0.5 * CIRCLE_XY[:, 0], 0.5 * CIRCLE_XY[:, 1]]), CIRCLE_W, 2, CIRCLE_KNOTS)
    def opened(gap: float) -> NurbsSurface:
        cylinder = full_cylinder()
        points = cylinder.points.copy()
        points[-1, :, 1] -= gap  # the last control row, at u = 4, moved off the first one
        return NurbsSurface(2, 1, cylinder.knots_u, cylinder.knots_v, points, cylinder.weights)

    surfaces = SurfaceSet([full_cylinder(), sphere, torus, quarter_cylinder(), opened(1e-4), opened(1e-8)])
    np.testing.assert_array_equal(surfaces.closed, [[True, False], [True, False], [True, True], [False, False],
                                                    [False, False], [True, False]])
    S = sphere.evaluate(np.array([0.0, 4.0, 1.3]), np.array([0.0, 0.0, 2.0])).S  # the poles, any u
    np.testing.assert_allclose(S, [[0, 0, -1], [0, 0, -1], [0, 0, 1]], atol=1e-15)


# --------------------------------------------------------------------------- degenerate normals: teapot poles


@pytest.fixture(scope="module")
def teapot() -> list[NurbsSurface]:
    return read_bpt(TEAPOT)


def patches_collapsed_at(patches: list[NurbsSurface], pole: np.ndarray) -> list[NurbsSurface]:
    """Patches whose whole u = 0 row of control points is the pole (the teapot's convention;
    asserted so a file with poles on another edge does not silently test nothing)."""
    found = [p for p in patches if np.all(p.points[0] == pole)]
    assert found, f"no teapot patch collapses its u = 0 edge to {pole}"
    return found


@pytest.mark.parametrize(
    "pole, expected_z",
    # Limits of S_u × S_v: at both poles it points into the teapot (lid top -z, bottom +z).
    [(LID_APEX, -1.0), (BOTTOM_CENTRE, +1.0)],
    ids=["lid apex", "bottom centre"],
)
def test_pole_normal_is_the_vertical_limit(teapot, pole, expected_z):
    patches = patches_collapsed_at(teapot, pole)
    assert len(patches) == 4
    v = np.r_[np.linspace(0.0, 1.0, 21), 0.5 + 1e-9]
    u = np.zeros_like(v)
    for patch in patches:
        S = patch.evaluate(u, v).S
        np.testing.assert_allclose(S, np.broadcast_to(pole, S.shape), rtol=1e-15, atol=1e-15, err_msg="u = 0 is not the pole")

        normal = patch.normals(u, v)
        assert np.isfinite(normal).all(), f"{patch.name}: non-finite normal at the pole"
        up = np.broadcast_to([0.0, 0.0, expected_z], normal.shape)
        assert angle_between(normal, up).max() <= 1e-9, f"{patch.name}: pole normal not along {up[0]}"

        # The orientation is the limit of the plain S_u × S_v from the interior, computed here
        # without normals(), so normals() cannot agree with itself by construction.
        inside = patch.evaluate(u + 1e-7, v)
        cross = np.cross(inside.Su, inside.Sv)
        cross /= np.linalg.norm(cross, axis=1, keepdims=True)
        assert angle_between(normal, cross).max() <= 1e-6, f"{patch.name}: pole normal is not the interior limit"
        assert angle_between(normal, patch.normals(u + 1e-7, v)).max() <= 1e-6, f"{patch.name}: normal jumps at the pole"

        # OpenNURBS also takes the limit at a singular point: an independent opinion.
        rh = to_rhino(patch)
        theirs = np.array([xyz(rh.NormalAt(0.0, b)) for b in v])
        assert angle_between(normal, theirs).max() <= 1e-9, f"{patch.name}: pole normal differs from rhino3dm"


# --------------------------------------------------------------------------- basis functions


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    degree=st.integers(1, 6),
    multiplicities=st.lists(st.integers(1, 6), max_size=4),
    seed=st.integers(0, 2**32 - 1),
)
def test_basis_is_a_partition_of_unity(degree, multiplicities, seed):
    rng = np.random.default_rng(seed)
    # An interior knot repeated more than the degree times would split the spline.
    knots = clamped_knots(rng, degree, [min(m, degree) for m in multiplicities])
    n_ctrl = len(knots) - degree - 1
    lo, hi = knots[degree], knots[n_ctrl]
    interior = np.unique(knots[(knots > lo) & (knots < hi)])
    t = np.r_[lo, hi, interior, rng.uniform(lo, hi, 50)]

    span = find_span(knots, degree, n_ctrl, t)
    # The span holds t and is non-empty, the domain's end included.
    assert (knots[span] <= t).all()
    assert (knots[span] < knots[span + 1]).all()
    assert ((t < knots[span + 1]) | (t == hi)).all()

    order = degree + 1  # one beyond the degree: that derivative must vanish
    ders = basis_derivatives(knots, degree, span, t, order)
    assert ders.shape == (len(t), order + 1, degree + 1)
    np.testing.assert_allclose(ders[:, 0].sum(axis=1), 1.0, rtol=0, atol=1e-14)
    assert (ders[:, 0] >= -1e-15).all(), "basis functions must be non-negative"
    # Derivatives of a constant sum vanish; their size grows like (degree / knot gap)^k.
    for k in range(1, order + 1):
        size = np.abs(ders[:, k]).max(axis=1) + 1.0
        np.testing.assert_allclose(ders[:, k].sum(axis=1) / size, 0.0, rtol=0, atol=1e-12, err_msg=f"derivative {k}")
    np.testing.assert_array_equal(ders[:, degree + 1], 0.0)

    # A clamped basis interpolates at the ends: there only the first (last) function is 1.
    np.testing.assert_allclose(ders[0, 0], np.eye(degree + 1)[0], rtol=0, atol=1e-15, err_msg="at the start")
    np.testing.assert_allclose(ders[1, 0], np.eye(degree + 1)[-1], rtol=0, atol=1e-15, err_msg="at the end")


# --------------------------------------------------------------------------- knot vectors


@settings(max_examples=100, deadline=None, derandomize=True)
@given(
    degree=st.integers(1, 5),
    multiplicities=st.lists(st.integers(1, 6), max_size=3),
    seed=st.integers(0, 2**32 - 1),
)
def test_knot_multiplicities_are_accepted_exactly_where_rhino_accepts_them(degree, multiplicities, seed):
    """Inner knots up to the degree (a C0 crease at most) are fine; degree + 1 splits the surface: OpenNURBS agrees."""
    rng = np.random.default_rng(seed)
    multiplicities = [min(m, degree + 1) for m in multiplicities]
    knots = clamped_knots(rng, degree, multiplicities)
    n_ctrl = len(knots) - degree - 1
    rh = rhino3dm.NurbsSurface.Create(3, False, degree + 1, 2, n_ctrl, 2)
    for i in range(n_ctrl):
        for j in range(2):
            rh.Points[i, j] = rhino3dm.Point4d(float(i), float(j), float((i * j) % 3), 1.0)
    for k, t in enumerate(knots[1:-1]):  # OpenNURBS leaves out the two outermost knots
        rh.KnotsU[k] = float(t)
    rh.KnotsV[0], rh.KnotsV[1] = 0.0, 1.0
    problem = knot_vector_problem(knots, degree, n_ctrl)
    assert (problem is None) == rh.IsValid, (knots, problem)
    assert (problem is None) == all(m <= degree for m in multiplicities)


def test_creases_are_the_knot_lines_where_the_normal_jumps():
    """A full circle as four rational quadratic arcs joined at double knots (C⁰ in its parameter, one tangent: a
    cylinder's arcs meet with one normal) has no crease; a roof, degree 1 across its ridge, has one there, at the
    ridge's knot, and none along it. A reader's triangulation of a face with a crease is not used (`reader_mesh`):
    nothing puts its vertices on the crease."""
    from rtreflect.geometry.tessellation import reader_mesh

    w = math.sqrt(0.5)
    ring = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1], [1, 0]], dtype=float)
    weights_u = np.array([1, w, 1, w, 1, w, 1, w, 1])
    points = np.array([[[x, y, z] for z in (0.0, 1.0)] for x, y in ring])
    knots_u = np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1])
    cylinder = NurbsSurface(2, 1, knots_u, np.array([0, 0, 1, 1.0]), points, np.repeat(weights_u[:, None], 2, axis=1))
    assert [len(c) for c in cylinder.creases] == [0, 0]
    roof_points = np.array([[[x, y, 0.3 * (x == 0)] for y in (0.0, 1.0)] for x in (-1.0, 0.0, 1.0)])
    roof = NurbsSurface(1, 1, np.array([0, 0, 0.5, 1, 1.0]), np.array([0, 0, 1, 1.0]), roof_points, np.ones((3, 2)))
    creases_u, creases_v = roof.creases
    assert creases_u.tolist() == [0.5] and len(creases_v) == 0
    mesh = (np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), np.array([[0, 1, 2], [0, 2, 3]]))
    assert reader_mesh(NurbsSurface(1, 1, roof.knots_u, roof.knots_v, roof.points, roof.weights, mesh_uv=mesh)) is None
    flat = roof_points.copy()
    flat[1, :, 2] = 0.0  # no ridge: the same knots, one plane
    kept = reader_mesh(NurbsSurface(1, 1, roof.knots_u, roof.knots_v, flat, roof.weights, mesh_uv=mesh))
    assert kept is not None and len(kept[1]) == 2
