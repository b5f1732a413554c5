"""`Tessellation.across_seam` (issue 12, "Exact hit": a hit that runs off its face restarts on the face across the
edge): the nearest boundary vertex that qualifies, against a brute force over every boundary vertex, and where two
qualifying vertices tie, the answer of scipy's k-d query (`Tessellation._across_by_query`), which served every point
before the compiled tree walk (`kernels.rims.nearest_across`) and decides the ties still.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rtreflect.geometry.tessellation import Tessellation

PARTS = Path(__file__).resolve().parents[1] / "parts"


def brute_force(tessellation: Tessellation, points, patch, tried, uv, reach):
    """Per point the squared distances to every boundary vertex (summed in cKDTree's order), the qualifying mask
    (another face, or the far side of the own face's closed seam; not tried; within reach), and the least."""
    vertices = tessellation.vertices[tessellation.boundary]
    cand = tessellation.vertex_patch[tessellation.boundary]
    cand_uv = tessellation.vertex_uv[tessellation.boundary]
    half = tessellation._boundary_uv[1]
    e = vertices[None, :, :] - points[:, None, :]
    d2 = e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1] + e[..., 2] * e[..., 2]
    other = cand[None] != patch[:, None]
    if uv is not None:
        far = np.abs(cand_uv[None] - uv[:, None]) > half[patch][:, None]
        other |= far.any(axis=2)
    if tried is not None:
        other &= ~(cand[None, :, None] == tried[:, None, :]).any(axis=2)
    if reach is not None:
        other &= np.sqrt(d2) <= reach[:, None]
    least = np.where(other, d2, np.inf).min(axis=1)
    return d2, other, least


def assert_as_brute_force(tessellation: Tessellation, points, patch, tried=None, uv=None, reach=None) -> int:
    """The answer is the qualifying vertex at the least distance (its face, (u, v) and distance, bit for bit); where
    several with another face or (u, v) tie there, the k-d query's. Returns the number of ties."""
    got_patch, got_u, got_v, got_dist = tessellation.across_seam(points, patch, tried, uv, reach)
    d2, qualifies, least = brute_force(tessellation, points, patch, tried, uv, reach)
    cand = tessellation.vertex_patch[tessellation.boundary]
    cand_uv = tessellation.vertex_uv[tessellation.boundary]
    ties = 0
    for i in range(len(points)):
        if not np.isfinite(least[i]):
            assert got_patch[i] == -1 and np.isinf(got_dist[i]) and np.isnan(got_u[i]), i
            continue
        at = np.flatnonzero(qualifies[i] & (d2[i] == least[i]))
        kinds = {(int(cand[j]), *cand_uv[j].tolist()) for j in at}
        assert got_dist[i] == np.sqrt(least[i]), i
        assert (int(got_patch[i]), float(got_u[i]), float(got_v[i])) in kinds, i
        if len(kinds) > 1:
            ties += 1
            query = tessellation._across_by_query(
                points[i:i + 1], patch[i:i + 1],
                np.zeros((1, 0), dtype=np.int64) if tried is None else tried[i:i + 1],
                np.zeros((0, 2)) if uv is None else uv[i:i + 1], np.zeros(0) if reach is None else reach[i:i + 1])
            assert (got_patch[i], got_u[i], got_v[i], got_dist[i]) == (query[0][0], *query[1][0], query[2][0]), i
    return ties


def grid_tessellation() -> Tessellation:
    """Four faces meeting at the origin, each a 3×3 grid of boundary vertices 1 apart: vertices of different faces
    at exactly the same distance from the grid points and the cell centres (ties), faces 0 and 1 sharing the x = 0
    column point for point."""
    vertices, uv, patch = [], [], []
    for face, (sx, sy) in enumerate(((-1, -1), (1, -1), (-1, 1), (1, 1))):
        for i in range(3):
            for j in range(3):
                vertices.append((sx * i, sy * j, 0.0))
                uv.append((float(i), float(j)))
                patch.append(face)
    vertices, uv, patch = np.array(vertices), np.array(uv), np.array(patch)
    return Tessellation(vertices=vertices, faces=np.zeros((0, 3), dtype=np.int64), vertex_uv=uv, vertex_patch=patch,
                        face_patch=np.zeros(0, dtype=np.int64), chord_error=np.zeros(4), meshes=(),
                        boundary=np.arange(len(vertices)), edge_length=np.ones(4))


def test_ties_are_decided_as_the_k_d_query_decides():
    tessellation = grid_tessellation()
    rng = np.random.default_rng(1)
    centres = np.array([(x + 0.5, y + 0.5, z) for x in range(-2, 2) for y in range(-2, 2) for z in (0.0, 0.5)])
    points = np.concatenate([centres, tessellation.vertices, rng.uniform(-3, 3, (200, 3))])
    patch = rng.integers(0, 4, len(points))
    tried = rng.integers(-1, 4, (len(points), 1))
    ties = assert_as_brute_force(tessellation, points, patch)
    ties += assert_as_brute_force(tessellation, points, patch, tried=tried, reach=rng.uniform(0.5, 3.0, len(points)))
    assert ties > 50  # the grid is made of ties: the test reaches the k-d query's side


def test_a_far_qualifying_vertex_behind_many_of_the_own_face():
    """A point among hundreds of its own face's vertices: the nearest other face's lies beyond all of them (the k-d
    query needed k = 512 there), or beyond the reach (none)."""
    ring = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    own = np.stack([np.cos(ring), np.sin(ring), np.zeros_like(ring)], axis=1)
    other = np.array([[5.0, 0.0, 0.0], [0.0, -6.0, 0.0]])
    vertices = np.concatenate([own, other])
    uv = np.stack([np.concatenate([ring, [0.0, 1.0]]), np.zeros(len(vertices))], axis=1)
    patch = np.array([0] * len(own) + [1, 2])
    tessellation = Tessellation(vertices=vertices, faces=np.zeros((0, 3), dtype=np.int64), vertex_uv=uv,
                                vertex_patch=patch, face_patch=np.zeros(0, dtype=np.int64), chord_error=np.zeros(3),
                                meshes=(), boundary=np.arange(len(vertices)), edge_length=np.ones(3))
    points = np.array([[0.0, 0.0, 0.0], [0.9, 0.1, 0.0], [0.0, -2.0, 0.0]])
    got = tessellation.across_seam(points, np.zeros(3, dtype=np.int64))
    np.testing.assert_array_equal(got[0], [1, 1, 2])
    np.testing.assert_array_equal(got[3], [5.0, np.sqrt(4.1**2 + 0.1**2), 4.0])
    got = tessellation.across_seam(points, np.zeros(3, dtype=np.int64), reach=np.array([4.0, 4.0, 4.0]))
    np.testing.assert_array_equal(got[0], [-1, -1, 2])  # 4.0 away counts: within the reach
    got = tessellation.across_seam(points, np.zeros(3, dtype=np.int64), reach=np.array([4.5, 4.5, 3.9]))
    np.testing.assert_array_equal(got[0], [-1, 1, -1])
    for reach in (None, np.full(3, 4.0), np.full(3, 4.5)):
        assert_as_brute_force(tessellation, points, np.zeros(3, dtype=np.int64), reach=reach)
    # Its own face's far side of a closed seam counts with (u, v) given: the vertex at u = π, 2 away.
    got = tessellation.across_seam(points[:1], np.zeros(1, dtype=np.int64), uv=np.array([[0.0, 0.0]]))
    assert got[0][0] == 0 and abs(got[1][0]) > np.pi / 2


def test_plate_restarts_as_brute_force():
    """The 206-face plate's boundary vertices, points scattered around them as a restart's are (within a mesh edge),
    with faces tried, their own (u, v) (a closed face's far side) and reaches: the brute force's answers."""
    pytest.importorskip("OCP")
    from rtreflect.exchange.load import load_scene
    from rtreflect.integrator.autorig import resolve
    from rtreflect.integrator.renderer import Renderer

    tessellation = Renderer(resolve(load_scene(PARTS / "plate.step").with_image(96, 54, 1))).tessellation
    rng = np.random.default_rng(7)
    pick = rng.choice(tessellation.boundary, 400, replace=False)
    step = tessellation.edge_length[tessellation.vertex_patch[pick]]
    points = tessellation.vertices[pick] + rng.normal(size=(400, 3)) * (0.3 * step)[:, None]
    patch = tessellation.vertex_patch[pick]
    uv = tessellation.vertex_uv[pick]
    first = tessellation.across_seam(points, patch)[0]
    tried = np.column_stack([first, rng.integers(-1, len(tessellation.edge_length), 400)])
    assert_as_brute_force(tessellation, points, patch)
    assert_as_brute_force(tessellation, points, patch, tried=tried, uv=uv, reach=2.0 * step)
    # Exactly on boundary vertices (coincident with the neighbours' at the B-rep's vertices and shared edges).
    assert_as_brute_force(tessellation, tessellation.vertices[pick], patch, uv=uv, reach=2.0 * step)


def test_points_that_are_not_finite_have_no_neighbour():
    """A NaN or infinite point (a diverged Newton step) answers "no neighbour" (patch −1, (u, v) NaN, distance inf)
    and leaves the other rows' answers as they are alone (scipy's k-d query, which decides ties, refuses them)."""
    tessellation = grid_tessellation()
    rng = np.random.default_rng(3)
    points = rng.uniform(-3, 3, (40, 3))
    points[::3] = tessellation.vertices[: len(points[::3])]  # ties: the k-d query's side is reached as well
    patch = rng.integers(0, 4, len(points))
    tried = rng.integers(-1, 4, (len(points), 1))
    reach = rng.uniform(0.5, 3.0, len(points))
    uv = rng.uniform(0, 2, (len(points), 2))
    bad = np.array([1, 4, 5, 17, 39])
    spoiled = points.copy()
    spoiled[bad] = [[np.nan, 0.0, 0.0], [np.inf, 1.0, 1.0], [np.nan] * 3, [0.0, -np.inf, 0.0], [1.0, 1.0, np.nan]]
    good = np.setdiff1d(np.arange(len(points)), bad)
    for args in ((None, None, None), (tried, None, reach), (tried, uv, reach)):
        got = tessellation.across_seam(spoiled, patch, *args)
        alone = tessellation.across_seam(points[good], patch[good], *(None if a is None else a[good] for a in args))
        np.testing.assert_array_equal(got[0][bad], -1)
        assert np.isnan(got[1][bad]).all() and np.isnan(got[2][bad]).all() and np.isinf(got[3][bad]).all()
        for column, expected in zip(got, alone):
            np.testing.assert_array_equal(column[good], expected)


def test_domain_span_is_each_faces_extent_in_u_and_v():
    """`Tessellation._domain_span` (half of it bounds `across_seam`'s (u, v) test): per face its vertices' extent in u
    and in v, whatever order the vertices come in; a face with no vertex spans nothing; a NaN (u, v) spreads to its
    face's figure (as np.ptp would), not to the others'."""
    rng = np.random.default_rng(5)
    lows, sizes = rng.uniform(-5, 5, (5, 2)), rng.uniform(0.1, 3.0, (5, 2))
    patch, uv = [], []
    for face in (0, 1, 3, 4):  # face 2 has no vertex
        corners = lows[face] + sizes[face] * np.array([[0, 0], [1, 0], [0, 1], [1, 1]])
        inner = lows[face] + sizes[face] * rng.uniform(0, 1, (20, 2))
        uv.append(np.concatenate([corners, inner]))
        patch.append(np.full(24, face))
    uv, patch = np.concatenate(uv), np.concatenate(patch)
    order = rng.permutation(len(uv))
    uv, patch = uv[order], patch[order]
    uv[np.flatnonzero(patch == 4)[3], 1] = np.nan
    tessellation = Tessellation(vertices=np.zeros((len(uv), 3)), faces=np.zeros((0, 3), dtype=np.int64), vertex_uv=uv,
                                vertex_patch=patch, face_patch=np.zeros(0, dtype=np.int64), chord_error=np.zeros(5),
                                meshes=(), boundary=np.arange(len(uv)), edge_length=np.ones(5))
    span = tessellation._domain_span
    expected = sizes.copy()
    expected[2] = 0.0
    np.testing.assert_allclose(span[[0, 1, 2, 3]], expected[[0, 1, 2, 3]], rtol=1e-12, atol=0)
    assert span[4, 0] == pytest.approx(sizes[4, 0], rel=1e-12) and np.isnan(span[4, 1])
