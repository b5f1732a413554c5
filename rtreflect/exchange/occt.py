"""Open CASCADE shape → one trimmed `NurbsSurface` per face (shared by the STEP, IGES and .3dm readers).

Steps (DESIGN.md, "CAD input"; measured facts in the project's OCP notes):

1. ``BRepBuilderAPI_NurbsConvert`` turns every face into a B-spline face **first**: conversion
   re-parameterises planes, cylinders, cones, spheres, tori and revolved faces and rewrites the
   pcurves to match, so trims and mesh are taken from the converted shape only. Where the whole shape does not
   convert, each face converts on its own (`converted_faces`).
2. Per face, the B-spline surface (location applied by ``BRep_Tool.Surface_s``) is cut to the
   face's (u, v) bounds with ``Geom_BSplineSurface.Segment``: this un-periodises periodic
   surfaces, clamps unclamped knot vectors, and keeps the geometry and the parameters (knot
   insertion, Piegl & Tiller A5.3); a cut point within `SIDE_SNAP` of a knot is put on it (`_snap_to_knots`: no
   sliver span). Knots closer than float64 resolves are merged (`clean_knots`). Weights are read with ``WeightsArray()`` whenever either rational flag is set.
3. Trims: the outer wire (``BRepTools.OuterWire_s``) and the holes, each edge's pcurve
   (``BRepAdaptor_Curve2d``, seam edges once per orientation, pole edges included) sampled by
   bisection until the polyline's midpoints lie within `TRIM_TOLERANCE` × the part's diagonal (the faces' own
   box's where the control points' box overstates it, `REMESH_RATIO`)
   of the pcurve's **in model space** (measured on the surface with rtreflect's evaluator). Each segment also
   carries its cubic Hermite end tangents (Δt·γ'(t) at its ends, ``BRepAdaptor_Curve2d.D1``; on .3dm faces the
   3D edge's tangent in (u, v)) where that piece matches the pcurve's midpoint (`_hermite_tangents`): the
   point-in-face test decides points between chord and edge against it (`kernels.trims`).
4. ``mesh_uv``: ``BRepMesh_IncrementalMesh`` on each converted face, the nodes' (u, v) and the
   triangles (flipped on reversed faces so they wind like the face's normal).

OCP is imported only here and in the per-format readers; without it the user is told which extra
to install.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..geometry.knots import MIN_KNOT_SPAN, knot_vector_problem
from ..geometry.patches import patch_problem
from ..geometry.surfaces import SIDE_SNAP, NurbsSurface

#: What to install for CAD input (pyproject.toml's [cad] extra).
CAD_EXTRA = "pip install 'rtreflect[cad]'"
#: Mesh chord deflection relative to the part's bounding-box diagonal. The mesh only seeds Newton
#: (hits are refined onto the exact surface), so it can be coarse: 2e-3 keeps a 200-face part near
#: 10k nodes and meshing near 0.1 s.
MESH_DEFLECTION = 2e-3
#: The mesh deflection is relative to the part's diagonal, taken first from the control points' box (cheap, but loose:
#: the converted rational faces of a revolution can put control points far out). Where that box's diagonal exceeds the
#: faces' own (`faces_bounds`, from the mesh nodes and trims on the surfaces) more than this many times, the faces are
#: meshed again at the deflection the true diagonal asks for: the sweep's revolved_seam.step (2,653 against 138.5) was
#: meshed to 4.8 from its surface, asked for 0.28, and its chord error widened every ray's error band across the part.
#: The trims are sampled again then too, to `TRIM_TOLERANCE` × the true diagonal.
#: The shipped parts' boxes are within 1.5× of their faces' (the vase's), so their meshes and trims are unchanged.
REMESH_RATIO = 2.0
#: The least chord deflection Open CASCADE's BRepMesh accepts (Precision::Confusion): a model under 5e-5 across
#: (the seventeenth round's filleted block at 1e-5 mm) asks for less, and every face failed "invalid parameter value".
SMALLEST_DEFLECTION = 1e-7
#: A face whose trim's `Trim.roundness` in its domain is below this encloses no area: its loop runs out along a curve
#: and back (OCCT's data/step/trj6_b1-ec-214.stp, faces 54 and 71: 1.1e-6, a degree-8 patch reaching 12,000 mm off
#: the 270 mm part inside its domain). It is left out with a note (as one whose loops enclose exactly nothing, once a
#: bad face that stopped the read): the span grid that meshes it kept the cells its sliver crosses, whose corners lay
#: on those wild parts, and the part's framing and extent took them in (the default view a dot in the middle of the
#: frame). The thinnest real faces of 3,353 (OCCT's files, the shipped parts) measured 6e-4.
NO_AREA_ROUNDNESS = 1e-5
#: Mesh angular deflection (radians): bounds the normal turn across a triangle on small, curved features
#: (OCCT's default; finer multiplies the nodes on small fillets without helping Newton).
MESH_ANGLE = 0.5
#: Largest model-space distance between a trim polyline and its pcurve's image, relative to the part's
#: diagonal: 1e-5 is 0.01 px when the part spans 1000 px, far below what a pixel shows.
TRIM_TOLERANCE = 1e-5
#: An edge's trim follows its 3D edge (samples projected onto the surface) where the pcurve's samples stray from the
#: edge by more than this fraction of the trim tolerance (`_strays_from_edge`).
STRAY_FRACTION = 0.1
#: Segments each pcurve starts with before bisection (a curved edge needs a few to show its bend).
TRIM_START_SEGMENTS = 8
#: Bisection rounds at most: 8 · 2^14 points an edge is far beyond any real edge's need.
TRIM_MAX_ROUNDS = 14
#: A periodic direction's knots that start this fraction of a period before a whole-period shift from the pcurves'
#: first parameter count as starting there (`_into_pcurves_period`): OCCT's parameters agree to its tolerances (1e-9
#: of the domain at cut corners, `SIDE_SNAP`), far below it; a cut that is not a whole period away lies far above.
PERIOD_SHIFT_SLACK = 1e-6
#: A closed face's non-seam pcurves that pass its surface's domain by more than this fraction of its width wind round it
#: more than once (`_over_periods`: the bottle's thread strips, 93 % past). Less is drift: converted pcurves ending at a
#: pole (bottle.step's sphere face, 1.4 %), Rhino's fitted pcurves (trimmed.3dm, 0.02 %), the 2D boxes' gap (1e-7).
WINDING_PAST = 0.05
#: A cut that would keep less than this fraction of the knot span it falls in moves out to the span's far knot
#: (`_snap_to_knots`): derivatives on a span of relative width w lose ~1/w² of float64's precision (S_vv came out 15 of
#: its scale off at w ~ 5e-8), so at 1e-3 they stay within ~1e-10. The face's trims bound it in the wider domain.
SLIVER_SPAN = 1e-3
#: Faces beyond which a progress bar is shown while a model loads (small parts load in well under a second).
PROGRESS_FACES = 200


class FaceError(Exception):
    """One face cannot be used; ``reason`` says why (the reader adds the file and face index)."""


def import_ocp(path: Path, what: str):
    """The OCP package, or a `SceneError` naming the extra to install."""
    try:
        import OCP  # noqa: F401
    except ImportError:
        raise SceneError(path, "", f"reading {what} needs Open CASCADE (OCP): {CAD_EXTRA}") from None
    silence_messages()
    return OCP


_silenced = False


def silence_messages() -> None:
    """OCCT's messenger prints transfer statistics to stdout: only failures pass from now on."""
    global _silenced
    if _silenced:
        return
    from OCP.Message import Message, Message_Gravity

    for printer in Message.DefaultMessenger_s().Printers():
        printer.SetTraceLevel(Message_Gravity.Message_Fail)
    _silenced = True


@contextlib.contextmanager
def quiet_stdout():
    """File descriptor 1 to /dev/null around OCCT calls: some readers print with printf, past the messenger."""
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:  # no stdout at all: nothing to protect
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


@dataclass
class CadModel:
    """What a CAD reader gives the scene: the faces' surfaces and what the summary reports."""

    surfaces: list[NurbsSurface]
    unit: str  # the model's length unit after reading, e.g. "mm"
    unit_note: str  # how the file's unit was handled, e.g. "file in inches, read in mm"; "" if nothing to say
    bounds: tuple[np.ndarray, np.ndarray]  # bounding box (lo, hi) of the faces read
    faces: int  # faces in the file (over all instances), read or skipped
    skipped: list[tuple[int, str]] = field(default_factory=list)  # (face index, reason) left out by --skip-bad-faces
    #: Per surface: the face is reversed (its outward normal is -S_u × S_v; its mesh triangles are flipped to match).
    reversed: list[bool] = field(default_factory=list)
    #: (face index, reason): faces read, but short of what the reader promises (trims kept coarser than
    #: `TRIM_TOLERANCE` of the faces' extent); the summary prints them as warnings (`exchange.cad.model_summary`).
    warnings: list[tuple[int, str]] = field(default_factory=list)
    #: What the reader left out of the file or placed, one summary line each without the file name (the .3dm reader:
    #: block instances placed, objects that are not surfaces by kind, hidden objects).
    notes: list[str] = field(default_factory=list)
    #: Faces left out as enclosing no area (`NO_AREA_ROUNDNESS`), by index; the summary lists them.
    no_area: list[int] = field(default_factory=list)

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.bounds[1] - self.bounds[0]))


def shape_bounds(shape) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box of a shape from its control points (OCCT's, without gap): a loose box, for scales."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    box.SetGap(0.0)
    BRepBndLib.Add_s(shape, box, False)
    if box.IsVoid():
        return np.zeros(3), np.zeros(3)
    lo, hi = box.CornerMin(), box.CornerMax()
    return np.array([lo.X(), lo.Y(), lo.Z()]), np.array([hi.X(), hi.Y(), hi.Z()])


def count_entities(shape) -> dict[str, int]:
    """Faces, edges and vertices of a shape: tells a file with only curves or points apart from an empty one."""
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_VERTEX
    from OCP.TopExp import TopExp_Explorer

    counts = {}
    for name, kind in (("faces", TopAbs_FACE), ("edges", TopAbs_EDGE), ("vertices", TopAbs_VERTEX)):
        n = 0
        explorer = TopExp_Explorer(shape, kind)
        while explorer.More():
            n += 1
            explorer.Next()
        counts[name] = n
    return counts


def surfaceless_faces(shape) -> int:
    """Faces with no surface (STEP AP242 tessellated geometry: a triangulation only, as OCCT reads it)."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    n, explorer = 0, TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        n += BRep_Tool.Surface_s(TopoDS.Face(explorer.Current())) is None
        explorer.Next()
    return n


def no_surfaces_error(path: Path, shape, what: str) -> SceneError:
    counts = count_entities(shape) if shape is not None and not shape.IsNull() else {"edges": 0, "vertices": 0}
    if counts.get("faces"):  # faces, none with a surface
        faces = f"{counts['faces']} face{'s' if counts['faces'] != 1 else ''}"
        held = (f"only meshes ({faces} without a surface: tessellated geometry); export the part's exact surfaces "
                "(a B-rep: STEP AP203/AP214, or AP242 with its B-rep)")
    elif counts.get("edges") or counts.get("vertices"):
        held = f"only curves or points ({counts['edges']} edges, {counts['vertices']} vertices)"
    else:
        held = "no surface Open CASCADE can transfer (the file is corrupt, or its entities are not supported)"
    return SceneError(path, "", f"no surfaces to render: the {what} holds {held}")


def clean_knots(knots: np.ndarray, degree: int, poles: np.ndarray, weights: np.ndarray, axis: int):
    """Knots valid for `NurbsSurface` (exchange/scene.py `_check_knots`) with the geometry kept.

    Knots closer than `MIN_KNOT_SPAN` are merged (each snapped onto the one before: the surface
    moves by that knot shift times its derivative, ~1e-12 of the part). A clamped end that then
    repeats more than degree + 1 times loses its outermost knot and control row: that row only
    shaped the merged, vanishing span. An inner knot repeated more than degree + 1 times cannot be
    merged without changing the surface: a `FaceError`.
    """
    knots = knots.copy()
    narrowest = MIN_KNOT_SPAN * max(1.0, float(np.max(np.abs(knots))))
    for i in range(len(knots) - 1):
        if 0 < knots[i + 1] - knots[i] < narrowest:
            knots[i + 1] = knots[i]
    while np.count_nonzero(knots == knots[0]) > degree + 1:
        knots = knots[1:]
        poles, weights = np.delete(poles, 0, axis=axis), np.delete(weights, 0, axis=axis)
    while np.count_nonzero(knots == knots[-1]) > degree + 1:
        knots = knots[:-1]
        poles, weights = np.delete(poles, -1, axis=axis), np.delete(weights, -1, axis=axis)
    values, counts = np.unique(knots, return_counts=True)
    if counts.max() > degree + 1:
        k = int(np.argmax(counts))
        raise FaceError(f"knot {values[k]:.17g} repeats {counts[k]} times after merging knots closer than float64 "
                        f"resolves (at most degree + 1 = {degree + 1})")
    if poles.shape[axis] < degree + 1:
        raise FaceError("the face's parameter range is narrower than float64 resolves")
    return knots, poles, weights


def _snap_to_knots(value: float, knots: np.ndarray, width: float, period: float = 0.0, outward: int = 0,
                   bounds: tuple[float, float] = (-math.inf, math.inf),
                   kept: tuple[float, float] = (-math.inf, math.inf)) -> float:
    """``value`` moved onto the nearest knot within `SIDE_SNAP` of ``width`` (the cut's range; at least
    `MIN_KNOT_SPAN`), so cutting there leaves no sliver knot span. A periodic direction's knots (one period's) are
    first moved by whole periods to ``value``'s period where ``value`` lies outside their range.

    A cut that close to a knot is OCCT's tolerance, not a feature: union_big.step's periodic cylinders were cut at
    u = -1.756e-9 beside the knot 0, leaving a 1.76e-9-wide span in which S_uu came out 0.65 of its scale off, and
    variable_fillet.step's fillets 9.4e-9 past a knot, S_vv 5.3e4 off (tests/test_nurbs_vs_occt.py). The trims and
    mesh nodes that far outside the cut are put on its side anyway (`_wire_loop`; the evaluator clamps to the domain).

    Farther from the knot, a cut that would still leave less than `SLIVER_SPAN` of the knot span it falls in on the
    kept side (``outward`` = +1 for the upper cut, −1 for the lower) moves out to that span's far knot instead, within
    ``bounds``: the face keeps the whole span, which holds it (its trims bound it), and no point of the surface moves.
    Only where that knot lies inside the cut's range ``kept`` (else the piece kept is no sliver beside a span, but the
    whole face inside one) and the move is at most the range's width (a face's domain stays about its size: the
    contour grids and the curvature map's range sample the whole domain).
    variable_fillet.step's fillets 2 and 6 end 4.4e-7 past a knot (1.5e-8 of their range: beyond the snap), and cut
    there their S_vv came out 8.6 and 15 of its scale off.
    """
    reach = max(SIDE_SNAP * width, MIN_KNOT_SPAN * max(1.0, float(np.max(np.abs(knots)))))
    if period and not knots[0] - reach <= value <= knots[-1] + reach:  # the knots as OCCT gave them where they serve
        knots = knots + period * math.floor((value - knots[0]) / period)
    gap = np.abs(knots - value)
    k = int(np.argmin(gap))
    if gap[k] < reach:
        return float(knots[k])
    if outward == 0:
        return value
    if period:  # the span may run into the next period (or the one before)
        knots = np.concatenate([knots[:-1] - period, knots, knots[1:] + period])
    above = int(np.searchsorted(knots, value))  # the knots below and above ``value``: the kept side's is the inner one
    inner, outer = (above - 1, above) if outward > 0 else (above, above - 1)
    if not (0 <= inner < len(knots) and 0 <= outer < len(knots)):
        return value
    sliver, span, far = abs(value - knots[inner]), abs(knots[outer] - knots[inner]), float(knots[outer])
    inside = kept[0] < knots[inner] < kept[1] and abs(far - value) <= kept[1] - kept[0]
    return far if sliver < SLIVER_SPAN * span and inside and bounds[0] <= far <= bounds[1] else value


def _cut_at_knots(lo: float, hi: float, knots: np.ndarray, period: float, first: float, last: float
                  ) -> tuple[float, float]:
    """The cut [lo, hi] of one direction with both ends put on knots where `_snap_to_knots` says: moved out over a
    sliver span only within the surface's bounds [first, last], and a periodic one's (``period`` > 0) single period."""
    width, kept = hi - lo, (lo, hi)
    lo = _snap_to_knots(lo, knots, width, period, -1, (hi - period if period else first, math.inf), kept)
    return lo, _snap_to_knots(hi, knots, width, period, +1, (-math.inf, lo + period if period else last), kept)


def _into_pcurves_period(knots: np.ndarray, lo: float, period: float) -> np.ndarray:
    """A periodic direction's knots after `Segment`, moved by whole periods so the domain starts at ``lo``, the
    pcurves' first parameter: where the trims and mesh (u, v) are. OCCT's `Segment` may return the span one period
    on (pcurves from -1.8e-9 to 2π on knots 0..2π came back as 2π..4π); on a periodic surface S(u) = S(u + period),
    so the shift keeps the geometry. The shift is the whole number of periods the first knot lies at or beyond ``lo``
    (floor, to `PERIOD_SHIFT_SLACK`): the first knot lands in [lo, lo + period), the pcurves' range, never before
    it (a nearest-integer rule sends a first knot k + ½ periods on to lo − ½ period for odd k, lo + ½ for even)."""
    shift = math.floor((knots[0] - lo) / period + PERIOD_SHIFT_SLACK) * period if period else 0.0
    return knots - shift if shift else knots


def bspline_of_face(face) -> NurbsSurface:
    """The converted face's B-spline surface, cut to the face's (u, v) bounds, as a `NurbsSurface` (no trim yet)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepTools import BRepTools
    from OCP.Geom import Geom_BSplineSurface

    surface = BRep_Tool.Surface_s(face)
    if surface is None:
        raise FaceError("it has no surface, only a mesh (tessellated geometry): rtreflect needs the exact surface")
    if not isinstance(surface, Geom_BSplineSurface):
        raise FaceError(f"Open CASCADE did not convert its {type(surface).__name__.removeprefix('Geom_')} surface to a B-spline")
    u_first, u_last, v_first, v_last = surface.Bounds()
    umin, umax, vmin, vmax = BRepTools.UVBounds_s(face)
    if not (np.isfinite([umin, umax, vmin, vmax]).all() and umax > umin and vmax > vmin):
        raise FaceError(f"its (u, v) range is empty or not finite ({umin:g}..{umax:g}, {vmin:g}..{vmax:g})")

    u_lo, u_hi, v_lo, v_hi = _pcurves_range(face)

    def cut(lo, hi, first, last, periodic, period, knots, closed, pcurves_lo, pcurves_hi):
        if periodic:
            hi = min(hi, lo + period)
        elif closed and _beyond(pcurves_lo, pcurves_hi, first, last, closed):
            lo, hi = first, last  # winds round more than once, or once from elsewhere: `_over_periods`
        else:  # the pcurves' bounds may pass the surface's by their tolerance
            lo, hi = max(lo, first), min(hi, last)
        return _cut_at_knots(lo, hi, knots, period if periodic else 0.0, first, last)

    uk = np.fromiter(surface.UKnots(), float)
    vk = np.fromiter(surface.VKnots(), float)
    u_period = surface.UPeriod() if surface.IsUPeriodic() else 0.0
    v_period = surface.VPeriod() if surface.IsVPeriodic() else 0.0
    # Closed as Open CASCADE judges it (to its own tolerance): only such a direction goes round from elsewhere (`_beyond`).
    u_closed, v_closed = surface.IsUClosed() or surface.IsUPeriodic(), surface.IsVClosed() or surface.IsVPeriodic()
    u0, u1 = cut(umin, umax, u_first, u_last, surface.IsUPeriodic(), u_period, uk, u_closed, u_lo, u_hi)
    v0, v1 = cut(vmin, vmax, v_first, v_last, surface.IsVPeriodic(), v_period, vk, v_closed, v_lo, v_hi)
    whole = (u0, u1, v0, v1) == (u_first, u_last, v_first, v_last)
    clamped = (surface.UMultiplicity(1) == surface.UDegree() + 1 and surface.UMultiplicity(len(uk)) == surface.UDegree() + 1
               and surface.VMultiplicity(1) == surface.VDegree() + 1 and surface.VMultiplicity(len(vk)) == surface.VDegree() + 1)
    if surface.IsUPeriodic() or surface.IsVPeriodic() or not whole or not clamped:
        surface = surface.Copy()
        try:
            surface.Segment(u0, u1, v0, v1)
        except Exception as exc:  # OCCT's Standard_Failure: a range it cannot cut
            raise FaceError(f"cannot cut its surface to the face's (u, v) range ({exc})") from None
        if surface.IsUPeriodic():
            surface.SetUNotPeriodic()
        if surface.IsVPeriodic():
            surface.SetVNotPeriodic()

    p, q = surface.UDegree(), surface.VDegree()
    nu, nv = surface.NbUPoles(), surface.NbVPoles()
    poles = np.array([[pt.X(), pt.Y(), pt.Z()] for pt in surface.Poles()], dtype=np.float64)
    # Array2 iterates row-major: u index first, v index fastest.
    poles = poles.reshape(nu, nv, 3)
    if surface.IsURational() or surface.IsVRational():  # either flag: a cylinder reports only one
        weights = np.fromiter(surface.WeightsArray(), float).reshape(nu, nv)  # never Weights(): it crashes OCP 8.0
    else:
        weights = np.ones((nu, nv))
    knots_u = _into_pcurves_period(np.fromiter(surface.UKnotSequence(), float), u0, u_period)
    knots_v = _into_pcurves_period(np.fromiter(surface.VKnotSequence(), float), v0, v_period)
    knots_u, poles, weights = clean_knots(knots_u, p, poles, weights, 0)
    knots_v, poles, weights = clean_knots(knots_v, q, poles, weights, 1)
    knots_u, poles, weights = _over_periods(knots_u, p, poles, weights, 0, u_lo, u_hi, u_closed)
    knots_v, poles, weights = _over_periods(knots_v, q, poles, weights, 1, v_lo, v_hi, v_closed)
    for direction, knots, degree, count in (("u", knots_u, p, poles.shape[0]), ("v", knots_v, q, poles.shape[1])):
        problem = knot_vector_problem(knots, degree, count)  # the rules every reader applies
        if problem:
            raise FaceError(f"knots in {direction}: {problem}")
    if not (np.isfinite(poles).all() and np.isfinite(weights).all() and (weights > 0).all()):
        raise FaceError("its surface has control points or weights that are not finite, or weights <= 0")
    surface = NurbsSurface(p, q, knots_u, knots_v, poles, weights)
    problem = patch_problem(surface)  # the checks inline and .bpt patches get
    if problem:
        raise FaceError(problem)
    return surface


def _pcurves_range(face) -> tuple[float, float, float, float]:
    """(u_min, u_max, v_min, v_max) of the face's pcurves but its seams' and poles' (``BndLib_Add2dCurve.AddOptimal``:
    tight, not the control polygon's box; NaN without such an edge). Not ``BRepTools.UVBounds``, which clips them to a
    B-spline surface's bounds. A seam's converted pcurves drift off the seam by the poles (sphere_hole.step: u = 1.518
    against the side π/2; `_on_seam_side` puts them back), which is no second turn."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve2d
    from OCP.Bnd import Bnd_Box2d
    from OCP.BndLib import BndLib_Add2dCurve

    box = Bnd_Box2d()
    for edge in _edges_of(face):
        if BRep_Tool.IsClosed_s(edge, face) or BRep_Tool.Degenerated_s(edge):
            continue
        curve = BRepAdaptor_Curve2d(edge, face)
        BndLib_Add2dCurve.AddOptimal_s(curve.Curve(), curve.FirstParameter(), curve.LastParameter(), 0.0, box)
    if box.IsVoid():
        return (math.nan,) * 4
    return box.GetXMin(), box.GetXMax(), box.GetYMin(), box.GetYMax()


def _past(lo: float, hi: float, first: float, last: float) -> bool:
    """Whether the pcurves' range ``lo``..``hi`` passes the domain ``first``..``last`` by more than `WINDING_PAST` of
    its width: a face winding round its closed surface more than once (`_over_periods`)."""
    reach = WINDING_PAST * (last - first)
    return bool(np.isfinite(lo) and np.isfinite(hi) and (lo < first - reach or hi > last + reach))


def _beyond(lo: float, hi: float, first: float, last: float, closed: bool) -> bool:
    """Whether a closed direction's pcurves ``lo``..``hi`` need the surface beyond its domain ``first``..``last``: they
    wind round it more than once (`_past`), or go round it once from elsewhere (`_turns_past`) where Open CASCADE
    calls the direction closed or periodic (``closed``): the wall of the sweep's thin_wide.step, a face 1e-5 wide whose
    pcurves pass it by 1e-7 with its first and last control rows within `_over_periods`' slack of each other, is not.
    The one test of `bspline_of_face`'s cut and of `_over_periods`."""
    return _past(lo, hi, first, last) or (closed and _turns_past(lo, hi, first, last))


def _turns_past(lo: float, hi: float, first: float, last: float) -> bool:
    """Whether the pcurves' range ``lo``..``hi`` spans a whole turn of the closed domain ``first``..``last`` and starts
    before it or ends after it (by more than `PERIOD_SHIFT_SLACK` of its width): a face round the whole closed surface
    whose turn starts elsewhere than the surface's parameters do (`_over_periods`).

    Open CASCADE's conversion of a cylinder trimmed to [π/2, π/2 + 2π] (OCCT's data/step/trj1_io1-ms.stp, face 13) keeps
    that range but re-computes the pcurves for the rational circle's own parameter: the edges ran from u = 1.5332 to
    7.8164, a whole turn 0.0376 before the domain. Cut to the domain, 2.2° of the cylinder along its seam were missing:
    rays there met the face behind it, 3.7 past Open CASCADE's first hit.
    """
    width = last - first
    slack = PERIOD_SHIFT_SLACK * width
    return bool(np.isfinite(lo) and np.isfinite(hi) and hi - lo >= width - slack
                and (lo < first - slack or hi > last + slack))


def _over_periods(knots: np.ndarray, degree: int, poles: np.ndarray, weights: np.ndarray, axis: int, lo: float,
                  hi: float, closed: bool):
    """A closed direction's surface repeated over the whole periods its pcurves ``lo``..``hi`` run through, where they
    run past its domain: (knots, poles, weights), unchanged otherwise.

    A face on a periodic surface may wind round it more than once: the bottle's thread faces (bottle.step, MakeBottle:
    the thread's side strips on the neck's cylinder) have pcurves from u = 0.26 to 12.34, two turns. Open CASCADE's
    conversion (``BRepBuilderAPI_NurbsConvert``) gives their cylinders a B-spline over one period and keeps the
    pcurves, and `Segment` cuts a periodic one to a period at most: the second turn lay outside the domain, and rays
    at it went on to the neck behind (a close-up of the thread: every pixel 0.33 behind OCCT's first hit). On a closed
    direction (its first and last control rows equal, weights too) the surface is periodic with its domain's width:
    copies shifted by whole periods, joined at knots of multiplicity ``degree`` (the shared row once), are the same
    surface on the pcurves' whole range (`bspline_of_face` leaves such a closed direction uncut for it). So is
    one they go round once from elsewhere (`_turns_past`) on a direction Open CASCADE calls closed (``closed``,
    `_beyond`). A domain the pcurves pass by no more than `WINDING_PAST` of its width (`_past`), not going round it, is
    kept.
    """
    a, b = float(knots[0]), float(knots[-1])
    width = b - a
    if not _beyond(lo, hi, a, b, closed):
        return knots, poles, weights
    clamped = np.count_nonzero(knots == a) == degree + 1 and np.count_nonzero(knots == b) == degree + 1
    first, last = np.take(poles, 0, axis=axis), np.take(poles, -1, axis=axis)
    scale = float(np.max(np.abs(poles)))
    closed = (np.max(np.abs(first - last)) <= PERIOD_SHIFT_SLACK * scale
              and np.allclose(np.take(weights, 0, axis=axis), np.take(weights, -1, axis=axis), rtol=1e-12, atol=0.0))
    if not (clamped and closed):
        return knots, poles, weights
    k0 = math.floor((lo - a) / width + PERIOD_SHIFT_SLACK)
    k1 = math.ceil((hi - a) / width - PERIOD_SHIFT_SLACK)
    inner = knots[degree + 1:len(knots) - degree - 1]
    parts, rows, row_weights = [np.full(degree + 1, a + k0 * width)], [], []
    for j in range(k0, k1):
        parts += [inner + j * width, np.full(degree if j < k1 - 1 else degree + 1, a + (j + 1) * width)]
        skip = slice(None) if j == k0 else slice(1, None)  # the row shared with the copy before: once
        index = np.arange(poles.shape[axis])[skip]
        rows.append(np.take(poles, index, axis=axis))
        row_weights.append(np.take(weights, index, axis=axis))
    return np.concatenate(parts), np.concatenate(rows, axis=axis), np.concatenate(row_weights, axis=axis)


def _edge_samples(edge, face, surface: NurbsSurface, tolerance: float, onto_edge: bool = False,
                  with_tangents: bool = False):
    """One edge's pcurve as (u, v) points in the wire's direction, bisected until within ``tolerance`` in 3D.

    ``onto_edge``: each sample is then moved to the foot of the 3D edge's point at the same parameter
    on the surface (`project_onto_surface`): for pcurves that only approximate the edge (fitted by
    ShapeFix for .3dm faces, 7.6e-3 mm off a 10 mm circle) the loop follows the exact 3D edge.

    ``with_tangents``: also each segment's cubic Hermite end tangents (m − 1, 4), `_hermite_tangents` (NaN rows: the
    chord), returned as ``(uv, tangents)``.
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Curve2d
    from OCP.gp import gp_Pnt2d, gp_Vec2d
    from OCP.TopAbs import TopAbs_REVERSED

    curve = BRepAdaptor_Curve2d(edge, face)
    t0, t1 = curve.FirstParameter(), curve.LastParameter()
    if not (np.isfinite(t0) and np.isfinite(t1)):
        raise FaceError("an edge's pcurve has an infinite parameter range")

    def at(ts: np.ndarray) -> np.ndarray:
        out = np.empty((len(ts), 2))
        for k, t in enumerate(ts):  # OCP per-point call (~1 µs): edges have tens to hundreds of samples
            pt = curve.Value(float(t))
            out[k] = pt.X(), pt.Y()
        return out

    ts = np.linspace(t0, t1, TRIM_START_SEGMENTS + 1)
    uv = at(ts)
    for _ in range(TRIM_MAX_ROUNDS):
        mids_t = 0.5 * (ts[:-1] + ts[1:])
        mids = at(mids_t)
        both = np.concatenate([mids, 0.5 * (uv[:-1] + uv[1:])])  # the pcurve's midpoints, then the chords'
        image = surface.evaluate(both[:, 0], both[:, 1]).S
        error = np.linalg.norm(image[:len(mids)] - image[len(mids):], axis=1)
        bad = error > tolerance
        if not bad.any():
            break
        # Keep every midpoint of a bad segment (the polyline is then exact there to the next round's test).
        order = np.argsort(np.r_[ts, mids_t[bad]], kind="stable")
        ts = np.r_[ts, mids_t[bad]][order]
        uv = np.r_[uv, mids[bad]][order]
        mids = None
    tangents = None
    degenerate = BRep_Tool.Degenerated_s(edge)
    seam = BRep_Tool.IsClosed_s(edge, face) and not degenerate
    # Open CASCADE's edge tolerance bounds how far its pcurves stray from it: most edges need no look.
    if not (onto_edge or seam or degenerate) and BRep_Tool.Tolerance_s(edge) > STRAY_FRACTION * tolerance:
        onto_edge = _strays_from_edge(edge, surface, ts, uv, tolerance)
    # A pole edge has no 3D curve to follow; a seam's pcurves are the domain's sides (and projecting onto a seam
    # could land on either side): put there (`_on_seam_side`). A seam is a straight side: its chords are exact.
    if seam:
        on_side = _on_seam_side(uv, surface, _seam_axis(edge, face, surface))
        if on_side is uv:  # not along a side of the domain: a seam inside it, or a pcurve that is not its edge
            _seam_follows_edge(edge, surface, ts, uv, tolerance)
        uv = on_side
        tangents = np.full((len(uv) - 1, 4), np.nan)
    elif onto_edge and not degenerate:
        curve3d = BRepAdaptor_Curve(edge)
        uv, duv = _edge_feet(curve3d, surface, ts, uv)
        if with_tangents:  # the midpoints too: `_hermite_tangents`
            mids_t = 0.5 * (ts[:-1] + ts[1:])
            mids = _edge_feet(curve3d, surface, mids_t, mids if mids is not None else at(mids_t))[0]
            tangents = _hermite_tangents(ts, uv, duv, mids)
    if with_tangents and tangents is None:
        if mids is None:  # the last round split segments: the final ones' midpoints
            mids = at(0.5 * (ts[:-1] + ts[1:]))
        duv = np.empty((len(ts), 2))
        point, vector = gp_Pnt2d(), gp_Vec2d()
        for k, t in enumerate(ts):  # OCP per-point call, as `at`
            curve.D1(float(t), point, vector)
            duv[k] = vector.X(), vector.Y()
        tangents = _hermite_tangents(ts, uv, duv, mids)
    if not degenerate:
        uv = _along_into_pole(uv, surface)
    if edge.Orientation() == TopAbs_REVERSED:
        uv = uv[::-1]
        if tangents is not None:  # each segment run backwards: its end tangents swapped and negated
            tangents = -tangents[::-1][:, [2, 3, 0, 1]]
    return (uv, tangents) if with_tangents else uv


#: A seam's pcurve off the domain's sides may lie this many times its edge's tolerance (plus the trim's) off the edge.
SEAM_STRAY_TOLERANCES = 2.0


def _seam_follows_edge(edge, surface: NurbsSurface, ts: np.ndarray, uv: np.ndarray, tolerance: float) -> None:
    """A seam's pcurve ``uv`` that does not run along a side of the domain (`_on_seam_side`) checked against its 3D
    edge: a `FaceError` where it lies farther from it than `SEAM_STRAY_TOLERANCES` edge tolerances plus the trim's.

    A face closed only to within its edges' tolerance (an export whose points moved by µm: the sweep's loose_nurbs
    part, a filleted block's hole wall converted to NURBS and written with every point moved up to 2e-3 mm) reads with
    its seam's two pcurves the same curve, swinging across the domain at one end (u 0 → 0 → 2π over v 1 → 11 → 21,
    0.22 off the straight 3D edge): the trim zigzagged across a 2 mm band and cut it out of the wall (938 pixels at
    320×180 showed the fillet behind, 12-14 mm farther; `validate` passed; Open CASCADE's own check finds the face
    invalid). Where the trim cannot follow the face's edges the face is not read, as the issue's bad input asks:
    named in one line, and ``--skip-bad-faces`` renders the others. Only where the pcurve and the 3D curve share their
    parameter (SameParameter, SameRange): elsewhere a point of one at t is not the other's at t."""
    from OCP.BRep import BRep_Tool

    if not (BRep_Tool.SameParameter_s(edge) and BRep_Tool.SameRange_s(edge)):
        return
    off = _distance_from_edge(edge, surface, ts, uv)
    allowed = SEAM_STRAY_TOLERANCES * BRep_Tool.Tolerance_s(edge) + tolerance
    if off > allowed:
        raise FaceError(f"its seam's pcurve lies {off:.3g} from the seam's edge (allowed {allowed:.3g}): Open CASCADE "
                        f"read the face damaged (a face closed only to within its tolerance?); heal the model, e.g. "
                        f"close the face in the CAD system and export it again")


def _distance_from_edge(edge, surface: NurbsSurface, ts: np.ndarray, uv: np.ndarray) -> float:
    """The largest 3D distance from the pcurve's samples ``uv`` on the surface to the edge's points at ``ts``."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve

    curve = BRepAdaptor_Curve(edge)
    points = np.array([(p.X(), p.Y(), p.Z()) for p in (curve.Value(float(t)) for t in ts)])
    return float(np.linalg.norm(surface.evaluate(uv[:, 0], uv[:, 1]).S - points, axis=1).max(initial=0.0))


def _strays_from_edge(edge, surface: NurbsSurface, ts: np.ndarray, uv: np.ndarray, tolerance: float) -> bool:
    """Whether the pcurve's samples ``uv`` (at the edge's parameters ``ts``) lie farther than `STRAY_FRACTION` of the
    trim ``tolerance`` from the 3D edge's points there: then the trim follows the edge (`_edge_samples`' ``onto_edge``).

    The NURBS conversion refits a face's pcurves where it reparametrises its surface, and by a pole the fit strays
    where |S_u| → 0 makes errors in u cheap (hollow_sphere_cut.step: the cut's meridian edge wavers up to 9.4e-4 off
    its plane within 0.2 of the pole, where the original face's classifier holds it exactly: close-ups there showed
    the cut face instead of the sphere in 3-38 of 6,400 pixels). Within the trim tolerance, but a trim can follow the
    edge to its samples' accuracy, not the refit's.
    """
    return _distance_from_edge(edge, surface, ts, uv) > STRAY_FRACTION * tolerance


def _along_into_pole(uv: np.ndarray, surface: NurbsSurface) -> np.ndarray:
    """An edge's samples with an end on a pole (a collapsed side, `NurbsSurface.collapsed`) given the parameter along
    that side of the sample next to it: every parameter there is the same 3D point, and the pcurve's end takes whichever
    (the unconverted face's, hollow_sphere_cut.step's meridian: u = 3π/2 at the pole where its other samples lie at
    u = 4.75), which slants the trim's last segment across the face by the pole; the edge runs into the pole along
    its meridian."""
    if len(uv) < 2:
        return uv
    (u0, u1), (v0, v1) = surface.domain
    su, sv = SIDE_SNAP * (u1 - u0), SIDE_SNAP * (v1 - v0)
    copied = False
    for end, near in ((0, 1), (-1, -2)):  # two points: plain floats (numpy's per-call cost is 10× the test's)
        u, v = float(uv[end, 0]), float(uv[end, 1])
        on_v = (abs(v - v0) <= sv, abs(v - v1) <= sv)
        on_u = (abs(u - u0) <= su, abs(u - u1) <= su)
        if not (any(on_v) or any(on_u)):
            continue
        collapsed = surface.collapsed
        if not copied:
            uv, copied = uv.copy(), True
        if (on_v[0] and collapsed[2]) or (on_v[1] and collapsed[3]):
            uv[end, 0] = uv[near, 0]
        elif (on_u[0] and collapsed[0]) or (on_u[1] and collapsed[1]):
            uv[end, 1] = uv[near, 1]
    return uv


#: A segment's cubic Hermite piece is used only where its midpoint lies at most this fraction of the chord's midpoint
#: error from the pcurve's midpoint (`_hermite_tangents`): a knot of lower continuity inside the segment (a kink the
#: end tangents do not see) keeps the chord.
HERMITE_MIDPOINT = 0.1


def _hermite_tangents(ts: np.ndarray, uv: np.ndarray, duv: np.ndarray, mids: np.ndarray) -> np.ndarray:
    """Per segment i of the samples ``uv`` (at edge parameters ``ts``, pcurve derivative ``duv``): the end tangents
    (Δt·γ'(t_i), Δt·γ'(t_{i+1})) of its cubic Hermite piece, (m − 1, 4); NaN (the chord) where the piece's midpoint
    H(½) = (a + b)/2 + (T₀ − T₁)/8 does not lie within `HERMITE_MIDPOINT` of the chord's midpoint error from the
    pcurve's midpoint ``mids`` (both in (u, v)), or the tangents are not finite.

    The Hermite piece matches a smooth pcurve to O(h⁴) where the chord does to O(h²) (de Boor, *A Practical Guide to
    Splines*, ch. IV): the point-in-face test decides points between a chord and its edge against it
    (`kernels.trims`)."""
    dt = np.diff(ts)[:, None]
    tangents = np.column_stack([dt * duv[:-1], dt * duv[1:]])
    chord_mid = 0.5 * (uv[:-1] + uv[1:])
    hermite_mid = chord_mid + (tangents[:, :2] - tangents[:, 2:]) / 8.0
    chord_error = np.linalg.norm(chord_mid - mids, axis=1)
    hermite_error = np.linalg.norm(hermite_mid - mids, axis=1)
    good = np.isfinite(tangents).all(axis=1) & (hermite_error <= HERMITE_MIDPOINT * chord_error)
    tangents[~good] = np.nan
    return tangents


def _edge_feet(curve3d, surface: NurbsSurface, ts: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The feet on ``surface`` of the 3D edge's points C(t) at ``ts`` (`project_onto_surface` from the (u, v)
    ``start``), and the projected curve's tangent there: C'(t) in the surface's (u, v) (`_surface_tangent`)."""
    from OCP.gp import gp_Pnt, gp_Vec

    target, d3 = np.empty((len(ts), 3)), np.empty((len(ts), 3))
    point, vector = gp_Pnt(), gp_Vec()
    for k, t in enumerate(ts):  # OCP per-point call (~1 µs)
        curve3d.D1(float(t), point, vector)
        target[k], d3[k] = (point.X(), point.Y(), point.Z()), (vector.X(), vector.Y(), vector.Z())
    feet = project_onto_surface(surface, target, start)
    return feet, _surface_tangent(surface, feet, d3)


def _surface_tangent(surface: NurbsSurface, uv: np.ndarray, d3: np.ndarray) -> np.ndarray:
    """(du, dv) whose image S_u du + S_v dv is nearest the 3D tangents ``d3`` at ``uv`` (normal equations; NaN where
    S_u, S_v are singular: a pole)."""
    ev = surface.evaluate(uv[:, 0], uv[:, 1])
    a, b, c = (np.einsum("ij,ij->i", x, y) for x, y in ((ev.Su, ev.Su), (ev.Su, ev.Sv), (ev.Sv, ev.Sv)))
    gu, gv = np.einsum("ij,ij->i", d3, ev.Su), np.einsum("ij,ij->i", d3, ev.Sv)
    det = a * c - b * b
    safe = np.where(det > 1e-12 * (a * c + 1e-300), det, np.nan)
    return np.column_stack([(c * gu - b * gv) / safe, (a * gv - b * gu) / safe])


#: A seam edge's pcurve within this fraction of the domain's range of one of its sides is put on that side.
#: The drift measured (sphere_hole.step's converted sphere near its pole) is 0.85 %; a pcurve farther off is left
#: alone (not a seam on the domain's side).
SEAM_SNAP = 0.02


def _seam_axis(edge, face, surface: NurbsSurface) -> int:
    """The parameter (0: u, 1: v) constant along a seam edge: the one its face's two pcurves of it differ in by the
    domain's width (a closed face's two sides), whatever the pieces' own extent or drift."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve2d
    from OCP.TopoDS import TopoDS

    here, there = (BRepAdaptor_Curve2d(TopoDS.Edge(e), face) for e in (edge, edge.Reversed()))
    t = 0.5 * (here.FirstParameter() + here.LastParameter())
    a, b = here.Value(t), there.Value(t)
    (u0, u1), (v0, v1) = surface.domain
    return int(abs(a.Y() - b.Y()) / (v1 - v0) > abs(a.X() - b.X()) / (u1 - u0))


def _on_seam_side(uv: np.ndarray, surface: NurbsSurface, axis: int) -> np.ndarray:
    """A seam edge's pcurve samples put on the domain side they run along (``axis``, `_seam_axis`: u = u₀ or u₁,
    or v alike).

    A closed face's seam is a side of its converted surface's domain: both pcurves lie on the two sides. OCCT's
    conversion (``BRepBuilderAPI_NurbsConvert``) re-approximates the pcurves and, near a pole, they drift: sphere_hole
    .step's seam at u = π/2 runs to u = 1.518 at v = 1.41, 0.05 outside the domain, and its other pcurve as far inside
    it, so the trim cut a strip off the face along the seam (sweep part sphere_hole.step and its mirrored assembly at
    160×90: 10 pixels stored the sphere's far side, 9-15 behind OCCT's hit). The sides are exact. The axis comes from
    the two pcurves, not from the samples' spread: a short piece near a pole may drift farther in u than it runs in v.
    """
    lo, hi = surface.domain[axis]
    span = hi - lo
    side = lo if abs(uv[:, axis].mean() - lo) <= abs(uv[:, axis].mean() - hi) else hi
    if np.max(np.abs(uv[:, axis] - side)) > SEAM_SNAP * span:
        return uv
    out = uv.copy()
    out[:, axis] = side
    return out


#: Gauss–Newton steps of `project_onto_surface`: from a start within the edge tolerance, 3 reach float64.
PROJECTION_STEPS = 4


def project_onto_surface(surface: NurbsSurface, target: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(u, v) of the surface points nearest ``target`` (N, 3), by Gauss–Newton from ``uv`` (vectorised).

    Each step solves the normal equations [S_u·S_u S_u·S_v; S_u·S_v S_v·S_v] Δ = −[d·S_u, d·S_v] with
    d = S(u, v) − target (the foot point condition d ⟂ S_u, S_v). Where the system is singular (a pole)
    the start is kept; the result stays in the domain.
    """
    (u0, u1), (v0, v1) = surface.domain
    start = uv
    uv = uv.copy()
    for _ in range(PROJECTION_STEPS):
        ev = surface.evaluate(uv[:, 0], uv[:, 1])
        d = ev.S - target
        a, b, c = (np.einsum("ij,ij->i", x, y) for x, y in ((ev.Su, ev.Su), (ev.Su, ev.Sv), (ev.Sv, ev.Sv)))
        gu, gv = np.einsum("ij,ij->i", d, ev.Su), np.einsum("ij,ij->i", d, ev.Sv)
        det = a * c - b * b
        ok = det > 1e-12 * (a * c + 1e-300)
        safe = np.where(ok, det, 1.0)
        du = np.where(ok, -(c * gu - b * gv) / safe, 0.0)
        dv = np.where(ok, -(a * gv - b * gu) / safe, 0.0)
        uv[:, 0] = np.clip(uv[:, 0] + du, u0, u1)
        uv[:, 1] = np.clip(uv[:, 1] + dv, v0, v1)
    # Keep the start where the steps did not bring the point closer (near a pole the metric degenerates).
    before = np.linalg.norm(surface.evaluate(start[:, 0], start[:, 1]).S - target, axis=1)
    after = np.linalg.norm(surface.evaluate(uv[:, 0], uv[:, 1]).S - target, axis=1)
    return np.where((after <= before)[:, None], uv, start)


def _wire_loop(wire, face, surface: NurbsSurface, tolerance: float, onto_edges: bool = False):
    """A wire's edges' samples joined into one closed (u, v) polyline (last point not repeated), and per segment
    i → i + 1 (the last closing the loop) its cubic Hermite end tangents (n, 4) (`_hermite_tangents`; NaN: the chord,
    as at the joints between edges)."""
    from OCP.BRepTools import BRepTools_WireExplorer

    pieces = []
    explorer = BRepTools_WireExplorer(wire, face)
    while explorer.More():
        pieces.append(_edge_samples(explorer.Current(), face, surface, tolerance, onto_edges, with_tangents=True))
        explorer.Next()
    edges = _wire_edges(wire)
    if len(pieces) < len(edges):
        # The explorer stopped at a joint it could not connect: every edge, chained by its pcurve's ends instead.
        pieces = _chained([_edge_samples(edge, face, surface, tolerance, onto_edges, with_tangents=True)
                           for edge in edges], surface)
    if not pieces:
        raise FaceError("a wire of the face has no edges")
    loop = np.concatenate([uv for uv, _ in pieces])
    # Per point, its outgoing segment's tangents: an edge's own segments, then NaN for the joint to the next edge.
    tangents = np.concatenate([np.r_[tan, np.full((1, 4), np.nan)] for _, tan in pieces])
    # (u, v) within `SIDE_SNAP` of the domain of a side is put on it, and consecutive points so close are one point:
    # pcurves meet their vertices and the sides only to OCCT's tolerances; a loop touching itself reads as crossing.
    close = SIDE_SNAP * np.array([hi - lo for lo, hi in surface.domain])
    for axis, (lo, hi) in enumerate(surface.domain):
        loop[np.abs(loop[:, axis] - lo) < close[axis], axis] = lo
        loop[np.abs(loop[:, axis] - hi) < close[axis], axis] = hi
    keep = np.r_[True, np.any(np.abs(np.diff(loop, axis=0)) > close, axis=1)]
    # A point dropped merges its (vanishing) incoming segment into its outgoing one: the kept point before a run of
    # dropped ones takes the last one's outgoing tangents.
    kept = np.flatnonzero(keep)
    tangents = tangents[np.r_[kept[1:] - 1, len(loop) - 1]]
    loop = loop[keep]
    if len(loop) > 1 and np.all(np.abs(loop[0] - loop[-1]) <= close):
        # The last point is the first: the segment before it closes the loop (the vanishing one after it goes).
        loop, tangents = loop[:-1], tangents[:-1]
    if len(loop) < 3:
        raise FaceError("a trim loop has fewer than 3 distinct (u, v) points")
    return loop, tangents


def _wire_edges(wire) -> list:
    """The wire's edges in its stored order (``TopoDS_Iterator``), each with its orientation in the wire."""
    from OCP.TopoDS import TopoDS, TopoDS_Iterator

    out, iterator = [], TopoDS_Iterator(wire)
    while iterator.More():
        out.append(TopoDS.Edge(iterator.Value()))
        iterator.Next()
    return out


def _chained(pieces: list, surface: NurbsSurface) -> list:
    """The edges' (u, v) samples (each in its wire direction; ``pieces``: (samples, tangents) pairs) put in loop order: from the first, each next piece is the
    one whose start lies nearest the current end (distances in fractions of the domain's sides).

    ``BRepTools_WireExplorer`` connects a wire's edges through their vertices and stops where it cannot: on a face of
    a mirrored assembly instance (a location of determinant −1) converted by ``BRepBuilderAPI_NurbsConvert``, the
    sphere corner of the filleted block met its pole edge 5e-4 rad off in u and the loop kept 2 of its 4 edges
    (sweep part mirrored_assembly.step: a third of the corner outside its own trim, rays there missed it).
    """
    scale = np.array([max(hi - lo, 1e-300) for lo, hi in surface.domain])
    left, ordered = list(pieces[1:]), [pieces[0]]
    while left:
        end = ordered[-1][0][-1]
        k = int(np.argmin([np.max(np.abs(piece[0][0] - end) / scale) for piece in left]))
        ordered.append(left.pop(k))
    return ordered


def trim_of_face(face, surface: NurbsSurface, tolerance: float, onto_edges: bool = False, edges: tuple = ()):
    """The face's `Trim`: outer wire and holes as (u, v) polylines of ``surface`` (already un-periodised), with each
    segment's cubic Hermite tangents (`_hermite_tangents`) for the point-in-face test.

    ``onto_edges``: samples follow the 3D edges rather than the pcurves (see `_edge_samples`).
    ``edges``: the face's B-rep edges (`face_edges`), carried on the trim to the seam finder.
    """
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    from ..geometry.trims import Trim

    outer_wire = BRepTools.OuterWire_s(face)
    if outer_wire.IsNull():
        raise FaceError("the face has no outer wire")
    outer, outer_tangents = _wire_loop(outer_wire, face, surface, tolerance, onto_edges)
    holes, tangents = [], [outer_tangents]
    explorer = TopExp_Explorer(face, TopAbs_WIRE)
    while explorer.More():
        wire = TopoDS.Wire(explorer.Current())
        explorer.Next()
        if not wire.IsSame(outer_wire):
            hole, hole_tangents = _wire_loop(wire, face, surface, tolerance, onto_edges)
            holes.append(hole)
            tangents.append(hole_tangents)
    return Trim(outer, tuple(holes), edges=edges, tangents=tuple(tangents))


#: Segments each shared edge is sampled in for the seam finder (the same edge parameters on both of its faces):
#: the continuity figures are measured at these points, so 64 locates a maximum to 1/64 of the edge while
#: costing ~0.2 ms per edge and face to read (65 pcurve evaluations through OCP).
EDGE_SEGMENTS = 64


#: Reads so far in this process: part of every edge key (`read_faces`).
_READS = itertools.count()


def edge_keys(shape, prefix: str) -> tuple:
    """The shape's edges indexed (``TopExp.MapShapes_s``: an edge is the same on every face using it, whatever its
    orientation; each located instance of an assembly has its own) and the key maker ``prefix#index``."""
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp
    from OCP.collections import IndexedMap_TopoDS_Shape_TopTools_ShapeMapHasher as IndexedMap

    index = IndexedMap()
    TopExp.MapShapes_s(shape, TopAbs_EDGE, index)
    return index, lambda edge: f"{prefix}#{index.FindIndex(edge)}"


def face_edges(face, surface: NurbsSurface, key_of, onto_edges: bool = False, tolerance: float | None = None) -> tuple:
    """The face's B-rep edges as `FaceEdge`s (geometry/topology.py): each pcurve γ(t) and γ'(t) at `EDGE_SEGMENTS` + 1
    parameters spread evenly over the edge's range (SameParameter: the same t on every face of the edge).

    A seam edge of this face (``BRep_Tool.IsClosed_s``: both sides of a periodic surface's seam line) and a
    degenerate edge (a pole) are recorded by their flags only: they join the face to no other face.
    ``onto_edges``: the points are projected from the 3D edge onto the surface (pcurves fitted by ShapeFix
    only approximate it, see `_edge_samples`). Else an edge's points are projected so where its pcurve strays from the
    3D edge by more than `STRAY_FRACTION` of the trim ``tolerance`` (`_strays_from_edge`), as its trim's are: the
    NURBS conversion of a mirrored instance refits pcurves that run along the edge at another speed than the 3D
    curve, and the two faces' points at the same t lay up to 6.4e-4 apart on an edge whose surfaces meet to 4e-13
    (the sweep's mirrored_assembly.step: `continuity` called the copy's sphere corner open, G0 0.000119).
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Curve2d
    from OCP.gp import gp_Pnt2d, gp_Vec2d
    from OCP.GCPnts import GCPnts_AbscissaPoint
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    from ..geometry.topology import FaceEdge

    out, seen = [], set()
    explorer = TopExp_Explorer(face, TopAbs_EDGE)
    none = np.zeros((0, 2))
    while explorer.More():
        edge = TopoDS.Edge(explorer.Current())
        explorer.Next()
        key = key_of(edge)
        if key in seen:  # a seam edge, met again with the other orientation
            continue
        seen.add(key)
        closed, degenerated = BRep_Tool.IsClosed_s(edge, face), BRep_Tool.Degenerated_s(edge)
        if closed or degenerated:
            out.append(FaceEdge(key, np.zeros(0), none, none, 0.0, closed, degenerated))
            continue
        curve = BRepAdaptor_Curve2d(edge, face)
        t = np.linspace(curve.FirstParameter(), curve.LastParameter(), EDGE_SEGMENTS + 1)
        uv, duv = np.empty((len(t), 2)), np.empty((len(t), 2))
        point, tangent = gp_Pnt2d(), gp_Vec2d()
        for k, tk in enumerate(t):  # OCP per-point calls: 65 an edge
            curve.D1(float(tk), point, tangent)
            uv[k] = point.X(), point.Y()
            duv[k] = tangent.X(), tangent.Y()
        (u0, u1), (v0, v1) = surface.domain
        uv[:, 0], uv[:, 1] = np.clip(uv[:, 0], u0, u1), np.clip(uv[:, 1], v0, v1)
        curve3d = BRepAdaptor_Curve(edge)
        if onto_edges or (tolerance is not None and BRep_Tool.Tolerance_s(edge) > STRAY_FRACTION * tolerance
                          and _strays_from_edge(edge, surface, t, uv, tolerance)):
            uv, duv = _edge_feet(curve3d, surface, t, uv)  # and the tangents of the projected curve there
        out.append(FaceEdge(key, t, uv, duv, float(GCPnts_AbscissaPoint.Length_s(curve3d))))
    return tuple(out)


def mesh_of_face(face, reversed_face: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """The face's BRepMesh triangulation in (u, v): nodes (m, 2) and 0-based triangles (k, 3), or None."""
    from OCP.BRep import BRep_Tool
    from OCP.TopLoc import TopLoc_Location

    triangulation = BRep_Tool.Triangulation_s(face, TopLoc_Location())
    if triangulation is None or triangulation.NbTriangles() == 0 or not triangulation.HasUVNodes():
        return None
    nodes = np.array([(p.X(), p.Y()) for p in triangulation.MapUVNodeArray()], dtype=np.float64)
    triangles = np.array([t.Get() for t in triangulation.MapTriangleArray()], dtype=np.int64) - 1  # OCCT counts from 1
    if reversed_face:  # the triangles wind with the face's normal, which is -S_u × S_v here
        triangles = triangles[:, ::-1]
    return nodes, np.ascontiguousarray(triangles)


#: A pcurve whose image strays farther than this many times its edge's tolerance from the edge's 3D curve (at the
#: edge's quarter points) is not the edge's: OCCT's own tolerance already covers a valid pcurve's error.
PCURVE_OFF = 10.0
#: A seam edge's two pcurves closer than this fraction of the face's (u, v) range are one curve: the seam was lost.
SEAM_LOST = 1e-9


def _edges_of(face) -> list:
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    out, explorer = [], TopExp_Explorer(face, TopAbs_EDGE)
    while explorer.More():
        out.append(TopoDS.Edge(explorer.Current()))
        explorer.Next()
    return out


def seam_lost(face) -> bool:
    """True when a seam edge of the converted ``face`` has a pcurve that is not on its edge.

    ``BRepBuilderAPI_NurbsConvert`` of a shape holding several faces whose B-spline surfaces are closed
    (a seam edge, not periodic: what Rhino and other modellers export for revolved faces and pipes) gives the
    seams of every such face after the first a pcurve on the wrong side of the seam, or off the face (OCCT
    8.0.1, measured on a .3dm with a revolved face and a pipe, read directly and through STEP and IGES): the trim
    loop then folds onto one side (no area) or cuts a wrong region. Each face converted alone keeps its seam.
    Checked for both pcurves of each seam edge: S(γ(t)) against the 3D curve C(t) at the edge's quarter points,
    and the two pcurves apart (on one side, S(γ(t)) = C(t) still holds on a closed surface).
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Curve2d, BRepAdaptor_Surface
    from OCP.TopAbs import TopAbs_FORWARD, TopAbs_REVERSED
    from OCP.TopoDS import TopoDS

    surface = None
    for edge in _edges_of(face):
        if not BRep_Tool.IsClosed_s(edge, face) or BRep_Tool.Degenerated_s(edge):
            continue
        if surface is None:
            surface = BRepAdaptor_Surface(face)
            span = max(surface.LastUParameter() - surface.FirstUParameter(), surface.LastVParameter() - surface.FirstVParameter())
        curve3d = BRepAdaptor_Curve(edge)
        reach = PCURVE_OFF * BRep_Tool.Tolerance_s(edge)
        sides = []
        for orientation in (TopAbs_FORWARD, TopAbs_REVERSED):
            curve = BRepAdaptor_Curve2d(TopoDS.Edge(edge.Oriented(orientation)), face)
            t0, t1 = curve.FirstParameter(), curve.LastParameter()
            for t in (t0 + 0.25 * (t1 - t0), 0.5 * (t0 + t1), t0 + 0.75 * (t1 - t0)):
                uv = curve.Value(t)
                if surface.Value(uv.X(), uv.Y()).Distance(curve3d.Value(t)) > reach:
                    return True
            sides.append((uv.X(), uv.Y()))
        if np.hypot(*np.subtract(*sides)) <= SEAM_LOST * span:  # both on one side: S is the same there
            return True
    return False


def converted_alone(original, face, key_of):
    """``original`` (an unconverted face) converted on its own (`seam_lost`), with the key maker of its edges:
    each edge keeps the key of its counterpart in the whole shape's conversion ``face`` (the modifier keeps the
    edges' order), so the seam finder still pairs it with its neighbours. Where the face alone still looks
    like a lost seam, ``face`` and ``key_of`` unchanged."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    with quiet_stdout():
        alone = BRepBuilderAPI_NurbsConvert(original, True).Shape()
    alone = TopoDS.Face(TopExp_Explorer(alone, TopAbs_FACE).Current())
    keyed = _keyed_by_order(alone, face, key_of)
    if keyed is None or seam_lost(alone):
        # Alone it fails the same test, so the whole shape's conversion did not cause it (an exporter's edge
        # tolerance understating its pcurve's distance, say): the face as converted, as before this check (the
        # trim checks downstream still refuse a loop that encloses nothing).
        return face, key_of
    return alone, keyed


def _keyed_by_order(face, counterpart, key_of):
    """The key maker of ``face``'s edges: each takes the key (``key_of``) of ``counterpart``'s edge in its place (the
    NURBS conversion keeps a face's edges in order), or None where the two have not as many edges."""
    mine, theirs = _edges_of(face), _edges_of(counterpart)
    if len(mine) != len(theirs):
        return None
    keys = [key_of(edge) for edge in theirs]
    return lambda edge: next(key for e, key in zip(mine, keys) if e.IsSame(edge))


#: A location whose gp_Trsf scales by more than this relative amount (|scale factor| ≠ 1) is baked into the geometry
#: before the NURBS conversion (`rigid_locations`).
SCALE_TOLERANCE = 1e-12


def _scales(location) -> bool:
    """True where a TopLoc_Location scales (a mirror's −1 does not: its geometry is only turned over)."""
    return abs(abs(location.Transformation().ScaleFactor()) - 1.0) > SCALE_TOLERANCE


def rigid_locations(shape):
    """``shape`` with every location that scales (an assembly instance placed at scale 0.5) baked into its
    geometry (``BRepBuilderAPI_Transform`` with a copy), the rest of the tree and its rigid locations as they were.

    ``BRepBuilderAPI_NurbsConvert`` converts a plane under a scaling location wrongly: a STEP instance of the filleted
    block at scale 0.5 came out with its flat faces' domains halved, their edges 4–11 mm off them (a quarter of each
    face shown, the block seen through), silently: its fillets were right. Baked, the faces are plain geometry and
    convert as any other. Any container may carry such a location (a compound's child, a solid's shell, a face); the
    containers above a baked one are copied empty (same type, location and orientation) and refilled in order, so the
    faces keep their explorer order. A shape with no such location is returned as it is, and so is one whose baking
    fails (Open CASCADE's exception: the conversion then proceeds as before)."""
    try:
        return _baked(shape)
    except Exception:  # OCCT's Standard_Failure: keep the shape as read
        return shape


def _baked(shape):
    """`rigid_locations`' walk: the shape itself, or a copy with its scaling locations baked."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_VERTEX, TopAbs_WIRE
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS_Iterator

    if _scales(shape.Location()):
        with quiet_stdout():
            baked = BRepBuilderAPI_Transform(shape.Located(TopLoc_Location()), shape.Location().Transformation(),
                                             True).Shape()
        return _baked(baked)
    if shape.ShapeType() in (TopAbs_FACE, TopAbs_WIRE, TopAbs_EDGE, TopAbs_VERTEX):  # geometry, not containers
        return shape
    children = []
    iterator = TopoDS_Iterator(shape, False, False)  # each child with its own location and orientation
    while iterator.More():
        children.append(iterator.Value())
        iterator.Next()
    rigid = [_baked(child) for child in children]
    if all(new is old for new, old in zip(rigid, children)):
        return shape
    builder, copy = BRep_Builder(), shape.EmptyCopied()
    for child in rigid:
        builder.Add(copy, child)
    return copy


def convert_shape(shape):
    """Every face as a B-spline face (``BRepBuilderAPI_NurbsConvert``), or None where Open CASCADE cannot convert the
    shape as a whole (then `converted_faces` converts it face by face)."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert

    try:
        with quiet_stdout():
            return BRepBuilderAPI_NurbsConvert(shape, True).Shape()
    except Exception:  # OCCT's Standard_Failure: one face it cannot convert fails the whole shape
        return None


class _Unconvertible:
    """A face Open CASCADE cannot convert on its own either, with its reason: `read_faces` names it (FaceError)."""

    def __init__(self, reason: str):
        self.reason = reason


def converted_faces(originals: list, shape, key_prefix: str) -> tuple[list, list, list]:
    """Where the whole shape does not convert: each face of ``originals`` converted on its own, with its edges' key
    maker (keys of the edges of ``shape``, the unconverted model, so faces sharing an edge still share its key:
    `_keyed_by_order`; each converts its copy of a shared edge alike), and per face the index of its original.
    A closed face whose conversion fails is converted in pieces (`_divided_converted`): several faces, one original.

    A face that fails alone but already lies on a B-spline surface is kept as it is: the conversion would only have
    rewritten its curves, which the trims sample through adaptors whatever their type (the sweep's
    periodic_trimmed.step, a periodic B-spline tube's face across the period's end: "Knots interval values too close"
    from the conversion of its edges). Any other face that fails is an `_Unconvertible`."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.Geom import Geom_BSplineSurface
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    _, original_key = edge_keys(shape, key_prefix)
    faces, key_makers, origin = [], [], []
    for index, original in enumerate(originals):
        keyed = None
        try:
            with quiet_stdout():
                alone = BRepBuilderAPI_NurbsConvert(original, True).Shape()
            face = TopoDS.Face(TopExp_Explorer(alone, TopAbs_FACE).Current())
            keyed = _keyed_by_order(face, original, original_key)
        except Exception as exc:
            if isinstance(BRep_Tool.Surface_s(original), Geom_BSplineSurface):
                face = original
            else:
                face = _unwrapped_converted(original)
                if face is None:
                    pieces = _divided_converted(original, f"{key_prefix}|face {index}")
                    if pieces is None:
                        pieces = [(_Unconvertible(f"Open CASCADE cannot convert it to NURBS ({exc})"), None)]
                    for piece, piece_key_of in pieces:
                        faces.append(piece)
                        key_makers.append(piece_key_of)
                        origin.append(index)
                    continue
        faces.append(face)
        origin.append(index)
        # A face kept unconverted (or converted with its edges segmented) has edges whose parameter t may differ from
        # a converted neighbour's along the same edge (the conversion reparametrises conics): sharing their keys would
        # pair points by t that are not the same point (false gaps). Keys of its own: those edges are no seam.
        key_makers.append(keyed or edge_keys(face, f"{key_prefix}|face {index}")[1])
    return faces, key_makers, origin


def _divided_converted(original, key_prefix: str) -> list | None:
    """A closed face the conversion refuses, cut in two across each closed direction (``ShapeUpgrade_ShapeDivideClosed``)
    and each piece converted: [(piece, its edges' key maker)], or None where that fails too. The pieces share the
    edges they were cut along (keys of the divided face's edges); their other edges have keys of their own, as a face
    kept unconverted has (`converted_faces`): no seam with the neighbouring faces is checked there.

    A face spanning a whole period from an offset may span it by a rounding more: OCCT's data/step/trj4_k1_geo-tu-214.stp
    (CAx-IF, a key's ring), face 37, a torus over v 1.7766..8.0597, 2π and one unit in the last place, which
    Convert_TorusToBSplineSurface refuses; its halves convert."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_NurbsConvert
    from OCP.ShapeUpgrade import ShapeUpgrade_ShapeDivideClosed
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    try:
        with quiet_stdout():
            divide = ShapeUpgrade_ShapeDivideClosed(original)
            divide.SetNbSplitPoints(1)
            if not divide.Perform():
                return None
            divided = divide.Result()
            _, key_of = edge_keys(divided, key_prefix)
            pieces, explorer = [], TopExp_Explorer(divided, TopAbs_FACE)
            while explorer.More():
                piece = TopoDS.Face(explorer.Current())
                converted = BRepBuilderAPI_NurbsConvert(piece, True).Shape()
                face = TopoDS.Face(TopExp_Explorer(converted, TopAbs_FACE).Current())
                pieces.append((face, _keyed_by_order(face, piece, key_of) or edge_keys(face, f"{key_prefix}|{len(pieces)}")[1]))
                explorer.Next()
    except Exception:  # OCCT's Standard_Failure: the face stays unconvertible
        return None
    return pieces if len(pieces) > 1 else None


#: `_unwrapped_converted` keeps a converted face only where its pcurves lie within this fraction of the face's
#: bounding-box diagonal (or 10× the edge's own tolerance) of its 3D edges.
UNWRAPPED_AGREEMENT = 1e-7


def _unwrapped_converted(original):
    """A face the NURBS conversion refuses, converted again once each edge's 3D curve that is a periodic B-spline
    (or a trimmed one) is replaced by its segment over the edge's range: the same points at the same parameters, no
    period. None where that fails too, or where a converted pcurve misses its 3D edge (`UNWRAPPED_AGREEMENT`).

    A face on a swept surface of a periodic B-spline curve (a linear extrusion, a revolution), its window across the
    curve's period end, has edges on that curve trimmed across its origin, and their conversion fails ("BSpline
    curve: Knots interval values too close"); segmented, they convert, and the surface with them.
    """
    from OCP.BRep import BRep_Builder, BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Curve2d
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy, BRepBuilderAPI_NurbsConvert
    from OCP.Geom import Geom_BSplineCurve, Geom_BSplineSurface, Geom_TrimmedCurve
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS

    try:
        copy = TopoDS.Face(BRepBuilderAPI_Copy(original).Shape())
        builder, unwrapped = BRep_Builder(), False
        for edge in _edges_of(copy):
            location = TopLoc_Location()
            curve = BRep_Tool.Curve_s(edge, location, 0.0, 0.0)
            basis = curve.BasisCurve() if isinstance(curve, Geom_TrimmedCurve) else curve
            if isinstance(basis, Geom_BSplineCurve) and basis.IsPeriodic():
                first, last = BRep_Tool.Range_s(edge)
                segment = basis.Copy()
                segment.Segment(first, last)
                builder.UpdateEdge(edge, segment, location, BRep_Tool.Tolerance_s(edge))
                unwrapped = True
        if not unwrapped:
            return None
        with quiet_stdout():
            shape = BRepBuilderAPI_NurbsConvert(copy, True).Shape()
        face = TopoDS.Face(TopExp_Explorer(shape, TopAbs_FACE).Current())
        surface = BRep_Tool.Surface_s(face)
        if not isinstance(surface, Geom_BSplineSurface):
            return None
        lo, hi = shape_bounds(original)
        reach = UNWRAPPED_AGREEMENT * float(np.linalg.norm(hi - lo))
        for edge in _edges_of(face):
            if BRep_Tool.Degenerated_s(edge):
                continue
            curve, curve3d = BRepAdaptor_Curve2d(edge, face), BRepAdaptor_Curve(edge)
            allowed = max(reach, 10.0 * BRep_Tool.Tolerance_s(edge))
            for t in np.linspace(curve.FirstParameter(), curve.LastParameter(), 9):
                uv = curve.Value(float(t))
                if surface.Value(uv.X(), uv.Y()).Distance(curve3d.Value(float(t))) > allowed:
                    return None
    except Exception:  # OCCT's Standard_Failure
        return None
    return face


def read_xstep(reader, path: Path, kind: str) -> None:
    """``reader`` (Open CASCADE's STEP or IGES control reader) reads ``path``; one line naming it when it cannot."""
    from OCP.IFSelect import IFSelect_ReturnStatus

    with quiet_stdout():
        status = reader.ReadFile(str(path))
    if status != IFSelect_ReturnStatus.IFSelect_RetDone:
        raise SceneError(path, "", f"not a readable {kind} file (Open CASCADE: {status.name.removeprefix('IFSelect_')}): "
                                   f"truncated, corrupt or not {kind}")


def transferred_shape(reader):
    """The read file's shape (assemblies: a compound of every located instance), transferred quietly."""
    with quiet_stdout():
        reader.TransferRoots()
        return reader.OneShape()


def read_faces(path: Path, shape, name: str, *, unit: str, unit_note: str, what: str,
               skip_bad_faces: bool = False, reversed_faces: list[bool] | None = None,
               trims_onto_edges: bool = False, topology: bool = True) -> CadModel:
    """All faces of ``shape`` (every located instance, in explorer order) as trimmed `NurbsSurface`s.

    ``reversed_faces`` overrides OCCT's face orientation (the .3dm reader knows Rhino's);
    ``trims_onto_edges`` makes trim samples follow the 3D edges (pcurves fitted by ShapeFix); ``topology``
    records each face's B-rep edges on its trim (`face_edges`) for the seam finder. A face
    that fails is a `SceneError` naming it, unless ``skip_bad_faces``: then it is listed in
    ``CadModel.skipped`` and the others are read.
    """
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS
    from tqdm import tqdm

    if shape is None or shape.IsNull():
        raise no_surfaces_error(path, shape, what)
    original_faces = count_entities(shape)["faces"]
    if original_faces == 0 or surfaceless_faces(shape) == original_faces:
        raise no_surfaces_error(path, shape, what)
    shape = rigid_locations(shape)
    converted = convert_shape(shape)
    lo, hi = shape_bounds(shape if converted is None else converted)
    diagonal = float(np.linalg.norm(hi - lo))
    if not (np.isfinite(diagonal) and diagonal > 0):
        raise SceneError(path, "", f"the model's bounding box is empty or not finite ({lo.tolist()} .. {hi.tolist()})")
    if MESH_DEFLECTION * diagonal < SMALLEST_DEFLECTION:
        raise SceneError(path, "", f"the model is {diagonal:.3g} {unit} across, too small for Open CASCADE's mesher "
                                   f"(its deflection, {MESH_DEFLECTION:g} of the model, must be at least "
                                   f"{SMALLEST_DEFLECTION:g} {unit}): scale it up")

    faces, originals = [], []
    for whole, out in ((converted, faces), (shape, originals)):
        explorer = TopExp_Explorer(whole, TopAbs_FACE) if whole is not None else None
        while explorer is not None and explorer.More():
            out.append(TopoDS.Face(explorer.Current()))
            explorer.Next()
    stem = name or path.stem
    # Keys unique per read: a scene that reads one file twice must not join the two copies' faces.
    key_prefix = f"{path}|{stem}|{next(_READS)}"
    if converted is None:  # face by face, each with its own key maker
        faces, key_makers, origin = converted_faces(originals, shape, key_prefix)
    else:
        _, key_of = edge_keys(converted, key_prefix)
        key_makers, origin = [key_of] * len(faces), list(range(len(faces)))
    pieces = np.bincount(origin, minlength=len(originals)) if origin else np.zeros(0, dtype=int)
    surfaces, skipped, reversed_flags, meshed, indices, warnings, no_area = [], [], [], [], [], [], []
    with tqdm(faces, desc=f"reading {path.name}", unit="face", leave=False, file=sys.stderr,
              disable=None if len(faces) > PROGRESS_FACES else True) as bar:
        for position, face in enumerate(bar):
            index = origin[position]  # the face's number in the file (a face converted in pieces: each piece's)
            try:
                if isinstance(face, _Unconvertible):
                    raise FaceError(face.reason)
                reversed_face = (face.Orientation() == TopAbs_REVERSED) if reversed_faces is None else reversed_faces[index]
                face_key_of = key_makers[position]
                if converted is not None and len(originals) == len(faces) and seam_lost(face):
                    face, face_key_of = converted_alone(originals[index], face, face_key_of)
                surface = bspline_of_face(face)
                edges = (face_edges(face, surface, face_key_of, trims_onto_edges, TRIM_TOLERANCE * diagonal)
                         if topology else ())
                trim = trim_of_face(face, surface, TRIM_TOLERANCE * diagonal, trims_onto_edges, edges)
                if trim.roundness(surface.domain) < NO_AREA_ROUNDNESS:  # a sliver of nothing: no face to show
                    no_area.append(index)
                    continue
                # Meshed face by face, its triangulation dropped once read: memory stays that of one face's
                # mesh (the whole shape's at once took 560 MB on a 2000-face plate).
                BRepMesh_IncrementalMesh(face, MESH_DEFLECTION * diagonal, False, MESH_ANGLE, False)
                mesh = mesh_of_face(face, reversed_face)
                BRepTools.Clean_s(face)
            except Exception as exc:  # a face that cannot be read (an OCCT exception too): name it, never a traceback
                reason = str(exc) if isinstance(exc, FaceError) else \
                    f"Open CASCADE failed on it ({type(exc).__name__}: {exc})"
                # A face read in pieces (`_divided_converted`): which piece failed.
                piece = f"its piece [{index}.{position - origin.index(index)}] of {pieces[index]}: " \
                    if pieces[index] > 1 else ""
                if not skip_bad_faces:
                    raise SceneError(path, f"face {index}", f"{piece}{reason} (--skip-bad-faces renders the other "
                                                            f"faces)") from None
                skipped.append((index, piece + reason))
                continue
            # The surface was built before its trim (sampling the trim needs its evaluator); setting the
            # remaining fields in place spares rebuilding its per-span power form.
            name = f"{stem}[{index}]" if pieces[index] == 1 else f"{stem}[{index}.{position - origin.index(index)}]"
            for key, value in (("name", name), ("trim", trim), ("mesh_uv", mesh)):
                object.__setattr__(surface, key, value)
            surfaces.append(surface)
            reversed_flags.append(reversed_face)
            meshed.append(face)
            indices.append(index)
    if not surfaces and not skipped:
        faces = "its only face encloses" if len(no_area) == 1 else f"its {len(no_area)} faces enclose"
        raise SceneError(path, "", f"{faces} no area (each loop runs out along a curve and back): nothing to render")
    if not surfaces:
        raise SceneError(path, "", f"no face of the {len(originals)} could be read (first: face {skipped[0][0]}: "
                                   f"{skipped[0][1]})")
    bounds = faces_bounds(surfaces)
    tight = float(np.linalg.norm(bounds[1] - bounds[0]))
    if np.isfinite(tight) and 0 < tight and REMESH_RATIO * tight < diagonal:
        for surface, face, reversed_face, index in zip(surfaces, meshed, reversed_flags, indices):
            try:
                BRepMesh_IncrementalMesh(face, MESH_DEFLECTION * tight, False, MESH_ANGLE, False)
                finer = mesh_of_face(face, reversed_face)
            except Exception:  # an OCCT exception on the finer mesh: the face read, its first mesh stands
                finer = None
            BRepTools.Clean_s(face)
            if finer is not None:  # an empty finer mesh keeps the first one too
                object.__setattr__(surface, "mesh_uv", finer)
            # The trims too were sampled to the loose box's tolerance (19× the true one on revolved_seam.step).
            try:
                trim = trim_of_face(face, surface, TRIM_TOLERANCE * tight, trims_onto_edges, surface.trim.edges)
                if trim.roundness(surface.domain) < NO_AREA_ROUNDNESS:  # sampled again into nothing: keep the first
                    raise FaceError("its trim loops sampled again enclose no area")
            except Exception as exc:
                # The face read at the loose tolerance: its first trim stands, a valid loop of its edges, but its trim
                # edges are coarser than the reader promises: the user is told which face, and by how much.
                reason = str(exc) if isinstance(exc, FaceError) else f"Open CASCADE: {type(exc).__name__}: {exc}"
                warnings.append((index, f"its trims are kept as first sampled, within {TRIM_TOLERANCE * diagonal:.3g} "
                                        f"of its edges instead of {TRIM_TOLERANCE * tight:.3g} ({diagonal / tight:.3g}× "
                                        f"coarser: the control points' box overstates the faces'), since sampling "
                                        f"them again failed ({reason})"))
                continue
            object.__setattr__(surface, "trim", trim)
        bounds = faces_bounds(surfaces)
    return CadModel(surfaces, unit, unit_note, bounds, len(originals), skipped, reversed_flags, warnings,
                    no_area=no_area)


def faces_bounds(surfaces: list[NurbsSurface]) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box of the trimmed faces: their mesh nodes and trim loops mapped onto the surfaces.

    Tighter than the control points' box (which the camera fit would otherwise frame loosely).
    """
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for surface in surfaces:
        uv = [surface.loop_uv()] if surface.trim is not None else []
        if surface.mesh_uv is not None:
            uv.append(surface.mesh_uv[0])
        if not uv:
            uv = [np.array(surface.domain).T]
        uv = np.concatenate(uv)
        points = surface.evaluate(uv[:, 0], uv[:, 1]).S
        lo, hi = np.minimum(lo, points.min(axis=0)), np.maximum(hi, points.max(axis=0))
    return lo, hi

