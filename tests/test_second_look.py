"""The nearest exact hit where the coarse mesh misses a nearer sheet (issue 11 item 2, trace/secondlook.py).

A constructed grazing case with a closed form: a cylinder's cap (radius 1 about the x axis, the
arc from 45° to 135°, one rational quadratic span, x ∈ [0, 1]) in front of a plane. At
tessellation 2 the cap's mesh near its straight rims (x = 0, x = 1) is the chord at z = cos 45°
(the rim keeps its vertices on the surface), 0.29 below the cap's top: a ray along y at height
z ∈ (0.71, 1) near a rim crosses the cap twice without meeting its mesh and used to stop on the
plane behind (or, higher up, on the farther of the two crossings). The expected first hit is the
closed form y = −√(1 − z²), t = y − y₀. Fails on the tracer without the second look.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rtreflect.exchange.load import load_scene
from rtreflect.geometry.surfaces import NurbsSurface
from rtreflect.integrator.renderer import Renderer

SCENES = Path(__file__).resolve().parent.parent / "scenes"
#: Where the rays start along y, in front of the cap; the plane behind stands at y = PLANE_Y.
Y0, PLANE_Y = -3.0, 2.0


def cylinder_cap() -> NurbsSurface:
    """The cap {(x, cos θ, sin θ): x ∈ [0, 1], θ ∈ [45°, 135°]}: a rational quadratic arc (u) extruded along x (v)."""
    c = np.sqrt(0.5)
    arc = np.array([[c, c], [0.0, 2.0 * c], [-c, c]])  # the middle control point where the end tangents meet
    points = np.array([[[x, y, z] for x in (0.0, 1.0)] for y, z in arc])
    weights = np.array([[1.0, 1.0], [c, c], [1.0, 1.0]])
    return NurbsSurface.bezier(points, weights, name="cap")


def plane_behind() -> NurbsSurface:
    points = np.array([[[x, PLANE_Y, z] for z in (-1.0, 2.0)] for x in (-1.0, 2.0)])
    return NurbsSurface.bezier(points, name="plane")


def renderer(tessellation: int = 1) -> Renderer:
    scene = load_scene(SCENES / "hood.toml").with_image(32, 18, 1)
    scene = replace(scene, surfaces=(cylinder_cap(), plane_behind()),
                    render=replace(scene.render, tessellation=tessellation))
    return Renderer(scene)


def grazing_rays():
    """Rays along +y at heights z across the cap, near each straight rim and in the middle."""
    x, z = np.meshgrid([0.002, 0.01, 0.03, 0.5, 0.97, 0.99, 0.998], np.linspace(0.72, 0.995, 24), indexing="ij")
    origins = np.stack([x.ravel(), np.full(x.size, Y0), z.ravel()], axis=1)
    directions = np.tile([0.0, 1.0, 0.0], (x.size, 1))
    return origins, directions


def test_a_ray_crossing_a_cap_its_mesh_misses_stops_at_the_first_crossing():
    origins, directions = grazing_rays()
    hits = renderer().trace(origins, directions)
    z = origins[:, 2]
    expected = -np.sqrt(1.0 - z * z) - Y0  # closed form: the nearer of the ray's two crossings of the cylinder
    assert hits.hit.all() and not hits.fallback.any()
    assert np.array_equal(hits.patch, np.zeros(len(z))), f"{np.count_nonzero(hits.patch)} rays stopped on the plane"
    np.testing.assert_allclose(hits.t, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(hits.P[:, 1:], axis=1), 1.0, atol=1e-9)  # on the cylinder


def test_rays_that_pass_the_cap_stop_on_the_plane_exactly():
    """Above the cap (z > 1) and beside it (x outside [0, 1]), the first hit is the plane's closed form."""
    x, z = np.meshgrid([-0.01, 0.5, 1.01], [0.9, 1.001, 1.05], indexing="ij")
    origins = np.stack([x.ravel(), np.full(x.size, Y0), z.ravel()], axis=1)
    above = (z.ravel() > 1.0) | (x.ravel() < 0.0) | (x.ravel() > 1.0)
    hits = renderer().trace(origins[above], np.tile([0.0, 1.0, 0.0], (above.sum(), 1)))
    assert hits.hit.all() and (hits.patch == 1).all() and not hits.fallback.any()
    np.testing.assert_allclose(hits.t, PLANE_Y - Y0, rtol=0, atol=1e-9)


def test_a_ray_between_an_edge_chord_and_the_edge_hits():
    """The cylinder scene at 320×180: pixel (82, 215)'s ray meets the surface 6e-5 inside its edge v = 1, at
    |N·D| = 0.49, between the edge's chords and the edge, where neither the mesh nor the second look's finer
    mesh had a triangle: it missed. Every pixel-centre ray must hit or miss as on a tessellation-96 mesh, at
    the same point."""
    scene = load_scene(SCENES / "cylinder.toml").with_image(320, 180, 1)
    coarse = Renderer(scene)
    rows, cols = np.divmod(np.arange(320 * 180), 320)
    origins, directions = coarse.camera.rays(rows, cols)
    hits = coarse.trace(origins, directions)
    fine = Renderer(replace(scene, render=replace(scene.render, tessellation=96))).trace(origins, directions)
    assert fine.hit[82 * 320 + 215] and fine.v[82 * 320 + 215] > 1.0 - 1e-4  # the case is still in the scene
    assert np.array_equal(hits.hit, fine.hit), f"{np.count_nonzero(hits.hit != fine.hit)} rays differ"
    np.testing.assert_allclose(hits.t[hits.hit], fine.t[fine.hit], rtol=0, atol=1e-9 * coarse.tessellation.extent)


def saddle() -> NurbsSurface:
    """z = x² − y²/2 over [−1, 1]²: a biquadratic Bézier patch (the control net's z is the sum of the two parabolas')."""
    cx, cy = (1.0, -1.0, 1.0), (-0.5, 0.5, -0.5)
    points = np.array([[[x, y, cx[i] + cy[j]] for j, y in enumerate((-1.0, 0.0, 1.0))]
                       for i, x in enumerate((-1.0, 0.0, 1.0))])
    return NurbsSurface.bezier(points, name="saddle")


def test_a_ray_clipping_a_saddles_ridge_stops_at_its_first_crossing():
    """A saddle's enclosing mesh moves to one side (the deeper chords', along x): along y its ridge z = x₀² − y²/2
    pokes out of the mesh, of the coarse one and of the second look's 4× one alike. A ray along y at height
    x₀² − ε crosses the ridge twice, at y = ∓√(2ε), meeting no triangle of either mesh; it used to stop on the
    plane behind (96 of these 468 rays) or on the farther crossing (33). The shell around the saddle (which
    selects the ray) now starts a refinement of its own: the first hit is the closed form y = −√(2ε)."""
    scene = load_scene(SCENES / "hood.toml").with_image(32, 18, 1)
    plane = NurbsSurface.bezier(np.array([[[x, PLANE_Y, z] for z in (-1.0, 2.0)] for x in (-2.0, 2.0)]), name="plane")
    scene = replace(scene, surfaces=(saddle(), plane), render=replace(scene.render, tessellation=2))
    x0, eps = np.meshgrid(np.linspace(-0.95, 0.95, 39), np.geomspace(1e-6, 3e-2, 12), indexing="ij")
    x0, eps = x0.ravel(), eps.ravel()
    origins = np.stack([x0, np.full(x0.size, Y0), x0 * x0 - eps], axis=1)
    hits = Renderer(scene).trace(origins, np.tile([0.0, 1.0, 0.0], (x0.size, 1)))
    expected = -np.sqrt(2.0 * eps) - Y0
    assert hits.hit.all() and not hits.fallback.any()
    assert (hits.patch == 0).all(), f"{np.count_nonzero(hits.patch)} rays stopped on the plane"
    # Newton's tolerance across the ray (~1e-12 of the part) moves t by that over the incidence |N·D| ≈ √(2ε).
    assert np.all(np.abs(hits.t - expected) <= 1e-9 + 1e-11 / np.sqrt(2.0 * eps))


def plate_with_hole() -> NurbsSurface:
    """The plane z = 0.6 over [−1.2, 1.2]² (a bilinear patch), trimmed by a circular hole of radius 0.48 at its centre."""
    from rtreflect.geometry.trims import Trim

    points = np.array([[[x, y, 0.6] for y in (-1.2, 1.2)] for x in (-1.2, 1.2)])
    theta = np.linspace(0.0, 2.0 * np.pi, 2000, endpoint=False)
    hole = np.column_stack([0.5 + 0.2 * np.cos(theta), 0.5 + 0.2 * np.sin(theta)])
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return replace(NurbsSurface.bezier(points, name="plate"), trim=Trim(square, (hole,)))


def test_a_plane_whose_mesh_is_crossed_outside_its_trim_selects_no_ray():
    """A plane's mesh lies in it, so the coarse trace's own refinement of a plane's triangle is the ray's one
    crossing of that plane: a plane has no shell (`flat`), and rays through the hole of a trimmed plate in front
    of the hood, which cross the plate's mesh there (its span grid keeps the triangles overlapping the trim, over
    the hole too), are not looked at again. Before, every one of them entered the plate's shell before the hood
    and was traced a second time. Their hits: the hood's where the plate's closed form falls in the hole (the hood
    traced alone), the plate's closed form elsewhere."""
    from rtreflect.trace.secondlook import flat
    from rtreflect.trace.tracing import trace

    scene = load_scene(SCENES / "hood.toml").with_image(160, 90, 1)
    hood, plate = scene.surfaces[0], plate_with_hole()
    scene = replace(scene, surfaces=(hood, plate), render=replace(scene.render, tessellation=4))
    renderer = Renderer(scene)
    assert flat(renderer.tessellation, renderer.surfaces).tolist() == [False, True]
    rows, cols = np.divmod(np.arange(160 * 90), 160)
    origins, directions = renderer.camera.rays(rows, cols)
    hits = renderer.trace(origins, directions)
    # The plate's closed form: the ray's crossing of z = 0.6 and its (u, v) on [−1.2, 1.2]².
    t_plate = (0.6 - origins[:, 2]) / directions[:, 2]
    X = origins + t_plate[:, None] * directions
    u, v = (X[:, 0] + 1.2) / 2.4, (X[:, 1] + 1.2) / 2.4
    on_square = (t_plate > 0) & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
    on_plate = on_square & plate.trim.contains(u, v)
    behind = Renderer(replace(scene, surfaces=(hood,))).trace(origins, directions)
    through = on_square & ~on_plate & behind.hit
    assert through.sum() > 200  # rays through the hole onto the hood
    expected_patch = np.where(on_plate, 1, np.where(behind.hit, 0, -1))
    assert np.array_equal(hits.patch, expected_patch), np.flatnonzero(hits.patch != expected_patch)[:10]
    np.testing.assert_allclose(hits.t[on_plate], t_plate[on_plate], rtol=0, atol=1e-9)
    np.testing.assert_allclose(hits.t[through], behind.t[through], rtol=0, atol=1e-9)
    assert not hits.fallback.any()
    # Those rays cross the plate's mesh before the hood (the coarse trace refined it, outside the trim) ...
    mesh = renderer.accelerator.intersect(origins[through], directions[through])
    assert (renderer.tessellation.face_patch[mesh.prim] == 1).all()
    # ... and none is looked at again (each was before).
    coarse = trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions)
    suspects, _ = renderer.second_look.suspects(coarse, origins, directions, np.full(len(origins), np.inf))
    assert not np.isin(np.flatnonzero(through), suspects).any(), np.isin(np.flatnonzero(through), suspects).sum()


def test_flat_is_a_plane_meshed_exactly():
    """`flat`: a tilted plane is (equal weights); a curved cap is not; nor a plane whose parameterisation is not
    affine (its control net in a plane but unevenly spaced along u, or unequal weights: its chords leave the
    surface within the plane)."""
    from rtreflect.geometry.surfaces import SurfaceSet
    from rtreflect.geometry.tessellation import tessellate
    from rtreflect.trace.secondlook import flat

    tilt = np.array([[[x, y, 0.3 * x - 0.2 * y + 1.0] for y in (0.0, 1.0)] for x in (0.0, 1.0)])
    tilted = NurbsSurface.bezier(tilt, np.full((2, 2), 2.0), name="tilted")
    weighted = NurbsSurface.bezier(tilt, np.array([[1.0, 2.0], [3.0, 1.0]]), name="weighted")  # a projective map
    uneven = np.array([[[x, y, 0.0] for y in (0.0, 1.0)] for x in (0.0, 0.1, 1.0)])  # quadratic in u: x = 0.2u + 0.8u²
    surfaces = [tilted, cylinder_cap(), NurbsSurface.bezier(uneven, name="uneven"), weighted]
    tessellation = tessellate(surfaces, 4, enclose=True)
    assert flat(tessellation, SurfaceSet(surfaces)).tolist() == [True, False, False, False]


def quarter_ring() -> NurbsSurface:
    """The flat ring ρ ∈ [0.5, 1], φ ∈ [0°, 90°] in z = 0: a rational quadratic quarter circle (u) times the radius
    (v). A plane, but not `flat`: its parameterisation is not affine, its outer edge v = 1 an arc in its own plane."""
    c = np.sqrt(0.5)
    arc = np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    points = np.array([[[r * x, r * y, 0.0] for r in (0.5, 1.0)] for x, y in arc])
    return NurbsSurface.bezier(points, np.array([[1.0, 1.0], [c, c], [1.0, 1.0]]), name="ring")


def test_a_ray_between_a_rim_chord_and_the_edge_curving_in_the_tangent_plane_hits():
    """At tessellation 2 the ring's outer edge has chords over 0°–45° and 45°–90°, up to 1 − cos 22.5° = 0.076 inside
    the arc, in the ring's own plane: the enclosing mesh keeps its rim on the edge, and the shell's sheets (moved
    along the normal, ±z) end at walls on the chords, so a ray straight down between a chord and the arc met
    neither mesh nor shell and missed. Boxes around the rim edges on the domain's edge (`_rim_boxes`) select it;
    the second look's finer mesh, widened past the edge, finds it: t = 3 (the ring's closed form)."""
    scene = load_scene(SCENES / "hood.toml").with_image(32, 18, 1)
    scene = replace(scene, surfaces=(quarter_ring(),), render=replace(scene.render, tessellation=2))
    renderer = Renderer(scene)
    phi = np.deg2rad(np.concatenate([np.linspace(2.0, 43.0, 12), np.linspace(47.0, 88.0, 12)]))
    chord = np.cos(np.deg2rad(22.5)) / np.cos(phi - np.deg2rad(np.where(phi < np.pi / 4, 22.5, 67.5)))
    phi, fraction = np.meshgrid(phi, [0.2, 0.5, 0.8], indexing="ij")
    rho = (chord[:, None] + fraction * (1.0 - chord[:, None])).ravel()  # between the chord and the arc
    phi = phi.ravel()
    origins = np.stack([rho * np.cos(phi), rho * np.sin(phi), np.full(rho.size, 3.0)], axis=1)
    directions = np.tile([0.0, 0.0, -1.0], (rho.size, 1))
    assert not (renderer.accelerator.intersect(origins, directions).prim >= 0).any()  # the coarse mesh misses them
    hits = renderer.trace(origins, directions)
    assert hits.hit.all(), f"{np.count_nonzero(~hits.hit)} of {rho.size} rays missed"
    assert not hits.fallback.any()
    np.testing.assert_allclose(hits.t, 3.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(hits.P[:, :2], axis=1), rho, rtol=0, atol=1e-9)


def test_plate_edge_sample_keeps_open_cascades_nearer_face():
    """parts/plate.step at 480×270, pixel (129, 148), edge sample 14 of 4×4: the ray passes the top plane's skirt over
    a hole (outside its trim), then meets face 14 1.53 before the face 115 it stored. The shell's first hit along
    it was the plane's, where Newton from the shell found nothing; planes now have no shell (`flat`) and the first
    shell hit is face 14's, whose Newton start finds the crossing. OCCT's nearest intersection is the reference."""
    pytest.importorskip("OCP")
    import sys

    from rtreflect.integrator.autorig import resolve
    from rtreflect.trace.camera import sample_offsets

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_cad_hits import occt_nearest
    from test_cad_reader import occt_faces

    part = SCENES.parent / "parts" / "plate.step"
    renderer = Renderer(resolve(load_scene(part).with_image(480, 270, 1)))
    origins, directions = renderer.camera.rays(np.array([129]), np.array([148]), sample_offsets(4)[14:15])
    hits = renderer.trace(origins, directions)
    expected = np.einsum("ij,ij->i", occt_nearest(occt_faces(part)[0], origins, directions) - origins, directions)
    assert hits.hit.all() and not hits.fallback.any()
    np.testing.assert_allclose(hits.t, expected, rtol=0, atol=1e-6 * renderer.tessellation.extent)


@pytest.fixture(scope="module")
def plate_ray_onto_fillet():
    """parts/plate.step at 480×270, pixel (133, 335), edge sample 10 of 4×4: its renderer, the ray, and Open CASCADE's
    nearest intersection's t along it (the reference)."""
    pytest.importorskip("OCP")
    import sys

    from rtreflect.integrator.autorig import resolve
    from rtreflect.trace.camera import sample_offsets

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_cad_hits import occt_nearest
    from test_cad_reader import occt_faces

    part = SCENES.parent / "parts" / "plate.step"
    renderer = Renderer(resolve(load_scene(part).with_image(480, 270, 1)))
    origins, directions = renderer.camera.rays(np.array([133]), np.array([335]), sample_offsets(4)[10:11])
    expected = np.einsum("ij,ij->i", occt_nearest(occt_faces(part)[0], origins, directions) - origins, directions)
    return renderer, origins, directions, expected


def test_plate_ray_through_a_hole_meets_the_fillet_across_its_seam(plate_ray_onto_fillet):
    """The ray passes the top plane just outside its trim, over a hole, and meets the hole's fillet (a closed face)
    at u = 0.017, 0.003 inside the hole; its mesh, a chord below the fillet's top circle, is not met. The plane's
    candidate runs off its trim and restarts on the fillet from their shared boundary vertex on the fillet's seam,
    whose (u, v) was taken at u = 2π: Newton stopped on the domain's edge, and the ray went on to the hole's floor
    (face 106) 7.56 farther. Now Newton goes on from the seam's other side (`tracing._over_closed_seam`): the
    coarse trace alone finds OCCT's nearest hit."""
    from rtreflect.trace.tracing import trace

    renderer, origins, directions, expected = plate_ray_onto_fillet
    scale = 1e-6 * renderer.tessellation.extent
    coarse = trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions)
    hits = renderer.trace(origins, directions)
    for h in (coarse, hits):
        assert h.hit.all() and not h.fallback.any()
        np.testing.assert_allclose(h.t, expected, rtol=0, atol=scale)


def test_second_look_from_the_shell_goes_on_across_a_closed_seam(plate_ray_onto_fillet, monkeypatch):
    """The same ray with the tracer's seam restarts and rim neighbours switched off (`SEAM_TRIES` = 0, no
    `_rim_neighbours`, which refines the fillet across the rim of a missed candidate too: the coarse and the fine trace
    both go on to the hole's floor): the second look's start from the shell, the fillet's last rim box before its
    seam at u = 2π, must go on from the seam's other side too, and finds OCCT's hit."""
    from rtreflect.trace import tracing

    renderer, origins, directions, expected = plate_ray_onto_fillet
    monkeypatch.setattr(tracing, "SEAM_TRIES", 0)
    monkeypatch.setattr(tracing, "_rim_neighbours", lambda *args: (np.zeros(0, dtype=np.int64),) * 2)
    coarse = tracing.trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions)
    assert coarse.t[0] > expected[0] + 1.0  # without the restart: the floor behind
    hits = renderer.trace(origins, directions)
    assert hits.hit.all() and not hits.fallback.any()
    np.testing.assert_allclose(hits.t, expected, rtol=0, atol=1e-6 * renderer.tessellation.extent)


def test_a_plane_supporting_the_scene_is_final_from_its_clear_side_only():
    """`secondlook.clear_sides`: the cap lies wholly on the plane's −y side (y ≤ 1 < 2), so only the +y side is clear
    (rays from the cap's side, the grazing ones above, are still looked at again); the cap is no plane (no sides)."""
    from rtreflect.trace.secondlook import clear_sides, flat

    r = renderer()
    _, normal, clear = clear_sides(r.tessellation, r.surfaces, flat(r.tessellation, r.surfaces))
    assert not clear[0].any()
    plus_y = normal[1, 1] > 0  # the SVD's normal may point either way
    assert clear[1].tolist() == ([True, False] if plus_y else [False, True])
    # From the clear side (origins at y = 3 > 2, looking back), a ray onto the plane is no suspect however close the cap.
    origins = np.array([[0.5, 3.0, 0.9], [0.5, 3.0, 1.2]])
    directions = np.tile([0.0, -1.0, 0.0], (2, 1))
    hits = r.trace(origins, directions)
    assert (hits.patch == 1).all()
    assert r.second_look._in_front_of_all(hits, origins).all()
    origins[:, 1], directions[:, 1] = Y0, 1.0  # from the cap's side: not final
    assert not r.second_look._in_front_of_all(r.trace(origins, directions), origins).any()


def test_plate_rays_onto_its_top_plane_need_no_second_look():
    """parts/plate.step: its top plane (face 0, 100 filleted holes) has every other face below it, so its hits seen
    from above are final: none of them is a suspect (before: 6,743 of the 17,169 suspects at 960×540, near the
    holes' fillets, whose shells reach over the plane; none changed). They agree with Open CASCADE's first hit."""
    pytest.importorskip("OCP")
    import sys

    from rtreflect.integrator.autorig import resolve
    from rtreflect.trace.secondlook import GRAZING_COS
    from rtreflect.trace.tracing import trace

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_cad_hits import occt_nearest
    from test_cad_reader import occt_faces

    part = SCENES.parent / "parts" / "plate.step"
    r = Renderer(resolve(load_scene(part).with_image(240, 135, 1)))
    rows, cols = np.divmod(np.arange(240 * 135), 240)
    origins, directions = r.camera.rays(rows, cols)
    hits = trace(r.accelerator, r.tessellation, r.surfaces, origins, directions)
    suspects, _ = r.second_look.suspects(hits, origins, directions, np.full(len(origins), np.inf))
    cos = np.abs(np.einsum("ij,ij->i", hits.N, directions))
    top = np.flatnonzero(hits.hit & (hits.patch == 0) & (cos >= GRAZING_COS) & ~hits.aside)
    assert len(top) > 5000
    assert not np.isin(top, suspects).any()
    # Rays that meet a fillet's shell before the plane (the suspects before), whose kept hit is now final: OCCT's.
    shell = r.second_look.shell.intersect(origins[top], directions[top])
    near = top[(shell.prim >= 0) & (shell.t < hits.t[top])]
    assert len(near) > 100
    near = np.random.default_rng(5).choice(near, 40, replace=False)
    expected = occt_nearest(occt_faces(part)[0], origins[near], directions[near])
    np.testing.assert_allclose(hits.P[near], expected, rtol=0, atol=1e-6 * r.tessellation.extent)


def test_an_own_shell_hit_far_from_the_kept_hit_in_u_v_is_another_part_of_the_face():
    """Inside a ray's passage its own face's shell hits are its way in (`SecondLook.suspects`), unless they lie
    farther in (u, v) than `FOLD_TRIANGLES` of their triangle's extent: another part of the same face curling back
    in front (pythonocc-demos' surf114.igs, a leaf). Across a closed face's seam (u = 0 and 1 of a full cylinder)
    the distance is the shorter way round."""
    from test_surfaces import full_cylinder

    from rtreflect.trace import secondlook

    scene = load_scene(SCENES / "hood.toml").with_image(32, 18, 1)
    look = Renderer(replace(scene, surfaces=(full_cylinder(), plane_behind()),
                            render=replace(scene.render, tessellation=4))).second_look
    assert look.surfaces.closed[0].tolist() == [True, False]
    sheet = np.flatnonzero(look.shell_mesh.face_patch == 0)[:2 * 16 * 4]
    third = np.full(len(sheet), 1.0 / 3.0)
    _, u, v = look.shell_mesh.start_parameters(sheet, third, third)
    extent_u, extent_v = look._triangle_uv_extent
    elsewhere = look._elsewhere_on_face
    assert not elsewhere(sheet, third, third, u, v).any()  # at the kept hit itself
    assert not elsewhere(sheet, third, third, u + extent_u[sheet], v).any()  # one triangle over
    far = secondlook.FOLD_TRIANGLES * 1.5
    assert elsewhere(sheet, third, third, u, v + far * extent_v[sheet]).all()
    (u0, u1), _ = look.surfaces.patches[0].domain
    # Just across the seam from a triangle at u = 0: near, the short way round; the same distance inside: far.
    first = sheet[u < u0 + extent_u[sheet]]
    assert len(first) > 0
    t1 = np.full(len(first), 1.0 / 3.0)
    _, uf, vf = look.shell_mesh.start_parameters(first, t1, t1)
    assert not elsewhere(first, t1, t1, u1 - (uf - u0), vf).any()
    assert elsewhere(first, t1, t1, uf + 0.5 * (u1 - u0), vf).all()


def _arc(a0: float, a1: float):
    """A circular arc of radius 1 from angle a0 to a1 as a rational quadratic B-spline: points, weights, knots."""
    n = int(np.ceil((a1 - a0) / (np.pi / 2)))
    half = 0.5 * (a1 - a0) / n
    points, weights, knots = [(np.cos(a0), np.sin(a0))], [1.0], [0.0] * 3
    for k in range(n):
        middle = a0 + (2 * k + 1) * half
        points += [(np.cos(middle) / np.cos(half), np.sin(middle) / np.cos(half)), (np.cos(middle + half),
                                                                                    np.sin(middle + half))]
        weights += [np.cos(half), 1.0]
        knots += [(k + 1) / n] * 2 if k < n - 1 else []
    return points, weights, knots + [1.0] * 3


def bowl(top_deg: float = 40.0, seam: float = 0.0) -> NurbsSurface:
    """The unit sphere from latitude −80° up to ``top_deg``: a bowl open at the top, its rim a circle that curves in
    the sphere's tangent plane (a rational biquadratic: a full circle in u from longitude ``seam``, radians, times a
    meridian arc in v)."""
    around, w_around, k_around = _arc(seam, seam + 2 * np.pi)
    meridian, w_meridian, k_meridian = _arc(np.radians(-80.0), np.radians(top_deg))
    points = np.array([[[x * r, y * r, z] for r, z in meridian] for x, y in around])
    weights = np.outer(w_around, w_meridian)
    return NurbsSurface(2, 2, np.array(k_around), np.array(k_meridian), points, weights, name="bowl")


@pytest.mark.parametrize("tessellation, eye, seam", [(2, (0.8, 0.0, 2.5), 0.0), (2, (1.2, 0.0, 2.5), 0.0),
                                                     (2, (2.0, 0.0, 4.0), 0.0), (4, (1.2, 0.0, 2.5), 0.0),
                                                     (2, (0.8, 0.0, 2.5), 2.6), (2, (0.8, 0.0, 2.5), 3.0)])
def test_a_ray_leaving_a_bowl_just_below_its_rim_stops_there(tessellation, eye, seam):
    """Looking down into a bowl, rays that leave its inside at grazing incidence just below the rim cross the sheet
    twice: first in the opening, off the face, then on it. Newton from a rim box's start on the edge ran to the first
    and stopped on the edge, and the ray kept what lay behind (1–2 pixels of 160×120 at tessellation 2 and 4); the
    boxes' corners on the face's side start inside the domain now (`secondlook._inside_the_edge`), on which side
    decided per rim edge: at the seam its end vertices are domain corners, on both edges (the seam on the far side,
    2.6 or 3.0 from +x: one pixel each when a corner's vertex decided). Every first hit is the closed form's: the
    sphere's nearer root below the rim, else the floor."""
    floor = NurbsSurface.bezier(np.array([[[x, y, -1.05] for y in (-3.0, 3.0)] for x in (-3.0, 3.0)]), name="floor")
    scene = load_scene(SCENES / "hood.toml").with_image(160, 120, 1)
    scene = replace(scene, surfaces=(bowl(seam=seam), floor), render=replace(scene.render, tessellation=tessellation),
                    camera=replace(scene.camera, eye=np.array(eye), look_at=np.zeros(3), up=np.array([0.0, 0.0, 1.0]),
                                   fov=50.0))
    renderer = Renderer(scene)
    rows, cols = np.divmod(np.arange(160 * 120), 160)
    O, D = renderer.camera.rays(rows, cols)
    hits = renderer.trace(O, D)
    b, c = 2.0 * np.einsum("ij,ij->i", O, D), np.einsum("ij,ij->i", O, O) - 1.0
    disc = b * b - 4.0 * c
    expected = np.full(len(O), np.inf)
    with np.errstate(invalid="ignore"):
        for sign in (-1.0, 1.0):
            t = 0.5 * (-b + sign * np.sqrt(disc))
            z = O[:, 2] + t * D[:, 2]
            on = (disc >= 0) & (t > 0) & (z <= np.sin(np.radians(40.0))) & (z >= np.sin(np.radians(-80.0)))
            expected = np.where(on & (t < expected), t, expected)
        t = (-1.05 - O[:, 2]) / D[:, 2]
        P = O + t[:, None] * D
        on = (t > 0) & np.all(np.abs(P[:, :2]) <= 3.0, axis=1)
        expected = np.where(on & (t < expected), t, expected)
    assert np.array_equal(hits.hit, np.isfinite(expected)) and not hits.fallback.any()
    assert np.abs(hits.t[hits.hit] - expected[hits.hit]).max() < 1e-6


def test_the_finer_mesh_splits_only_faces_coarser_than_its_own_level():
    """`fine_factors`: each curved face's coarse chord error δ (∝ segments⁻²) is brought down to the finer mesh's
    level, max δ / 16, by the fewest whole multiples of the segments from 2 to 4: δ = max → 4, max/3 → ⌈√(16/3)⌉ = 3,
    max/8 and below → 2; a face meshed exactly (δ = 0, a plane) → 1. On a scene of a curved patch and a plane beside
    it, the plane's finer mesh is its coarse mesh, and the patch's is 4 × 4 times as many triangles."""
    from rtreflect.trace.secondlook import fine_factors

    grid = NurbsSurface.bezier(np.array([[[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]]))
    chord = np.array([2.0, 2.0 / 3.0, 2.0 / 8.0, 2.0 / 100.0, 0.0])
    assert fine_factors([grid] * 5, chord, 4).tolist() == [4, 3, 2, 2, 1]
    scene = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "hood.toml")
    curved = scene.surfaces[0]
    plane = NurbsSurface.bezier(np.array([[[-1.0, -1.0, -0.5], [-1.0, 1.0, -0.5]], [[1.0, -1.0, -0.5], [1.0, 1.0, -0.5]]]))
    renderer = Renderer(replace(scene, surfaces=(curved, plane)))
    coarse = renderer.tessellation
    fine, _ = renderer.second_look.fine()
    assert coarse.chord_error[1] == 0.0 < coarse.chord_error[0]
    per_face = lambda t: np.bincount(t.face_patch, minlength=2)  # noqa: E731
    assert per_face(fine)[1] == per_face(coarse)[1]
    assert per_face(fine)[0] == 16 * per_face(coarse)[0]
