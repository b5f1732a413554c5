"""Newton stops on a pole (a collapsed side of a face's domain, one point in 3D) decided as inside the face (issue 12
leftovers): by the Levenberg–Marquardt search in the second look's restarts from the shell, and by a neighbouring face
sharing the pole where the search leaves it undecided.

Parts are written at test time by tools/make_sweep_parts.py; the reference is Open CASCADE's nearest exact hit
(`IntCurvesFace_ShapeIntersector.PerformNearest`, tests/test_cad_hits.py's `occt_nearest`).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

OCP = pytest.importorskip("OCP")
pytest.importorskip("shapely")

from rtreflect.exchange.load import load_scene  # noqa: E402
from rtreflect.integrator.autorig import resolve  # noqa: E402
from rtreflect.integrator.renderer import Renderer  # noqa: E402
from rtreflect.trace.accelerator import MeshHits  # noqa: E402
from rtreflect.trace.tracing import Hits, _on_collapsed_side, refine_all  # noqa: E402

from test_cad_hits import POINT_TOLERANCE, occt_nearest  # noqa: E402
from test_cad_reader import occt_faces  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import make_sweep_parts as sweep  # noqa: E402


def halves_renderer(solid, path: Path) -> Renderer:
    """A renderer (160×90, automatic scene) of ``solid`` with its closed faces cut in two along meridians (OCCT's
    `ShapeUpgrade_ShapeDivideClosed`), written to ``path``: the halves share the poles."""
    from OCP.ShapeUpgrade import ShapeUpgrade_ShapeDivideClosed

    divide = ShapeUpgrade_ShapeDivideClosed(solid)
    divide.SetNbSplitPoints(1)
    divide.Perform()
    sweep.write_step_in(divide.Result(), path, "MM")
    return Renderer(resolve(load_scene(path).with_image(160, 90, 1)))


def test_shell_restart_that_stops_on_a_pole_is_searched(tmp_path):
    """sphere_pole_view.step (a sphere whose pole faces the default camera), the ray of pixel (37, 77) at 160×90, which
    meets the sphere near its pole: a second-look start from the shell triangle at the pole an eighth of a turn round
    from the hit (`SecondLook._from_shell`) sends Newton onto the pole, where it stops, clamped. That is no exit from
    the face (the side is one point in 3D): the search must decide there, as the tracer's candidates do. It found no
    hit; now OCCT's nearest."""
    path = tmp_path / "sphere_pole_view.step"
    sweep.PARTS[path.name](path)
    renderer = Renderer(resolve(load_scene(path).with_image(160, 90, 1)))
    surfaces, look = renderer.surfaces, renderer.second_look
    origins, directions = renderer.camera.rays(np.array([37]), np.array([77]))
    hit = renderer.trace(origins, directions)
    assert hit.hit.all()
    (u0,), (u1,), (v0,), (v1,) = surfaces.domains(np.array([0]))
    side = v0 if abs(hit.v[0] - v0) < abs(hit.v[0] - v1) else v1
    shell = look.shell_mesh
    corners = shell.vertex_uv[shell.faces]
    # A triangle touching the pole, not one lying in it (a skirt clamped to the domain's side: all three corners on
    # the pole, no area in 3D, where no ray meets it and a start is the pole itself).
    on_side = corners[:, :, 1] == side
    at_pole = np.flatnonzero(on_side.any(axis=1) & ~on_side.all(axis=1) & (shell.face_patch == 0))
    turned = u0 + (hit.u[0] - u0 + 0.125 * (u1 - u0)) % (u1 - u0)
    prim = at_pole[np.argmin(np.abs(corners[at_pole].mean(axis=1)[:, 0] - turned))]
    entry = MeshHits(np.array([prim]), np.array([0.1]), np.array([0.1]), hit.t.copy())
    patch, u, v = shell.start_parameters(entry.prim, entry.b1, entry.b2)
    u, v, _, converged, edge = refine_all(surfaces, patch, u, v, origins, directions, entry.t, renderer.tessellation.extent)[:5]
    assert edge[0] and not converged[0] and _on_collapsed_side(surfaces, patch, u, v)[0]  # Newton stops on the pole
    hits = Hits.blank(1, np.zeros(1, dtype=bool))
    look._from_shell(hits, origins, directions, np.full(1, np.inf), np.array([0]), entry)
    shape, _, _, _ = occt_faces(path)
    expected = np.einsum("ij,ij->i", occt_nearest(shape, origins, directions) - origins, directions)
    assert hits.hit.all() and np.isfinite(expected).all()
    np.testing.assert_allclose(hits.t, expected, rtol=0, atol=POINT_TOLERANCE * renderer.tessellation.extent)


def test_pole_stop_left_undecided_goes_on_to_the_face_sharing_the_pole(tmp_path, monkeypatch):
    """A sphere cut in two along meridians (`ShapeUpgrade_ShapeDivideClosed`), its poles facing the default camera: the
    two faces share each pole and no edge there. A mesh hit on the first face beside the pole whose ray meets the
    second face: Newton stops on the pole; with the search switched off (`RESCUE_STEPS` = 0, so it leaves the stop
    undecided, as it does where it runs out of steps) and `_passes_by` finding no positive minimum, the candidate
    stayed unresolved (a fallback) though the neighbour across the pole holds the hit. Now it is tried there
    (`tracing._across_pole`) and found: OCCT's nearest hit, on the second face."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeSphere
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    from rtreflect.trace import tracing

    sphere = BRepPrimAPI_MakeSphere(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(*sweep.ISO_FROM)), 20.0).Shape()
    path = tmp_path / "sphere_halves.step"
    renderer = halves_renderer(sphere, path)
    surfaces, tessellation = renderer.surfaces, renderer.tessellation
    assert len(surfaces) == 2
    rows, cols = np.meshgrid(np.arange(90), np.arange(160), indexing="ij")
    origins, directions = renderer.camera.rays(rows.ravel(), cols.ravel())
    hits = tracing.trace(renderer.accelerator, tessellation, surfaces, origins, directions)
    (u0,), (u1,), (v0,), (v1,) = surfaces.domains(np.array([1]))
    beside = np.flatnonzero(hits.hit & (hits.patch == 1) & (np.minimum(np.abs(hits.v - v0), np.abs(hits.v - v1)) < 0.1))
    corners = tessellation.vertex_uv[tessellation.faces]
    monkeypatch.setattr(tracing, "RESCUE_STEPS", 0)
    tried = 0
    shape, _, _, _ = occt_faces(path)
    for ray in beside:
        side = v0 if abs(hits.v[ray] - v0) < abs(hits.v[ray] - v1) else v1
        at_pole = np.flatnonzero((corners[:, :, 1] == side).any(axis=1) & (tessellation.face_patch == 0))
        O, D, t = origins[ray:ray + 1], directions[ray:ray + 1], hits.t[ray:ray + 1]
        for prim in at_pole:
            b = np.array([0.2])
            patch, u, v = tessellation.start_parameters(np.array([prim]), b, b)
            u, v, _, converged, edge = tracing.refine_all(surfaces, patch, u, v, O, D, t, tessellation.extent)[:5]
            if converged[0] or not edge[0] or not tracing._on_collapsed_side(surfaces, patch, u, v)[0]:
                continue  # Newton does not stop on the pole from there
            c = tracing._candidates(tessellation, surfaces, O, D, np.array([prim]), b, b, t)
            expected = np.einsum("ij,ij->i", occt_nearest(shape, O, D) - O, D)
            assert c.status[0] == tracing.VALID and c.patch[0] == 1, (ray, prim, c.status, c.patch)
            np.testing.assert_allclose(c.t, expected, rtol=0, atol=POINT_TOLERANCE * tessellation.extent)
            tried += 1
            if tried == 5:
                return
    assert tried, "no mesh hit beside the pole whose Newton stops on it"


def test_pole_stop_whose_search_converges_far_goes_on_to_the_face_sharing_the_apex(tmp_path):
    """A cone cut in two along meridians (`ShapeUpgrade_ShapeDivideClosed`), its apex facing the default camera: the two
    faces share the apex and no edge there. A ray enters the second face beside the apex and leaves through the first
    3.7 farther; a mesh hit on the first face's triangle at the apex (t = the entry's) sends Newton onto the apex, where
    it stops, and the search from the mesh hit converges on the ray's exit through the first face: on the ray, but
    beyond the reach of the mesh hit. The candidate stayed unresolved (a fallback; the ray went on past the entry, to
    the cone's far side): the face sharing the pole was tried only where the search stayed undecided. Now any pole stop
    left unresolved is tried there (`tracing._across_pole`), and found: OCCT's nearest hit, on the second face."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCone
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    from rtreflect.trace import tracing

    axis = np.array(sweep.ISO_FROM) / np.linalg.norm(sweep.ISO_FROM)
    cone = BRepPrimAPI_MakeCone(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(*axis)), 15.0, 0.0, 25.0).Shape()
    path = tmp_path / "cone_halves.step"
    renderer = halves_renderer(cone, path)
    surfaces, tessellation = renderer.surfaces, renderer.tessellation
    (u0,), (u1,), (v0,), (v1,) = surfaces.domains(np.array([0]))
    assert surfaces.collapsed[0, 2] and surfaces.collapsed[1, 2]  # both faces end at the apex, v = v0
    O = np.array([[64.68506105058178, 21.16805508583975, -36.49864186919903]])
    D = np.array([[-0.6848195626998844, -0.45748347965392133, 0.5672133922848429]])
    shape, _, _, _ = occt_faces(path)
    expected = np.einsum("ij,ij->i", occt_nearest(shape, O, D) - O, D)
    assert np.isfinite(expected).all()
    corners = tessellation.vertex_uv[tessellation.faces]
    at_apex = np.flatnonzero((corners[:, :, 1] == v0).any(axis=1) & (tessellation.face_patch == 0))
    band = tessellation.chord_error + tracing.FLOAT32_SLACK * tessellation.extent
    b, tried = np.array([0.01]), 0
    for prim in at_apex:
        patch, u, v = tessellation.start_parameters(np.array([prim]), b, b)
        un, vn, _, converged, edge = tracing.refine_all(surfaces, patch, u, v, O, D, expected, tessellation.extent)[:5]
        if converged[0] or not edge[0] or not tracing._on_collapsed_side(surfaces, patch, un, vn)[0]:
            continue  # Newton does not stop on the apex from there
        tol = tracing._search_tolerance(expected, tessellation.extent)
        _, _, d2, found = tracing._rescue(surfaces, patch, u, v, O, D, tol)[:4]
        near, _ = tracing._near_mesh_hit(d2, patch, O, D, expected, band)
        if not found[0] or near[0]:
            continue  # the search does not converge far from the mesh hit from there
        c = tracing._candidates(tessellation, surfaces, O, D, np.array([prim]), b, b, expected)
        assert c.status[0] == tracing.VALID and c.patch[0] == 1, (prim, c.status, c.patch)
        np.testing.assert_allclose(c.t, expected, rtol=0, atol=POINT_TOLERANCE * tessellation.extent)
        tried += 1
    assert tried, "no mesh hit at the apex whose Newton stops there and whose search converges far"
