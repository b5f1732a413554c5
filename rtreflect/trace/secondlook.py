"""Second look: rays whose nearest exact hit the coarse mesh may not have led to (DESIGN.md, "Exact hit").

The candidate search (tracing.py) refines the coarse mesh's hits; it cannot see an exact surface
point whose sheet the ray passes within the chord error of without meeting its triangles, nor a
second root of the same sheet when Newton from the mesh hit settles on the farther one. Both happen
only where the ray runs close to a sheet: at grazing incidence (a ray clipping a cap of a sheet near
a patch's rim, where the enclosing mesh keeps its vertices on the surface so neighbours stay joined)
or where it skims a saddle or a rim before the surface it stops on. The shipped teapot stored 63 such
hits at 960×540 (tessellation 12) where the spout and handle meet the body.

Three steps, each vectorised over the rays:

1. **Which rays.** A *shell* encloses every sheet on both sides: the coarse mesh's vertices moved by
   ±`SHELL_CHORDS` chord errors along the exact normal, closed by walls along each face's mesh
   boundary, so the surface, which lies within the chord error of its mesh, lies inside it; where the
   mesh ends on the face's domain edge, which may curve in the tangent plane past its chords, boxes
   around those rim edges enclose the band between chord and edge too (`_rim_boxes`). A ray
   that comes within reach of a sheet enters its shell. A plane meshed exactly (`flat`: its mesh lies in
   it to float32 rounding) has none: its shell would be its mesh, and the coarse trace has already refined
   every triangle of it the ray meets before its kept hit onto the ray's one crossing of that plane (on the
   face or not: nothing nearer is left there to find; on the 206-face plate its big planes' skirts over the
   holes made two thirds of the suspects). A ray is suspect when its kept hit is grazing
   (|N·D| < `GRAZING_COS`); or when the shell has a triangle before the *passage* of that hit
   (t* − 2δ/|N·D|, the flat-sheet entry with a factor 2 for curvature), whatever its face (Embree's
   occlusion query, cheaper than the nearest hit); or another face's shell triangle within the passage:
   the shell's hits there are walked along the ray (at most `SHELL_STEPS`), so a neighbouring face the
   ray meets where it meets the kept face's edge is not hidden behind it, nor the kept face's own shell
   far from the hit in (u, v), another part of the face folding back in front (`FOLD_TRIANGLES`); not
   walked on faces no other face's shell comes near (`isolated`) unless the passage is longer than the
   face's longest mesh edge; or, for a ray that missed, any shell triangle; or a hit the
   tracer found beside its mesh hit (``Hits.aside``: no mesh hit led there).
2. **Look again.** The suspects are traced once more by the same candidate search (`trace`) on a
   finer enclosing mesh (`FINE_FACTOR` × the scene's segments per knot span, a chord error ~1/16
   of the coarse one; a reader's triangulation split `FINE_LEVELS` times, ~1/4; an untrimmed face's
   edge vertices moved out past the edge, `tessellation._widened`), up to their kept
   hit. A valid hit nearer than the kept one by more than float32 rounding replaces it; an
   undecided candidate there flags the ray as a fallback (with its nearer hit, where it has one).
3. **From the shell.** An enclosing mesh covers a sheet on one side only (`tessellation._enclosing`):
   where the surface is a saddle (the teapot's rim lip, 960×540 pixel (211, 570)) or the ray runs
   along it for a while ((177, 621), |N·D| = 0.006), a ray can cross it at grazing incidence between
   both meshes and their surface. The shell, which selected the ray, lies on both sides: the
   suspect's first shell hit of another sheet (of any, for the grazing and ``aside`` suspects)
   starts Newton on its face (a short miss search, `SHELL_RESCUE_STEPS`, where Newton fails inside
   the domain); a point on the ray, on the face, nearer than the kept hit replaces it (at grazing
   incidence the nearer of the sheet's two crossings, `tracing._other_root`). A start that leads off its
   face is followed by the ray's next shell hits, up to `SHELL_WALK` (passing where it leaves the shell it
   tried): a ray running along a face thinner than the mesh's reach meets its shell first far from where
   it crosses the face.

Rays not suspected keep their hits bit for bit. The fine mesh is built on the first suspect, once
per scene (thread-safe), and bounded by `FINE_MAX_VERTICES`.
"""

from __future__ import annotations

import threading
from dataclasses import replace
from functools import cached_property

import numpy as np

from .accelerator import Accelerator, MeshHits
from .tracing import (FLOAT32_SLACK, VALID, Hits, _normals, _other_root, _over_closed_seam, _rescue, _search_tolerance,
                      _stopped_at_pole, facing, float32_rounding, refine_all, trace)
from ..clock import NULL_CLOCK, StageClock
from ..geometry.surfaces import SurfaceDerivatives, SurfaceSet
from ..geometry.tessellation import Tessellation, _once, largest_factor, reader_mesh, tessellate, unique_rows

#: Half-thickness of the shell in chord errors: the mesh-to-surface distance is sampled at edge
#: midpoints and vertices (`_chord_error`), a triangle's interior may stray a little farther.
SHELL_CHORDS = 2.0
#: An own face's shell hit inside the passage farther than this many of its triangle's (u, v) extents from the kept
#: hit's (u, v) is another part of the face (`SecondLook._elsewhere_on_face`): on a mesh that follows its face the
#: passage spans a triangle or two of the sheet around the hit (2δ/|N·D| ≤ 10 shell half-widths, a triangle's chord
#: error far less than its size). On a coarse one (a sphere in 4 × 2 cells) it can span the face: no (u, v) test
#: tells a fold there (docs/cad-reading.md, "Real exports").
FOLD_TRIANGLES = 4.0
#: A rim box's inner corners start at most this share of the domain across its edge inside it (`_inside_the_edge`).
INSIDE_SHARE = 0.25
#: Shell hits walked per ray past its own face's passage (its two sheets and walls, a neighbour's wall).
SHELL_STEPS = 6
#: Shell hits per suspect that step 3 refines in turn (`_from_shell`), until one leads onto its face: a ray running
#: along a face thinner than the mesh's reach meets its shell first far from where it crosses the face (the sweep's
#: long_strip.step, a bicubic strip 1000 × 0.1 whose mesh strays 1 from it: a ray crossing it 366 along met its shell
#: at 42, and crossed it at its 7th shell hit, the walk's 4th refinement, passing where it leaves the shells it tried).
SHELL_WALK = 8
#: Below this |N·D| at the kept hit the shell cannot tell the ray's own passage from a nearer sheet's
#: (the passage is 2δ/|N·D| long): such rays are looked at again. At 0.2 (78°) on the teapot at
#: 960×540, ~6% of the hits; every wrong hit found there had |N·D| ≤ 0.16 at one of its two points.
GRAZING_COS = 0.2
#: Levenberg–Marquardt steps (`tracing._rescue`) where Newton from a shell hit fails: a start up to the shell's
#: depth from the sheet, far along a grazing ray. The saddle test (tests/test_second_look.py) needs 15 (10 leave 77 of
#: its 468 rays on the plane, Newton alone 95): 60 for margin; the tracer's 200 cost trimmed_face.step 1.3 s at
#: 480×270 before the domain-edge filter below.
SHELL_RESCUE_STEPS = 60
#: Faces per block of `isolated`'s box tests (a block × all faces booleans, ×3 axes).
ISOLATION_CHUNK = 512
#: The finer mesh's segments per knot span, in multiples of the scene's: chord error ~1/16.
FINE_FACTOR = 4
#: A reader's triangulation (CAD faces, `mesh_uv`) is split this many times in (u, v), 4 triangles each (chord
#: error ~1/4 a time). Once: on the 206-face plate twice took 3.6 s to build against 1.3 s, for the same suspects.
FINE_LEVELS = 1
#: Cap on the finer mesh's vertices (fewer segments where it would exceed it): ~100 bytes each with
#: their triangles and BVH, so at most ~200 MB besides the scene's own mesh.
FINE_MAX_VERTICES = 1 << 21


def fine_factors(surfaces, chord: np.ndarray, per_span: int) -> np.ndarray:
    """Per face, the finer mesh's multiple of the scene's segments per knot span: 1 on a face its coarse mesh follows
    exactly (chord error 0: a plane), else the fewest from 2 (its own chord error, ∝ segments⁻², at least 4× smaller)
    to `FINE_FACTOR` that bring its chord error (``chord``, the coarse mesh's) down to the finer mesh's level,
    1/`FINE_FACTOR`² of the largest; capped where the span grids would exceed `FINE_MAX_VERTICES` (`largest_factor`).
    A reader's triangulation is subdivided (`FINE_LEVELS`) where the factor is over 1.

    Split by the coarsest face's factor, every face's mesh grew 16×, the finest ones' too (OCCT's
    data/step/trj3_s1-al-214.stp: 94 faces, chord errors from 0 to 2.87, its biggest faces at 3 % of that: 1.8M
    triangles, built in 5.6 s on the first suspect).
    """
    chord = np.asarray(chord, dtype=np.float64)
    target = float(np.max(chord, initial=0.0)) / FINE_FACTOR ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        want = np.clip(np.nan_to_num(np.ceil(np.sqrt(chord / target)), nan=2.0), 2, FINE_FACTOR)
    want = np.where(chord > 0, want, 1).astype(np.int64)
    grid = [s for s in surfaces if s.mesh_uv is None]  # the others: a reader's triangulation, subdivided
    return np.minimum(want, largest_factor(grid, per_span, FINE_FACTOR, FINE_MAX_VERTICES))


def subdivided(nodes: np.ndarray, triangles: np.ndarray, levels: int) -> tuple[np.ndarray, np.ndarray]:
    """A triangulation in (u, v) with each triangle split in 4 at its edges' midpoints, ``levels`` times."""
    nodes, triangles = np.asarray(nodes, dtype=np.float64).reshape(-1, 2), np.asarray(triangles).reshape(-1, 3)
    for _ in range(levels):
        edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
        edge_of = unique_rows(edges)
        unique = np.empty((edge_of.max(initial=-1) + 1, 2), dtype=edges.dtype)
        unique[edge_of] = edges
        mid = len(nodes) + edge_of.reshape(3, -1)  # the midpoints of edges 01, 12, 20 of every triangle
        nodes = np.concatenate([nodes, nodes[unique].mean(axis=1)])
        a, b, c = triangles.T
        triangles = np.concatenate([np.stack(x, 1) for x in ((a, mid[0], mid[2]), (mid[0], b, mid[1]),
                                                             (mid[2], mid[1], c), (mid[0], mid[1], mid[2]))])
    return nodes, triangles


def flat(tessellation: Tessellation, surfaces: SurfaceSet) -> np.ndarray:
    """Per face: True where its shell would be its own mesh (a plane whose mesh lies in it, to float32 rounding).

    The face's control net lies in one plane (so, weights being positive, does the surface) and its mesh
    deviates from the surface by less than Embree's float32 rounding of the scene's coordinates (then its
    ±`SHELL_CHORDS` chord-error sheets coincide with the mesh and its walls have no height).
    """
    rounding = float32_rounding(tessellation)
    deviation = surfaces.net_planes[2]
    return (deviation <= rounding) & (SHELL_CHORDS * tessellation.chord_error <= rounding)


def clear_sides(tessellation: Tessellation, surfaces: SurfaceSet, flat_faces: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per face: (a point on its plane (P, 3), unit normal (P, 3), (P, 2) bool: no other face in front of its side
    +n, of its side −n), for the `flat` faces that support the whole scene (False elsewhere).

    A face whose plane has every other face's control net behind it (on the far side from +n, or from −n), within
    ``GRAZING_COS`` × float32 rounding less its own net's deviation from the plane, supports the scene (the top of the
    plate, every plane of a convex solid): the surfaces lie in their nets' convex hulls (weights > 0), so a ray from
    that side meets no other surface before it crosses the plane, nor any nearer than that rounding over |N·D| ≥
    ``GRAZING_COS``, which the second look would not take (`SecondLook.apply`): its hit there is final.
    """
    n = len(surfaces)
    centre, normal, clear = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 2), dtype=bool)
    rows = np.flatnonzero(flat_faces)
    planes, normals, deviations, positive = surfaces.net_planes
    if len(rows) == 0 or not positive.all():
        return centre, normal, clear
    nets = [s.points.reshape(-1, 3) for s in surfaces.patches]
    owner = np.concatenate([np.full(len(x), k) for k, x in enumerate(nets)])
    nets = np.concatenate(nets)
    slack = GRAZING_COS * FLOAT32_SLACK * tessellation.extent
    for k in rows:
        centre[k], normal[k], deviation = planes[k], normals[k], deviations[k]
        d = (nets[owner != k] - centre[k]) @ normal[k]
        clear[k] = d.max(initial=-np.inf) + deviation < slack, -d.min(initial=np.inf) + deviation < slack
    return centre, normal, clear


def shell(tessellation: Tessellation, surfaces: SurfaceSet) -> tuple[Accelerator, Tessellation, int]:
    """A BVH of the mesh moved by ±`SHELL_CHORDS` chord errors along the exact normals (module doc, step 1), the
    shell as a `Tessellation` (each sheet's vertices keep their (u, v) and face; a wall triangle's face is that
    of its rim edge), so a shell hit gives a starting (u, v) as a mesh hit does (`Tessellation.start_parameters`),
    and how many of its triangles are the two sheets' (the first; walls and rim boxes follow).
    The `flat` faces' triangles are left out, not their vertices (which keep the BVH's box, hence its float32
    origin, that of the mesh); the `_rim_boxes` are added."""
    normal = np.nan_to_num(surfaces.normals(tessellation.vertex_patch, tessellation.vertex_uv[:, 0],
                                            tessellation.vertex_uv[:, 1]))  # degenerate points: not moved
    delta = (SHELL_CHORDS * tessellation.chord_error[tessellation.vertex_patch])[:, None] * normal
    vertices = np.concatenate([tessellation.vertices + delta, tessellation.vertices - delta])
    n = len(tessellation.vertices)
    keep = ~flat(tessellation, surfaces)[tessellation.face_patch]
    faces, patch = tessellation.faces[keep], tessellation.face_patch[keep]
    # Walls along each face's mesh boundary join the two sheets: a ray may enter the shell there, along a sheet.
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    rim = _once(edges)  # edges of one triangle only; edge i belongs to triangle i mod F
    a, b = edges[rim].T
    walls = np.concatenate([np.stack([a, b, b + n], 1), np.stack([a, b + n, a + n], 1)])
    rim_patch = patch[rim % max(len(faces), 1)]
    box_vertices, box_faces, box_uv, box_patch = _rim_boxes(tessellation, surfaces, normal, a, b, rim_patch, 2 * n)
    shell_patch = np.concatenate([patch, patch, np.tile(rim_patch, 2), box_patch])
    shelled = replace(tessellation, vertices=np.concatenate([vertices, box_vertices]),
                      faces=np.concatenate([faces, faces + n, walls, box_faces]),
                      vertex_uv=np.concatenate([tessellation.vertex_uv] * 2 + [box_uv]),
                      vertex_patch=np.concatenate([tessellation.vertex_patch] * 2 + [box_patch[::12].repeat(8)]),
                      face_patch=shell_patch,
                      boundary=np.concatenate([tessellation.boundary, tessellation.boundary + n]))
    return Accelerator(shelled), shelled, 2 * len(faces)


#: A box's 12 triangles over its 8 corners, corner index 4·(end b) + 2·(outer side) + (lower sheet).
_BOX = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6],  # the ends at a and at b
                 [0, 1, 5], [0, 5, 4], [2, 6, 7], [2, 7, 3],  # the inner and the outer side
                 [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])  # the upper and the lower sheet


def _rim_boxes(tessellation: Tessellation, surfaces: SurfaceSet, normal: np.ndarray, a: np.ndarray, b: np.ndarray,
               patch: np.ndarray, first: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closed boxes around the rim edges ab that lie on their face's domain edge: (vertices, triangles numbered
    from ``first``, their (u, v), their face).

    There the mesh cannot reach past the edge (a reader's skirt is clamped to the domain, `_with_skirt`; a span
    grid ends there), so the band between the edge's chord and the curved edge it cuts off lay outside the sheets
    and the walls: a ray crossing the face there met neither its mesh nor its shell (on the plate, rays through a
    hole onto a fillet's top circle, where its seam restart from the plane starts on the far side of the fillet's
    periodic seam: 5 pixels' edge samples at 480×270, found before only because they crossed the plane's shell,
    see `flat`). The box reaches `SHELL_CHORDS` times the edge's deviation from its chord across it in the
    tangent plane (the sagitta's component there, at the midpoint) on either side, and the sheets'
    ±`SHELL_CHORDS` chord errors along the normals.
    """
    u0, u1, v0, v1 = surfaces.domains(patch)
    (ua, va), (ub, vb) = tessellation.vertex_uv[a].T, tessellation.vertex_uv[b].T
    # Which domain edge a rim edge lies on is the edge's (both ends), not a vertex's: a corner vertex is on two.
    low_u, high_u = (ua == u0) & (ub == u0), (ua == u1) & (ub == u1)
    on_u = low_u | high_u
    on_edge = on_u | ((va == v0) & (vb == v0)) | ((va == v1) & (vb == v1))
    inward = np.where(on_u, np.where(low_u, 1.0, -1.0), np.where(va == v0, 1.0, -1.0))  # the step into the domain
    a, b, patch, on_u, inward = a[on_edge], b[on_edge], patch[on_edge], on_u[on_edge], inward[on_edge]
    pa, pb = tessellation.vertices[a], tessellation.vertices[b]
    across = np.cross(pb - pa, normal[a] + normal[b])
    big = np.abs(across).max(axis=1, initial=0.0, keepdims=True)  # scaled first: tiny edges' norms do not underflow
    across = np.divide(across, big, out=np.zeros_like(across), where=big > 0)  # degenerate edges: none
    across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1.0)
    # The edge's sagitta across the chord in the tangent plane (along the normal the sheets' depth covers it).
    mid = 0.5 * (tessellation.vertex_uv[a] + tessellation.vertex_uv[b])
    sagitta = np.abs(np.einsum("ij,ij->i", surfaces.evaluate(patch, mid[:, 0], mid[:, 1]).S - 0.5 * (pa + pb), across))
    # An edge straight in the tangent plane (a cylinder's seam, a circle curving along the normal): its wall suffices.
    rounding = float32_rounding(tessellation)
    bent = SHELL_CHORDS * sagitta > rounding
    a, b, patch, pa, pb, across, sagitta, on_u, inward = (x[bent] for x in (a, b, patch, pa, pb, across, sagitta,
                                                                              on_u, inward))
    width = (SHELL_CHORDS * sagitta)[:, None]
    depth = (SHELL_CHORDS * tessellation.chord_error[patch])[:, None]
    corners = [end + side * width * across + sheet * depth * n_end
               for end, n_end in ((pa, normal[a]), (pb, normal[b])) for side in (-1.0, 1.0) for sheet in (1.0, -1.0)]
    vertices = np.stack(corners, axis=1).reshape(-1, 3)
    faces = (first + 8 * np.arange(len(a)))[:, None, None] + _BOX[None]
    # The corners on the face's side of the edge start Newton inside the domain, as far in as the box reaches: a
    # start on the edge itself runs to a crossing past it where the ray crosses the sheet twice (a bowl's inside
    # left at grazing incidence just below its rim, the nearer crossing in the opening), stopping on the edge.
    inner = [_inside_the_edge(surfaces, patch, tessellation.vertex_uv[end], width[:, 0], across, on_u, inward)
             for end in (a, b)]
    uv = np.stack([inner[0][0], inner[0][0], inner[0][1], inner[0][1], inner[1][0], inner[1][0], inner[1][1],
                   inner[1][1]], axis=1).reshape(-1, 2)
    return vertices, faces.reshape(-1, 3), uv, np.repeat(patch, 12)


def _inside_the_edge(surfaces: SurfaceSet, patch: np.ndarray, uv: np.ndarray, width: np.ndarray, across: np.ndarray,
                     on_u: np.ndarray, inward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For rim-box corners at one end (u, v) of rim edges on a domain edge (u = const where ``on_u``, else v = const;
    ``inward`` ±1 the sign of the step into the domain): their (u, v) on the side −``across`` and on the side
    +``across`` (`_rim_boxes`): the end's own on the side away from the face, and on the face's side the end's moved
    into the domain by ``width`` along the surface (over |S_u| or |S_v| there, at most `INSIDE_SHARE` of the domain
    across: near a pole the partial vanishes), clamped to it."""
    u0, u1, v0, v1 = surfaces.domains(patch)
    u, v = uv[:, 0], uv[:, 1]
    derivs = surfaces.evaluate(patch, u, v)
    partial = np.where(on_u[:, None], derivs.Su, derivs.Sv)
    speed = np.linalg.norm(partial, axis=1)
    most = INSIDE_SHARE * np.where(on_u, u1 - u0, v1 - v0)
    with np.errstate(divide="ignore", invalid="ignore"):
        step = np.minimum(np.nan_to_num(np.where(speed > 0, width / speed, 0.0)), most)
    moved = uv.copy()
    moved[:, 0] = np.where(on_u, np.clip(u + inward * step, u0, u1), u)
    moved[:, 1] = np.where(on_u, v, np.clip(v + inward * step, v0, v1))
    # Which side of the box is the face's: the one +across points to where the inward partial does.
    face_side = np.einsum("ij,ij->i", inward[:, None] * partial, across) > 0
    plus = np.where(face_side[:, None], moved, uv)
    minus = np.where(face_side[:, None], uv, moved)
    return minus, plus


def isolated(shell_mesh: Tessellation, reach: float) -> np.ndarray:
    """Per face: True where no other face's shell comes within ``reach`` of its own (bounding boxes: conservative).

    A ray's passage of its kept hit lies within its face's shell's box grown by the longest passage,
    so there it can meet no other face's shell: its walk is skipped unless the passage is longer than the face's
    longest mesh edge (where its own shell far from the hit may lie in it, `SecondLook._elsewhere_on_face`).
    A `flat` face has no shell: its box (its mesh's, where its hits lie) counts as its own, not as another's.
    """
    lo, hi = shell_mesh.patch_bounds(shell_mesh.vertices)
    faces = len(lo)
    shelled = np.bincount(shell_mesh.face_patch, minlength=faces) > 0
    alone = np.ones(faces, dtype=bool)
    for first in range(0, faces, ISOLATION_CHUNK):  # faces × faces box tests, in bounded memory
        rows = slice(first, min(first + ISOLATION_CHUNK, faces))
        overlap = np.all((lo[rows, None] - reach <= hi[None]) & (lo[None] <= hi[rows, None] + reach), axis=2)
        overlap &= shelled[None]
        overlap[np.arange(overlap.shape[0]), np.arange(first, rows.stop)] = False  # a face and itself
        alone[rows] = ~overlap.any(axis=1)
    return alone


class SecondLook:
    """Built once per scene from its surfaces (``scene_surfaces``, as read) and the coarse tessellation."""

    def __init__(self, scene_surfaces, per_span: int, tessellation: Tessellation, surfaces: SurfaceSet):
        self._scene_surfaces, self._per_span = list(scene_surfaces), per_span
        self.tessellation, self.surfaces = tessellation, surfaces
        self.shell, self.shell_mesh, self._sheet_triangles = shell(tessellation, surfaces)
        self._reach = 2.0 * SHELL_CHORDS * float(tessellation.chord_error.max(initial=0.0))
        # Past a shell hit by float32 rounding of the scene's largest coordinates, with margin (as `trace`'s).
        self._skip = float32_rounding(tessellation)
        self.isolated = isolated(self.shell_mesh, self._reach / GRAZING_COS + 2.0 * self._skip)
        self._planes = clear_sides(tessellation, surfaces, flat(tessellation, surfaces))
        self._any_clear = bool(self._planes[2].any())
        self._lock = threading.Lock()
        self._fine: tuple[Tessellation, Accelerator] | None = None

    def fine(self) -> tuple[Tessellation, Accelerator]:
        """The finer enclosing mesh of the span grid and its BVH (module doc, step 2), built on first use."""
        with self._lock:
            if self._fine is None:
                # A reader's triangulation is subdivided in (u, v) (clipping a span grid to the trim costs ~10×).
                # One too coarse to follow its face (`reader_mesh`) is dropped: the span grid meshes that face.
                factors = fine_factors(self._scene_surfaces, self.tessellation.chord_error, self._per_span)
                finer = [s if s.mesh_uv is None or factor == 1 else
                         replace(s, mesh_uv=None if (m := reader_mesh(s)) is None else subdivided(*m, FINE_LEVELS))
                         for s, factor in zip(self._scene_surfaces, factors)]
                fine = tessellate(finer, factors * self._per_span, enclose=True, widen=True)
                self._fine = fine, Accelerator(fine)
            return self._fine

    def suspects(self, hits: Hits, origins: np.ndarray, directions: np.ndarray,
                 far: np.ndarray) -> tuple[np.ndarray, MeshHits]:
        """Indices of the rays to look at again (module doc, step 1), and per suspect the shell hit that made it
        one, or for the others (grazing, ``aside``, blocked before the passage, still walking) its first shell hit
        (step 3; prim −1 where there is none, and for every ray not suspected or a fallback)."""
        n = len(origins)
        entry = MeshHits(np.full(n, -1), np.zeros(n), np.zeros(n), np.full(n, np.nan))
        cos = np.nan_to_num(hits.cos)  # no normal (a miss): as a zero N
        slack = FLOAT32_SLACK * self.tessellation.extent
        with np.errstate(divide="ignore"):
            passage = np.where(hits.hit, hits.t - self._reach / np.maximum(cos, GRAZING_COS) - slack, far)
        look = hits.hit & ~hits.fallback & ((cos < GRAZING_COS) | hits.aside)
        ask = ~look & ~hits.fallback & ~self._in_front_of_all(hits, origins)
        # Any shell before the passage (for a ray that missed: anywhere) makes a suspect, whatever its face:
        # Embree's occlusion query answers that, cheaper than the nearest hit (the entry is found below). Asked of
        # every ray (an empty segment for the others): gathering the rays first cost more than the query saves.
        before = np.where(ask, np.clip(np.minimum(passage, np.where(hits.hit, hits.t - slack, far)), 0.0, None), 0.0)
        look |= ask & self.shell.occluded(origins, directions, before)
        rays = np.flatnonzero(ask)
        # Within the passage only another face's shell does, or the own face's far from the hit in (u, v)
        # (`_elsewhere_on_face`): walk its hits, unless no other face's shell comes within the longest passage of
        # the kept face's (`isolated`) and the passage is shorter than the face's longest mesh edge (then every
        # hit there is its own way in: the shell around a triangle or two).
        rays = rays[~look[rays] & hits.hit[rays]]
        patch = hits.patch[rays]
        rays = rays[~self.isolated[patch] | (hits.t[rays] - passage[rays] > self.tessellation.edge_length[patch])]
        start, end = np.maximum(passage[rays], 0.0), hits.t[rays] - slack
        for _ in range(SHELL_STEPS):
            go = start < end
            rays, start, end = rays[go], start[go], end[go]
            if len(rays) == 0:
                break
            O, D = origins[rays], directions[rays]
            mesh = self.shell.intersect(O + start[:, None] * D, D, end - start)
            met = mesh.prim >= 0
            t = mesh.t + start
            own = met & (self.shell_mesh.face_patch[np.maximum(mesh.prim, 0)] == hits.patch[rays])
            other = met & ~own
            other[own] = self._elsewhere_on_face(mesh.prim[own], mesh.b1[own], mesh.b2[own], hits.u[rays[own]],
                                                 hits.v[rays[own]])
            own &= ~other
            look[rays[other]] = True
            for have, new in zip(entry, (mesh.prim, mesh.b1, mesh.b2, t)):
                have[rays[other]] = new[other]
            rays, start, end = rays[own], t[own] + self._skip, end[own]
        look[rays] = True  # still walking after SHELL_STEPS: looked at again rather than passed
        # Suspects not walked (grazing, aside) or still walking: their first shell hit is refined too (step 3).
        rays = np.flatnonzero(look & ~hits.fallback & (entry.prim < 0))
        if len(rays):
            end = np.where(hits.hit[rays], hits.t[rays] - slack, far[rays])
            mesh = self.shell.intersect(origins[rays], directions[rays], end)
            for have, new in zip(entry, mesh):
                have[rays] = new
        return np.flatnonzero(look), entry

    def _elsewhere_on_face(self, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray, u: np.ndarray,
                           v: np.ndarray) -> np.ndarray:
        """True where a shell hit of the kept hit's own face, inside its passage, lies more than `FOLD_TRIANGLES` of
        its triangle's (u, v) extent from the kept (u, v) (across a closed face's seam the shorter way): not the
        ray's passage to its hit (which crosses a triangle or two of the sheet around it) but another part of the
        same face folding back within the passage, which the ray may cross first (pythonocc-demos' surf114.igs: a
        leaf curling 23 in front of its own hit, inside a 31-long passage at |N·D| 0.24, kept the far side)."""
        patch, us, vs = self.shell_mesh.start_parameters(prim, b1, b2)
        extent_u, extent_v = self._triangle_uv_extent
        u0, u1, v0, v1 = self.surfaces.domains(patch)
        closed = self.surfaces.closed[patch]
        du, dv = np.abs(us - u), np.abs(vs - v)
        du = np.where(closed[:, 0], np.minimum(du, (u1 - u0) - du), du)
        dv = np.where(closed[:, 1], np.minimum(dv, (v1 - v0) - dv), dv)
        return (du > FOLD_TRIANGLES * extent_u[prim]) | (dv > FOLD_TRIANGLES * extent_v[prim])

    @cached_property
    def _triangle_uv_extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Per shell triangle, the spread of its vertices' u and of their v, at least the mean of its face's sheet
        triangles' (a sliver or a triangle at a pole is no measure of where the passage reaches); a wall's or rim
        box's (its corners at one mesh edge's ends) the largest of its face's sheet triangles'."""
        uv = self.shell_mesh.vertex_uv[self.shell_mesh.faces]  # (T, 3, 2)
        spread = uv.max(axis=1) - uv.min(axis=1)
        sheets, patch = self._sheet_triangles, self.shell_mesh.face_patch
        faces = len(self.surfaces.patches)
        largest = np.zeros((faces, 2))
        np.maximum.at(largest, patch[:sheets], spread[:sheets])
        count = np.maximum(np.bincount(patch[:sheets], minlength=faces), 1)[:, None]
        total = [np.bincount(patch[:sheets], spread[:sheets, k], minlength=faces) for k in (0, 1)]
        mean = np.stack(total, axis=1) / count
        spread[:sheets] = np.maximum(spread[:sheets], mean[patch[:sheets]])
        spread[sheets:] = largest[patch[sheets:]]
        return spread[:, 0], spread[:, 1]

    def _in_front_of_all(self, hits: Hits, origins: np.ndarray) -> np.ndarray:
        """Rays whose kept hit lies on a plane supporting the scene, from its clear side (`clear_sides`): none nearer."""
        centre, normal, clear = self._planes
        out = np.zeros(len(origins), dtype=bool)
        if not self._any_clear:  # no face supports the scene (any curved scene): 1.4 ms of gathers per 65536 rays
            return out
        rays = np.flatnonzero(hits.hit)
        rays = rays[clear[hits.patch[rays]].any(axis=1)]
        if len(rays):
            k = hits.patch[rays]
            side = np.einsum("ij,ij->i", origins[rays] - centre[k], normal[k])
            out[rays] = np.where(side > 0, clear[k, 0], np.where(side < 0, clear[k, 1], False))
        return out

    def apply(self, hits: Hits, origins: np.ndarray, directions: np.ndarray, far: np.ndarray,
              clock: StageClock = NULL_CLOCK) -> Hits:
        """``hits`` (from `trace` on the coarse mesh) with the suspects' nearer hits, in place (module doc)."""
        with clock.stage("second look"):
            rays, entry = self.suspects(hits, origins, directions, far)
            if len(rays) == 0:
                return hits
            fine, accelerator = self.fine()
            kept = np.where(hits.hit[rays], hits.t[rays], far[rays])
            # No clearance cones on the finer mesh (`clearance`): 16× the triangles, for a few suspects.
            again = trace(accelerator, fine, self.surfaces, origins[rays], directions[rays], max_distance=kept,
                          clear=False)
            # The same root refined from another start agrees to Newton's tolerance: nearer means beyond float32 rounding.
            # A nearer valid hit is taken even where the finer trace left a candidate undecided (the ray stays a
            # fallback): it is an exact point on the ray before the kept one (far_away.step, orthographic 1e-4 of the
            # part across onto a sphere corner's silhouette: 43 rays kept no hit, where the finer trace had OCCT's
            # entry at |N·D| 0.0075 and an unresolved candidate 1.1 past it).
            slack = FLOAT32_SLACK * self.tessellation.extent
            nearer = again.hit & (again.t < kept - slack)
            rows = rays[nearer]
            hits.replace_rows(rows, again, nearer)
            hits.fallback[rays[again.fallback]] = True
            self._from_shell(hits, origins, directions, far, rays, entry)
        return hits

    def _from_shell(self, hits: Hits, origins, directions, far, rays, entry: MeshHits) -> None:
        """The suspects' shell hits refined by Newton (module doc, step 3), in place.

        Any converged point on the ray, on its face, ahead of the eye and nearer than the kept hit is an exact
        surface point before it, wherever Newton went; at grazing incidence the nearer of the sheet's two
        crossings is sought as the tracer does (`tracing._other_root`). Where Newton stops on a closed face's seam
        it goes on from the seam's other side (`tracing._over_closed_seam`: a seam wall's or rim box's start lies on
        one side only); where it fails inside the domain a
        short miss search (`SHELL_RESCUE_STEPS`) follows; a start that leads nowhere decides nothing (no miss
        verdict, no fallback: the finer mesh's trace has looked there too), and the ray's next shell hit is tried
        instead, up to `SHELL_WALK` starts.
        """
        rays = rays[(entry.prim[rays] >= 0) & ~hits.fallback[rays]]
        prim, b1, b2, t_entry = (x[rays] for x in entry)
        for step in range(SHELL_WALK):
            if len(rays) == 0:
                return
            led = self._refined_from(hits, origins, directions, far, rays, prim, b1, b2, t_entry)
            if step == SHELL_WALK - 1:
                return
            # Led nowhere (Newton left the face or failed): the ray's next shell hit before its kept hit (a ray running
            # along a face thinner than the mesh's reach meets its shell first far from where it crosses the face). A
            # start that led onto its face, to the kept hit or behind it, ends the walk: a grazing ray's shell hits
            # before its kept hit are mostly its own face's, and lead there again.
            rays, tried, t_entry = rays[~led], self.shell_mesh.face_patch[prim[~led]], t_entry[~led]
            at, prim, b1, b2, t_entry = self._next_shell_hits(hits, origins, directions, far, rays, t_entry)
            rays, tried = rays[at], tried[at]
            # The tried face's next hit is most often where the ray leaves its shell again, and leads where the entry
            # did: passed once (halves the walk's Newton runs on the sweep's rational_high.step).
            again = np.flatnonzero(self.shell_mesh.face_patch[prim] == tried)
            if len(again):
                at, p2, c1, c2, t2 = self._next_shell_hits(hits, origins, directions, far, rays[again], t_entry[again])
                moved = again[at]
                prim[moved], b1[moved], b2[moved], t_entry[moved] = p2, c1, c2, t2
                keep = np.ones(len(rays), dtype=bool)
                keep[again] = False
                keep[moved] = True
                rays, prim, b1, b2, t_entry = (x[keep] for x in (rays, prim, b1, b2, t_entry))

    def _next_shell_hits(self, hits: Hits, origins, directions, far, rays, after):
        """Each ray's first shell hit past ``after`` (by float32 rounding) and before its kept hit: the positions in
        ``rays`` of the rays that have one, and its triangle, barycentrics and t."""
        slack = FLOAT32_SLACK * self.tessellation.extent
        start = after + self._skip
        end = np.where(hits.hit[rays], hits.t[rays], far[rays]) - slack
        go = np.flatnonzero(start < end)
        rays, start, end = rays[go], start[go], end[go]
        mesh = self.shell.intersect(origins[rays] + start[:, None] * directions[rays], directions[rays], end - start)
        met = mesh.prim >= 0
        return go[met], mesh.prim[met], mesh.b1[met], mesh.b2[met], mesh.t[met] + start[met]

    def _refined_from(self, hits: Hits, origins, directions, far, rays, prim, b1, b2, t_entry) -> np.ndarray:
        """`_from_shell` from one shell hit (``prim``, ``b1``, ``b2`` at ``t_entry``) of each of ``rays``, in place:
        which of them led to a point on the ray on its face (a nearer hit, then kept, or one not nearer)."""
        O, D = origins[rays], directions[rays]
        patch, u, v = self.shell_mesh.start_parameters(prim, b1, b2)
        u0, v0 = u, v
        u, v, derivs, converged, edge, normal, cosine = refine_all(self.surfaces, patch, u, v, O, D, t_entry,
                                                                   self.tessellation.extent)
        # A start on a closed face's seam (its last wall or rim box) may lie on the side away from the hit.
        over = _over_closed_seam(self.surfaces, patch, u, v, derivs, converged, edge, O, D, t_entry,
                                 self.tessellation.extent)
        _normals(self.surfaces, patch, derivs, D, over, normal, cosine, np.zeros(len(rays), dtype=bool))
        # Newton from a start far along a grazing ray can fail where the ray does meet the sheet: search there.
        # (Not where Newton ran off the face's domain: the ray leaves the face there, as `tracing._candidates` decides;
        # but a stop on a collapsed side, a pole, which is one point in 3D, has not left it: the search decides there.)
        off = edge & ~_stopped_at_pole(self.surfaces, patch, u, v, edge)
        stuck = np.flatnonzero(~converged & ~off)
        if len(stuck):
            tol = _search_tolerance(t_entry[stuck], self.tessellation.extent)
            u2, v2, d2, ok2, _, _ = _rescue(self.surfaces, patch[stuck], u0[stuck], v0[stuck], O[stuck], D[stuck], tol,
                                            SHELL_RESCUE_STEPS)
            u[stuck], v[stuck], converged[stuck] = u2, v2, ok2
            for have, new in zip(derivs[:3], d2[:3]):
                have[stuck] = new
            _normals(self.surfaces, patch, derivs, D, stuck, normal, cosine, np.zeros(len(rays), dtype=bool))
        t = np.einsum("ij,ij->i", derivs.S - O, D)
        kept = np.where(hits.hit[rays], hits.t[rays], far[rays])
        slack = FLOAT32_SLACK * self.tessellation.extent
        led = converged & (t > 0)  # behind the eye: no crossing of this ray, the walk goes on
        led[led] = self.surfaces.on_face(patch[led], u[led], v[led])
        ok = led & (t < kept - slack)
        rays, O, D, patch, u, v, t, normal, cosine = (x[ok] for x in (rays, O, D, patch, u, v, t, normal, cosine))
        if len(rays) == 0:
            return led
        derivs = SurfaceDerivatives(derivs.S[ok], derivs.Su[ok], derivs.Sv[ok])
        _other_root(self.tessellation, self.surfaces, O, D, np.full(len(rays), VALID), patch, u, v, t, derivs,
                    normal, cosine, np.zeros(len(rays), dtype=bool))
        hits.hit[rays], hits.patch[rays], hits.u[rays], hits.v[rays], hits.t[rays] = True, patch, u, v, t
        hits.P[rays], hits.aside[rays] = derivs.S, True
        hits.Su[rays], hits.Sv[rays] = derivs.Su, derivs.Sv
        hits.N[rays] = facing(self.surfaces.normals(patch, u, v, derivs), D)
        hits.cos[rays] = np.abs(np.einsum("ij,ij->i", hits.N[rays], D))
        hits.curvature[rays] = np.nan  # not known at the new hits: the AOV stage computes them
        return led
