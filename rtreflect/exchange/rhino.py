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

What is rendered is what Rhino shows (`placed_breps`): the visible objects of the model (not hidden, on a layer
that is on together with its parents), and every **block instance** (``InstanceReference``) as its definition's
objects transformed by the instance's 4×4 ``Xform`` (nested blocks composed, outermost first; each face's NURBS
surface and edge curves transformed, `rebuild_face`); the definitions' own objects
(``ObjectMode.InstanceDefinitionObject``, also listed in ``File3dm.Objects``) are not rendered where they are stored.
A transform of determinant < 0 (a mirrored instance) maps S_u × S_v inwards: its faces are reversed, as Open
CASCADE does for a mirrored STEP location (``BRepTools_TrsfModification``), so that they still face out. What is
left out (meshes, SubD, curves, hidden objects, blocks that cannot be placed) is counted in `CadModel.notes`.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SceneError
from .occt import CAD_EXTRA, CadModel, FaceError, import_ocp, read_faces

#: Rhino's unit systems by the short names the model summary uses (others are reported by their Rhino name).
UNIT_NAMES = {"Millimeters": "mm", "Centimeters": "cm", "Meters": "m", "Inches": "in", "Feet": "ft",
              "Microns": "µm", "Kilometers": "km", "None": "unitless"}
#: Gap closing tolerance when the file does not state one (Rhino's default absolute tolerance, model units).
DEFAULT_TOLERANCE = 1e-3
#: Blocks nested deeper than this are left out: real assemblies nest a few levels, and a cycle (a definition placing
#: itself, directly or not, which Rhino refuses to make but a damaged file may hold) is caught before by the path
#: of definitions it is inside; the limit bounds the work a pathological file can ask for.
MAX_BLOCK_DEPTH = 32


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


def rebuild_face(brep, face, edges: dict, tolerance: float, context=None, xform=None):
    """One Rhino Brep face as an OCCT face: its surface, its loops' 3D edges as wires, pcurves by ShapeFix_Face.

    ``context`` (a ``ShapeBuild_ReShape`` shared by the Brep's faces) records the edges ShapeFix replaces, so that
    applied to all the Brep's rebuilt faces it keeps one edge per Rhino edge (the Brep's topology). ``xform`` (a block
    instance's ``Transform``) places the face: its NURBS surface and edge curves are transformed (their homogeneous
    control points: exact for any affine map), and a transform of determinant < 0 reverses the face."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace
    from OCP.ShapeFix import ShapeFix_Face
    from OCP.TopoDS import TopoDS, TopoDS_Wire

    surface = occt_surface(_placed(face.ToNurbsSurface(), xform))
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
                curve = occt_curve(_placed(brep.Edges[trim.EdgeIndex].ToNurbsCurve(), xform))
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
    if face.OrientationIsReversed != (xform is not None and xform.Determinant() < 0):
        rebuilt = TopoDS.Face(rebuilt.Reversed())
    return rebuilt


def _placed(nurbs, xform):
    """A NurbsSurface or NurbsCurve (a fresh copy) transformed by ``xform`` in place, unless it is None.

    Not ``Brep.Transform``: that transforms a sphere's or cylinder's RevSurface as a surface of revolution, wrong under
    a non-uniform scale (measured on blocks.3dm's sphere scaled (1, 0.6, 2): 1.24 off the ellipsoid, Open CASCADE's
    first hits 2.9 behind ours); the NURBS form's control points carry any affine map exactly (2e-15 here)."""
    if xform is not None:
        nurbs.Transform(xform)
    return nurbs


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
    placed = placed_breps(model, rhino3dm)
    index, failed = 0, []
    for geometry, xform in placed.breps:
        edges: dict = {}
        context = ShapeBuild_ReShape()
        brep_faces = TopoDS_Compound()
        builder.MakeCompound(brep_faces)
        for face in geometry.Faces:
            try:
                builder.Add(brep_faces, rebuild_face(geometry, face, edges, tolerance, context, xform))
            except FaceError as exc:
                failed.append((index, str(exc)))
            except Exception as exc:  # an OCCT exception while rebuilding: name the face
                failed.append((index, f"its trims cannot be rebuilt in Open CASCADE ({type(exc).__name__}: {exc})"))
            index += 1
        # The edges a later face's fix replaced, replaced in the faces fixed before it too: shared again.
        builder.Add(compound, context.Apply(brep_faces))
    if index == 0:
        held = ", ".join(filter(None, [_tally(placed.others), placed.unplaced and _unplaced(placed.unplaced),
                                       placed.on_pages and _on_pages(placed.on_pages)]))
        if placed.hidden:
            held = (held + " and " if held else "") + f"{_hidden(placed.hidden)}: show them in Rhino to render them"
        held = held or "no objects"
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
        model_read.no_area = [k for k, _ in _renumber([(k, "") for k in model_read.no_area], [f for f, _ in failed])]
        model_read.faces = index
    model_read.notes = placed.notes()
    return model_read


@dataclass
class Placed:
    """What `placed_breps` found in a model: the Breps to render, and what it left out (for the summary)."""

    #: (rhino3dm Brep, its block instance's composed Transform or None), in the file's object order, instances expanded
    breps: list = field(default_factory=list)
    others: Counter = field(default_factory=Counter)  # objects left out by kind: "Mesh", "SubD", "LineCurve", ...
    hidden: int = 0  # objects left out because Rhino does not show them (hidden, or on a layer that is off)
    unplaced: Counter = field(default_factory=Counter)  # block instances that cannot be placed, by reason
    instances: int = 0  # block instances placed (nested ones included)
    mirrored: int = 0  # of which of determinant < 0
    on_pages: int = 0  # objects left out because they lie on a layout page (page space), not in the model

    def notes(self) -> list[str]:
        """Summary lines (without the file name): the blocks placed, the objects left out by kind, the hidden ones."""
        lines = []
        if self.instances:
            lines.append(f"placed {self.instances} block instance{'s' * (self.instances != 1)}"
                         + (f" ({self.mirrored} mirrored)" if self.mirrored else ""))
        if self.unplaced:
            lines.append(f"left out {_unplaced(self.unplaced)}")
        if self.others:
            lines.append(f"left out {_tally(self.others)}: not surfaces")
        if self.hidden:
            lines.append(f"left out {_hidden(self.hidden)}")
        if self.on_pages:
            lines.append(f"left out {_on_pages(self.on_pages)}")
        return lines


def _tally(counts: Counter) -> str:
    return ", ".join(f"{n} {kind}" for kind, n in sorted(counts.items()))


def _unplaced(reasons: Counter) -> str:
    return "block instances: " + _tally(reasons)


def _on_pages(count: int) -> str:
    return f"{count} object{'s' * (count != 1)} on layout pages (page space, not the model)"


def _hidden(count: int) -> str:
    return f"{count} hidden object{'s' * (count != 1)} (hidden, or on a layer that is off)"


def placed_breps(model, rhino3dm) -> Placed:
    """The Breps Rhino shows in ``model`` (a ``File3dm``), in world coordinates, in the file's object order.

    Breps, Extrusions (``ToBrep``) and bare Surfaces (``Brep.CreateFromSurface``) are taken; each block instance
    (``InstanceReference``) is its definition's objects (``InstanceDefinition.GetObjectIds``, in that order)
    placed by its ``Xform``, a nested instance's transform composed after its parent's (world = T_outer · T_inner ·
    p), given with the Brep for `rebuild_face` to apply. Objects a
    designer does not see are left out and counted: hidden ones (``ObjectMode.Hidden``) and those on a layer that
    is off or under one that is (inside a block too, as Rhino draws it); objects of the definitions themselves
    (``ObjectMode.InstanceDefinitionObject``) render only through their instances.
    """
    placed = Placed()
    objects = {obj.Attributes.Id: obj for obj in model.Objects}
    definitions = {definition.Id: definition for definition in model.InstanceDefinitions}
    shown = _layers_shown(model)
    definition_mode = rhino3dm.ObjectMode.InstanceDefinitionObject
    page_space = rhino3dm.ActiveSpace.PageSpace

    def visit(obj, xform, path: tuple) -> None:
        attributes = obj.Attributes
        if attributes.ActiveSpace == page_space:  # a layout's title block or annotation: drawn on paper, not modelled
            placed.on_pages += 1
            return
        if attributes.Mode == rhino3dm.ObjectMode.Hidden or not attributes.Visible \
                or not shown.get(attributes.LayerIndex, True):
            placed.hidden += 1
            return
        geometry = obj.Geometry
        if isinstance(geometry, rhino3dm.InstanceReference):
            definition = definitions.get(geometry.ParentIdefId)
            members = [objects.get(member) for member in definition.GetObjectIds()] if definition else []
            inner = geometry.Xform if xform is None else rhino3dm.Transform.Multiply(xform, geometry.Xform)
            why = _unplaceable(definition, members, inner, path)
            if why:
                placed.unplaced[why] += 1
                return
            placed.instances += 1
            placed.mirrored += inner.Determinant() < 0
            for member in members:
                visit(member, inner, (*path, definition.Id))
            return
        if isinstance(geometry, rhino3dm.Extrusion):
            brep = geometry.ToBrep(False)
        elif isinstance(geometry, rhino3dm.Surface):
            brep = rhino3dm.Brep.CreateFromSurface(geometry)
        elif isinstance(geometry, rhino3dm.Brep):
            brep = geometry
        else:
            placed.others[type(geometry).__name__] += 1
            return
        placed.breps.append((brep, xform))

    for obj in model.Objects:
        if obj.Attributes.Mode != definition_mode:
            visit(obj, None, ())
    return placed


def _unplaceable(definition, members: list, xform, path: tuple) -> str:
    """Why a block instance of ``definition`` (its objects ``members``, placed by ``xform`` inside the definitions
    ``path``, outermost first) cannot be placed, or ""."""
    if definition is None:
        return "whose block definition is not in the file"
    if definition.Id in path:  # a damaged file: followed, it would never end
        return f"of block {definition.Name!r} inside itself"
    if len(path) >= MAX_BLOCK_DEPTH:
        return f"nested over {MAX_BLOCK_DEPTH} deep"
    if not members:
        return f"of block {definition.Name!r}, which holds no objects"
    if None in members:  # a linked block whose file was not embedded
        return f"of block {definition.Name!r}, whose objects are not in the file (linked?)"
    if xform.Determinant() == 0:
        return "flattened (a transform of determinant 0)"
    return ""


def _layers_shown(model) -> dict[int, bool]:
    """Layer index → whether Rhino shows its objects: the layer and every parent layer on."""
    layers = list(model.Layers)
    by_id = {layer.Id: layer for layer in layers}

    def shown(layer) -> bool:
        seen = set()
        while layer is not None and layer.Id not in seen:  # a parent cycle (a damaged file) ends the walk
            if not layer.Visible:
                return False
            seen.add(layer.Id)
            layer = by_id.get(layer.ParentLayerId)
        return True

    return {layer.Index: shown(layer) for layer in layers}


def _renumber(skipped: list[tuple[int, str]], failed: list[int]) -> list[tuple[int, str]]:
    """(index, reason) of skipped or warned faces: indices among the rebuilt faces → indices among all of the file's faces (the failed ones left out)."""
    kept = [i for i in range(len(skipped) + len(failed) + max([s for s, _ in skipped], default=0) + 1) if i not in set(failed)]
    return [(kept[s], reason) for s, reason in skipped]
