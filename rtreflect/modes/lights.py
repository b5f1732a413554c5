"""Lights and modes: parallel light tubes and the reflection-line mode (Ulmet, sections 3–4).

Notation of the paper: surface point R, unit normal n, a towards the eye,
s the reflected direction, light line k through B_k with unit direction c.
The tubes lie in a plane through Q with unit normal m; e = (c × m)/|c × m|, and
tube k passes through B_k = Q + c_k e.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exchange.scene import LightSpec
from ..kernels import tubes as tubes_kernel
from ..trace.tracing import occluded

#: Point × tube pairs per chunk of the skew-line distances (eq. 4): about 80 MB of temporaries. `reach` (the
#: renderer's path) no longer builds the tables: `integrator.tiling` still budgets memory with it.
TUBE_ENTRIES_PER_CHUNK = 1 << 20


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...j,...j->...", a, b)


def reflect(a: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Reflected direction, paper eq. (3): s = 2 (a·n) n − a, for unit a and n (N, 3) (`kernels.tubes.reflect`)."""
    a, n = np.ascontiguousarray(a, dtype=np.float64), np.ascontiguousarray(n, dtype=np.float64)
    out = np.empty(a.shape)
    tubes_kernel.reflect(a, n, out)
    return out


def reflect_rays(directions: np.ndarray, rows: np.ndarray, n: np.ndarray, s: np.ndarray) -> np.ndarray:
    """`reflect` of the rays ``directions[rows]`` (a = −D, for either camera) at their unit normals n (len(rows), 3):
    written into ``s[rows]`` and returned as an array of their own (`kernels.tubes.reflect_rays`)."""
    out = np.empty((len(rows), 3))
    tubes_kernel.reflect_rays(np.ascontiguousarray(directions, dtype=np.float64),
                              np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(n, dtype=np.float64),
                              out, s)
    return out


#: |m·n| at or below which a normal line counts as parallel to the light plane (`TubeLights.normal_line_f`): it would
#: cross it more than 10⁹ times its distance away, and a unit normal's rounding (~1e-13 on a converted plane) would
#: decide where.
PARALLEL_COS = 1e-9

@dataclass(frozen=True)
class TubeDistances:
    """Per point and tube (N, K): skew-line distance d, ray parameter t of closest approach, and reach."""

    d: np.ndarray
    t: np.ndarray
    ahead: np.ndarray  # t > 0 and within the tube's length


@dataclass(frozen=True)
class TubeReach:
    """Per point, what eq. (4) tells about the tubes ahead of its reflected ray (see `TubeLights.reach`)."""

    line_id: np.ndarray  # nearest tube ahead, −1 where none is
    line_dist: np.ndarray  # its distance d, NaN where none is
    line_sigma: np.ndarray  # its signed distance σ (`signed_distance`), NaN where none is
    line_t: np.ndarray  # the ray parameter t of its closest approach, NaN where none is
    candidate: np.ndarray  # some tube ahead lies within the radius
    t_candidate: np.ndarray  # ray parameter t of the nearest such (inf where none)
    t_of: np.ndarray | None  # t of the tube asked for per point (`reach`'s ``tube``), else None
    f: np.ndarray  # Ulmet's f of the same reflected ray (`TubeLights.ulmet_f`), NaN where it never meets the plane


@dataclass(frozen=True)
class TubeLights:
    Q: np.ndarray
    m: np.ndarray
    c: np.ndarray
    e: np.ndarray
    c_k: np.ndarray
    radius: float
    length: float

    @classmethod
    def from_spec(cls, spec: LightSpec) -> "TubeLights":
        e = np.cross(spec.direction, spec.normal)
        return cls(spec.point, spec.normal, spec.direction, e / np.linalg.norm(e), np.asarray(spec.positions, float),
                   float(spec.radius), float(spec.length))

    @property
    def spacing(self) -> float:
        """Smallest distance between two distinct tube positions c_k: f's natural unit (inf for a single position)."""
        gaps = np.diff(np.unique(self.c_k))
        return float(gaps.min()) if len(gaps) else float("inf")

    def plane_t(self, R: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Ray parameter where R + t s meets the light plane, t = m·(Q − R)/(m·s) (±inf or NaN where s ∥ plane), for
        points R and directions s (N, 3), by the kernel `kernels.tubes.plane_t` (the t `ulmet_f` and `reach` read f at)."""
        f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
        out = np.empty(len(R))
        tubes_kernel.plane_t(f64(self.Q), f64(self.m), f64(R), f64(s), out)
        return out

    @property
    def points(self) -> np.ndarray:
        """B_k = Q + c_k e: a point of each tube's axis, its centre for a finite tube."""
        return self.Q + self.c_k[:, None] * self.e

    def _kernel_args(self) -> tuple:
        half = 0.5 * self.length if np.isfinite(self.length) else np.inf
        f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
        return f64(self.Q), f64(self.c), f64(self.e), f64(self.c_k), half

    def distances(self, R: np.ndarray, s: np.ndarray) -> TubeDistances:
        """Skew-line distance d between the ray R + t s and every light line, paper eq. (4) (`kernels.tubes`).

        d = |(s × c)·b| / |s × c| with b = B_k − R; if s ∥ c, d = |b × c|. Since
        b = (Q − R) + c_k e, d and the ray parameter t of closest approach are
        per-point scalars combined with c_k: d = |g − c_k h| / |s × c|, t = α + β c_k.
        """
        Q, c, e, c_k, half = self._kernel_args()
        n, k = len(R), len(c_k)
        d, t, ahead = np.empty((n, k)), np.empty((n, k)), np.empty((n, k), dtype=bool)
        tubes_kernel.distances(Q, c, e, c_k, half, np.ascontiguousarray(R, dtype=np.float64),
                               np.ascontiguousarray(s, dtype=np.float64), d, t, ahead)
        return TubeDistances(d, t, ahead)

    def normal_line_f(self, R: np.ndarray, n: np.ndarray) -> np.ndarray:
        """The highlight's field (Beier and Chen): the e-coordinate where the normal line R + λn, λ of either sign,
        meets the light plane; NaN where n is parallel to it, to `PARALLEL_COS`.

        On a face whose normals lie in the light plane's direction to rounding, λ n carries that rounding times a
        distance over it: φ was noise of the part's size, and `validate`'s analytic lines crossed the face where the
        renderer's stripes (the skew-line distance, `reach`) rightly draw none (OCCT's data/step/bug32596_abc_0_13.step,
        a wall at |m·n| 1.3e-13 under lights straight above: 42 misses at 320×180)."""
        lam = self.plane_t(R, n)  # either sign: the whole normal line
        with np.errstate(invalid="ignore"):
            f = _dot(R + lam[:, None] * n - self.Q, self.e)
        return np.where(np.isfinite(lam) & (np.abs(_dot(n, self.m)) > PARALLEL_COS), f, np.nan)

    def ulmet_f(self, R: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Ulmet's function, general form of paper eq. (5): the e-coordinate where the reflected ray meets the light plane.

        t = m·(Q − R)/(m·s), f = e·(R + t s − Q); NaN where t ≤ 0 (the ray never reaches the plane).
        For m = k, c = j this is f = [(s × r)·j + z0 (s·i)] / (s·k). By the kernel `kernels.tubes.ulmet_f`
        (`reach` gives the same f beside the nearest tube).
        """
        f64 = lambda x: np.ascontiguousarray(x, dtype=np.float64)  # noqa: E731
        out = np.empty(len(R))
        tubes_kernel.ulmet_f(f64(self.Q), f64(self.m), f64(self.e), f64(R), f64(s), out)
        return out

    def nearest(self, dist: TubeDistances) -> tuple[np.ndarray, np.ndarray]:
        """Index and distance d of the nearest tube ahead of each point; −1 and NaN where none is."""
        masked = np.where(dist.ahead, dist.d, np.inf)
        k = np.argmin(masked, axis=1)
        dk = masked[np.arange(len(k)), k]
        found = np.isfinite(dk)
        return np.where(found, k, -1), np.where(found, dk, np.nan)

    def candidates(self, dist: TubeDistances) -> tuple[np.ndarray, np.ndarray]:
        """Per point: whether some tube ahead is within the radius, and the ray distance to the nearest such."""
        within = dist.ahead & (dist.d <= self.radius)
        t_hit = np.where(within, dist.t, np.inf).min(axis=1)
        return within.any(axis=1), t_hit

    def signed_distance(self, R: np.ndarray, s: np.ndarray, tube: np.ndarray) -> np.ndarray:
        """Signed skew-line distance σ of each ray R + t s to the axis of tube ``tube[i]`` (`kernels.tubes.signed`).

        |σ| is eq. (4)'s d; the sign tells the two sides of the axis apart, so σ is smooth across a
        stripe and the stripe is |σ| ≤ r (`integrator.analytic` needs it and its gradient).
        """
        Q, c, e, c_k, _ = self._kernel_args()
        out = np.empty(len(R))
        tubes_kernel.signed(Q, c, e, c_k, np.ascontiguousarray(R, dtype=np.float64),
                            np.ascontiguousarray(s, dtype=np.float64), np.ascontiguousarray(tube, dtype=np.int64), out)
        return out

    def reach(self, R: np.ndarray, s: np.ndarray, tube: np.ndarray | None = None) -> TubeReach:
        """`nearest` and `candidates` of eq. (4)'s distances, per point by the kernel `kernels.tubes.reach`.

        No (points, tubes) table is built, so memory does not grow with the number of tubes; each
        point's values depend on its own row only. The nearest tube's signed distance and t come in the
        same pass (the analytic path's σ and occlusion distance, `modes.base.Stripes`). With ``tube`` (one tube
        index per point), also the ray parameter t of closest approach to that tube. Ulmet's f (`ulmet_f`) comes
        along: the renderer's f AOV without a second pass over the rays.
        """
        Q, c, e, c_k, half = self._kernel_args()
        n = len(R)
        line_id, line_dist, line_sigma, line_t = np.empty(n, dtype=np.int64), np.empty(n), np.empty(n), np.empty(n)
        candidate, t_candidate = np.empty(n, dtype=bool), np.empty(n)
        t_of, f = np.full(n, np.nan), np.empty(n)
        which = np.zeros(0, dtype=np.int64) if tube is None else np.ascontiguousarray(tube, dtype=np.int64)
        tubes_kernel.reach(Q, np.ascontiguousarray(self.m, dtype=np.float64), c, e, c_k, float(self.radius), half,
                           np.ascontiguousarray(R, dtype=np.float64), np.ascontiguousarray(s, dtype=np.float64), which,
                           line_id, line_dist, line_sigma, line_t, candidate, t_candidate, t_of, f)
        return TubeReach(line_id, line_dist, line_sigma, line_t, candidate, t_candidate, None if tube is None else t_of,
                         f)


def reaches_light_plane(scene, lights: TubeLights, R: np.ndarray, n: np.ndarray,
                        patch: np.ndarray, s: np.ndarray) -> np.ndarray:
    """True where the reflected ray R + t s meets the light plane ahead (t > 0) with no surface on the way.

    ``scene`` is anything with ``accelerator``, ``tessellation`` and ``surfaces`` (a `Renderer`, an
    `UlmetField`); the occlusion is `tracing.occluded`, which respects trims.

    n is the unit normal at R turned to the side the ray leaves from; the ray starts there,
    off the surface by more than the mesh's chord error (`Accelerator.surface_origins`), as the
    renderer's do.
    """
    t = lights.plane_t(R, s)
    clear = t > 0
    idx = np.flatnonzero(clear)
    origin = scene.accelerator.surface_origins(R[idx], n[idx], patch[idx])
    clear[idx] = ~occluded(scene.accelerator, scene.tessellation, scene.surfaces, origin, s[idx], t[idx])
    return clear
