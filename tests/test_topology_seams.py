"""Seams of CAD parts from the B-rep topology (issue 16), against Open CASCADE read here directly.

The reference is OCCT's own shared-edge set: ``TopExp.MapShapesAndAncestors_s(shape, EDGE, FACE)``
over the converted shape; an edge with two different faces is a seam between them, an edge used
twice by one face (a periodic face's seam) is not. The samples of each seam are checked against
the pcurves OCCT gives for the edge on each face (``BRepAdaptor_Curve2d``), and their ends
against the edge's vertices.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

OCP = pytest.importorskip("OCP")

from rtreflect.analysis.continuity import sample_seam  # noqa: E402
from rtreflect.exchange.cad import read_cad  # noqa: E402
from rtreflect.geometry.seams import find_seams, part_size, scene_seams  # noqa: E402

PARTS = Path(__file__).resolve().parents[1] / "parts"
#: Samples on the pcurves: OCCT's evaluation and the stored samples are the same float64 numbers, 1e-9 is the brief.
ON_PCURVE = 1e-9


def occt_topology(path: Path):
    """(converted faces in explorer order, [(edge, [face indices using it])]) of a STEP file, read with OCP directly."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.collections import IndexedDataMap_TopoDS_Shape_List_TopoDS_Shape_TopTools_ShapeMapHasher as EdgeFaces
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE
    from OCP.TopExp import TopExp, TopExp_Explorer
    from OCP.TopoDS import TopoDS

    reader = STEPControl_Reader()
    reader.ReadFile(str(path))
    reader.TransferRoots()
    shape = BRepBuilderAPI_NurbsConvert(reader.OneShape(), True).Shape()
    faces, explorer = [], TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        faces.append(TopoDS.Face(explorer.Current()))
        explorer.Next()
    ancestors = EdgeFaces()
    TopExp.MapShapesAndAncestors_s(shape, TopAbs_EDGE, TopAbs_FACE, ancestors)
    edges = []
    for i in range(1, ancestors.Extent() + 1):
        users = [next(k for k, f in enumerate(faces) if f.IsSame(g)) for g in ancestors.FindFromIndex(i)]
        edges.append((TopoDS.Edge(ancestors.FindKey(i)), users))
    return faces, edges


def occt_pairs(edges) -> Counter:
    """Face pairs (A < B) sharing an edge, with multiplicity; an edge used twice by one face pairs nothing."""
    pairs = Counter()
    for _, users in edges:
        distinct = sorted(set(users))
        for i, a in enumerate(distinct):
            for b in distinct[i + 1:]:
                pairs[(a, b)] += 1
    return pairs


@pytest.mark.parametrize("name", ["filleted_block.step", "assembly.step", "plate.step"])
def test_seams_are_exactly_the_shared_edges_of_the_brep(name):
    faces, edges = occt_topology(PARTS / name)
    surfaces = read_cad(PARTS / name).surfaces
    assert len(surfaces) == len(faces)
    expected = occt_pairs(edges)
    seams = scene_seams(surfaces)
    got = Counter(tuple(sorted(s.patches)) for s in seams)
    assert got == expected
    assert len(seams) == sum(expected.values())
    # The plate's holes are periodic faces, each with its own seam edge: none of them is a seam between faces.
    assert all(a != b for a, b in got)
    if name == "plate.step":
        assert sum(len(set(u)) == 1 and len(u) == 2 for _, u in edges) == 200


def test_geometric_finder_pairs_a_periodic_face_with_itself():
    """The geometric finder reads the plate's hole cylinders' own seams (one face's two period ends, a single
    B-rep edge) as seams: the topology, and OCCT, say they join no two faces."""
    surfaces = read_cad(PARTS / "plate.step").surfaces
    _, edges = occt_topology(PARTS / "plate.step")
    geometric = Counter(tuple(sorted(s.patches)) for s in find_seams(surfaces))
    assert geometric != occt_pairs(edges)
    assert any(a == b for a, b in geometric)


def test_fillet_edges_are_g1_along_the_whole_edge_and_on_both_pcurves():
    """filleted_block: every shared edge (plane–cylinder, cylinder–torus, ...) is tangent to 1e-6° at every sample,
    from one vertex of the edge to the other, and each sample lies on both faces' pcurves at the same parameter."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve2d
    from OCP.TopExp import TopExp

    path = PARTS / "filleted_block.step"
    faces, edges = occt_topology(path)
    surfaces = read_cad(path).surfaces
    size = part_size(surfaces)
    seams = {tuple(sorted(s.patches)): s for s in scene_seams(surfaces)}
    for edge, users in edges:
        if len(set(users)) != 2:
            continue
        a, b = sorted(users)
        seam = seams[(a, b)]
        samples = sample_seam(surfaces, seam, size)
        assert np.degrees(samples.g1).max() <= 1e-6
        # G0 at the common parameter: within the edge's own tolerance (OCCT's SameParameter bound).
        assert samples.g0.max() <= BRep_Tool.Tolerance_s(edge)
        # The whole edge: the first and last samples are the edge's vertices (in either direction).
        ends = [BRep_Tool.Pnt_s(TopExp.FirstVertex_s(edge)), BRep_Tool.Pnt_s(TopExp.LastVertex_s(edge))]
        ends = np.array([[p.X(), p.Y(), p.Z()] for p in ends])
        got = samples.P[[0, -1]]
        assert min(np.abs(got - ends).max(), np.abs(got[::-1] - ends).max()) <= 1e-9 * size
        # On both pcurves: OCCT's pcurve of this edge on each face, at the edge's parameters.
        for face_index, uv in ((seam.a.patch, samples.uv_a), (seam.b.patch, samples.uv_b)):
            curve = BRepAdaptor_Curve2d(edge, faces[face_index])
            t = np.linspace(curve.FirstParameter(), curve.LastParameter(), len(uv))
            ref = np.array([(p.X(), p.Y()) for p in (curve.Value(float(x)) for x in t)])
            assert np.abs(uv - ref).max() <= ON_PCURVE
        # A fillet of radius 4 against a plane: the curvature across jumps by 1/4 along the whole edge.
        if seam.length == pytest.approx(22.0) or seam.length == pytest.approx(32.0):
            np.testing.assert_allclose(samples.jump, 0.25, rtol=1e-9)


def test_toml_patches_keep_the_geometric_finder():
    """Inline patches carry no topology: g1_join's one seam is still found from the boundary curves."""
    from rtreflect.exchange.load import load_scene

    scene = load_scene(Path(__file__).resolve().parents[1] / "scenes" / "g1_join.toml")
    seams = scene_seams(list(scene.surfaces))
    assert [s.paired for s in seams] == [False]
    assert [tuple(sorted(s.patches)) for s in seams] == [(0, 1)]


def rhino_pairs(path: Path) -> Counter:
    """Face pairs sharing an edge by rhino3dm's own Brep topology (the trims' edge indices), faces numbered over the
    file's Breps in order."""
    rhino3dm = pytest.importorskip("rhino3dm")
    pairs, base = Counter(), 0
    for obj in rhino3dm.File3dm.Read(str(path)).Objects:
        brep = obj.Geometry
        users: dict[int, set] = {}
        for k, face in enumerate(brep.Faces):
            for loop in face.Loops:
                for trim in loop.Trims:
                    if trim.EdgeIndex >= 0:
                        users.setdefault(trim.EdgeIndex, set()).add(base + k)
        for faces in users.values():
            if len(faces) == 2:
                pairs[tuple(sorted(faces))] += 1
        base += len(brep.Faces)
    return pairs


def test_rhino_seams_are_the_breps_shared_edges():
    """trimmed.3dm: the seams are the Brep edges two faces share (the capped cylinder's two rims), by rhino3dm's
    topology; the cylinder's own seam edge (used twice by one face) is none. The geometric finder paired the
    cylinder with itself there."""
    path = PARTS / "trimmed.3dm"
    surfaces = read_cad(path).surfaces
    expected = rhino_pairs(path)
    assert expected == Counter({(1, 2): 1, (1, 3): 1})
    assert Counter(tuple(sorted(s.patches)) for s in scene_seams(surfaces)) == expected
    assert (1, 1) in Counter(tuple(sorted(s.patches)) for s in find_seams(surfaces))


def test_seam_picture_sees_the_whole_rim_of_a_cap_seen_from_above():
    """trimmed.3dm's top cap (z = 25, a disc bounded by its rim) seen from an eye above its plane: the disc is convex
    and faces the eye, so every point of its rim is visible. The seam picture drew only bits of it: its visibility
    rays left the rim along the cylinder's normal, on the cap's plane, and the cap's triangles (which overhang the
    trim) hid them."""
    from rtreflect.analysis.contours import UlmetField
    from rtreflect.analysis.seamcheck import check_scene
    from rtreflect.analysis.seampicture import _seen_from_eye
    from rtreflect.exchange.load import load_scene
    from rtreflect.integrator.renderer import Renderer

    result = check_scene(load_scene(PARTS / "trimmed.3dm"), lines=False)
    field = UlmetField.of(Renderer(result.scene))
    top = next(e for e in result.edges if np.allclose(e.samples.P[:, 2], 25.0))
    assert field.camera.spec.eye[2] > 25.0
    s = top.samples
    assert np.all(_seen_from_eye(field, top.seam.patches, s.P, s.n_a, s.n_b))


def test_a_part_read_twice_joins_no_face_of_one_copy_to_the_other(tmp_path):
    """A scene naming one STEP file twice holds two copies of each edge: each copy's faces pair among themselves only
    (edge keys are unique per read), 48 seams each, as the part alone."""
    import shutil

    from rtreflect.exchange.load import load_scene

    shutil.copy(PARTS / "filleted_block.step", tmp_path)
    (tmp_path / "twice.toml").write_text('[[surface]]\nfile = "filleted_block.step"\n' * 2)
    surfaces = list(load_scene(tmp_path / "twice.toml").surfaces)
    assert len(surfaces) == 52
    pairs = [tuple(sorted(s.patches)) for s in scene_seams(surfaces)]
    assert len(pairs) == 96 and all((a < 26) == (b < 26) for a, b in pairs)
