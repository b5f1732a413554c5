"""Write the shipped CAD example parts into parts/ (Open CASCADE through OCP; rhino3dm for the .3dm).

    python tools/make_parts.py            # all parts
    python tools/make_parts.py --big N    # also parts/plate_N.step with about 2N faces (benchmarks; not shipped)

Parts (millimetres):
  trimmed_face.step   one bicubic B-spline face, cut by a wavy outer boundary, with three holes
  filleted_block.step a block with every edge filleted: planes, cylinders and tori (26 faces)
  revolved.step       a vase revolved from a B-spline profile (periodic surface of revolution, poles)
  plate.step          a plate with a grid of filleted holes (a few hundred faces)
  assembly.step       an assembly: the filleted block placed twice (two located instances)
  filleted_block.igs  the filleted block again, as IGES (B-rep mode)
  trimmed.3dm         a Rhino model: a trimmed planar face and a capped cylinder (periodic, trimmed caps)
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "parts"


def _edges(shape):
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    explorer = TopExp_Explorer(shape, TopAbs_EDGE)
    while explorer.More():
        yield TopoDS.Edge(explorer.Current())
        explorer.Next()


def compound_of(*shapes):
    """The shapes as one compound (not fused: each keeps its faces)."""
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Compound

    compound = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(compound)
    for shape in shapes:
        builder.Add(compound, shape)
    return compound


def trimmed_face():
    """A wavy bicubic B-spline face; boolean cuts give it a curved outer boundary and three holes."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox, BRepPrimAPI_MakeCylinder
    from OCP.Geom import Geom_BSplineSurface
    from OCP.collections import Array1_double, Array1_int, Array2_gp_Pnt
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    n = 6
    poles = Array2_gp_Pnt(1, n, 1, n)
    for i in range(n):
        for j in range(n):
            x, y = 20.0 * i, 16.0 * j
            z = 6.0 * math.sin(0.9 * i) * math.cos(0.7 * j) + 0.02 * x
            poles.SetValue(i + 1, j + 1, gp_Pnt(x, y, z))
    knots = Array1_double(1, 4)
    mults = Array1_int(1, 4)
    for k, (value, mult) in enumerate(((0.0, 4), (0.4, 1), (0.7, 1), (1.0, 4))):
        knots.SetValue(k + 1, value)
        mults.SetValue(k + 1, mult)
    surface = Geom_BSplineSurface(poles, knots, knots, mults, mults, 3, 3)
    shape = BRepBuilderAPI_MakeFace(surface, 1e-7).Face()
    up = gp_Dir(0, 0, 1)
    for (cx, cy, r) in ((30.0, 30.0, 8.0), (62.0, 50.0, 6.0), (70.0, 20.0, 4.5)):
        tool = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(cx, cy, -50), up), r, 100).Shape()
        shape = BRepAlgoAPI_Cut(shape, tool).Shape()
    # A round bite out of one corner and a straight cut off another: the outer loop mixes edge kinds.
    shape = BRepAlgoAPI_Cut(shape, BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(100, 80, -50), up), 22, 100).Shape()).Shape()
    shape = BRepAlgoAPI_Cut(shape, BRepPrimAPI_MakeBox(gp_Pnt(-10, -10, -50), 18, 100, 100).Shape()).Shape()
    return shape


def filleted_block(size=(40.0, 30.0, 20.0), radius: float = 4.0):
    """A block (by default 40 × 30 × 20), every edge filleted (by default at 4): 6 planes, 12 cylinders, 8 sphere corners
    (26 faces)."""
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    box = BRepPrimAPI_MakeBox(*map(float, size)).Shape()
    fillet = BRepFilletAPI_MakeFillet(box)
    for edge in _edges(box):
        fillet.Add(radius, edge)
    return fillet.Shape()


def revolved():
    """A vase: a B-spline profile revolved a full turn about z (a surface of revolution with a seam), closed by a base."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeRevol
    from OCP.Geom import Geom_BSplineCurve
    from OCP.collections import Array1_double, Array1_gp_Pnt, Array1_int
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt

    profile = [(0.0, 0.0), (18.0, 0.0), (24.0, 12.0), (12.0, 30.0), (10.0, 42.0), (15.0, 55.0), (13.0, 60.0)]
    poles = Array1_gp_Pnt(1, len(profile))
    for k, (r, z) in enumerate(profile):
        poles.SetValue(k + 1, gp_Pnt(r, 0, z))
    inner = len(profile) - 4  # inner knots of a clamped uniform cubic
    knots = Array1_double(1, inner + 2)
    mults = Array1_int(1, inner + 2)
    for k in range(inner + 2):
        knots.SetValue(k + 1, k / (inner + 1))
        mults.SetValue(k + 1, 4 if k in (0, inner + 1) else 1)
    curve = Geom_BSplineCurve(poles, knots, mults, 3)
    wire = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(curve).Edge()).Wire()
    return BRepPrimAPI_MakeRevol(wire, gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 2 * math.pi).Shape()


def plate(rows: int = 10, cols: int = 10):
    """A plate with rows × cols holes whose top edges are filleted: about 2·rows·cols + 6 faces."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox, BRepPrimAPI_MakeCylinder
    from OCP.BRep import BRep_Tool
    from OCP.collections import List_TopoDS_Shape as TopTools_ListOfShape
    from OCP.TopoDS import TopoDS_Compound
    from OCP.BRep import BRep_Builder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    pitch, radius, thickness = 10.0, 3.0, 4.0
    body = BRepPrimAPI_MakeBox(gp_Pnt(0, 0, 0), cols * pitch, rows * pitch, thickness).Shape()
    tools = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(tools)
    for i in range(cols):
        for j in range(rows):
            axis = gp_Ax2(gp_Pnt((i + 0.5) * pitch, (j + 0.5) * pitch, -1), gp_Dir(0, 0, 1))
            builder.Add(tools, BRepPrimAPI_MakeCylinder(axis, radius, thickness + 2).Shape())
    cut = BRepAlgoAPI_Cut()
    arguments, cutters = TopTools_ListOfShape(), TopTools_ListOfShape()
    arguments.Append(body)
    cutters.Append(tools)
    cut.SetArguments(arguments)
    cut.SetTools(cutters)
    cut.Build()
    shape = cut.Shape()
    fillet = BRepFilletAPI_MakeFillet(shape)
    for edge in _edges(shape):  # the holes' top circles: edges at z = thickness that are not straight
        first, last = BRep_Tool.Range_s(edge)
        curve = BRep_Tool.Curve_s(edge, first, last)
        mid = curve.Value(0.5 * (first + last))
        if abs(mid.Z() - thickness) < 1e-9 and type(curve).__name__ != "Geom_Line":
            fillet.Add(0.8, edge)
    return fillet.Shape()


def write_step(shape, path: Path) -> None:
    from OCP.IFSelect import IFSelect_ReturnStatus
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    writer = STEPControl_Writer()
    writer.Transfer(shape, STEPControl_AsIs)
    if writer.Write(str(path)) != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise SystemExit(f"could not write {path}")


def write_assembly(shape, path: Path, transforms=None) -> None:
    """Located instances of one part, through an XCAF document (a real STEP assembly, not a copy): by default two,
    the second turned 30° and moved; else one per ``transforms`` (gp_Trsf)."""
    from OCP.STEPCAFControl import STEPCAFControl_Writer
    from OCP.STEPControl import STEPControl_AsIs
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDocStd import TDocStd_Document
    from OCP.TopLoc import TopLoc_Location
    from OCP.XCAFDoc import XCAFDoc_DocumentTool
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt, gp_Trsf, gp_Vec

    document = TDocStd_Document(TCollection_ExtendedString("XmlOcaf"))
    tool = XCAFDoc_DocumentTool.ShapeTool_s(document.Main())
    part = tool.AddShape(shape, False)
    assembly = tool.NewShape()
    if transforms is None:
        second = gp_Trsf()
        second.SetRotation(gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), math.radians(30))
        second.SetTranslationPart(gp_Vec(60, 10, 0))
        transforms = (gp_Trsf(), second)
    for trsf in transforms:
        tool.AddComponent(assembly, part, TopLoc_Location(trsf))
    tool.UpdateAssemblies()
    writer = STEPCAFControl_Writer()
    writer.Transfer(document, STEPControl_AsIs)
    writer.Write(str(path))


def write_iges(shape, path: Path, mode: int = 1) -> None:
    """``mode`` 1: B-rep (the default: faces mode turns cylinders into slow revolutions); 0: faces mode (trimmed
    surfaces, entity 144)."""
    from OCP.IGESControl import IGESControl_Writer

    writer = IGESControl_Writer("MM", mode)
    writer.AddShape(shape)
    writer.ComputeModel()
    if not writer.Write(str(path)):
        raise SystemExit(f"could not write {path}")


def write_3dm(path: Path) -> None:
    """A trimmed planar face (wavy closed outline) and a capped cylinder (periodic side, trimmed caps)."""
    import rhino3dm as r

    model = r.File3dm()
    model.Settings.ModelUnitSystem = r.UnitSystem.Millimeters
    outline = [r.Point3d(30 * math.cos(t) * (1 + 0.15 * math.cos(5 * t)), 20 * math.sin(t) * (1 + 0.15 * math.cos(5 * t)), 0)
               for t in [2 * math.pi * k / 40 for k in range(40)]]
    outline.append(outline[0])
    boundary = r.Curve.CreateControlPointCurve(outline, 3)
    face = r.Brep.CreateTrimmedPlane(r.Plane.WorldXY(), boundary)
    if face is None:
        raise SystemExit("rhino3dm could not build the trimmed plane")
    model.Objects.AddBrep(face)
    cylinder = r.Cylinder(r.Circle(r.Point3d(70, 0, 0), 10.0), 25.0)
    model.Objects.AddBrep(r.Brep.CreateFromCylinder(cylinder, True, True))
    if not model.Write(str(path), 7):
        raise SystemExit(f"could not write {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--big", type=int, default=0, metavar="N", help="also write parts/plate_N.step, about 2N faces")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    import sys

    sys.path.insert(0, str(ROOT))
    from rtreflect.exchange.occt import silence_messages

    silence_messages()  # the writers' transfer statistics
    block = filleted_block()
    write_step(trimmed_face(), args.out / "trimmed_face.step")
    write_step(block, args.out / "filleted_block.step")
    write_step(revolved(), args.out / "revolved.step")
    write_step(plate(), args.out / "plate.step")
    write_assembly(block, args.out / "assembly.step")
    write_iges(block, args.out / "filleted_block.igs")
    write_3dm(args.out / "trimmed.3dm")
    if args.big:
        side = max(1, round(math.sqrt(args.big)))
        write_step(plate(side, side), args.out / f"plate_{args.big}.step")
    for path in sorted(args.out.iterdir()):
        print(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: {path.stat().st_size / 1024:.0f} kB")


if __name__ == "__main__":
    main()
