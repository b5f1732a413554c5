"""Validation: the render against the analytic contours f = c_k (paper section 4).

The scene is rendered as `rtreflect render` would (`Renderer.render`: colour at the
scene's samples, AOVs from the pixel-centre rays) and checked two ways.

**Traced centres.** The render's `f` AOV and the analytic level sets must agree: the
traced line of tube k is centred where f = c_k. Between two neighbouring pixel centres
(horizontal or vertical) where f − c_k changes sign, the centre is placed on the cubic
through f at the four pixel centres around the crossing (linear interpolation would err
by up to |f''|/(8|f'|) px where lines bend tightly). A pair counts only when it lies
inside one smooth, visible piece of surface where the pixels resolve the lines, and tube
k is really seen there: the pair and the pairs before and after it hit the same patch
with exact hits (P = S(u, v): no Newton fallback) and finite f, neighbouring hit points
are no farther apart than `JUMP_FOOTPRINTS` pixel footprints (so no silhouette or
occlusion edge lies between them), f changes by less than 1/`MIN_LINE_GAP_PX` of tube k's
neighbour gap per pixel (the nearest tube at another position is at least that many pixels
away there: resolvability is decided per line and locally, so one tube close to another does
not blind the check for the rest), both pixels have
``line.id == k`` (tube k, or one at the same position, is the nearest tube ahead, within
its length) and neither pixel's reflected ray is blocked before the light plane. A pixel whose
f lies on c_k exactly (as float32 stores it) makes a crossing only where the pixels past it lie
on the other side: a level f only touches is no line (`_touches`).

**Deviation.** Each traced centre's distance in pixels to the nearest segment of tube
k's projected analytic polylines, or, where that is beyond the tolerance, to the exact root
of f = c_k between its own two pixels' hits if nearer (`exact_crossings`: the contours' grid
can step over a strip narrower than a cell). A centre whose nearest contour point is the open end
of a polyline (where visibility, a patch edge or the tube's end cuts the contour), and
lies within `END_MARGIN_PX` of it, sits beyond the analytic line's end and is left out.

**Misses** (both directions): analytic contour points with no traced centre of the same
tube within `MISS_RADIUS_PX`, counted only away from silhouettes, patch edges, occlusion
boundaries, pixels whose reflected ray is blocked (lines seen along a ray) and the image border
(the pixel is `CLEAN_MARGIN_PX` from any such pixel, and
the point is `END_MARGIN_PX` along the contour from a polyline end), and not on a closed contour
round no pixel centre (`encloses_a_pixel_centre`: no two centres lie on either side of it); plus
traced centres with no analytic contour of their tube within `SEARCH_RADIUS_PX` and no exact root
between their pixels.

**Colour.** The lines that are drawn (the `lit` flags of eq. 4 with occlusion, weighted by
the stripe profile and blended into RGB over the shaded surface) are checked against the
pixel-centre `line.dist` d and its gradient: the share of the line colour in a pixel must lie
between the profile's weights at its farthest and nearest samples, so a pixel all of whose
samples lie within the radius of an unblocked tube must be fully lit and one all of whose
samples lie outside must show no line (`colour_mismatches`). The surface colour each pixel is
read against is shaded as the renderer shades it (`modes.shading`, from the pixel-centre N and ray).

A scene passes when the maximum deviation is within the tolerance, there are no misses
and no colour mismatches, and something was compared: at least one traced centre, and
every tube with `NOTHING_COMPARED_POINTS` analytic points in clean view has some.
Overall figures count each tube position once (tubes sharing a position draw one line).

**Unresolved lines.** Where a tube's neighbour line comes closer than `MIN_LINE_GAP_PX`
pixels, the pixel grid cannot tell the two apart and that stretch of the line is not
checked. Each line reports how many of its analytic points in clean view were left out for
this (``unresolved_points``), and a line left out mostly or wholly is named in the report's
notes: unchecked, not failed, and not silently dropped. Likewise a pixel's colour is not checked where φ moves
to a neighbouring pixel by more than half the spacing to the next level near the bank (`_unresolved`): σ may
bend through a stripe between two pixel centres that both lie off it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Callable

import numpy as np

from .contours import ContourLines, UlmetField, analytic_contours, field_of, reaches_light_plane  # noqa: F401 (UlmetField: callers)
from .nearest import nearest_segment
from .parallax import zebra_parallax
from ..integrator.film import Film
from ..modes.base import SurfacePoints, level_offset
from ..modes.legend import LEGEND_MODES
from ..modes.regions import FaceRegions
from ..modes.lights import reflect
from ..modes.reflection import ReflectionMode
from ..modes.profile import stripe_reach, stripe_weight
from ..modes.shading import shade_factor
from ..integrator.autorig import resolve
from ..integrator.analytic import EDGE_SAMPLES
from ..integrator.renderer import Renderer
from ..exchange.scene import ANALYTIC, MAX_MESH_VERTICES, Scene
from ..geometry.tessellation import Tessellation, distinct, largest_factor, reader_mesh, tessellate
from ..trace.accelerator import Accelerator
from ..trace.tracing import occluded, refine

DEFAULT_TOLERANCE_PX = 0.5
#: A pixel's colour is checked where the stripe profile pins the line's share to an interval this narrow: half the
#: contrast between line and surface, so the check at least tells a pixel nearer the line colour from one nearer
#: the surface; across a hard stripe edge (0 to 1) nothing is pinned and the pixel is left out.
COLOUR_CHECK_SPAN = 0.5
#: Neighbouring hit points farther apart than this many pixel footprints straddle an edge (or graze).
JUMP_FOOTPRINTS = 8.0
#: Share of the surface pixels that must see a tube (pixel centre within the radius, eq. 4) for the picture to
#: show lines at all: the shipped scenes draw lines on 10-25 % of the surface; tubes placed below a surface
#: reflect at a few grazing silhouette pixels (0.05 %), whose few centres must not make the scene pass.
MIN_DRAWN_SHARE = 0.005
#: Lines closer together than this in the image are not resolved by the pixel grid: no centres, no misses there.
MIN_LINE_GAP_PX = 3.0
#: Traced centres with no analytic contour within this distance are misses.
SEARCH_RADIUS_PX = 16.0
#: An analytic point with no traced centre within this distance is a miss.
MISS_RADIUS_PX = 1.5
#: Contour points this close (along the contour) to a polyline end are not checked for misses,
#: and traced centres this close beyond an end are left out.
END_MARGIN_PX = 2.0
#: Contour points are checked for misses only this many pixels from unusable pixels and the border.
CLEAN_MARGIN_PX = 2
#: A tube with this many analytic points in clean view (checked for misses) must have compared points.
NOTHING_COMPARED_POINTS = 5
#: A stored hit is on the surface when the pixel-centre ray at the stored distance Z meets S(u, v) within this
#: fraction of the part's size (bounding-box diagonal), beyond the rounding of the stored float32 Z, u and v.
#: Relative to the part, not to |P|: far from the origin |P| would allow whole chord errors (10⁵ |P| ≈ 1 unit).
ON_SURFACE = 1e-5
#: Float32's unit roundoff, 2⁻²⁴: the rounding of a stored AOV value relative to its magnitude.
FLOAT32_ROUNDOFF = 2.0**-24
#: A ray meeting the surface at cos θ = |N·D| at least this (θ ≤ 84°) does not graze it: Newton converges there, so
#: a fallback there, with the pixel's four neighbours on the same patch (no silhouette or seam), is a fault.
GRAZING_COS = 0.1
#: The stored N must lie within this angle (radians) of the normal S_u × S_v at the stored (u, v). Float32 storage
#: moves both by ~1e-7; a normal from a wrong formula or a wrong degenerate-point verdict is off by far more.
NORMAL_ANGLE = 1e-4
#: S_u × S_v is a trustworthy reference only where the partials are well apart (sine of their angle) and
#: clear of rounding (|S_u| (u1 − u0) against the net's reach): generous bounds, unlike the renderer's own.
TANGENT_SINE = 1e-3
TANGENT_FLOOR = 1e-6
#: A line whose neighbour is too close for more than this share of its clean-view points gets a note: a few
#: points where lines crowd (near a silhouette, at grazing angles) are normal; most of a line is worth saying.
NOTE_UNRESOLVED_SHARE = 0.5
#: The nearer-hit check's own mesh has this many times the scene's segments per knot span (chord error ~1/36 of
#: the renderer's), fewer where that exceeds the vertex limit: sheets the renderer's mesh merges come apart.
#: Not 4 (nor 2): the renderer's second look traces suspect rays on a 4× mesh (trace/secondlook.py), and the
#: check must not share the mesh it judges.
FINE_TESSELLATION = 6
#: A face the renderer meshes by its reader's triangulation (a CAD face) gets the fewest segments per span, up to
#: the factor above, whose span grid lies within this share of that triangulation's chord error of the surface:
#: its span grid at the scene's own count is often far finer already (sunglasses_lens.igs of pythonocc-core, 9
#: faces of 13 × 13 spans: 6.2 million vertices at the factor above, 49 s of a 50 s validate at 320×180).
FINE_CHORD_SHARE = 1.0 / 16.0
#: How far beyond an exact point the fine mesh's hit may lie, in fine chord errors: 2 chords (the mesh-to-surface
#: gap across the surface) grown 10× for incidence down to cos θ = 0.1.
FINE_BAND_CHORDS = 20.0
#: Fine-mesh hits examined per ray before the stored point: bounds the work on a ray through a stack of sheets.
FINE_MAX_HITS = 16
#: Rays per chunk of the nearer-hit check: bounds its memory (a few dozen float64 per ray and step).
NEARER_CHUNK = 1 << 16
#: Relative float32 rounding of Embree's coordinates, with margin: where the next query starts beyond a mesh hit.
FINE_SLACK = 1e-6


def neighbour_gaps(c_k: np.ndarray) -> np.ndarray:
    """Per tube, the distance from its position to the nearest other position (inf when it is alone).

    Tubes sharing a position draw one line: they are not each other's neighbours.
    """
    positions = np.unique(c_k)
    if len(positions) < 2:
        return np.full(len(c_k), math.inf)
    steps = np.diff(positions)
    nearest = np.minimum(np.concatenate([[math.inf], steps]), np.concatenate([steps, [math.inf]]))
    return nearest[np.searchsorted(positions, c_k)]


@dataclass(frozen=True)
class LineSpec:
    """The lines under test: the levels c_k of φ, the stripe's half width in line.dist's unit and its profile.

    Reflection lines (`along_ray`): φ = f, the tubes' radius, the blur, and stripes seen along the
    reflected ray, so their traced centres and colours are checked for occlusion up to the tube
    (`reach`: the radius out to the blur's reach). Another mode's lines are drawn where they are:
    φ its own, line.dist |φ − c_k| (highlight: the skew-line distance to the tube), hard edges.
    """

    levels: np.ndarray
    radius: float
    blur: float
    along_ray: bool
    reach: float
    tubes: bool = True  # line.id names a tube (occlusion up to it); else the ray is tested up to the light plane


def line_spec(renderer: Renderer) -> LineSpec:
    """The `LineSpec` of the renderer's `[render] mode` (circular reflection lines are seen along the ray too)."""
    if isinstance(renderer.mode, ReflectionMode):
        return LineSpec(renderer.lights.c_k, renderer.lights.radius, renderer.scene.render.blur, True,
                        renderer.stripe_lights.radius)
    mode = renderer.mode
    blur = renderer.scene.render.blur if renderer.soft_stripes else 0.0
    return LineSpec(np.asarray(mode.levels, dtype=np.float64), float(mode.half_width), blur,
                    mode.along_ray, stripe_reach(float(mode.half_width), blur), tubes=False)


@dataclass
class PixelAOVs:
    """Per-pixel values of a finished render, (H, W) or (H, W, 3), in float64.

    From the film (`Renderer.render`): the AOVs of the pixel-centre ray (f, patch, P, N, Z,
    line.id, line.dist) and A, with P of exact hits replaced by S(u, v) in float64; ``s`` is
    recomputed from N and the camera's pixel-centre ray (paper eq. 3); ``line_coverage`` is the share of the line
    colour (the samples' mean stripe weight), read back from RGB against the shaded surface colour (see `line_coverage`); ``fallback`` marks hits off the surface (Newton failed, the
    mesh hit kept: P ≠ S(u, v), or the ray at distance Z ≠ S(u, v)); ``incidence`` is |N·D|
    for the pixel-centre ray D; ``normal_error`` the angle between N and S_u × S_v at (u, v)
    on exact hits where that reference is trustworthy (NaN elsewhere); ``nearer`` marks exact
    hits with an exact surface point before them on the pixel-centre ray (`nearer_surface`).
    """

    f: np.ndarray
    patch: np.ndarray
    P: np.ndarray
    N: np.ndarray
    s: np.ndarray
    Z: np.ndarray
    line_id: np.ndarray
    line_dist: np.ndarray
    fallback: np.ndarray
    coverage: np.ndarray  # A: fraction of samples that hit the surface
    line_coverage: np.ndarray  # fraction of samples that see a tube (NaN where colours cannot tell)
    incidence: np.ndarray | None = None
    normal_error: np.ndarray | None = None
    nearer: np.ndarray | None = None  # exact hits with an exact surface point before them on the ray (`nearer_surface`)
    # Signed offset σ from the centre of line.id's level (`modes.base.level_offset`; line.dist = |σ|), NaN where
    # none is: the colour check's slopes are taken of σ, since |σ| folds at a line's centre and understates them.
    line_offset: np.ndarray | None = None
    # A map mode's surface colour varies within a pixel, and a sampled pixel shows its samples' mean, not the centre's
    # colour the line share is read against: the share L this may move, (H, W) (`map_bend`); None for one colour.
    map_bend: np.ndarray | None = None
    # The knot span (u, v) of each pixel's hit as one key, (H, W) (`knot_spans`), between the knot lines where f (or
    # φ) creases or jumps: every knot for a curvature map (φ of second derivatives), the surface's creases for the
    # others (`normal_breaks`). Pixels in different spans are no smooth pair (`_smooth_pairs`). None: no line counts.
    span: np.ndarray | None = None
    uv: np.ndarray | None = None  # (H, W, 2) the hit's (u, v) (float32 storage)


def line_offsets(renderer: Renderer, points: SurfacePoints, level: np.ndarray, size: int,
                 hit: np.ndarray) -> np.ndarray:
    """Per pixel σ of the hits ``hit`` (their ``points``) to their level ``level`` (−1: none; σ NaN there)."""
    sigma = np.full(size, np.nan)
    has = np.flatnonzero(level >= 0)
    if len(has):
        sigma[hit[has]] = level_offset(renderer.mode, SurfacePoints(*(getattr(points, f.name)[has] for f in fields(points))),
                                       level[has].astype(int))
    return sigma


def line_coverage(rgba: np.ndarray, surface_color, line_color, background) -> np.ndarray:
    """Share L of the line colour in a pixel (the mean stripe weight of its samples), from its linear RGBA.

    film.coverage_color inverted: RGB = L·line_color + (A − L)·surface_color + (1 − A)·background,
    so RGB − A·surface_color − (1 − A)·background = L·(line_color − surface_color): L by least
    squares over the three channels. ``surface_color`` may be one colour or one per pixel (..., 3):
    the shaded surface colour (`modes.shading`). NaN where line and surface colours are equal.
    """
    line_color, surface_color, background = (np.asarray(c, dtype=np.float64) for c in
                                             (line_color, surface_color, background))
    contrast = line_color - surface_color
    denom = np.sum(contrast * contrast, axis=-1)
    A = rgba[..., 3:4].astype(np.float64)
    rest = rgba[..., :3].astype(np.float64) - A * surface_color - (1.0 - A) * background
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(denom > 0.0, np.sum(rest * contrast, axis=-1) / np.where(denom > 0.0, denom, 1.0), np.nan)


def film_aovs(renderer: Renderer, film: Film) -> PixelAOVs:
    """The film's pixel values as `PixelAOVs` (see there)."""
    height, width = film.height, film.width
    channel = lambda name: film.channel(name).astype(np.float64)  # noqa: E731
    triple = lambda prefix: np.stack([channel(f"{prefix}.{c}") for c in "XYZ"], axis=-1)  # noqa: E731
    P, N = triple("P"), triple("N")
    N /= np.linalg.norm(N, axis=-1, keepdims=True)  # float32 storage: back to unit length
    uv = np.stack([channel("u"), channel("v")], axis=-1)  # read once: the stored-hit check, σ and `PixelAOVs.uv`
    u, v = uv[..., 0].ravel(), uv[..., 1].ravel()
    patch = channel("patch")
    hit = np.flatnonzero(patch.ravel() >= 0)
    rows, cols = np.divmod(hit, width)
    origins, directions = renderer.camera.rays(rows, cols)
    s = np.full((height * width, 3), np.nan)
    s[hit] = reflect(-directions, N.reshape(-1, 3)[hit])
    fallback = np.zeros(height * width, dtype=bool)
    incidence = np.full(height * width, np.nan)
    incidence[hit] = np.abs(np.einsum("ij,ij->i", N.reshape(-1, 3)[hit], directions))
    normal_error = np.full(height * width, np.nan)
    nearer = np.zeros(height * width, dtype=bool)
    if renderer.vertex_normals is None:  # exact mode; mesh mode never falls back (and is never on S)
        fallback[hit], normal_error[hit], S = _stored_hit_errors(
            renderer, patch.ravel()[hit].astype(int), u[hit], v[hit],
            P.reshape(-1, 3)[hit], N.reshape(-1, 3)[hit], channel("Z").ravel()[hit], origins, directions)
        # Exact hits: P as S(u, v) in float64. Far from the origin float32 P is coarse (1/128 at 10⁵), and the
        # checks below (occlusion rays, neighbour distances) need the point as the renderer had it.
        exact = hit[~fallback[hit]]
        P.reshape(-1, 3)[exact] = S[~fallback[hit]]
        # Fallbacks are reported as such; an exact hit must also be the nearest exact point on its ray.
        on = ~fallback[hit]
        nearer[exact] = nearer_surface(renderer, patch.ravel()[exact].astype(int), channel("Z").ravel()[exact],
                                       origins[on], directions[on])
    line_id = channel("line.id")
    line_offset = None
    if isinstance(renderer.mode, ReflectionMode):  # another mode's σ is its own (`mode_aovs`)
        points = SurfacePoints(P.reshape(-1, 3)[hit], N.reshape(-1, 3)[hit], s[hit], patch.ravel()[hit].astype(int),
                               u[hit], v[hit])
        line_offset = line_offsets(renderer, points, line_id.ravel()[hit], height * width, hit).reshape(height, width)
    render = renderer.scene.render
    # The surface colour as the renderer shaded it at the pixel centre (its samples' shade differs to second order).
    surface = np.broadcast_to(render.surface_color, (height * width, 3)).copy()
    surface[hit] *= shade_factor(N.reshape(-1, 3)[hit], directions, render.shading)[:, None]
    return PixelAOVs(
        f=channel("f"), patch=patch, P=P, N=N, s=s.reshape(height, width, 3), Z=channel("Z"),
        line_id=line_id, line_dist=channel("line.dist"), fallback=fallback.reshape(height, width),
        coverage=channel("A"),
        line_coverage=line_coverage(film.pixels[..., :4], surface.reshape(height, width, 3), render.line_color,
                                    render.background),
        incidence=incidence.reshape(height, width), normal_error=normal_error.reshape(height, width),
        nearer=nearer.reshape(height, width), line_offset=line_offset, span=knot_spans(renderer, film, normal_breaks),
        uv=uv,
    )


def normal_breaks(surface) -> tuple[np.ndarray, np.ndarray]:
    """A patch's domain ends and its creases (`NurbsSurface.creases`: knot lines where the normal jumps), in u and
    in v.

    f, and the other modes' φ of the normal, jump there too, and the cubic through four pixels (`_crossing`) across
    a crease finds a line where none is drawn. OCCT's data/iges/PRO20359-L2.igs, a degree-5 face whose v knots 1 and
    2 (m = 5) turn the normal by up to 7° either side of a sliver 0.018 wide: pairs across the sliver counted as
    smooth, 31 misses and 5 colour mismatches at 320×180."""
    (u0, u1), (v0, v1) = surface.domain
    creases_u, creases_v = surface.creases
    return np.concatenate([[u0], creases_u, [u1]]), np.concatenate([[v0], creases_v, [v1]])


def knot_spans(renderer: Renderer, film: Film, breaks=lambda surface: surface.span_breaks()) -> np.ndarray:
    """(H, W) key of each pixel's knot span: (span of u, span of v) as one integer, unique within its patch (pairs
    compare the patch too, `_smooth_pairs`), −1 off the surface. ``breaks``: a patch's span limits (all its knots;
    its creases, `normal_breaks`, for a field of the normal alone).

    Curvature is C^(p − 2 − m) across a knot of multiplicity m: C⁰ (a crease) on a bicubic's simple knots, a jump
    where a knot is doubled. The cubic through four pixels (`_crossing`) across such a knot line put the traced
    centre of H = 0 0.70 px off the analytic one (the sweep's near_knots.step at 320×180, its rows straddling
    u = 0.25 and v = 0.3 / 0.300001: φ −0.0015, −0.0017, 0.0079, −0.0086). For max |κ| and the radius the key also
    holds which of |κ1|, |κ2| is the larger: φ creases where they meet."""
    patch = film.channel("patch").astype(np.int64)
    u, v = film.channel("u").astype(np.float64), film.channel("v").astype(np.float64)
    key = np.full(patch.shape, -1, dtype=np.int64)
    for k in np.unique(patch[patch >= 0]):
        on = patch == k
        breaks_u, breaks_v = breaks(renderer.surfaces.patches[int(k)])
        su = np.searchsorted(breaks_u[1:-1], u[on], side="right")
        sv = np.searchsorted(breaks_v[1:-1], v[on], side="right")
        key[on] = (int(k) * (len(breaks_u) + 1) + su) * (len(breaks_v) + 1) + sv
    if getattr(renderer.mode, "quantity", None) in ("maxabs", "radius"):
        # max(|κ1|, |κ2|) creases where the two meet: the branch it takes is part of the key (rational_high.step at
        # 160×90: φ = |κ2| 0.0204, 0.0204 then κ1 0.0223, 0.0257 down a column, the cubic's centre 0.52 px off).
        # Not on a face where φ is constant (a sphere, umbilic all over: which is larger is rounding there, and the
        # key would split the face into noise that no colour check could pass).
        k1, k2 = np.abs(film.channel("k1").astype(np.float64)), np.abs(film.channel("k2").astype(np.float64))
        lined = (patch >= 0) & ~np.asarray(renderer.mode.constant_faces)[np.maximum(patch, 0)]
        key = np.where(key >= 0, 2 * key + (lined & (k1 >= k2)), key)
    return key


def mode_aovs(renderer: Renderer, film: Film, aovs: PixelAOVs) -> PixelAOVs:
    """The AOVs as another mode's lines see them: f := φ (channel phi), line.id and line.dist of the mode's stripes.

    The nearest level and its distance are the mode's own (`Mode.stripes`) at the pixel-centre hit
    (P as S(u, v), the stored N, s); a map mode's line share is read against its own surface
    colour there (map modes are not shaded, `film.map_color`).
    """
    height, width = film.height, film.width
    size = height * width
    hit = np.flatnonzero(aovs.patch.ravel() >= 0)
    points = SurfacePoints(aovs.P.reshape(-1, 3)[hit], aovs.N.reshape(-1, 3)[hit], aovs.s.reshape(-1, 3)[hit],
                           aovs.patch.ravel()[hit].astype(int), film.channel("u").ravel()[hit].astype(np.float64),
                           film.channel("v").ravel()[hit].astype(np.float64))
    stripes = renderer.mode.stripes(points)
    line_id, line_dist = np.full(size, -1.0), np.full(size, np.nan)
    line_id[hit], line_dist[hit] = stripes.level_id, stripes.level_dist
    coverage = aovs.line_coverage
    rgb = renderer.mode.surface_rgb(points)
    if rgb is not None:
        surface = np.broadcast_to(renderer.scene.render.background, (size, 3)).copy()
        surface[hit] = rgb
        render = renderer.scene.render
        coverage = line_coverage(film.pixels[..., :4], surface.reshape(height, width, 3), render.line_color,
                                 render.background)
        bend = map_bend(surface.reshape(height, width, 3), render.line_color)
    else:
        bend = None
    phi = film.channel("phi").astype(np.float64)
    curvature = renderer.mode.name == "curvature"
    span = knot_spans(renderer, film) if curvature else aovs.span  # the others': film_aovs's, by the creases
    if curvature and len(renderer.mode.levels):
        # A region inside a face (φ at a level to rounding, no stripe: `modes.regions`) is a piece of its own: along
        # its edge φ leaves the level without crossing it, no line the pixels can trace (the sweep's kink.step, κ1 ≡ 0
        # where the face bends one way: the analytic contour runs along that edge).
        region = np.zeros(size, dtype=bool)
        lined = renderer.mode.lined_at(points)
        region[hit] = lined & np.isfinite(phi.ravel()[hit]) & (stripes.level_id < 0)
        span = np.where(span >= 0, 2 * span + region.reshape(height, width), span)
    return replace(aovs, f=phi, line_id=line_id.reshape(height, width),
                   line_dist=line_dist.reshape(height, width), line_coverage=coverage,
                   line_offset=line_offsets(renderer, points, stripes.level_id, size, hit).reshape(height, width),
                   map_bend=bend, span=span)


def second_differences(grid: np.ndarray) -> np.ndarray:
    """|g_xx| + |g_yy| of an image (H, W[, C]) by central differences (0 on its border rows and columns): where a
    field bends within a pixel, g_xx x²/2 + g_yy y²/2 with |x|, |y| ≤ ½ moves its samples off the centre's value by at
    most that over 8 (`map_bend`, and the σ bend in `colour_mismatches`)."""
    bend = np.zeros_like(grid)
    bend[:, 1:-1] += np.abs(grid[:, :-2] - 2.0 * grid[:, 1:-1] + grid[:, 2:])
    bend[1:-1, :] += np.abs(grid[:-2, :] - 2.0 * grid[1:-1, :] + grid[2:, :])
    return bend


def map_bend(rgb: np.ndarray, line_color) -> np.ndarray:
    """(H, W) bound on how far a map mode's line share L, read against the pixel-centre surface colour (`line_coverage`),
    moves where the pixel shows its samples' mean colour: the colour's second differences to the neighbours,
    (|c_xx| + |c_yy|) / 8 as for σ in `colour_mismatches`, projected on the line-surface contrast.

    Linear in the pixel the map's mean is its centre's colour; where φ bends (a curvature map along a knot line,
    where H is only C0) it is not: the sweep's periodic_bspline.step, mean curvature at 160×90, read L −0.033 and
    −0.040 at two pixels on its knot u = 5 (φ 0.0024 above both neighbours), beyond half a sample, a false FAIL.
    """
    bend = second_differences(rgb)
    contrast = np.asarray(line_color, dtype=np.float64) - rgb
    denom = np.sum(contrast * contrast, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(denom > 0.0, np.sum(bend / 8.0 * np.abs(contrast), axis=-1) / np.where(denom > 0.0, denom, 1.0),
                        0.0)


def _stored_hit_errors(renderer: Renderer, patch: np.ndarray, u: np.ndarray, v: np.ndarray, P: np.ndarray,
                       N: np.ndarray, Z: np.ndarray, origins: np.ndarray,
                       directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per stored hit: off the surface (a fallback), the angle of N to S_u × S_v (NaN where not checked), S(u, v).

    On the surface: the pixel-centre ray at the stored distance, O + Z D, and the stored P both
    meet S(u, v) within `ON_SURFACE` of the part's size, plus what float32 storage of Z, u, v
    (and of P: its coordinates' own rounding) can move them. O + Z D keeps its precision far
    from the origin, where P's float32 coordinates cannot tell a mesh hit from the surface.
    """
    derivs = renderer.surfaces.evaluate(patch, u, v)
    S, Su, Sv = derivs.S, derivs.Su, derivs.Sv
    len_u, len_v = np.linalg.norm(Su, axis=1), np.linalg.norm(Sv, axis=1)
    rounding = FLOAT32_ROUNDOFF * (np.abs(Z) + len_u * np.abs(u) + len_v * np.abs(v))
    allowed = ON_SURFACE * renderer.tessellation.extent + 2.0 * rounding
    on_ray = np.linalg.norm(origins + Z[:, None] * directions - S, axis=1) <= allowed
    on_point = np.linalg.norm(P - S, axis=1) <= allowed + 2.0 * FLOAT32_ROUNDOFF * np.linalg.norm(P, axis=1)
    fallback = ~(on_ray & on_point)
    cross = np.cross(Su, Sv)
    norm = np.linalg.norm(cross, axis=1)
    u0, u1, v0, v1 = renderer.surfaces.domains(patch)
    reach = np.array([surface.reach for surface in renderer.surfaces.patches])[patch]
    with np.errstate(invalid="ignore", divide="ignore"):
        trusted = ~fallback & (norm > TANGENT_SINE * len_u * len_v) \
            & (len_u * (u1 - u0) > TANGENT_FLOOR * reach) & (len_v * (v1 - v0) > TANGENT_FLOOR * reach)
        angle = np.arctan2(np.linalg.norm(np.cross(N, cross), axis=1), np.abs(np.einsum("ij,ij->i", N, cross)))
    return fallback, np.where(trusted, angle, np.nan), S


def fine_tessellation_factor(renderer: Renderer) -> int:
    """`FINE_TESSELLATION`, or the largest factor below it whose mesh fits `MAX_MESH_VERTICES` (at least 1)."""
    return largest_factor(renderer.scene.surfaces, renderer.scene.render.tessellation, FINE_TESSELLATION,
                          MAX_MESH_VERTICES)


def fine_mesh(renderer: Renderer) -> Tessellation:
    """The nearer-hit check's enclosing mesh (`nearer_surface`): each face's span grid at `fine_tessellation_factor`
    × the scene's segments per knot span, or, on a face the renderer meshes by its reader's triangulation, at the
    fewest multiple of them, from 1 up, whose chord error (measured at the scene's count, falling as its square)
    is at most `FINE_CHORD_SHARE` of that triangulation's."""
    per_span = renderer.scene.render.tessellation
    most = fine_tessellation_factor(renderer)
    grids = [replace(s, mesh_uv=None) if s.mesh_uv is not None else s for s in renderer.scene.surfaces]
    factors = np.full(len(grids), most, dtype=np.int64)
    # The faces the renderer meshes by their reader's triangulation: not those whose triangulation `reader_mesh`
    # dropped as too coarse, which it meshes by the span grid (the second look's at 4×: the check must not share it).
    read = np.flatnonzero([reader_mesh(s) is not None for s in renderer.scene.surfaces])
    if len(read) and most > 1:
        grid_chord = tessellate([grids[k] for k in read], per_span, enclose=True).chord_error
        target = FINE_CHORD_SHARE * renderer.tessellation.chord_error[read]
        with np.errstate(divide="ignore", invalid="ignore"):
            needed = np.ceil(np.sqrt(grid_chord / target))
        # A face its reader meshed exactly (a plane: target 0) needs no more than its grid's own exactness; a figure
        # that is not finite decides nothing: the full factor.
        needed = np.where(target > 0, needed, np.where(grid_chord > 0, most, 1))
        known = np.isfinite(target) & np.isfinite(grid_chord)
        factors[read] = np.where(known, np.clip(np.nan_to_num(needed, nan=most, posinf=most), 1, most), most)
    return tessellate(grids, factors * per_span, enclose=True)


def _well_inside(surfaces, patch, u, v, Su, Sv, margin: float) -> np.ndarray:
    """True where (u, v) lies on its face (domain and trim) with the points ``margin`` away along S_u and S_v too.

    (u ± δu, v ± δv) with δ = margin / |S_·|: the parameter steps that move S by about ``margin``
    (infinite at a degenerate point, which is then not inside).
    """
    with np.errstate(divide="ignore"):
        du, dv = margin / np.linalg.norm(Su, axis=1), margin / np.linalg.norm(Sv, axis=1)
    u0, u1, v0, v1 = surfaces.domains(patch)
    inside = (u - du >= u0) & (u + du <= u1) & (v - dv >= v0) & (v + dv <= v1)
    for su, sv in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
        inside &= surfaces.on_face(patch, u + su * du, v + sv * dv)
    return inside


def nearer_surface(renderer: Renderer, patch: np.ndarray, Z: np.ndarray, origins: np.ndarray,
                   directions: np.ndarray) -> np.ndarray:
    """True where an exact surface point lies on the ray (O, D) before the stored hit at distance Z.

    Independent of the renderer's candidate search (tracing.py): a mesh of its own (`fine_mesh`: the span grid on
    every face, also where a reader gave its own triangulation, finer than the renderer's), enclosing the surface,
    in its own BVH.
    Along each ray, every fine-mesh hit up to Z − tol + `FINE_BAND_CHORDS` fine chord errors is
    taken in turn (at most `FINE_MAX_HITS`) and refined by Newton on its own face (`refine`, the
    shared solver). One that converges (S(u, v) on the ray to Newton's tolerance), inside its
    face by more than `ON_SURFACE` of the part's size (`_well_inside`: a ray that meets the face closer
    to its edge than that may pass it, as far as the renderer can tell), at 0 < t < Z − tol is an exact
    surface point nearer than the stored one: a fault,
    wherever Newton went (a point on the ray is one, whichever mesh hit led there). tol is
    `ON_SURFACE` of the part's size plus float32 rounding of the stored Z. A hit whose Newton fails
    decides nothing (the fine mesh lies within 1/16 of the renderer's chord error of the surface,
    where Newton converges). Work and memory are bounded by chunks of `NEARER_CHUNK` rays.
    """
    nearer = np.zeros(len(Z), dtype=bool)
    if len(Z) == 0:
        return nearer
    fine = fine_mesh(renderer)
    accelerator = Accelerator(fine)
    surfaces = renderer.surfaces
    extent = renderer.tessellation.extent  # the part's size, as for the on-surface test
    tol = ON_SURFACE * extent + 2.0 * FLOAT32_ROUNDOFF * np.abs(Z)
    band = FINE_BAND_CHORDS * float(fine.chord_error.max(initial=0.0)) + FINE_SLACK * extent
    skip = FINE_SLACK * (extent + float(np.abs(fine.vertices).max(initial=0.0)))
    for lo in range(0, len(Z), NEARER_CHUNK):
        rays = np.arange(lo, min(lo + NEARER_CHUNK, len(Z)))
        start, limit = np.zeros(len(rays)), Z[rays] - tol[rays] + band
        for _ in range(FINE_MAX_HITS):
            O, D = origins[rays], directions[rays]
            mesh = accelerator.intersect(O + start[:, None] * D, D, limit - start)
            found = mesh.prim >= 0
            rays, O, D, limit = rays[found], O[found], D[found], limit[found]
            if len(rays) == 0:
                break
            t_mesh = mesh.t[found] + start[found]
            pk, us, vs = fine.start_parameters(mesh.prim[found], mesh.b1[found], mesh.b2[found])
            u, v, derivs, converged = refine(surfaces, pk, us, vs, O, D, t_mesh, extent)
            t = np.einsum("ij,ij->i", derivs.S - O, D)
            fault = converged & (t > 0) & (t < Z[rays] - tol[rays])
            maybe = np.flatnonzero(fault)  # few: the boundary test only for them
            fault[maybe] = _well_inside(surfaces, pk[maybe], u[maybe], v[maybe], derivs.Su[maybe], derivs.Sv[maybe],
                                        ON_SURFACE * extent)
            nearer[rays[fault]] = True
            start = t_mesh + skip
            go = ~fault & (start < limit)
            rays, start, limit = rays[go], start[go], limit[go]
    return nearer


def hit_faults(aovs: PixelAOVs) -> list[str]:
    """Reasons to fail found in the stored hits alone: normals off the surface, fallbacks where none belong,
    and exact hits that are not the nearest exact surface point on their ray (`PixelAOVs.nearer`).

    A fallback (Newton failed, the mesh hit kept) is expected where the ray grazes the surface
    or at a silhouette or seam; one on a ray at cos θ ≥ `GRAZING_COS` whose four neighbouring
    pixels hit the same patch is a wrong pixel (e.g. a BVH that lost precision).
    """
    reasons = []
    if aovs.normal_error is not None:
        with np.errstate(invalid="ignore"):
            off = aovs.normal_error > NORMAL_ANGLE
        if off.any():
            reasons.append(f"{int(off.sum())} pixels store a normal N off the surface normal S_u × S_v at (u, v) "
                           f"(by up to {float(np.nanmax(aovs.normal_error)):.3g} rad)")
    if aovs.incidence is not None:
        patch = np.pad(aovs.patch, 1, constant_values=-1)
        centre = patch[1:-1, 1:-1]
        inside = ((centre >= 0) & (patch[:-2, 1:-1] == centre) & (patch[2:, 1:-1] == centre)
                  & (patch[1:-1, :-2] == centre) & (patch[1:-1, 2:] == centre))
        with np.errstate(invalid="ignore"):
            stray = aovs.fallback & inside & (aovs.incidence >= GRAZING_COS)
        if stray.any():
            reasons.append(f"{int(stray.sum())} pixels inside the surface, not grazing it, keep a mesh hit off the "
                           f"surface (Newton fallback)")
    if aovs.nearer is not None and aovs.nearer.any():
        reasons.append(f"{int(aovs.nearer.sum())} pixels store an exact hit behind a nearer exact surface point on "
                       f"the pixel-centre ray (not the first hit)")
    return reasons


@dataclass
class TracedCentres:
    """Sub-pixel centres of the traced lines: image positions (n, 2), tube index, and the two pixels (flat indices)."""

    px: np.ndarray
    light: np.ndarray
    pixel_a: np.ndarray
    pixel_b: np.ndarray

    def take(self, keep: np.ndarray) -> "TracedCentres":
        return TracedCentres(self.px[keep], self.light[keep], self.pixel_a[keep], self.pixel_b[keep])


#: Pixel steps (rows, columns) to the neighbour of `_smooth_pairs`' axes 1 and 0 and of the two diagonals.
STEPS = {1: (0, 1), 0: (1, 0), "diagonal": (1, 1), "antidiagonal": (1, -1)}


def _smooth_pairs(renderer: Renderer, aovs: PixelAOVs, axis: int | str,
                  gap: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """Flat indices (a, b) of neighbouring pixels along ``axis`` (a key of `STEPS`) inside one smooth visible piece
    of a patch.

    With ``gap`` (a tube's neighbour gap), also where f changes by less than gap / MIN_LINE_GAP_PX
    between them: there the two lines are resolved by the pixel grid.
    """
    height, width = aovs.f.shape
    index = np.arange(height * width).reshape(height, width)
    dy, dx = STEPS[axis]
    a = index[:height - dy, max(0, -dx):width - max(0, dx)]
    b = index[dy:, max(0, dx):width + min(0, dx)]
    a, b = a.ravel(), b.ravel()
    patch, f, fallback = aovs.patch.ravel(), aovs.f.ravel(), aovs.fallback.ravel()
    P, fp = aovs.P.reshape(-1, 3), renderer.camera.pixel_footprint(aovs.Z).ravel()
    ok = (patch[a] >= 0) & (patch[a] == patch[b]) & ~fallback[a] & ~fallback[b]
    if aovs.span is not None:
        span = aovs.span.ravel()
        ok &= span[a] == span[b]
    ok &= np.isfinite(f[a]) & np.isfinite(f[b])
    with np.errstate(invalid="ignore"):
        ok &= np.linalg.norm(P[a] - P[b], axis=1) <= JUMP_FOOTPRINTS * np.fmax(fp[a], fp[b])
        ok &= np.abs(f[b] - f[a]) <= gap / MIN_LINE_GAP_PX
    return a[ok], b[ok]


def _resolved_pairs(renderer: Renderer, aovs: PixelAOVs,
                    gap: float = math.inf) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """`_smooth_pairs` per axis (1: along rows, 0: down columns); with ``gap``, only where lines that far
    apart in f are resolved. Without, the geometry alone: each line's own gap is applied per crossing."""
    return {axis: _smooth_pairs(renderer, aovs, axis, gap) for axis in (1, 0)}


def _unblocked(renderer: Renderer, aovs: PixelAOVs, pixels: np.ndarray) -> np.ndarray:
    """True where the pixel's reflected ray reaches the light plane without meeting the surface."""
    P, n, s = aovs.P.reshape(-1, 3)[pixels], aovs.N.reshape(-1, 3)[pixels], aovs.s.reshape(-1, 3)[pixels]
    patch = aovs.patch.ravel()[pixels].astype(int)
    return reaches_light_plane(renderer, renderer.lights, P, n, patch, s)


def _crossing(f: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, jump_next: np.ndarray,
              limit: np.ndarray, step: int) -> tuple[np.ndarray, np.ndarray]:
    """Fraction δ in [0, 1] from pixel a to b where f = c, and whether f is resolved there.

    ``jump_next[p]`` is |f(p + step) − f(p)| where that pair is smooth (inf where not). f is
    resolved when the pair and those before and after, (a − 1, a) and (b, b + 1), change f by at
    most ``limit`` (the line's neighbour gap / MIN_LINE_GAP_PX); δ is then the root of the cubic
    through f at a − 1, a, b, b + 1. Linear interpolation alone errs by up to |f''| / (8 |f'|)
    pixels, a visible fraction of a pixel where lines bend tightly; the cubic leaves an error of
    the order of the fourth derivative.
    """
    fa, fb = f[a], f[b]
    delta = (c - fa) / (fb - fa)
    prev, after = a - step, b + step
    ok = (prev >= 0) & (after < f.size) & (jump_next[a] <= limit)
    ok[ok] &= (jump_next[prev[ok]] <= limit[ok]) & (jump_next[b[ok]] <= limit[ok])
    # No wrapping across rows: jump_next is inf at a row's last pixel, where a pair would wrap.
    if not ok.any():
        return delta, ok
    idx = np.flatnonzero(ok)
    y0, y1, y2, y3 = f[prev[idx]], fa[idx], fb[idx], f[after[idx]]
    # Lagrange cubic through x = -1, 0, 1, 2 written as y1 + p1 x + p2 x^2 + p3 x^3.
    p1 = -y0 / 3 - y1 / 2 + y2 - y3 / 6
    p2 = y0 / 2 - y1 + y2 / 2
    p3 = -y0 / 6 + y1 / 2 - y2 / 2 + y3 / 6
    x = delta[idx].copy()
    target = c[idx] - y1
    for _ in range(6):
        g = ((p3 * x + p2) * x + p1) * x - target
        dg = (3 * p3 * x + 2 * p2) * x + p1
        with np.errstate(divide="ignore", invalid="ignore"):
            x = x - g / dg
    good = np.isfinite(x) & (x >= 0) & (x <= 1)
    delta[idx[good]] = x[good]
    ok[idx[~good]] = False
    return delta, ok


#: Pixels `_touches` walks past along a run of pixels whose f lies on the level exactly.
LEVEL_RUN = 8


def _touches(f: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, jump_next: np.ndarray,
             step: int) -> np.ndarray:
    """True where the pair (a, b) meets the level c without crossing it: one end's f lies on it exactly (as float32
    stores c), and the first pixel past the run of pixels on it (along the pair's axis, over smooth pairs:
    ``jump_next`` as `_crossing`'s) lies on the other end's side, or none does within `LEVEL_RUN`. A film's float32 f rounds onto a level that its
    extremum reaches to ~1e-5 of it: a draft or isophote angle of 90° where a face turns vertical and back (Open
    CASCADE's ec_turbine-A.stp at 160×90: two "crossings" of 90° by a fillet whose angle peaks at 90° − 4e-12°, 13 px
    from any contour, as φ never crosses 90°). Its stripe is drawn; the level set there is no line to trace.
    A crossing through a pixel on the level (its neighbours on either side) stays, counted once as before."""
    touch = np.zeros(len(a), dtype=bool)
    # On the level as the film stores it: a level float32 cannot hold (89.8°) is met at its float32 rounding.
    stored = np.asarray(c, dtype=np.float64).astype(np.float32).astype(np.float64)
    for end, other, forward in ((b, a, True), (a, b, False)):
        rows = np.flatnonzero(f[end] == stored)
        if len(rows) == 0:
            continue
        level, on_level, p = c[rows], stored[rows], end[rows]
        known = np.ones(len(rows), dtype=bool)
        for _ in range(LEVEL_RUN):
            on = known & (f[p] == on_level)
            if not on.any():
                break
            beyond = p + step if forward else p - step
            if forward:
                smooth = jump_next[p] < math.inf
            else:
                smooth = (beyond >= 0) & (jump_next[np.maximum(beyond, 0)] < math.inf)
            known &= ~on | smooth
            p = np.where(on & smooth, beyond, p)
        past = f[p]
        touch[rows] = ~known | (past == on_level) | (np.sign(past - level) == np.sign(f[other[rows]] - level))
    return touch


def traced_centres(renderer: Renderer, aovs: PixelAOVs,
                   pairs: dict[int, tuple[np.ndarray, np.ndarray]] | None = None,
                   levels: np.ndarray | None = None) -> TracedCentres:
    """Where f − c_k changes sign between neighbouring pixel centres, on the cubic through four pixels (module doc).

    ``pairs``: `_resolved_pairs` of these AOVs (the geometry alone), when the caller has them already;
    each crossing of tube k is kept where tube k's own neighbour gap is resolved. ``levels``: the
    c_k of the lines (`LineSpec.levels`; the tube positions by default).
    """
    pairs = pairs if pairs is not None else _resolved_pairs(renderer, aovs)
    height, width = aovs.f.shape
    c_k = renderer.lights.c_k if levels is None else levels
    limits = neighbour_gaps(c_k) / MIN_LINE_GAP_PX
    order = np.argsort(c_k)
    c_sorted = c_k[order]
    f, line_id = aovs.f.ravel(), aovs.line_id.ravel()
    pos, light, first_pixel, second_pixel = [], [], [], []
    for axis in (1, 0):
        a, b = pairs[axis]
        jump_next = np.full(f.size, math.inf)  # |Δf| of the smooth pair (p, p + step), keyed by p
        jump_next[a] = np.abs(f[b] - f[a])
        lo_f, hi_f = np.fmin(f[a], f[b]), np.fmax(f[a], f[b])
        first = np.searchsorted(c_sorted, lo_f, side="right")  # c > lo_f
        last = np.searchsorted(c_sorted, hi_f, side="right")  # c <= hi_f
        count = last - first
        pair = np.repeat(np.arange(len(a)), count)
        which = np.arange(len(pair)) - np.repeat(np.cumsum(count) - count, count) + first[pair]
        k = order[which]
        a, b = a[pair], b[pair]
        # line.id names the nearest tube ahead; a tube at the same position as k counts as k.
        pos_a = np.where(line_id[a] >= 0, c_k[np.maximum(line_id[a], 0).astype(int)], np.nan)
        pos_b = np.where(line_id[b] >= 0, c_k[np.maximum(line_id[b], 0).astype(int)], np.nan)
        keep = (pos_a == c_k[k]) & (pos_b == c_k[k])
        a, b, k = a[keep], b[keep], k[keep]
        step = 1 if axis == 1 else width
        crossed = ~_touches(f, a, b, c_k[k], jump_next, step)
        a, b, k = a[crossed], b[crossed], k[crossed]
        delta, resolved = _crossing(f, a, b, c_k[k], jump_next, limits[k], step=step)
        a, b, k, delta = a[resolved], b[resolved], k[resolved], delta[resolved]
        row, col = np.divmod(a, width)
        x = col + 0.5 + (delta if axis == 1 else 0.0)
        y = row + 0.5 + (delta if axis == 0 else 0.0)
        pos.append(np.column_stack([x, y]))
        light.append(k)
        first_pixel.append(a)
        second_pixel.append(b)
    return TracedCentres(np.concatenate(pos), np.concatenate(light), np.concatenate(first_pixel),
                         np.concatenate(second_pixel))


def blocked_pixels(renderer: Renderer, aovs: PixelAOVs) -> np.ndarray:
    """(H, W) True where the pixel's reflected ray is blocked before the light plane (`_unblocked`), on hit pixels."""
    pixels = np.flatnonzero((aovs.patch.ravel() >= 0) & np.isfinite(aovs.f.ravel()))
    blocked = np.zeros(aovs.f.size, dtype=bool)
    blocked[pixels] = ~_unblocked(renderer, aovs, pixels)
    return blocked.reshape(aovs.f.shape)


def _filter_unblocked(renderer: Renderer, aovs: PixelAOVs, centres: TracedCentres) -> TracedCentres:
    """The centres whose two pixels see the tube: reflected rays unblocked (line.id already says it is ahead)."""
    pixels = distinct(np.concatenate([centres.pixel_a, centres.pixel_b]))
    clear = np.zeros(aovs.f.size, dtype=bool)
    clear[pixels] = _unblocked(renderer, aovs, pixels)
    return centres.take(clear[centres.pixel_a] & clear[centres.pixel_b])


# -- the colour image -----------------------------------------------------------------------------


def colour_mismatches(renderer: Renderer, aovs: PixelAOVs, spec: LineSpec | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) masks of the pixels whose colour was checked, and of those whose colour is wrong (module doc).

    A pixel is checked where it and its four neighbours hit one smooth piece of one patch
    (`_smooth_pairs`), all with the same nearest tube ahead (line.id), φ resolved by the pixel grid near the
    levels (`_unresolved`), every sample hits
    (A = 1), and the colours tell lines from surface. With d = |σ| the pixel-centre line.dist (σ the
    signed offset, `line_offset`) and g = |∇σ| from one-sided differences to those neighbours (the
    larger per axis; differences of d would understate g where σ changes sign), d moves by at
    most 0.71·g (= g·√2/2) to a sample inside the pixel, to first order. The stripe profile
    w(d) (`modes.profile`, falling in d) then bounds the line's share L of the pixel's colour:
    w(d + 0.71·g) ≤ L ≤ w(d − 0.71·g) where the reflected rays of the pixel and its neighbours
    are unblocked, or where every sample is out of the profile's reach; L = 0 where they are all
    blocked with every sample within reach. L is read from the colour (`line_coverage`, against
    the shaded surface colour) and must keep within those bounds to half a sample. A pixel is
    checked only where the bounds are at most `COLOUR_CHECK_SPAN` apart. Without blur (the hard
    tube of eq. 4) this is: d + 0.71·g < r with the rays unblocked, fully lit; d − 0.71·g > r,
    or no tube ahead, or blocked within the radius, no line at all; pixels across a stripe's
    edge unchecked. Another mode's lines (``spec``, `LineSpec`) are seen where they are: no occlusion.
    """
    spec = spec or line_spec(renderer)
    height, width = aovs.f.shape
    size = height * width
    line_id, d = aovs.line_id.ravel(), aovs.line_dist.ravel()
    # The slopes are of the signed σ where known: |σ| folds where a pixel's neighbours lie on either side of the
    # line's centre, and its differences there understate how far σ moves within the pixel.
    sigma = d if aovs.line_offset is None else aovs.line_offset.ravel()
    checked = (aovs.patch.ravel() >= 0) & (aovs.coverage.ravel() >= 1.0 - 1e-6) & np.isfinite(aovs.line_coverage.ravel())
    # Along rows, down columns and the two diagonals: a pixel's corner samples lie halfway to its diagonal
    # neighbours, and σ's cross term σ_xy, which the axes' differences miss, reaches them (the sweep's
    # dense_net.step at 320×180: σ 1.2 at a pixel, within 1.4 at its four neighbours, −4.7 and another tube's at
    # two diagonal ones; 4 of its 16 samples off the stripe a first-order bound from the axes kept them on).
    slope = np.zeros((len(STEPS), size))
    f = aovs.f.ravel()
    f_step = np.zeros(size)  # the largest |Δφ| to a neighbour of the pairs below (`_unresolved`)
    for i, axis in enumerate(STEPS):
        a, b = _smooth_pairs(renderer, aovs, axis)
        same = line_id[a] == line_id[b]
        a, b = a[same], b[same]
        np.maximum.at(f_step, a, np.abs(f[b] - f[a]))
        np.maximum.at(f_step, b, np.abs(f[b] - f[a]))
        step = np.zeros(size)
        with np.errstate(invalid="ignore"):
            diff = np.abs(sigma[b] - sigma[a])
        diff = np.where(np.isfinite(diff), diff, 0.0)  # no tube ahead on either side: d is NaN, no slope
        np.maximum.at(step, a, diff)
        np.maximum.at(step, b, diff)
        slope[i] = step
        has_next = np.zeros(size, dtype=bool)
        has_prev = np.zeros(size, dtype=bool)
        has_next[a] = True
        has_prev[b] = True
        checked &= has_next & has_prev
    checked &= ~_unresolved(f, f_step, line_id, spec.levels)
    g = np.hypot(slope[0], slope[1])
    radius, blur = spec.radius, spec.blur
    # How far d may move to a sample in the pixel: 0.71·g to first order, or half the step to a diagonal neighbour
    # (where a corner sample lies) where that is more. Another mode's φ may bend within a pixel
    # (a curvature map near a fold of its field), so there the second differences' share is added: d_xx x²/2 +
    # d_yy y²/2 with |x|, |y| ≤ ½ is at most (|d_xx| + |d_yy|)/8.
    move = np.maximum(0.71 * g, 0.5 * np.maximum(slope[2], slope[3]))
    if not spec.along_ray:
        move = move + second_differences(np.nan_to_num(sigma.reshape(height, width)).astype(np.float64)).ravel() / 8.0
    # The line's share each sample may show, by the stripe profile (monotone in d): at least its weight at the
    # farthest sample, d + move, at most at the nearest, d − move (NaN d, no tube ahead: 0).
    low = stripe_weight(d + move, radius, blur)
    high = stripe_weight(d - move, radius, blur)
    with np.errstate(invalid="ignore"):
        within = (line_id >= 0) & (d + move < spec.reach)  # every sample may see the tube
    # Occlusion of the reflected ray, for every pixel with a tube ahead: up to the nearest tube within the
    # profile's reach along the ray (as the renderer does), else up to the nearest tube ahead.
    ahead = np.flatnonzero(line_id >= 0) if spec.along_ray else np.zeros(0, dtype=int)
    blocked = np.zeros(size, dtype=bool)
    if len(ahead):
        P, n, s = aovs.P.reshape(-1, 3)[ahead], aovs.N.reshape(-1, 3)[ahead], aovs.s.reshape(-1, 3)[ahead]
        if spec.tubes:
            tubes = renderer.stripe_lights.reach(P, s, tube=line_id[ahead].astype(int))
            t = np.where(tubes.candidate, tubes.t_candidate, tubes.t_of)
        else:  # circles: the ray up to the light plane
            t = renderer.lights.plane_t(P, s)
        start = renderer.accelerator.surface_origins(P, n, aovs.patch.ravel()[ahead].astype(int))
        blocked[ahead] = occluded(renderer.accelerator, renderer.tessellation, renderer.surfaces, start, s, t)
    blocked_grid = blocked.reshape(height, width)
    padded = np.pad(blocked_grid, 1, mode="edge")
    uniform = ((padded[1:-1, :-2] == blocked_grid) & (padded[1:-1, 2:] == blocked_grid)
               & (padded[:-2, 1:-1] == blocked_grid) & (padded[2:, 1:-1] == blocked_grid)).ravel()
    # Blocked (the pixel and its neighbours) with every sample in reach: no line at all.
    dark = uniform & blocked & within
    low, high = np.where(dark, 0.0, low), np.where(dark, 0.0, high)
    known = (high == 0.0) | (uniform & ~blocked) | dark
    checked &= known & (high - low <= COLOUR_CHECK_SPAN)
    samples = renderer.scene.image.samples
    # Half a sample; analytic AA (continuous coverage): half a sample of its edge pixels' s×s grid.
    tolerance = 0.5 / (EDGE_SAMPLES if samples == ANALYTIC else samples)**2
    if aovs.map_bend is not None:  # a map's colour bending within the pixel
        tolerance = tolerance + np.nan_to_num(aovs.map_bend.ravel())
    L = aovs.line_coverage.ravel()
    wrong = checked & ~((L >= low - tolerance) & (L <= high + tolerance))
    return checked.reshape(height, width), wrong.reshape(height, width)


def _unresolved(f: np.ndarray, step: np.ndarray, line_id: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """True where the pixel grid does not resolve φ near the levels: φ moves to a neighbouring pixel by more than half
    the spacing from the pixel's level to the next (``step``), and φ ± that step comes within a spacing of the bank
    of levels. There σ may bend through a stripe between two pixel centres that both lie off it, on the same level or
    not, and the colour bounds of one smooth line say nothing (the sweep's dense_net.step at 160×90: σ 33 at a pixel,
    −2 at its neighbour on the same line, φ 35 apart where the levels are 25 apart; 2 of its 16 samples on the
    stripe). Far from the bank (a cylinder's reflected rays running off along the light plane, φ ~1e5) the step
    can be large with no stripe within reach: those pixels stay checked. Half a spacing, not `_smooth_pairs`'
    gap / `MIN_LINE_GAP_PX`: locating two lines' centres needs them pixels apart, checking a pixel's colour needs
    only that no stripe hide between its centre and its neighbours' (the diagonal ones too: the colour bound reads all
    eight)."""
    if len(levels) == 0:
        return np.zeros(len(f), dtype=bool)
    gap = np.where(line_id >= 0, neighbour_gaps(levels)[np.maximum(line_id, 0).astype(int)], np.inf)
    with np.errstate(invalid="ignore"):
        near_bank = (f + step >= np.min(levels) - gap) & (f - step <= np.max(levels) + gap)
        return (step > 0.5 * gap) & near_bank


# -- nearest distances ------------------------------------------------------------------------


@dataclass
class _Segments:
    a: np.ndarray
    b: np.ndarray
    open_start: np.ndarray  # a is the first point of an open polyline
    open_end: np.ndarray  # b is the last point of an open polyline


def _segments(contours: ContourLines, light: int) -> _Segments:
    a, b, s0, s1 = [], [], [], []
    for poly in contours.lines[light].polylines:
        px = poly.px
        closed = bool(np.all(px[0] == px[-1]))
        n = len(px) - 1
        a.append(px[:-1])
        b.append(px[1:])
        start = np.zeros(n, bool)
        end = np.zeros(n, bool)
        if not closed:
            start[0] = True
            end[-1] = True
        s0.append(start)
        s1.append(end)
    if not a:
        z = np.zeros((0, 2))
        return _Segments(z, z, np.zeros(0, bool), np.zeros(0, bool))
    return _Segments(np.concatenate(a), np.concatenate(b), np.concatenate(s0), np.concatenate(s1))


def _checkable_points(contours: ContourLines, light: int, clean: np.ndarray) -> np.ndarray:
    """Analytic contour points of one tube that must have a traced centre nearby (see module doc); not those of a
    loop round no pixel centre (`encloses_a_pixel_centre`)."""
    height, width = clean.shape
    out = []
    for poly in contours.lines[light].polylines:
        px = poly.px
        step = np.linalg.norm(np.diff(px, axis=0), axis=1)
        along = np.concatenate([[0.0], np.cumsum(step)])
        ok = np.isfinite(along)
        if not np.all(px[0] == px[-1]):
            ok &= (along >= END_MARGIN_PX) & (along[-1] - along >= END_MARGIN_PX)
        elif not encloses_a_pixel_centre(px, width, height):
            continue
        inside = (px[:, 0] >= CLEAN_MARGIN_PX) & (px[:, 0] <= width - CLEAN_MARGIN_PX) & \
                 (px[:, 1] >= CLEAN_MARGIN_PX) & (px[:, 1] <= height - CLEAN_MARGIN_PX)
        ok &= inside
        idx = np.flatnonzero(ok)
        col = np.clip(np.floor(px[idx, 0]).astype(int), 0, width - 1)
        row = np.clip(np.floor(px[idx, 1]).astype(int), 0, height - 1)
        ok[idx] &= clean[row, col]
        out.append(px[ok])
    return np.concatenate(out) if out else np.zeros((0, 2))


def encloses_a_pixel_centre(loop: np.ndarray, width: int, height: int) -> bool:
    """Whether a closed contour (image positions, first = last) has one of the image's pixel centres inside it.

    Traced centres are where φ − c_k changes sign between neighbouring pixel centres, and a loop with no centre inside
    separates no two of them: nothing can trace it, at any accuracy. Such loops are sub-pixel rings round a shallow
    extremum of φ at a level, or slivers between two rows of centres (the sweep's rhino_mix.3dm, Gaussian curvature
    at 160×90: K = 0 round a bump 0.4 px across, 18 points counted as misses, a false FAIL; parts/trimmed_face.step's
    zebra at 160×90: ψ dips below 40° inside four pixel centres at 40.01°–40.03°, a loop 0.5 × 0.15 px, 26 points).

    The even–odd rule along each row of centres in the loop's box, clipped to the image (a contour is not clipped to
    the frame: a loop round the camera inside a part may span thousands of pixels): the row's crossings with the loop,
    sorted, bound the runs inside it, and a run holding a centre x = i + ½ (0 ≤ i < width) decides. Rows × segments
    of work, not centres × segments.
    """
    if not np.isfinite(loop).all():  # a point that did not project: the loop is kept (checked as before)
        return True
    rows = np.arange(max(0.0, np.ceil(loop[:, 1].min() - 0.5)), min(height - 1.0, np.floor(loop[:, 1].max() - 0.5)) + 1)
    if len(rows) == 0:
        return False
    (x0, y0), (x1, y1) = loop[:-1].T, loop[1:].T
    y = rows + 0.5
    for chunk in np.array_split(np.arange(len(y)), max(1, len(y) * len(x0) // (1 << 22))):  # bounded memory
        row, seg = np.nonzero((y0[None] > y[chunk, None]) != (y1[None] > y[chunk, None]))
        x = x0[seg] + (y[chunk][row] - y0[seg]) * (x1[seg] - x0[seg]) / (y1[seg] - y0[seg])
        order = np.lexsort((x, row))
        row, x = row[order], x[order]
        # Even–odd: crossings 0–1, 2–3, … of a row bound its runs inside the loop (a row has an even count).
        start, end, same = x[0::2], x[1::2], row[0::2] == row[1::2]
        first = np.maximum(np.ceil(start - 0.5), 0.0)  # the first centre i + ½ ≥ the run's start
        if np.any(same & (first + 0.5 <= end) & (first <= width - 1)):
            return True
    return False


def clean_pixels(renderer: Renderer, aovs: PixelAOVs,
                 pairs: dict[int, tuple[np.ndarray, np.ndarray]] | None = None,
                 blocked: np.ndarray | None = None) -> np.ndarray:
    """(H, W) True where every pixel within CLEAN_MARGIN_PX hits one smooth piece of one patch (see module doc).

    ``pairs``: `_resolved_pairs` of these AOVs (for one line's neighbour gap, or the geometry alone).
    ``blocked``: (H, W) pixels whose reflected ray meets the surface before the light plane (`blocked_pixels`,
    lines seen along a ray): no line is drawn there, so a contour within the margin runs along the edge of a
    reflected occluder, where the traced pairs straddling it are left out.
    """
    pairs = pairs if pairs is not None else _resolved_pairs(renderer, aovs)
    height, width = aovs.f.shape
    bad = ~(aovs.patch >= 0) | aovs.fallback
    if blocked is not None:
        bad = bad | blocked
    flat_bad = bad.ravel().copy()
    for axis in (1, 0):
        index = np.arange(height * width).reshape(height, width)
        a = (index[:, :-1] if axis == 1 else index[:-1, :]).ravel()
        b = (index[:, 1:] if axis == 1 else index[1:, :]).ravel()
        good_a, _ = pairs[axis]
        smooth = np.zeros(height * width, dtype=bool)
        smooth[good_a] = True  # pair (a, a + step) is smooth, keyed by a
        edge = ~smooth[a]
        flat_bad[a[edge]] = True
        flat_bad[b[edge]] = True
    bad = flat_bad.reshape(height, width)
    grown = bad.copy()
    r = CLEAN_MARGIN_PX
    padded = np.pad(bad, r, constant_values=True)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            grown |= padded[r + dy:r + dy + height, r + dx:r + dx + width]
    return ~grown


# -- reports ----------------------------------------------------------------------------------


@dataclass
class LineReport:
    light: int
    position: float
    points: int
    max_px: float | None
    p95_px: float | None
    mean_px: float | None
    misses: int
    colour_mismatches: int
    neighbour_gap: float | None = None  # distance in f to the nearest tube at another position (None: alone)
    unresolved_points: int = 0  # analytic points in clean view left out: the neighbour line closer than MIN_LINE_GAP_PX
    clean_points: int = 0  # analytic points in clean view (the geometry alone), resolved or not

    def to_json(self) -> dict:
        return dict(vars(self))


def _stats(dev: np.ndarray) -> tuple[float | None, float | None, float | None]:
    if len(dev) == 0:
        return None, None, None
    return float(dev.max()), float(np.percentile(dev, 95)), float(dev.mean())


@dataclass
class SceneReport:
    """One scene's result. Overall figures count each tube position once (tubes sharing one draw one line)."""

    name: str
    path: str
    width: int
    height: int
    normals: str
    tolerance: float
    lines: list[LineReport]
    deviations: np.ndarray = field(repr=False)  # every compared point's deviation (one tube per position), px
    colour_mismatches: int = 0  # pixels whose colour disagrees with line.dist (all tubes, and no tube ahead)
    colour_checked: int = 0  # pixels whose colour was checked
    reasons: list[str] = field(default_factory=list)  # why the scene fails besides deviations, misses and colours
    notes: list[str] = field(default_factory=list)  # lines left (mostly) unchecked: not failures, not silent either
    counted: list[bool] | None = field(default=None, repr=False)  # per line: first tube at its position
    contours: ContourLines | None = field(default=None, repr=False)
    centres: TracedCentres | None = field(default=None, repr=False)
    parallax: dict | None = None  # zebra: `parallax.ParallaxReport.to_json`, the stripes against physical tubes (not judged)

    @property
    def points(self) -> int:
        return int(len(self.deviations))

    @property
    def misses(self) -> int:
        counted = self.counted or [True] * len(self.lines)
        return sum(line.misses for line, first in zip(self.lines, counted) if first)

    @property
    def max_px(self) -> float | None:
        return _stats(self.deviations)[0]

    @property
    def p95_px(self) -> float | None:
        return _stats(self.deviations)[1]

    @property
    def mean_px(self) -> float | None:
        return _stats(self.deviations)[2]

    @property
    def passed(self) -> bool:
        return (self.misses == 0 and self.colour_mismatches == 0 and not self.reasons
                and (self.max_px is None or self.max_px <= self.tolerance))

    def to_json(self) -> dict:
        return {"max_px": self.max_px, "p95_px": self.p95_px, "mean_px": self.mean_px, "points": self.points,
                "misses": self.misses, "colour_mismatches": self.colour_mismatches,
                "colour_checked": self.colour_checked, "reasons": list(self.reasons),
                "lines": [line.to_json() for line in self.lines],
                **({"parallax": self.parallax} if self.parallax is not None else {})}


def exact_crossings(renderer: Renderer, aovs: PixelAOVs, first: np.ndarray, second: np.ndarray,
                    c: np.ndarray, field: UlmetField | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(n, 2) image positions of the level set f = c (the mode's φ) between the hits of the pixel pairs (first,
    second) (flat indices; one smooth piece of one face): the root on the (u, v) segment joining their hits, exactly
    (`contours.UlmetField.bracket` on the exact field, not the film's values), where it is seen (`UlmetField.seen`);
    NaN where there is none (f not across c at both ends, or a periodic φ, whose wrap no bracket spans); and (n, 2)
    the level set's unit normal in the image there (`level_set_normals`). ``field``: the renderer's
    (`contours.field_of`), when the caller has it.

    The analytic contours are found on a grid of cells ~`contours.GRID_CELL_PX` across: a strip narrower than a cell
    where f dips across a level and back can lie between its points, and a traced centre on its far side then meets
    only the contour on its near side (OCCT's linkrods.step, κ1 = 0 beside a C1 knot line of a degree-10 face at
    320×180: a strip 1.3 px wide where κ1 dips to −0.004 of a level gap of 2, its far edge 1.24 px from the contour).
    The exact root between the very pixels is a point of the analytic level set too: a traced centre off it is off.
    """
    out, normal = np.full((len(first), 2), np.nan), np.full((len(first), 2), np.nan)
    field = field or field_of(renderer)
    if len(first) == 0 or getattr(field, "period", None):
        return out, normal
    patch = aovs.patch.ravel()[first].astype(int)
    if aovs.uv is None:  # AOVs made without the film's (u, v)
        return out, normal
    uv = aovs.uv.reshape(-1, 2)
    ua, va, ub, vb = uv[first, 0], uv[first, 1], uv[second, 0], uv[second, 1]
    edge = np.column_stack([ua, va, ub, vb, field.f(patch, ua, va), field.f(patch, ub, vb)])
    u, v, ok = field.bracket(patch, edge, np.asarray(c, dtype=np.float64))
    rows = np.flatnonzero(ok)
    rows = rows[field.seen(patch[rows], u[rows], v[rows])]
    out[rows] = field.project(patch[rows], u[rows], v[rows])[0]
    normal[rows] = level_set_normals(field, patch[rows], u[rows], v[rows])
    return out, normal


#: (u, v) step of `level_set_normals`' central differences, as a share of the face's domain.
NORMAL_STEP = 1e-6


def level_set_normals(field: UlmetField, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 2) unit normals in the image of the level set of φ through S(u, v): the image gradient g of φ, from
    φ_u = g·x_u and φ_v = g·x_v (x the point's image position), each differenced over (u, v) ± `NORMAL_STEP` of the
    domain (kept inside it); NaN where the projection is singular (an edge-on face) or φ is stationary."""
    u0, u1, v0, v1 = field.surfaces.domains(patch)
    hu, hv = NORMAL_STEP * (u1 - u0), NORMAL_STEP * (v1 - v0)
    ends_u = np.clip(np.stack([u + hu, u - hu, u, u]), u0, u1)
    ends_v = np.clip(np.stack([v, v, v + hv, v - hv]), v0, v1)
    n = len(u)
    at = (np.tile(patch, 4), ends_u.ravel(), ends_v.ravel())
    phi = field.f(*at).reshape(4, n)
    x = field.project(*at)[0].reshape(4, n, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        d_phi = np.stack([(phi[0] - phi[1]) / (ends_u[0] - ends_u[1]), (phi[2] - phi[3]) / (ends_v[2] - ends_v[3])], 1)
        jacobian = np.stack([(x[0] - x[1]) / (ends_u[0] - ends_u[1])[:, None],
                             (x[2] - x[3]) / (ends_v[2] - ends_v[3])[:, None]], 1)  # rows x_u, x_v
        det = jacobian[:, 0, 0] * jacobian[:, 1, 1] - jacobian[:, 0, 1] * jacobian[:, 1, 0]
        # g from J g = (φ_u, φ_v), by Cramer's rule
        g = np.stack([d_phi[:, 0] * jacobian[:, 1, 1] - d_phi[:, 1] * jacobian[:, 0, 1],
                      jacobian[:, 0, 0] * d_phi[:, 1] - jacobian[:, 1, 0] * d_phi[:, 0]], 1) / det[:, None]
        return g / np.linalg.norm(g, axis=1, keepdims=True)


def compare(renderer: Renderer, aovs: PixelAOVs, contours: ContourLines, tolerance: float) -> SceneReport:
    """Deviation of traced centres from the analytic contours, misses both ways and colour mismatches, per line."""
    spec = line_spec(renderer)
    pairs = _resolved_pairs(renderer, aovs)  # the geometry alone; each line's gap is applied on top
    centres = traced_centres(renderer, aovs, pairs, spec.levels)
    if spec.along_ray:
        centres = _filter_unblocked(renderer, aovs, centres)
    checked, wrong = colour_mismatches(renderer, aovs, spec)
    wrong_light = aovs.line_id[wrong].astype(int)
    c_k = spec.levels
    gaps = neighbour_gaps(c_k)
    clean_by_gap: dict[float, np.ndarray] = {}  # few distinct gaps in a scene: one clean map each
    blocked = blocked_pixels(renderer, aovs) if spec.along_ray else None

    def clean_for(gap: float) -> np.ndarray:
        if gap not in clean_by_gap:
            clean_by_gap[gap] = clean_pixels(renderer, aovs, pairs if math.isinf(gap) else
                                             _resolved_pairs(renderer, aovs, gap), blocked)
        return clean_by_gap[gap]

    reports, all_dev, counted, reasons, notes = [], [], [], [], []
    field = None  # `exact_crossings`' field, made on first use
    for line in contours.lines:
        k = line.light
        segs = _segments(contours, k)
        mine = centres.light == k
        pts = centres.px[mine]
        dist, seg = nearest_segment(pts, segs.a, segs.b, SEARCH_RADIUS_PX)
        # Beyond an open end of the analytic polyline: the traced line runs on where the contour was cut.
        found = np.flatnonzero(np.isfinite(dist))
        at_end = np.zeros(len(pts), dtype=bool)
        if len(found):
            sa, sb = segs.a[seg[found]], segs.b[seg[found]]
            near_start = segs.open_start[seg[found]] & (np.linalg.norm(pts[found] - sa, axis=1) <= dist[found] + 1e-9)
            near_end = segs.open_end[seg[found]] & (np.linalg.norm(pts[found] - sb, axis=1) <= dist[found] + 1e-9)
            at_end[found] = (near_start | near_end) & (dist[found] <= END_MARGIN_PX)
        # Off every contour found on the grid by more than the tolerance: the level set's exact root between the
        # centre's own two pixels counts as well (`exact_crossings`).
        off = np.flatnonzero(~(dist <= tolerance) & ~at_end)
        if len(off):
            field = field or field_of(renderer)
            exact, normal = exact_crossings(renderer, aovs, centres.pixel_a[mine][off], centres.pixel_b[mine][off],
                                            np.full(len(off), c_k[k]), field)
            # Across the level set, as the grid's contours are measured: the centre and the root lie on one pixel
            # axis, which the level set may cross at a slant (then the centre is nearer it than to the root).
            across = np.abs(np.einsum("ij,ij->i", pts[off] - exact, normal))
            between = np.where(np.isfinite(across), across, np.linalg.norm(pts[off] - exact, axis=1))
            nearer = between < np.where(np.isfinite(dist[off]), dist[off], np.inf)
            dist[off[nearer]] = between[nearer]
        unmatched = ~np.isfinite(dist)
        dev = dist[~unmatched & ~at_end]
        # Analytic points with no traced centre nearby, where this line and its neighbour are resolved.
        check = _checkable_points(contours, k, clean_for(gaps[k]))
        in_view = len(check) if math.isinf(gaps[k]) else len(_checkable_points(contours, k, clean_for(math.inf)))
        found_gap, _ = nearest_segment(check, pts, pts, MISS_RADIUS_PX)
        misses = int(np.count_nonzero(~np.isfinite(found_gap))) + int(np.count_nonzero(unmatched))
        reports.append(LineReport(light=k, position=line.position, points=int(len(dev)), max_px=_stats(dev)[0],
                                  p95_px=_stats(dev)[1], mean_px=_stats(dev)[2], misses=misses,
                                  colour_mismatches=int(np.count_nonzero(wrong_light == k)),
                                  neighbour_gap=float(gaps[k]) if math.isfinite(gaps[k]) else None,
                                  unresolved_points=max(0, in_view - len(check)), clean_points=in_view))
        # Tubes sharing a position have the same traced centres: count them once overall.
        first = int(np.flatnonzero(c_k == c_k[k])[0]) == k
        counted.append(first)
        if first:
            all_dev.append(dev)
            if len(dev) == 0 and len(check) >= NOTHING_COMPARED_POINTS:
                reasons.append(f"light {k}: {len(check)} analytic points in clean view but no traced centre compared")
            unresolved = in_view - len(check)
            if in_view >= NOTHING_COMPARED_POINTS and unresolved > NOTE_UNRESOLVED_SHARE * in_view:
                how = "not checked" if len(dev) == 0 else f"only {len(dev)} centres compared"
                notes.append(f"light {k} (c_k = {c_k[k]:g}): {how}; {unresolved} of its {in_view} analytic points in "
                             f"clean view left out: its neighbour {gaps[k]:g} away lies closer than "
                             f"{MIN_LINE_GAP_PX:g} px in the image there")
    deviations = np.concatenate(all_dev) if all_dev else np.zeros(0)
    seen = int(np.count_nonzero(aovs.coverage > 0))
    with np.errstate(invalid="ignore"):
        drawn = int(np.count_nonzero((aovs.coverage > 0) & (aovs.line_id >= 0) & (aovs.line_dist <= spec.radius)))
    # Analytic points in the image (resolved by the pixels or not).
    image = np.array([renderer.camera.width, renderer.camera.height], dtype=np.float64)
    shown = sum(int(np.count_nonzero(np.all((poly.px >= 0) & (poly.px <= image), axis=1)))
                for line in contours.lines for poly in line.polylines)
    if seen == 0:
        reasons.insert(0, "no traced line centre was compared (the camera sees no surface)")
    elif len(c_k) == 0:
        hint = ("a curvature map draws iso-lines only with [render] bands = 2 or more"
                if renderer.scene.render.mode == "curvature" else "its levels are empty")
        reasons.insert(0, f"no traced line centre was compared: the mode draws no lines ({hint})")
    elif len(deviations) == 0 and (renderer.scene.render.mode in LEGEND_MODES
                                   or (isinstance(renderer.mode, FaceRegions) and not shown and drawn == 0)) \
            and len(c_k) and not reasons and not notes and np.count_nonzero(checked):
        # A map or isophotes whose levels cross none of the faces in view (a face where φ is constant, K = 0 on a plane,
        # a 0° wall, a plane facing the light, is a region, not a line: `modes.regions`): its picture is the map's
        # colours or the shading, checked line-free (isophotes: no pixel centre within a stripe either).
        # A map's level reached only along face edges (a fillet meeting a 0° wall: huge_inch.step's draft, 423
        # analytic points all within 2 px of an edge) is no line the pixels can check either: said so, not failed.
        # (Isophotes crowding on a fillet are lines in view, unresolved: they fail, below. A map without levels has
        # nothing to compare: it fails, as the docs say.)
        where = ("φ crosses none of the levels where the camera sees the surface (faces where it is constant are "
                 "regions, not lines)" if not shown else
                 f"its {shown} analytic points in the image lie only along face edges or where lines crowd, "
                 f"which the pixels cannot check at this size")
        notes.append(f"no iso-line in {'clean ' if shown else ''}view: {where}; {int(np.count_nonzero(checked))} "
                     f"pixels' colours checked free of lines")
    elif len(deviations) == 0:
        # Analytic points in the image but none in clean view: the lines are there, unresolved (small_fillet.step's
        # isophotes: 351 points on a fillet a few pixels wide was reported as no line where the camera looks).
        why = ("every line's neighbour lies closer than the pixels resolve" if notes and len(notes) == sum(counted)
               else "no tube is reflected where the camera sees the surface" if spec.along_ray and not shown
               else f"the {shown} analytic points in the image lie where the pixels resolve no line: neighbouring "
                    f"lines closer than {MIN_LINE_GAP_PX:g} px, or within {CLEAN_MARGIN_PX} px of a face's edge"
               if shown and not any(r.clean_points for r in reports)
               else f"no pixel pair's φ crosses a level where {sum(r.clean_points for r in reports)} analytic points lie "
                    f"in clean view" if any(r.clean_points for r in reports)
               else "none of the mode's lines lies where the camera sees the surface")
        reasons.insert(0, f"no traced line centre was compared ({why})")
    elif spec.along_ray and drawn < MIN_DRAWN_SHARE * seen:
        # A few stray centres (grazing rays at silhouettes) compare well, but the picture shows no lines.
        reasons.insert(0, f"no tube is reflected where the camera sees the surface: {drawn} of its {seen} pixels "
                          f"see a tube within its radius (fewer than {100 * MIN_DRAWN_SHARE:g} %)")
    reasons.extend(hit_faults(aovs))
    camera = renderer.camera
    scene = renderer.scene
    return SceneReport(scene.output.name, str(scene.path), camera.width, camera.height, scene.render.normals,
                       tolerance, reports, deviations, colour_mismatches=int(np.count_nonzero(wrong)),
                       colour_checked=int(np.count_nonzero(checked)), reasons=reasons, notes=notes, counted=counted,
                       contours=contours, centres=centres)


def validate_scene(scene: Scene, tolerance: float = DEFAULT_TOLERANCE_PX, progress: Callable[[int], None] | None = None,
                   threads: int | None = None, renderer: Renderer | None = None) -> SceneReport:
    """Render the scene (colour at its samples, pixel-centre AOVs) in memory and check it against the analytic contours.

    The contours are the level sets of the scene's `[render] mode`: Ulmet's f for reflection lines,
    the mode's φ otherwise (`contours.field_of`), compared by the same rules (`compare`, `LineSpec`).
    A zebra render also gets its parallax against equivalent physical tubes (`parallax`), reported
    beside the verdict, not part of it.
    """
    renderer = renderer or Renderer(resolve(scene))
    film = renderer.render(progress, threads).film
    contours = analytic_contours(field_of(renderer))
    aovs = film_aovs(renderer, film)
    if not isinstance(renderer.mode, ReflectionMode):
        aovs = mode_aovs(renderer, film, aovs)
    report = compare(renderer, aovs, contours, tolerance)
    if renderer.mode.name == "zebra":
        report.parallax = zebra_parallax(renderer, contours).to_json()
    return report
