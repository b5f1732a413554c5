"""Rhino ``.3dm`` reader: rhino3dm for the file, Open CASCADE to rebuild each face's trims.

rhino3dm gives each Brep face's NURBS surface (``ToNurbsSurface``: knots without the two end
knots, control points homogeneous (x·w, y·w, z·w, w)), its loops and the 3D curves of their
edges, but no 2D trim curves. Each face is therefore rebuilt in Open CASCADE from its surface
and edge curves: ``BRepBuilderAPI_MakeFace(surface, outer wire, False)`` (True would orient the
wires before any pcurve exists), inner wires added, and ``ShapeFix_Face`` computing the pcurves
(projecting the 3D edges onto the surface) and closing gaps within the model's tolerance. The
rebuilt faces then go through `occt.read_faces` like a STEP file's, their trim samples moved onto the exact 3D
edges (ShapeFix's pcurves only approximate them: 7.6e-3 mm off a 10 mm circle). Rhino's face orientation
(``OrientationIsReversed``) becomes the OCCT face's. Lengths stay in the model's unit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import SceneError
from .occt import CAD_EXTRA, CadModel, FaceError, import_ocp, read_faces

#: Rhino's unit systems by the short names the model summary uses (others are reported by their Rhino name).
UNIT_NAMES = {"Millimeters": "mm", "Centimeters": "cm", "Meters": "m", "Inches": "in", "Feet": "ft",
              "Microns": "µm", "Kilometers": "km", "None": "unitless"}
#: Gap closing tolerance when the file does not state one (Rhino's default absolute tolerance, model units).
DEFAULT_TOLERANCE = 1e-3


def _import_rhino3dm(path: Path):
    try:
        import rhino3dm
    except ImportError:
        raise SceneError(path, "", f"reading .3dm files needs rhino3dm: {CAD_EXTRA}") from None
    return rhino3dm


def _knots_and_mults(inner: list[float], degree: int):
    """OCCT knots and multiplicities from rhino's knot list (which omits one end knot at each side)."""
    from OCP.collections import Array1_double, Array1_int

    full = np.r_[inner[0], inner, inner[-1]]
    values, counts = np.unique(full, return_counts=True)
    knots, mults = Array1_double(1, len(values)), Array1_int(1, len(values))
    for k, (value, count) in enumerate(zip(values, counts)):
        knots.SetValue(k + 1, float(value))
        mults.SetValue(k + 1, int(count))
    return knots, mults


def occt_surface(surface):
    """A rhino3dm NurbsSurface as a ``Geom_BSplineSurface`` (non-periodic: `occt.bspline_of_face` clamps it)."""
    from OCP.Geom import Geom_BSplineSurface
    from OCP.collections import Array2_double, Array2_gp_Pnt
    from OCP.gp import gp_Pnt

    nu, nv = surface.Points.CountU, surface.Points.CountV
    poles, weights = Array2_gp_Pnt(1, nu, 1, nv), Array2_double(1, nu, 1, nv)
    for i in range(nu):
        for j in range(nv):
            p = surface.Points.GetControlPoint(i, j)  # homogeneous: (x·w, y·w, z·w, w)
            if not p.W > 0:
                raise FaceError(f"control point ({i}, {j}) has weight {p.W:g}; weights must be > 0")
            poles.SetValue(i + 1, j + 1, gp_Pnt(p.X / p.W, p.Y / p.W, p.Z / p.W))
            weights.SetValue(i + 1, j + 1, p.W)
    p, q = surface.OrderU - 1, surface.OrderV - 1
    uk, um = _knots_and_mults(list(surface.KnotsU), p)
    vk, vm = _knots_and_mults(list(surface.KnotsV), q)
    try:
        return Geom_BSplineSurface(poles, weights, uk, vk, um, vm, p, q, False, False)
    except Exception as exc:
        raise FaceError(f"Open CASCADE refuses its NURBS surface ({exc})") from None


def occt_curve(curve):
    """A rhino3dm NurbsCurve (an edge's 3D curve) as a ``Geom_BSplineCurve``."""
    from OCP.Geom import Geom_BSplineCurve
    from OCP.collections import Array1_double, Array1_gp_Pnt
    from OCP.gp import gp_Pnt

    n = len(curve.Points)
    poles, weights = Array1_gp_Pnt(1, n), Array1_double(1, n)
    for i in range(n):
        p = curve.Points[i]  # homogeneous, like surface control points
        poles.SetValue(i + 1, gp_Pnt(p.X / p.W, p.Y / p.W, p.Z / p.W))
        weights.SetValue(i + 1, p.W)
    knots, mults = _knots_and_mults(list(curve.Knots), curve.Order - 1)
    return Geom_BSplineCurve(poles, weights, knots, mults, curve.Order - 1, False)


def rebuild_face(brep, face, edges: dict, tolerance: float, context=None):
    """One Rhino Brep face as an OCCT face: its surface, its loops' 3D edges as wires, pcurves by ShapeFix_Face.

    ``context`` (a ``ShapeBuild_ReShape`` shared by the Brep's faces) records the edges ShapeFix replaces, so that
    applied to all the Brep's rebuilt faces it keeps one edge per Rhino edge (the Brep's topology)."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace
    from OCP.ShapeFix import ShapeFix_Face
    from OCP.TopoDS import TopoDS, TopoDS_Wire

    surface = occt_surface(face.ToNurbsSurface())
    builder = BRep_Builder()
    wires = []
    for loop in face.Loops:
        wire = TopoDS_Wire()
        builder.MakeWire(wire)
        count = 0
        for trim in loop.Trims:
            if trim.EdgeIndex < 0:  # a pole (singular trim): no 3D edge; ShapeFix adds the degenerate edge
                continue
            if trim.EdgeIndex not in edges:  # one TopoDS edge per Rhino edge: a seam is the same edge twice
                curve = occt_curve(brep.Edges[trim.EdgeIndex].ToNurbsCurve())
                made = BRepBuilderAPI_MakeEdge(curve)
                if not made.IsDone():
                    raise FaceError(f"Open CASCADE cannot make an edge of Rhino edge {trim.EdgeIndex}")
                edges[trim.EdgeIndex] = made.Edge()
            edge = edges[trim.EdgeIndex]
            builder.Add(wire, TopoDS.Edge(edge.Reversed()) if trim.IsReversed else edge)
            count += 1
        if count:
            wires.append((loop.LoopType.name == "Outer", wire))
    outer = [w for is_outer, w in wires if is_outer]
    if len(outer) != 1:
        raise FaceError(f"it has {len(outer)} outer trim loops with edges (1 expected)")
    made = BRepBuilderAPI_MakeFace(surface, outer[0], False)
    if not made.IsDone():
        raise FaceError("Open CASCADE cannot make a face from its surface and outer loop")
    for is_outer, wire in wires:
        if not is_outer:
            made.Add(wire)
    fix = ShapeFix_Face(made.Face())
    if context is not None:
        fix.SetContext(context)
    fix.SetPrecision(tolerance)
    fix.SetMaxTolerance(10 * tolerance)
    fix.Perform()
    rebuilt = fix.Face()
    if face.OrientationIsReversed:
        rebuilt = TopoDS.Face(rebuilt.Reversed())
    return rebuilt


def read_3dm(path: Path, name: str = "", skip_bad_faces: bool = False) -> CadModel:
    """Every Brep face (and bare surface) of a .3dm file as a trimmed NURBS surface.

    The Brep's topology is kept: one OCCT edge per Rhino edge, shared by the faces that use it, through one
    ``ShapeBuild_ReShape`` context per Brep (``ShapeFix_Face`` alone gives each face edges of its own), so the seam
    finder pairs .3dm faces by their shared edges as STEP faces.
    """
    rhino3dm = _import_rhino3dm(path)
    import_ocp(path, ".3dm files")
    from OCP.BRep import BRep_Builder
    from OCP.ShapeBuild import ShapeBuild_ReShape
    from OCP.TopoDS import TopoDS_Compound

    model = rhino3dm.File3dm.Read(str(path))
    if model is None:
        raise SceneError(path, "", "not a readable .3dm file (rhino3dm cannot open it): truncated, corrupt or not Rhino")
    tolerance = float(model.Settings.ModelAbsoluteTolerance) or DEFAULT_TOLERANCE
    unit_name = str(model.Settings.ModelUnitSystem).rsplit(".", 1)[-1]
    unit = UNIT_NAMES.get(unit_name, unit_name.lower())
    compound = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(compound)
    others, index, failed = {}, 0, []
    for obj in model.Objects:
        geometry = obj.Geometry
        if isinstance(geometry, rhino3dm.Extrusion):
            geometry = geometry.ToBrep(False)
        elif isinstance(geometry, rhino3dm.Surface):
            geometry = rhino3dm.Brep.CreateFromSurface(geometry)
        if not isinstance(geometry, rhino3dm.Brep):
            kind = type(obj.Geometry).__name__
            others[kind] = others.get(kind, 0) + 1
            continue
        edges: dict = {}
        context = ShapeBuild_ReShape()
        brep_faces = TopoDS_Compound()
        builder.MakeCompound(brep_faces)
        for face in geometry.Faces:
            try:
                builder.Add(brep_faces, rebuild_face(geometry, face, edges, tolerance, context))
            except FaceError as exc:
                failed.append((index, str(exc)))
            except Exception as exc:  # an OCCT exception while rebuilding: name the face
                failed.append((index, f"its trims cannot be rebuilt in Open CASCADE ({type(exc).__name__}: {exc})"))
            index += 1
        # The edges a later face's fix replaced, replaced in the faces fixed before it too: shared again.
        builder.Add(compound, context.Apply(brep_faces))
    if index == 0:
        held = ", ".join(f"{n} {k}" for k, n in sorted(others.items())) or "no objects"
        raise SceneError(path, "", f"no surfaces to render: the .3dm file holds {held}")
    if failed and not skip_bad_faces:
        face, reason = failed[0]
        raise SceneError(path, f"face {face}", f"{reason} (--skip-bad-faces renders the other faces)")
    # Face numbers in the model are the file's; the faces rebuilt are numbered apart from the failed ones.
    model_read = read_faces(path, compound, name, unit=unit, unit_note="", what=".3dm file",
                            skip_bad_faces=skip_bad_faces, trims_onto_edges=True)
    if failed:
        model_read.skipped = sorted(failed + _renumber(model_read.skipped, [f for f, _ in failed]))
        model_read.warnings = _renumber(model_read.warnings, [f for f, _ in failed])
        model_read.faces = index
    return model_read


def _renumber(skipped: list[tuple[int, str]], failed: list[int]) -> list[tuple[int, str]]:
    """(index, reason) of skipped or warned faces: indices among the rebuilt faces → indices among all of the file's faces (the failed ones left out)."""
    kept = [i for i in range(len(skipped) + len(failed) + max([s for s, _ in skipped], default=0) + 1) if i not in set(failed)]
    return [(kept[s], reason) for s, reason in skipped]
