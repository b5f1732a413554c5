"""Analytic reflection lines: the level sets f(u, v) = c_k of Ulmet's function (paper section 4, eq. 5–6).

The paper's theorem: the reflection line of light line k is the image of the level
set f(u, v) = c_k, where f is the e-coordinate at which the reflected ray R + t s
meets the light plane (general form in DESIGN.md: t = m·(Q − R)/(m·s),
f = e·(R + t s − Q), defined where t > 0). Per patch:

1. f on a (u, v) grid whose cells project to about `GRID_CELL_PX` pixels;
2. the level sets f = c_k on that grid by contourpy (cells touching t ≤ 0 are masked);
3. every vertex polished onto f = c_k by Newton along ∇f (finite differences);
4. segments subdivided (midpoints polished) until each projects to at most
   `MAX_SEGMENT_PX` and its chord strays less than `CHORD_TOLERANCE_PX` from the curve;
5. each vertex classified: in front of the camera, seen from the eye (Embree occlusion
   towards A), its reflected ray unblocked up to the light plane, and on the tube
   (|τ| ≤ length/2 for a finite tube); the polylines are cut where the class changes,
   the cut located by bisection to a small fraction of a pixel;
6. the surviving pieces are mapped to 3D by the exact evaluator and projected with the camera.

The result, `ContourLines`, holds per light line the polylines in (u, v) and in
pixels (x = column, y = row, pixel centres at half-integers, like `Camera.project`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import contourpy
import numpy as np

from ..trace.accelerator import Accelerator
from ..trace.camera import Camera
from ..modes.base import SurfacePoints, seen_at
from ..modes.lights import TubeLights, reaches_light_plane
from ..modes.reflection import ReflectionMode
from ..geometry.surfaces import SurfaceSet
from ..geometry.tessellation import Tessellation
from ..trace.tracing import facing, trace

#: Target size in pixels of one cell of the (u, v) grid that contourpy sees.
GRID_CELL_PX = 2.0
#: Points per side of the fine grid over the 2 × 2 cells round an extremum of f between grid points (`_small_loops`).
LOOP_GRID = 17
#: Probe points per side of the window that sizes a patch's grid (`_grid_window`) ...
PROBE = 33
#: ... narrowed at most this many times (each round ~10× for a close-up: a window 10⁻⁸ of the domain).
ZOOM_ROUNDS = 8
#: Times the grid's cells next to a blow-up of f are halved (`_refined_at_blowups`): one recovered every level of
#: xr1-tu-rod.stp at 160×90 to 640×360, and adds 6 % to the teapot's grid (more halvings: 12 %, 16 %, ...).
BLOWUP_ROUNDS = 1
#: Seed rays across the image's larger side (`UlmetField.seed_uv`): a close-up's face shows between probe points.
SEED_RAYS = 64
MIN_GRID = 16
MAX_GRID = 2048
#: Points evaluated per chunk of the grid: bounds memory for huge patches.
GRID_CHUNK = 1 << 16
#: Subdivide a contour segment while it projects longer than this ...
MAX_SEGMENT_PX = 2.0
#: ... or while its polished midpoint lies farther than this from the chord.
CHORD_TOLERANCE_PX = 0.005
SUBDIVISION_ROUNDS = 12
#: Segments farther than this outside the image are not refined (a huge patch stays cheap).
IMAGE_MARGIN_PX = 8.0
#: Bisection steps that locate where a contour is cut (visibility, tube end): 2^-10 of a ≤ 1 px segment.
BISECTION_STEPS = 10
NEWTON_STEPS = 8
#: Steps of the bracketed search along a grid edge (`UlmetField.bracket`), where Newton fails from contourpy's vertex.
BRACKET_STEPS = 60
#: Newton is done when |f − c_k| is below this fraction of the tube spacing (or of 1 when there is one tube).
NEWTON_TOLERANCE = 1e-11
#: A surface point is hidden from the eye by a hit this fraction of the part's size (bounding-box diagonal) or more
#: before it on the camera's ray: well above the exact hits' error (~1e-12), well below any wall's thickness.
SAME_POINT = 1e-6


@dataclass(frozen=True)
class Polyline:
    patch: int
    uv: np.ndarray  # (n, 2)
    px: np.ndarray  # (n, 2) image (x = column, y = row), pixel centres at half-integers


@dataclass(frozen=True)
class ContourLine:
    light: int  # index k of the tube
    position: float  # c_k
    polylines: list[Polyline]


@dataclass(frozen=True)
class ContourLines:
    width: int
    height: int
    lines: list[ContourLine]

    def to_json(self) -> dict:
        """The `NAME.contours.json` document: per line the light index and polylines in pixels and in (u, v)."""
        return {
            "width": self.width,
            "height": self.height,
            "pixel_convention": "x = column, y = row from the top-left corner; pixel (i, j) has its centre at (j + 0.5, i + 0.5)",
            "lines": [{"light": line.light, "position": line.position,
                       "polylines": [{"patch": p.patch, "pixels": np.round(p.px, 4).tolist(), "uv": p.uv.tolist()}
                                     for p in line.polylines]}
                      for line in self.lines],
        }


class UlmetField:
    """f(u, v) and the visibility of contour points, for one scene's surfaces, camera, tubes and BVH."""

    def __init__(self, surfaces: SurfaceSet, tessellation: Tessellation, accelerator: Accelerator, camera: Camera,
                 lights: TubeLights, tracer=None):
        self.surfaces = surfaces
        self.tessellation = tessellation
        self.accelerator = accelerator
        self.camera = camera
        self.lights = lights
        #: Camera rays (origins, directions) → `Hits` for `seed_uv`: the renderer's own trace where given (its second
        #: look included), else the coarse `trace`.
        self.tracer = tracer
        self._seeds = None  # `seed_uv`'s hits, traced on first use

    @classmethod
    def of(cls, renderer) -> "UlmetField":
        """The field of a `render.Renderer`'s scene, sharing its patches, mesh, BVH, camera, tubes and trace."""
        return cls(renderer.surfaces, renderer.tessellation, renderer.accelerator, renderer.camera, renderer.lights,
                   renderer.trace)

    @property
    def levels(self) -> np.ndarray:
        """The levels c_k whose level sets are the lines: the tube positions."""
        return self.lights.c_k

    #: f's period where it is an angle that wraps (`modes.base.Mode.period`), else None.
    period: float | None = None

    def lined(self, k: int) -> bool:
        """Whether patch k's level sets are lines: not on a map's face where φ is constant (`modes.regions`)."""
        return True

    def newton_scale(self) -> float:
        """φ's natural unit, for Newton's tolerance: the tube spacing (1 with one tube), not below rounding."""
        spacing = self.lights.spacing
        scale = spacing if math.isfinite(spacing) else 1.0
        return max(scale, 1e-9 * (self.tessellation.extent + float(np.abs(self.lights.c_k).max())))

    # -- the function ----------------------------------------------------------------------
    def geometry(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray):
        """R = S(u, v), the exact unit normal n, a and s = 2(a·n)n − a (paper eq. 3): `modes.base.seen_at`."""
        return seen_at(self.surfaces, self.camera, patch, u, v)

    def f(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Ulmet's f at (patch, u, v), paper eq. (5) in the general form; NaN where t ≤ 0."""
        R, _, _, s = self.geometry(patch, u, v)
        return self.lights.ulmet_f(R, s)

    def f_grid(self, k: int, us: np.ndarray, vs: np.ndarray) -> np.ndarray:
        """f on the tensor grid us × vs of patch k, shape (len(us), len(vs)), evaluated in chunks."""
        uu, vv = np.meshgrid(us, vs, indexing="ij")
        uu, vv = uu.ravel(), vv.ravel()
        out = np.empty(len(uu))
        for lo in range(0, len(uu), GRID_CHUNK):
            hi = min(lo + GRID_CHUNK, len(uu))
            out[lo:hi] = self.f(np.full(hi - lo, k), uu[lo:hi], vv[lo:hi])
        return out.reshape(len(us), len(vs))

    def seed_uv(self, k: int) -> np.ndarray:
        """(n, 2) (u, v) of patch k where camera rays on a coarse grid (`SEED_RAYS` across) hit it first.

        Traced as the renderer traces its pixels (`tracer`): in a close-up from within the coarse mesh's chord error
        of a face the coarse trace meets nothing there that its second look finds (dense_net.step, its edge at fov
        0.1°, 320×180: no seed hit, the grid's window never zoomed, and `validate` compared no line of the 12 the render
        shows, a false FAIL)."""
        if self._seeds is None:
            camera = self.camera
            step = max(camera.width, camera.height) / SEED_RAYS
            rows = np.arange(0.5 * step, camera.height, step).astype(int)
            cols = np.arange(0.5 * step, camera.width, step).astype(int)
            rows, cols = (a.ravel() for a in np.meshgrid(rows, cols, indexing="ij"))
            rays = camera.rays(rows, cols)
            hits = (self.tracer(*rays) if self.tracer is not None
                    else trace(self.accelerator, self.tessellation, self.surfaces, *rays))
            self._seeds = hits.patch[hits.hit], np.column_stack([hits.u, hits.v])[hits.hit]
        patch, uv = self._seeds
        return uv[patch == k]

    # -- Newton onto f = c -----------------------------------------------------------------
    def polish(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray, c: np.ndarray,
               max_move: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Newton on f(u, v) − c = 0 along ∇f (the contour's normal in (u, v)); returns u, v, converged.

        ∇f by one-sided differences stepped into the domain. A point on an edge of the
        domain stays on it (the edge's own parameter is held fixed), so contours end
        exactly on patch boundaries. Points that would move farther than ``max_move``
        jumped to another branch and are reported unconverged. Steps and moves are measured
        in the domain's unit square, (u/(u1 − u0), v/(v1 − v0)): a metric that mixed u's and
        v's own units would aim along whichever parameter happens to be scaled smaller.
        """
        u0, u1, v0, v1 = self.surfaces.domains(patch)
        u, v = u.astype(np.float64).copy(), v.astype(np.float64).copy()
        start_u, start_v = u.copy(), v.copy()
        hold_u = (u <= u0) | (u >= u1)
        hold_v = (v <= v0) | (v >= v1)
        hu = 1e-7 * (u1 - u0)
        hv = 1e-7 * (v1 - v0)
        scale = self.newton_scale()
        ok = np.zeros(len(u), dtype=bool)
        active = np.arange(len(u))
        for _ in range(NEWTON_STEPS):
            if len(active) == 0:
                break
            # f first, ∇f only where Newton goes on: a converged point would waste its two differences.
            f0 = self.f(patch[active], u[active], v[active])
            r = f0 - c[active]
            done = np.abs(r) <= NEWTON_TOLERANCE * scale
            ok[active[done]] = True
            going = ~done & np.isfinite(r)
            active, r, f0 = active[going], r[going], f0[going]
            p, ua, va = patch[active], u[active], v[active]
            su = np.where(ua + hu[active] <= u1[active], hu[active], -hu[active])
            sv = np.where(va + hv[active] <= v1[active], hv[active], -hv[active])
            values = self.f(np.concatenate([p, p]), np.concatenate([ua + su, ua]),
                            np.concatenate([va, va + sv])).reshape(2, -1)
            # ∇f in unit-square coordinates: ∂f/∂(u/(u1 − u0)) = (u1 − u0) ∂f/∂u.
            gu = np.where(hold_u[active], 0.0, (values[0] - f0) / su * (u1[active] - u0[active]))
            gv = np.where(hold_v[active], 0.0, (values[1] - f0) / sv * (v1[active] - v0[active]))
            g2 = gu * gu + gv * gv
            step = np.isfinite(g2) & (g2 > 0)
            active, r, gu, gv, g2 = (x[step] for x in (active, r, gu, gv, g2))
            u[active] = np.clip(u[active] - r * gu / g2 * (u1[active] - u0[active]), u0[active], u1[active])
            v[active] = np.clip(v[active] - r * gv / g2 * (v1[active] - v0[active]), v0[active], v1[active])
        if len(active):  # the last step's result
            r = self.f(patch[active], u[active], v[active]) - c[active]
            ok[active] = np.abs(r) <= 1e3 * NEWTON_TOLERANCE * scale
        ok &= np.hypot((u - start_u) / (u1 - u0), (v - start_v) / (v1 - v0)) <= max_move
        return u, v, ok

    def bracket(self, patch: np.ndarray, edge: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """f(u, v) = c on the grid edges ``edge`` ((n, 6): the ends (u, v) and f there, on either side of c) by regula
        falsi whose end kept by a step has its residual halved (a variant of the Illinois method: the bracket closes
        from both sides): returns u, v, converged.

        Where Newton along ∇f fails from contourpy's interpolated crossing: f far from linear within the cell
        (near a blow-up, f ~ 1/d, Newton's step from half a cell out lands where t ≤ 0), the bracket still closes.
        """
        ua, va, ub, vb, fa, fb = (edge[:, i].copy() for i in range(6))
        ra, rb = fa - c, fb - c
        tolerance = NEWTON_TOLERANCE * self.newton_scale()
        s_a, s_b = np.zeros(len(c)), np.ones(len(c))
        s = np.full(len(c), 0.5)
        ok = np.zeros(len(c), dtype=bool)
        active = np.flatnonzero(np.isfinite(ra) & np.isfinite(rb) & (ra * rb <= 0))
        for _ in range(BRACKET_STEPS):
            if len(active) == 0:
                break
            a, b = s_a[active], s_b[active]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(rb[active] != ra[active], a - ra[active] * (b - a) / (rb[active] - ra[active]), 0.5 * (a + b))
            t = np.where(np.isfinite(t) & (t > np.minimum(a, b)) & (t < np.maximum(a, b)), t, 0.5 * (a + b))
            s[active] = t
            r = self.f(patch[active], ua[active] + t * (ub[active] - ua[active]),
                       va[active] + t * (vb[active] - va[active])) - c[active]
            done = np.abs(r) <= tolerance
            ok[active[done]] = True
            # Keep the bracket: the new point replaces the end whose residual has its sign; the other end's residual
            # is halved when it stays (Illinois), so the bracket shrinks from both sides.
            same_a = np.sign(r) == np.sign(ra[active])
            rows_a, rows_b = active[same_a & ~done], active[~same_a & ~done]
            s_a[rows_a], ra[rows_a] = t[same_a & ~done], r[same_a & ~done]
            rb[rows_a] *= 0.5
            s_b[rows_b], rb[rows_b] = t[~same_a & ~done], r[~same_a & ~done]
            ra[rows_b] *= 0.5
            active = active[~done & np.isfinite(r)]
        return ua + s * (ub - ua), va + s * (vb - va), ok

    # -- where a contour is seen --------------------------------------------------------------
    def project(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image positions (n, 2) and depth along the view direction of S(u, v)."""
        R = self.surfaces.evaluate(patch, u, v).S
        depth = (R - self.camera.spec.eye) @ self.camera.basis[0]
        return self.camera.project(R), depth

    def seen(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """True where the contour point S(u, v) shows its tube: on its face, visible, unblocked, on the tube.

        Inside its face's trim (so a level set is cut where it leaves the face, the cut located
        by `_cut_points`' bisection like any other); in front of the camera (depth > 0 for either projection: orthographic rays start on
        the eye plane too, DESIGN.md's camera contract); no triangle between the point and the eye; no triangle on
        the reflected ray before it reaches the light plane; for a finite tube, the ray meets
        the plane within the tube's length. Rays start off the surface along the normal
        turned towards the eye by more than the mesh's chord error, as the renderer's do.
        """
        R, n, a, s = self.geometry(patch, u, v)
        lights = self.lights
        w = self.camera.basis[0]
        depth = (R - self.camera.spec.eye) @ w
        good = (depth > 0) & self.surfaces.on_face(patch, u, v)  # a trimmed face's contour ends at its trim
        t = lights.plane_t(R, s)
        good &= t > 0
        tau = (R + np.where(np.isfinite(t), t, 0.0)[:, None] * s - lights.Q) @ lights.c
        if math.isfinite(lights.length):
            good &= np.abs(tau) <= 0.5 * lights.length
        n = facing(n, -a)  # a points to the eye: the incoming ray runs along −a
        idx = np.flatnonzero(good)
        good[idx] &= eye_sees(self, self.camera, R[idx], a[idx])
        idx = np.flatnonzero(good)
        good[idx] &= reaches_light_plane(self, lights, R[idx], n[idx], patch[idx], s[idx])
        return good


class ModeField(UlmetField):
    """φ(u, v) of another line-drawing mode (`modes.base.Mode`) in place of Ulmet's f: same grid, Newton and cuts.

    φ comes from the mode itself, at S(u, v) with the exact unit normal turned towards the eye
    (as the renderer writes N) and s of eq. (3), so the contours are the level sets φ = c_k of
    the very function the renderer shades; ∇φ for Newton by the same one-sided differences of
    the exact evaluator as f's. The levels are the mode's. A mode whose stripes are not seen
    along a reflected ray (highlight, isophote, zebra, draft, curvature) is cut by the eye's
    visibility and the trims only; highlight lines also where the normal line meets the light
    plane beyond a finite tube's ends; circular reflection lines (`modes.circles`) also where the
    reflected ray is blocked before the light plane.
    """

    def __init__(self, surfaces: SurfaceSet, tessellation: Tessellation, accelerator: Accelerator, camera: Camera,
                 lights: TubeLights, mode, tracer=None):
        super().__init__(surfaces, tessellation, accelerator, camera, lights, tracer)
        self.mode = mode

    @property
    def levels(self) -> np.ndarray:
        return np.asarray(self.mode.levels, dtype=np.float64)

    @property
    def period(self) -> float | None:
        return self.mode.period

    def lined(self, k: int) -> bool:
        constant = getattr(self.mode, "constant_faces", None)
        return constant is None or not constant[k]

    def newton_scale(self) -> float:
        """The smallest gap between the mode's levels (φ's natural unit), 1 with one level."""
        gaps = np.diff(np.unique(self.levels))
        return float(gaps.min()) if len(gaps) else 1.0

    def f(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The mode's φ at (patch, u, v)."""
        R, n, a, s = self.geometry(patch, u, v)
        return self.mode.phi(SurfacePoints(R, facing(n, -a), s, patch, u, v))

    def seen(self, patch: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """True where S(u, v) is on its face, in front of the camera and seen from the eye (and on a highlight's tube)."""
        R, n, a, s = self.geometry(patch, u, v)
        w = self.camera.basis[0]
        good = (((R - self.camera.spec.eye) @ w) > 0) & self.surfaces.on_face(patch, u, v)
        lights = self.lights
        if self.mode.name == "highlight" and math.isfinite(lights.length):
            lam = lights.plane_t(R, n)  # the normal line, either sign
            tau = (R + np.where(np.isfinite(lam), lam, 0.0)[:, None] * n - lights.Q) @ lights.c
            good &= np.isfinite(lam) & (np.abs(tau) <= 0.5 * lights.length)
        n = facing(n, -a)
        idx = np.flatnonzero(good)
        good[idx] &= eye_sees(self, self.camera, R[idx], a[idx])
        if self.mode.along_ray:  # circular reflection lines: the reflected ray reaches the plane
            idx = np.flatnonzero(good)
            good[idx] &= reaches_light_plane(self, lights, R[idx], n[idx], patch[idx], s[idx])
        return good


def field_of(renderer) -> UlmetField:
    """The field whose level sets are the lines of a `Renderer`'s `[render] mode`: f for the tubes' reflection lines,
    else the mode's φ (circles too)."""
    if isinstance(renderer.mode, ReflectionMode):
        return UlmetField.of(renderer)
    return ModeField(renderer.surfaces, renderer.tessellation, renderer.accelerator, renderer.camera, renderer.lights,
                     renderer.mode, renderer.trace)


def eye_sees(scene, camera: Camera, R: np.ndarray, a: np.ndarray) -> np.ndarray:
    """True where the surface point R is the first surface the camera's ray towards it meets.

    ``scene`` is anything with ``accelerator``, ``tessellation`` and ``surfaces``; ``a`` the unit vector
    from R to the eye (eq. 3). The ray is the camera's own, from the eye (the eye plane for an
    orthographic camera) along −a, traced exactly (`tracing.trace`, as the renderer traces pixels):
    R is hidden when an exact hit or an undecided mesh hit lies more than `SAME_POINT` of the part's size
    before it. Not a shadow ray from R towards the eye: that one must start off the surface by the mesh's
    chord error (`Accelerator.surface_origins`), and every wall within that offset of R, in front of it,
    would be missed (the sweep's `revolved_seam.step`: chord error 6.3 on a part 140 across, and 5,981
    contour points behind a nearer wall by 1.2–24 counted as seen).
    """
    eye = camera.spec.eye
    if camera.orthographic:  # rays start on the eye plane (DESIGN.md's camera contract)
        to_R = (R - eye) @ camera.basis[0]
    else:
        to_R = np.linalg.norm(R - eye, axis=1)
    origins = R + to_R[:, None] * a
    seen = np.ones(len(R), dtype=bool)
    if len(R) == 0:
        return seen
    margin = SAME_POINT * scene.tessellation.extent
    hits = trace(scene.accelerator, scene.tessellation, scene.surfaces, origins, -a, max_distance=to_R - margin)
    seen &= ~(hits.fallback | (hits.hit & (hits.t < to_R - margin)))
    return seen


# -- polylines as flat arrays -------------------------------------------------------------------


@dataclass
class _Chains:
    """Many polylines as flat arrays: vertex rows, chain id per vertex (chains are contiguous)."""

    u: np.ndarray
    v: np.ndarray
    chain: np.ndarray
    ok: np.ndarray  # vertex polished onto its level set
    # Per vertex contourpy put on a grid edge: the edge's ends (u, v) and f there, (n, 6) (`_grid_edges`); NaN else.
    edge: np.ndarray | None = None

    def segments(self) -> np.ndarray:
        """Index i of segments (i, i + 1) within one chain."""
        return np.flatnonzero(self.chain[:-1] == self.chain[1:])

    def insert(self, after: np.ndarray, u: np.ndarray, v: np.ndarray, ok: np.ndarray) -> None:
        at = after + 1
        self.u = np.insert(self.u, at, u)
        self.v = np.insert(self.v, at, v)
        self.chain = np.insert(self.chain, at, self.chain[after])
        self.ok = np.insert(self.ok, at, ok)
        if self.edge is not None:  # a midpoint lies on no grid edge
            self.edge = np.insert(self.edge, at, np.nan, axis=0)


def _seam_split(field: UlmetField, k: int) -> list[tuple[float, float, float, float]]:
    """Patch k's domain (u0, u1, v0, v1), or where the image shows it on both sides of a closed direction's seam
    (`SurfaceSet.closed`), its two sides: split at the middle of the widest stretch of that parameter the image does
    not show, for `_grid_window` to zoom into each.

    One window round a seam's view spans the whole period (the near points lie at both of its ends), and is never
    narrowed: its grid's cells were ~30× the pixel size in a close-up of a closed face's seam (sphere.3dm and
    parts/trimmed.3dm's cylinder at fov 0.17–0.19°, 320×180: the analytic lines of one side missing, 1,500–1,700
    misses and 16 px in `validate`, where the hits are Open CASCADE's). The shown parameters are the `PROBE` probe
    points near the image and the seed rays' hits (`UlmetField.seed_uv`). (A split in v once gave the lower side
    twice and never the upper: torus.step's zebra, isophotes and highlight lines lost every piece there.)"""
    (u0, u1), (v0, v1) = field.surfaces.patches[k].domain
    windows = [(u0, u1, v0, v1)]
    closed = field.surfaces.closed[k]
    if not closed.any():
        return windows
    size = np.array([field.camera.width, field.camera.height], dtype=np.float64)
    margin = 0.25 * size.max()
    us, vs = np.linspace(u0, u1, PROBE), np.linspace(v0, v1, PROBE)
    uu, vv = np.meshgrid(us, vs, indexing="ij")
    px, depth = field.project(np.full(uu.size, k), uu.ravel(), vv.ravel())
    near = (depth > 0) & np.all((px >= -margin) & (px <= size + margin), axis=1)
    shown = np.concatenate([np.column_stack([uu.ravel(), vv.ravel()])[near], field.seed_uv(k)])
    for axis, (lo, hi) in enumerate(((u0, u1), (v0, v1))):
        if not closed[axis] or len(shown) < 2:
            continue
        values = np.unique(shown[:, axis])
        gaps = np.diff(values)
        if len(gaps) == 0:
            continue
        widest = int(np.argmax(gaps))
        # Across the seam the shown values are (values[0] − lo) + (hi − values[-1]) apart: split only where a stretch
        # inside the domain is wider, i.e. the shown part straddles the seam.
        if gaps[widest] <= (values[0] - lo) + (hi - values[-1]):
            continue
        cut = 0.5 * (values[widest] + values[widest + 1])
        windows = [w for window in windows for w in (
            ((window[0], cut, *window[2:]), (cut, *window[1:])) if axis == 0 else
            ((*window[:2], window[2], cut), (*window[:2], cut, window[3])))]
    return windows


def _grid_window(field: UlmetField, k: int, window: tuple[float, float, float, float] | None = None,
                 ) -> tuple[tuple[float, float, float, float], int, int]:
    """The part (u0, u1, v0, v1) of patch k's domain (or of ``window`` in it, a side of a seam: `_seam_split`) the
    image can show, and grid points along u and v so that one of its cells projects to about `GRID_CELL_PX` pixels.

    A `PROBE` × `PROBE` grid of the window (at first the whole domain) is projected; the probe points in front of
    the camera and within a quarter image of it are *near*. Where near neighbours lie more than that quarter image
    apart, or where a seed ray's hit (`UlmetField.seed_uv`) lies in a probe cell not all near, something the image
    shows may lie between probe points: the window narrows to the cells of the near points and seeds (one cell of
    margin) and is probed again, `ZOOM_ROUNDS` times at most. A close-up of a big face sized its grid from the whole
    face: hundreds of pixels a cell, and no line at all (revolved.step's default view at fov 0.2°, 320×180: 1,300
    analytic points missing in `validate`).
    """
    (u0, u1), (v0, v1) = field.surfaces.patches[k].domain
    window = (u0, u1, v0, v1) if window is None else window
    size = np.array([field.camera.width, field.camera.height], dtype=np.float64)
    margin = 0.25 * size.max()
    seeds = field.seed_uv(k)
    for _ in range(ZOOM_ROUNDS):
        wu0, wu1, wv0, wv1 = window
        us, vs = np.linspace(wu0, wu1, PROBE), np.linspace(wv0, wv1, PROBE)
        uu, vv = np.meshgrid(us, vs, indexing="ij")
        px, depth = field.project(np.full(uu.size, k), uu.ravel(), vv.ravel())
        px = px.reshape(PROBE, PROBE, 2)
        near = (depth.reshape(PROBE, PROBE) > 0) & np.all((px >= -margin) & (px <= size + margin), axis=2)
        px = np.where(near[..., None], px, np.nan)
        with np.errstate(invalid="ignore"):
            step_u = np.nanmax(np.linalg.norm(np.diff(px, axis=0), axis=2), initial=0.0)
            step_v = np.nanmax(np.linalg.norm(np.diff(px, axis=1), axis=2), initial=0.0)
        inside = (seeds[:, 0] >= wu0) & (seeds[:, 0] <= wu1) & (seeds[:, 1] >= wv0) & (seeds[:, 1] <= wv1)
        cell_u = np.minimum(((seeds[inside, 0] - wu0) / (wu1 - wu0) * (PROBE - 1)).astype(int), PROBE - 2)
        cell_v = np.minimum(((seeds[inside, 1] - wv0) / (wv1 - wv0) * (PROBE - 1)).astype(int), PROBE - 2)
        whole = near[:-1, :-1] & near[1:, :-1] & near[:-1, 1:] & near[1:, 1:]  # cells with all four corners near
        if max(step_u, step_v) <= margin and whole[cell_u, cell_v].all():
            break
        rows_u = np.concatenate([np.nonzero(near)[0], cell_u, cell_u + 1])
        rows_v = np.concatenate([np.nonzero(near)[1], cell_v, cell_v + 1])
        if len(rows_u) == 0:
            break  # nothing of the patch near the image: no line of it is seen
        lo_u, hi_u = max(rows_u.min() - 1, 0), min(rows_u.max() + 1, PROBE - 1)
        lo_v, hi_v = max(rows_v.min() - 1, 0), min(rows_v.max() + 1, PROBE - 1)
        if (lo_u, hi_u, lo_v, hi_v) == (0, PROBE - 1, 0, PROBE - 1):
            break  # the window holds no less: probing it again finds the same
        window = (us[lo_u], us[hi_u], vs[lo_v], vs[hi_v])
    breaks_u, breaks_v = field.surfaces.patches[k].span_breaks()
    n_u = int(np.clip(math.ceil((PROBE - 1) * step_u / GRID_CELL_PX), MIN_GRID, MAX_GRID))
    n_v = int(np.clip(math.ceil((PROBE - 1) * step_v / GRID_CELL_PX), MIN_GRID, MAX_GRID))
    # At least a few cells per knot span in the window: f's pieces follow the surface's.
    spans_u = np.count_nonzero((breaks_u > window[0]) & (breaks_u < window[1])) + 1
    spans_v = np.count_nonzero((breaks_v > window[2]) & (breaks_v < window[3])) + 1
    return window, max(n_u, 4 * spans_u) + 1, max(n_v, 4 * spans_v) + 1


def _patch_chains(field: UlmetField, k: int) -> tuple[_Chains, np.ndarray, float]:
    """contourpy's level sets f = c_j on patch k's grid, as chains, with each chain's tube index."""
    (u0, u1), (v0, v1) = field.surfaces.patches[k].domain
    lines_u, lines_v, chain_light, edges, cell = [], [], [], [], 0.0
    for side in _seam_split(field, k):  # one grid per side of a seam the image shows both sides of
        (wu0, wu1, wv0, wv1), n_u, n_v = _grid_window(field, k, side)
        # The knots are grid lines too: f is only as smooth as the surface across a knot, and a cell straddling one
        # (where f bends sharply, a near-double knot) interpolates a crossing onto the wrong piece, whence the polish
        # jumps to another branch or fails (the sweep's near_knots.step: spans 1e-6 wide, f's slope ×16 across u = 0.5,
        # one branch of the outermost line missing, 4.5 px from the traced one, at 320×180).
        breaks_u, breaks_v = field.surfaces.patches[k].span_breaks()
        us = np.union1d(np.linspace(wu0, wu1, n_u), breaks_u[(breaks_u > wu0) & (breaks_u < wu1)])
        vs = np.union1d(np.linspace(wv0, wv1, n_v), breaks_v[(breaks_v > wv0) & (breaks_v < wv1)])
        us, vs, f = _refined_at_blowups(field, k, us, vs, field.f_grid(k, us, vs))
        generator = contourpy.contour_generator(vs, us, f, line_type="Separate", corner_mask=True)
        finite = f[np.isfinite(f)]
        lo, hi = (finite.min(), finite.max()) if finite.size else (np.inf, -np.inf)
        on_level = NEWTON_TOLERANCE * field.newton_scale()
        for j, level in enumerate(field.levels):
            if field.period is not None:
                unwrapped = _unwrapped(f, float(level), field.period)
                near = unwrapped[np.isfinite(unwrapped)]
                if not (near.size and near.min() <= level <= near.max()):  # no cell can cross it: no grid to build
                    continue
                snapped = _snapped(unwrapped, float(level), on_level)
                lines = contourpy.contour_generator(vs, us, unwrapped if snapped is None else snapped,
                                                    line_type="Separate", corner_mask=True).lines(float(level))
            elif lo <= level <= hi:
                snapped = _snapped(f, float(level), on_level)
                lines = (generator if snapped is None else contourpy.contour_generator(
                    vs, us, snapped, line_type="Separate", corner_mask=True)).lines(float(level))
            else:
                continue
            for line in lines:
                if len(line) >= 2:
                    lines_v.append(line[:, 0])
                    lines_u.append(line[:, 1])
                    chain_light.append(j)
                    # A wrapping φ is contoured unwrapped about each level: its raw values bracket nothing there.
                    edges.append(_grid_edges(us, vs, f, line[:, 1], line[:, 0]) if field.period is None
                                 else np.full((len(line), 6), np.nan))
        for line_u, line_v, j in _small_loops(field, k, us, vs, f):
            lines_u.append(line_u)
            lines_v.append(line_v)
            chain_light.append(j)
            edges.append(np.full((len(line_u), 6), np.nan))
        # In the domain's unit square, like `UlmetField.polish`: the coarser side's, where there are two.
        cell = max(cell, math.hypot((wu1 - wu0) / (u1 - u0) / (n_u - 1), (wv1 - wv0) / (v1 - v0) / (n_v - 1)))
    if not lines_u:
        empty = np.zeros(0)
        return _Chains(empty, empty, np.zeros(0, int), np.zeros(0, bool)), np.zeros(0, int), 0.0
    lengths = [len(a) for a in lines_u]
    chains = _Chains(np.concatenate(lines_u), np.concatenate(lines_v), np.repeat(np.arange(len(lengths)), lengths),
                     np.ones(sum(lengths), dtype=bool), np.concatenate(edges))
    return chains, np.asarray(chain_light), cell


def _grid_edges(us: np.ndarray, vs: np.ndarray, f: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per contourpy vertex (u, v) on a grid line strictly between two grid points, the grid edge it lies on: its
    ends (u, v) and f there, (n, 6); NaN for a vertex on no grid edge (at a grid point, or on a masked cell's
    diagonal). contourpy interpolates along an edge, so a vertex there has the grid line's coordinate in its bits."""
    out = np.full((len(u), 6), np.nan)
    i = np.clip(np.searchsorted(us, u), 0, len(us) - 1)
    j = np.clip(np.searchsorted(vs, v), 0, len(vs) - 1)
    on_u, on_v = us[i] == u, vs[j] == v
    along_v = np.flatnonzero(on_u & ~on_v & (j > 0))  # on the line u = us[i], between vs[j − 1] and vs[j]
    along_u = np.flatnonzero(on_v & ~on_u & (i > 0))
    for rows, a, b in ((along_v, (i[along_v], j[along_v] - 1), (i[along_v], j[along_v])),
                       (along_u, (i[along_u] - 1, j[along_u]), (i[along_u], j[along_u]))):
        out[rows] = np.column_stack([us[a[0]], vs[a[1]], us[b[0]], vs[b[1]], f[a], f[b]])
    return out


def _snapped(f: np.ndarray, level: float, tolerance: float) -> np.ndarray | None:
    """The grid values with those within ``tolerance`` (Newton's, `NEWTON_TOLERANCE`) of ``level`` set to it exactly,
    or None where none is that close.

    Where a level set runs along a grid line, a domain edge or a closed face's seam (the equator of a torus whose
    seam circle it is, where the isophote 90° about its axis lies), f there is the level give or take rounding, and
    contourpy follows the rounding's signs: crossings in bits, wandering into the cells beside the edge, whose
    vertices Newton drags back along the grid line further than a cell and so rejects (torus.step's isophote 90°
    at 160×90: the line missing for 13 px, its traced centres 6.9 px from the nearest analytic piece, a false FAIL).
    On the level exactly, a grid line is on one side of it for contourpy (z > c is above): the line is found once,
    along the grid line, from the side where f rises above it.
    """
    with np.errstate(invalid="ignore"):
        close = np.abs(f - level) <= tolerance
    if not close.any():
        return None
    return np.where(close, level, f)


def _unwrapped(f: np.ndarray, level: float, period: float) -> np.ndarray:
    """A wrapping φ's grid values shifted by whole periods into (c − P/2, c + P/2] about level c, NaN within P/8 of
    that window's ends.

    Linear interpolation across φ's cut (zebra: ψ from 179° to −179° between grid points) finds no crossing of a
    level on the cut's far side of the jump and a false one of every level it spans: the zebra stripe ψ = 168° of the
    filleted block's vertical fillet, where ψ passes ±180°, missing, its traced line 2.7–7.6 px from any analytic
    one (a false FAIL at 160×90). About c the cut lies opposite it; the cells next to it, which would draw c along the
    jump, are masked (a true crossing of c there would need φ to change by P/4 within a cell).
    """
    shifted = level + np.mod(f - level + 0.5 * period, period) - 0.5 * period
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(shifted - level) <= 3.0 / 8.0 * period, shifted, np.nan)


def _levels_beyond(levels: np.ndarray, f0: np.ndarray, sign: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """How many of the (sorted) ``levels`` lie beyond the grid value f₀ within ``reach`` of it, the way f heads:
    f₀ < c ≤ f₀ + reach upwards (sign +1), f₀ − reach ≤ c < f₀ downwards (sign −1)."""
    return (np.searchsorted(levels, np.where(sign > 0, f0 + reach, f0), side="right")
            - np.searchsorted(levels, np.where(sign > 0, f0, f0 - reach), side="left") - np.isin(f0, levels))


def _blowup_edges(levels: np.ndarray, f: np.ndarray, axis: int) -> np.ndarray:
    """Per edge of the grid along ``axis`` ((n − 1, m) for n values along it), whether it runs from a finite value
    into NaN (t ≤ 0) with a level beyond the finite value in the direction f heads there (from its other neighbour).

    As the reflected ray turns parallel to the light plane t → ∞ and f → ±∞, so each such level is crossed in the cell
    that the NaN corner masks: contourpy draws none of them.
    """
    a = np.moveaxis(f, axis, 0)
    finite = np.isfinite(a)
    edges = np.zeros((len(a) - 1,) + a.shape[1:], dtype=bool)
    centre = np.nan_to_num(a[1:-1])
    # The finite end at i + 1 with NaN at i + 2 (heading on from i), or with NaN at i (heading on from i + 2).
    for end, before, edge in ((finite[1:-1] & finite[:-2] & ~finite[2:], a[:-2], edges[1:]),
                              (finite[1:-1] & finite[2:] & ~finite[:-2], a[2:], edges[:-1])):
        heading = np.where(end, np.sign(centre - np.nan_to_num(before)), 0.0)
        edge |= (heading != 0) & (_levels_beyond(levels, centre, heading, np.inf) > 0)
    return edges


def _refined_at_blowups(field: UlmetField, k: int, us: np.ndarray, vs: np.ndarray,
                        f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Patch k's grid (us × vs, values f) with grid lines added where levels crowd into a masked cell unseen.

    Where f runs off to ±∞ (`_blowup_edges`) the levels beyond the last finite grid value lie in the masked cell,
    a band of lines along its NaN side, which converge on the side where f's numerator changes sign: the tip of a
    sharp V in the image (OCCT's xr1-tu-rod.stp, a rod 200 × 10: each reflection line's V lay in such a band by the
    rod's side, its analytic contour up to 15 px short of the traced one, at every image size). The grid intervals
    with such an edge are halved and f evaluated on the new lines, `BLOWUP_ROUNDS` times: f ~ 1/d there, so each
    halving doubles the last finite value and brings the levels up to it into unmasked cells.
    """
    levels = np.sort(field.levels)
    for _ in range(BLOWUP_ROUNDS):
        new = []
        for axis, grid in enumerate((us, vs)):
            split = _blowup_edges(levels, f, axis).any(axis=1)
            new.append(0.5 * (grid[:-1] + grid[1:])[split])
        new_u, new_v = new
        if len(new_u) == 0 and len(new_v) == 0:
            break
        if len(new_u):
            order = np.argsort(np.concatenate([us, new_u]), kind="stable")
            us = np.concatenate([us, new_u])[order]
            f = np.concatenate([f, field.f_grid(k, new_u, vs)], axis=0)[order]
        if len(new_v):
            order = np.argsort(np.concatenate([vs, new_v]), kind="stable")
            vs = np.concatenate([vs, new_v])[order]
            f = np.concatenate([f, field.f_grid(k, us, new_v)], axis=1)[:, order]
    return us, vs, f


def _small_loops(field: UlmetField, k: int, us: np.ndarray, vs: np.ndarray,
                 f: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """Level sets f = c_j closing round an extremum of f that no grid point lies inside: (u, v) chains and their j.

    A level between a strict local extremum of the grid's values f₀ and the extremum of f itself is a loop between
    grid points, which contourpy cannot see. Where the parabolas through the grid extremum's neighbours along u and v
    put f's extremum past a level (by twice their overshoot, (f₊ − f₋)² / 8|f₊ − 2f₀ + f₋| on an even grid, for
    margin), the 2 × 2 cells round it are sampled `LOOP_GRID` points a side and contoured for the levels beyond f₀
    (the sweep's dense_net.step at 320×180: a loop f = 87.5 round a crest 88.2 between grid values below it, its
    traced line 4.1 px from every analytic one).
    """
    centre = f[1:-1, 1:-1]
    rows, cols = f.shape
    around = [f[1 + di:rows - 1 + di, 1 + dj:cols - 1 + dj] for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]
    with np.errstate(invalid="ignore"):  # NaN (t ≤ 0) compares False: no extremum next to it
        peak = np.logical_and.reduce([centre > other for other in around])
        pit = np.logical_and.reduce([centre < other for other in around])
    i, j = np.nonzero(peak | pit)
    if len(i) == 0:
        return []
    sign = np.where(peak[i, j], 1.0, -1.0)
    i, j = i + 1, j + 1
    f0 = f[i, j]
    # The parabola p(x) = f₀ + bx + ax² through the three values at x = −h₋, 0, h₊ along each direction (the grid
    # is uneven where `_refined_at_blowups` added lines): its extremum lies b²/4|a| past f₀ ((f₊ − f₋)²/8|f₊ − 2f₀ + f₋|
    # where h₋ = h₊).
    overshoot = 0.0
    for grid, at, di, dj in ((us, i, 1, 0), (vs, j, 0, 1)):  # (not k: that is the patch)
        below, above = f[i - di, j - dj] - f0, f[i + di, j + dj] - f0
        h_below, h_above = grid[at] - grid[at - 1], grid[at + 1] - grid[at]
        with np.errstate(divide="ignore", invalid="ignore"):
            b = (above * h_below ** 2 - below * h_above ** 2) / (h_below * h_above * (h_below + h_above))
            a = (above * h_below + below * h_above) / (h_below * h_above * (h_below + h_above))
            overshoot = overshoot + b * b / (4.0 * np.abs(a))
    reach = np.nan_to_num(2.0 * overshoot, nan=0.0, posinf=0.0)
    # Levels beyond f₀ towards the extremum, within reach (f₀ on a level: contourpy has that one).
    keep = np.flatnonzero(_levels_beyond(np.sort(field.levels), f0, sign, reach) > 0)
    if len(keep) == 0:
        return []
    i, j, f0, sign = i[keep], j[keep], f0[keep], sign[keep]
    s = np.linspace(0.0, 1.0, LOOP_GRID)
    fine_u = us[i - 1, None] + s * (us[i + 1] - us[i - 1])[:, None]
    fine_v = vs[j - 1, None] + s * (vs[j + 1] - vs[j - 1])[:, None]
    uu = np.broadcast_to(fine_u[:, :, None], (len(i), LOOP_GRID, LOOP_GRID)).ravel()
    vv = np.broadcast_to(fine_v[:, None, :], (len(i), LOOP_GRID, LOOP_GRID)).ravel()
    fine = np.concatenate([field.f(np.full(min(GRID_CHUNK, len(uu) - lo), k), uu[lo:lo + GRID_CHUNK],
                                   vv[lo:lo + GRID_CHUNK]) for lo in range(0, len(uu), GRID_CHUNK)])
    fine = fine.reshape(len(i), LOOP_GRID, LOOP_GRID)
    loops = []
    for e in range(len(i)):  # one contourpy call per extremum: few per patch, none on a smooth one
        values = fine[e][np.isfinite(fine[e])]
        if values.size == 0:
            continue
        if sign[e] > 0:
            wanted = np.flatnonzero((field.levels > f0[e]) & (field.levels < values.max()))
        else:
            wanted = np.flatnonzero((field.levels < f0[e]) & (field.levels > values.min()))
        generator = contourpy.contour_generator(fine_v[e], fine_u[e], fine[e], line_type="Separate", corner_mask=True)
        for light in wanted:
            for line in generator.lines(float(field.levels[light])):
                if len(line) >= 2:
                    loops.append((line[:, 1], line[:, 0], int(light)))
    return loops


def _cut_points(field: UlmetField, patch: np.ndarray, light: np.ndarray, ua, va, ub, vb, good_a: np.ndarray,
                cell: np.ndarray):
    """Bisect segments whose ends differ in class (a good, b not, or the reverse) down to the boundary.

    ``cell``: per segment, its patch's grid cell (`_patch_chains`), the farthest a polished midpoint may move.
    Returns the last point on the good side of each segment.
    """
    good_u = np.where(good_a, ua, ub)
    good_v = np.where(good_a, va, vb)
    bad_u = np.where(good_a, ub, ua)
    bad_v = np.where(good_a, vb, va)
    c = field.levels[light]
    for _ in range(BISECTION_STEPS):
        mu, mv, ok = field.polish(patch, 0.5 * (good_u + bad_u), 0.5 * (good_v + bad_v), c, cell)
        mid_good = ok & field.seen(patch, mu, mv)
        good_u, good_v = np.where(mid_good, mu, good_u), np.where(mid_good, mv, good_v)
        bad_u, bad_v = np.where(mid_good, bad_u, mu), np.where(mid_good, bad_v, mv)
    return good_u, good_v


@dataclass
class _Classified:
    """Patch k's polished, subdivided chains with each vertex's class (`UlmetField.seen`), awaiting the cut points
    of the segments ``change`` whose ends differ in class. Kept apart from the cuts so `analytic_contours` bisects
    every patch's cuts together: ten rounds of a few dozen eye rays per patch cost the tracer's fixed overhead
    each, and a point's bisection does not depend on the others'."""

    k: int
    chains: _Chains
    px: np.ndarray
    chain_light: np.ndarray
    good: np.ndarray
    change: np.ndarray
    cell: float

    def cut_args(self) -> tuple[np.ndarray, ...]:
        """`_cut_points`' per-segment arguments (patch, light, ua, va, ub, vb, good_a, cell) for ``change``."""
        c, n = self.change, len(self.change)
        light = self.chain_light[self.chains.chain[c]]
        return (np.full(n, self.k), light, self.chains.u[c], self.chains.v[c], self.chains.u[c + 1],
                self.chains.v[c + 1], self.good[c], np.full(n, self.cell))


def patch_contours(field: UlmetField, k: int) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(tube index, (n, 2) array of (u, v), (n, 2) image positions) of every visible contour piece on patch k."""
    classified = _classify(field, k)
    if classified is None:
        return []
    cut_u, cut_v = _cut_points(field, *classified.cut_args())
    return _pieces(field, classified, cut_u, cut_v)


def _classify(field: UlmetField, k: int) -> _Classified | None:
    """Patch k's level sets polished, subdivided and classified (steps 1–5 but the cuts' bisection); None if none."""
    if not field.lined(k):
        return None
    chains, chain_light, cell = _patch_chains(field, k)
    if len(chains.u) == 0:
        return None
    c_of = lambda rows: field.levels[chain_light[chains.chain[rows]]]  # noqa: E731
    every = np.arange(len(chains.u))
    pk = np.full(len(chains.u), k)
    chains.u, chains.v, chains.ok = field.polish(pk, chains.u, chains.v, c_of(every), np.full(len(pk), cell))
    # Where Newton failed from a vertex on a grid edge, the search along that edge, whose ends bracket c.
    failed = np.flatnonzero(~chains.ok & np.isfinite(chains.edge[:, 0]))
    if len(failed):
        u, v, ok = field.bracket(pk[failed], chains.edge[failed], c_of(failed))
        rows = failed[ok]
        chains.u[rows], chains.v[rows], chains.ok[rows] = u[ok], v[ok], True

    # Subdivide until every segment is short and straight in the image.
    px, depth = field.project(np.full(len(chains.u), k), chains.u, chains.v)
    front = depth > 0
    width, height = field.camera.width, field.camera.height
    # settled[i]: segment (i, i + 1) passed (or was left out) and its ends have not moved since, so the same
    # test would give the same answer: it is not polished again in later rounds (most segments settle early).
    settled = np.zeros(len(chains.u), dtype=bool)
    for _ in range(SUBDIVISION_ROUNDS):
        seg = chains.segments()
        seg = seg[~settled[seg]]
        # Only what can be seen needs refining: both ends polished and in front, the segment near the image.
        lo = np.minimum(px[seg], px[seg + 1])
        hi = np.maximum(px[seg], px[seg + 1])
        near_image = ((hi[:, 0] >= -IMAGE_MARGIN_PX) & (lo[:, 0] <= width + IMAGE_MARGIN_PX)
                      & (hi[:, 1] >= -IMAGE_MARGIN_PX) & (lo[:, 1] <= height + IMAGE_MARGIN_PX))
        wanted = chains.ok[seg] & chains.ok[seg + 1] & front[seg] & front[seg + 1] & near_image
        settled[seg[~wanted]] = True
        seg = seg[wanted]
        if len(seg) == 0:
            break
        mid_u = 0.5 * (chains.u[seg] + chains.u[seg + 1])
        mid_v = 0.5 * (chains.v[seg] + chains.v[seg + 1])
        (u0, u1), (v0, v1) = field.surfaces.patches[k].domain
        half = 0.5 * np.hypot((chains.u[seg + 1] - chains.u[seg]) / (u1 - u0), (chains.v[seg + 1] - chains.v[seg]) / (v1 - v0))
        mu, mv, mok = field.polish(np.full(len(seg), k), mid_u, mid_v, c_of(seg), np.maximum(half, 1e-3 * cell))
        mpx, mdepth = field.project(np.full(len(seg), k), mu, mv)
        chord_mid = 0.5 * (px[seg] + px[seg + 1])
        length = np.linalg.norm(px[seg + 1] - px[seg], axis=1)
        off = np.linalg.norm(mpx - chord_mid, axis=1)
        split = ~((length <= MAX_SEGMENT_PX) & (off <= CHORD_TOLERANCE_PX)) | ~np.isfinite(length)
        split &= half > 1e-9 * cell  # nothing left to split
        settled[seg[~split]] = True
        if not split.any():
            break
        seg, mu, mv, mok, mpx, mdepth = seg[split], mu[split], mv[split], mok[split], mpx[split], mdepth[split]
        chains.insert(seg, mu, mv, mok)
        settled = np.insert(settled, seg + 1, False)  # both halves of a split segment are new
        px = np.insert(px, seg + 1, mpx, axis=0)
        front = np.insert(front, seg + 1, mdepth > 0)

    good = chains.ok & field.seen(np.full(len(chains.u), k), chains.u, chains.v)
    # Cut where the class changes, at the boundary found by bisection (`_cut_points`).
    seg = chains.segments()
    return _Classified(k, chains, px, chain_light, good, seg[good[seg] != good[seg + 1]], cell)


def _pieces(field: UlmetField, classified: _Classified, cut_u: np.ndarray,
            cut_v: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """`patch_contours`' pieces: the classified chains with the cut points inserted, split into runs of good vertices."""
    k, chains, px, chain_light = classified.k, classified.chains, classified.px, classified.chain_light
    good, change = classified.good, classified.change
    # A good vertex followed by a bad one: append the cut after it; a bad one followed by a good one: before the good one.
    u, v, chain, keep = chains.u, chains.v, chains.chain, good
    ends_after = change[good[change]]
    starts_before = change[~good[change]]
    order = np.argsort(np.concatenate([ends_after, starts_before]), kind="stable")
    where = np.concatenate([ends_after, starts_before])[order]
    new_u = np.concatenate([cut_u[good[change]], cut_u[~good[change]]])[order]
    new_v = np.concatenate([cut_v[good[change]], cut_v[~good[change]]])[order]
    new_px, _ = field.project(np.full(len(new_u), k), new_u, new_v)
    u = np.insert(u, where + 1, new_u)
    v = np.insert(v, where + 1, new_v)
    px = np.insert(px, where + 1, new_px, axis=0)
    chain = np.insert(chain, where + 1, chain[where])
    keep = np.insert(keep, where + 1, True)
    # Runs of kept vertices within one chain become the pieces.
    run_start = keep & np.concatenate([[True], ~keep[:-1] | (chain[1:] != chain[:-1])])
    run_id = np.cumsum(run_start) - 1
    pieces = []
    kept = np.flatnonzero(keep)
    if len(kept) == 0:
        return []
    bounds = np.flatnonzero(np.diff(run_id[kept])) + 1
    for rows in np.split(kept, bounds):
        if len(rows) >= 2:
            pieces.append((int(chain_light[chain[rows[0]]]), np.column_stack([u[rows], v[rows]]), px[rows]))
    return pieces


def analytic_contours(field: UlmetField, progress=None) -> ContourLines:
    """Every tube's visible reflection line as projected polylines (the contour theorem, section 4)."""
    levels = field.levels
    per_light: dict[int, list[Polyline]] = {j: [] for j in range(len(levels))}
    classified = []
    for k in range(len(field.surfaces)):
        found = _classify(field, k)
        if found is not None:
            classified.append(found)
        if progress:
            progress(1)
    # Every patch's cuts bisected together (`_Classified`), then handed back patch by patch.
    args = [c.cut_args() for c in classified]
    if args:
        cut_u, cut_v = _cut_points(field, *(np.concatenate(column) for column in zip(*args)))
        bounds = np.cumsum([len(c.change) for c in classified])[:-1]
        for c, cu, cv in zip(classified, np.split(cut_u, bounds), np.split(cut_v, bounds)):
            for light, uv, px in _pieces(field, c, cu, cv):
                per_light[light].append(Polyline(c.k, uv, px))
    lines = [ContourLine(j, float(levels[j]), per_light[j]) for j in range(len(levels))]
    return ContourLines(field.camera.width, field.camera.height, lines)
