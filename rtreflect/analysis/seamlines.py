"""The continuity read back from the stripes: the kink of each reflection line where it crosses a seam.

The paper (section 1): across a G^k seam the reflection lines are G^(k−1). A reflection line
is the level set f(u, v) = c_k of Ulmet's function (`contours.UlmetField.f`, eq. 5–6); f
depends on the normal, so across a G1 seam f is continuous and the line continuous, but ∇f
depends on the normal's derivative (the second fundamental form), and where the curvature
jumps the line's direction jumps: a kink. Across a G2 seam the line is smooth; across a G0
seam (a normal jump) f itself jumps and the line breaks.

For each light line c_k and seam: the crossings are located on the seam's curve of face A
by bisection of f_A − c_k between the seam's samples; at each crossing the line's tangent
on each side is the level set's direction, (du, dv) ∝ (f_v, −f_u), mapped to 3D by
S_u du + S_v dv (∇f by second-order one-sided differences, stepped into the domain). The
kink is the angle between the two sides' tangents, both oriented across the seam from A to
B; in the image, between the two tangents' projections. The jump of the line's geodesic
curvature across the seam comes from points traced along the line on each side (Richardson-extrapolated
one-sided differences).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.seams import curve, match_points
from .contours import UlmetField
from .continuity import EdgeReport, angle_between

#: Bisection steps locating a crossing on the seam: 2^-40 of a sample spacing, below rounding of f.
CROSSING_STEPS = 40
#: Finite-difference step for ∇f, as a fraction of the parameter range: the second-order one-sided
#: difference's error (~h²) and rounding (~ε/h) balance near 1e-5.
GRADIENT_STEP = 1e-5
#: Step along the tangent for its image direction, as a fraction of the part's size.
IMAGE_STEP = 1e-6


#: Arc-length step, as a fraction of the part's size, of the two points traced along a line on each side of a
#: seam for its geodesic curvature: the one-sided difference is off by ~h κ' (cancelled to ~h² by Richardson
#: extrapolation from h and h/2), the polish's rounding adds ~1e-11/h².
GEODESIC_STEP = 1e-3


@dataclass
class Crossing:
    light: int
    point: np.ndarray
    kink_deg: float
    image_kink_deg: float
    seen: bool
    geodesic_jump: float = float("nan")  # |κg_A − κg_B|, 1/unit, the line oriented from A to B


def _geodesic_curvature(field: UlmetField, patch: int, uv: np.ndarray, tau: np.ndarray, n: np.ndarray,
                        c: float | np.ndarray, h: float) -> np.ndarray:
    """κg of the level line f = c through each (u, v) (c one per point, or one for all), for the line oriented along ``tau``.

    Two more points of the line are traced into the face (steps h and 2h in arc length along the line's
    (u, v) direction, each put back onto f = c by `UlmetField.polish`); with chord lengths h1, h2 the
    second derivative γ'' ≈ 2 ((Q2 − Q0)/h2 − (Q1 − Q0)/h1) / (h2 − h1), and κg = γ'' · (n × τ)
    (do Carmo 4-4: the geodesic curvature is the tangential part of the curvature vector).
    """
    surface = field.surfaces.patches[patch]
    (u0, u1), (v0, v1) = surface.domain
    fu, fv = _gradient_uv(field, patch, uv[:, 0], uv[:, 1])
    d = surface.evaluate(uv[:, 0], uv[:, 1])
    duv = np.stack([fv, -fu], axis=1)
    step3 = d.Su * duv[:, :1] + d.Sv * duv[:, 1:]
    # Into the face: the traced points must lie on this side.
    centre = np.array([0.5 * (u0 + u1), 0.5 * (v0 + v1)])
    duv *= np.where(np.sum(duv * (centre - uv), axis=1) >= 0, 1.0, -1.0)[:, None]
    duv *= (h / np.linalg.norm(step3, axis=1))[:, None]
    points = [surface.evaluate(uv[:, 0], uv[:, 1]).S]
    m = len(uv)
    for k in (1, 2):
        q = uv + k * duv
        q[:, 0] = np.clip(q[:, 0], u0, u1)
        q[:, 1] = np.clip(q[:, 1], v0, v1)
        u, v, ok = field.polish(np.full(m, patch), q[:, 0], q[:, 1], np.full(m, c), np.full(m, 0.5))
        S = surface.evaluate(u, v).S
        S[~ok] = np.nan
        points.append(S)
    Q0, Q1, Q2 = points
    h1 = np.linalg.norm(Q1 - Q0, axis=1)
    h2 = np.linalg.norm(Q2 - Q0, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):  # NaN where the line left the face (polish failed)
        gamma2 = 2.0 * ((Q2 - Q0) / h2[:, None] - (Q1 - Q0) / h1[:, None]) / (h2 - h1)[:, None]
    return np.einsum("ij,ij->i", gamma2, np.cross(n, tau))


def _gradient_uv(field: UlmetField, patch: int, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(∂f/∂u, ∂f/∂v) by (−3 f0 + 4 f1 − f2) / 2h, stepping towards the domain's centre."""
    surface = field.surfaces.patches[patch]
    (u0, u1), (v0, v1) = surface.domain
    hu = GRADIENT_STEP * (u1 - u0) * np.where(u < 0.5 * (u0 + u1), 1.0, -1.0)
    hv = GRADIENT_STEP * (v1 - v0) * np.where(v < 0.5 * (v0 + v1), 1.0, -1.0)
    n = len(u)
    p = np.full(5 * n, patch)
    f = field.f(p, np.concatenate([u, u + hu, u + 2 * hu, u, u]),
                np.concatenate([v, v, v, v + hv, v + 2 * hv])).reshape(5, n)
    fu = (-3 * f[0] + 4 * f[1] - f[2]) / (2 * hu)
    fv = (-3 * f[0] + 4 * f[3] - f[4]) / (2 * hv)
    return fu, fv


def _tangent(field: UlmetField, patch: int, uv: np.ndarray) -> np.ndarray:
    """3D direction of the level set of f through each (u, v): S_u f_v − S_v f_u."""
    fu, fv = _gradient_uv(field, patch, uv[:, 0], uv[:, 1])
    d = field.surfaces.patches[patch].evaluate(uv[:, 0], uv[:, 1])
    return d.Su * fv[:, None] - d.Sv * fu[:, None]


def seam_crossings(field: UlmetField, edge: EdgeReport, size: float) -> list[Crossing]:
    """Every crossing of a light line with the seam (G1 or better: f continuous), with its kink."""
    seam, s = edge.seam, edge.samples
    surfaces = field.surfaces.patches
    sa, sb = surfaces[seam.a.patch], surfaces[seam.b.patch]
    pa = seam.a.patch
    fA = field.f(np.full(len(s.t), pa), s.uv_a[:, 0], s.uv_a[:, 1])
    # Every light at once: one bracket per (light k, sample interval) where f − c_k changes sign, all bisected
    # together (one call per step for the whole seam, not one per light: the per-call cost dominated).
    c_all = np.asarray(field.lights.c_k, dtype=np.float64)
    r = fA[None, :] - c_all[:, None]
    kk, idx = np.nonzero(np.isfinite(r[:, :-1]) & np.isfinite(r[:, 1:]) & (np.sign(r[:, :-1]) * np.sign(r[:, 1:]) < 0))
    if len(idx) == 0:
        return []
    c = c_all[kk]
    lo, hi, r_lo = s.t[idx].copy(), s.t[idx + 1].copy(), r[kk, idx]
    for _ in range(CROSSING_STEPS):
        mid = 0.5 * (lo + hi)
        uv = curve(sa, seam.a, mid)[3]
        r_mid = field.f(np.full(len(mid), pa), uv[:, 0], uv[:, 1]) - c
        left = np.sign(r_mid) == np.sign(r_lo)
        lo, r_lo = np.where(left, mid, lo), np.where(left, r_mid, r_lo)
        hi = np.where(left, hi, mid)
    t = 0.5 * (lo + hi)
    P, _, _, uv_a, _ = curve(sa, seam.a, t)
    t_b, _ = match_points(sb, seam.b, P)
    uv_b = curve(sb, seam.b, t_b)[3]
    tau_a = _tangent(field, pa, uv_a)
    tau_b = _tangent(field, seam.b.patch, uv_b)
    # Across the seam from A to B: out of A (against w_A), into B (along w_B).
    w_a = np.interp(t, s.t, np.arange(len(s.t)))
    j = np.clip(np.round(w_a).astype(int), 0, len(s.t) - 1)
    tau_a *= np.where(np.einsum("ij,ij->i", tau_a, s.w_a[j]) > 0, -1.0, 1.0)[:, None]
    tau_b *= np.where(np.einsum("ij,ij->i", tau_b, s.w_b[j]) < 0, -1.0, 1.0)[:, None]
    kink = np.degrees(angle_between(tau_a, tau_b))
    cam = field.camera
    h = IMAGE_STEP * size
    x0 = cam.project(P)
    da = cam.project(P + h * tau_a / np.linalg.norm(tau_a, axis=1, keepdims=True)) - x0
    db = cam.project(P + h * tau_b / np.linalg.norm(tau_b, axis=1, keepdims=True)) - x0
    image = np.degrees(np.abs(np.arctan2(da[:, 0] * db[:, 1] - da[:, 1] * db[:, 0], np.sum(da * db, axis=1))))
    seen = field.seen(np.full(len(t), pa), uv_a[:, 0], uv_a[:, 1]) | field.seen(
        np.full(len(t), seam.b.patch), uv_b[:, 0], uv_b[:, 1])
    unit_a = tau_a / np.linalg.norm(tau_a, axis=1, keepdims=True)
    unit_b = tau_b / np.linalg.norm(tau_b, axis=1, keepdims=True)
    step = GEODESIC_STEP * size
    # Richardson: the one-sided estimate's O(h) error cancels in 2 κg(h/2) − κg(h).
    kg_a, kg_b = ((2.0 * _geodesic_curvature(field, p, uv, unit, n, c, 0.5 * step)
                   - _geodesic_curvature(field, p, uv, unit, n, c, step))
                  for p, uv, unit, n in ((pa, uv_a, unit_a, s.n_a[j]), (seam.b.patch, uv_b, unit_b, s.n_b[j])))
    jump = np.abs(kg_a - kg_b)
    return [Crossing(int(kk[i]), P[i], float(kink[i]), float(image[i]), bool(seen[i]), float(jump[i]))
            for i in range(len(t))]


def attach_line_kinks(field: UlmetField, edges: list[EdgeReport], size: float) -> None:
    """Fill each G1-or-better edge's line_kink_max_deg (on the surface) and line_kink_image_max_deg (in the image)
    over the crossings seen from the camera; G0 and open edges break the lines, their kink stays None."""
    for edge in edges:
        if edge.cls not in ("G1", "G2"):
            edge.extra["line_note"] = "normals jump: reflection lines break here (no kink to measure)"
            continue
        crossings = [c for c in seam_crossings(field, edge, size) if c.seen]
        edge.line_crossings = len(crossings)
        if crossings:
            edge.line_kink_max_deg = max(c.kink_deg for c in crossings)
            edge.line_kink_image_max_deg = max(c.image_kink_deg for c in crossings)
            jumps = [c.geodesic_jump for c in crossings if np.isfinite(c.geodesic_jump)]
            edge.extra["line_geodesic_jump_max"] = max(jumps) if jumps else None
