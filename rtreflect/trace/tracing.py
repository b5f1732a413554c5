"""Tracing: from rays to exact surface hits (DESIGN.md, "Exact hit").

The BVH hit on the mesh gives a triangle and barycentrics, hence a starting
(u, v). Newton on S(u, v) = O + tD then moves the hit onto the true surface.
The ray condition is written as two equations across the ray,
e1·(S − O) = 0 and e2·(S − O) = 0 with e1, e2 ⊥ D, whose Jacobian is
[[e1·S_u, e1·S_v], [e2·S_u, e2·S_v]]; t = D·(S − O) follows.

**The exact first hit** (DESIGN.md, "Exact hit" and "CAD input"). The first mesh hit need not
carry the first exact hit: where two sheets come closer than the mesh's chord error
(intersecting patches, thin parts, faces meeting at a sharp edge) the nearer exact surface may
belong to a mesh hit a little farther along the ray; a refined point may lie outside its face's
trim; and near a silhouette the mesh is hit where the exact surface is not. So each ray gathers
its **candidates**: mesh hits from the first up to the error band (`BAND_CHORDS` chord errors,
grown at grazing incidence) beyond the nearest exact hit found so far, each found by re-querying
Embree from just beyond the previous one (vectorised over the rays still open, at most
`MAX_CANDIDATES` per ray). Every candidate is refined and classified:

- *valid*: Newton converged near its mesh hit, ahead of the origin, inside its face's trim;
- *miss*: the surface is not there: the refinement left the face (ran off the patch's domain, not
  through a collapsed side, a pole, which is one point in 3D: the search below decides there; or out of its trim) and no neighbouring face across that edge takes it (a restart on the
  nearest face sharing the edge, `Tessellation.across_seam`; where it stops on a closed face's seam,
  again from the seam's other side, `_over_closed_seam`), or a Levenberg–Marquardt search
  for the ray–surface distance stalls at a positive minimum (the ray passes the surface's
  silhouette; Newton on the distance decides where the search runs out of steps, `_passes_by`);
- *unresolved*: neither could be shown (Newton and the search failed in the face's interior, or
  the search, run too where Newton converged on another sheet, converged on it far from its mesh hit). Where the
  search is undecided and the ray does not pass by, Newton goes on from where it stopped (`_newton_on`).
  A Newton stop on a pole left so is tried on a face sharing the pole first (`_across_pole`: a sphere
  cut in two along meridians has its halves meet there, at one point, not along an edge).

Two places beside a candidate's mesh hit are refined too (`_rim_neighbours`: the faces across
its triangle's rim, whose coincident triangle the next query skips, whatever the candidate's status; and beside a
valid one, `_other_root`: the nearer of two crossings of a sheet met at grazing incidence); and past a miss at a positive minimum, the ray is followed on while it
stays within the error band of the face (`_past_minimum`: the surface may dip across it where the mesh does not). A hit
found so is flagged ``aside`` for the second look.

The ray keeps the nearest valid candidate; one whose candidates are all misses or unresolved
continues to the next mesh hit, and to the background when there is none. An unresolved
candidate that could hide a nearer exact hit (its mesh hit before the kept hit plus the error
band) flags the ray as a **fallback**, so the fallback count covers every stored point (or
miss) that might not be the nearest exact surface point on its ray. (Keeping such a
candidate's mesh point instead, as the tracer did before, was wrong on all 48 such samples of
the teapot at 960×540: 31 rays pass the surface there, 17 meet it behind; going on finds all
of them as tessellation 96 does.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import clearance
from .accelerator import Accelerator, MeshHits
from ..clock import NULL_CLOCK, StageClock
from ..geometry.curvature import curvatures, curvatures_at
from ..geometry import surfaces as surface_module  # its DEGENERATE_SINE, VANISHING_PARTIAL: read at call time
from ..geometry.surfaces import SurfaceDerivatives, SurfaceSet, parameter_steps
from ..geometry.tessellation import Tessellation
from ..kernels import nurbs as nurbs_kernel
from ..kernels import rims as rims_kernel
from ..kernels.pixels import scatter_picked, spread_rows

#: Newton stops once the point is this close to the ray, relative to the ray distance (or the part's size),
#: and at least to the hit's distance from the origin: S's coordinates cannot be computed more finely than
#: that (float64 rounding of sums of control points ~1e5 units out), so far from the origin Newton never stopped.
NEWTON_TOLERANCE = 1e-12
NEWTON_MAX_STEPS = 8
#: A refined hit farther than this many chord errors (plus a little) from the mesh hit went to another sheet.
#: Along a ray meeting the surface at angle θ to the normal, the mesh-to-surface gap grows as 1/cos θ:
#: the limit grows with it, up to GRAZING_ALLOWANCE times.
JUMP_LIMIT = 8.0
GRAZING_ALLOWANCE = 10.0
#: Mesh hits examined per ray: the first and those behind it within the error band (or past misses).
#: Bounds the work on a ray through a stack of sheets; a ray still open after them is a fallback. 12, not 8:
#: a ray grazing a fillet meets its mesh many times within the band, grown ×10 at grazing incidence
#: (parts/plate.step at 480×270: 3 edge samples were still open after 8, their hits the same after 12). 24, not
#: 12: the band is the largest chord error's, and on a long part with thin ribs (pythonocc-demos' 11752.stp, an
#: Inventor export 1295 across: a cylinder's chord error 2.4, most faces' 0.03) a ray past a rib's edge met 12
#: mesh hits of the ribs behind it within the band (2 pixels at 480×270; decided, the same hits, after 24).
#: Only rays still open pay for the extra rounds.
MAX_CANDIDATES = 24
#: Planar faces per block of `_coplanar_faces`' box tests (a block × all planar faces booleans, ×3 axes).
COPLANAR_CHUNK = 512
#: A mesh lies within its chord error of the surface along the normal (measured at edge midpoints,
#: which can fall a little short of the true maximum): twice it bounds the mesh-to-surface gap.
BAND_CHORDS = 2.0
#: Relative size of float32 rounding (Embree's coordinates) with margin: ~8 ulps. Where the query for
#: the next mesh hit starts beyond the last one, so Embree does not return the same triangle.
FLOAT32_SLACK = 1e-6
#: Levenberg–Marquardt steps of the search for the ray–surface distance where Newton failed. On the
#: teapot (960×540, s = 4) 60 steps settle 978 of its 993 such rays (30: 928); none of the 870 it
#: calls misses is hit by that patch alone at tessellation 128.
RESCUE_STEPS = 200
#: At a stationary point of |r|² the residual r is normal to the columns of the Jacobian: cosine below this.
STATIONARY_COSINE = 1e-6
#: Marquardt's damping grows ×4 on every step that fails to lower |r|: beyond this (~20 failures in a
#: row) the step is a vanishing fraction of the gradient step and still does not descend: a minimum
#: to float precision (on the 206-face plate, rays passing a fillet's silhouette 0.02 away stalled so).
STALLED_DAMPING = 1e9
#: The search crawls, and stops undecided (`_passes_by` decides), where this many accepted steps in a row lowered |r|
#: by less than the fraction `CRAWL_GAIN`: by a positive minimum where a column of J nearly vanishes (a silhouette
#: along a latitude circle: S_v along the ray, sweep part sphere_pole_view.step) Gauss–Newton's steps creep and
#: `STATIONARY_COSINE` is out of reach. A search heading for a hit (|r| → 0) gains far more per step: at 480×270 over
#: scenes/, parts/ and the five sweep parts it stops none that the 200 steps converge, only some they find stationary
#: (sphere_pole_view, teapot: 1e-3 and 1e-6 stop about as many), every pixel and AOV stays the same; sphere_pole_view 1.75× less CPU.
CRAWL_STEPS = 10
CRAWL_GAIN = 1e-4

#: Newton steps on the ray–surface distance where the search (`_rescue`) stops undecided (`_passes_by`): it starts
#: close to the minimum, where Newton converges quadratically.
SETTLE_STEPS = 8

#: Neighbouring faces tried in turn for a hit that ran off its face: where several faces meet at a
#: corner their boundary vertices coincide, and the nearest need not be the one the ray goes on to.
SEAM_TRIES = 3
#: Reach of the second and third tries beyond the first neighbour's vertex, in its longest mesh edges: the faces
#: meeting at a corner share its vertex, their meshes' nearest vertices to it lie within an edge of it. Without it
#: the third try on parts/plate.step's top face (longest edge 100) searched 3.5–4 units away, for 11,600 rays at
#: 960×540 and no win (430 rays now).
SEAM_CORNER_EDGES = 1.0
#: Where more faces than `SEAM_TRIES` meet at a B-rep vertex (a pyramid's apex; a five-pointed star's has ten), the
#: nearest boundary vertices of the other faces are all that corner's, at one distance from the point to rounding, and
#: which come first is arbitrary (the k-d walk's order): star_apex.step's ray off one face's side 2.3 from the apex
#: tried three faces meeting only at the apex, never the one across that side, and went through the part to its base
#: 18 behind. Past `SEAM_TRIES` the tries go on while the next neighbour's vertex lies at the previous one's distance
#: to within `CORNER_TIE` of the part's extent (the reader's trim tolerance, `occt.TRIM_TOLERANCE`: the faces' meshes
#: put a shared vertex there within it), up to `SEAM_CORNER_TRIES` in all.
CORNER_TIE = 1e-5
SEAM_CORNER_TRIES = 16

#: `_rim_neighbours` looks across the rim where the mesh hit lies within this many times the two faces' summed
#: chord errors of a rim edge: each mesh lies within its chord error of the shared edge, ×2 as `BAND_CHORDS`
#: (the measured chord error can fall short).
RIM_REACH_CHORDS = 2.0
#: A closed face's seam is a crease where its normals either side differ by more than this angle (radians,
#: `_seam_twins`): two sheets meet there at an edge, and `_rim_neighbours` refines the sheet across it as a face across
#: a rim (a wing skin lofted as one face through closed sections, its seam on the sharp trailing edge, a wedge of
#: ~9°: rays met the mesh on one side, Newton settled on that sheet, the nearer crossing 0.04 before it lay across).
SEAM_CREASE = 1e-3
#: A boundary vertex lies on its face's seam where its u (or v) is within this share of the domain of the domain's end.
SEAM_MATCH = 1e-9
#: Boundary vertices `_corner_faces` asks the k-d tree for around each boundary vertex: the faces meeting at a
#: B-rep vertex (3 at a box's corner, 4–6 at a fillet's setback or a cone's apex) with room for a pole's coincident
#: vertices of one face.
CORNER_VERTICES = 8
#: Below this |N·D| a valid hit may be the farther of two close crossings of its sheet: the nearer one is
#: sought (`_other_root`). As the second look's grazing threshold (78°): ~6% of the teapot's hits at 960×540.
OTHER_ROOT_COS = 0.2
#: At any |N·D| the nearer crossing is sought too where the ray's chord through the sheet's cap between its two
#: crossings (depth (N·D)²/2κ) is no deeper than this many chord errors of the face: the mesh, within its chord
#: error of the sheet, need not reach into such a cap (instances.step's sphere-corner fillets, r = 4, chord error
#: 0.35: entries at |N·D| 0.22 and 0.32, caps 0.10 and 0.21 deep, were stored at their exits). ×2 as the second
#: look's shell (`secondlook.SHELL_CHORDS`): the chord error is sampled, a triangle's interior may stray farther.
OTHER_ROOT_CHORDS = 2.0
#: The prefilter of `_nearer_on_parabola` grows the largest |κ| it reads by this share: the Newton kernel's curvatures
#: may be those of a point one last short step before the hit (`kernels.nurbs.taylor_finish_lanes`; within 4e-5 of
#: the largest |κ| on the shipped scenes and parts), and a bound must not drop a ray the hit's own would keep.
CURVATURE_SLACK = 1e-3
#: Where Newton from the predicted other crossing fails, leaves the face or goes back to the kept hit, the search for
#: the ray's distance (`_rescue`) from the same start, at most this many steps: the sheet is no parabola along the
#: ray (a wave), and the descent from the predicted start runs down into the dip that prediction stood for
#: (rational_high.step, a grazing close-up: 5 steps needed, 8 enough; its cost on parts/plate.step at 960×540,
#: 1,098 such rays, 12 ms).
OTHER_ROOT_RESCUE_STEPS = 30
#: Rounds of `_other_root`: a crossing it finds has a nearer one of its own where it is a dip's far side (the second
#: round finds it; a third for margin, run only on the rays the second replaced).
OTHER_ROOT_ROUNDS = 3

#: `_past_minimum` follows the ray on from a positive minimum of its distance to the face in steps of this fraction of
#: the face's longest mesh edge: the two hidden entries it was made for lay 0.62 and 0.41 edges past their minimum
#: (torus_hole_view.step, pipe_spline.step at 480×270: 2.5 and 1.6 steps); a dip below the ray shorter than a step
#: can fall between two steps' points.
PAST_MINIMUM_EDGES = 0.25
#: At most this many steps (4 mesh edges), all rows together: over scenes/, parts/ and the sweep parts at 480×270 the
#: crossings it found lay at most 12.4 steps past their minimum; its cost is bounded whatever the ray.
PAST_MINIMUM_STEPS = 16
#: Gauss–Newton steps for the surface point nearest each step's ray point, from the previous step's: the heights lie
#: within the band, where the iteration converges fast. Over those inputs 1 step found 616 crossings, 2 found 625 and
#: 3 found 629 (the same pixel-centre hits each way); 2: the walk's CPU 4 ms on the teapot, 16 ms on parts/plate.step,
#: 27 ms on torus_hole_view.step at 480×270 (3: 7, 21, 37 ms).
FOOT_ITERATIONS = 2

VALID, MISS, UNRESOLVED = 0, 1, 2


def float32_rounding(tessellation: Tessellation) -> float:
    """Float32 rounding of the scene's coordinates, with margin: `FLOAT32_SLACK` × (extent + largest |coordinate|).

    Embree holds the mesh and the rays in float32 (24 bits: a relative 6e-8 of a coordinate's magnitude), and a
    mesh hit's t comes back so rounded. A coordinate is at most the mesh's largest |coordinate| (the BVH's centred
    ones are smaller: an upper bound) and a ray distance across the part at most its extent, so two points closer
    than this may be one to Embree: the step past a mesh hit for the next query (`trace`, the second look's shell
    walk), the reach within which another face's mesh may coincide with the hit's (`_rim_neighbours`,
    `_corner_faces`), and the flatness Embree cannot resolve (`_net_planes`, `secondlook.flat`,
    `secondlook._rim_boxes`). Computed once per tessellation, on first use (kept in its ``__dict__``, as
    `_rim_planes` is).
    """
    cached = tessellation.__dict__.get("_float32_rounding")
    if cached is None:
        cached = tessellation.__dict__["_float32_rounding"] = (
            FLOAT32_SLACK * (tessellation.extent + float(np.abs(tessellation.vertices).max(initial=0.0))))
    return cached


@dataclass
class Hits:
    """Exact hits of N rays; rows where ``hit`` is False hold NaN (patch −1)."""

    hit: np.ndarray  # bool
    patch: np.ndarray  # int, −1 on a miss
    u: np.ndarray
    v: np.ndarray
    t: np.ndarray  # ray distance
    P: np.ndarray  # (N, 3) exact surface point S(u, v)
    N: np.ndarray  # (N, 3) exact unit normal, turned to face the incoming ray
    fallback: np.ndarray  # bool: a mesh hit nearer than the stored hit (or miss) could not be decided (module doc)
    #: bool: the stored hit was not the refinement of a mesh hit but found beside it (`_other_root`,
    #: `_rim_neighbours`, `_past_minimum`): the mesh did not lead there, so the second look (secondlook.py) traces the
    #: ray again.
    aside: np.ndarray
    #: (N, 3) S_u and S_v at (u, v), as the kernel that found the hit had them (NaN on the mesh-normals path).
    Su: np.ndarray
    Sv: np.ndarray
    #: (N, 4) K, H, κ1, κ2 at the hit, signed with N as stored, where the tracer already had them (the Newton kernel's
    #: order-2 evaluation, `kernels.nurbs.CURVATURE_EVALUATION`: at the hit or one last step of ≤ 1e-6 of a knot span
    #: before it, `kernels.nurbs.taylor_finish_lanes`; or `_other_root`'s prefilter: the same formulas), else NaN: the
    #: AOV stage computes only the NaN rows.
    curvature: np.ndarray
    #: |N·D| at the hit (the cosine of the incidence, as the tracer computed it with N), NaN on a miss
    cos: np.ndarray

    #: The (N, 3) and (N, 4) fields, in the order the tracer stores them (`trace`).
    ROW_FIELDS = ("P", "Su", "Sv", "N", "curvature")

    def rows(self) -> tuple[np.ndarray, ...]:
        """The `ROW_FIELDS` arrays, in that order."""
        return tuple(getattr(self, name) for name in self.ROW_FIELDS)

    def replace_rows(self, rows: np.ndarray, other: "Hits", pick: np.ndarray) -> None:
        """Rows ``rows`` become ``other``'s rows ``pick`` (an index array or mask of its rows), in place: every field
        but `fallback`, which says how the search went, not what it found (the second look's nearer hits)."""
        for name in self.__dataclass_fields__:
            if name != "fallback":
                getattr(self, name)[rows] = getattr(other, name)[pick]

    @classmethod
    def blank(cls, n: int, hit: np.ndarray, rows: bool = True) -> "Hits":
        """Rows for n rays flagged ``hit``, every value still that of a miss: to be filled in where hit.

        ``rows=False``: P, N, S_u, S_v and the curvatures (`ROW_FIELDS`) left uninitialised, for a caller that writes
        each of their rows (`trace`'s first query: `kernels.pixels.spread_rows`)."""
        new = (lambda shape: np.full(shape, np.nan)) if rows else np.empty  # noqa: E731
        return cls(hit, np.full(n, -1), np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan),
                   new((n, 3)), new((n, 3)), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool),
                   new((n, 3)), new((n, 3)), new((n, 4)), np.full(n, np.nan))


def facing(normals: np.ndarray, directions: np.ndarray, cosine: np.ndarray | None = None) -> np.ndarray:
    """The normals turned to face the incoming rays, in place: the surface is a two-sided mirror.

    ``cosine``: n·D where already known (the tracer's kernel gives it), else computed.
    """
    if cosine is None:
        cosine = np.einsum("ij,ij->i", normals, directions)
    normals[cosine > 0] *= -1.0
    return normals


def refine(surfaces: SurfaceSet, patch, u, v, origins, directions, t_mesh, tolerance_distance):
    """Newton on S(u, v) = O + tD from given (u, v), by the compiled kernel `kernels.nurbs.refine_mesh_hits`.

    Returns (u, v, derivatives at the final (u, v), converged); the derivatives serve the normals.
    The tolerance as for a mesh hit: `NEWTON_TOLERANCE` × max(t_mesh, tolerance_distance, |O + t_mesh D|).
    """
    return refine_all(surfaces, patch, u, v, origins, directions, t_mesh, tolerance_distance)[:4]


def refine_all(surfaces: SurfaceSet, patch, u, v, origins, directions, t_mesh, tolerance_distance):
    """`refine`, with what the kernel also tells: (u, v, derivatives, converged, on the domain's edge (Newton
    ran off it), unit normal n (not turned), n·D). The kernel's curvatures are not kept: these are the rare paths'
    points, whose rows the callers reset (`_candidates`), and their few order-2 evaluations cost little."""
    n = len(u)
    table = surfaces.table
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    pk = np.array(patch, dtype=np.int64)
    us, vs = np.array(u, dtype=np.float64), np.array(v, dtype=np.float64)
    ur, vr, t, cosine = (np.empty(n) for _ in range(4))
    S, Su, Sv, normal = (np.empty((n, 3)) for _ in range(4))
    converged, near, edge, degenerate = (np.empty(n, dtype=bool) for _ in range(4))
    no_mesh = np.full(n, -1, dtype=np.int64)  # prim < 0: start from (patch, u, v) as given
    nurbs_kernel.refine_mesh_hits(
        *table.args, table.scale, *_NO_TRIANGLES, np.zeros(len(table.domain)), no_mesh, np.zeros(n), np.zeros(n),
        f64(origins), f64(directions), f64(t_mesh), float(tolerance_distance), NEWTON_TOLERANCE, NEWTON_MAX_STEPS,
        JUMP_LIMIT, GRAZING_ALLOWANCE, surface_module.DEGENERATE_SINE, surface_module.VANISHING_PARTIAL,
        pk, us, vs, ur, vr, S, Su, Sv, t, normal, cosine, converged, near, edge, degenerate, np.empty((n, 4)))
    return ur, vr, SurfaceDerivatives(S, Su, Sv), converged, edge, normal, cosine


#: `refine`'s stand-in for the tessellation's (faces, vertex_uv, face_patch): no mesh hit to start from.
_NO_TRIANGLES = (np.zeros((0, 3), dtype=np.int64), np.zeros((0, 2)), np.zeros(0, dtype=np.int64))


def _near_mesh_hit(derivs: SurfaceDerivatives, patch, O, D, t_mesh, band) -> tuple[np.ndarray, np.ndarray]:
    """Whether refined hits lie ahead and within reach of the mesh hit (not on another sheet), and their t = (S − O)·D.

    By the kernel `kernels.nurbs.near_at` (the fused `refine_mesh_hits` applies it to the first refinement);
    ``band`` per patch: the reach of `JUMP_LIMIT` chord errors.
    """
    n = len(patch)
    near, t = np.empty(n, dtype=bool), np.empty(n)
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    nurbs_kernel.near_mesh_hits(np.ascontiguousarray(patch, dtype=np.int64), f64(derivs.S), f64(derivs.Su),
                                f64(derivs.Sv), f64(O), f64(D), f64(t_mesh), band, JUMP_LIMIT, GRAZING_ALLOWANCE, near, t)
    return near, t


def _rescue(surfaces: SurfaceSet, patch, u, v, origins, directions, tol, steps: int | None = None):
    """Levenberg–Marquardt on the ray residual r = (e1·(S − O), e2·(S − O)) where Newton failed.

    A descent on |r|² from the mesh hit's (u, v), damped by Marquardt's diagonal scaling
    (JᵀJ + λ diag JᵀJ), which makes it invariant under rescaling u or v. It either reaches
    |r| ≤ tol (the ray meets the surface: Newton's answer), or stalls where r is normal to the
    surface's tangent plane, or where no step lowers |r| (`STALLED_DAMPING`), with |r| > tol: a
    positive local minimum of the distance, the ray passes the surface. Where it crawls (`CRAWL_STEPS`,
    `CRAWL_GAIN`) it stops undecided, for `_passes_by`. By the compiled kernel
    `kernels.nurbs.rescue`, per ray. Returns (u, v, derivatives, converged, stationary, on the domain edge).
    ``steps``: at most that many steps (default `RESCUE_STEPS`, read when called: tests switch the search off;
    the second look's shell starts take fewer).
    """
    n = len(u)
    u, v = np.array(u, dtype=np.float64), np.array(v, dtype=np.float64)
    S, Su, Sv = (np.empty((n, 3)) for _ in range(3))
    converged, stationary, edge = (np.empty(n, dtype=bool) for _ in range(3))
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    nurbs_kernel.rescue(*surfaces.table.args, np.ascontiguousarray(patch, dtype=np.int64), u, v, f64(origins),
                        f64(directions), f64(tol), RESCUE_STEPS if steps is None else steps, STATIONARY_COSINE, STALLED_DAMPING, CRAWL_STEPS,
                        CRAWL_GAIN, S, Su, Sv,
                        converged, stationary, edge)
    return u, v, SurfaceDerivatives(S, Su, Sv), converged, stationary, edge


def _passes_by(surfaces: SurfaceSet, patch, u, v, O, D, tol) -> np.ndarray:
    """True where the ray passes the surface at a positive local minimum of its distance, found by Newton from
    (u, v) where the search (`_rescue`) left off without deciding.

    The search is Gauss–Newton, JᵀJ for the Hessian: at a positive minimum it converges only linearly, so
    slowly that it crawls (`CRAWL_GAIN`) or `RESCUE_STEPS` end short of `STATIONARY_COSINE` (parts/plate.step at 480×270: all 7 of its
    fallbacks, rays passing a fillet's silhouette 0.014–0.06 away, stationary after 1,000–5,000 steps or not
    at all). Newton on f = ½|r|², r = (S − O) − ((S − O)·D) D the point's offset from the ray, takes the full
    Hessian: gradient (r·S_u, r·S_v), Hessian [[|S_u⊥|² + r·S_uu, S_u⊥·S_v⊥ + r·S_uv], [·, |S_v⊥|² + r·S_vv]]
    with S_u⊥ = S_u − (S_u·D) D. A point where the Hessian is positive definite, |r| > tol and the cosine of
    (r·S_u, r·S_v) against |r| (|S_u⊥|² + |S_v⊥|²)^½ at most `STATIONARY_COSINE` is such a minimum: the search's own
    test (`kernels.nurbs.stationary_at`; its Jᵀr and |J| in the frame (e1, e2) across the ray are these).
    `SETTLE_STEPS` steps, the test at the last point: by the compiled kernel `kernels.nurbs.passes_by`, per ray (in
    numpy, ~25 array operations a step cost ~3.6 ms a call whatever its rows: 22 calls per plate render at 960×540).
    """
    passes = np.empty(len(patch), dtype=bool)
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    nurbs_kernel.passes_by(*surfaces.table.args, np.ascontiguousarray(patch, dtype=np.int64), f64(u), f64(v), f64(O),
                           f64(D), f64(tol), SETTLE_STEPS, STATIONARY_COSINE, passes)
    return passes


def _normals(surfaces: SurfaceSet, patch, derivs: SurfaceDerivatives, D, rows, normal, cosine, degenerate) -> None:
    """Unit normals n = (S_u × S_v)/|S_u × S_v| (not turned), n·D and the degenerate flag of ``rows``, in place.

    For the rows whose hit a rare path (rescue, seam restart, `_other_root`, `_rim_neighbours`) replaced:
    the same kernel formula (`kernels.nurbs.normal_at`) as the fused first refinement.
    """
    if len(rows) == 0:
        return
    n = len(rows)
    out, cos, bad = np.empty((n, 3)), np.empty(n), np.empty(n, dtype=bool)
    table = surfaces.table
    nurbs_kernel.normals_and_cosines(table.domain, table.scale, np.ascontiguousarray(patch[rows], dtype=np.int64),
                                     np.ascontiguousarray(derivs.Su[rows]), np.ascontiguousarray(derivs.Sv[rows]),
                                     np.ascontiguousarray(D[rows]), surface_module.DEGENERATE_SINE,
                                     surface_module.VANISHING_PARTIAL, out, cos, bad)
    normal[rows], cosine[rows], degenerate[rows] = out, cos, bad


@dataclass
class _Candidates:
    """Mesh hits of some rays refined onto the exact surface and classified (VALID, MISS, UNRESOLVED)."""

    status: np.ndarray
    patch: np.ndarray
    u: np.ndarray
    v: np.ndarray
    t: np.ndarray  # exact t where VALID, the mesh hit's t otherwise
    derivs: SurfaceDerivatives
    normal: np.ndarray  # (S_u × S_v)/|S_u × S_v|, not turned to the ray (`kernels.nurbs.normal_at`)
    cosine: np.ndarray  # normal·D
    degenerate: np.ndarray  # bool: normal undefined there (the limit is taken: `SurfaceSet.normals`)
    start_u: np.ndarray  # the mesh hit's interpolated (u, v): kept by an unresolved candidate
    start_v: np.ndarray
    aside: np.ndarray  # bool: VALID by `_other_root`, `_rim_neighbours`, `_crossing_on_face` or `_past_minimum`
    #: (n, 4) K, H, κ1, κ2 for ``normal`` turned to face the ray where known (the Newton kernel's, or `_other_root`'s
    #: prefilter's), else NaN
    curvature: np.ndarray
    #: bool: VALID by `_crossing_on_face` (the other crossing of a sheet the refinement left) or `_past_minimum`
    crossed: np.ndarray


def _candidates(tessellation: Tessellation, surfaces: SurfaceSet, O, D, prim, b1, b2, tm) -> _Candidates:
    """Refine and classify one mesh hit per ray (module doc): Newton, then the seam restart and the rescue.

    The common case in one compiled pass per ray (`kernels.nurbs.refine_mesh_hits`: start, Newton, the
    near-mesh-hit test, t, the domain-edge test, the unit normal and n·D); the rare paths (rescue, seam
    restart, `_other_root`, `_rim_neighbours`) in numpy on the rays that need them.
    """
    n = len(prim)
    band = tessellation.chord_error + FLOAT32_SLACK * tessellation.extent  # per patch: `JUMP_LIMIT`'s chord error
    # The reach of the near-mesh-hit test (`_near_mesh_hit`) per patch: unbounded on a planar face (`_net_planes`), one
    # sheet the ray crosses once, so a converged point ahead on it is that crossing however far float32 rounding put
    # the mesh hit: at grazing incidence that distance grows as 1/|n·D| past the test's `GRAZING_ALLOWANCE` (the sweep's
    # filleted_block.step, a close-up at fov 0.2° from 2.7e-4 off its side face y = 0: rays at |n·D| ~ 1e-4 met the
    # face's mesh 0.007 from their crossing, were left unresolved and went on to the fillet 14 behind, 600 pixels).
    near_reach = np.where(_net_planes(tessellation, surfaces)[3], np.inf, band)
    pk = np.empty(n, dtype=np.int64)
    us, vs, ur, vr, tr, cosine = (np.empty(n) for _ in range(6))
    S, Su, Sv, normal = (np.empty((n, 3)) for _ in range(4))
    conv, near, edge, degenerate = (np.empty(n, dtype=bool) for _ in range(4))
    curvature = np.empty((n, 4))  # K, H, κ1, κ2 at the kernel's hits, facing the ray (NaN where it had none)
    table = surfaces.table
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    nurbs_kernel.refine_mesh_hits(
        *table.args, table.scale, *tessellation.start_arrays, near_reach, np.ascontiguousarray(prim, dtype=np.int64),
        f64(b1), f64(b2), f64(O), f64(D), f64(tm), tessellation.extent, NEWTON_TOLERANCE, NEWTON_MAX_STEPS,
        JUMP_LIMIT, GRAZING_ALLOWANCE, surface_module.DEGENERATE_SINE, surface_module.VANISHING_PARTIAL,
        pk, us, vs, ur, vr, S, Su, Sv, tr, normal, cosine, conv, near, edge, degenerate, curvature)
    derivs = SurfaceDerivatives(S, Su, Sv)
    status = np.full(n, UNRESOLVED)
    inside = surfaces.on_face(pk, ur, vr)
    status[conv & near & inside] = VALID
    # Newton stopped on a collapsed side (a pole) has not left the face: the side is one point in 3D, and near it
    # Newton's steps in the parameter along it are wild (|S_u| → 0). The search decides there, as inside the face.
    at_pole = _stopped_at_pole(surfaces, pk, ur, vr, edge)
    pole = np.flatnonzero(at_pole)
    off = edge & ~at_pole
    left = off | (conv & near & ~inside)  # ran off the face: the ray may go on on a neighbour, else it misses
    # Newton failed inside the face, or went to another sheet: search for the ray's distance to the surface instead.
    stuck = np.flatnonzero(~(conv & near) & ~off)
    pole_point = derivs.S[pole].copy()  # where Newton stopped on a pole (`_across_pole` starts there)
    restarted, passed = [stuck], []
    if len(stuck):
        newton_u, newton_v = ur[stuck], vr[stuck]  # where Newton stopped (the search's results replace them)
        tol = _search_tolerance(tm[stuck], tessellation.extent)
        u2, v2, d2, ok2, flat2, edge2 = _rescue(surfaces, pk[stuck], us[stuck], vs[stuck], O[stuck], D[stuck], tol)
        near2, t2 = _near_mesh_hit(d2, pk[stuck], O[stuck], D[stuck], tm[stuck], near_reach)
        in2 = surfaces.on_face(pk[stuck], u2, v2)
        ur[stuck], vr[stuck], tr[stuck] = u2, v2, t2
        for have, new in zip(derivs[:3], d2[:3]):
            have[stuck] = new
        status[stuck[ok2 & near2 & in2]] = VALID
        status[stuck[flat2]] = MISS
        passed = [stuck[flat2]]  # misses at a positive minimum of the ray's distance: the surface may dip past it
        left[stuck[edge2 | (ok2 & near2 & ~in2)]] = True
        # The search slows to a crawl by a positive minimum (its steps ignore the surface's curvature): Newton there.
        undecided = np.flatnonzero(~ok2 & ~flat2 & ~edge2)
        if len(undecided):
            rows = stuck[undecided]
            passes = _passes_by(surfaces, pk[rows], u2[undecided], v2[undecided], O[rows], D[rows], tol[undecided])
            status[rows[passes]] = MISS
            passed.append(rows[passes])
            _newton_on(surfaces, rows[~passes], newton_u[undecided[~passes]], newton_v[undecided[~passes]], O, D, tm,
                       near_reach, tessellation.extent, status, pk, ur, vr, tr, derivs)
        # A pole stop still unresolved (the search undecided, or converged on the face far from the mesh hit: on
        # another crossing of the ray) is tried on the face sharing the pole.
        at_pole = (status[pole] == UNRESOLVED) & ~left[pole]
        restarted.append(_across_pole(tessellation, surfaces, pole[at_pole], pole_point[at_pole], O, D, tm, band,
                                      status, pk, ur, vr, tr, derivs))
    seam = np.flatnonzero(left)
    status[seam] = MISS
    # From the edge point Newton stopped at (a domain edge), or the mesh hit (a trim edge, where the
    # converged point lies on the surface's extension beyond the face).
    at = np.where(edge[seam, None], derivs.S[seam], O[seam] + tm[seam, None] * D[seam])
    tried = np.zeros((len(seam), 0), dtype=int)  # neighbours tried so far (the patch itself: by `across_seam`)
    # A neighbour shares the edge: its boundary vertex lies within a mesh edge of the point.
    reach = 2.0 * tessellation.edge_length[pk[seam]]
    # Every row that left its face, and that face: its sheet's other crossing may lie on it (`_crossing_on_face`).
    gone, gone_patch = seam, pk[seam]
    last = np.full(len(seam), np.nan)  # the distance of the previous try's vertex
    tie = CORNER_TIE * tessellation.extent
    for attempt in range(SEAM_CORNER_TRIES):
        if len(seam) == 0:
            break
        pn, un, vn, gap = tessellation.across_seam(at, pk[seam], tried, _seam_sides(surfaces, pk[seam], ur[seam], vr[seam]),
                                                   reach)
        close = pn >= 0
        if attempt >= SEAM_TRIES:  # only at a corner more faces share (`SEAM_CORNER_TRIES`)
            close &= np.abs(gap - last) <= tie
        seam, at, tried, reach, pn, un, vn, gap = (x[close] for x in (seam, at, tried, reach, pn, un, vn, gap))
        if attempt == 0:
            # The faces meeting at a corner have their boundary vertices there within a mesh edge of each other: a
            # later try's lies within the first neighbour's edge length of its vertex (`SEAM_CORNER_EDGES`).
            reach = np.minimum(reach, gap + SEAM_CORNER_EDGES * tessellation.edge_length[pn])
        # Only the restarts that may win (`_may_win_restart`): the rest go on to the next try as a loss would.
        go = np.flatnonzero(_may_win_restart(tessellation, surfaces, seam, pn, O, D, tm, band))
        ray = seam[go]
        u3, v3, d3, ok, edge3 = refine_all(surfaces, pn[go], un[go], vn[go], O[ray], D[ray], tm[ray],
                                           tessellation.extent)[:5]
        _over_closed_seam(surfaces, pn[go], u3, v3, d3, ok, edge3, O[ray], D[ray], tm[ray], tessellation.extent)
        _search_at_pole(surfaces, pn[go], un[go], vn[go], u3, v3, d3, ok, edge3, O[ray], D[ray], tm[ray],
                        tessellation.extent)
        near3, t3 = _near_mesh_hit(d3, pn[go], O[ray], D[ray], tm[ray], near_reach)
        ok &= near3 & surfaces.on_face(pn[go], u3, v3)
        ok3 = np.zeros(len(seam), dtype=bool)
        ok3[go] = ok
        won = ray[ok]
        _store(won, ok, pn[go], u3, v3, t3, d3, pk, ur, vr, tr, derivs)
        status[won] = VALID
        restarted.append(won)
        seam, at, reach, tried = seam[~ok3], at[~ok3], reach[~ok3], np.column_stack([tried[~ok3], pn[~ok3]])
        last = gap[~ok3]
    # A mesh hit by a pole that nothing above resolved onto its face: the search again from the meridian towards it.
    restarted.append(_off_pole(tessellation, surfaces, np.flatnonzero(status != VALID), prim, O, D, tm, band, status, pk,
                               ur, vr, tr, derivs))
    crossed = _crossing_on_face(tessellation, surfaces, gone, gone_patch, O, D, tm, us, vs, band, status, pk, ur, vr, tr,
                                derivs)
    restarted.append(crossed)
    passed = np.concatenate([np.zeros(0, dtype=np.int64), *passed])
    dipped = _past_minimum(tessellation, surfaces, passed[(status[passed] == MISS) & ~left[passed]], O, D, band, status,
                           pk, ur, vr, tr, derivs)
    restarted.append(dipped)
    restarted = np.concatenate(restarted)
    _normals(surfaces, pk, derivs, D, restarted, normal, cosine, degenerate)
    curvature[restarted] = np.nan  # not the kernel's point any more
    aside = np.zeros(n, dtype=bool)
    aside[crossed] = True
    aside[dipped] = True
    _other_root(tessellation, surfaces, O, D, status, pk, ur, vr, tr, derivs, normal, cosine, aside, curvature)
    beside, beside_crossed = _rim_neighbours(tessellation, surfaces, O, D, prim, tm, status, pk, ur, vr, tr, derivs, band,
                                             aside)
    beside = np.concatenate([beside, _coplanar_neighbours(tessellation, surfaces, O, D, prim, tm, status, pk, ur, vr,
                                                          tr, derivs, band, aside)])
    moved = np.flatnonzero(aside)
    _normals(surfaces, pk, derivs, D, moved, normal, cosine, degenerate)
    curvature[moved] = np.nan  # found beside: not the point the curvatures were taken at
    curvature[degenerate] = np.nan  # the normal kept there is the limit (`trace`), not the one they were taken with
    t = np.where(status == VALID, tr, tm)
    crossed_rows = np.zeros(n, dtype=bool)
    crossed_rows[crossed] = status[crossed] == VALID  # (`_other_root` may have replaced it since: still on its sheet)
    crossed_rows[dipped] = True  # found off the mesh as `_crossing_on_face`'s: `trace` weighs it so
    crossed_rows[beside] = False  # another face's hit now: `trace` weighs it as any mesh-led one
    crossed_rows[beside_crossed] = True  # ... but for one its predicted crossing found, as `_crossing_on_face`'s
    return _Candidates(status, pk, ur, vr, t, derivs, normal, cosine, degenerate, us, vs, aside, curvature,
                       crossed_rows)


def _newton_on(surfaces: SurfaceSet, rows, u, v, O, D, tm, near_reach, extent, status, pk, ur, vr, tr, derivs) -> None:
    """Newton again from where the first `NEWTON_MAX_STEPS` stopped (``u``, ``v``), on rows the search left undecided
    and not passing by (`_passes_by`); VALID in place where it converges near the mesh hit on the face.

    A mesh hit at the very point where the ray is tangent to the sheet between its two close crossings starts Newton
    where its Jacobian is singular: the first step overshoots, and the steps left are too few (sphere.3dm, a close-up
    at fov 0.06° along its seam meridian, rays crossing the sheet at |n·D| ≤ 0.003 with the seam's mesh hit at the
    tangent point: 252 of 2,048 rays ended 2.6e-5 from the ray after 8 steps, the search crawled off, and they were
    fallbacks showing background where OCCT meets the sphere; a second run converged in 2 steps)."""
    if len(rows) == 0:
        return
    u3, v3, d3, ok3 = refine(surfaces, pk[rows], u, v, O[rows], D[rows], tm[rows], extent)
    near3, t3 = _near_mesh_hit(d3, pk[rows], O[rows], D[rows], tm[rows], near_reach)
    ok3 &= near3 & surfaces.on_face(pk[rows], u3, v3)
    won = rows[ok3]
    _store(won, ok3, pk[rows], u3, v3, t3, d3, pk, ur, vr, tr, derivs)
    status[won] = VALID


def _store(won, pick, patch, u, v, t, derivatives: SurfaceDerivatives, pk, ur, vr, tr, derivs: SurfaceDerivatives):
    """A refinement's points ``pick`` (indices or a mask of its rows: face ``patch``, (u, v), ray distance t, S and its
    first derivatives) stored as the candidates of rays ``won``, in place; the caller flags them (VALID, ``aside``)."""
    pk[won], ur[won], vr[won], tr[won] = patch[pick], u[pick], v[pick], t[pick]
    for have, new in zip(derivs[:3], derivatives[:3]):
        have[won] = new[pick]


def _rim_reach(band, allowance, skip):
    """How far from its mesh hit (in t) a rim neighbour's hit may win (`_rim_neighbours`): `BAND_CHORDS` of the
    neighbour's chord errors, grown as 1/cos θ there (``allowance``, at most `GRAZING_ALLOWANCE`: the filters
    `_may_win_on_plane` and `_may_win_in_hull` take that largest), plus the step the next mesh query skips."""
    return BAND_CHORDS * band * allowance + skip


def _may_win_restart(tessellation: Tessellation, surfaces: SurfaceSet, rows, pn, O, D, tm, band) -> np.ndarray:
    """Which seam restarts (ray ``rows`` of the candidates' arrays O, D, tm, on neighbour ``pn``) may win: False only
    where no point the restart could converge to passes its tests, whatever Newton (or `_over_closed_seam`) does.

    A winning point S is converged (within Newton's tol of the ray), ahead (t > 0) and near the mesh hit
    M = O + t_mesh D: |S − M| within the kernel's reach at the point's incidence (`_near_mesh_hit`,
    `kernels.nurbs.jump_reach`), at most its reach at a grazing ray (cos θ = 0: `JUMP_LIMIT` × band[k] ×
    `GRAZING_ALLOWANCE`), so |t − t_mesh| ≤ |S − M| lies within that largest reach; no kept hit bounds it. The
    same bounds as `_rim_neighbours`' rows with that reach: a planar neighbour's crossing (`_may_win_on_plane`), a
    curved one's control net hull (`_may_win_in_hull`). On the plate at 960×540 it drops 2,182 of 55,509 restarts
    (all of them losers): that reach, 80 chord errors of the neighbour (2.4–6.4 there), spans a hole's fillet
    (radius 0.8), so the walls tried from the top plane over a hole (10,209, 949 win) mostly stay in their nets' hulls.
    """
    reach = np.empty(len(band))
    # The kernel's own reach (one formula with `_near_mesh_hit`'s test) at cos θ = 0, where it is largest.
    nurbs_kernel.jump_reaches(np.ascontiguousarray(band, dtype=np.float64), 0.0, JUMP_LIMIT, GRAZING_ALLOWANCE, reach)
    kept = np.full(len(tm), np.inf)  # a restart replaces a miss: no nearer hit bounds it
    may = _may_win_on_plane(tessellation, surfaces, pn, O[rows], D[rows], tm[rows], kept[rows], reach, 0.0)
    return may & _may_win_in_hull(tessellation, surfaces, rows, pn, O, D, tm, kept, reach, 0.0)


#: Levenberg–Marquardt steps of `_across_pole`'s search on the face sharing the pole: from the pole, one point in 3D
#: with the hit beside it, it converges in a few (a sphere cut in two: 20 reach the hit), as the second look's
#: `secondlook.SHELL_RESCUE_STEPS` from its shell starts.
POLE_RESCUE_STEPS = 60


def _off_pole(tessellation: Tessellation, surfaces: SurfaceSet, rows, prim, O, D, tm, band, status, pk, ur, vr, tr,
              derivs) -> np.ndarray:
    """Candidates ``rows`` (not VALID) whose mesh hit lies on a triangle with a vertex on a pole of its face (a collapsed
    side, `SurfaceSet.collapsed`): the search (`_rescue`) on that face from the meridian that leaves the pole towards the
    mesh hit, off the pole by its first-order distance (`_meridian_towards`). In place where it converges near the mesh
    hit, on the face: VALID, whatever the candidate was (a miss, unresolved). Returns the rows replaced.

    By a pole |S_u| → 0, and from a mesh start on the far side of it Newton and the search turn u by steps so wild that
    they run onto the pole, or off the seam and onto the pole from its other side, and stall there at the pole's
    distance from the ray: the sweep's hollow_sphere_cut.step, close-ups of its outer sphere's pole (fov 0.05°, and
    orthographic 0.0069 high), rays passing 0.0035 from the pole were judged to miss the outer sheet and went on to the
    inner one 0.114 behind OCCT's first hit (624 and 555 of 14,400 pixels). From the meridian towards the point the
    search has no u to turn.
    """
    if len(rows) == 0:
        return rows
    faces, vertex_uv, face_patch = tessellation.start_arrays
    corners = faces[prim[rows]]  # (m, 3) vertex indices
    k = np.repeat(face_patch[prim[rows]], 3)
    cu, cv = vertex_uv[corners.ravel(), 0], vertex_uv[corners.ravel(), 1]
    pu, pv = _meridian_towards(surfaces, k, cu, cv, np.repeat(O[rows] + tm[rows, None] * D[rows], 3, axis=0))
    moved = ((pu != cu) | (pv != cv)).reshape(-1, 3)  # the corners on a pole (moved off it towards the mesh hit)
    on = moved.any(axis=1)
    first = np.argmax(moved, axis=1)
    rows, pick = rows[on], (np.arange(len(moved)) * 3 + first)[on]
    if len(rows) == 0:
        return rows
    return _search_off_pole(tessellation, surfaces, rows, k[pick], pu[pick], pv[pick], O, D, tm, band, status, pk, ur,
                            vr, tr, derivs)


def _search_off_pole(tessellation: Tessellation, surfaces: SurfaceSet, rows, patch, un, vn, O, D, tm, band, status, pk,
                     ur, vr, tr, derivs) -> np.ndarray:
    """The search (`_rescue`, `POLE_RESCUE_STEPS`) for rays ``rows`` on faces ``patch`` from (un, vn) off a pole; in
    place where it converges near the mesh hit, on the face (VALID). Returns the rows replaced."""
    tol = _search_tolerance(tm[rows], tessellation.extent)
    u2, v2, d2, ok2 = _rescue(surfaces, patch, un, vn, O[rows], D[rows], tol, POLE_RESCUE_STEPS)[:4]
    near2, t2 = _near_mesh_hit(d2, patch, O[rows], D[rows], tm[rows], band)
    ok2 &= near2 & surfaces.on_face(patch, u2, v2)
    won = rows[ok2]
    _store(won, ok2, patch, u2, v2, t2, d2, pk, ur, vr, tr, derivs)
    status[won] = VALID
    return won


def _across_pole(tessellation: Tessellation, surfaces: SurfaceSet, rows, points, O, D, tm, band, status, pk, ur, vr,
                 tr, derivs) -> np.ndarray:
    """Candidates ``rows`` whose Newton stopped on a pole (at ``points``) left UNRESOLVED (neither the search nor
    `_passes_by` decides, or the search converged on the face far from the mesh hit: on another crossing of the ray,
    a cone's apex shared by two faces), tried on the face sharing the pole: its boundary vertex nearest the pole
    (`Tessellation.across_seam`, within two of the face's mesh edges), moved onto the meridian towards the mesh hit and
    off the pole (`_meridian_towards`), from which the search (`_rescue`, not Newton:
    at a pole |S_u| = 0 and Newton's step along u is wild there too) looks for the ray on that face. In place where it
    converges near the mesh hit, on that face (VALID); the others stay unresolved. Returns the rows replaced.

    Faces sharing one pole (a sphere cut in two along meridians) meet at that point only, not along an edge: the
    tracer's seam restart, which follows Newton off a domain edge, never led there.
    """
    if len(rows) == 0:
        return rows
    pn, un, vn, _ = tessellation.across_seam(points, pk[rows], None, np.column_stack([ur[rows], vr[rows]]),
                                             2.0 * tessellation.edge_length[pk[rows]])
    close = pn >= 0
    rows, pn, un, vn = rows[close], pn[close], un[close], vn[close]
    if len(rows) == 0:
        return rows
    un, vn = _meridian_towards(surfaces, pn, un, vn, O[rows] + tm[rows, None] * D[rows])
    return _search_off_pole(tessellation, surfaces, rows, pn, un, vn, O, D, tm, band, status, pk, ur, vr, tr, derivs)


#: Parameters along a pole's collapsed side that `_meridian_towards` compares (a meridian every 1/64 of the range).
POLE_MERIDIANS = 64


def _meridian_towards(surfaces: SurfaceSet, patch, u, v, X) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) on a collapsed side (a pole) moved along it to the meridian that leaves the pole towards the points X, and
    down that meridian by h = |X − S| / |S_v| (where X lies, to first order).

    At a pole on v = v_p, S(u, v_p + h) ≈ S(u, v_p) + h S_v(u, v_p) (S_u = 0 there): every u is the same point, and the
    meridian heading to X is the u whose S_v, turned into the domain, points most nearly at X − S; from there the search
    does not have to turn u at the pole, where its steps in u are wild (u ↔ v for a pole on a side u = u_p). Of
    `POLE_MERIDIANS` + 1 parameters spread along the side; points not on a collapsed side are returned as given.
    """
    u, v = np.array(u, dtype=np.float64), np.array(v, dtype=np.float64)
    u0, u1, v0, v1 = surfaces.domains(patch)
    side = surfaces.collapsed[np.asarray(patch, dtype=np.int64)]
    # A reader's mesh node this close to a collapsed side lies on the pole (`geometry.surfaces.SIDE_SNAP`).
    snap = surface_module.SIDE_SNAP
    eu, ev = snap * (u1 - u0), snap * (v1 - v0)
    on_v = (side[:, 2] & (np.abs(v - v0) <= ev)) | (side[:, 3] & (np.abs(v - v1) <= ev))
    on_u = ~on_v & ((side[:, 0] & (np.abs(u - u0) <= eu)) | (side[:, 1] & (np.abs(u - u1) <= eu)))
    v = np.where(on_v, np.where(np.abs(v - v0) <= ev, v0, v1), v)  # onto the side itself
    u = np.where(on_u, np.where(np.abs(u - u0) <= eu, u0, u1), u)
    s = np.linspace(0.0, 1.0, POLE_MERIDIANS + 1)
    for rows, along, fixed, lo, hi, lo_fixed, hi_fixed, inward, order in (
            (np.flatnonzero(on_v), u, v, u0, u1, v0, v1, np.where(v == v0, 1.0, -1.0), "v"),
            (np.flatnonzero(on_u), v, u, v0, v1, u0, u1, np.where(u == u0, 1.0, -1.0), "u")):
        if len(rows) == 0:
            continue
        tries = (lo[rows, None] + s[None] * (hi - lo)[rows, None]).ravel()
        at = np.repeat(fixed[rows].copy(), len(s))
        k = np.repeat(np.asarray(patch)[rows], len(s))
        d = surfaces.evaluate(k, *((tries, at) if order == "v" else (at, tries)))
        leave = (d.Sv if order == "v" else d.Su) * np.repeat(inward[rows], len(s))[:, None]
        towards = np.repeat(X[rows], len(s), axis=0) - d.S
        with np.errstate(invalid="ignore", divide="ignore"):
            cosine = np.einsum("ij,ij->i", leave, towards) / (np.linalg.norm(leave, axis=1) * np.linalg.norm(towards, axis=1))
        pick = np.arange(len(rows)) * len(s) + np.argmax(np.nan_to_num(cosine, nan=-2.0).reshape(len(rows), len(s)), axis=1)
        along[rows] = tries[pick]
        # And off the pole along that meridian by h = |X − S| / |S_v|, to first order where X lies: the search's steps
        # from the pole itself ran into the domain's edge (a sphere cut in two).
        with np.errstate(invalid="ignore", divide="ignore"):
            h = np.nan_to_num(np.linalg.norm(towards[pick], axis=1) / np.linalg.norm(leave[pick], axis=1))
        fixed[rows] = np.clip(fixed[rows] + inward[rows] * h, lo_fixed[rows], hi_fixed[rows])
    return u, v


def _on_collapsed_side(surfaces: SurfaceSet, patch, u, v) -> np.ndarray:
    """Whether (u, v) lies on a collapsed side of its patch's domain (`SurfaceSet.collapsed`: a pole)."""
    u0, u1, v0, v1 = surfaces.domains(patch)
    side = surfaces.collapsed[np.asarray(patch, dtype=np.int64)]
    return (side[:, 0] & (u == u0)) | (side[:, 1] & (u == u1)) | (side[:, 2] & (v == v0)) | (side[:, 3] & (v == v1))


def _stopped_at_pole(surfaces: SurfaceSet, patch, u, v, edge) -> np.ndarray:
    """Which Newton stops on a domain edge (``edge``) lie on a collapsed side (`_on_collapsed_side`: a pole). Such a
    stop has not left the face, whose side there is one point in 3D: the search decides it, as inside the face."""
    at_pole = np.zeros(len(edge), dtype=bool)
    rows = np.flatnonzero(edge)
    at_pole[rows] = _on_collapsed_side(surfaces, np.asarray(patch)[rows], np.asarray(u)[rows], np.asarray(v)[rows])
    return at_pole


def _search_tolerance(t, extent) -> np.ndarray:
    """The distance |r| at which the search (`_rescue`) from a start at ray distance ``t`` counts as on the ray: Newton's
    tolerance at that distance, `NEWTON_TOLERANCE` × max(t, the scene's extent)."""
    return NEWTON_TOLERANCE * np.maximum(t, extent)


def _seam_sides(surfaces: SurfaceSet, patch, u, v) -> np.ndarray:
    """(N, 2) (u, v) for `Tessellation.across_seam`'s far side of a closed face's seam: NaN in a direction the face is
    not closed in (`SurfaceSet.closed`), where none of its own vertices is across a seam. An open face's vertices half
    its span away are no seam: panel_fillet.step's fillet (2 wide, u from 0 to 2003 across it) offered its own end, 81
    away, as the first of the `SEAM_TRIES`, and the side face it ran onto was never tried (the ray went through)."""
    return np.where(surfaces.closed[np.asarray(patch, dtype=np.int64)], np.column_stack([u, v]), np.nan)


def _over_closed_seam(surfaces: SurfaceSet, patch, u, v, derivs: SurfaceDerivatives, converged, edge, O, D, t_mesh,
                      extent) -> np.ndarray:
    """Newton that stopped unconverged on a closed face's seam, restarted from the same point's parameters on the
    seam's other side (u₀ ↔ u₁ where S(u₀, ·) ≡ S(u₁, ·), `SurfaceSet.closed`; v alike); in place where it converges
    there. Returns the rows replaced.

    A boundary vertex on the seam belongs to both sides, and a restart from it (`Tessellation.across_seam`, a
    shell hit on the seam's last wall or rim box) may start on the side away from the hit: Newton then runs into
    the domain's edge, clamped, though the surface goes on across it (parts/plate.step at 480×270, pixel
    (133, 335): a ray through a hole onto its fillet's top circle at u = 0.017, the restart from the plane
    at u = 2π; the ray went on to the hole's floor 7.6 farther).
    """
    u0, u1, v0, v1 = surfaces.domains(patch)
    closed = surfaces.closed[np.asarray(patch, dtype=np.int64)]
    # Equality: Newton's clamp stops a point exactly on the domain's end (`_seam_twins` matches mesh vertices, whose
    # parameters a reader may round, within SEAM_MATCH instead).
    on_u, on_v = closed[:, 0] & ((u == u0) | (u == u1)), closed[:, 1] & ((v == v0) | (v == v1))
    rows = np.flatnonzero(~converged & edge & (on_u | on_v))
    if len(rows) == 0:
        return rows
    # The other end exactly (u₀ + u₁ − u need not round to it).
    us = np.where(on_u[rows], np.where(u[rows] == u0[rows], u1[rows], u0[rows]), u[rows])
    vs = np.where(on_v[rows], np.where(v[rows] == v0[rows], v1[rows], v0[rows]), v[rows])
    u2, v2, d2, ok2 = refine(surfaces, patch[rows], us, vs, O[rows], D[rows], t_mesh[rows], extent)
    won = rows[ok2]
    u[won], v[won], converged[won], edge[won] = u2[ok2], v2[ok2], True, False
    for have, new in zip(derivs[:3], d2[:3]):
        have[won] = new[ok2]
    return won


def _search_at_pole(surfaces: SurfaceSet, patch, us, vs, u, v, derivs: SurfaceDerivatives, converged, edge, O, D,
                    t_mesh, extent) -> np.ndarray:
    """Restarts (from ``us``, ``vs``) whose Newton stopped unconverged on a collapsed side of their patch (a pole,
    `_on_collapsed_side`): the search for the ray's distance (`_rescue`) from the same start instead, in place where
    it converges. Returns the rows replaced.

    The collapsed-side rule of the mesh hits' own refinement (`_candidates`): the side is one point in 3D, so Newton
    stopping there has not left the face, and near it Newton's steps in the parameter along the side are wild
    (|S_u| → 0). A seam restart onto a face with a pole (a sphere's cap, a cone's apex) stopped there missed.
    """
    rows = np.flatnonzero(~converged & _stopped_at_pole(surfaces, patch, u, v, edge))
    if len(rows) == 0:
        return rows
    tol = _search_tolerance(t_mesh[rows], extent)
    u2, v2, d2, ok2 = _rescue(surfaces, patch[rows], us[rows], vs[rows], O[rows], D[rows], tol)[:4]
    won = rows[ok2]
    u[won], v[won], converged[won], edge[won] = u2[ok2], v2[ok2], True, False
    for have, new in zip(derivs[:3], d2[:3]):
        have[won] = new[ok2]
    return won


def _curvature_along_ray(d2, n, D, c):
    """The sheet's normal curvature along the ray, κ = n·S''(δ, δ), and δ = (du, dv), the parameter step per unit
    length of D's tangential part D_T = D − (n·D) n: least squares of [S_u S_v] δ = D_T (the 2×2 normal equations).
    The ray's height over the sheet is then g(s) = h₀ + (n·D) s − ½ κ s² to second order (`_other_root`,
    `_crossing_on_face`); κ is inf or NaN where the second derivatives overflow."""
    du, dv = parameter_steps(d2.Su, d2.Sv, D - c[:, None] * n)
    with np.errstate(invalid="ignore", over="ignore"):
        kappa = np.einsum("ij,ij->i", n, d2.Suu * (du * du)[:, None] + 2.0 * d2.Suv * (du * dv)[:, None]
                          + d2.Svv * (dv * dv)[:, None])
    return kappa, du, dv


def _may_cross_twice(c, kappa, cap):
    """Where the ray's two crossings of its sheet may both matter: grazing (|n·D| < `OTHER_ROOT_COS`), or a cap
    between them no deeper than ``cap`` = 2·`OTHER_ROOT_CHORDS` chord errors of the face ((n·D)²/2|κ| ≤ that)."""
    with np.errstate(invalid="ignore", over="ignore"):
        return (np.abs(c) < OTHER_ROOT_COS) | (c * c <= cap * np.abs(kappa))


def _into_domain(surfaces: SurfaceSet, patch, u, v) -> tuple[np.ndarray, np.ndarray]:
    """Predicted Newton starts (u, v) moved into their patch's domain: across a closed face's seam
    (S(u₀, ·) ≡ S(u₁, ·), `SurfaceSet.closed`; v alike) wrapped one period round, since the surface goes on there;
    at an open edge clamped. Starts inside the domain keep their bits.

    Clamped at a seam, a start predicted past it lands on the seam's far side, and Newton goes to the ray's other
    crossing (blocks.3dm at 480×270: the non-uniformly scaled sphere's entry lies across its seam from the mesh hit;
    clamped, 2 pixels stored the exit 0.65 behind it)."""
    # Writeable C arrays, as the compiled kernel's signature takes them (a read-only broadcast would go to the JIT).
    patch = np.require(patch, np.int64, ("C", "W"))
    u, v = (np.require(np.broadcast_to(x, patch.shape), np.float64, ("C", "W")) for x in (u, v))
    u_out, v_out = np.empty(len(patch)), np.empty(len(patch))
    nurbs_kernel.into_domains(surfaces.table.domain, surfaces.closed, patch, u, v, u_out, v_out)
    return u_out, v_out


def _other_root(tessellation: Tessellation, surfaces: SurfaceSet, O, D, status, pk, ur, vr, tr, derivs, normal, cosine,
                aside, curvature: np.ndarray | None = None) -> None:
    """Grazing valid hits, and those the mesh may have led past a shallow cap: the nearer of the ray's two crossings of
    the same sheet, in place.

    A ray meeting a sheet at grazing incidence crosses it twice, close together; where the mesh
    lies on the wrong side of the sheet by a fraction of its chord error (at a face's rim, which
    `_enclosing` does not move) its first mesh hit lies between the two crossings and Newton goes
    to the farther one (assembly.step at 480×270: |N·D| = 0.02, the nearer crossing 0.24 before
    it, missed by the second look's finer mesh too). To second order about the hit at t₁ the sheet
    leaves the ray as g(s) = ½ κ s² − (n·D) s along the normal n, κ = n·S''(δ, δ) with δ the
    parameter step per unit length of D's tangential part: the other crossing lies at s = 2(n·D)/κ.
    Where that is before the hit, Newton starts there on the same face; a valid point nearer than
    t₁ by more than float32 rounding replaces it. Where Newton goes back to t₁ instead (the sheet is no parabola
    along the ray: it waves, and the ray dips under a crest before t₁), the search for the ray's distance
    (`_rescue`, `OTHER_ROOT_RESCUE_STEPS`) from the same start runs down into that dip (rational_high.step, a
    grazing close-up: the ray runs 0.55 over the sheet 5 before its hit at t = 71.23 and 0.0065 under it at 52.81–54.57,
    where the mesh, 2.5 off, has no hit). A crossing found is looked before in turn (`OTHER_ROOT_ROUNDS`): the
    search meets a dip's far side first. ``normal`` and ``cosine`` (n·D) as the kernel gives them, updated in place
    for the rows replaced.
    Looked for below `OTHER_ROOT_COS`, and at any incidence where the ray's depth inside the cap between the
    crossings, max |g| = (n·D)²/2|κ|, is within `OTHER_ROOT_CHORDS` chord errors of the face: a deeper cap
    the mesh reaches into, so the ray meets it there and Newton starts near the nearer crossing.
    ``curvature`` (n, 4): where given, K, H, κ1, κ2 known at the hits (the Newton kernel's; NaN where none), taken with
    the normal turned to face the ray as `trace` stores it (`facing`: n·D ≤ 0): the prefilter reads them and stores
    the ones it computes, so they are the AOV stage's (`Hits.curvature`); the caller resets the rows whose hit it
    replaces.
    """
    rays = np.flatnonzero(status == VALID)
    degenerate = np.zeros(len(status), dtype=bool)
    for _ in range(OTHER_ROOT_ROUNDS):
        rays = _nearer_crossing(tessellation, surfaces, O, D, rays, pk, ur, vr, tr, derivs, normal, cosine, aside,
                                curvature)
        # The next round looks before the crossings just found, with their own normals (the caller resets the
        # curvature rows of every replaced hit).
        _normals(surfaces, pk, derivs, D, rays, normal, cosine, degenerate)
        curvature = None
        if len(rays) == 0:
            return


def _nearer_crossing(tessellation: Tessellation, surfaces: SurfaceSet, O, D, rays, pk, ur, vr, tr, derivs, normal,
                     cosine, aside, curvature: np.ndarray | None) -> np.ndarray:
    """One round of `_other_root` over the valid hits ``rays``: the rays whose hit it replaced, in place. The second-order
    prediction first (`_nearer_on_parabola`), then, for the others by a pole, the pole's tangent cone
    (`_nearer_by_pole`)."""
    won = _nearer_on_parabola(tessellation, surfaces, O, D, rays, pk, ur, vr, tr, derivs, normal, cosine, aside,
                              curvature)
    rest = rays[~np.isin(rays, won, assume_unique=True)] if len(won) else rays
    by_pole = _nearer_by_pole(tessellation, surfaces, O, D, rest, pk, ur, vr, tr, derivs, cosine)
    aside[by_pole] = True
    return np.concatenate([won, by_pole]) if len(by_pole) else won


def _nearer_on_parabola(tessellation: Tessellation, surfaces: SurfaceSet, O, D, rays, pk, ur, vr, tr, derivs, normal,
                        cosine, aside, curvature: np.ndarray | None) -> np.ndarray:
    """`_nearer_crossing` where the sheet along the ray is a parabola to second order (`_other_root`)."""
    cap = 2.0 * OTHER_ROOT_CHORDS * tessellation.chord_error  # per face: a shallow cap's |κ| ≥ (n·D)²/cap
    keep = np.abs(cosine[rays]) < OTHER_ROOT_COS
    # A shallow cap needs |κ| ≥ (n·D)²/2Cδ, and |κ| ≤ max(|κ1|, |κ2|)(1 − (n·D)²) (the principal curvatures bound
    # the normal curvature, the ray's tangential part is that long): rays that cannot pass are dropped before
    # the order-2 evaluation (one compiled pass; the curvatures' NaN at degenerate points keeps the ray).
    rest = rays[~keep]
    if len(rest):
        # With −n, (K, H, κ1, κ2) become (K, −H, −κ2, −κ1) (II changes sign; exactly so, rounding to nearest being
        # symmetric, but for the sign of a zero), so max(|κ1|, |κ2|) is the same either way: the normal facing the ray.
        largest = _largest_curvature(surfaces, rest, pk, ur, vr, normal, cosine, curvature)
        c2 = cosine[rest] ** 2
        bound = cap[pk[rest]] * (1.0 - c2) * (1.0 + CURVATURE_SLACK)
        with np.errstate(invalid="ignore"):
            far = c2 > bound * largest
        keep[~keep] = ~far
        rays = rays[keep]
    if len(rays) == 0:
        return rays
    d2 = surfaces.evaluate(pk[rays], ur[rays], vr[rays], order=2)
    nr, cr, Dr = normal[rays], cosine[rays], D[rays]
    kappa, du, dv = _curvature_along_ray(d2, nr, Dr, cr)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # κ ~ 0: no finite root, dropped below
        step = 2.0 * cr / kappa
    ahead = np.isfinite(step) & (step < 0.0) & (tr[rays] + step > 0.0) & _may_cross_twice(cr, kappa, cap[pk[rays]])
    rays, step, du, dv = rays[ahead], step[ahead], du[ahead], dv[ahead]
    if len(rays) == 0:
        return rays
    us, vs = _into_domain(surfaces, pk[rays], ur[rays] + step * du, vr[rays] + step * dv)
    t_start = tr[rays] + step
    u3, v3, d3, ok3 = refine(surfaces, pk[rays], us, vs, O[rays], D[rays], t_start, tessellation.extent)
    t3 = np.einsum("ij,ij->i", d3.S - O[rays], D[rays])
    slack = FLOAT32_SLACK * tessellation.extent
    ok3 &= (t3 > 0) & (t3 < tr[rays] - slack) & surfaces.on_face(pk[rays], u3, v3)

    back = np.flatnonzero(~ok3)
    if len(back):
        rb = rays[back]
        tol = _search_tolerance(t_start[back], tessellation.extent)
        u4, v4, d4, ok4 = _rescue(surfaces, pk[rb], us[back], vs[back], O[rb], D[rb], tol, OTHER_ROOT_RESCUE_STEPS)[:4]
        t4 = np.einsum("ij,ij->i", d4.S - O[rb], D[rb])
        ok4 &= (t4 > 0) & (t4 < tr[rb] - slack)
        ok4[ok4] = surfaces.on_face(pk[rb[ok4]], u4[ok4], v4[ok4])
        got = back[ok4]
        u3[got], v3[got], t3[got], ok3[got] = u4[ok4], v4[ok4], t4[ok4], True
        for have, new in zip(d3[:3], d4[:3]):
            have[got] = new[ok4]
    won = rays[ok3]
    ur[won], vr[won], tr[won], aside[won] = u3[ok3], v3[ok3], t3[ok3], True
    for have, new in zip(derivs[:3], d3[:3]):
        have[won] = new[ok3]
    return won


def _largest_curvature(surfaces: SurfaceSet, rows, pk, ur, vr, normal, cosine, known: np.ndarray | None) -> np.ndarray:
    """max(|κ1|, |κ2|) at the hits ``rows``: from ``known`` (n, 4: K, H, κ1, κ2 for the normal turned to face the ray
    as `facing` turns it, the Newton kernel's, `kernels.nurbs.CURVATURE_EVALUATION`) where its rows are not NaN, the
    others by `curvatures_at` and stored in ``known`` (None: all of them, stored nowhere)."""
    if known is None:
        largest = np.full(len(rows), np.nan)
    else:  # over every row, then taken: ~4× faster than gathering (n, 4) rows or columns by fancy indexing
        largest = np.take(np.maximum(np.abs(known[:, 2]), np.abs(known[:, 3])), rows)
    missing = np.flatnonzero(np.isnan(largest))  # no curvatures in the row (NaN), or NaN κ from rounding: recomputed
    if len(missing):
        at = rows[missing]
        turned = np.take(normal, at, axis=0)
        turned[cosine[at] > 0] *= -1.0  # as `facing` turns them
        k = curvatures_at(surfaces, pk[at], ur[at], vr[at], turned)
        largest[missing] = np.maximum(np.abs(k.k1), np.abs(k.k2))
        if known is not None:
            known[at] = np.column_stack(k)
    return largest


def _nearer_by_pole(tessellation: Tessellation, surfaces: SurfaceSet, O, D, rays, pk, ur, vr, tr, derivs, cosine):
    """`_nearer_crossing` for valid hits ``rays`` by an apex of their face (a pole whose tangent cone is no plane,
    `SurfaceSet.apexes`): the search (`_rescue`, `POLE_RESCUE_STEPS`)
    from the nearer of the ray's two crossings of the pole's tangent cone (`_tangent_cone_starts`); where it converges
    on the face before the kept hit by more than float32 rounding it replaces it, in place. Returns those rays.

    By a cone's apex the sheet is no parabola along the ray: its normal turns round the apex between the crossings,
    and the mesh's fan there lies inside the surface, so a ray entering it by the apex meets the fan only on its way
    out, and Newton from there goes to the exit (the sweep's cone_apex_view.step in close-ups: rays 0.0006-0.0075 from
    the apex kept the exit up to 0.05 behind the entry, the two up to ~140° apart round the axis: 1,936 of 14,400
    pixels at 120×120, fov 0.5°); the parabola's prediction lands on the pole, from where Newton and the search run to
    the seam. Looked for where a pole lies within the kept hit's passage (the shell's reach over |n·D|, as the second
    look's: `secondlook.SecondLook.suspects`), where a nearer crossing is left to this round.
    """
    has_apex = surfaces.apexes.any(axis=1)
    if len(rays) == 0 or not has_apex.any():
        return rays[:0]
    rays = rays[has_apex[pk[rays]]]
    if len(rays) == 0:
        return rays
    reach = 2.0 * OTHER_ROOT_CHORDS * tessellation.chord_error[pk[rays]] / np.maximum(np.abs(cosine[rays]),
                                                                                       OTHER_ROOT_COS)
    at, un, vn = _tangent_cone_starts(surfaces, pk[rays], O[rays], D[rays], derivs.S[rays], reach)
    if len(at) == 0:
        return at
    slack = FLOAT32_SLACK * tessellation.extent
    rb = rays[at]
    tol = _search_tolerance(tr[rb], tessellation.extent)
    u4, v4, d4, ok4 = _rescue(surfaces, pk[rb], un, vn, O[rb], D[rb], tol, POLE_RESCUE_STEPS)[:4]
    t4 = np.einsum("ij,ij->i", d4.S - O[rb], D[rb])
    ok4 &= (t4 > 0) & (t4 < tr[rb] - slack)
    ok4[ok4] = surfaces.on_face(pk[rb[ok4]], u4[ok4], v4[ok4])
    _store(rb[ok4], ok4, pk[rb], u4, v4, t4, d4, pk, ur, vr, tr, derivs)
    return rb[ok4]


def _tangent_cone_starts(surfaces: SurfaceSet, patch, O, D, X, reach):
    """Starts for the crossings of rays whose hit X lies within ``reach`` of an apex of its face (a pole, `apexes`) with
    the pole's tangent cone (`_nearer_by_pole`), where it crosses the cone twice: (positions of those rays, u, v) of
    the nearer crossing (the farther one is where the kept hit lies).

    To first order the surface by a pole A (a side v = v_p; u ↔ v) is its tangent cone: S(w, v_p + h) ≈ A + h e(w),
    e = S_v(w, v_p) turned into the domain, h ≥ 0. The ray meets the half-line of meridian w where e(w)·(D × (O − A))
    = 0: a root between two of `POLE_MERIDIANS` + 1 meridians, placed by linear interpolation, and there t D − h e =
    A − O gives the ray's t and the parameter step h off the pole (least squares).
    """
    u0, u1, v0, v1 = surfaces.domains(patch)
    with np.errstate(invalid="ignore"):  # NaN: no pole on that side; a smooth pole's cone is its tangent plane
        distance = np.where(surfaces.apexes[patch], np.linalg.norm(surfaces.poles[patch] - X[:, None], axis=2), np.nan)
    which = np.argmin(np.nan_to_num(distance, nan=np.inf), axis=1)
    nearest = np.nan_to_num(distance[np.arange(len(patch)), which], nan=np.inf)
    found_at, found_u, found_v, found_t = [], [], [], []
    w = np.linspace(0.0, 1.0, POLE_MERIDIANS + 1)
    for s, (lo, hi, pole) in enumerate(((v0, v1, u0), (v0, v1, u1), (u0, u1, v0), (u0, u1, v1))):
        rows = np.flatnonzero((which == s) & (nearest <= reach))
        if len(rows) == 0:
            continue
        m, n = len(rows), len(w)
        along = (lo[rows, None] + w[None] * (hi - lo)[rows, None]).ravel()  # the meridians' parameters
        fixed = np.repeat(pole[rows], n)
        on_u = s < 2  # a pole on a side u = u_p: its meridians run along u, parametrised by v
        d = surfaces.evaluate(np.repeat(patch[rows], n), *((fixed, along) if on_u else (along, fixed)))
        inward = 1.0 if s % 2 == 0 else -1.0
        e = (d.Su if on_u else d.Sv) * inward
        A = d.S[::n]
        normal = np.cross(D[rows], O[rows] - A)  # e(w) in the plane through the ray and A: this is 0
        side_of = np.einsum("ij,ij->i", e, np.repeat(normal, n, axis=0)).reshape(m, n)
        r, j = np.nonzero((side_of[:, :-1] <= 0) != (side_of[:, 1:] <= 0))
        f0, f1 = side_of[r, j], side_of[r, j + 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.nan_to_num(f0 / (f0 - f1))
        grid = along.reshape(m, n)
        at_w = grid[r, j] + share * (grid[r, j + 1] - grid[r, j])
        k = rows[r]
        ed = surfaces.evaluate(patch[k], *((pole[k], at_w) if on_u else (at_w, pole[k])))
        e_root = (ed.Su if on_u else ed.Sv) * inward
        # The ray O + tD and the half-line A + h e meet where (t, h) solve t D − h e = A − O (least squares).
        Dk, Ok, Ak = D[k], O[k], A[r]
        de, ee = np.einsum("ij,ij->i", Dk, e_root), np.einsum("ij,ij->i", e_root, e_root)
        b1, b2 = np.einsum("ij,ij->i", Dk, Ak - Ok), np.einsum("ij,ij->i", e_root, Ak - Ok)
        with np.errstate(divide="ignore", invalid="ignore"):
            det = de * de - ee  # |D| = 1
            t = (-ee * b1 + de * b2) / det
            h = (-de * b1 + b2) / det
        ok = np.isfinite(t) & np.isfinite(h) & (h > 0) & (t > 0)
        k, at_w, t, h = k[ok], at_w[ok], t[ok], h[ok]
        off = np.where(s % 2 == 0, np.minimum(pole[k] + h, (u1 if on_u else v1)[k]),
                       np.maximum(pole[k] - h, (u0 if on_u else v0)[k]))
        found_at.append(k)
        found_u.append(off if on_u else at_w)
        found_v.append(at_w if on_u else off)
        found_t.append(t)
    if not found_at:
        return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
    at, u, v, t = (np.concatenate(x) for x in (found_at, found_u, found_v, found_t))
    order = np.lexsort((t, at))
    at, u, v = at[order], u[order], v[order]
    # A ray crossing the cone once crosses it where its kept hit lies: only the nearer of two crossings is a start.
    first = np.concatenate([[True], at[1:] != at[:-1]])
    twice = np.flatnonzero(first[:-1] & (at[1:] == at[:-1]))  # each ray's nearest, where it has another
    return at[twice], u[twice], v[twice]


def _crossing_on_face(tessellation: Tessellation, surfaces: SurfaceSet, rows, patch, O, D, tm, us, vs, band, status, pk,
                      ur, vr, tr, derivs) -> np.ndarray:
    """Candidates ``rows`` whose refinement left their face ``patch`` (per row: Newton ran off its domain's edge or
    converged outside its trim) at grazing incidence: the ray's other crossing of the same sheet, on the face, in
    place. Returns the rows it made VALID (or nearer: where a neighbour across the edge took the ray, its hit stays
    unless this one lies before it by more than float32 rounding).

    The mirror case of `_other_root`: a ray grazing a sheet crosses it twice, close together, and Newton from a mesh
    hit between the crossings may go to either. Where it goes to the one beyond the face's edge, the ray left the
    face there, but the other may lie on it (parts/plate.step at 960×551, pixel (425, 750): a ray skimming a hole's
    wall at |N·D| = 0.012 met the wall's mesh at its top rim, v = 4.2, between the wall's crossings at t = 74.08 and
    74.2007; Newton ran off v = 4.2 towards the first, on the cylinder's extension above the wall where the fillet
    curves away, and the ray went on to the hole's floor 4.8 farther). To second order about the mesh hit's (u, v)
    (point S₀, unit normal n, δ the parameter step per unit length of D's tangential part, κ = n·S''(δ, δ) as in
    `_other_root`) the ray's height over the sheet at O + (t_mesh + s) D is g(s) = h₀ + (n·D) s − ½ κ s², with
    h₀ = n·(O + t_mesh D − S₀): the crossings lie at s = ((n·D) ± √((n·D)² + 2κ h₀))/κ (both at the closest
    approach s = (n·D)/κ where the model's root is complex: the sheet may still come that close). Newton starts from
    both on the same face; the nearest point that converges, within reach of the mesh hit (`_near_mesh_hit`) and on
    the face wins. Looked for where `_other_root` looks: |n·D| < `OTHER_ROOT_COS` at the mesh hit's (u, v), or the
    cap between the crossings no deeper than `OTHER_ROOT_CHORDS` chord errors of the face.
    """
    if len(rows) == 0:
        return rows
    cap = 2.0 * OTHER_ROOT_CHORDS * tessellation.chord_error  # per face: a shallow cap's |κ| ≥ (n·D)²/cap
    O, D, tm, u, v = O[rows], D[rows], tm[rows], us[rows], vs[rows]
    d2 = surfaces.evaluate(patch, u, v, order=2)
    n = surfaces.normals(patch, u, v, d2)
    c = np.einsum("ij,ij->i", n, D)
    h0 = np.einsum("ij,ij->i", n, O + tm[:, None] * D - d2.S)
    kappa, du, dv = _curvature_along_ray(d2, n, D, c)
    with np.errstate(invalid="ignore", over="ignore"):  # κ ~ 0: no second crossing, dropped below
        root = np.sqrt(np.maximum(c * c + 2.0 * kappa * h0, 0.0))
    grazing = np.isfinite(kappa) & (kappa != 0.0) & _may_cross_twice(c, kappa, cap[patch])
    if not grazing.any():
        return rows[:0]
    rows, patch, O, D, tm, u, v, c, kappa, root, du, dv = (x[grazing] for x in
                                                          (rows, patch, O, D, tm, u, v, c, kappa, root, du, dv))
    m = len(rows)
    # Both crossings of every row in one refinement: rows 0..m−1 the one at s₋, m..2m−1 the one at s₊.
    s = np.concatenate([(c - root) / kappa, (c + root) / kappa])
    k2, O2, D2, tm2 = (np.concatenate([x, x]) for x in (patch, O, D, tm))
    starts_u, starts_v = _into_domain(surfaces, k2, np.tile(u, 2) + s * np.tile(du, 2), np.tile(v, 2) + s * np.tile(dv, 2))
    # Newton's tolerance is taken at the mesh hit's t, not at the predicted crossing's: where the sheet is nearly
    # straight along the ray (κ → 0) s₋ runs off to ~1/κ, and a tolerance scaled by it accepted points far off the ray
    # (the sweep's cone.step, a ray along a generator at |N·D| = 0.006: s = 4·10¹¹, tolerance 0.4, a hit stored 0.03
    # off its ray where OCCT finds none). The kept point must lie within reach of the mesh hit anyway (below).
    u3, v3, d3, ok3 = refine(surfaces, k2, starts_u, starts_v, O2, D2, tm2, tessellation.extent)
    near3, t3 = _near_mesh_hit(d3, k2, O2, D2, tm2, band)
    ok3 &= near3 & surfaces.on_face(k2, u3, v3)
    t3 = np.where(ok3, t3, np.inf)
    pick = np.where(t3[m:] < t3[:m], np.arange(m) + m, np.arange(m))  # the nearer of each row's two
    best = t3[pick]
    # A neighbour's hit across the edge (the ray's next face there) stays unless this one is nearer beyond rounding.
    win = np.isfinite(best) & ((status[rows] != VALID) | (best < tr[rows] - FLOAT32_SLACK * tessellation.extent))
    won, pick = rows[win], pick[win]
    _store(won, pick, k2, u3, v3, t3, d3, pk, ur, vr, tr, derivs)
    status[won] = VALID
    return won


def _past_minimum(tessellation: Tessellation, surfaces: SurfaceSet, rows, O, D, band, status, pk, ur, vr, tr,
                  derivs) -> np.ndarray:
    """Candidates ``rows`` judged a miss at a positive local minimum of the ray's distance to their face (the search,
    `_rescue`, stationary there, or `_passes_by`), their (u, v) that minimum's: the ray followed on past it, and where
    it crosses the face, that crossing, in place. Returns the rows it made VALID.

    A positive minimum shows the ray passes the surface there, not that it never meets it: a little farther on the
    surface may dip across the ray where the mesh, within its chord error of it, stays on the ray's far side
    (torus_hole_view.step at 480×270, pixel (180, 364): the ray passes the inner wall 0.028 away at t = 59.8, rises to
    0.037, and enters it at t = 65.33, OCCT's first hit; the renderer stored the torus's far side at 99.36;
    pipe_spline.step, pixel (84, 106): 0.017 away at 35.0, entered at 37.28, stored 53.41). From the minimum the ray
    point X = O + tD moves on in steps of `PAST_MINIMUM_EDGES` of the face's longest mesh edge, at most
    `PAST_MINIMUM_STEPS`, while its height g = n·(X − S) over its nearest surface point S (Gauss–Newton from the
    previous step's, `kernels.nurbs.walk_past_minimum`) stays within the error band (`BAND_CHORDS` chord errors of
    the face, where the mesh cannot tell which side of the surface the ray is on); where g changes sign the ray crossed the surface: Newton
    (`refine`) from the nearer of the two feet, at t interpolated between them, finds the crossing, kept where it
    converges within reach of that t (`_near_mesh_hit`) and on the face (its trim). The caller flags it ``aside`` and,
    as a `_crossing_on_face` hit, `trace` keeps it only nearer than the stored hit by more than float32 rounding. All
    walk is compiled, per row; a dip shorter than a step between two steps' points, both above the surface, is not
    seen.
    """
    if len(rows) == 0:
        return rows
    patch = pk[rows]
    reach = BAND_CHORDS * tessellation.chord_error[patch] + FLOAT32_SLACK * tessellation.extent
    step = PAST_MINIMUM_EDGES * tessellation.edge_length[patch]
    # At the minimum X − S is normal to the surface: the search's point is X's foot.
    u, v = ur[rows].copy(), vr[rows].copy()
    d = SurfaceDerivatives(*(x[rows] for x in derivs[:3]))
    Or, Dr = O[rows], D[rows]
    t = np.einsum("ij,ij->i", d.S - Or, Dr)
    g = np.einsum("ij,ij->i", surfaces.normals(patch, u, v, d), Or + t[:, None] * Dr - d.S)
    # The walk, compiled (`kernels.nurbs.walk_past_minimum`); a foot with a degenerate normal comes back for the
    # limit normal (`SurfaceSet.normals`) and the walk goes on from there.
    n = len(rows)
    steps_left = np.full(n, PAST_MINIMUM_STEPS, dtype=np.int64)
    u1, v1, g1 = np.zeros(n), np.zeros(n), np.zeros(n)
    pending = np.zeros(n, dtype=bool)
    state = np.full(n, nurbs_kernel.WALK_DROPPED, dtype=np.int64)
    live = np.flatnonzero(np.abs(g) <= reach)  # indices into rows
    while len(live):
        nurbs_kernel.walk_past_minimum(*surfaces.table.args, surfaces.table.scale, surfaces.closed, live, patch,
                                       Or, Dr, reach, step, FOOT_ITERATIONS, surface_module.DEGENERATE_SINE,
                                       surface_module.VANISHING_PARTIAL, pending, u, v, t, g, steps_left, u1, v1, g1,
                                       state)
        live = live[state[live] == nurbs_kernel.WALK_PAUSED]
        if len(live):
            k = patch[live]
            foot = surfaces.evaluate(k, u1[live], v1[live])
            X = Or[live] + (t[live] + step[live])[:, None] * Dr[live]
            g1[live] = np.einsum("ij,ij->i", surfaces.normals(k, u1[live], v1[live], foot), X - foot.S)
            pending[live] = True
    at = np.flatnonzero(state == nurbs_kernel.WALK_CROSSED)
    if len(at) == 0:
        return rows[:0]
    t0, u0, v0, g0 = t[at], u[at], v[at], g[at]
    u1, v1, g1 = u1[at], v1[at], g1[at]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_start = t0 + step[at] * np.nan_to_num(g0 / (g0 - g1), nan=0.5)
    first = np.abs(g0) < np.abs(g1)
    us, vs = np.where(first, u0, u1), np.where(first, v0, v1)
    r, k = rows[at], patch[at]
    u3, v3, d3, ok = refine(surfaces, k, us, vs, O[r], D[r], t_start, tessellation.extent)
    near, t3 = _near_mesh_hit(d3, k, O[r], D[r], t_start, band)
    ok &= near & surfaces.on_face(k, u3, v3)
    won = r[ok]
    _store(won, ok, k, u3, v3, t3, d3, pk, ur, vr, tr, derivs)
    status[won] = VALID
    return won


def _across_reach(chord: np.ndarray, other_chord: np.ndarray, skip: float) -> np.ndarray:
    """How far from a face's mesh boundary `_rim_neighbours` looks across it: `RIM_REACH_CHORDS` times both faces'
    chord errors, plus the next query's float32 skip."""
    return RIM_REACH_CHORDS * (chord + other_chord) + skip


def _rim_corner(tessellation: Tessellation, prim: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each point on its triangle ``prim``: the distance to its face's mesh boundary near the triangle (inf where
    it has none), the distance to its triangle's chords between two boundary vertices (inf: none), and the
    triangle's boundary vertex nearest the point (−1: none).

    Near the boundary: the face's boundary edges from the triangle's corners on it (`Tessellation.rim_path`), and the
    triangle's edges from a boundary vertex into the face (a reader's mesh may run a row of slivers from its
    boundary nodes to interior nodes a float64 rounding away in (u, v), which `_enclosing` moves off the edge; a
    coarse grid's triangles reach in from the boundary too). Not a chord between two boundary vertices across
    the face: a planar face's reader mesh is all such chords, every triangle's corners on the boundary, so
    measured to the triangle's edges nearly every ray of parts/plate.step (143,000 first candidates at
    960×540) was refined across the rim. Near such a chord the face across the rim is looked at only where its
    surface passes the point (`_neighbour_passes`). By the compiled kernel `kernels.rims.rim_distances`.
    """
    n = len(prim)
    dist, chords, corner = np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    rims_kernel.rim_distances(tessellation.start_arrays[0], tessellation.vertices, tessellation.on_rim,
                              tessellation.rim_path, np.ascontiguousarray(prim, dtype=np.int64),
                              np.ascontiguousarray(points, dtype=np.float64), dist, chords, corner)
    return dist, chords, corner


def _rim_neighbours(tessellation: Tessellation, surfaces: SurfaceSet, O, D, prim, tm, status, pk, ur, vr, tr, derivs,
                    band, aside) -> tuple[np.ndarray, np.ndarray]:
    """Candidates on a triangle at its face's rim (valid, missed or unresolved): the neighbouring face across the rim
    refined too, in place (VALID where it wins). Returns the rows whose candidate it replaced, and those of them found
    by `_crossing_on_face` (not led there by a mesh hit: `trace` weighs them as such).

    Another face's triangle can meet the ray at the mesh hit's own distance, to float32 rounding: where
    faces join (a reader's mesh with a row of slivers lying in the neighbouring face's plane, faces
    joined tangentially). Embree returns one of them and the next query starts past float32 rounding
    (`trace`), so the other's candidate is never examined, though its exact hit may be the nearer (on
    trimmed.3dm at 480×270, 7 pixels: a boss's top and bottom caps behind its wall's slivers). The
    other face's mesh lies there only near the edge the faces share, so where the mesh hit lies within
    `RIM_REACH_CHORDS` times both faces' chord errors of its face's boundary (`_rim_corner`; near a chord across
    the face only where the other face's surface passes that close, `_neighbour_passes`), the face across the rim (the nearest
    boundary vertex of another face to the triangle's nearest boundary vertex, `Tessellation.rim_neighbour`)
    is refined from that vertex. Where that vertex is a corner where 3+ faces meet, every other face with a
    boundary vertex there is refined too (`_corner_faces`): the nearest other vertex is only one of them (at
    shelled_box.step's rim corner the wall's, tied to 1e-14 with the rim's, whose triangle was the skipped one).
    A closed face's creased seam (`_seam_twins`) is such a rim too, the face across it the same face, refined from
    the candidate's (u, v) carried across the seam.
    The nearest valid hit within its band of the mesh hit's distance (the skipped triangle's hit) and nearer
    than the kept one by more than float32 rounding replaces it (the same point on the shared edge does
    not: pixels there keep their face).
    """
    twins, creased = _seam_twins(tessellation, surfaces)
    if not tessellation.has_rim_neighbours and not creased:  # no face has a neighbour, nor a creased seam
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    patch_of, uv_of, gap_of = tessellation.rim_neighbour
    # Not only under a valid hit: the next query skips the coincident triangle past a miss or an unresolved candidate
    # too, and there the neighbour's valid hit wins outright (blocks.3dm, a close-up at fov 0.05° up a scaled
    # cylinder's wall, |n·D| 1e-4, onto its cap: the rays met the wall's rim sliver first, Newton left it unresolved or
    # missed, and the cap's triangle at the same t was never examined: 1,073 of 4,096 rays hit nothing, 1,063 of them
    # fallbacks, where Open CASCADE meets the cap face-on).
    kept = np.where(status == VALID, tr, np.inf)  # the hit a neighbour's must beat
    rays = np.flatnonzero(tessellation.rim_face[prim])
    slack = FLOAT32_SLACK * tessellation.extent
    skip = float32_rounding(tessellation)  # as `trace`'s
    points = O[rays] + tm[rays, None] * D[rays]
    edge_dist, chord_dist, corner = _rim_corner(tessellation, prim[rays], points)
    pn, un, vn, gap = patch_of[corner], uv_of[corner, 0], uv_of[corner, 1], gap_of[corner]
    chord = tessellation.chord_error
    # A neighbour shares the edge: its boundary vertex lies within a mesh edge of the corner; and the mesh hit
    # lies within both meshes' chord errors of the edge (`RIM_REACH_CHORDS`), where the other mesh can be. Not the
    # face the hit is already on (a seam restart's, from another face's triangle): Newton found its root there.
    pn_ = np.maximum(pn, 0)
    reach = _across_reach(chord[pk[rays]], chord[pn_], skip)
    close = (pn >= 0) & (pn != pk[rays]) & (gap <= tessellation.edge_length[pn_])
    # Near a chord across the face (not its boundary) only where the neighbour's surface passes within that reach too.
    across = np.flatnonzero(close & (edge_dist > reach) & (chord_dist <= reach))
    close &= edge_dist <= reach
    close[across] = _neighbour_passes(tessellation, surfaces, corner[across], points[across], reach[across])
    # At a corner the other faces meeting there, where the mesh hit lies within their reach of the boundary and
    # their surface passes within it too (along a long edge whose only vertices are corners, most rays do not).
    slot, cp, cuv, cX, cn, ckappa = _corner_faces(tessellation, surfaces)
    near = np.flatnonzero(corner >= 0)
    near = near[slot[corner[near]] >= 0]  # the few rays whose nearest boundary vertex is a corner
    at = slot[corner[near]]
    cp = cp[at]
    more = (cp >= 0) & (cp != pk[rays[near], None])
    reach_more = _across_reach(chord[pk[rays[near]], None], chord[np.maximum(cp, 0)], skip)
    row, col = np.nonzero(more & (edge_dist[near, None] <= reach_more))
    passes = _within(cX[at[row], col], cn[at[row], col], ckappa[at[row], col], points[near[row]], reach_more[row, col])
    row, col = row[passes], col[passes]
    cuv = cuv[at[row], col]
    # Across a creased seam of the hit's own face (`_seam_twins`): that face again, from the candidate's (u, v) taken
    # across the seam (its other coordinate kept: the vertex's may lie far along a sliver at the seam), else the twin's.
    # The twin's face is the triangle's, which a seam restart may have left for another (then the twin's (u, v)).
    seam = np.flatnonzero(corner >= 0)
    seam = seam[twins[corner[seam], 2] >= 0]
    own = tessellation.vertex_patch[corner[seam]]
    keep = edge_dist[seam] <= _across_reach(chord[own], chord[own], skip)  # both faces this one
    seam, own = seam[keep], own[keep]
    twin = twins[corner[seam]]
    across_u = twin[:, 2] == 0
    tuv = np.stack([np.where(across_u, twin[:, 0], ur[rays[seam]]), np.where(across_u, vr[rays[seam]], twin[:, 1])], 1)
    tuv = np.where(np.isfinite(tuv) & (pk[rays[seam]] == own)[:, None], tuv, twin[:, :2])
    rays, pn = (np.concatenate([rays[close], rays[near[row]], rays[seam]]),
                np.concatenate([pn[close], cp[row, col], own]))
    un, vn = np.concatenate([un[close], cuv[:, 0], tuv[:, 0]]), np.concatenate([vn[close], cuv[:, 1], tuv[:, 1]])
    # A planar neighbour is met where the ray crosses its plane: rows whose crossing cannot win below are not refined.
    win_reach = _rim_reach(band, GRAZING_ALLOWANCE, skip)  # the reach test below at its largest allowance
    may = _may_win_on_plane(tessellation, surfaces, pn, O[rays], D[rays], tm[rays], kept[rays], win_reach, slack)
    rays, pn, un, vn = rays[may], pn[may], un[may], vn[may]
    # Any neighbour lies in its control net's hull: rows whose ray stays clear of it where a win could lie are not refined.
    may = _may_win_in_hull(tessellation, surfaces, rays, pn, O, D, tm, kept, win_reach, slack)
    rays, pn, un, vn = rays[may], pn[may], un[may], vn[may]
    if len(rays) == 0:
        return rays, rays
    u3, v3, d3, ok3 = refine(surfaces, pn, un, vn, O[rays], D[rays], tm[rays], tessellation.extent)
    predicted = np.zeros(len(rays), dtype=bool)  # found by `_crossing_on_face`
    # Where Newton fails, the neighbour's sheet may still cross the ray nearby at grazing incidence: its crossings
    # predicted from the start (`_crossing_on_face`, on copies of the rows). huge_inch.step, a close-up at fov 0.39°
    # from 4.6 off a sphere corner (r 1000), inside its mesh's chord error (31): the rays meet the corner's mesh only at
    # its rim, 1–23 past their entry at |N·D| 0.001–0.027, and Newton from the rim vertex stopped short of the entry or
    # on the domain's edge: 1,382 of 2,048 rays went on to the part's far side, 5,500 behind OCCT's first hit.
    fail = np.flatnonzero(~ok3)
    if len(fail):
        ra = rays[fail]
        status3, tr3 = np.full(len(fail), MISS), np.full(len(fail), np.inf)
        pk3, ur3, vr3 = pn[fail].copy(), u3[fail].copy(), v3[fail].copy()
        d4 = SurfaceDerivatives(*(x[fail] for x in d3[:3]))  # copies, written where a crossing is found
        got = _crossing_on_face(tessellation, surfaces, np.arange(len(fail)), pn[fail], O[ra], D[ra], tm[ra], un[fail],
                                vn[fail], band, status3, pk3, ur3, vr3, tr3, d4)
        take = fail[got]
        u3[take], v3[take], ok3[take], predicted[take] = ur3[got], vr3[got], True, True
        for have, new in zip(d3[:3], d4[:3]):
            have[take] = new[got]
    t3 = np.einsum("ij,ij->i", d3.S - O[rays], D[rays])
    # Only the hit a triangle at the mesh hit's distance leads to (the one the next query skips): within
    # the neighbour's band of it (2 chord errors grown as 1/cos θ there), plus the skipped step.
    cross = np.cross(d3.Su, d3.Sv)
    with np.errstate(divide="ignore", invalid="ignore"):  # a ray in the face's tangent plane: cos = 0
        cos = np.abs(np.einsum("ij,ij->i", cross, D[rays])) / np.linalg.norm(cross, axis=1)
        allowance = np.clip(np.nan_to_num(1.0 / cos, nan=GRAZING_ALLOWANCE), 1.0, GRAZING_ALLOWANCE)
    reach = _rim_reach(band[pn], allowance, skip)
    ok3 &= (t3 > 0) & (np.abs(t3 - tm[rays]) <= reach) & surfaces.on_face(pn, u3, v3) & (t3 < kept[rays] - slack)
    # A ray with several faces refined (a corner): its nearest valid hit wins.
    won, pick = _keep_nearest(rays, ok3, pn, u3, v3, t3, d3, status, pk, ur, vr, tr, derivs, aside)
    return won, won[predicted[pick]]


def _keep_nearest(rays, ok, pn, u, v, t, derivatives, status, pk, ur, vr, tr, derivs, aside):
    """Of refinements on other faces (rows: ray ``rays[i]`` on face ``pn[i]``, (u, v), t and derivatives), the
    nearest valid one (``ok``) per ray stored as its candidate, VALID and ``aside`` (found beside its mesh hit), in
    place. Returns the rays that took one and the rows taken."""
    pick = np.flatnonzero(ok)
    pick = pick[np.lexsort((t[pick], rays[pick]))]
    pick = pick[np.r_[True, rays[pick][1:] != rays[pick][:-1]]] if len(pick) else pick
    won = rays[pick]
    _store(won, pick, pn, u, v, t, derivatives, pk, ur, vr, tr, derivs)
    status[won] = VALID
    aside[won] = True
    return won, pick


def _coplanar_faces(tessellation: Tessellation, surfaces: SurfaceSet) -> np.ndarray:
    """Per face (P, k ≥ 1) the other planar faces lying in its plane where their meshes' boxes overlap (−1 padded; a
    face that is not planar has none): parts of an assembly resting on each other, a face and the coplanar one it was
    split from. Both control nets lie in each other's plane within float32 rounding of the scene and their deviations
    (`_net_planes`), so where both meshes cover a point Embree meets them at one distance, to rounding. Built once per
    tessellation, on first use (kept in its ``__dict__``, as `_net_planes` is)."""
    cached = tessellation.__dict__.get("_coplanar_faces")
    if cached is not None:
        return cached
    faces = len(surfaces.patches)
    centre, normal, deviation, planar = _net_planes(tessellation, surfaces)
    skip = float32_rounding(tessellation)
    lo, hi = tessellation.patch_bounds(tessellation.vertices, faces)
    flat = np.flatnonzero(planar & np.isfinite(lo).all(axis=1))
    pairs = []
    for first in range(0, len(flat), COPLANAR_CHUNK):  # box overlaps, a block of faces × all planar faces at a time
        rows = flat[first:first + COPLANAR_CHUNK]
        meet = np.all((lo[rows, None] - skip <= hi[None, flat]) & (lo[None, flat] <= hi[rows, None] + skip), axis=2)
        a, b = np.nonzero(meet)
        pairs.append(np.stack([rows[a], flat[b]], axis=1))
    pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    # B's net in A's plane: its points' distances (along A's normal) within the rounding and both deviations.
    nets = [np.asarray(surfaces.patches[k].points, dtype=np.float64).reshape(-1, 3) for k in range(faces)]
    sizes = np.array([len(x) for x in nets], dtype=np.int64)
    a, b = pairs[:, 0], pairs[:, 1]
    point = np.concatenate([nets[k] for k in b]) if len(b) else np.zeros((0, 3))
    owner = np.repeat(np.arange(len(pairs)), sizes[b])
    distance = np.abs(np.einsum("ij,ij->i", point - centre[a][owner], normal[a][owner]))
    farthest = np.zeros(len(pairs))
    np.maximum.at(farthest, owner, distance)
    pairs = pairs[farthest <= skip + deviation[a] + deviation[b]]
    table = np.full((faces, max(int(np.bincount(pairs[:, 0], minlength=1).max(initial=0)), 1)), -1, dtype=np.int64)
    order = np.argsort(pairs[:, 0], kind="stable")
    pairs = pairs[order]
    slot = np.arange(len(pairs)) - np.searchsorted(pairs[:, 0], pairs[:, 0])
    table[pairs[:, 0], slot] = pairs[:, 1]
    tessellation.__dict__["_coplanar_faces"] = table
    return table


def _coplanar_neighbours(tessellation: Tessellation, surfaces: SurfaceSet, O, D, prim, tm, status, pk, ur, vr, tr, derivs,
                         band, aside) -> np.ndarray:
    """Candidates left unresolved or missed on a planar face's triangle: the faces lying in its plane
    (`_coplanar_faces`) refined where the ray crosses it, in place (VALID where one is met on its face, the nearest;
    ``aside``). Returns the rows whose candidate it replaced.

    Where two faces' meshes overlap in one plane, Embree returns one of them and the next query starts past float32
    rounding (`trace`): the other is never examined. Where the one returned is off its face (its mesh's skirt, its
    untrimmed domain), the ray went on through the other (OCCT's data/step/trj2_as1-tc-214.stp, the CAx-IF as1
    assembly: the L-brackets' feet rest on the plate's top, z = 20; rays past a foot's edge met its skirt there and
    went on to the plate's bottom face 20 below, 5 pixels at 320×180). `_rim_neighbours` finds such a face only
    across a shared edge; a part resting on another shares none. Newton on the plane converges from the middle of
    its domain; its crossing must lie within the face's reach of the mesh hit (`_rim_reach`), as the skipped
    triangle's does. Likewise where the candidate went across an edge to a neighbour (`_candidates`' seam restarts):
    a coplanar face's crossing nearer than the neighbour's hit (by float32 rounding) replaces it (OCCT's
    data/step/bug33569.stp: two faces in one plane; the ray met one's skirt and went on to its neighbour, 2.05
    behind the other face's crossing, one pixel at 160×90).
    """
    partners = _coplanar_faces(tessellation, surfaces)
    paired = partners[:, 0] >= 0
    if not paired.any():  # no two faces share a plane (any curved scene): no per-ray gathers
        return np.zeros(0, dtype=np.int64)
    face = tessellation.face_patch[prim]
    rays = np.flatnonzero(((status != VALID) | (pk != face)) & paired[face])
    if len(rays) == 0:
        return rays
    row, col = np.nonzero(partners[face[rays]] >= 0)
    rays, pn = rays[row], partners[face[rays[row]], col]
    centre, normal = _net_planes(tessellation, surfaces)[:2]
    skip = float32_rounding(tessellation)
    nd = np.einsum("ij,ij->i", normal[pn], D[rays])
    with np.errstate(divide="ignore", invalid="ignore"):  # a ray along the plane: NaN, dropped
        tp = np.einsum("ij,ij->i", normal[pn], centre[pn] - O[rays]) / nd
        allowance = np.clip(1.0 / np.abs(nd), 1.0, GRAZING_ALLOWANCE)
    reach = _rim_reach(band[pn], allowance, skip)
    close = (tp > 0) & (np.abs(tp - tm[rays]) <= reach)
    rays, pn, reach = rays[close], pn[close], reach[close]
    if len(rays) == 0:
        return rays
    (u0, u1, v0, v1) = surfaces.domains(pn)
    u3, v3, d3, ok3 = refine(surfaces, pn, 0.5 * (u0 + u1), 0.5 * (v0 + v1), O[rays], D[rays], tm[rays],
                             tessellation.extent)
    t3 = np.einsum("ij,ij->i", d3.S - O[rays], D[rays])
    ok3 &= (t3 > 0) & (np.abs(t3 - tm[rays]) <= reach) & surfaces.on_face(pn, u3, v3)
    ok3 &= (status[rays] != VALID) | (t3 < tr[rays] - FLOAT32_SLACK * tessellation.extent)
    return _keep_nearest(rays, ok3, pn, u3, v3, t3, d3, status, pk, ur, vr, tr, derivs, aside)[0]


def _may_win_on_plane(tessellation: Tessellation, surfaces: SurfaceSet, pn, O, D, tm, tr, reach, slack) -> np.ndarray:
    """Which (ray, neighbour) rows of `_rim_neighbours` (or seam restarts, `_may_win_restart`) may win: False only
    where the neighbour is planar (`_net_planes`) and its crossing cannot pass the winning tests (ahead, within
    ``reach[k]`` of the mesh hit along the ray, nearer than the kept hit ``tr`` by ``slack``), whatever Newton from
    any start converges to.

    A converged point S lies within |r⊥| ≤ tol of the ray (Newton's test, tol = `NEWTON_TOLERANCE` × max(t_mesh,
    extent, |O + t_mesh D|)) and, in its net's convex hull (weights > 0), within the net's deviation ρ of the plane
    (point c, unit normal n); so its t = (S − O)·D lies within (ρ + tol)/|n·D| of the ray's crossing of that plane,
    t_p = n·(c − O)/(n·D), plus 1000× tol for the rounding of both. ``reach`` per face: the caller's reach test at
    its largest allowance (`GRAZING_ALLOWANCE`). On the plate at 960×540 the faces across the rim of its holes'
    fillets include the big top plane, whose crossing lies far from the fillet's mesh hit for all but a few of
    those rays.
    """
    may = np.ones(len(pn), dtype=bool)
    centre, normal, deviation, planar = _net_planes(tessellation, surfaces)
    rows = np.flatnonzero(planar[pn])
    if len(rows) == 0:
        return may
    k, O, D, tm, tr = pn[rows], O[rows], D[rows], tm[rows], tr[rows]
    nd = np.einsum("ij,ij->i", normal[k], D)
    tol = NEWTON_TOLERANCE * np.maximum(np.maximum(tm, tessellation.extent), np.linalg.norm(O + tm[:, None] * D, axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        tp = np.einsum("ij,ij->i", normal[k], centre[k] - O) / nd
        margin = (deviation[k] + tol) / np.abs(nd) + 1000.0 * tol
        # Comparisons with NaN or inf (a ray along the plane) are False: such rows are refined.
        never = (tp + margin <= 0.0) | (tp - margin >= tr - slack) | (np.abs(tp - tm) - margin > reach[k])
    may[rows[never]] = False
    return may


def _may_win_in_hull(tessellation: Tessellation, surfaces: SurfaceSet, rays, pn, O, D, tm, tr, reach,
                     slack) -> np.ndarray:
    """Which (ray, neighbour) rows of `_rim_neighbours` (or seam restarts, `_may_win_restart`) may win: False only
    where the ray's stretch on which a winning hit could lie passes clear of the neighbour's control net, whatever
    Newton from any start converges to. For the curved neighbours (a planar one's crossing is known:
    `_may_win_on_plane`).

    A winning point S is converged, so within tol (`NEWTON_TOLERANCE` × max(t_mesh, extent, |O + t_mesh D|)) of the
    ray, at t = (S − O)·D with t > 0, |t − t_mesh| within ``reach[k]`` (the caller's reach test at its largest
    allowance, `GRAZING_ALLOWANCE`) and t below the kept hit's by ``slack``: on the segment t ∈ [max(0, t_mesh −
    reach), min(t_mesh + reach, t_kept − slack)]. With weights > 0 the surface lies in its net's convex hull (Piegl
    and Tiller, *The NURBS Book*, property 4.5 of rational surfaces), so in the net's slab along any unit direction
    m: min m·P ≤ m·S ≤ max m·P, and m·S lies within tol of the segment's range of m·X. A row whose segment range,
    widened by tol (and 1000× tol for the rounding of both), misses the net's slab along the axes (its bounding box)
    or its plane's normal (`_net_boxes`) cannot win. Rows (``rays``, ``pn``) of the candidates' arrays O, D, tm,
    tr; by the compiled kernel `kernels.rims.clear_of_hulls`. On the plate at 960×540: a hole's fillet from the top
    plane and its wall from the fillet lie below the face the ray meets first (3 of 4 such rows); a wall from its
    fillet does not separate so.
    """
    lo, hi, normal, low, high, hull = _net_boxes(tessellation, surfaces)
    clear = np.empty(len(pn), dtype=bool)
    f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
    rims_kernel.clear_of_hulls(np.ascontiguousarray(rays, dtype=np.int64), np.ascontiguousarray(pn, dtype=np.int64),
                               f64(O), f64(D), f64(tm), f64(tr), f64(reach), lo, hi,
                               normal, low, high, hull, NEWTON_TOLERANCE, float(tessellation.extent), float(slack), clear)
    return ~clear


def _net_boxes(tessellation: Tessellation, surfaces: SurfaceSet) -> tuple[np.ndarray, ...]:
    """Per face, its control net's slabs (`_may_win_in_hull`): the bounding box lo, hi (P, 3), the net plane's unit
    normal m (P, 3) and the range low, high (P,) of m·P over the net, and whether they bound a curved face: weights all
    > 0 (else no hull holds the surface) and not planar (`_net_planes`: `_may_win_on_plane` decides those). Built once
    per tessellation, on first use (kept in its ``__dict__``, as `_net_planes` is)."""
    cached = tessellation.__dict__.get("_net_boxes")
    if cached is None:
        _, normal, _, positive = surfaces.net_planes
        nets = [s.points.reshape(-1, 3) for s in surfaces.patches]
        lo, hi = np.array([x.min(axis=0) for x in nets]).reshape(-1, 3), np.array([x.max(axis=0) for x in nets]).reshape(-1, 3)
        along = [x @ m for x, m in zip(nets, normal)]
        low, high = np.array([x.min() for x in along]), np.array([x.max() for x in along])
        hull = positive & ~_net_planes(tessellation, surfaces)[3]
        cached = tessellation.__dict__["_net_boxes"] = tuple(np.ascontiguousarray(x) for x in (lo, hi, normal, low, high, hull))
    return cached


def _net_planes(tessellation: Tessellation, surfaces: SurfaceSet) -> tuple[np.ndarray, ...]:
    """Per face: its control net's plane (`SurfaceSet.net_planes`: point (P, 3), unit normal (P, 3), the net's
    deviation (P,)) and whether it is planar: deviation within float32 rounding of the scene, weights > 0. Built once
    per tessellation, on first use (kept in its ``__dict__``, as `_rim_planes` is)."""
    cached = tessellation.__dict__.get("_net_planes")
    if cached is None:
        centre, normal, deviation, positive = surfaces.net_planes
        planar = (deviation <= float32_rounding(tessellation)) & positive
        cached = tessellation.__dict__["_net_planes"] = (centre, normal, deviation, planar)
    return cached


def _seam_twins(tessellation: Tessellation, surfaces: SurfaceSet) -> tuple[np.ndarray, bool]:
    """Per vertex (V, 3), for a boundary vertex on a closed face's seam where the seam is a crease (its normals either
    side differ by more than `SEAM_CREASE`): the (u, v) of the same point across the seam (u₀ ↔ u₁ or v₀ ↔ v₁, the
    other coordinate kept) and the axis crossed (0: u, 1: v); NaN, NaN, −1 elsewhere. And whether any vertex has one.
    Built once per tessellation, on first use (kept in its ``__dict__``, as `_corner_faces` is)."""
    cached = tessellation.__dict__.get("_seam_twins")
    if cached is not None:
        return cached
    twins = np.full((len(tessellation.vertices), 3), np.nan)
    twins[:, 2] = -1
    rows = tessellation.boundary
    patch = tessellation.vertex_patch[rows]
    closed = surfaces.closed[patch] if len(rows) else np.zeros((0, 2), dtype=bool)
    if closed.any():
        uv = tessellation.vertex_uv[rows].astype(np.float64)
        here, there, axes = uv.copy(), np.full_like(uv, np.nan), np.full(len(rows), -1.0)
        u0, u1, v0, v1 = surfaces.domains(patch)
        for axis, (lo, hi) in enumerate(((u0, u1), (v0, v1))):
            match = SEAM_MATCH * (hi - lo)
            for end, other in ((lo, hi), (hi, lo)):
                on = closed[:, axis] & (np.abs(uv[:, axis] - end) <= match)
                here[on, axis] = end[on]
                there[on] = uv[on]
                there[on, axis] = other[on]
                axes[on] = axis
        seam = np.flatnonzero(axes >= 0)
        if len(seam):
            n_here = surfaces.normals(patch[seam], here[seam, 0], here[seam, 1])
            n_there = surfaces.normals(patch[seam], there[seam, 0], there[seam, 1])
            crease = seam[np.einsum("ij,ij->i", n_here, n_there) < np.cos(SEAM_CREASE)]
            twins[rows[crease], :2], twins[rows[crease], 2] = there[crease], axes[crease]
    cached = tessellation.__dict__["_seam_twins"] = twins, bool((twins[:, 2] >= 0).any())
    return cached


def _corner_faces(tessellation: Tessellation, surfaces: SurfaceSet) -> tuple[np.ndarray, ...]:
    """The other faces meeting at a boundary vertex beyond its `Tessellation.rim_neighbour`: per vertex its row
    ``slot`` (V,) in the tables that follow (−1: none, the last row, all padding); per row the faces (M + 1, k)
    (−1 padded), their boundary vertices' (u, v) (M + 1, k, 2), and there their point, unit normal and largest
    |principal curvature| (`_planes`). Rows only for the vertices at a corner: (V, k) tables of a fine mesh
    would take ~0.6 kB per vertex.

    A face counts where one of its boundary vertices lies as close as the rim neighbour's does, give or take
    `RIM_REACH_CHORDS` times both faces' chord errors and float32 rounding: at a B-rep vertex every face's mesh
    has a vertex there, a model tolerance apart, while along an edge the next face's vertices lie an edge away.
    Its nearest such vertex; the faces by distance. Among the `CORNER_VERTICES` nearest boundary vertices. Built
    once per tessellation, on first use (kept in its ``__dict__``, as `_rim_planes` is).
    """
    cached = tessellation.__dict__.get("_corner_faces")
    if cached is not None:
        return cached
    first, _, gap = tessellation.rim_neighbour
    rows = tessellation.boundary[first[tessellation.boundary] >= 0]
    k = max(min(CORNER_VERTICES, len(tessellation.boundary)), 1)
    other, keep, at = np.zeros((0, k), dtype=np.int64), np.zeros((0, k), dtype=bool), np.zeros((0, k), dtype=np.int64)
    if len(rows):
        tree, cand_patch = tessellation._boundary_tree
        dist, nearest = tree.query(tessellation.vertices[rows], k=k)
        dist, nearest = dist.reshape(len(rows), k), nearest.reshape(len(rows), k)
        other = cand_patch[nearest]
        own = tessellation.vertex_patch[rows]
        chord = tessellation.chord_error
        skip = float32_rounding(tessellation)
        keep = (other != own[:, None]) & (other != first[rows, None])
        keep &= dist <= gap[rows, None] + _across_reach(chord[own, None], chord[other], skip)
        # One vertex per face, its nearest (the columns run by distance).
        for j in range(1, k):
            keep[:, j] &= ~np.any(keep[:, :j] & (other[:, :j] == other[:, j, None]), axis=1)
        used = keep.any(axis=1)
        rows, other, keep, at = rows[used], other[used], keep[used], tessellation.boundary[nearest[used]]
    slot = np.full(len(tessellation.vertices), -1)
    slot[rows] = np.arange(len(rows))
    patch = np.vstack([np.where(keep, other, -1), np.full((1, k), -1)])
    uv = np.full((len(rows) + 1, k, 2), np.nan)
    uv[:-1] = np.where(keep[:, :, None], tessellation.vertex_uv[at], np.nan)
    X, n, kappa = _planes(surfaces, patch.ravel(), uv.reshape(-1, 2))
    cached = tessellation.__dict__["_corner_faces"] = (slot, patch, uv, X.reshape(-1, k, 3), n.reshape(-1, k, 3),
                                                       kappa.reshape(-1, k))
    return cached


def _neighbour_passes(tessellation: Tessellation, surfaces: SurfaceSet, corner, points, reach) -> np.ndarray:
    """Whether the face across the rim at boundary vertex ``corner`` (`Tessellation.rim_neighbour`) passes within
    ``reach`` of ``points``: to second order about its point X there, with unit normal n and largest principal
    curvature |κ|, the surface lies within |n·(P − X)| + ½ |κ| |P − X|² of P. As where two faces meet at a shallow
    angle and one's mesh lies in the other's plane over its whole width (tests/test_exact_hits.py), not only near
    their edge.
    """
    X, n, kappa = _rim_planes(tessellation, surfaces)
    return _within(X[corner], n[corner], kappa[corner], points, reach)


def _within(X, n, kappa, points, reach) -> np.ndarray:
    """|n·(P − X)| + ½ |κ| |P − X|² ≤ reach: the surface through X (unit normal n, largest |principal curvature| κ)
    passes within reach of P, to second order (`_neighbour_passes`)."""
    d = points - X
    return np.abs(np.einsum("ij,ij->i", d, n)) + 0.5 * kappa * np.einsum("ij,ij->i", d, d) <= reach


def _rim_planes(tessellation: Tessellation, surfaces: SurfaceSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per vertex: the point (V, 3), unit normal (V, 3) and largest |principal curvature| (V,) of the face across
    the rim at its `Tessellation.rim_neighbour` (NaN off the rim; curvature 0 where undefined, at a pole: the
    test `_neighbour_passes` then looks at more rays, not fewer). Built once per tessellation, on first use (kept in its
    ``__dict__``, as its cached properties are)."""
    cached = tessellation.__dict__.get("_rim_planes")
    if cached is None:
        patch, uv, _ = tessellation.rim_neighbour
        cached = tessellation.__dict__["_rim_planes"] = _planes(surfaces, patch, uv)
    return cached


def _planes(surfaces: SurfaceSet, patch: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At (u, v) of each patch (M,) (−1: none): the point (M, 3), unit normal (M, 3) and largest |principal
    curvature| (M,) (NaN where none; curvature 0 where undefined, at a pole: `_within` then passes more rays)."""
    X, n, kappa = np.full((len(patch), 3), np.nan), np.full((len(patch), 3), np.nan), np.full(len(patch), np.nan)
    rows = np.flatnonzero(patch >= 0)
    derivs = surfaces.evaluate(patch[rows], uv[rows, 0], uv[rows, 1], order=2)
    X[rows], n[rows] = derivs.S, surfaces.normals(patch[rows], uv[rows, 0], uv[rows, 1], derivs)
    k = curvatures(derivs, n[rows])
    kappa[rows] = np.nan_to_num(np.maximum(np.abs(k.k1), np.abs(k.k2)), nan=0.0)
    return X, n, kappa


def _band(tessellation: Tessellation, cos: np.ndarray) -> np.ndarray:
    """How far beyond an exact hit (along the ray) another sheet's mesh hit may hide a nearer exact hit.

    `BAND_CHORDS` times the largest chord error, grown as 1/cos θ at the hit's incidence θ (up to
    GRAZING_ALLOWANCE; the full allowance where cos is NaN: no normal known), plus float32 slack.
    """
    with np.errstate(divide="ignore"):
        allowance = np.clip(np.nan_to_num(1.0 / cos, nan=GRAZING_ALLOWANCE), 1.0, GRAZING_ALLOWANCE)
    chord = float(tessellation.chord_error.max(initial=0.0))
    return BAND_CHORDS * chord * allowance + FLOAT32_SLACK * tessellation.extent


def _put_rows(targets: tuple[np.ndarray, ...], rows: np.ndarray | slice, values: tuple[np.ndarray, ...],
              pick: np.ndarray | slice, fill: float | None = None) -> None:
    """``target[rows] = value[pick]`` for (N, 3) and (N, 4) arrays: slices copy as numpy does, index rows by a compiled
    row copy (`kernels.pixels.scatter_picked`, ~4× numpy's fancy indexing of (N, 3) rows, and no gathered copy). With
    ``fill`` the targets are unwritten (`Hits.blank` with ``rows=False``) and their other rows get ``fill``, each row
    written once (`kernels.pixels.spread_rows`; a slice is then every row). The values are copied, not computed."""
    for target, value in zip(targets, values):
        if isinstance(rows, slice):
            target[rows] = value[pick]
            continue
        picked = np.arange(len(rows)) if isinstance(pick, slice) else pick
        if fill is None:
            scatter_picked(target, rows, np.ascontiguousarray(value), picked)
        else:
            spread_rows(target, rows, np.ascontiguousarray(value), picked, fill)


def _off_plane(tessellation: Tessellation, surfaces: SurfaceSet, prim, previous, O, D, t_next, lift, skip):
    """The next mesh queries' origin offsets (n, 3) or None (none yet): where a ray's mesh hit (triangle ``prim``) is on
    the same planar face as its previous one (``previous``, its triangle; None on the first query), or on the same
    triangle of a curved face, and the next query's origin lies within float32 rounding (``skip``) of that plane (the
    face's, or the triangle's own), the origin is moved off the plane to ``skip`` on the side the ray heads for (on its
    own side where it runs along the plane).

    Embree meets a plane the ray skims again at each query `skip` farther on while the ray is within float32 rounding of
    it, over 2 `skip` / |n·D| along it: the sweep's faces.igs (the shelled box's faces, unsewn), an extreme close-up (fov
    0.05°) from an eye exactly in a rim face's plane (z = 20): every ray, at |n·D| ≤ 2·10⁻⁴, met the rim's mesh skirt
    at t = 0, 9.4·10⁻⁵, 1.9·10⁻⁴, ... until `MAX_CANDIDATES` ran out: no pixel hit (all fallbacks) where OCCT's first
    hit is the wall 2.69 on; filleted_block.step from 2.7·10⁻⁴ off its side face y = 0 (fov 0.2°): rays at |n·D| ~
    10⁻⁴ met the face's mesh every 9.4·10⁻⁵ from 0.003 before their crossing, all 1,080 rays flagged fallbacks. A plane
    meets the ray once, and two hits of it refined that crossing (Newton on a plane from any start; the near-mesh-hit
    test is unbounded there, `_candidates`): a query origin moved past it by `skip` (the rounding Embree already has)
    sees what lies beyond. Only after a repeat, so a coplanar face's mesh at the same crossing still comes first.
    A triangle is a plane too: a curved face's skirt lying in a neighbour's plane was met so (bspline_prism.step, a
    close-up at fov 0.28° from 7.4·10⁻⁶ under its top plane z = 20, rays rising 10⁻⁴ per unit onto the side wall's top
    edge: the wall's skirt triangle in z = 20 every 9.2·10⁻⁵ until the candidates ran out, 62 rays flagged fallbacks);
    the same triangle twice has been refined twice from its points."""
    if previous is None:
        return lift
    centre, normal, _, planar = _net_planes(tessellation, surfaces)
    patch = tessellation.face_patch[prim]
    on_face = (patch == tessellation.face_patch[previous]) & planar[patch]
    rows = np.flatnonzero(on_face | (prim == previous))
    if len(rows) == 0:
        return lift
    k = patch[rows]
    centre, normal = centre[k], normal[k]
    own = np.flatnonzero(~on_face[rows])  # a curved face's triangle met twice: its own plane
    if len(own):
        a, b, c = (tessellation.vertices[tessellation.faces[prim[rows[own]], i]] for i in range(3))
        m = np.cross(b - a, c - a)
        with np.errstate(invalid="ignore", divide="ignore"):  # a zero-area triangle: no plane, NaN drops it below
            centre[own], normal[own] = a, m / np.linalg.norm(m, axis=1, keepdims=True)
    X = O[rows] + t_next[rows, None] * D[rows] + (0.0 if lift is None else lift[rows])
    h = np.einsum("ij,ij->i", X - centre, normal)
    c = np.einsum("ij,ij->i", D[rows], normal)
    side = np.where(c != 0.0, np.sign(c), np.where(h != 0.0, np.sign(h), 1.0))
    near = np.abs(h) < skip
    rows, normal, h, side = rows[near], normal[near], h[near], side[near]
    if len(rows) == 0:
        return lift
    lift = np.zeros((len(prim), 3)) if lift is None else lift.copy()
    lift[rows] += (side * skip - h)[:, None] * normal
    return lift


def trace(accelerator: Accelerator, tessellation: Tessellation, surfaces: SurfaceSet,
          origins: np.ndarray, directions: np.ndarray, clock: StageClock = NULL_CLOCK,
          max_distance: np.ndarray | None = None, clear: bool = True) -> Hits:
    """Exact first hits of rays (origins, unit directions), both (N, 3) float64 (module doc).

    With ``max_distance`` (N,), only hits with t below it count. ``clear``: the any-hit test past a mesh hit is
    skipped where the BVH's clearance cones prove it finds nothing (`clearance`; used in traces of at least
    `clearance.MIN_RAYS` rays, once the BVH has traced enough to repay them): the same hits, fewer queries.
    """
    n = len(origins)
    far = np.full(n, np.inf) if max_distance is None else np.asarray(max_distance, dtype=np.float64)
    hits = Hits.blank(n, np.zeros(n, dtype=bool), rows=False)  # its rows written whole by the first query (below)
    best = np.full(n, np.inf)  # t of the kept valid hit
    cos = np.full(n, np.nan)  # |n·D| there
    doubt = np.full(n, np.inf)  # mesh t of the nearest unresolved candidate
    rays, start, limit = np.arange(n), None, far
    # Past a mesh hit by float32 rounding of the scene's largest coordinates, with margin.
    skip = float32_rounding(tessellation)
    # Per open ray: the previous mesh hit's triangle, and the query origin's offset off planes the ray skims (`_off_plane`).
    last, lift = np.full(n, -1, dtype=np.int64), None
    slack = FLOAT32_SLACK * tessellation.extent
    crossing = np.zeros(n, dtype=bool)  # the kept hit is a `_crossing_on_face` one
    with clock.stage("clearance cones"):  # built once the BVH has traced enough rays to repay them
        cones = clearance.cones(accelerator, tessellation, skip, n) if clear and n >= clearance.MIN_RAYS else None
    for query in range(MAX_CANDIDATES):
        if len(rays) == 0:
            break
        # The first query is of every ray (rays = 0..n−1): the given arrays themselves, not gathered copies.
        O, D = (origins, directions) if start is None else (np.take(origins, rays, axis=0), np.take(directions, rays, axis=0))
        with clock.stage("intersect (Embree)"):
            if start is None:
                mesh = accelerator.intersect(O, D, max_distance)
            else:  # beyond the last mesh hit: an any-hit test first, the full query only where it finds something
                shifted = O + start[:, None] * D
                if lift is not None:
                    shifted += lift
                some = accelerator.occluded(shifted, D, limit - start)
                if not some.any():  # the common case (no sheet behind the first): no empty gathers and query
                    rays = rays[:0]
                    break
                rays, O, D, shifted, start, limit, last = (x[some] for x in (rays, O, D, shifted, start, limit, last))
                lift = None if lift is None else lift[some]
                mesh = accelerator.intersect(shifted, D, limit - start)
                mesh = mesh._replace(t=mesh.t + start)
        found = mesh.prim >= 0
        if not found.all():
            rays, O, D = rays[found], np.compress(found, O, axis=0), np.compress(found, D, axis=0)  # ~4× numpy's O[found]
            mesh = MeshHits(*(x[found] for x in mesh))
            last = last[found]
            lift = None if lift is None else lift[found]
        if len(rays) == 0:
            break
        # The rays still open are every ray in order (the first query, all found): slices, not index arrays.
        every = start is None and len(rays) == n
        at = slice(None) if every else rays
        with clock.stage("newton (exact hit)"):
            c = _candidates(tessellation, surfaces, O, D, mesh.prim, mesh.b1, mesh.b2, mesh.t)
            # A hit by `_crossing_on_face` is often a root another candidate's refinement reaches too (Newton's
            # tolerance apart): it wins only nearer by more than float32 rounding, and yields to a mesh-led hit within it.
            nearer = np.where(c.crossed, c.t < best[at] - slack,
                              (c.t < best[at]) | (crossing[at] & (c.t < best[at] + slack)))
            take = (c.status == VALID) & nearer & (c.t < far[at])
            # The candidates kept (`pick`) and their rays (`rows`): slices where every ray keeps its candidate (the
            # common case), no gathers.
            pick = slice(None) if take.all() else np.flatnonzero(take)
            rows = at if isinstance(pick, slice) else rays[pick]
            best[rows], hits.patch[rows], hits.u[rows], hits.v[rows] = c.t[pick], c.patch[pick], c.u[pick], c.v[pick]
            hits.aside[rows] = c.aside[pick]
            crossing[rows] = c.crossed[pick]
            odd = np.flatnonzero((c.status == UNRESOLVED) & (mesh.t < doubt[at]))
            doubt[rays[odd]] = mesh.t[odd]
        with clock.stage("exact normals"):
            # Per row: the normals of every candidate turned in place, only the kept ones' stored.
            normal, cosine = c.normal, c.cosine
            bad = np.flatnonzero(c.degenerate & take)
            if len(bad):  # the limit from the interior (`SurfaceSet.normals`)
                kept = SurfaceDerivatives(*(x[bad] for x in c.derivs[:3]))
                normal[bad] = surfaces.normals(c.patch[bad], c.u[bad], c.v[bad], kept)
                cosine[bad] = np.einsum("ij,ij->i", normal[bad], D[bad])
            facing(normal, D, cosine)
            values = (c.derivs.S, c.derivs.Su, c.derivs.Sv, normal, c.curvature)
            # The first query: the kept rows, a miss's NaN in the others, each row written once.
            _put_rows(hits.rows(), rows, values, pick, np.nan if start is None else None)
            cos[rows] = np.abs(cosine[pick])
        # Go on where a mesh hit behind this one could still carry a nearer exact hit.
        # An unresolved candidate does not stop the search: the exact hit may lie behind it.
        limit = np.minimum(far[at], best[at] + _band(tessellation, cos[at]))
        nxt = mesh.t + skip
        go = nxt < limit
        if cones is not None and query < MAX_CANDIDATES - 1:
            # Where the mesh around the hit's triangle provably leaves the segment clear (`clearance`), the any-hit
            # test would find nothing: not asked. (Not after the last query: a ray still open there is a fallback.)
            cones.drop(O, D, mesh.prim, nxt, limit, go)
        lift = _off_plane(tessellation, surfaces, mesh.prim, last if start is not None else None, O, D, nxt, lift, skip)
        rays, start, limit, last = rays[go], nxt[go], limit[go], mesh.prim[go]
        lift = None if lift is None else lift[go]
    if start is None:  # no mesh hit at all (the first query broke off): the rows are still unwritten
        _put_rows(hits.rows(), np.zeros(0, dtype=np.int64), (np.zeros((0, 3)),) * 4 + (np.zeros((0, 4)),), slice(None),
                  np.nan)
    open_rays = rays  # still had candidates to examine after MAX_CANDIDATES
    hits.hit[:] = np.isfinite(best)
    # Unresolved candidates that may hide a nearer exact hit than the kept one (module doc).
    hidden = np.flatnonzero(np.isfinite(doubt))
    hidden = hidden[doubt[hidden] < best[hidden] + _band(tessellation, np.full(len(hidden), np.nan))]
    hits.fallback[hidden] = True
    hits.fallback[open_rays] = True
    idx = np.flatnonzero(hits.hit)
    hits.t[idx] = best[idx]
    hits.cos = cos  # set with each kept hit, NaN where none
    return hits


def occluded(accelerator: Accelerator, tessellation: Tessellation, surfaces: SurfaceSet, origins: np.ndarray,
             directions: np.ndarray, max_distance: np.ndarray) -> np.ndarray:
    """True where the surface lies on the segment from each origin to max_distance along its direction.

    The mesh answers (Embree's occlusion query); where faces are trimmed, a ray the mesh blocks is
    traced exactly (`trace`) so a ray through a hole or past a trim edge is not blocked by the
    triangles that overhang it. A fallback on the way counts as blocking.
    """
    blocked = accelerator.occluded(origins, directions, max_distance)
    if not surfaces.trimmed:
        return blocked
    idx = np.flatnonzero(blocked)
    if len(idx):
        hits = trace(accelerator, tessellation, surfaces, origins[idx], directions[idx], max_distance=max_distance[idx])
        blocked[idx] = hits.fallback | (hits.hit & (hits.t < max_distance[idx]))
    return blocked
