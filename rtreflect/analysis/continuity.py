"""Continuity across shared edges: the G0 gap, the G1 angle and the G2 curvature jump, exact along each seam.

For a seam (`rtreflect.geometry.seams.Seam`) the boundary curve C_A(t) of face A is sampled;
each sample P = C_A(t) is matched on face B by Newton (the foot point on B's boundary curve,
Piegl & Tiller section 6.1) — or, for a B-rep edge of a CAD part, by the edge's parameter:
B's pcurve at the same t (both pcurves are exact there) — and at both points the exact derivatives S, S_u, S_v, S_uu, S_uv,
S_vv come from `NurbsSurface.evaluate`. Then (do Carmo, *Differential Geometry of Curves and
Surfaces*, sections 3-2 and 3-3; Piegl & Tiller eq. 4.20 for the rational derivatives):

- **G0**: the gap |S_A − S_B|.
- **G1**: the angle between the unit normals n = S_u × S_v / |S_u × S_v|, their orientations made
  consistent across the edge: with T the edge's unit tangent and w the unit vector tangent to the
  face, perpendicular to T and pointing into the face, each normal is turned so that
  n_A = T × w_A and n_B = −T × w_B (as on a flat sheet, where w_B = −w_A). Angle
  atan2(|n_A × n_B|, n_A · n_B), accurate at 0 and at 180°.
- **G2**: the normal curvature of each side across the edge, in the direction w (do Carmo
  3-2, Proposition 4 / Piegl & Tiller section 9.5):

      κ(w) = II(w, w) / I(w, w),   with w = a S_u + b S_v,
      I = E a² + 2F ab + G b² (E = S_u·S_u, F = S_u·S_v, G = S_v·S_v),
      II = L a² + 2M ab + N b² (L = S_uu·n, M = S_uv·n, N = S_vv·n),

  with the consistent n of each side; κ(w) = κ(−w), so the two sides' figures compare
  directly. The jump |κ_A − κ_B| is reported in 1/unit and relative:

  - ``rel`` = |κ_A − κ_B| / max(|κ_A|, |κ_B|): the jump against the larger curvature. With the
    signed radii ρ = 1/κ it equals |ρ_A − ρ_B| / max(|ρ_A|, |ρ_B|) (the radius-based ratio),
    so the two CAD conventions agree and one figure stands for both;
  - ``rel_mean`` = |κ_A − κ_B| / ((|κ_A| + |κ_B|) / 2): the jump against the mean curvature
    magnitude, the "percentage" some checkers print; it differs from ``rel`` (up to 2×).

  Both are 0 where the jump is within `FLAT_CURVATURE` (times 1/size) — two flat sides.

Each seam is sampled adaptively: its knot spans first, then midpoints inserted wherever a
quantity changes between neighbours by more than `REFINE_FRACTION` of its range along the seam.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry.curvature import normal_curvature
from ..geometry.seams import Seam, closest_on_surface, curve, match_points, sample_parameters
from ..geometry.surfaces import NurbsSurface

#: Samples per Bézier span of the seam before refinement.
INITIAL_PER_SPAN = 8
#: Insert a midpoint where G0, G1 or a side's curvature changes between neighbours by more than this
#: fraction of its range on the seam (so the maxima are located to a few percent of their spacing).
REFINE_FRACTION = 0.05
REFINE_ROUNDS = 6
#: Changes below these are rounding, not shape, and drive no refinement: a gap of 1e-12 of the part's size,
#: an angle of 1e-10 rad (the normals' rounding is ~1e-13..1e-11 rad near poles).
NOISE_GAP = 1e-12
NOISE_ANGLE = 1e-10
#: Most samples per seam: bounds the work on a wild seam; the knot spans are always covered.
MAX_SEAM_SAMPLES = 4097
#: A curvature jump below this many 1/size is zero: two flat (or equally curved) sides rounded apart. Double
#: rounding on κ from second derivatives is ~1e-14/size; 1e-8 leaves a margin of a million.
FLAT_CURVATURE = 1e-8
CLASSES = ("open", "G0", "G1", "G2")
#: Where the seam runs into a degenerate point (a pole, a collapsed side: S_u or the edge's C' vanishes) the
#: tangent, w and the curvature are limits; they are measured this fraction of the seam's parameter range inside.
#: At distance h from a pole the fundamental forms lose ~ε/h² of their digits and the limit is off by ~h:
#: 1e-5 keeps both near 1e-5 of the figures.
POLE_STEP = 1e-5


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _unit(a: np.ndarray) -> np.ndarray:
    return a / np.linalg.norm(a, axis=1, keepdims=True)


def across(der, n: np.ndarray, T: np.ndarray, inward_uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """w: unit tangent of the face perpendicular to the edge tangent T, pointing into the face (``inward_uv``,
    (n, 2), says which way is in); and σ = ±1 with w = σ (n × T), i.e. T × w = σ n (see the module doc)."""
    w = np.cross(n, T)
    into = der.Su * inward_uv[:, :1] + der.Sv * inward_uv[:, 1:]
    sigma = np.where(_dot(w, into) >= 0, 1.0, -1.0)
    return _unit(w * sigma[:, None]), sigma


@dataclass
class SeamSamples:
    """The measures at samples t of one seam (arrays of one entry per sample)."""

    t: np.ndarray
    s: np.ndarray  # arc length from the seam's start
    P: np.ndarray  # the point on A (n, 3)
    uv_a: np.ndarray
    uv_b: np.ndarray
    t_b: np.ndarray
    g0: np.ndarray
    g1: np.ndarray  # radians
    kappa_a: np.ndarray
    kappa_b: np.ndarray
    n_a: np.ndarray  # consistently oriented unit normals
    n_b: np.ndarray
    w_a: np.ndarray  # unit, into A across the edge
    w_b: np.ndarray  # unit, into B across the edge
    size: float = 1.0

    @property
    def jump(self) -> np.ndarray:
        """|κ_A − κ_B|, 1/unit; zeroed within `FLAT_CURVATURE` / size."""
        j = np.abs(self.kappa_a - self.kappa_b)
        return np.where(j * self.size <= FLAT_CURVATURE, 0.0, j)

    @property
    def rel(self) -> np.ndarray:
        big = np.maximum(np.abs(self.kappa_a), np.abs(self.kappa_b))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.jump > 0, self.jump / big, 0.0)

    @property
    def rel_mean(self) -> np.ndarray:
        mean = 0.5 * (np.abs(self.kappa_a) + np.abs(self.kappa_b))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.jump > 0, self.jump / mean, 0.0)


def measure(surfaces: list[NurbsSurface], seam: Seam, t: np.ndarray, size: float = 1.0) -> SeamSamples:
    """The exact G0, G1, G2 figures at parameters t of the seam's curve on A.

    At a degenerate point (see `POLE_STEP`) the figures are those `POLE_STEP` inside the seam.
    """
    out = _measure(surfaces, seam, t, size)
    bad = ~(np.isfinite(out.g1) & np.isfinite(out.kappa_a) & np.isfinite(out.kappa_b))
    if np.any(bad):
        step = POLE_STEP * (seam.t1 - seam.t0)
        tb = t[bad]
        inner = np.where(tb - seam.t0 < seam.t1 - tb, tb + step, tb - step)
        again = _measure(surfaces, seam, inner, size)
        for name in ("g0", "g1", "kappa_a", "kappa_b", "n_a", "n_b", "w_a", "w_b"):
            getattr(out, name)[bad] = getattr(again, name)
    return out


def _measure(surfaces: list[NurbsSurface], seam: Seam, t: np.ndarray, size: float) -> SeamSamples:
    sa, sb = surfaces[seam.a.patch], surfaces[seam.b.patch]
    P, C1a, _, uv_a, der_a = curve(sa, seam.a, t, order=2)
    # A B-rep edge pairs its two pcurves by parameter; boundaries found geometrically are matched by foot points.
    t_b = t if seam.paired else match_points(sb, seam.b, P)[0]
    Q, C1b, _, uv_b, der_b = curve(sb, seam.b, t_b, order=2)
    # A sampled trim loop: the exact edge lies on B's surface, not on the loop's chords. A B-rep edge's point on B is
    # B's pcurve at the same parameter (SameParameter): G0 is then the gap the edge's tolerance bounds.
    if not seam.b.exact and not seam.paired:
        uv_b = closest_on_surface(sb, P, uv_b)
        der_b = sb.evaluate(uv_b[:, 0], uv_b[:, 1], order=2)
        Q = der_b.S
    with np.errstate(divide="ignore", invalid="ignore"):  # C' = 0 at a pole: NaN, measured again inside
        Ta = _unit(C1a)
        Tb = _unit(C1b)
    Tb *= np.where(_dot(Ta, Tb) >= 0, 1.0, -1.0)[:, None]
    na = sa.normals(uv_a[:, 0], uv_a[:, 1], der_a)
    nb = sb.normals(uv_b[:, 0], uv_b[:, 1], der_b)
    w_a, sig_a = across(der_a, na, Ta, seam.a.inward_at(t))
    w_b, sig_b = across(der_b, nb, Tb, seam.b.inward_at(t_b))
    na = na * sig_a[:, None]   # T × w_A = n_A
    nb = -nb * sig_b[:, None]  # T × w_B = −n_B
    g1 = np.arctan2(np.linalg.norm(np.cross(na, nb), axis=1), _dot(na, nb))
    with np.errstate(divide="ignore", invalid="ignore"):
        ka = normal_curvature(der_a, na, w_a)
        kb = normal_curvature(der_b, nb, w_b)
    # Degenerate: the edge's tangent or the first fundamental form vanishes (relative to its scale).
    for surface, C1, der, k in ((sa, C1a, der_a, ka), (sb, C1b, der_b, kb)):
        k[surface.degenerate(der) | ~(np.linalg.norm(C1, axis=1) > 0)] = np.nan
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    return SeamSamples(t, np.r_[0.0, np.cumsum(seg)], P, uv_a, uv_b, t_b, np.linalg.norm(P - Q, axis=1), g1, ka, kb,
                       na, nb, w_a, w_b, size)


def _merge(a: SeamSamples, b: SeamSamples) -> SeamSamples:
    """The samples of a and b, sorted by t (arc length recomputed)."""
    order = np.argsort(np.r_[a.t, b.t], kind="stable")
    out = {}
    for name in ("t", "P", "uv_a", "uv_b", "t_b", "g0", "g1", "kappa_a", "kappa_b", "n_a", "n_b", "w_a", "w_b"):
        out[name] = np.concatenate([getattr(a, name), getattr(b, name)])[order]
    seg = np.linalg.norm(np.diff(out["P"], axis=0), axis=1)
    return SeamSamples(s=np.r_[0.0, np.cumsum(seg)], size=a.size, **out)


def sample_seam(surfaces: list[NurbsSurface], seam: Seam, size: float) -> SeamSamples:
    """Adaptive sampling of the seam (knot spans first, then midpoints where the figures change)."""
    sa = surfaces[seam.a.patch]
    if not seam.a.exact:  # a sampled trim loop is on the edge at its vertices only: measure there
        inner = np.arange(np.ceil(seam.t0), np.floor(seam.t1) + 1.0)
        return measure(surfaces, seam, np.unique(np.r_[seam.t0, inner, seam.t1]), size=size)
    t = sample_parameters(sa, seam.a, seam.t0, seam.t1, per_span=INITIAL_PER_SPAN)
    samples = measure(surfaces, seam, t, size=size)
    for _ in range(REFINE_ROUNDS):
        refine = np.zeros(len(samples.t) - 1, dtype=bool)
        floors = (NOISE_GAP * size, NOISE_ANGLE, FLAT_CURVATURE / size, FLAT_CURVATURE / size)
        for q, floor in zip((samples.g0, samples.g1, samples.kappa_a, samples.kappa_b), floors):
            span = np.ptp(q)
            if span > floor and np.all(np.isfinite(q)):
                refine |= np.abs(np.diff(q)) > REFINE_FRACTION * span
        idx = np.flatnonzero(refine)
        if len(idx) == 0 or len(samples.t) + len(idx) > MAX_SEAM_SAMPLES:
            break
        mid = 0.5 * (samples.t[idx] + samples.t[idx + 1])
        samples = _merge(samples, measure(surfaces, seam, mid, size))
    return samples


@dataclass(frozen=True)
class Thresholds:
    """When an edge reaches a class: gap ≤ g0 (model units), angle ≤ g1 (degrees), rel jump ≤ g2 (fraction)."""

    g0: float
    g1_deg: float
    g2: float


@dataclass
class EdgeReport:
    seam: Seam
    samples: SeamSamples
    cls: str
    line_kink_max_deg: float | None = None
    line_kink_image_max_deg: float | None = None
    line_crossings: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def g0_max(self) -> float:
        return float(np.max(self.samples.g0))

    @property
    def g1_max_deg(self) -> float:
        return float(np.degrees(np.max(self.samples.g1)))

    @property
    def g2_max_abs(self) -> float:
        return float(np.max(self.samples.jump))

    @property
    def g2_max_rel(self) -> float:
        return float(np.max(self.samples.rel))

    def worst(self, which: str) -> list[float]:
        q = {"g0": self.samples.g0, "g1": self.samples.g1, "g2": self.samples.jump}[which]
        return self.samples.P[int(np.argmax(q))].tolist()

    def to_json(self) -> dict:
        s = self.samples
        return {
            "patches": [self.seam.a.patch, self.seam.b.patch],
            "sides": [self.seam.a.side, self.seam.b.side],
            "length": self.seam.length,
            "samples": int(len(s.t)),
            "g0_max": self.g0_max,
            "g1_max_deg": self.g1_max_deg,
            "g2_max_abs": self.g2_max_abs,
            "g2_max_rel": self.g2_max_rel,
            "g2_max_rel_mean": float(np.max(s.rel_mean)),
            "class": self.cls,
            "worst": {k: self.worst(k) for k in ("g0", "g1", "g2")},
            "line_kink_max_deg": self.line_kink_max_deg,
            "line_kink_image_max_deg": self.line_kink_image_max_deg,
            "line_geodesic_jump_max": None,  # filled (in extra) where lines cross in view
            "line_crossings": self.line_crossings,
            "along": {"s": s.s.tolist(), "g0": s.g0.tolist(), "g1_deg": np.degrees(s.g1).tolist(),
                      "kappa_a": s.kappa_a.tolist(), "kappa_b": s.kappa_b.tolist()},
            **self.extra,
        }


def classify(samples: SeamSamples, th: Thresholds) -> str:
    """The highest class the seam reaches at every sample: open (gap), G0, G1 or G2."""
    if not np.all(samples.g0 <= th.g0):
        return "open"
    if not np.all(np.degrees(samples.g1) <= th.g1_deg):
        return "G0"
    if not np.all(samples.rel <= th.g2):
        return "G1"
    return "G2"


def continuity(surfaces: list[NurbsSurface], seams: list[Seam], th: Thresholds, size: float) -> list[EdgeReport]:
    """One `EdgeReport` per seam."""
    reports = []
    for seam in seams:
        samples = sample_seam(surfaces, seam, size)
        reports.append(EdgeReport(seam, samples, classify(samples, th)))
    return reports


def class_rank(cls: str) -> int:
    return CLASSES.index(cls)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in radians between the rows of a and b (any lengths), accurate near 0 and π."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


__all__ = ["Thresholds", "EdgeReport", "SeamSamples", "continuity", "classify", "measure", "sample_seam",
           "normal_curvature", "angle_between", "CLASSES", "class_rank"]
