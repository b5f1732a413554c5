"""The same part renders the same however its parameters are scaled and wherever it sits.

Real CAD exports have knots in millimetres (or in arc length) and parts metres from the
origin. The reference for each case is the original hood rendered pixel by pixel: with
knots_u × k_u and knots_v × k_v (the same surface, S(u, v) = S'(k_u u, k_v v)) and with the
whole scene moved by an offset, the colour, P, N and the other AOVs must not change (u and
v scale with the knots, P moves with the offset). Normals of the rescaled surfaces are also
compared with rhino3dm's. And `validate` must fail the wrong images these cases used to give.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from reference import angle_between, to_rhino, xyz
import rtreflect.geometry.surfaces as surfaces_module
import rtreflect.trace.accelerator as accelerator_module
import rtreflect.trace.tracing as tracing_module
import rtreflect.integrator.scenegeometry as scenegeometry
from rtreflect.analysis.validate import validate_scene
from rtreflect.exchange.bpt import read_bpt
from rtreflect.exchange.scene import load_scene
from rtreflect.integrator.film import CHANNELS
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace.accelerator import Accelerator

HOOD = Path(__file__).resolve().parent.parent / "scenes" / "hood.toml"
TEAPOT = HOOD.with_name("teapot.bpt")
WIDTH, HEIGHT = 320, 180
#: Knot scalings per direction (k_u, k_v): the issue's cases, both ways round.
SCALINGS = [(1e5, 1e-5), (1e6, 1e-6), (1e-6, 1e6)]
OFFSET = 1e5


def hood(knots_u: float = 1.0, knots_v: float = 1.0, offset: float = 0.0, samples: int = 2):
    """The hood scene with its knot vectors scaled, and surface, camera and lights moved by (offset, offset, offset)."""
    scene = load_scene(HOOD).with_image(WIDTH, HEIGHT, samples)
    move = np.full(3, offset)
    surface = scene.surfaces[0]
    surface = replace(surface, knots_u=surface.knots_u * knots_u, knots_v=surface.knots_v * knots_v,
                      points=surface.points + move)
    return replace(scene, surfaces=(surface,),
                   camera=replace(scene.camera, eye=scene.camera.eye + move, look_at=scene.camera.look_at + move),
                   lights=replace(scene.lights, point=scene.lights.point + move))


def channels(pixels: np.ndarray, *names: str) -> np.ndarray:
    return pixels[..., [CHANNELS.index(n) for n in names]].astype(np.float64)


@pytest.fixture(scope="module")
def original():
    return Renderer(hood()).render(threads=1)


# -- parameter scaling (issue 11 item 1) ----------------------------------------------------------


@pytest.mark.parametrize("k_u, k_v", SCALINGS, ids=[f"{a:g}x{b:g}" for a, b in SCALINGS])
def test_rescaled_knots_render_the_same_pixels(original, k_u, k_v):
    result = Renderer(hood(k_u, k_v)).render(threads=1)
    ours, ref = result.film.pixels, original.film.pixels
    np.testing.assert_allclose(channels(ours, "R", "G", "B", "A"), channels(ref, "R", "G", "B", "A"), atol=1e-6)
    hit = channels(ref, "patch")[..., 0] >= 0
    assert hit.sum() > 0.15 * hit.size
    np.testing.assert_array_equal(channels(ours, "patch")[..., 0] >= 0, hit)
    for names, atol in ((("P.X", "P.Y", "P.Z"), 1e-6), (("N.X", "N.Y", "N.Z"), 1e-6), (("Z",), 1e-6),
                        (("f",), 1e-5), (("line.id",), 0), (("line.dist",), 1e-6)):
        np.testing.assert_allclose(channels(ours, *names)[hit], channels(ref, *names)[hit], atol=atol, err_msg=names)
    # u and v scale with their knots (float32 storage: relative precision).
    np.testing.assert_allclose(channels(ours, "u")[hit], k_u * channels(ref, "u")[hit], rtol=1e-6, atol=1e-6 * k_u)
    np.testing.assert_allclose(channels(ours, "v")[hit], k_v * channels(ref, "v")[hit], rtol=1e-6, atol=1e-6 * k_v)
    assert result.stats.fallbacks == original.stats.fallbacks


@pytest.mark.parametrize("k_u, k_v", SCALINGS, ids=[f"{a:g}x{b:g}" for a, b in SCALINGS])
def test_rescaled_surface_normals_agree_with_rhino(k_u, k_v):
    """Inside the domain against rhino3dm on the rescaled surface; at the corners against rhino3dm on the original.

    OpenNURBS itself gets the corners of the rescaled surface wrong (NormalAt(0, 0) turns by 3 rad at
    1e5/1e-5, apparently a corner fallback with a scale-dependent test), so there the unscaled surface
    is the reference.
    """
    surface = hood().surfaces[0]
    scaled = hood(k_u, k_v).surfaces[0]
    rng = np.random.default_rng(7)
    u, v = np.r_[rng.uniform(0, 1, 200), 1e-9, 1 - 1e-9], np.r_[rng.uniform(0, 1, 200), 1e-9, 0.5]
    ours = scaled.normals(k_u * u, k_v * v)
    rh = to_rhino(scaled)
    theirs = np.array([xyz(rh.NormalAt(float(k_u * a), float(k_v * b))) for a, b in zip(u, v)])
    assert angle_between(ours, theirs).max() < 1e-9
    cu, cv = np.array([0.0, 1.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0, 1.0])
    rh_original = to_rhino(surface)
    corners = np.array([xyz(rh_original.NormalAt(float(a), float(b))) for a, b in zip(cu, cv)])
    assert angle_between(scaled.normals(k_u * cu, k_v * cv), corners).max() < 1e-9
    assert angle_between(scaled.normals(k_u * u, k_v * v), surface.normals(u, v)).max() < 1e-12


@pytest.mark.parametrize("k_u, k_v, offset", [(1e5, 1e-5, 0.0), (1e-6, 1e6, 0.0), (1.0, 1.0, OFFSET), (1e6, 1e-6, OFFSET)],
                         ids=["1e5x1e-5", "1e-6x1e6", "moved", "1e6x1e-6 moved"])
def test_teapot_pole_normals_survive_rescaling_and_moving(k_u, k_v, offset):
    """The teapot's poles (a collapsed u = 0 row): the limit normal stays vertical, and near the pole (where a
    partial is tiny and its rounding counts) the normals stay those of the original patch."""
    patches = read_bpt(TEAPOT)
    for pole, z in ((np.array([0.0, 0.0, 3.15]), -1.0), (np.zeros(3), 1.0)):
        for patch in (p for p in patches if np.all(p.points[0] == pole)):
            moved = replace(patch, knots_u=patch.knots_u * k_u, knots_v=patch.knots_v * k_v, points=patch.points + offset)
            v = np.linspace(0.0, 1.0, 21)
            at_pole = moved.normals(np.zeros_like(v), k_v * v)
            assert angle_between(at_pole, np.broadcast_to([0.0, 0.0, z], at_pole.shape)).max() < 1e-9
            for d in (1e-9, 1e-7, 1e-5, 1e-3):
                near = moved.normals(np.full_like(v, k_u * d), k_v * v)
                assert angle_between(near, patch.normals(np.full_like(v, d), v)).max() < 1e-6, (patch.name, d)


def test_validate_fails_normals_taken_as_degenerate_everywhere(monkeypatch):
    """What the old |S_u × S_v| ≤ 1e-10 (|S_u|² + |S_v|²) test did at 1e6/1e-6: every point taken as degenerate.

    The contours use the same normals, so the lines agree with them; the stored N must still be
    checked against the surface's tangents.
    """
    assert validate_scene(hood(1e6, 1e-6, samples=1), threads=1).passed
    monkeypatch.setattr(surfaces_module, "VANISHING_PARTIAL", np.inf)
    report = validate_scene(hood(1e6, 1e-6, samples=1), threads=1)
    assert not report.passed
    assert any("normal N off the surface normal" in reason for reason in report.reasons), report.reasons


# -- far from the origin (issue 11 item 3) --------------------------------------------------------


def test_embree_hits_far_from_the_origin_are_as_precise_as_at_the_origin():
    near, far = Renderer(hood(samples=1)), Renderer(hood(offset=OFFSET, samples=1))
    rows, cols = np.divmod(np.arange(WIDTH * HEIGHT), WIDTH)
    origins, directions = near.camera.rays(rows, cols)
    a = near.accelerator.intersect(origins, directions)
    b = far.accelerator.intersect(origins + OFFSET, directions)
    assert (a.prim >= 0).sum() > 0.15 * len(a.prim)
    same = (a.prim == b.prim) & (a.prim >= 0)
    assert same.sum() >= (a.prim >= 0).sum() - 20  # at most a few triangle edges change hands
    # float32 at the mesh's own scale (3 units, 4 from the eye): ~1e-6, not float32 at 1e5 (~1e-2).
    assert np.abs(a.t[same] - b.t[same]).max() < 1e-5
    far_eye = far.accelerator.occluded(origins + OFFSET, directions, np.full(len(origins), 100.0))
    np.testing.assert_array_equal(far_eye, a.prim >= 0)


def test_translated_scene_renders_the_same_pixels(original):
    result = Renderer(hood(offset=OFFSET)).render(threads=1)
    ours, ref = result.film.pixels, original.film.pixels
    hit = channels(ref, "patch")[..., 0] >= 0
    np.testing.assert_array_equal(channels(ours, "patch")[..., 0] >= 0, hit)
    colour = np.abs(channels(ours, "R", "G", "B", "A") - channels(ref, "R", "G", "B", "A")).max(axis=-1)
    assert np.count_nonzero(colour > 1e-6) <= 5  # a few edge pixels at most
    # P = original P + offset, to float32's precision at 1e5 (one unit in the last place: 1/128).
    P, P0 = channels(ours, "P.X", "P.Y", "P.Z")[hit], channels(ref, "P.X", "P.Y", "P.Z")[hit] + OFFSET
    assert np.all(np.abs(P - P0) <= np.spacing(np.float32(P0)))
    np.testing.assert_allclose(channels(ours, "N.X", "N.Y", "N.Z")[hit], channels(ref, "N.X", "N.Y", "N.Z")[hit],
                               atol=1e-6)
    for name in ("u", "v", "Z", "f", "line.dist"):
        np.testing.assert_allclose(channels(ours, name)[hit], channels(ref, name)[hit], atol=1e-5, err_msg=name)
    assert result.stats.fallbacks <= original.stats.fallbacks + 2


def test_validate_passes_the_translated_scene_and_fails_mesh_hits_kept_there(monkeypatch):
    """The old render far from the origin: the BVH in world float32 coordinates, and the mesh hits kept.

    It kept mesh hits ~0.01 off the surface; validate's on-surface test allowed 1e-5 |P| (1.7 units
    at 1e5 on a 2.85-unit part) and passed it. Relative to the part's size it sees them. (The
    correct render used to fail on misses instead: validate's checks ran on float32 P, 1/128
    coarse at 1e5.) The tracer no longer keeps an unrefined mesh point, so the old behaviour is
    simulated by a "Newton" that stops at the mesh hit's interpolated (u, v) and calls it converged
    (an infinite tolerance: the compiled Newton accepts its first evaluation, there).
    """
    far = hood(offset=OFFSET, samples=1)
    assert validate_scene(far, threads=1).passed

    monkeypatch.setattr(tracing_module, "NEWTON_TOLERANCE", np.inf)
    monkeypatch.setattr(accelerator_module, "bvh_centre", lambda vertices: np.zeros(3))
    monkeypatch.setattr(scenegeometry, "_last", None)  # the scene's BVH built again, uncentred (not the one above)
    report = validate_scene(far, threads=1)
    assert not report.passed, report.reasons


def test_bvh_works_in_its_own_centred_coordinates():
    renderer = Renderer(hood(offset=OFFSET, samples=1))
    accelerator: Accelerator = renderer.accelerator
    np.testing.assert_allclose(accelerator.centre, accelerator_module.bvh_centre(renderer.tessellation.vertices))
    assert np.abs(accelerator.centre - OFFSET).max() < 2.0


# -- knots far from 0 for their spans (the eleventh sweep) ---------------------------------------


def test_knots_far_from_zero_hit_where_open_cascade_does(tmp_path):
    """An inline patch whose knots_u run 1e6 … 1e6 + 7 (spans 1–4 wide) is the same surface as with 0 … 7.

    float64 resolves u there only to ~1e-10, S along u no finer than ~1e-10 of the patch: above Newton's
    tolerance, so 1,803 of 2,325 rays that Open CASCADE sees hit it missed (96×64). The parser moves such a
    knot vector to start at 0. Checked against Open CASCADE's first hits on the surface with the given knots.
    """
    pytest.importorskip("OCP")
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.collections import Array2_gp_Pnt

    from rtreflect.exchange.rhino import _knots_and_mults
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt
    from test_cad_hits import occt_nearest

    a, b = np.meshgrid(np.linspace(-1, 1, 6), np.linspace(-1, 1, 5), indexing="ij")
    points = np.stack([a, b, 0.3 * np.sin(3 * a) * b], axis=-1)
    knots_u = [1e6] * 4 + [1e6 + 1, 1e6 + 3] + [1e6 + 7] * 4
    knots_v = [-5.0] * 3 + [-1.0, 0.0] + [2.0] * 3
    rows = ",\n".join("  [" + ", ".join(f"[{x!r}, {y!r}, {z!r}]" for x, y, z in row) + "]" for row in points.tolist())
    path = tmp_path / "far_knots.toml"
    path.write_text(f"""[image]
width = 64
height = 48
[camera]
eye = [1.06, -2.26, 1.23]
look_at = [0.0, 0.0, 0.0]
fov = 50.0
[lights]
point = [0.0, 0.0, 3.0]
normal = [0.0, 0.0, 1.0]
direction = [0.0, 1.0, 0.0]
spacing = 0.4
count = 9
[[surface]]
degree = [3, 2]
knots_u = {knots_u}
knots_v = {knots_v}
points = [
{rows}
]
""")
    renderer = Renderer(load_scene(path))
    rows_, cols = np.divmod(np.arange(64 * 48), 64)
    O, D = renderer.camera.rays(rows_, cols)
    hits = renderer.trace(O, D)

    poles = Array2_gp_Pnt(1, 6, 1, 5)
    for i in range(6):
        for j in range(5):
            poles.SetValue(i + 1, j + 1, gp_Pnt(*points[i, j]))

    # OCCT's distinct knots and multiplicities (the .3dm reader's conversion, given the knots without their end ones).
    (uk, um), (vk, vm) = _knots_and_mults(knots_u[1:-1], 3), _knots_and_mults(knots_v[1:-1], 2)
    face = BRepBuilderAPI_MakeFace(Geom_BSplineSurface(poles, uk, vk, um, vm, 3, 2), 1e-7).Face()
    expected = occt_nearest(face, O, D)
    seen = np.isfinite(expected[:, 0])
    assert seen.sum() > 0.2 * len(seen)
    assert hits.hit[seen].all()
    assert (hits.hit & ~seen).sum() <= 2  # a silhouette ray Open CASCADE's intersector passes
    t = np.einsum("ij,ij->i", expected[seen] - O[seen], D[seen])
    np.testing.assert_allclose(hits.t[seen], t, rtol=0, atol=1e-6 * renderer.tessellation.extent)
    assert hits.fallback.sum() == 0
    # Only the knot vector far from 0 for its spans is moved (`scene.KNOT_OFFSET_SPANS`): v keeps the scene's
    # parameters (its domain starts 5 spans from 0), so its AOV is the (u, v) the scene's author wrote.
    assert renderer.surfaces.patches[0].domain == ((0.0, 7.0), (-5.0, 2.0))
