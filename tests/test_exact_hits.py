"""The exact first hit (issue 11 item 2, issue 12 "How it computes" 3–5): nearest, on the face, or none.

Every expectation comes from something independent of the candidate mechanism under test:

- two surfaces together (intersecting patches, a thin plate): each surface traced **alone**
  (a single smooth patch, where the first mesh hit carries the exact hit) and the nearer
  of the two exact hits kept, or a plane's closed form;
- a trimmed face: the untrimmed patch traced alone, its exact (u, v) tested against the trim
  loops (`Trim.contains`), the ray missing where (u, v) lies outside;
- occlusion through a hole: the plane's closed-form intersection with the reflected ray, its
  (u, v) tested against the trim.

Each two-surface test fails on the tracer that kept the first mesh hit's refinement.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rtreflect.exchange.load import load_scene
from rtreflect.geometry.surfaces import NurbsSurface
from rtreflect.geometry.trims import Trim
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace.tracing import occluded

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def hood_scene(width: int = 320, height: int = 180, tessellation: int = 4, surfaces=None):
    scene = load_scene(SCENES / "hood.toml").with_image(width, height, 1)
    scene = replace(scene, render=replace(scene.render, tessellation=tessellation))
    return scene if surfaces is None else replace(scene, surfaces=tuple(surfaces))


def pixel_rays(renderer: Renderer):
    w, h = renderer.scene.image.width, renderer.scene.image.height
    rows, cols = np.divmod(np.arange(w * h), w)
    return renderer.camera.rays(rows, cols)


def alone(scene, surface: NurbsSurface, origins, directions):
    """Hits of the rays on one surface alone (its own mesh and BVH): the single-patch tracer."""
    return Renderer(replace(scene, surfaces=(surface,))).trace(origins, directions)


def plane_patch(corner, du, dv, name="plane") -> NurbsSurface:
    """The bilinear patch corner + u du + v dv, (u, v) ∈ [0, 1]²: a parallelogram of a plane."""
    corner, du, dv = (np.asarray(x, dtype=np.float64) for x in (corner, du, dv))
    points = np.array([[corner, corner + dv], [corner + du, corner + du + dv]])
    return NurbsSurface.bezier(points, name=name)


def plane_hits(surface: NurbsSurface, origins, directions):
    """Closed form: t and (u, v) where each ray meets the plane of a `plane_patch` (NaN outside [0, 1]²)."""
    P = surface.points
    corner, du, dv = P[0, 0], P[1, 0] - P[0, 0], P[0, 1] - P[0, 0]
    normal = np.cross(du, dv)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((corner - origins) @ normal) / (directions @ normal)
    X = origins + t[:, None] * directions - corner
    G = np.array([[du @ du, du @ dv], [du @ dv, dv @ dv]])
    uv = np.linalg.solve(G, np.stack([X @ du, X @ dv])).T
    inside = (t > 0) & np.all((uv >= 0) & (uv <= 1), axis=1)
    return np.where(inside, t, np.nan), uv


def nearest_of(*candidates):
    """Per ray, the index of the nearest finite t among the candidates (−1 where none) and that t."""
    T = np.stack([np.where(np.isfinite(t), t, np.inf) for t in candidates])
    which = np.argmin(T, axis=0)
    best = T[which, np.arange(T.shape[1])]
    return np.where(np.isfinite(best), which, -1), best


def assert_same_hits(hits, patch_expected, t_expected, scale):
    """Every ray: the same patch (−1 for a miss) and the same exact ray distance."""
    wrong_patch = np.flatnonzero(hits.patch != patch_expected)
    assert len(wrong_patch) == 0, f"{len(wrong_patch)} rays on the wrong patch, e.g. rows {wrong_patch[:5]}"
    both = np.flatnonzero(patch_expected >= 0)
    err = np.abs(hits.t[both] - t_expected[both])
    assert err.max() <= 1e-9 * scale, err.max()
    assert not hits.fallback.any(), hits.fallback.sum()


# --- Issue 11 item 2: surfaces closer than the chord error ----------------------------------------


def test_intersecting_patches_keep_the_nearest_exact_hit():
    """The hood and a plane cutting through it: near the intersection curve the coarse mesh's first hit
    lies on the farther surface; every pixel must show the nearer exact surface."""
    scene = hood_scene()
    hood = scene.surfaces[0]
    cut = plane_patch([-1.3, -1.2, 0.05], [2.6, 0.0, 0.55], [0.0, 2.4, 0.0], name="cut")
    renderer = Renderer(replace(scene, surfaces=(hood, cut)))
    origins, directions = pixel_rays(renderer)
    hits = renderer.trace(origins, directions)
    t_hood = alone(scene, hood, origins, directions).t
    t_cut, _ = plane_hits(cut, origins, directions)
    expected, t_expected = nearest_of(t_hood, t_cut)
    assert (expected == 0).sum() > 1000 and (expected == 1).sum() > 1000  # both surfaces in view
    assert_same_hits(hits, expected, t_expected, renderer.tessellation.extent)


def test_thin_plate_keeps_the_upper_sheet():
    """Two sheets closer than the chord error (the hood and a copy 0.3 chord errors above it, its net
    stretched so the meshes differ): every hit belongs to the sheet nearer the eye."""
    scene = hood_scene()
    hood = scene.surfaces[0]
    chord = Renderer(scene).tessellation.chord_error[0]
    points = hood.points * np.array([1.003, 1.003, 1.0]) + np.array([0.0, 0.0, 0.3 * chord])
    upper = replace(hood, points=points, name="upper")
    renderer = Renderer(replace(scene, surfaces=(hood, upper)))
    origins, directions = pixel_rays(renderer)
    hits = renderer.trace(origins, directions)
    expected, t_expected = nearest_of(alone(scene, hood, origins, directions).t,
                                      alone(scene, upper, origins, directions).t)
    assert (expected == 1).sum() > 10000
    assert_same_hits(hits, expected, t_expected, renderer.tessellation.extent)


def test_coincident_triangle_of_the_face_across_the_edge_is_not_skipped():
    """Two faces meeting at an edge, B under A (a wedge 0.1 deep): B's mesh lies in A's plane 1e-6 above it
    (as a reader's row of slivers at a cylinder's rim lay in its cap's plane on trimmed.3dm), so the ray
    meets B's triangle first and A's at the same distance to float32 rounding. The next query starts past
    that rounding and never met A's triangle: the ray kept B's exact hit 0.1 (1 − x) behind A's. Every ray
    must keep the plane A's closed-form hit."""
    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.geometry.tessellation import tessellate
    from rtreflect.trace.accelerator import Accelerator
    from rtreflect.trace.tracing import trace

    a = plane_patch([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], name="A")
    b = plane_patch([0.0, 0.0, -0.1], [1.0, 0.0, 0.1], [0.0, 1.0, 0.0], name="B")  # z = 0.1 (x − 1): joins A at x = 1
    tessellation = tessellate([a, b], 2)
    vertices = tessellation.vertices.copy()
    vertices[tessellation.vertex_patch == 1, 2] = 1e-6  # B's mesh: in A's plane, a hair nearer the eye
    chord = tessellation.chord_error.copy()
    chord[1] = 0.1  # so its mesh lies within its chord error of B, as a mesh must
    tessellation = replace(tessellation, vertices=vertices, chord_error=chord)
    surfaces = SurfaceSet([a, b])
    x, y = np.meshgrid(np.linspace(0.05, 0.95, 19), np.linspace(0.05, 0.95, 19))
    origins = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 2.0)])
    directions = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    hits = trace(Accelerator(tessellation), tessellation, surfaces, origins, directions)
    t_a, _ = plane_hits(a, origins, directions)
    assert_same_hits(hits, np.zeros(len(origins), dtype=int), t_a, tessellation.extent)


def test_a_face_resting_in_another_faces_plane_does_not_hide_it_past_its_trim():
    """A part resting on another (OCCT's data/step/trj2_as1-tc-214.stp: an L-bracket's foot on a plate's top): F, a
    disc trimmed from a square domain, lies in the plane of A, a big plate's top, with B the plate's bottom 0.2 below.
    F's mesh covers its domain's square a hair above A's (so Embree meets it first at A's distance, to float32
    rounding); off the disc F's candidate misses, and the next query started past A's triangle at that distance: the
    ray went on to B (5 pixels at 320×180 there). F and A share no edge, so no rim neighbour is tried. Every ray
    must keep the plane z = 0: F's hit inside the disc, A's elsewhere (the closed forms)."""
    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.geometry.tessellation import tessellate
    from rtreflect.trace.accelerator import Accelerator
    from rtreflect.trace.tracing import trace

    a = plane_patch([-2.0, -2.0, 0.0], [5.0, 0.0, 0.0], [0.0, 5.0, 0.0], name="A")
    b = plane_patch([-2.0, -2.0, -0.2], [5.0, 0.0, 0.0], [0.0, 5.0, 0.0], name="B")
    angle = np.linspace(0.0, 2.0 * np.pi, 256, endpoint=False)
    disc = Trim(np.column_stack([0.5 + 0.35 * np.cos(angle), 0.5 + 0.35 * np.sin(angle)]))
    f = replace(plane_patch([0.3, 0.3, 0.0], [0.4, 0.0, 0.0], [0.0, 0.4, 0.0], name="F"), trim=disc)
    tessellation = tessellate([a, b, f], 2)
    vertices = tessellation.vertices.copy()
    vertices[tessellation.vertex_patch == 2, 2] = 1e-6  # F's mesh: in A's plane, a hair nearer the eye
    chord = tessellation.chord_error.copy()
    chord[2] = 1e-5  # so its mesh lies within its chord error of F, as a mesh must
    tessellation = replace(tessellation, vertices=vertices, chord_error=chord)
    x, y = np.meshgrid(np.linspace(0.31, 0.69, 39), np.linspace(0.31, 0.69, 39))
    origins = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 2.0)])
    directions = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    hits = trace(Accelerator(tessellation), tessellation, SurfaceSet([a, b, f]), origins, directions)
    on_disc = np.hypot(x.ravel() - 0.5, y.ravel() - 0.5) < 0.4 * 0.35
    off_disc = np.hypot(x.ravel() - 0.5, y.ravel() - 0.5) > 0.4 * 0.35 + 1e-3  # clear of the disc's polygon
    assert off_disc.sum() > 300
    rows = on_disc | off_disc
    expected = np.where(on_disc, 2, 0)[rows]
    t_a, _ = plane_hits(a, origins, directions)
    assert_same_hits(replace(hits, patch=hits.patch[rows], t=hits.t[rows], fallback=hits.fallback[rows]), expected,
                     t_a[rows], tessellation.extent)


def test_a_face_in_another_faces_plane_is_not_hidden_by_a_neighbour_across_the_trim_edge():
    """F, trimmed to x ≤ 0.5 of its square domain, lies in the plane of A (a plate's top, z = 0), its mesh a hair
    above A's; N leaves F's trim edge downwards. Past F's edge the ray meets F's mesh (its cells overhang the trim),
    Newton leaves F's trim there and the restart across the edge takes N's crossing, behind A's: A's triangle at the
    same distance was passed (OCCT's data/step/bug33569.stp: two faces in one plane, the kept hit 2.05 behind,
    one pixel at 160×90; here every one of the 90 rays kept N's). Every ray must keep A's plane z = 0 (the closed form)."""
    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.geometry.tessellation import tessellate
    from rtreflect.trace.accelerator import Accelerator
    from rtreflect.trace.tracing import trace

    a = plane_patch([-2.0, -2.0, 0.0], [5.0, 0.0, 0.0], [0.0, 5.0, 0.0], name="A")
    f = replace(plane_patch([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], name="F"),
                trim=Trim(np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [0.0, 1.0]])))
    n = plane_patch([0.5, 0.0, 0.0], [0.5, 0.0, -0.005], [0.0, 1.0, 0.0], name="N")  # within the restart's reach
    tessellation = tessellate([a, f, n], 2)
    vertices = tessellation.vertices.copy()
    vertices[tessellation.vertex_patch == 1, 2] = 1e-6  # F's mesh: in A's plane, a hair nearer the eye
    tessellation = replace(tessellation, vertices=vertices)
    x, y = np.meshgrid(np.linspace(0.505, 0.55, 10), np.linspace(0.1, 0.9, 9))
    origins = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 2.0)])
    directions = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    assert np.all(tessellation.face_patch[Accelerator(tessellation).intersect(origins, directions).prim] == 1)
    hits = trace(Accelerator(tessellation), tessellation, SurfaceSet([a, f, n]), origins, directions)
    t_a, _ = plane_hits(a, origins, directions)
    assert_same_hits(hits, np.zeros(len(origins), dtype=int), t_a, tessellation.extent)


def test_a_reader_triangulation_that_leaves_part_of_its_face_out_is_not_used():
    """A trimmed plane (the square [0.1, 0.9]² of its domain) whose reader triangulation (a 4 × 4 grid of the trim)
    misses the cell [0.3, 0.5]²: rays there passed through the face (OCCT's data/step/trj10_b2-oc-214.stp: BRepMesh left
    a region 3 × 3.5 of a 16 × 13 planar face out, 11 pixels at 320×180 kept faces up to 67 behind). Such a
    triangulation's boundary edges run across the face, not along its trim: the span grid meshes the face instead
    (`tessellation.reader_mesh`), and every ray hits the plane (the closed form). A whole one is used as it is, and so
    is one that overhangs its trim."""
    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.geometry.tessellation import grid_faces, reader_mesh, tessellate
    from rtreflect.trace.accelerator import Accelerator
    from rtreflect.trace.tracing import trace

    g = np.linspace(0.1, 0.9, 5)
    nodes = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    triangles = grid_faces(5, 5)
    corner = np.isin(nodes, g[1:3]).all(axis=1)  # the corners of the cell [0.3, 0.5]²
    middle = corner[triangles].all(axis=1)
    assert middle.sum() == 2
    square = Trim(np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]]))
    plane = replace(plane_patch([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], name="F"), trim=square)
    whole = replace(plane, mesh_uv=(nodes, triangles))
    torn = replace(plane, mesh_uv=(nodes, triangles[~middle]))
    assert reader_mesh(whole) is not None and reader_mesh(torn) is None
    # A triangulation overhanging its trim leaves nothing out (the sweep's bottle.step: a thread's tip 0.03 past it).
    inset = replace(whole, trim=Trim(np.array([[0.16, 0.16], [0.84, 0.16], [0.84, 0.84], [0.16, 0.84]])))  # 0.3 of a side
    assert reader_mesh(inset) is not None
    tessellation = tessellate([torn], 2)
    x, y = np.meshgrid(np.linspace(0.32, 0.48, 9), np.linspace(0.32, 0.48, 9))
    origins = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 2.0)])
    directions = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    hits = trace(Accelerator(tessellation), tessellation, SurfaceSet([torn]), origins, directions)
    t, _ = plane_hits(plane, origins, directions)
    assert_same_hits(hits, np.zeros(len(origins), dtype=int), t, tessellation.extent)


def test_hit_replaced_across_the_rim_is_no_longer_a_crossing_hit(monkeypatch):
    """`_candidates`' ``crossed`` (the kept hit is `_crossing_on_face`'s, which `trace` lets win only nearer by float32
    rounding) must describe the hit it returns: where `_rim_neighbours` replaced that hit by another face's, the row is
    an ordinary hit again. The wedge above (B's mesh a hair above A's plane, every ray's hit moved to A across the rim),
    each of B's valid hits claimed as a crossing hit first (a stand-in for `_crossing_on_face`): after the rim's
    replacement none of A's hits may stay flagged crossed (they did: the flag was taken before the rim's look)."""
    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.geometry.tessellation import tessellate
    from rtreflect.trace import tracing
    from rtreflect.trace.accelerator import Accelerator

    a = plane_patch([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], name="A")
    b = plane_patch([0.0, 0.0, -0.1], [1.0, 0.0, 0.1], [0.0, 1.0, 0.0], name="B")
    tessellation = tessellate([a, b], 2)
    vertices = tessellation.vertices.copy()
    vertices[tessellation.vertex_patch == 1, 2] = 1e-6
    chord = tessellation.chord_error.copy()
    chord[1] = 0.1
    tessellation = replace(tessellation, vertices=vertices, chord_error=chord)
    surfaces = SurfaceSet([a, b])
    x, y = np.meshgrid(np.linspace(0.05, 0.95, 19), np.linspace(0.05, 0.95, 19))
    O = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 2.0)])
    D = np.tile([0.0, 0.0, -1.0], (len(O), 1))
    mesh = Accelerator(tessellation).intersect(O, D)
    assert (mesh.prim >= 0).all()
    claimed = []

    def claim(tessellation, surfaces, rows, patch, O, D, tm, us, vs, band, status, *rest):
        rows = np.flatnonzero(status == tracing.VALID)
        claimed.append(rows)
        return rows

    monkeypatch.setattr(tracing, "_crossing_on_face", claim)
    c = tracing._candidates(tessellation, surfaces, O, D, mesh.prim, mesh.b1, mesh.b2, mesh.t)
    moved = c.aside & (c.patch == 0)
    assert len(claimed[0]) > 100 and moved.sum() > 100  # B's hits claimed, then moved to A across the rim
    assert not (c.crossed & moved).any()
    assert c.crossed[np.setdiff1d(claimed[0], np.flatnonzero(moved))].all()  # the rest keep their flag


def test_restart_stopped_on_a_pole_is_searched():
    """A seam restart whose Newton stops on a collapsed side of the neighbour (a pole, `SurfaceSet.collapsed`) has not
    left that face: the side is one point in 3D. The mesh hit's own refinement hands such a stop to the search
    (`_candidates`); a restart counted it a loss (the ray went on behind the face). `_search_at_pole` searches from the
    restart's start: on a cone z = 1 − r (apex at v = 0) the vertical rays at x₀ meet it at (x₀, 0, 1 − x₀),
    and started from boundary vertices at other (u, v) Newton runs onto the apex for many of them."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_surfaces import revolved

    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.trace.tracing import _on_collapsed_side, _search_at_pole, refine_all

    surfaces = SurfaceSet([revolved(np.array([[0.0, 1.0], [1.0, 0.0]]), np.ones(2), 1, np.array([0, 0, 1, 1.0]))])
    grid = np.meshgrid([0.01, 0.03, 0.1], [0.5, 1.0, 1.5, 2.0, 2.5, 3.0], [0.05, 0.1, 0.2, 0.4])
    x0, us, vs = (g.ravel() for g in grid)  # the ray's x, the restart's start (u, v)
    n = len(x0)
    origins = np.column_stack([x0, np.zeros(n), np.full(n, 3.0)])
    directions = np.tile([0.0, 0.0, -1.0], (n, 1))
    patch = np.zeros(n, dtype=np.int64)
    t_mesh = 2.0 + x0
    u, v, derivs, converged, edge = refine_all(surfaces, patch, us, vs, origins, directions, t_mesh, 3.0)[:5]
    pole = np.flatnonzero(~converged & edge & _on_collapsed_side(surfaces, patch, u, v))
    assert len(pole) >= 10  # what a restart stopped at before: a loss
    won = _search_at_pole(surfaces, patch, us, vs, u, v, derivs, converged, edge, origins, directions, t_mesh, 3.0)
    assert len(won) >= 10 and np.isin(won, pole).all()
    assert converged[won].all() and not edge[won].any()
    expected = np.column_stack([x0, np.zeros(n), 1.0 - x0])[won]
    np.testing.assert_allclose(derivs.S[won], expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v[won], x0[won], rtol=0, atol=1e-12)


# --- Issue 12: trimmed faces -------------------------------------------------------------------------


def wavy_trim(samples: int = 4000) -> Trim:
    """A wavy outer loop and a circular hole inside the hood's parameter square."""
    theta = np.linspace(0.0, 2.0 * np.pi, samples, endpoint=False)
    r = 0.40 + 0.05 * np.sin(5.0 * theta)
    outer = np.column_stack([0.5 + r * np.cos(theta), 0.5 + r * np.sin(theta)])
    hole = np.column_stack([0.56 + 0.12 * np.cos(theta), 0.44 + 0.12 * np.sin(theta)])
    return Trim(outer, (hole,))


@pytest.mark.parametrize("mesh", ["grid", "mesh_uv"])
def test_trimmed_face_hits_exactly_inside_its_trim(mesh):
    """Coverage and hit points of a trimmed hood equal those of the whole hood masked by the trim, pixel by pixel."""
    scene = hood_scene(tessellation=8)
    hood = scene.surfaces[0]
    trim = wavy_trim()
    face = replace(hood, trim=trim)
    if mesh == "mesh_uv":  # a reader's triangulation in (u, v): here a Delaunay of points on and inside the loops
        face = replace(face, mesh_uv=reader_like_mesh(trim))
    renderer = Renderer(replace(scene, surfaces=(face,)))
    origins, directions = pixel_rays(renderer)
    hits = renderer.trace(origins, directions)
    whole = alone(scene, hood, origins, directions)
    inside = whole.hit.copy()
    inside[whole.hit] = trim.contains(whole.u[whole.hit], whole.v[whole.hit])
    assert inside.sum() > 2500 and (whole.hit & ~inside).sum() > 1000  # hole and cut-away margin in view
    assert_same_hits(hits, np.where(inside, 0, -1), whole.t, renderer.tessellation.extent)


def reader_like_mesh(trim: Trim) -> tuple[np.ndarray, np.ndarray]:
    """Nodes on the loops (every 40th sample) and on a grid inside, triangles of their Delaunay kept inside the face."""
    import shapely

    loops = np.concatenate([trim.outer[::40], *(h[::40] for h in trim.holes)])
    g = np.linspace(0.0, 1.0, 13)
    grid = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    grid = grid[trim.contains(grid[:, 0], grid[:, 1])]
    nodes = np.concatenate([loops, grid])
    triangles = shapely.get_parts(shapely.delaunay_triangles(shapely.multipoints(nodes)))
    corners = shapely.get_coordinates(triangles).reshape(-1, 4, 2)[:, :3]
    centroid = corners.mean(axis=1)
    corners = corners[trim.contains(centroid[:, 0], centroid[:, 1])]
    index = {tuple(p): k for k, p in enumerate(nodes)}
    faces = np.array([[index[tuple(p)] for p in tri] for tri in corners])
    return nodes, faces


def test_reflected_ray_through_a_hole_is_not_blocked():
    """A trimmed plane above the hood with a hole: reflected rays through the hole reach the lights,
    those meeting the plate are blocked (closed form + the trim), whatever the plate's mesh covers."""
    scene = hood_scene()
    hood = scene.surfaces[0]
    plate = plane_patch([-2.0, -2.0, 1.2], [4.0, 0.0, 0.0], [0.0, 4.0, 0.0], name="plate")
    theta = np.linspace(0.0, 2.0 * np.pi, 3000, endpoint=False)
    hole = np.column_stack([0.5 + 0.11 * np.cos(theta), 0.55 + 0.11 * np.sin(theta)])
    plate = replace(plate, trim=Trim(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), (hole,)))
    renderer = Renderer(replace(scene, surfaces=(hood, plate)))
    origins, directions = pixel_rays(renderer)
    # Points of the hood (traced alone: the plate would hide them from this eye) and their reflected rays.
    whole = alone(scene, hood, origins, directions)
    idx = np.flatnonzero(whole.hit)
    R, n = whole.P[idx], whole.N[idx]
    s = directions[idx] - 2.0 * np.einsum("ij,ij->i", directions[idx], n)[:, None] * n
    start = renderer.accelerator.surface_origins(R, n, whole.patch[idx])
    far = np.full(len(idx), 10.0)
    blocked = occluded(renderer.accelerator, renderer.tessellation, renderer.surfaces, start, s, far)
    t_plate, uv = plane_hits(plate, start, s)
    expected = np.isfinite(t_plate) & (t_plate < far) & plate.trim.contains(uv[:, 0], uv[:, 1])
    through_hole = np.isfinite(t_plate) & ~expected
    assert through_hole.sum() > 500 and expected.sum() > 500
    assert np.array_equal(blocked, expected), np.flatnonzero(blocked != expected)[:10]


# --- Contours and validate on a trimmed face ---------------------------------------------------------


def test_contours_stop_at_the_trim_and_validate_passes():
    """On the trimmed hood every analytic contour point lies on the face, each cut lands on the trim
    loop to a small fraction of a pixel, and `validate` passes with the usual tolerances."""
    import shapely

    from rtreflect.analysis.contours import UlmetField, analytic_contours
    from rtreflect.analysis.validate import validate_scene

    trim = wavy_trim()
    scene = hood_scene(tessellation=8)
    scene = replace(scene.with_image(320, 180, 2), surfaces=(replace(scene.surfaces[0], trim=trim),))
    renderer = Renderer(scene)
    field = UlmetField.of(renderer)
    lines = analytic_contours(field)
    boundary = shapely.MultiLineString([np.vstack([loop, loop[:1]]) for loop in (trim.outer, *trim.holes)])
    ends = []
    for line in lines.lines:
        for poly in line.polylines:
            assert trim.contains(poly.uv[:, 0], poly.uv[:, 1]).all()
            ends += [poly.uv[0], poly.uv[-1]]
    ends = np.array(ends)
    gap_uv = shapely.distance(boundary, shapely.points(ends))
    cut = ends[gap_uv < 0.02]  # ends near the trim (the others end at the image, an occlusion or the tube's end)
    assert len(cut) >= 20
    nearest = shapely.get_coordinates(shapely.shortest_line(shapely.points(cut), boundary)).reshape(-1, 2, 2)[:, 1]
    px_end, _ = field.project(np.zeros(len(cut), dtype=int), cut[:, 0], cut[:, 1])
    px_loop, _ = field.project(np.zeros(len(cut), dtype=int), nearest[:, 0], nearest[:, 1])
    assert np.linalg.norm(px_end - px_loop, axis=1).max() <= 0.01

    report = validate_scene(scene, renderer=renderer)
    assert report.passed, (report.max_px, report.misses, report.colour_mismatches, report.reasons)
    assert report.points > 200


def test_newton_stopped_on_a_closed_seam_goes_on_from_its_other_side():
    """A restart from a boundary vertex on a closed face's seam (issue 12; parts/plate.step at 480×270, pixel
    (133, 335)): the vertex has (u, v) on both sides, and started at u₁ Newton runs into the domain's edge though
    the ray meets the face just past u₀. `_over_closed_seam` restarts it from the other side: the closed form of a
    ray along −x at height y meeting the unit cylinder at (√(1 − y²), y), t = x₀ − √(1 − y²)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_surfaces import full_cylinder

    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.trace.tracing import _over_closed_seam, refine_all

    surfaces = SurfaceSet([full_cylinder()])
    y = np.array([0.003, 0.02, 0.06, -0.02])  # past the seam at (1, 0) counter-clockwise (u > 0), and before it
    origins = np.column_stack([np.full(len(y), 3.0), y, np.full(len(y), 1.0)])
    directions = np.tile([-1.0, 0.0, 0.0], (len(y), 1))
    patch = np.zeros(len(y), dtype=np.int64)
    start_u = np.array([4.0, 4.0, 4.0, 0.0])  # the seam vertex's parameters on the side away from the hit
    u, v, derivs, converged, edge = refine_all(surfaces, patch, start_u, np.full(len(y), 0.5), origins, directions,
                                               np.full(len(y), 2.0), 3.0)[:5]
    assert not converged.any() and edge.all()  # clamped on the seam: what the tracer stopped at before
    won = _over_closed_seam(surfaces, patch, u, v, derivs, converged, edge, origins, directions, np.full(len(y), 2.0), 3.0)
    np.testing.assert_array_equal(won, np.arange(len(y)))
    assert converged.all() and not edge.any()
    x = np.sqrt(1.0 - y * y)
    np.testing.assert_allclose(derivs.S, np.column_stack([x, y, np.ones(len(y))]), rtol=0, atol=1e-12)
    assert ((u > 0) & (u < 0.1)).sum() == 3 and 3.9 < u[3] < 4.0


def viewed_from(eye, surfaces, size: tuple[int, int], fov: float, tessellation: int):
    """The hood scene's image, lights and settings with other ``surfaces`` seen from ``eye`` towards the origin (+z up)."""
    scene = hood_scene(*size, tessellation=tessellation, surfaces=surfaces)
    camera = replace(scene.camera, eye=np.asarray(eye, dtype=np.float64), look_at=np.zeros(3),
                     up=np.array([0.0, 0.0, 1.0]), fov=fov)
    return replace(scene, camera=camera)


def cylinder_with_open_seam(gap: float, seam_deg: float) -> NurbsSurface:
    """The unit cylinder x² + y² = 1, |z| ≤ 1, as a rational quadratic closed in u whose seam (at ``seam_deg`` from
    +x) is left open by ``gap`` (its last control row moved out by that share), as CAD exports leave a periodic
    face's seam (the IGES apple of pythonocc-demos' surf114.igs: 2.4e-5 over a reach of 251)."""
    w = float(np.sqrt(0.5))
    circle = [(1, 0, 1), (1, 1, w), (0, 1, 1), (-1, 1, w), (-1, 0, 1), (-1, -1, w), (0, -1, 1), (1, -1, w), (1, 0, 1)]
    c, s = np.cos(np.radians(seam_deg)), np.sin(np.radians(seam_deg))
    rows, weights = [], []
    for k, (x, y, weight) in enumerate(circle):
        scale = 1.0 + gap if k == len(circle) - 1 else 1.0
        rows.append([[scale * (c * x - s * y), scale * (s * x + c * y), z] for z in (-1.0, 1.0)])
        weights.append([weight, weight])
    return NurbsSurface(2, 1, np.array([0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1], dtype=float),
                        np.array([0.0, 0.0, 1.0, 1.0]), np.array(rows), np.array(weights), name="cylinder")


@pytest.mark.parametrize("seam_deg", [-5.0, 0.0, 7.0, 190.0])
def test_a_seam_left_open_by_rounding_is_crossed_as_a_closed_one(seam_deg):
    """A periodic face's seam a CAD export leaves open by 1e-7 of the face (the two edges' control rows not
    identical) near the silhouette: a ray whose mesh hit lay on one side and whose exact hit on the other got
    Newton stopped at the domain's edge and kept the cylinder's far side, 0.5–0.7 farther (43 pixels at 320×180,
    seam at 0°; the apple of surf114.igs showed its inside). Such a face counts as closed (`SurfaceSet.closed`,
    `CLOSED_FRACTION`): every first hit is the cylinder's, the closed form's nearer root."""
    renderer = Renderer(viewed_from([0.35, -4.0, 0.3], [cylinder_with_open_seam(1e-7, seam_deg)], (320, 180), 30.0, 2))
    assert renderer.surfaces.closed.tolist() == [[True, False]]
    O, D = pixel_rays(renderer)
    hits = renderer.trace(O, D)
    a = D[:, 0] ** 2 + D[:, 1] ** 2
    b = 2.0 * (O[:, 0] * D[:, 0] + O[:, 1] * D[:, 1])
    disc = b * b - 4.0 * a * (O[:, 0] ** 2 + O[:, 1] ** 2 - 1.0)
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(disc)) / (2.0 * a)
    t = np.where((disc >= 0) & (np.abs(O[:, 2] + t * D[:, 2]) <= 1.0), t, np.inf)
    assert np.array_equal(hits.hit, np.isfinite(t)) and not hits.fallback.any()
    # The seam's 1e-7 offset, seen at grazing incidence (|N·D| ~ 0.01 on the silhouette): ~1e-5 along the ray.
    assert np.abs(hits.t[hits.hit] - t[hits.hit]).max() < 1e-4


def test_a_stack_of_sheets_within_the_band_is_decided_not_a_fallback():
    """The band behind a kept hit is the largest chord error's (`tracing._band`): a coarse curved face anywhere in
    the scene makes it long, and a ray through a stack of thin plates meets every plate behind the first within
    it. 16 plates 0.25 apart behind the first, a dome meshed to a chord error of ~0.6: with 12 candidates a ray
    (every one here) was still open and a fallback; now decided, at the first plate, the closed form's."""
    plates = [plane_patch([-1.0, 0.25 * k, -1.0], [2.0, 0.0, 0.0], [0.0, 0.0, 2.0], name=f"plate {k}")
              for k in range(17)]
    # A bicubic dome 40 behind the plates, its four inner control points raised by 6.
    side = np.linspace(-10.0, 10.0, 4)
    dome = np.array([[[x, 40.0 + (6.0 if i in (1, 2) and j in (1, 2) else 0.0), z] for j, z in enumerate(side)]
                     for i, x in enumerate(side)])
    renderer = Renderer(viewed_from([0.0, -3.0, 0.0], plates + [NurbsSurface.bezier(dome, name="dome")], (48, 32),
                                    20.0, 2))
    chord = renderer.tessellation.chord_error
    assert chord[-1] > 0.5 and chord[:-1].max() < 1e-6
    O, D = pixel_rays(renderer)
    hits = renderer.trace(O, D)
    t = -O[:, 1] / D[:, 1]  # the plane y = 0 of the first plate
    on = np.all(np.abs((O + t[:, None] * D)[:, [0, 2]]) < 1.0, axis=1)
    assert on.sum() > 1000 and np.array_equal(hits.hit[on], on[on])
    assert not hits.fallback.any()
    np.testing.assert_allclose(hits.t[on], t[on], rtol=0, atol=1e-9)
    assert np.all(hits.patch[on] == 0)
