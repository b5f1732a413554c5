"""Write a varied set of CAD parts nobody shipped, for the robustness sweep of the CAD readers (issue 12).

    python tools/make_sweep_parts.py OUTDIR        # every part below into OUTDIR (not parts/: not shipped)
    python tools/make_sweep_parts.py OUTDIR NAME…  # only those parts

Each part stresses one thing real exports contain (Open CASCADE through OCP; rhino3dm for the .3dm):
  sphere_hole.step     a sphere drilled through along x: poles, a periodic seam, two trimmed holes
  torus.step           a full torus: periodic in u and v, no trim edge at all
  cone.step            a cone with its apex (a pole at the apex) and a planar base
  shelled_box.step     a box with rounded corners shelled with BRepOffsetAPI_MakeThickSolid, its top face removed
  bottle.step          Open CASCADE's MakeBottle tutorial: fillets, a neck, threads on a cylindrical surface
  loft_hole.step       a freeform lofted face (BRepOffsetAPI_ThruSections) with a hole cut through it
  bspline_prism.step   a closed B-spline curve extruded (BRepPrimAPI_MakePrism)
  tiny_inch.step       the filleted block scaled to 0.01 mm across, written in inches
  huge_inch.step       the filleted block scaled to 10 m across, written in inches
  two_solids.step      a compound of two disjoint solids (a box and a sphere)
  reversed_face.step   one B-spline face stored with reversed orientation
  sliver.step          a box with a 1e-4-thin sliver face left by a cut
  small_fillet.step    a box with a 0.01 and a 2 fillet, beside a free edge and vertex (no surface)
  brep.igs, faces.igs  the shelled box through IGESControl_Writer, B-rep mode and faces mode
  sphere.3dm           a Rhino sphere (periodic, two poles)
  union_big.step       a cylinder fused with a sphere and a crossing cylinder (trims are intersection curves),
                       scaled to 10 m: OCCT's Segment puts two periodic faces one period past their pcurves
  union.step, union.igs  the same at 50 mm, and through IGESControl_Writer
  union_micro.step     the same at 1e-3 mm
  union_far.step       the same at 50 mm, moved to (1e5, -1e5, 1e5)
  sphere_pole_view.step  a sphere whose axis (its poles) points at the default 3/4 view's camera
  cone_apex_view.step  a cone whose apex points at the default camera
  torus_patch.step     a torus cut to 270° round and a half tube, its seam facing the camera
  revolved_seam.step   a wavy B-spline profile revolved a full turn (poles at both ends), its seam facing the camera
  loft_fillet_hole.step  a lofted solid with a through-hole whose top edge is filleted
  instances.step       the filleted block three times (one TShape, rotated locations) and a mirrored copy
  kink.step            one face of degree 3 × 7 with an interior C0 crease (a knot of multiplicity 3)
  offset_face.step     a Geom_OffsetSurface of a B-spline (not a NURBS: OCCT approximates it)
  rational_wild.step   a rational bicubic with weights from 0.05 to 20
  extrusion_holes.3dm  rhino3dm: a polyline outline extruded with two round holes (caps: trimmed planes with holes)
  rhino_mix.3dm        rhino3dm's builders: a bare rational surface, a capped cone, a revolved profile (seam and
                       poles), a pipe extrusion with a hole, a trimmed plane
Third sweep:
  loft_skin_edge_on.step  a thin wavy lofted skin (one face) seen edge-on by the 3/4 view (3° off)
  pipe_spline.step     a circle swept along a 3D spline (BRepOffsetAPI_MakePipe)
  hollow_sphere_cut.step  a sphere shell 0.1 thick with a quarter cut away: rays between the sheets
  variable_fillet.step a box whose top edges are filleted with radius 1 → 6
  torus_hole_view.step a torus whose axis points at the camera: seen through its hole
  many_holes.step, many_holes.igs  a plate with 28 holes 0.15 from its outer edges (IGES: faces mode)
  tiny_on_huge.step    a 2000 mm slab with a 0.05 cube and a 0.02-radius pin on it
  periodic_bspline.step  a face on a B-spline surface periodic in u (OCCT keeps it periodic)
  mirrored_assembly.step  the filleted block and an instance LOCATED by a mirror (determinant -1) in an XCAF assembly
Fourth sweep (what real .3dm files contain):
  blocks.3dm           block instances (InstanceReference) of a box, a sphere and a capped cylinder extrusion: rotated,
                       mirrored, scaled uniformly and not, and a nested block placed by a mirror; a loose box, a hidden
                       box, a box on a layer that is off, a mesh and a curve (`write_blocks_3dm`; `blocks_occt` builds
                       the same placed solids in Open CASCADE)
Fifth sweep (car-body, aircraft and product kinds):
  three_sided.step     a domed bicubic face with one side collapsed to a point (a degenerate edge), the point in view
  panel_fillet.step    a 2000 × 2000 gently curved B-spline panel, 30 thick, one top edge filleted at 2
  double_cone.step     one conical face running through its apex (both nappes): the apex inside the face
  offset_cylinder.step a Geom_OffsetSurface of a half cylinder (r 20, offset 5) with a round hole through it
  thin_chamfer.step    a cylinder (r 50) whose top rim is chamfered 0.05: a conical sliver 0.07 × 314
  touching_hole.step   a domed bicubic face whose round hole touches its straight outer side at one point
Sixth sweep (vertices many faces share, trims across seams, concave loops, high degrees, thin walls):
  star_apex.step       a five-pointed star drawn to an apex (ten planar faces meet there), the apex at the camera;
                       its base a non-convex ten-sided loop
  seam_hole.step       a cylinder drilled across its periodic seam: each hole's trim loop straddles the seam
  slot_plate.step      a plate with a slot 1.2 wide and 35 long cut in from one side: non-convex outer loops
  twisted_ruled.step   a degree-1 × 1 B-spline face (bilinear: a hyperbolic paraboloid), twisted 30 over 40
  rational_high.step   a rational B-spline face of degree 6 × 5, weights 0.3 to 4
  thin_wall.step       a wall 0.01 thick, 80 long and 40 high on a base: two large faces 0.01 apart, seen edge-on
  wavy_cut.step        a cylinder whose top is cut away by a wavy 13 × 13 bicubic sheet (an intersection-curve trim)
  sphere_seam_hole.step  a sphere with a pocket across its seam and a hole beside its pole
  revolved_pinch.step  an hourglass profile revolved a full turn, touching the axis at an interior point
  corner_blend.step    a box corner whose three edges are filleted at 3, 5 and 7: the vertex blend where they meet
Seventh sweep (far coordinates, exact axis views, thin and sloppy faces, sheets):
  far_away.step        the filleted block and a filleted bicubic slab moved to car coordinates (25000, -3000, 1200)
  axis_box.step        a box with filleted vertical edges, a boss along x and a hole along y: for views exactly
                       along an axis (planes edge-on, N·D = 0 exactly)
  closed_room.step     a box filleted all round, to be seen from inside (the camera in the solid)
  spindle_torus.step   half a spindle torus (major radius 8 < minor 12): a self-intersecting surface, cusps on its axis
  coincident_solids.step  two boxes and a cylinder in one compound, not fused: overlapping coplanar faces, one solid
                       through another
  long_strip.step      one bicubic face 1000 long and 0.1 wide, bent in plan and elevation (its mesh strays 1 from it)
  near_knots.step      a bicubic face with knot spans of 1e-6 in u and 1e-6 and 1e-9 in v (unmerged near-duplicates)
  high_degree_extrusion.step  a degree-8 B-spline curve extruded, and a rational quadratic profile revolved a full turn
  open_sheets.step     open sheets: a curved face with a hole seen from its back, and three sheets sharing one edge
  perforated.step      one planar face 100 × 60 with 331 round holes (trim with 331 inner loops)
  sloppy_sewn.step     four bicubic faces moved 0.02 apart and sewn at tolerance 0.05 (edges 0.04 off their faces)
  skewed_param.step    a domed bicubic face whose u speed |S_u| varies a thousandfold across it
  polygon_outline.step a planar sheet outlined by a 280-segment polygon with an 80-segment polygonal hole
  oversized_surface.step  a 40 × 30 trimmed piece (with a hole) of a bicubic surface 10,000 across, beside a box
  slit.step            two blocks 0.001 apart (not fused): a slit seen along its length, a cylinder behind it
  dense_net.step       a scanned-looking bicubic face, 48 × 48 control points with bumps, and a hole
Eighth sweep (extreme close-ups; new surface kinds):
  rational_extrusion.step  a surface of linear extrusion of a rational degree-7 curve (weights 0.2 to 6)
  periodic_trimmed.step  a RectangularTrimmedSurface of a u-periodic B-spline tube, its u window across the period's end
  touching_holes.step  a plate with two holes whose rims touch at a point, a third tangent to the second
  thin_wide.step       a wall 100 long and 1e-5 thick on a base: a 100 × 1e-5 face seen face-on
Tenth sweep:
  periodic_trimmed_box.step  periodic_trimmed's face beside a box: the whole model does not convert, the box's faces do
  extrusion_window.step  a face on a surface of linear extrusion of a periodic B-spline curve, its u window across the
                       curve's period end (Open CASCADE's NURBS conversion refuses it), beside a box
  revolution_window.step a face on a surface of revolution of a periodic B-spline profile, its v window across the
                       profile's period end (refused by the conversion likewise)
Sixteenth round (a first-hit sweep of Open CASCADE's test files against its intersector):
  turned_band.step     a whole turn of a cylinder trimmed to [π/2, 5π/2]: its converted pcurves start 0.0376 before it
Seventeenth round (a sweep of new kinds: high degrees, lofted skins, nested and scaled assemblies):
  scaled_assembly.step the filleted block and an instance LOCATED at scale 0.5 and moved (an XCAF assembly)
  wing_skin.step       a tapered, swept, twisted wing's skin lofted as ONE face through closed NACA 2412 sections: closed
                       in u, its seam on the sharp trailing edge (a crease, a wedge of ~9°)
Nineteenth round (loose exports):
  loose_seam.step      the filleted block with an r 6 hole, converted to NURBS and written with every CARTESIAN_POINT
                       moved by up to 2e-3 (seeded): its closed faces' seams left open by µm, which Open CASCADE reads
                       damaged (the hole wall's seam pcurves swing across the domain)
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

from make_parts import _edges, compound_of, filleted_block, write_assembly, write_iges, write_step  # noqa: E402


def _faces(shape):
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        yield TopoDS.Face(explorer.Current())
        explorer.Next()


def _cylinder(x, y, z, direction, radius, height):
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    return BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(x, y, z), gp_Dir(*direction)), radius, height).Shape()


def sphere_hole():
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeSphere

    sphere = BRepPrimAPI_MakeSphere(20.0).Shape()
    return BRepAlgoAPI_Cut(sphere, _cylinder(-30, 0, 0, (1, 0, 0), 6.0, 60)).Shape()


def torus():
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeTorus

    return BRepPrimAPI_MakeTorus(30.0, 8.0).Shape()


def cone():
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCone

    return BRepPrimAPI_MakeCone(15.0, 0.0, 30.0).Shape()


def shelled_box():
    """A 40 × 30 × 20 box, vertical edges filleted at 5, shelled 2 inwards with its top face removed (19 faces).

    Filleting every edge first makes OCCT's shell invalid (BRepCheck: two coincident top faces, one of
    negative area): only the vertical edges are rounded, and the result is checked.
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepOffsetAPI import BRepOffsetAPI_MakeThickSolid
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.collections import List_TopoDS_Shape

    box = BRepPrimAPI_MakeBox(40.0, 30.0, 20.0).Shape()
    fillet = BRepFilletAPI_MakeFillet(box)
    for edge in _edges(box):
        first, last = BRep_Tool.Range_s(edge)
        curve = BRep_Tool.Curve_s(edge, first, last)
        if abs(curve.Value(first).Z() - curve.Value(last).Z()) > 1.0:
            fillet.Add(5.0, edge)
    box = fillet.Shape()
    top = max(_faces(box), key=lambda f: _centre(f)[2])
    removed = List_TopoDS_Shape()
    removed.Append(top)
    maker = BRepOffsetAPI_MakeThickSolid()
    maker.MakeThickSolidByJoin(box, removed, -2.0, 1e-3)
    shell = maker.Shape()
    if not BRepCheck_Analyzer(shell).IsValid():
        raise RuntimeError("Open CASCADE's shell is not a valid solid")
    return shell


def _centre(face):
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, props)
    c = props.CentreOfMass()
    return c.X(), c.Y(), c.Z()


def bottle(width=50.0, height=70.0, thickness=30.0):
    """Open CASCADE's MakeBottle tutorial, step by step (profile, prism, fillets, neck, shell, threads)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Fuse
    from OCP.BRepBuilderAPI import (BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeWire,
                                    BRepBuilderAPI_Transform)
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepLib import BRepLib
    from OCP.BRepOffsetAPI import BRepOffsetAPI_MakeThickSolid, BRepOffsetAPI_ThruSections
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder, BRepPrimAPI_MakePrism
    from OCP.GC import GC_MakeArcOfCircle, GC_MakeSegment, GC_MakeSegment2d
    from OCP.Geom import Geom_CylindricalSurface
    from OCP.Geom2d import Geom2d_Ellipse, Geom2d_TrimmedCurve
    from OCP.TopoDS import TopoDS
    from OCP.collections import List_TopoDS_Shape
    from OCP.gp import gp_Ax1, gp_Ax2, gp_Ax2d, gp_Ax3, gp_Dir, gp_Dir2d, gp_Pnt, gp_Pnt2d, gp_Trsf, gp_Vec

    p1, p2, p3 = gp_Pnt(-width / 2, 0, 0), gp_Pnt(-width / 2, -thickness / 4, 0), gp_Pnt(0, -thickness / 2, 0)
    p4, p5 = gp_Pnt(width / 2, -thickness / 4, 0), gp_Pnt(width / 2, 0, 0)
    arc = GC_MakeArcOfCircle(p2, p3, p4).Value()
    e1 = BRepBuilderAPI_MakeEdge(GC_MakeSegment(p1, p2).Value()).Edge()
    e2 = BRepBuilderAPI_MakeEdge(arc).Edge()
    e3 = BRepBuilderAPI_MakeEdge(GC_MakeSegment(p4, p5).Value()).Edge()
    half = BRepBuilderAPI_MakeWire(e1, e2, e3).Wire()
    mirror = gp_Trsf()
    mirror.SetMirror(gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(1, 0, 0)))
    mirrored = TopoDS.Wire(BRepBuilderAPI_Transform(half, mirror).Shape())
    wire = BRepBuilderAPI_MakeWire()
    wire.Add(half)
    wire.Add(mirrored)
    face = BRepBuilderAPI_MakeFace(wire.Wire()).Face()
    body = BRepPrimAPI_MakePrism(face, gp_Vec(0, 0, height)).Shape()
    fillet = BRepFilletAPI_MakeFillet(body)
    for edge in _edges(body):
        fillet.Add(thickness / 12, edge)
    body = fillet.Shape()
    neck_radius, neck_height = thickness / 4, height / 10
    neck = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, height), gp_Dir(0, 0, 1)), neck_radius, neck_height).Shape()
    body = BRepAlgoAPI_Fuse(body, neck).Shape()
    top = max(_faces(body), key=lambda f: _centre(f)[2])
    removed = List_TopoDS_Shape()
    removed.Append(top)
    maker = BRepOffsetAPI_MakeThickSolid()
    maker.MakeThickSolidByJoin(body, removed, -thickness / 50, 1e-3)
    body = maker.Shape()
    # Threads: two ellipse arcs on two coaxial cylinders, lofted into a solid.
    axis = gp_Ax3(gp_Pnt(0, 0, height), gp_Dir(0, 0, 1))
    cyl1, cyl2 = Geom_CylindricalSurface(axis, neck_radius * 0.99), Geom_CylindricalSurface(axis, neck_radius * 1.05)
    centre, direction = gp_Pnt2d(2 * math.pi, neck_height / 2), gp_Dir2d(2 * math.pi, neck_height / 4)
    ax = gp_Ax2d(centre, direction)
    major, minor = 2 * math.pi, neck_height / 10
    ellipse1, ellipse2 = Geom2d_Ellipse(ax, major, minor), Geom2d_Ellipse(ax, major, minor / 4)
    arc1, arc2 = Geom2d_TrimmedCurve(ellipse1, 0, math.pi), Geom2d_TrimmedCurve(ellipse2, 0, math.pi)
    a, b = ellipse1.Value(0), ellipse1.Value(math.pi)
    segment = GC_MakeSegment2d(a, b).Value()
    wires = []
    for arc2d, surface in ((arc1, cyl1), (arc2, cyl2)):
        edge_arc = BRepBuilderAPI_MakeEdge(arc2d, surface).Edge()
        edge_seg = BRepBuilderAPI_MakeEdge(segment, surface).Edge()
        w = BRepBuilderAPI_MakeWire(edge_arc, edge_seg).Wire()
        BRepLib.BuildCurves3d_s(w)
        wires.append(w)
    loft = BRepOffsetAPI_ThruSections(True)
    for w in wires:
        loft.AddWire(w)
    loft.CheckCompatibility(False)
    threading = loft.Shape()
    return compound_of(body, threading)


def loft_hole():
    """A freeform face lofted through three wavy B-spline sections, then a hole cut through it."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire
    from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections
    from OCP.GeomAPI import GeomAPI_PointsToBSpline
    from OCP.collections import Array1_gp_Pnt
    from OCP.gp import gp_Pnt

    loft = BRepOffsetAPI_ThruSections(False, False)
    for k, y in enumerate((0.0, 25.0, 50.0)):
        points = Array1_gp_Pnt(1, 7)
        for i in range(7):
            x = 10.0 * i
            points.SetValue(i + 1, gp_Pnt(x, y, 5.0 * math.sin(0.8 * i + k)))
        curve = GeomAPI_PointsToBSpline(points).Curve()
        loft.AddWire(BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(curve).Edge()).Wire())
    loft.Build()
    return BRepAlgoAPI_Cut(loft.Shape(), _cylinder(30, 25, -50, (0, 0, 1), 8.0, 100)).Shape()


def bspline_prism():
    """A closed periodic B-spline curve (an interpolated blob) extruded 20 along z, with its caps."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeWire
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.GeomAPI import GeomAPI_Interpolate
    from OCP.collections import HArray1_gp_Pnt as TColgp_HArray1OfPnt
    from OCP.gp import gp_Pnt, gp_Vec

    n = 9
    points = TColgp_HArray1OfPnt(1, n)
    for k in range(n):
        t = 2 * math.pi * k / n
        r = 20.0 * (1 + 0.25 * math.cos(3 * t))
        points.SetValue(k + 1, gp_Pnt(r * math.cos(t), r * math.sin(t), 0))
    interpolate = GeomAPI_Interpolate(points, True, 1e-7)
    interpolate.Perform()
    curve = interpolate.Curve()
    wire = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(curve).Edge()).Wire()
    return BRepPrimAPI_MakePrism(BRepBuilderAPI_MakeFace(wire).Face(), gp_Vec(0, 0, 20)).Shape()


def scaled_block(size: float):
    """The filleted block (40 mm long) scaled so its long side is ``size`` mm."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Pnt, gp_Trsf

    trsf = gp_Trsf()
    trsf.SetScale(gp_Pnt(0, 0, 0), size / 40.0)
    return BRepBuilderAPI_Transform(filleted_block(), trsf, True).Shape()


def two_solids():
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox, BRepPrimAPI_MakeSphere
    from OCP.gp import gp_Pnt

    return compound_of(
        BRepPrimAPI_MakeBox(20.0, 20.0, 20.0).Shape(),
        BRepPrimAPI_MakeSphere(gp_Pnt(50, 10, 10), 10.0).Shape())


def reversed_face():
    """A bicubic dome as one face, stored reversed (its normal is -S_u × S_v)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_BSplineSurface
    from OCP.collections import Array1_double, Array1_int, Array2_gp_Pnt
    from OCP.gp import gp_Pnt

    poles = Array2_gp_Pnt(1, 4, 1, 4)
    for i in range(4):
        for j in range(4):
            z = 12.0 if (i in (1, 2) and j in (1, 2)) else 0.0
            poles.SetValue(i + 1, j + 1, gp_Pnt(15.0 * i, 15.0 * j, z))
    knots, mults = Array1_double(1, 2), Array1_int(1, 2)
    for k, value in enumerate((0.0, 1.0)):
        knots.SetValue(k + 1, value)
        mults.SetValue(k + 1, 4)
    surface = Geom_BSplineSurface(poles, knots, knots, mults, mults, 3, 3)
    return BRepBuilderAPI_MakeFace(surface, 1e-7).Face().Reversed()


def sliver():
    """A box cut by a second box offset 1e-4 from its side: a face 1e-4 wide along one edge."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    body = BRepPrimAPI_MakeBox(30.0, 20.0, 10.0).Shape()
    step = BRepPrimAPI_MakeBox(gp_Pnt(1e-4, -1, 5.0), 40.0, 30.0, 10.0).Shape()
    return BRepAlgoAPI_Cut(body, step).Shape()


def small_fillet():
    """A 100 × 60 × 40 box with one edge filleted at 0.01 (a face 10⁴ times narrower than the part) and one at 2,
    in a compound with a free edge and a free vertex (entities with no surface, to be passed over)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeVertex
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    box = BRepPrimAPI_MakeBox(100.0, 60.0, 40.0).Shape()
    fillet = BRepFilletAPI_MakeFillet(box)
    edges = list(_edges(box))
    fillet.Add(0.01, edges[0])
    fillet.Add(2.0, edges[5])
    return compound_of(
        fillet.Shape(),
        BRepBuilderAPI_MakeEdge(gp_Pnt(0, 0, 50), gp_Pnt(100, 60, 50)).Edge(),
        BRepBuilderAPI_MakeVertex(gp_Pnt(50, 50, 50)).Vertex())


def union_curved(size: float = 50.0):
    """A vertical cylinder (r 10) fused with a sphere (r 14) on its top and a crossing cylinder (r 7) along x: every
    trim between them is an intersection curve. ``size``: the cylinder's height is scaled to it (50 as built)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Fuse
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeSphere
    from OCP.gp import gp_Pnt, gp_Trsf

    shape = BRepAlgoAPI_Fuse(_cylinder(0, 0, -20, (0, 0, 1), 10.0, 40.0), BRepPrimAPI_MakeSphere(gp_Pnt(0, 0, 20), 14.0).Shape()).Shape()
    shape = BRepAlgoAPI_Fuse(shape, _cylinder(-25, 0, 0, (1, 0, 0), 7.0, 50.0)).Shape()
    if size != 50.0:
        trsf = gp_Trsf()
        trsf.SetScale(gp_Pnt(0, 0, 0), size / 50.0)
        shape = BRepBuilderAPI_Transform(shape, trsf, True).Shape()
    return shape


def _moved(shape, offset):
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Trsf, gp_Vec

    trsf = gp_Trsf()
    trsf.SetTranslation(gp_Vec(*offset))
    return BRepBuilderAPI_Transform(shape, trsf, True).Shape()


#: The default scene's 3/4 view direction (`exchange.partscene.ISO_FROM`): axes pointed at the camera.
ISO_FROM = (0.55, -1.0, 0.75)


def sphere_pole_view():
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeSphere
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    return BRepPrimAPI_MakeSphere(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(*ISO_FROM)), 20.0).Shape()


def cone_apex_view():
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCone
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    return BRepPrimAPI_MakeCone(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(*ISO_FROM)), 15.0, 0.0, 25.0).Shape()


def torus_patch():
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeTorus
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    axes = gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1), gp_Dir(ISO_FROM[0], ISO_FROM[1], 0))
    return BRepPrimAPI_MakeTorus(axes, 30.0, 10.0, -math.pi / 2, math.pi / 2, 1.5 * math.pi).Shape()


def revolved_seam():
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_Transform
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeRevol
    from OCP.GeomAPI import GeomAPI_PointsToBSpline
    from OCP.collections import Array1_gp_Pnt
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt, gp_Trsf

    radii = [0.001, 14, 9, 16, 8, 12, 0.001]
    points = Array1_gp_Pnt(1, len(radii))
    for k, r in enumerate(radii):
        points.SetValue(k + 1, gp_Pnt(float(r), 0, 6.0 * k))
    edge = BRepBuilderAPI_MakeEdge(GeomAPI_PointsToBSpline(points).Curve()).Edge()
    axis = gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1))
    turn = gp_Trsf()
    turn.SetRotation(axis, math.atan2(ISO_FROM[1], ISO_FROM[0]))  # the profile (the seam) on the camera's side
    edge = BRepBuilderAPI_Transform(edge, turn, True).Shape()
    return BRepPrimAPI_MakeRevol(edge, axis, 2 * math.pi).Shape()


def loft_fillet_hole():
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.BRep import BRep_Tool
    from OCP.GeomAPI import GeomAPI_PointsToBSpline
    from OCP.collections import Array1_gp_Pnt
    from OCP.gp import gp_Pnt, gp_Vec

    loft = BRepOffsetAPI_ThruSections(False, False)
    for k, y in enumerate((0.0, 25.0, 50.0)):
        points = Array1_gp_Pnt(1, 7)
        for i in range(7):
            points.SetValue(i + 1, gp_Pnt(10.0 * i, y, 10 + 3.0 * math.sin(0.8 * i + k)))
        loft.AddWire(BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(GeomAPI_PointsToBSpline(points).Curve()).Edge()).Wire())
    loft.Build()
    solid = BRepPrimAPI_MakePrism(next(_faces(loft.Shape())), gp_Vec(0, 0, -15)).Shape()
    solid = BRepAlgoAPI_Cut(solid, _cylinder(30, 25, -50, (0, 0, 1), 8.0, 100)).Shape()
    fillet = BRepFilletAPI_MakeFillet(solid)
    for edge in _edges(solid):  # the hole's top rim: on the r = 8 circle, above the prism's bottom
        first, last = BRep_Tool.Range_s(edge)
        p = BRep_Tool.Curve_s(edge, first, last).Value(0.5 * (first + last))
        if abs(math.hypot(p.X() - 30, p.Y() - 25) - 8.0) < 1e-3 and p.Z() > 3:
            fillet.Add(2.0, edge)
    return fillet.Shape()


def instances():
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS_Compound
    from OCP.gp import gp_Ax1, gp_Ax2, gp_Dir, gp_Pnt, gp_Trsf, gp_Vec

    block = filleted_block()
    compound = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(compound)
    builder.Add(compound, block)
    for k in (1, 2):  # repeated: the same TShape at new locations
        turn, place = gp_Trsf(), gp_Trsf()
        turn.SetRotation(gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)), 0.4 * k)
        place.SetTranslation(gp_Vec(60.0 * k, 0, 0))
        place.Multiply(turn)
        builder.Add(compound, block.Located(TopLoc_Location(place)))
    mirror = gp_Trsf()
    mirror.SetMirror(gp_Ax2(gp_Pnt(0, -30, 0), gp_Dir(0, 1, 0)))
    builder.Add(compound, BRepBuilderAPI_Transform(block, mirror, True).Shape())
    return compound


def _bspline_face(poles, degree_u: int, degree_v: int, u_knots, weights=None, v_knots=None):
    """A face on a B-spline surface through ``poles`` (nested lists of xyz): clamped, ``u_knots`` (value,
    multiplicity) pairs, v without interior knots unless ``v_knots`` (the same form) are given."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_BSplineSurface
    from OCP.collections import Array1_double, Array1_int, Array2_double, Array2_gp_Pnt
    from OCP.gp import gp_Pnt

    nu, nv = len(poles), len(poles[0])
    net = Array2_gp_Pnt(1, nu, 1, nv)
    for i in range(nu):
        for j in range(nv):
            net.SetValue(i + 1, j + 1, gp_Pnt(*poles[i][j]))

    def knots(pairs):
        values, mults = Array1_double(1, len(pairs)), Array1_int(1, len(pairs))
        for k, (value, mult) in enumerate(pairs):
            values.SetValue(k + 1, value)
            mults.SetValue(k + 1, mult)
        return values, mults

    uk, um = knots(u_knots)
    vk, vm = knots(v_knots or [(0.0, degree_v + 1), (1.0, degree_v + 1)])
    if weights is None:
        surface = Geom_BSplineSurface(net, uk, vk, um, vm, degree_u, degree_v)
    else:
        w = Array2_double(1, nu, 1, nv)
        for i in range(nu):
            for j in range(nv):
                w.SetValue(i + 1, j + 1, weights[i][j])
        surface = Geom_BSplineSurface(net, w, uk, vk, um, vm, degree_u, degree_v)
    return BRepBuilderAPI_MakeFace(surface, 1e-7).Face()


def kink():
    poles = [[(10.0 * i, 8.0 * j, 8.0 * abs(i - 3) / 3 + 3.0 * math.sin(j)) for j in range(8)] for i in range(7)]
    return _bspline_face(poles, 3, 7, [(0.0, 4), (0.5, 3), (1.0, 4)])


def offset_face():
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRep import BRep_Tool
    from OCP.Geom import Geom_OffsetSurface

    poles = [[(10.0 * i, 10.0 * j, 5.0 * math.sin(i) * math.cos(j)) for j in range(5)] for i in range(5)]
    base = BRep_Tool.Surface_s(_bspline_face(poles, 4, 4, [(0.0, 5), (1.0, 5)]))
    return BRepBuilderAPI_MakeFace(Geom_OffsetSurface(base, 3.0), 1e-7).Face()


def rational_wild():
    poles = [[(15.0 * i, 15.0 * j, 10.0 if (i, j) in ((1, 1), (2, 2)) else 0.0) for j in range(4)] for i in range(4)]
    weights = [[20.0 if (i, j) == (1, 1) else 0.05 if (i, j) == (2, 2) else 1.0 for j in range(4)] for i in range(4)]
    return _bspline_face(poles, 3, 3, [(0.0, 4), (1.0, 4)], weights)


def write_extrusion_holes_3dm(path: Path) -> None:
    import rhino3dm as r

    model = new_3dm()
    outline = r.Curve.CreateControlPointCurve([r.Point3d(40 * math.cos(t) * (1 + 0.2 * math.cos(2 * t)), 25 * math.sin(t), 0)
                                               for t in [2 * math.pi * k / 16 for k in range(17)]], 1)
    extrusion = r.Extrusion.Create(outline, 10.0, True)
    for x in (-15.0, 15.0):
        extrusion.AddInnerProfile(r.Circle(r.Point3d(x, 0, 0), 6.0).ToNurbsCurve())
    model.Objects.AddExtrusion(extrusion)
    save_3dm(model, path)


def write_step_in(shape, path: Path, unit: str) -> None:
    """A STEP file whose length unit is ``unit`` (Open CASCADE's ``write.step.unit``), e.g. "INCH"."""
    from OCP.Interface import Interface_Static

    Interface_Static.SetCVal_s("write.step.unit", unit)
    try:
        write_step(shape, path)
    finally:
        Interface_Static.SetCVal_s("write.step.unit", "MM")


def new_3dm():
    """An empty Rhino model in millimetres."""
    import rhino3dm as r

    model = r.File3dm()
    model.Settings.ModelUnitSystem = r.UnitSystem.Millimeters
    return model


def save_3dm(model, path: Path) -> None:
    if not model.Write(str(path), 7):  # 7: the Rhino 7 format
        raise SystemExit(f"could not write {path}")


def write_sphere_3dm(path: Path) -> None:
    import rhino3dm as r

    model = new_3dm()
    model.Objects.AddBrep(r.Brep.CreateFromSphere(r.Sphere(r.Point3d(0, 0, 0), 15.0)))
    save_3dm(model, path)


def write_rhino_mix_3dm(path: Path) -> None:
    """rhino3dm has no general trimmed-surface builder (no CreateTrimmedSurface): what it can make that a
    modeller exports: a bare rational freeform surface, a cone revolved from a line (apex pole, capped), a revolved profile a full turn
    (seam and a pole), a capped pipe extrusion with a hole (Extrusion: inner profile), and a trimmed plane."""
    import rhino3dm as r

    model = new_3dm()
    n = 5
    surface = r.NurbsSurface.Create(3, True, 4, 4, n, n)
    for i in range(n):
        for j in range(n):
            w = 1.0 + 0.5 * ((i + j) % 2)
            x, y, z = 10.0 * i, 10.0 * j, 6.0 * math.sin(i + 0.5 * j)
            surface.Points[i, j] = r.Point4d(x * w, y * w, z * w, w)  # homogeneous
    for knots in (surface.KnotsU, surface.KnotsV):  # rhino's list omits one end knot each side
        for k, value in enumerate([0, 0, 0, 0.3, 1, 1, 1]):
            knots[k] = value
    model.Objects.AddSurface(surface)
    line = r.Curve.CreateControlPointCurve([r.Point3d(80, 0, 0), r.Point3d(70, 0, 25)], 1)  # rhino3dm's Cone has no constructor
    model.Objects.AddBrep(r.Brep.CreateFromRevSurface(r.RevSurface.Create(line, r.Line(r.Point3d(70, 0, 0), r.Point3d(70, 0, 25)),
                                                                          0.0, 2 * math.pi), True, False))
    profile = r.Curve.CreateControlPointCurve([r.Point3d(0, 0, 0), r.Point3d(8, 0, 2), r.Point3d(10, 0, 10),
                                               r.Point3d(5, 0, 16), r.Point3d(0, 0, 18)], 3)
    profile.Translate(r.Vector3d(0, 50, 0))
    axis = r.Line(r.Point3d(0, 50, 0), r.Point3d(0, 50, 18))
    model.Objects.AddBrep(r.Brep.CreateFromRevSurface(r.RevSurface.Create(profile, axis, 0.0, 2 * math.pi), False, False))
    pipe = r.Extrusion.CreatePipeExtrusion(r.Cylinder(r.Circle(r.Point3d(70, 50, 0), 8.0), 12.0), 4.0, 8.0, True)
    model.Objects.AddExtrusion(pipe)
    outline = [r.Point3d(-30 + 12 * math.cos(t), 20 * math.sin(t) * (1 + 0.2 * math.cos(3 * t)), 0)
               for t in [2 * math.pi * k / 30 for k in range(30)]]
    outline.append(outline[0])
    model.Objects.AddBrep(r.Brep.CreateTrimmedPlane(r.Plane.WorldXY(), r.Curve.CreateControlPointCurve(outline, 3)))
    save_3dm(model, path)


# --- Third sweep (issue 12): kinds the sweeps above did not cover. ---------------------------------------------------

def _wavy_curve(points_xyz):
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire
    from OCP.GeomAPI import GeomAPI_PointsToBSpline
    from OCP.collections import Array1_gp_Pnt
    from OCP.gp import gp_Pnt

    points = Array1_gp_Pnt(1, len(points_xyz))
    for k, p in enumerate(points_xyz):
        points.SetValue(k + 1, gp_Pnt(*map(float, p)))
    return BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(GeomAPI_PointsToBSpline(points).Curve()).Edge()).Wire()


def _turned_to(shape, direction):
    """``shape`` rotated so that its z axis points along ``direction``."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.gp import gp_Ax3, gp_Dir, gp_Pnt, gp_Trsf

    trsf = gp_Trsf()
    trsf.SetTransformation(gp_Ax3(gp_Pnt(0, 0, 0), gp_Dir(*direction)), gp_Ax3())
    return BRepBuilderAPI_Transform(shape, trsf.Inverted(), True).Shape()


def loft_skin_edge_on():
    """A thin, nearly flat lofted skin (one face, ripples 0.3 on 60 × 50) turned so that the 3/4 view sees it edge-on
    (its mean plane contains the view direction, tilted 3° off it)."""
    from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections

    loft = BRepOffsetAPI_ThruSections(False, False)
    for k, y in enumerate((0.0, 12.0, 25.0, 37.0, 50.0)):
        loft.AddWire(_wavy_curve([(10.0 * i, y, 0.3 * math.sin(1.3 * i + 0.9 * k)) for i in range(7)]))
    loft.Build()
    # the skin's normal (z) perpendicular to the view, 3 degrees off: along view × (up-ish), tilted
    view = [c / math.sqrt(sum(x * x for x in ISO_FROM)) for c in ISO_FROM]
    side = (view[1], -view[0], 0.0)
    n = math.hypot(*side)
    tilt = math.radians(3.0)
    normal = tuple(math.cos(tilt) * s / n + math.sin(tilt) * v for s, v in zip(side, view))
    return _turned_to(loft.Shape(), normal)


def pipe_spline():
    """A circle (r 2) swept along an interpolated 3D spline (BRepOffsetAPI_MakePipe): a pipe that winds in x, y, z."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire
    from OCP.BRepOffsetAPI import BRepOffsetAPI_MakePipe
    from OCP.GC import GC_MakeCircle
    from OCP.GeomAPI import GeomAPI_PointsToBSpline
    from OCP.collections import Array1_gp_Pnt
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    pts = [(0, 0, 0), (10, 5, 3), (20, -4, 8), (30, 3, 2), (38, 12, -4), (45, 20, 5)]
    points = Array1_gp_Pnt(1, len(pts))
    for k, p in enumerate(pts):
        points.SetValue(k + 1, gp_Pnt(*map(float, p)))
    spine_curve = GeomAPI_PointsToBSpline(points).Curve()
    spine = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(spine_curve).Edge()).Wire()
    start, tangent = gp_Pnt(), __import__("OCP.gp", fromlist=["gp_Vec"]).gp_Vec()
    spine_curve.D1(spine_curve.FirstParameter(), start, tangent)
    circle = GC_MakeCircle(gp_Ax2(start, gp_Dir(tangent)), 2.0).Value()
    profile = BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(circle).Edge()).Wire()
    return BRepOffsetAPI_MakePipe(spine, profile).Shape()


def hollow_sphere_cut():
    """A sphere shell 0.1 thick (r 20 and 19.9), its front quarter cut away towards the 3/4 view: rays enter between
    the sheets at the cut and graze along the gap."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox, BRepPrimAPI_MakeSphere
    from OCP.gp import gp_Pnt

    shell = BRepAlgoAPI_Cut(BRepPrimAPI_MakeSphere(20.0).Shape(), BRepPrimAPI_MakeSphere(19.9).Shape()).Shape()
    return BRepAlgoAPI_Cut(shell, BRepPrimAPI_MakeBox(gp_Pnt(0, -30, 0), gp_Pnt(30, 0, 30)).Shape()).Shape()


def variable_fillet():
    """A 40 × 30 × 20 box whose four top edges are filleted with radius varying 1 → 6 along each edge."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    box = BRepPrimAPI_MakeBox(40.0, 30.0, 20.0).Shape()
    fillet = BRepFilletAPI_MakeFillet(box)
    for edge in _edges(box):
        first, last = BRep_Tool.Range_s(edge)
        curve = BRep_Tool.Curve_s(edge, first, last)
        if curve.Value(first).Z() > 19 and curve.Value(last).Z() > 19:
            fillet.Add(1.0, 6.0, edge)
    return fillet.Shape()


def torus_hole_view():
    """A full torus (R 30, r 8) whose axis points at the 3/4 view's camera: the view looks through its hole."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeTorus
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt

    return BRepPrimAPI_MakeTorus(gp_Ax2(gp_Pnt(0, 0, 0), gp_Dir(*ISO_FROM)), 30.0, 8.0).Shape()


def many_holes():
    """A 60 × 40 plate (2 thick) with 28 holes (r 1.2) whose rims pass 0.15 from the plate's outer edges: the top and
    bottom faces' trims have 28 holes crowding their outer loop."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.TopoDS import TopoDS_Compound

    tools = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(tools)
    r, gap = 1.2, 0.15
    for k in range(8):
        x = 4.0 + 7.4 * k
        builder.Add(tools, _cylinder(x, r + gap, -1, (0, 0, 1), r, 4))
        builder.Add(tools, _cylinder(x, 40 - r - gap, -1, (0, 0, 1), r, 4))
    for k in range(6):
        y = 5.0 + 6.0 * k
        builder.Add(tools, _cylinder(r + gap, y, -1, (0, 0, 1), r, 4))
        builder.Add(tools, _cylinder(60 - r - gap, y, -1, (0, 0, 1), r, 4))
    return BRepAlgoAPI_Cut(BRepPrimAPI_MakeBox(60.0, 40.0, 2.0).Shape(), tools).Shape()


def tiny_on_huge():
    """A 2000 × 2000 × 20 slab with a 0.05 cube and a 0.02-radius pin standing on its top near the middle, and a
    0.01 fillet on one slab edge: faces 10⁵ times smaller than their neighbours."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Fuse
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    slab = BRepPrimAPI_MakeBox(gp_Pnt(-1000, -1000, -20), gp_Pnt(1000, 1000, 0)).Shape()
    cube = BRepPrimAPI_MakeBox(gp_Pnt(3, 3, 0), gp_Pnt(3.05, 3.05, 0.05)).Shape()
    fused = BRepAlgoAPI_Fuse(slab, cube).Shape()
    return BRepAlgoAPI_Fuse(fused, _cylinder(-4, 2, 0, (0, 0, 1), 0.02, 0.3)).Shape()


def _periodic_tube():
    """The wavy bicubic tube surface of `periodic_bspline`: a Geom_BSplineSurface periodic in u (period 8, knots 0..8),
    v from 0 to 1 (32 along z)."""
    from OCP.Geom import Geom_BSplineSurface
    from OCP.collections import Array1_double, Array1_int, Array2_gp_Pnt
    from OCP.gp import gp_Pnt

    nu, nv = 8, 5
    net = Array2_gp_Pnt(1, nu, 1, nv)
    for i in range(nu):
        a = 2 * math.pi * i / nu
        for j in range(nv):
            r = 10.0 + 3.0 * math.sin(2 * a + j)
            net.SetValue(i + 1, j + 1, gp_Pnt(r * math.cos(a), r * math.sin(a), 8.0 * j))
    uk, um = Array1_double(1, nu + 1), Array1_int(1, nu + 1)
    for k in range(nu + 1):
        uk.SetValue(k + 1, float(k))
        um.SetValue(k + 1, 1)
    vk, vm = Array1_double(1, 2), Array1_int(1, 2)
    vk.SetValue(1, 0.0), vk.SetValue(2, 1.0)
    vm.SetValue(1, nv), vm.SetValue(2, nv)
    return Geom_BSplineSurface(net, uk, vk, um, vm, 3, nv - 1, True, False)


def periodic_bspline():
    """A tube-like face on a B-spline surface periodic in u (Geom_BSplineSurface.SetUPeriodic), wavy radius,
    bicubic; OCCT keeps it periodic through STEP."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace

    return BRepBuilderAPI_MakeFace(_periodic_tube(), 1e-7).Face()


def write_mirrored_assembly(path: Path) -> None:
    """The filleted block as a STEP assembly (XCAF) of two instances, the second LOCATED by a mirror (a transform of
    determinant -1, not a transformed copy): its faces come back turned inside out unless the reader flips them."""
    from OCP.gp import gp_Ax2, gp_Dir, gp_Pnt, gp_Trsf

    mirror = gp_Trsf()
    mirror.SetMirror(gp_Ax2(gp_Pnt(0, -25, 0), gp_Dir(0, 1, 0)))
    write_assembly(filleted_block(), path, (gp_Trsf(), mirror))


# --- Fourth sweep (issue 12): block instances, hidden objects and what is not a surface in a .3dm. -----------------

def _turn(degrees: float, axis: int) -> np.ndarray:
    """4×4 rotation by ``degrees`` about the coordinate axis ``axis`` (0: x, 1: y, 2: z) through the origin."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    i, j = [k for k in range(3) if k != axis]
    m = np.eye(4)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def _affine(linear=np.eye(3), move=(0.0, 0.0, 0.0)) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = linear, move
    return m


#: blocks.3dm's definition "part": a 10 × 5 × 3 box at the origin, a sphere (radius 3 about (16, 2.5, 1.5)) and a
#: capped cylinder extrusion (radius 2 about (-6, 2.5), height 6).
BLOCK_BOX, BLOCK_SPHERE, BLOCK_CYLINDER = ((0, 0, 0), (10, 5, 3)), ((16, 2.5, 1.5), 3.0), ((-6, 2.5, 0), 2.0, 6.0)
#: Definition "pair": "part" twice, the second turned 90° about x, moved 6 along x and lifted by 12 (the move along x
#: does not commute with the instance's mirror in x, so composing the two in the wrong order misplaces it).
BLOCK_PAIR = (np.eye(4), _affine(move=(6, 0, 12)) @ _turn(90, 0))
#: The model's instances (definition, 4×4 transform), in file order: "part" turned 30° about z and moved; mirrored in
#: the plane y = -8 (determinant -1); scaled 1.5 about the origin and moved; scaled (1, 0.6, 2) and moved (the
#: sphere becomes an ellipsoid); "pair" mirrored in the plane x = -15 (its two parts mirrored through the nesting).
BLOCK_INSTANCES = (("part", _affine(move=(32, 0, 0)) @ _turn(30, 2)),
                   ("part", _affine(np.diag([1.0, -1.0, 1.0]), (0, -16, 0))),
                   ("part", _affine(1.5 * np.eye(3), (0, 14, 0))),
                   ("part", _affine(np.diag([1.0, 0.6, 2.0]), (32, 14, 0))),
                   ("pair", _affine(np.diag([-1.0, 1.0, 1.0]), (-30, 0, 0))))
#: A box outside the blocks, and where the hidden ones are.
LOOSE_BOX = ((20, -30, 0), (28, -24, 4))


def _rhino_transform(matrix: np.ndarray):
    import rhino3dm as r

    xform = r.Transform(1.0)
    for i in range(4):
        for j in range(4):
            setattr(xform, f"M{i}{j}", float(matrix[i, j]))
    return xform


def _block_part():
    """The definition "part"'s objects in rhino3dm: a Brep box, a Brep sphere, an Extrusion cylinder."""
    import rhino3dm as r

    (lo, hi), (centre, radius), (base, cylinder_radius, height) = BLOCK_BOX, BLOCK_SPHERE, BLOCK_CYLINDER
    return (r.Brep.CreateFromBoundingBox(r.BoundingBox(r.Point3d(*lo), r.Point3d(*hi))),
            r.Brep.CreateFromSphere(r.Sphere(r.Point3d(*centre), radius)),
            r.Extrusion.Create(r.Circle(r.Point3d(*base), cylinder_radius).ToNurbsCurve(), height, True))


def _loose_box():
    import rhino3dm as r

    return r.Brep.CreateFromBoundingBox(r.BoundingBox(*(r.Point3d(*corner) for corner in LOOSE_BOX)))


def write_blocks_3dm(path: Path, exploded: bool = False, instances=BLOCK_INSTANCES) -> None:
    """blocks.3dm: ``instances`` of the definitions "part" and "pair" (nested), a loose box, and what a renderer
    leaves out: a hidden box, a box on a layer that is off, a mesh and a line. ``exploded``: the same model with each
    instance's objects transformed by rhino3dm (``Brep.Transform``, nested transforms applied inner first; flipped
    where mirrored, as Rhino's Explode leaves a solid facing out) and written as Breps, in the order of the instances.
    rhino3dm's ``Brep.Transform`` keeps a sphere a surface of revolution under a non-uniform scale (1.24 off the
    ellipsoid): exploded, only similarities are written (rotations, mirrors, uniform scales)."""
    import rhino3dm as r

    model = new_3dm()
    members = {"part": [(np.eye(4), g) for g in _block_part()]}
    members["pair"] = [(inner @ m, g) for inner in BLOCK_PAIR for m, g in members["part"]]
    if exploded:
        for name, matrix in instances:
            gram = matrix[:3, :3].T @ matrix[:3, :3]
            if not np.allclose(gram, gram[0, 0] * np.eye(3), rtol=0, atol=1e-12 * gram[0, 0]):
                raise ValueError(f"rhino3dm cannot explode a block placed by a non-similarity transform:\n{matrix}")
            for inner, geometry in members[name]:
                brep = geometry.ToBrep(False) if isinstance(geometry, r.Extrusion) else geometry.Duplicate()
                for step in ((inner, matrix) if name == "pair" else (matrix,)):
                    brep.Transform(_rhino_transform(step))
                if np.linalg.det(matrix[:3, :3] @ inner[:3, :3]) < 0:
                    brep.Flip()
                model.Objects.AddBrep(brep)
    else:
        default = r.Layer()
        default.Name = "Default"
        attributes = r.ObjectAttributes()
        attributes.LayerIndex = model.Layers.Add(default)
        part = model.InstanceDefinitions.Add("part", "", "", "", r.Point3d(0, 0, 0), _block_part(), (attributes,) * 3)
        ids = {"part": model.InstanceDefinitions.FindIndex(part).Id}
        pair = tuple(r.InstanceReference(ids["part"], _rhino_transform(m)) for m in BLOCK_PAIR)
        ids["pair"] = model.InstanceDefinitions.FindIndex(
            model.InstanceDefinitions.Add("pair", "", "", "", r.Point3d(0, 0, 0), pair, (attributes,) * 2)).Id
        for name, matrix in instances:
            model.Objects.AddInstanceObject(r.InstanceReference(ids[name], _rhino_transform(matrix)), attributes)
        hidden = r.ObjectAttributes()
        hidden.LayerIndex, hidden.Mode = attributes.LayerIndex, r.ObjectMode.Hidden
        model.Objects.AddBrep(_loose_box(), hidden)
        off = r.Layer()
        off.Name, off.Visible = "off", False
        on_off = r.ObjectAttributes()
        on_off.LayerIndex = model.Layers.Add(off)
        model.Objects.AddBrep(_loose_box(), on_off)
        mesh = r.Mesh()
        for x, y in ((0, -30), (8, -30), (0, -24)):
            mesh.Vertices.Add(x, y, 0)
        mesh.Faces.AddFace(0, 1, 2)
        model.Objects.AddMesh(mesh)
        model.Objects.AddCurve(r.LineCurve(r.Point3d(0, -30, 0), r.Point3d(8, -24, 4)))
    model.Objects.AddBrep(_loose_box())
    save_3dm(model, path)


def blocks_occt():
    """blocks.3dm's visible solids built in Open CASCADE from the same numbers (primitives, each placed by its composed
    4×4 transform through ``BRepBuilderAPI_GTransform``): the reference for its first hits."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_GTransform
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox, BRepPrimAPI_MakeSphere
    from OCP.gp import gp_GTrsf, gp_Mat, gp_Pnt, gp_XYZ
    from OCP.TopoDS import TopoDS_Compound

    (lo, hi), (centre, radius), (base, cylinder_radius, height) = BLOCK_BOX, BLOCK_SPHERE, BLOCK_CYLINDER
    part = [BRepPrimAPI_MakeBox(gp_Pnt(*lo), gp_Pnt(*hi)).Shape(),
            BRepPrimAPI_MakeSphere(gp_Pnt(*centre), radius).Shape(),
            _cylinder(*base, (0, 0, 1), cylinder_radius, height)]
    placements = {"part": [np.eye(4)], "pair": list(BLOCK_PAIR)}
    compound = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(compound)
    for name, matrix in BLOCK_INSTANCES:
        for inner in placements[name]:
            m = matrix @ inner
            trsf = gp_GTrsf(gp_Mat(*m[:3, :3].ravel()), gp_XYZ(*m[:3, 3]))
            for shape in part:
                builder.Add(compound, BRepBuilderAPI_GTransform(shape, trsf, True).Shape())
    builder.Add(compound, BRepPrimAPI_MakeBox(*(gp_Pnt(*corner) for corner in LOOSE_BOX)).Shape())
    return compound



# --- Fifth sweep (issue 12): what car-body, aircraft and product parts have that the sweeps above lack. -------------

def three_sided():
    """A bicubic B-spline face whose u = 0 row of poles is one point (a degenerate edge: a three-sided patch, as car
    bodies close a corner), domed, its collapsed corner towards the 3/4 view's camera."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRep import BRep_Tool

    back = math.atan2(-ISO_FROM[1], -ISO_FROM[0])  # the fan opens away from the camera
    poles = [[(0.0, 0.0, 0.0)] * 4]
    for i in (1, 2, 3):
        row = []
        for j in range(4):
            a = back + math.radians(-35.0 + 70.0 * j / 3)
            r = 15.0 * i
            row.append((r * math.cos(a), r * math.sin(a), 6.0 * math.sin(i) * (1.2 if j in (1, 2) else 0.4)))
        poles.append(row)
    face = _bspline_face(poles, 3, 3, [(0.0, 4), (1.0, 4)])
    return BRepBuilderAPI_MakeFace(BRep_Tool.Surface_s(face), 1e-7).Face()


#: panel_fillet.step: the panel's size, and the radius of the fillet along one of its top edges.
PANEL_SIZE, PANEL_FILLET = 2000.0, 2.0


def panel_fillet():
    """A 2000 × 2000 B-spline panel sagging 60 (a roof, a wing skin), 30 thick (its top face extruded down), one top
    edge filleted at 2: a face a thousand times narrower than the part."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Vec

    half = PANEL_SIZE / 2
    poles = [[(-half + PANEL_SIZE * i / 3, -half + PANEL_SIZE * j / 3, 60.0 * (i in (1, 2)) + 25.0 * (j in (1, 2)))
              for j in range(4)] for i in range(4)]
    solid = BRepPrimAPI_MakePrism(_bspline_face(poles, 3, 3, [(0.0, 4), (1.0, 4)]), gp_Vec(0, 0, -30)).Shape()
    fillet = BRepFilletAPI_MakeFillet(solid)
    for edge in _edges(solid):  # the top face's edge along y = -half
        first, last = BRep_Tool.Range_s(edge)
        curve = BRep_Tool.Curve_s(edge, first, last)
        a, b = curve.Value(first), curve.Value(last)
        if abs(a.Y() + half) < 1e-6 and abs(b.Y() + half) < 1e-6 and min(a.Z(), b.Z()) > -1.0:
            fillet.Add(PANEL_FILLET, edge)
    return fillet.Shape()


def double_cone():
    """A conical face (semi-angle 30°) running through its apex: v from 20 before it to 15 past it, 270° round, so the
    apex lies inside the face (both nappes, one face), its axis across the 3/4 view."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_ConicalSurface
    from OCP.gp import gp_Ax3, gp_Dir, gp_Pnt

    # gp_Cone: radius 10 at v = 0, the apex at v = -10 / sin 30° = -20
    surface = Geom_ConicalSurface(gp_Ax3(gp_Pnt(0, 0, 0), gp_Dir(1, 1, 0), gp_Dir(0, 0, 1)), math.radians(30.0), 10.0)
    return BRepBuilderAPI_MakeFace(surface, 0.0, 1.5 * math.pi, -40.0, -5.0, 1e-7).Face()


def offset_cylinder():
    """A half cylinder (r 20, 40 long) offset by 5 as a Geom_OffsetSurface face, with a round hole cut through it."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_CylindricalSurface, Geom_OffsetSurface
    from OCP.gp import gp_Ax3

    surface = Geom_OffsetSurface(Geom_CylindricalSurface(gp_Ax3(), 20.0), 5.0)
    face = BRepBuilderAPI_MakeFace(surface, 0.0, math.pi, 0.0, 40.0, 1e-7).Face()
    return BRepAlgoAPI_Cut(face, _cylinder(0, -50, 20, (0, 1, 0), 6.0, 100)).Shape()


def thin_chamfer():
    """A cylinder (r 50, 30 high) whose top rim is chamfered 0.05: a conical sliver 0.07 wide and 314 long between
    the large cap and side."""
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeChamfer
    from OCP.BRep import BRep_Tool

    body = _cylinder(0, 0, 0, (0, 0, 1), 50.0, 30.0)
    chamfer = BRepFilletAPI_MakeChamfer(body)
    for edge in _edges(body):
        first, last = BRep_Tool.Range_s(edge)
        curve = BRep_Tool.Curve_s(edge, first, last)
        if curve is not None and abs(curve.Value(first).Z() - 30.0) < 1e-9 and abs(curve.Value(last).Z() - 30.0) < 1e-9:
            chamfer.Add(0.05, edge)
    return chamfer.Shape()


def touching_hole():
    """A domed bicubic face with a round hole (r 8) whose rim touches the face's straight side y = 0 at one point
    (a vertical cylinder tangent to that side's plane): the outer trim touches itself there."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut

    poles = [[(15.0 * i, 15.0 * j, 10.0 if (i in (1, 2) and j in (1, 2)) else 0.0) for j in range(4)] for i in range(4)]
    face = _bspline_face(poles, 3, 3, [(0.0, 4), (1.0, 4)])
    return BRepAlgoAPI_Cut(face, _cylinder(22.5, 8.0, -20, (0, 0, 1), 8.0, 60)).Shape()


# --- Sixth sweep (issue 12): vertices where many faces meet, seams crossed by trims, concave loops, high degrees. --

def star_apex():
    """A five-pointed star (outer radius 25, inner 10) drawn to an apex 20 above it: ten planar faces meet at the
    apex, which points at the 3/4 view's camera, and the base is a non-convex ten-sided loop."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakePolygon, BRepBuilderAPI_MakeVertex, BRepBuilderAPI_Transform
    from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt, gp_Trsf

    polygon = BRepBuilderAPI_MakePolygon()
    for k in range(10):
        a, r = math.pi / 2 + math.pi * k / 5, 25.0 if k % 2 == 0 else 10.0
        polygon.Add(gp_Pnt(r * math.cos(a), r * math.sin(a), 0.0))
    polygon.Close()
    loft = BRepOffsetAPI_ThruSections(True, True)
    loft.AddWire(polygon.Wire())
    loft.AddVertex(BRepBuilderAPI_MakeVertex(gp_Pnt(0, 0, 20.0)).Vertex())
    loft.Build()
    tilt = gp_Trsf()  # the apex's axis z turned towards the camera
    towards = np.array(ISO_FROM) / np.linalg.norm(ISO_FROM)
    tilt.SetRotation(gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(*np.cross((0.0, 0.0, 1.0), towards))), math.acos(towards[2]))
    return BRepBuilderAPI_Transform(loft.Shape(), tilt, True).Shape()


def seam_hole():
    """A cylinder (r 20, 50 high; its seam at angle 0, x > 0) drilled through along x at mid-height by an r 6 hole:
    each hole's trim loop straddles the lateral face's periodic seam (and the seam edge is split by it)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut

    return BRepAlgoAPI_Cut(_cylinder(0, 0, 0, (0, 0, 1), 20.0, 50.0), _cylinder(-40, 0, 25, (1, 0, 0), 6.0, 80)).Shape()


def slot_plate():
    """A 60 × 40 × 4 plate with a slot 1.2 wide and 35 long cut in from one side, its end round: the top and bottom
    faces' outer loops are non-convex, with a narrow re-entrant bay."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut, BRepAlgoAPI_Fuse
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    plate = BRepPrimAPI_MakeBox(gp_Pnt(0, 0, 0), gp_Pnt(60, 40, 4)).Shape()
    slot = BRepPrimAPI_MakeBox(gp_Pnt(-1, 19.4, -1), gp_Pnt(35, 20.6, 5)).Shape()
    slot = BRepAlgoAPI_Fuse(slot, _cylinder(35, 20, -1, (0, 0, 1), 0.6, 6)).Shape()
    return BRepAlgoAPI_Cut(plate, slot).Shape()


def twisted_ruled():
    """A degree-1 × 1 B-spline face (a bilinear patch, a hyperbolic paraboloid): its straight sides 40 long twisted
    by 30 between the ends."""
    poles = [[(0.0, 0.0, 0.0), (0.0, 40.0, 30.0)], [(40.0, 0.0, 30.0), (40.0, 40.0, 0.0)]]
    return _bspline_face(poles, 1, 1, [(0.0, 2), (1.0, 2)])


def rational_high():
    """A rational B-spline face of degree 6 × 5 (one span), its poles a wavy 7 × 6 net, weights from 0.3 to 4."""
    poles = [[(8.0 * i, 8.0 * j, 6.0 * math.sin(1.1 * i) * math.cos(0.9 * j) + 0.5 * i * j) for j in range(6)]
             for i in range(7)]
    weights = [[0.3 + 3.7 * ((3 * i + 5 * j) % 7) / 6 for j in range(6)] for i in range(7)]
    return _bspline_face(poles, 6, 5, [(0.0, 7), (1.0, 7)], weights)


def thin_wall():
    """A wall 0.01 thick, 80 long and 40 high on a 100 × 60 × 5 base: two large faces 0.01 apart, its top a strip
    0.01 wide, standing across the 3/4 view."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Fuse
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    base = BRepPrimAPI_MakeBox(gp_Pnt(0, 0, 0), gp_Pnt(100, 60, 5)).Shape()
    wall = BRepPrimAPI_MakeBox(gp_Pnt(10, 30, 5), gp_Pnt(90, 30.01, 45)).Shape()
    return BRepAlgoAPI_Fuse(base, wall).Shape()


def wavy_cut():
    """A cylinder (r 15, 40 high) whose top is cut away by a wavy bicubic B-spline sheet (six waves across it): the
    cut face is a trimmed B-spline with an intersection-curve loop, the side face's top trim many short edges."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Vec

    n = 13
    poles = [[(-20.0 + 40.0 * i / (n - 1), -20.0 + 40.0 * j / (n - 1),
               30.0 + 3.0 * math.sin(1.7 * i) + 2.0 * math.cos(1.3 * j)) for j in range(n)] for i in range(n)]
    knots = [(0.0, 4)] + [(k / (n - 3), 1) for k in range(1, n - 3)] + [(1.0, 4)]
    sheet = _bspline_face(poles, 3, 3, knots, v_knots=knots)
    cutter = BRepPrimAPI_MakePrism(sheet, gp_Vec(0, 0, 30)).Shape()
    return BRepAlgoAPI_Cut(_cylinder(0, 0, 0, (0, 0, 1), 15.0, 40.0), cutter).Shape()


def sphere_seam_hole():
    """A sphere (r 20) with two holes: an r 5 hole drilled through along x across its seam (the seam at angle 0,
    x > 0), and an r 4 hole along z offset 5 from the axis, beside the pole (the pole's point left on the face)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeSphere

    sphere = BRepPrimAPI_MakeSphere(20.0).Shape()
    sphere = BRepAlgoAPI_Cut(sphere, _cylinder(0, 0, 0, (1, 0, 0), 5.0, 30)).Shape()
    return BRepAlgoAPI_Cut(sphere, _cylinder(0, 9.5, 0, (0, 0, 1), 4.0, 30)).Shape()


def revolved_pinch():
    """An hourglass profile revolved a full turn, touching the axis at an interior point (radius 0 at z = 15; ends discs
    of radius 12 and 10 left open): two faces of revolution meeting at one point on the axis (each with a pole
    there), their seam facing the 3/4 view's camera. (Open CASCADE will not revolve one edge through the axis.)"""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire, BRepBuilderAPI_Transform
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeRevol
    from OCP.GeomAPI import GeomAPI_PointsToBSpline
    from OCP.collections import Array1_gp_Pnt
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt, gp_Trsf

    def profile(xz):
        points = Array1_gp_Pnt(1, len(xz))
        for k, (x, z) in enumerate(xz):
            points.SetValue(k + 1, gp_Pnt(x, 0.0, z))
        return BRepBuilderAPI_MakeEdge(GeomAPI_PointsToBSpline(points).Curve()).Edge()

    wire = BRepBuilderAPI_MakeWire(profile([(12.0, 0.0), (11.0, 5.0), (6.0, 11.0), (0.0, 15.0)]),
                                   profile([(0.0, 15.0), (5.0, 19.0), (9.0, 25.0), (10.0, 30.0)])).Wire()
    axis = gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1))
    turn = gp_Trsf()
    turn.SetRotation(axis, math.atan2(ISO_FROM[1], ISO_FROM[0]))
    wire = BRepBuilderAPI_Transform(wire, turn, True).Shape()
    return BRepPrimAPI_MakeRevol(wire, axis, 2 * math.pi).Shape()


def corner_blend():
    """A 40 × 30 × 20 box whose three edges at the corner facing the 3/4 view's camera are filleted at 3, 5 and 7:
    three fillets of unequal radius and the blend Open CASCADE builds where they meet (a vertex blend)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    box = BRepPrimAPI_MakeBox(40.0, 30.0, 20.0).Shape()
    fillet = BRepFilletAPI_MakeFillet(box)
    corner = np.array([40.0, 0.0, 20.0])
    for edge in _edges(box):
        first, last = BRep_Tool.Range_s(edge)
        curve = BRep_Tool.Curve_s(edge, first, last)
        ends = [np.array([p.X(), p.Y(), p.Z()]) for p in (curve.Value(first), curve.Value(last))]
        if any(np.allclose(e, corner) for e in ends):
            along = int(np.argmax(np.abs(ends[1] - ends[0])))
            fillet.Add((3.0, 5.0, 7.0)[along], edge)
    return fillet.Shape()


# -- seventh sweep ------------------------------------------------------------------------------------------------


#: Where `far_away` puts its parts: a car body's rear corner in vehicle coordinates (mm).
FAR_OFFSET = (25000.0, -3000.0, 1200.0)


def far_away():
    """The filleted block and a small bicubic slab (a curved B-spline face extruded 6) with a 0.5 fillet on its top
    edge along y = 0 and the two vertical edges at its ends, moved to car coordinates (25000, -3000, 1200): float32
    resolution there is ~0.002."""
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.gp import gp_Vec

    n = 5
    poles = [[(50.0 + 5.0 * i, 5.0 * j, 1.5 * math.sin(i) * math.cos(0.8 * j)) for j in range(n)] for i in range(n)]
    knots = [(0.0, 4), (0.5, 1), (1.0, 4)]
    sheet = _bspline_face(poles, 3, 3, knots, v_knots=knots)
    slab = BRepPrimAPI_MakePrism(sheet, gp_Vec(0, 0, 6)).Shape()
    fillet = BRepFilletAPI_MakeFillet(slab)
    for edge in _edges(slab):  # the curved top face's edge along y = 0 and its two vertical neighbours
        ends = _edge_ends(edge)
        if max(abs(ends[0][1]), abs(ends[1][1])) < 1e-6 and (ends[0][2] > 3 or ends[1][2] > 3):
            fillet.Add(0.5, edge)
    return _moved(compound_of(filleted_block(), fillet.Shape()), FAR_OFFSET)


def axis_box():
    """A 40 × 30 × 20 box whose four vertical edges are filleted at 5, with a cylinder boss (r 6, along +x) on its +x
    face and a round hole (r 4) along y: seen exactly along an axis its planes are edge-on (N·D = 0 exactly)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut, BRepAlgoAPI_Fuse
    from OCP.BRepFilletAPI import BRepFilletAPI_MakeFillet
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    box = BRepPrimAPI_MakeBox(40.0, 30.0, 20.0).Shape()
    fillet = BRepFilletAPI_MakeFillet(box)
    for edge in _edges(box):
        first, last = _edge_ends(edge)
        if abs(last[2] - first[2]) > 1.0:
            fillet.Add(5.0, edge)
    shape = BRepAlgoAPI_Fuse(fillet.Shape(), _cylinder(40, 15, 10, (1, 0, 0), 6.0, 10.0)).Shape()
    return BRepAlgoAPI_Cut(shape, _cylinder(20, -5, 10, (0, 1, 0), 4.0, 40.0)).Shape()


def _edge_ends(edge):
    """The two end points (numpy) of an ``edge``'s 3D curve."""
    from OCP.BRep import BRep_Tool

    first, last = BRep_Tool.Range_s(edge)
    curve = BRep_Tool.Curve_s(edge, first, last)
    return [np.array([p.X(), p.Y(), p.Z()]) for p in (curve.Value(first), curve.Value(last))]


def closed_room():
    """A 60 × 50 × 30 box with every edge filleted at 6, meant to be seen from inside (the camera in the solid): the
    rays leave through the back of every face."""
    return filleted_block((60.0, 50.0, 30.0), 6.0)


def spindle_torus():
    """One face on a spindle torus (major radius 8, minor 12: the surface passes through itself twice along its axis),
    half of it in u (0 to π), the whole tube in v: a self-intersecting surface, two cusps on the axis."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_ToroidalSurface
    from OCP.gp import gp_Ax3

    surface = Geom_ToroidalSurface(gp_Ax3(), 8.0, 12.0)
    return BRepBuilderAPI_MakeFace(surface, 0.0, math.pi, 0.0, 2 * math.pi, 1e-7).Face()


def coincident_solids():
    """Three solids in one compound, not fused: two boxes sharing part of a face (coplanar, overlapping: z = 10 for
    both, the upper one shifted) and a cylinder driven through the lower box."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    return compound_of(
        BRepPrimAPI_MakeBox(gp_Pnt(0, 0, 0), gp_Pnt(40, 30, 10)).Shape(),
        BRepPrimAPI_MakeBox(gp_Pnt(10, 8, 10), gp_Pnt(50, 40, 22)).Shape(),
        _cylinder(-10, 15, 5, (1, 0, 0), 4.0, 60.0))


def long_strip():
    """A bicubic strip 1000 long and 0.1 wide, bent in an S along its length and twisted: one B-spline face of aspect
    10⁴."""
    n = 12
    poles = []
    for i in range(n):
        x = 1000.0 * i / (n - 1)
        twist = 0.6 * math.sin(2 * math.pi * i / (n - 1))
        row = []
        for j in range(4):
            w = 0.1 * (j / 3 - 0.5)
            row.append((x, 60.0 * math.sin(2 * math.pi * x / 1000) + w * math.cos(twist), w * math.sin(twist)
                        + 20.0 * math.sin(math.pi * x / 1000)))
        poles.append(row)
    knots = [(0.0, 4)] + [(k / (n - 3), 1) for k in range(1, n - 3)] + [(1.0, 4)]
    return _bspline_face(poles, 3, 3, knots)


def near_knots():
    """A domed bicubic face whose u knot vector holds a span 1e-6 long (knots 0.5 and 0.500001) and whose v knots
    hold two spans of 1e-6 and 1e-9 (a CAD export's unmerged near-duplicate knots)."""
    poles = [[(4.0 * i, 4.0 * j, 3.0 * math.sin(0.5 * i) + 2.0 * math.cos(0.6 * j) + (1.5 if i == 3 else 0.0))
              for j in range(8)] for i in range(7)]
    u = [(0.0, 4), (0.25, 1), (0.5, 1), (0.500001, 1), (1.0, 4)]
    v = [(0.0, 4), (0.3, 1), (0.300001, 1), (0.7, 1), (0.700000001, 1), (1.0, 4)]
    return _bspline_face(poles, 3, 3, u, v_knots=v)


def high_degree_extrusion():
    """A closed-looking degree-8 B-spline curve (13 poles) extruded 25 along z, and beside it a rational quadratic
    curve (a quarter ellipse and a conic arc, weights 0.5 to 2) revolved a full turn about z."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism, BRepPrimAPI_MakeRevol
    from OCP.Geom import Geom_BSplineCurve
    from OCP.collections import Array1_double, Array1_gp_Pnt, Array1_int
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt, gp_Vec

    def curve(points, degree, knots, mults, weights=None):
        poles = Array1_gp_Pnt(1, len(points))
        for k, p in enumerate(points):
            poles.SetValue(k + 1, gp_Pnt(*p))
        kv, mv = Array1_double(1, len(knots)), Array1_int(1, len(knots))
        for k, (value, mult) in enumerate(zip(knots, mults)):
            kv.SetValue(k + 1, value)
            mv.SetValue(k + 1, mult)
        if weights is None:
            return Geom_BSplineCurve(poles, kv, mv, degree)
        w = Array1_double(1, len(weights))
        for k, value in enumerate(weights):
            w.SetValue(k + 1, value)
        return Geom_BSplineCurve(poles, w, kv, mv, degree)

    m = 13
    ring = [(15.0 * math.cos(2 * math.pi * k / m) * (1 + 0.3 * math.sin(3 * 2 * math.pi * k / m)),
             15.0 * math.sin(2 * math.pi * k / m) * (1 + 0.3 * math.sin(3 * 2 * math.pi * k / m)), 0.0)
            for k in range(m)]
    wavy = curve(ring, 8, [0.0, 0.5, 1.0], [9, 4, 9])
    prism = BRepPrimAPI_MakePrism(BRepBuilderAPI_MakeEdge(wavy).Edge(), gp_Vec(0, 0, 25)).Shape()
    conic = curve([(50.0, 0, 0), (62.0, 0, 0), (62.0, 0, 10), (55.0, 0, 20), (48.0, 0, 28)], 2,
                  [0.0, 0.5, 1.0], [3, 2, 3], weights=[1.0, 0.5, 1.0, 2.0, 1.0])
    axis = gp_Ax1(gp_Pnt(40.0, 0, 0), gp_Dir(0, 0, 1))
    revolved = BRepPrimAPI_MakeRevol(BRepBuilderAPI_MakeEdge(conic).Edge(), axis, 2 * math.pi).Shape()
    return compound_of(prism, revolved)


def open_sheets():
    """Open sheets, no solid: a curved bicubic sheet with a round hole whose back faces the 3/4 view's camera, and a
    non-manifold compound of three planar sheets sharing one edge (a T: 0°, 120°, 240°) beside it."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakePolygon, BRepBuilderAPI_Sewing
    from OCP.gp import gp_Pnt

    n = 5
    poles = [[(5.0 * i, 5.0 * j, 4.0 * math.sin(0.7 * i) * math.cos(0.5 * j)) for j in range(n)] for i in range(n)]
    sheet = _bspline_face(poles, 3, 3, [(0.0, 4), (0.5, 1), (1.0, 4)], v_knots=[(0.0, 4), (0.5, 1), (1.0, 4)])
    # face the sheet's back (its normal is -z-ish after the reversal) up to the camera
    sheet = BRepAlgoAPI_Cut(sheet, _cylinder(10, 10, -20, (0, 0, 1), 3.0, 40.0)).Shape()
    sheet = sheet.Reversed()
    sewing = BRepBuilderAPI_Sewing(1e-6, True, True, True, True)  # non-manifold mode
    for angle in (0.0, 120.0, 240.0):
        a = math.radians(angle)
        corners = [(40.0, 10.0, 0.0), (40.0, 10.0, 20.0),
                   (40.0 + 15 * math.cos(a), 10.0 + 15 * math.sin(a), 20.0),
                   (40.0 + 15 * math.cos(a), 10.0 + 15 * math.sin(a), 0.0)]
        poly = BRepBuilderAPI_MakePolygon()
        for c in corners:
            poly.Add(gp_Pnt(*c))
        poly.Close()
        sewing.Add(BRepBuilderAPI_MakeFace(poly.Wire(), True).Face())
    sewing.Perform()
    return compound_of(sheet, sewing.SewedShape())


def perforated():
    """A 100 × 60 perforated sheet (one planar face, no thickness) with 17 rows of round holes (r 1, pitch 5, alternate
    rows shifted by half a pitch, 331 holes): one trim with 331 inner loops."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeWire
    from OCP.gp import gp_Ax2, gp_Circ, gp_Dir, gp_Pln, gp_Pnt

    maker = BRepBuilderAPI_MakeFace(gp_Pln(), 0.0, 100.0, 0.0, 60.0)
    for row in range(17):
        for col in range(20):
            x = 3.0 + 5.0 * col + (2.5 if row % 2 else 0.0)
            if x > 97.0:
                continue
            circle = gp_Circ(gp_Ax2(gp_Pnt(x, 2.5 + 3.5 * row, 0.0), gp_Dir(0, 0, -1)), 1.0)
            maker.Add(BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(circle).Edge()).Wire())
    from OCP.ShapeFix import ShapeFix_Face

    fix = ShapeFix_Face(maker.Face())
    fix.Perform()
    return fix.Face()


def sloppy_sewn():
    """A bicubic dome cut into four faces whose shared edges were moved apart by up to 0.02 before sewing with tolerance
    0.05 (a typical export's gaps): the sewn shell's edges carry tolerances far above their faces' precision."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Sewing

    sewing = BRepBuilderAPI_Sewing(0.05)
    for a in range(2):
        for b in range(2):
            n = 4
            def z(x, y):
                return 8.0 - 0.004 * ((x - 20) ** 2 + (y - 20) ** 2)
            jitter = 0.02 * (1 if (a + b) % 2 else -1)
            poles = [[(20.0 * a + 20.0 * i / (n - 1), 20.0 * b + 20.0 * j / (n - 1),
                       z(20.0 * a + 20.0 * i / (n - 1), 20.0 * b + 20.0 * j / (n - 1)) + jitter) for j in range(n)]
                     for i in range(n)]
            sewing.Add(_bspline_face(poles, 3, 3, [(0.0, 4), (1.0, 4)]))
    sewing.Perform()
    return sewing.SewedShape()


def skewed_param():
    """A domed bicubic face whose u parametrization is squeezed a thousandfold at one side: its control points' u
    spacing grows geometrically (×2.2 a row, 0.004 to 16), so |S_u| varies ~10³ across the domain."""
    n = 10
    xs = np.cumsum([0.0] + [0.004 * 2.2 ** k for k in range(n - 1)])
    xs = 40.0 * xs / xs[-1]
    poles = [[(float(x), 5.0 * j, 4.0 * math.sin(x / 8.0) * math.cos(0.4 * j)) for j in range(6)] for x in xs]
    knots = [(0.0, 4)] + [(k / (n - 3), 1) for k in range(1, n - 3)] + [(1.0, 4)]
    return _bspline_face(poles, 3, 3, knots, v_knots=[(0.0, 4), (1 / 3, 1), (2 / 3, 1), (1.0, 4)])


def polygon_outline():
    """A planar sheet whose outline is a 280-segment polygon (a wavy closed curve sampled as a scanned or tessellated
    export's boundary) with an 80-segment polygonal hole: one face trimmed by 360 straight edges."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakePolygon
    from OCP.gp import gp_Pnt

    def polygon(count, radius, wave, centre=(0.0, 0.0)):
        poly = BRepBuilderAPI_MakePolygon()
        for k in range(count):
            a = 2 * math.pi * k / count
            r = radius * (1.0 + wave * math.sin(7 * a))
            poly.Add(gp_Pnt(centre[0] + r * math.cos(a), centre[1] + r * math.sin(a), 0.0))
        poly.Close()
        return poly.Wire()

    maker = BRepBuilderAPI_MakeFace(polygon(280, 40.0, 0.08), True)
    hole = polygon(80, 8.0, 0.15, (10.0, 5.0))
    hole.Reverse()
    maker.Add(hole)
    return maker.Face()


def oversized_surface():
    """A small trimmed piece (40 × 30, with a round hole) of a bicubic surface 10,000 × 10,000 across (a surface
    extended far past its trim before it was cut, as some exports keep it), beside a 40 × 30 × 20 box: the surface's
    control points span 250 times the part."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Common, BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    n = 6
    poles = [[(-5000.0 + 2000.0 * i, -5000.0 + 2000.0 * j,
               300.0 * math.sin(0.9 * i + 0.3) * math.cos(0.7 * j + 0.2) + 48.4)
              for j in range(n)] for i in range(n)]
    knots = [(0.0, 4), (1 / 3, 1), (2 / 3, 1), (1.0, 4)]
    sheet = _bspline_face(poles, 3, 3, knots, v_knots=knots)
    piece = BRepAlgoAPI_Common(sheet, BRepPrimAPI_MakeBox(gp_Pnt(0, 0, -200), gp_Pnt(40, 30, 200)).Shape()).Shape()
    piece = BRepAlgoAPI_Cut(piece, _cylinder(20, 15, -200, (0, 0, 1), 5.0, 400.0)).Shape()
    return compound_of(piece, BRepPrimAPI_MakeBox(gp_Pnt(50, 0, -10), gp_Pnt(90, 30, 10)).Shape())


def slit():
    """Two 40 × 30 × 20 blocks 0.001 apart (a compound, not fused), their facing faces a slit seen along its length:
    rays entering it meet one of two planes 0.001 apart at grazing incidence; a filleted cylinder stands behind."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    return compound_of(
        BRepPrimAPI_MakeBox(gp_Pnt(0, 0, 0), gp_Pnt(40, 15, 20)).Shape(),
        BRepPrimAPI_MakeBox(gp_Pnt(0, 15.001, 0), gp_Pnt(40, 30, 20)).Shape(),
        _cylinder(60, 15, 0, (0, 0, 1), 6.0, 25.0))


def dense_net():
    """A scanned-looking bicubic face: a 48 × 48 control net (45 × 45 knot spans) over 60 × 60 with bumps of several
    wavelengths, and a round hole."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut

    n = 48
    rng = np.random.default_rng(7)
    bumps = rng.normal(0.0, 0.25, (n, n))
    poles = [[(60.0 * i / (n - 1), 60.0 * j / (n - 1),
               3.0 * math.sin(i / 6.0) * math.cos(j / 9.0) + 0.8 * math.sin(i / 1.7 + j / 2.3) + float(bumps[i, j]))
              for j in range(n)] for i in range(n)]
    knots = [(0.0, 4)] + [(k / (n - 3), 1) for k in range(1, n - 3)] + [(1.0, 4)]
    face = _bspline_face(poles, 3, 3, knots, v_knots=knots)
    return BRepAlgoAPI_Cut(face, _cylinder(25, 35, -20, (0, 0, 1), 6.0, 40.0)).Shape()



# --- Eighth sweep: rational extrusions, rectangular trims across a period, pinched holes, thin wide faces. ---------

def rational_extrusion():
    """A surface of linear extrusion (Geom_SurfaceOfLinearExtrusion, from BRepPrimAPI_MakePrism of an edge) of a
    rational degree-7 B-spline curve (one span, 8 poles, weights 0.2 to 6): an open wavy wall 30 high, tilted."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
    from OCP.BRepPrimAPI import BRepPrimAPI_MakePrism
    from OCP.Geom import Geom_BSplineCurve
    from OCP.collections import Array1_double, Array1_gp_Pnt, Array1_int
    from OCP.gp import gp_Pnt, gp_Vec

    points = [(0.0, 0.0, 0.0), (8.0, 14.0, 0.0), (16.0, -10.0, 0.0), (24.0, 12.0, 0.0), (32.0, -14.0, 0.0),
              (40.0, 9.0, 0.0), (48.0, -6.0, 0.0), (56.0, 3.0, 0.0)]
    weights = [1.0, 0.2, 6.0, 0.5, 3.0, 0.3, 2.0, 1.0]
    poles, w = Array1_gp_Pnt(1, len(points)), Array1_double(1, len(points))
    for k, (p, weight) in enumerate(zip(points, weights)):
        poles.SetValue(k + 1, gp_Pnt(*p))
        w.SetValue(k + 1, weight)
    kv, mv = Array1_double(1, 2), Array1_int(1, 2)
    kv.SetValue(1, 0.0), kv.SetValue(2, 1.0)
    mv.SetValue(1, 8), mv.SetValue(2, 8)
    curve = Geom_BSplineCurve(poles, w, kv, mv, 7)
    return BRepPrimAPI_MakePrism(BRepBuilderAPI_MakeEdge(curve).Edge(), gp_Vec(4.0, 3.0, 30.0)).Shape()


def periodic_trimmed():
    """A face on a Geom_RectangularTrimmedSurface of `periodic_bspline`'s tube (periodic in u, period 8) trimmed to
    u from 6.5 to 9.5: across the period's end (u = 8 ≡ 0), a 135° window of the tube, v from 0.2 to 0.8."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_RectangularTrimmedSurface

    trimmed = Geom_RectangularTrimmedSurface(_periodic_tube(), 6.5, 9.5, 0.2, 0.8)
    return BRepBuilderAPI_MakeFace(trimmed, 1e-7).Face()


def periodic_trimmed_box():
    """`periodic_trimmed`'s face (which Open CASCADE's NURBS conversion refuses) and a 6 × 6 × 6 box inside the tube's
    window, not fused: a model whose faces convert one by one but not as a whole."""
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    return compound_of(periodic_trimmed(), BRepPrimAPI_MakeBox(gp_Pnt(-3.0, -3.0, 13.0), 6.0, 6.0, 6.0).Shape())


def _periodic_curve(points):
    """A periodic cubic B-spline curve through the control points ``points`` (xyz), knots 0, 1, … n."""
    from OCP.Geom import Geom_BSplineCurve
    from OCP.collections import Array1_double, Array1_gp_Pnt, Array1_int
    from OCP.gp import gp_Pnt

    n = len(points)
    poles, knots, mults = Array1_gp_Pnt(1, n), Array1_double(1, n + 1), Array1_int(1, n + 1)
    for i, p in enumerate(points):
        poles.SetValue(i + 1, gp_Pnt(*p))
    for i in range(n + 1):
        knots.SetValue(i + 1, float(i))
        mults.SetValue(i + 1, 1)
    return Geom_BSplineCurve(poles, knots, mults, 3, True)


def extrusion_window():
    """A wavy periodic B-spline outline (9 poles, period 9) extruded along (0.1, 0.2, 1), the face u from -2.5 to 2.5
    (across the period's end) and v from 0 to 15, beside a 6 × 6 × 6 box."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.Geom import Geom_SurfaceOfLinearExtrusion
    from OCP.gp import gp_Dir, gp_Pnt

    angles = [2 * math.pi * k / 9 for k in range(9)]
    outline = _periodic_curve([(10 * math.cos(a) * (1 + 0.25 * math.cos(3 * a)), 8 * math.sin(a), 0.0) for a in angles])
    face = BRepBuilderAPI_MakeFace(Geom_SurfaceOfLinearExtrusion(outline, gp_Dir(0.1, 0.2, 1.0)), -2.5, 2.5, 0.0, 15.0,
                                   1e-7).Face()
    return compound_of(face, BRepPrimAPI_MakeBox(gp_Pnt(-20.0, -3.0, 0.0), 6.0, 6.0, 6.0).Shape())


def revolution_window():
    """A periodic B-spline profile (8 poles, period 8) round (20, 0, 0) revolved about z, the face u (the angle) from
    -1 to 1.5 and v from -2 to 3 (across the profile's period end)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_SurfaceOfRevolution
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt

    angles = [2 * math.pi * k / 8 for k in range(8)]
    profile = _periodic_curve([(20 + 5 * math.cos(a) + 1.5 * math.cos(2 * a), 0.0, 6 * math.sin(a)) for a in angles])
    surface = Geom_SurfaceOfRevolution(profile, gp_Ax1(gp_Pnt(0, 0, 0), gp_Dir(0, 0, 1)))
    return BRepBuilderAPI_MakeFace(surface, -1.0, 1.5, -2.0, 3.0, 1e-7).Face()


def touching_holes():
    """A 60 × 40 × 3 plate drilled by two holes (r 6) whose rims touch at one point (centres 12 apart), and a third
    (r 4) tangent to the second's rim from outside on the other side: inner loops touching each other."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox

    plate = BRepPrimAPI_MakeBox(60.0, 40.0, 3.0).Shape()
    for x, y, r in ((18.0, 20.0, 6.0), (30.0, 20.0, 6.0), (40.0, 20.0, 4.0)):
        plate = BRepAlgoAPI_Cut(plate, _cylinder(x, y, -5.0, (0, 0, 1), r, 13.0)).Shape()
    return plate


def thin_wide():
    """A box 100 long, 1e-5 thick and 10 high standing on a 20 × 20 × 2 base: a face 100 × 1e-5 (its top) to be seen
    face-on, from above, and its two 100 × 10 sides 1e-5 apart."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Fuse
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    wall = BRepPrimAPI_MakeBox(gp_Pnt(-40.0, 10.0, 2.0), 100.0, 1e-5, 10.0).Shape()
    return BRepAlgoAPI_Fuse(BRepPrimAPI_MakeBox(20.0, 20.0, 2.0).Shape(), wall).Shape()


def turned_band():
    """A whole turn of a cylinder (r 10, 6 high, axis z) as one face whose surface is trimmed to [π/2, 5π/2]: Open
    CASCADE's conversion keeps that range for its B-spline but puts the edges' pcurves at u 1.5332 to 7.8164, the
    rational circle's own parameter (as OCCT's data/step/trj1_io1-ms.stp, face 13)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.Geom import Geom_CylindricalSurface, Geom_RectangularTrimmedSurface
    from OCP.gp import gp_Ax3

    band = Geom_RectangularTrimmedSurface(Geom_CylindricalSurface(gp_Ax3(), 10.0), math.pi / 2, 2.5 * math.pi, 0.0, 6.0)
    return BRepBuilderAPI_MakeFace(band, 1e-7).Face()


def write_loose_seam(path: Path, amplitude: float = 2e-3) -> None:
    """The filleted block with a through hole of radius 6, converted to NURBS (its hole wall a face closed in u) and
    written as STEP with every CARTESIAN_POINT moved by a uniform amount in [-amplitude, amplitude] per coordinate
    (seed 19): a loose export whose closed faces' seams are open by µm, within their edges' tolerance."""
    import random
    import re

    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert

    block = BRepAlgoAPI_Cut(filleted_block(), _cylinder(20.0, 15.0, -1.0, (0.0, 0.0, 1.0), 6.0, 30.0)).Shape()
    write_step(BRepBuilderAPI_NurbsConvert(block, True).Shape(), path)
    moves = random.Random(19)

    def moved(match) -> str:
        coordinates = [float(x) + moves.uniform(-amplitude, amplitude) for x in match.group(2).split(",")]
        return match.group(1) + ",".join("%.17E" % x for x in coordinates) + "))"  # ISO 10303-21 reals

    path.write_text(re.sub(r"(CARTESIAN_POINT\('[^']*',\()([^)]*)\)\)", moved, path.read_text()))


def write_scaled_assembly(path: Path) -> None:
    """The filleted block as a STEP assembly (XCAF) of two instances, the second LOCATED at scale 0.5 and moved
    (-60, 0, 0): Open CASCADE's NURBS conversion of the whole shape halves that instance's planes' domains, their edges
    4–11 off them, unless the reader bakes the scaling location into the geometry first (`occt.rigid_locations`)."""
    from OCP.gp import gp_Trsf, gp_Vec

    scaled = gp_Trsf()
    scaled.SetScaleFactor(0.5)
    scaled.SetTranslationPart(gp_Vec(-60.0, 0.0, 0.0))
    write_assembly(filleted_block(), path, (gp_Trsf(), scaled))


def _naca_section(m: float = 0.02, p: float = 0.4, t: float = 0.12, n: int = 40) -> list[tuple[float, float]]:
    """A NACA 4-digit section (x in [0, 1]) with a sharp trailing edge (closed-TE coefficient −0.1036): from the
    trailing edge over the upper side to the leading edge and back along the lower side."""
    beta = np.linspace(0.0, math.pi, n)
    x = 0.5 * (1 - np.cos(beta))
    thickness = 5 * t * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x ** 2 + 0.2843 * x ** 3 - 0.1036 * x ** 4)
    camber = np.where(x < p, m / p ** 2 * (2 * p * x - x ** 2), m / (1 - p) ** 2 * ((1 - 2 * p) + 2 * p * x - x ** 2))
    theta = np.arctan(np.where(x < p, 2 * m / p ** 2 * (p - x), 2 * m / (1 - p) ** 2 * (p - x)))
    upper = list(zip(x - thickness * np.sin(theta), camber + thickness * np.cos(theta)))[::-1]
    lower = list(zip(x + thickness * np.sin(theta), camber - thickness * np.cos(theta)))[1:]
    points = upper + lower
    points[0] = points[-1] = (1.0, float(camber[-1]))
    return points


def wing_skin():
    """A wing (span 300, chord 120 tapering to 54, swept 60, twisted −4°, dihedral 15) lofted through five NACA 2412
    sections, each one closed non-periodic B-spline from the trailing edge round to it (an open sheet): one face
    closed in u, its seam on the sharp trailing edge, where the two sheets meet at ~9°."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeWire
    from OCP.BRepOffsetAPI import BRepOffsetAPI_ThruSections
    from OCP.collections import Array1_gp_Pnt
    from OCP.GeomAbs import GeomAbs_C2
    from OCP.GeomAPI import GeomAPI_PointsToBSpline
    from OCP.gp import gp_Pnt

    loft = BRepOffsetAPI_ThruSections(False, False, 1e-6)
    for s in np.linspace(0.0, 1.0, 5):
        chord, sweep_by, twist, dihedral = 120.0 * (1 - 0.55 * s), 60.0 * s, math.radians(-4.0 * s), 15.0 * s ** 2
        section = _naca_section()
        points = Array1_gp_Pnt(1, len(section))
        for k, (x, y) in enumerate(section):
            xx, yy = (x - 0.25) * chord, y * chord
            points.SetValue(k + 1, gp_Pnt(xx * math.cos(twist) - yy * math.sin(twist) + 30.0 + sweep_by, 300.0 * s,
                                          xx * math.sin(twist) + yy * math.cos(twist) + dihedral))
        curve = GeomAPI_PointsToBSpline(points, 3, 8, GeomAbs_C2, 1e-4).Curve()
        loft.AddWire(BRepBuilderAPI_MakeWire(BRepBuilderAPI_MakeEdge(curve).Edge()).Wire())
    loft.Build()
    return loft.Shape()


PARTS = {
    "sphere_hole.step": lambda p: write_step(sphere_hole(), p),
    "torus.step": lambda p: write_step(torus(), p),
    "cone.step": lambda p: write_step(cone(), p),
    "shelled_box.step": lambda p: write_step(shelled_box(), p),
    "bottle.step": lambda p: write_step(bottle(), p),
    "loft_hole.step": lambda p: write_step(loft_hole(), p),
    "bspline_prism.step": lambda p: write_step(bspline_prism(), p),
    "tiny_inch.step": lambda p: write_step_in(scaled_block(0.01), p, "INCH"),
    "huge_inch.step": lambda p: write_step_in(scaled_block(10000.0), p, "INCH"),
    "two_solids.step": lambda p: write_step(two_solids(), p),
    "reversed_face.step": lambda p: write_step(reversed_face(), p),
    "sliver.step": lambda p: write_step(sliver(), p),
    "small_fillet.step": lambda p: write_step(small_fillet(), p),
    "union_big.step": lambda p: write_step(union_curved(10000.0), p),
    "union.step": lambda p: write_step(union_curved(), p),
    "union.igs": lambda p: write_iges(union_curved(), p),
    "union_micro.step": lambda p: write_step(union_curved(1e-3), p),
    "union_far.step": lambda p: write_step(_moved(union_curved(), (1e5, -1e5, 1e5)), p),
    "sphere_pole_view.step": lambda p: write_step(sphere_pole_view(), p),
    "cone_apex_view.step": lambda p: write_step(cone_apex_view(), p),
    "torus_patch.step": lambda p: write_step(torus_patch(), p),
    "revolved_seam.step": lambda p: write_step(revolved_seam(), p),
    "loft_fillet_hole.step": lambda p: write_step(loft_fillet_hole(), p),
    "instances.step": lambda p: write_step(instances(), p),
    "kink.step": lambda p: write_step(kink(), p),
    "offset_face.step": lambda p: write_step(offset_face(), p),
    "rational_wild.step": lambda p: write_step(rational_wild(), p),
    "extrusion_holes.3dm": write_extrusion_holes_3dm,
    "brep.igs": lambda p: write_iges(shelled_box(), p),
    "faces.igs": lambda p: write_iges(shelled_box(), p, mode=0),
    "sphere.3dm": write_sphere_3dm,
    "rhino_mix.3dm": write_rhino_mix_3dm,
    "loft_skin_edge_on.step": lambda p: write_step(loft_skin_edge_on(), p),
    "pipe_spline.step": lambda p: write_step(pipe_spline(), p),
    "hollow_sphere_cut.step": lambda p: write_step(hollow_sphere_cut(), p),
    "variable_fillet.step": lambda p: write_step(variable_fillet(), p),
    "torus_hole_view.step": lambda p: write_step(torus_hole_view(), p),
    "many_holes.step": lambda p: write_step(many_holes(), p),
    "many_holes.igs": lambda p: write_iges(many_holes(), p, mode=0),
    "tiny_on_huge.step": lambda p: write_step(tiny_on_huge(), p),
    "periodic_bspline.step": lambda p: write_step(periodic_bspline(), p),
    "mirrored_assembly.step": write_mirrored_assembly,
    "blocks.3dm": write_blocks_3dm,
    "three_sided.step": lambda p: write_step(three_sided(), p),
    "panel_fillet.step": lambda p: write_step(panel_fillet(), p),
    "double_cone.step": lambda p: write_step(double_cone(), p),
    "offset_cylinder.step": lambda p: write_step(offset_cylinder(), p),
    "thin_chamfer.step": lambda p: write_step(thin_chamfer(), p),
    "touching_hole.step": lambda p: write_step(touching_hole(), p),
    "star_apex.step": lambda p: write_step(star_apex(), p),
    "seam_hole.step": lambda p: write_step(seam_hole(), p),
    "slot_plate.step": lambda p: write_step(slot_plate(), p),
    "twisted_ruled.step": lambda p: write_step(twisted_ruled(), p),
    "rational_high.step": lambda p: write_step(rational_high(), p),
    "thin_wall.step": lambda p: write_step(thin_wall(), p),
    "wavy_cut.step": lambda p: write_step(wavy_cut(), p),
    "sphere_seam_hole.step": lambda p: write_step(sphere_seam_hole(), p),
    "revolved_pinch.step": lambda p: write_step(revolved_pinch(), p),
    "corner_blend.step": lambda p: write_step(corner_blend(), p),
    "far_away.step": lambda p: write_step(far_away(), p),
    "axis_box.step": lambda p: write_step(axis_box(), p),
    "closed_room.step": lambda p: write_step(closed_room(), p),
    "spindle_torus.step": lambda p: write_step(spindle_torus(), p),
    "coincident_solids.step": lambda p: write_step(coincident_solids(), p),
    "long_strip.step": lambda p: write_step(long_strip(), p),
    "near_knots.step": lambda p: write_step(near_knots(), p),
    "high_degree_extrusion.step": lambda p: write_step(high_degree_extrusion(), p),
    "open_sheets.step": lambda p: write_step(open_sheets(), p),
    "perforated.step": lambda p: write_step(perforated(), p),
    "sloppy_sewn.step": lambda p: write_step(sloppy_sewn(), p),
    "skewed_param.step": lambda p: write_step(skewed_param(), p),
    "polygon_outline.step": lambda p: write_step(polygon_outline(), p),
    "oversized_surface.step": lambda p: write_step(oversized_surface(), p),
    "slit.step": lambda p: write_step(slit(), p),
    "dense_net.step": lambda p: write_step(dense_net(), p),
    "rational_extrusion.step": lambda p: write_step(rational_extrusion(), p),
    "periodic_trimmed.step": lambda p: write_step(periodic_trimmed(), p),
    "periodic_trimmed_box.step": lambda p: write_step(periodic_trimmed_box(), p),
    "extrusion_window.step": lambda p: write_step(extrusion_window(), p),
    "revolution_window.step": lambda p: write_step(revolution_window(), p),
    "touching_holes.step": lambda p: write_step(touching_holes(), p),
    "thin_wide.step": lambda p: write_step(thin_wide(), p),
    "turned_band.step": lambda p: write_step(turned_band(), p),
    "scaled_assembly.step": write_scaled_assembly,
    "wing_skin.step": lambda p: write_step(wing_skin(), p),
    "loose_seam.step": write_loose_seam,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=Path)
    parser.add_argument("names", nargs="*", help="only these parts")
    args = parser.parse_args()
    unknown = sorted(set(args.names) - set(PARTS))
    if unknown:
        parser.error(f"no such part: {', '.join(unknown)} (known: {', '.join(PARTS)})")
    args.out.mkdir(parents=True, exist_ok=True)
    sys.path.insert(0, str(ROOT))
    from rtreflect.exchange.occt import silence_messages

    silence_messages()
    for name, make in PARTS.items():
        if args.names and name not in args.names:
            continue
        path = args.out / name
        try:
            make(path)
        except Exception as exc:  # report and go on: the sweep wants every part it can make
            print(f"{name}: FAILED to make ({type(exc).__name__}: {exc})")
            continue
        print(f"{name}: {path.stat().st_size / 1024:.0f} kB")


if __name__ == "__main__":
    main()
