"""The CAD readers against Open CASCADE and rhino3dm as independent references (issue 12).

For every shipped part, each face read by rtreflect is compared with the face Open CASCADE
itself gives for the same file (read here with OCP directly, without rtreflect's code):

- points: rtreflect's `NurbsSurface` at sampled (u, v) equals OCCT's converted face surface
  there, and lies on the ORIGINAL (unconverted) face's surface (conversion kept the geometry);
- normals: S_u × S_v, flipped on reversed faces, equals OCCT's face normal (``BRepGProp_Face``,
  which follows face orientation);
- trims: `Trim.contains` agrees with ``BRepClass_FaceClassifier`` at random (u, v) except within
  `TRIM_BAND` of the trim boundary;
- face counts and bounding boxes agree with OCCT's; every knot vector passes the scene reader's checks;
- .3dm: the surfaces equal rhino3dm's own evaluation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

OCP = pytest.importorskip("OCP")
shapely = pytest.importorskip("shapely")

from rtreflect.exchange.cad import read_cad  # noqa: E402
from rtreflect.exchange.occt import TRIM_TOLERANCE  # noqa: E402

PARTS = Path(__file__).resolve().parents[1] / "parts"
STEP_PARTS = ["trimmed_face.step", "filleted_block.step", "revolved.step", "plate.step", "assembly.step",
              "filleted_block.igs"]
#: Faces in each shipped part, counted by OCCT's explorer over the file's shape (assembly: 2 instances × 26).
FACE_COUNTS = {"trimmed_face.step": 1, "filleted_block.step": 26, "revolved.step": 1, "plate.step": 206,
               "assembly.step": 52, "filleted_block.igs": 26, "trimmed.3dm": 4}
#: Samples per face (plate: fewer, it has 206 faces).
SAMPLES = 24
#: Point agreement with OCCT's evaluation of the same B-spline, relative to the part's diagonal: float64 rounding.
POINT_TOLERANCE = 1e-11
#: Distance to the original (unconverted) face surface, relative to the diagonal: OCCT's conversion
#: of cylinders, tori and revolved surfaces is exact (rational); 1e-9 leaves room for projection.
ORIGINAL_TOLERANCE = 1e-9
#: Normal agreement (1 − cos of the angle).
NORMAL_TOLERANCE = 1e-9
#: Trim and classifier may disagree only this close (in (u, v), relative to the domain's size) to the
#: trim polyline: the polyline is within TRIM_TOLERANCE of the pcurve in model space, and the classifier
#: has its own tolerance at the boundary.
TRIM_BAND = 1e-4


def occt_faces(path: Path):
    """(shape, original faces, converted shape, converted faces) of a STEP or IGES file, read with OCP directly (the
    shape itself where OCCT cannot convert it)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.IGESControl import IGESControl_Reader
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    reader = STEPControl_Reader() if path.suffix.lower() in (".step", ".stp") else IGESControl_Reader()
    reader.ReadFile(str(path))
    reader.TransferRoots()
    shape = reader.OneShape()
    try:
        converted = BRepBuilderAPI_NurbsConvert(shape, True).Shape()
    except Exception:  # OCCT cannot convert it (the sweep's periodic_trimmed.step): its faces are B-splines already
        converted = shape

    def faces(s):
        out, explorer = [], TopExp_Explorer(s, TopAbs_FACE)
        while explorer.More():
            out.append(TopoDS.Face(explorer.Current()))
            explorer.Next()
        return out

    return shape, faces(shape), converted, faces(converted)


def inside_samples(surface, count: int, rng) -> np.ndarray:
    """Random (u, v) on the trimmed face (rejection sampling in the domain)."""
    (u0, u1), (v0, v1) = surface.domain
    found = []
    for _ in range(50):
        uv = np.column_stack([rng.uniform(u0, u1, 4 * count), rng.uniform(v0, v1, 4 * count)])
        found.append(uv[surface.trim.contains(uv[:, 0], uv[:, 1])])
        if sum(len(f) for f in found) >= count:
            break
    return np.concatenate(found)[:count]


@pytest.fixture(scope="module", params=STEP_PARTS)
def part(request):
    path = PARTS / request.param
    return path, read_cad(path), occt_faces(path)


def test_face_counts_and_bounding_box(part):
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    path, model, (shape, originals, converted, faces) = part
    assert len(model.surfaces) == len(faces) == len(originals) == FACE_COUNTS[path.name] == model.faces
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(shape, box, False, False)  # exact box of the original geometry
    lo, hi = box.CornerMin(), box.CornerMax()
    reference = np.array([[lo.X(), lo.Y(), lo.Z()], [hi.X(), hi.Y(), hi.Z()]])
    ours = np.array(model.bounds)
    # Ours is the box of sampled points of the faces (mesh nodes, trim loops): inside OCCT's, and close to it.
    diagonal = np.linalg.norm(reference[1] - reference[0])
    assert np.all(ours[0] >= reference[0] - 1e-6 * diagonal) and np.all(ours[1] <= reference[1] + 1e-6 * diagonal)
    assert np.max(np.abs(ours - reference)) < 2e-3 * diagonal


def test_points_and_normals_match_occt(part):
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepGProp import BRepGProp_Face
    from OCP.BRep import BRep_Tool
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.gp import gp_Pnt, gp_Vec

    path, model, (shape, originals, converted, faces) = part
    diagonal = model.diagonal
    rng = np.random.default_rng(12)
    stride = max(1, len(faces) // 40)  # the plate: every fifth face
    for k in range(0, len(faces), stride):
        surface, face, original = model.surfaces[k], faces[k], originals[k]
        assert model.reversed[k] == (face.Orientation() == TopAbs_REVERSED)
        uv = inside_samples(surface, SAMPLES, rng)
        assert len(uv) > 0, f"face {k}: no sample inside its trim"
        ours = surface.evaluate(uv[:, 0], uv[:, 1])
        normal = np.cross(ours.Su, ours.Sv)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        if model.reversed[k]:
            normal = -normal
        adaptor = BRepAdaptor_Surface(face)
        props = BRepGProp_Face(face)
        original_surface = BRep_Tool.Surface_s(original)
        for (u, v), point, n in zip(uv, ours.S, normal):
            reference = adaptor.Value(float(u), float(v))
            assert np.linalg.norm(point - [reference.X(), reference.Y(), reference.Z()]) <= POINT_TOLERANCE * diagonal, (k, u, v)
            p, vec = gp_Pnt(), gp_Vec()
            props.Normal(float(u), float(v), p, vec)
            m = np.array([vec.X(), vec.Y(), vec.Z()])
            if np.linalg.norm(m) > 1e-12 * diagonal:  # OCCT's normal vanishes at poles; ours is the limit there
                assert 1 - n @ (m / np.linalg.norm(m)) <= NORMAL_TOLERANCE, (k, u, v)
            projection = GeomAPI_ProjectPointOnSurf(gp_Pnt(*point), original_surface)
            assert projection.NbPoints() > 0 and projection.LowerDistance() <= ORIGINAL_TOLERANCE * diagonal, (k, u, v)


def test_trim_contains_matches_face_classifier(part):
    from OCP.BRepClass import BRepClass_FaceClassifier
    from OCP.TopAbs import TopAbs_IN, TopAbs_ON
    from OCP.gp import gp_Pnt2d

    path, model, (shape, originals, converted, faces) = part
    rng = np.random.default_rng(7)
    stride = max(1, len(faces) // 40)
    checked = 0
    for k in range(0, len(faces), stride):
        surface, face = model.surfaces[k], faces[k]
        (u0, u1), (v0, v1) = surface.domain
        uv = np.column_stack([rng.uniform(u0, u1, 300), rng.uniform(v0, v1, 300)])
        ours = surface.trim.contains(uv[:, 0], uv[:, 1])
        reference = np.array([BRepClass_FaceClassifier(face, gp_Pnt2d(float(u), float(v)), 1e-9).State() in (TopAbs_IN, TopAbs_ON)
                              for u, v in uv])
        assert ours.any() and reference.any(), f"face {k}: no sample inside"
        disagree = np.flatnonzero(ours != reference)
        if len(disagree):
            boundary = shapely.Polygon(surface.trim.outer, surface.trim.holes).boundary
            distance = shapely.distance(boundary, shapely.points(uv[disagree]))
            band = TRIM_BAND * max(u1 - u0, v1 - v0)
            assert np.all(distance <= band), (k, uv[disagree][distance > band], distance.max())
        checked += len(uv)
    assert checked >= 300


def test_knots_pass_the_scene_readers_checks(part):
    from rtreflect.exchange.scene import _check_knots, _Table

    path, model, _ = part
    for surface in model.surfaces:
        table = _Table(path, "surface", {})
        nu, nv = surface.weights.shape
        _check_knots(table, "knots_u", surface.knots_u, surface.degree_u, nu)
        _check_knots(table, "knots_v", surface.knots_v, surface.degree_v, nv)
        # Clamped: the ends repeat degree + 1 times.
        assert np.all(surface.knots_u[:surface.degree_u + 1] == surface.knots_u[0])
        assert np.all(surface.knots_v[-surface.degree_v - 1:] == surface.knots_v[-1])


def test_trim_polyline_within_tolerance_of_pcurve():
    """Between samples, the polyline stays within TRIM_TOLERANCE × diagonal of the pcurve's image, measured
    at points the reader did not use (quarter points of every segment), on the curved-edge parts."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve2d
    from OCP.BRepTools import BRepTools_WireExplorer
    from OCP.TopAbs import TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    for name in ("trimmed_face.step", "revolved.step", "filleted_block.step"):
        path = PARTS / name
        model = read_cad(path)
        _, _, _, faces = occt_faces(path)
        worst = 0.0
        for surface, face in zip(model.surfaces, faces):
            loops = [surface.trim.outer, *surface.trim.holes]
            polyline = shapely.MultiLineString([np.vstack([loop, loop[:1]]) for loop in loops])
            wires = TopExp_Explorer(face, TopAbs_WIRE)
            while wires.More():
                edges = BRepTools_WireExplorer(TopoDS.Wire(wires.Current()), face)
                wires.Next()
                while edges.More():
                    curve = BRepAdaptor_Curve2d(edges.Current(), face)
                    edges.Next()
                    ts = np.linspace(curve.FirstParameter(), curve.LastParameter(), 257)
                    uv = np.array([(p.X(), p.Y()) for p in (curve.Value(float(t)) for t in ts)])
                    # Nearest polyline point in (u, v), then the model-space distance between the two images.
                    lines = shapely.shortest_line(shapely.points(uv), polyline)
                    nearest = shapely.get_coordinates(lines).reshape(-1, 2, 2)[:, 1]
                    a = surface.evaluate(uv[:, 0], uv[:, 1]).S
                    b = surface.evaluate(nearest[:, 0], nearest[:, 1]).S
                    worst = max(worst, float(np.max(np.linalg.norm(a - b, axis=1))) / model.diagonal)
        assert worst <= 1.5 * TRIM_TOLERANCE, (name, worst)


def test_3dm_surfaces_match_rhino3dm():
    rhino3dm = pytest.importorskip("rhino3dm")
    path = PARTS / "trimmed.3dm"
    model = read_cad(path)
    rhino = rhino3dm.File3dm.Read(str(path))
    faces = [face for obj in rhino.Objects for face in obj.Geometry.Faces]
    assert len(model.surfaces) == len(faces) == FACE_COUNTS["trimmed.3dm"]
    rng = np.random.default_rng(3)
    for k, (surface, face) in enumerate(zip(model.surfaces, faces)):
        reference = face.ToNurbsSurface()
        uv = inside_samples(surface, SAMPLES, rng)
        ours = surface.evaluate(uv[:, 0], uv[:, 1])
        normal = np.cross(ours.Su, ours.Sv)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        if face.OrientationIsReversed:
            normal = -normal
        assert model.reversed[k] == face.OrientationIsReversed
        for (u, v), point, n in zip(uv, ours.S, normal):
            p = reference.PointAt(float(u), float(v))
            assert np.linalg.norm(point - [p.X, p.Y, p.Z]) <= 1e-9 * model.diagonal, (k, u, v)
            m = reference.NormalAt(float(u), float(v))
            assert 1 - n @ [m.X, m.Y, m.Z] <= NORMAL_TOLERANCE, (k, u, v)
        # The trimmed area equals the face's area as Rhino's own outline gives it (the caps: π·10²; the
        # wavy plane: the polygon of its control-point outline is close, checked loosely).
    caps = [s for s in model.surfaces[2:]]
    for cap in caps:
        assert cap.trim._polygon.area == pytest.approx(np.pi * 100, rel=1e-3)


def test_mesh_uv_covers_the_trimmed_face_and_winds_with_its_normal(part):
    """The reader's (u, v) triangulation covers what the trim encloses (areas agree to 1 %, the mesh's chords
    cut the curved loops a little), and winds counter-clockwise in (u, v) unless the face is reversed."""
    path, model, _ = part
    for k, surface in enumerate(model.surfaces):
        nodes, triangles = surface.mesh_uv
        a, b, c = (nodes[triangles[:, i]] for i in range(3))
        signed = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
        expected_sign = -1.0 if model.reversed[k] else 1.0
        assert np.all(signed * expected_sign >= 0), f"face {k}: triangles wind against the face"
        assert abs(signed.sum()) == pytest.approx(surface.trim._polygon.area, rel=1e-2), f"face {k}"


def test_3dm_trims_follow_the_exact_edges():
    """The cylinder's caps are trimmed by its exact rational circles (radius 10 about (70, 0)): the trim
    loops' images lie on them to float precision, not just to ShapeFix's pcurve fit (7.6e-3 mm)."""
    pytest.importorskip("rhino3dm")
    model = read_cad(PARTS / "trimmed.3dm")
    for cap in model.surfaces[2:]:
        points = cap.evaluate(cap.trim.outer[:, 0], cap.trim.outer[:, 1]).S
        assert np.max(np.abs(np.hypot(points[:, 0] - 70, points[:, 1]) - 10)) < 1e-9


@pytest.mark.parametrize("periods", [-2.5, -1.5, -0.5, 0.5, 1.5, 2.5, -1.0, 1.0, 2.0, 1.0 + 3e-10, 1.0 - 3e-10])
def test_period_shift_puts_the_first_knot_in_the_pcurves_range(periods):
    """`occt._into_pcurves_period`: knots `Segment` left some periods on from the pcurves' first parameter lo move
    by whole periods so the first lands in [lo, lo + period) (to `PERIOD_SHIFT_SLACK`), the same side of lo whatever
    the count: half-periods too (Python's round, half to even, sent 1.5 periods to lo − ½ period and 2.5 to lo + ½),
    and a whole period off by OCCT's rounding (±3e-10 of one) lands on lo."""
    from rtreflect.exchange.occt import PERIOD_SHIFT_SLACK, _into_pcurves_period

    period, lo = 2.0 * np.pi, 0.3
    knots = lo + periods * period + np.array([0.0, 0.0, 0.0, 0.0, 1.0, 2.5, 4.0, 4.0, 4.0, 4.0])
    moved = _into_pcurves_period(knots, lo, period)
    whole = (knots[0] - moved[0]) / period
    assert abs(whole - round(whole)) < 1e-12  # by whole periods: the periodic surface's geometry kept
    assert lo - PERIOD_SHIFT_SLACK * period <= moved[0] < lo + period
    half = periods % 1.0 == 0.5
    np.testing.assert_allclose(moved[0], lo + (0.5 * period if half else 0.0), rtol=0, atol=1e-8)


@pytest.mark.parametrize("value, periods, snapped", [
    (-1.756e-9, 0, 0.0),  # union_big.step's cylinders: cut beside the knot 0, a 1.76e-9 sliver span before
    (2 * np.pi - 1.756e-9, 0, 2 * np.pi),
    (1.5, 0, 1.5),  # between knots: kept
    (2.0 + 1e-8, 0, 2.0 + 1e-8),  # beyond SIDE_SNAP of the range (1e-8 > 1e-9 · 2π): kept
    (2.0 - 5e-10, 0, 2.0),
    (-1e-9, 2, 4 * np.pi),  # two periods on: onto the knot there
    (1.5, 2, 1.5 + 4 * np.pi),
])
def test_cut_points_snap_onto_knots_within_side_snap(value, periods, snapped):
    """`occt._snap_to_knots`: a cut point within `SIDE_SNAP` of the cut's range from a knot is put on the knot (a
    periodic direction's knots moved by whole periods to it first), so `Segment` leaves no sliver knot span; farther
    points are kept."""
    from rtreflect.exchange.occt import _snap_to_knots

    period = 2 * np.pi
    knots = np.array([0.0, 2.0, 4.0, period])
    value += periods * period
    assert _snap_to_knots(value, knots, period, period) == pytest.approx(snapped, rel=0, abs=1e-12)
    if periods == 0:  # not periodic: the same knots, the same verdict
        assert _snap_to_knots(value, knots, period) == snapped


@pytest.mark.parametrize("knots, period, lo, hi, cut", [
    ([0, 1, 2, 3], 0, 0.5, 2.0000001, (0.5, 3.0)),  # 1e-7 of a span kept past the knot 2: out to 3
    ([0, 1, 2, 3], 0, 0.9999999, 2.5, (0.0, 2.5)),  # the lower cut alike: out to 0
    ([0, 1, 2], 0, 1.0001, 1.0005, (1.0001, 1.0005)),  # the whole face inside one span: no sliver beside a span
    ([0, 1, 1000], 0, 0.0, 1.0000001, (0.0, 1.0000001)),  # out to 1000 would be 999 face widths: kept
    ([0, 1, 2, 3], 0, 0.5, 3.0 - 1e-6, (0.5, 3.0 - 1e-6)),  # just short of a knot: no sliver (the span is kept whole)
    ([0, 2, 4, 6, 8], 8, 5.0, 8.0000001, (5.0, 10.0)),  # periodic: past the period's end, out to the next period's 2
    ([0, 2, 4, 6, 8], 8, 2.5, 10.0000001, (2.5, 10.0000001)),  # ... not past lo + period (10.5): kept
])
def test_a_cut_leaving_a_sliver_span_moves_out_to_the_spans_far_knot(knots, period, lo, hi, cut):
    """`occt._cut_at_knots` (`bspline_of_face`'s cut): a cut keeping less than `SLIVER_SPAN` of a knot span beyond
    a knot inside the face's range moves out to that span's far knot, within the surface's bounds (a periodic one's
    single period) and at most the range's width away; other cuts stay."""
    from rtreflect.exchange.occt import _cut_at_knots

    knots = np.array(knots, dtype=float)
    assert _cut_at_knots(lo, hi, knots, period, knots[0], knots[-1]) == pytest.approx(cut, rel=0, abs=1e-12)
