"""Tracing: from rays to exact surface hits (DESIGN.md, "Exact hit").

The BVH hit on the mesh gives a triangle and barycentrics, hence a starting
(u, v). Newton on S(u, v) = O + tD then moves the hit onto the true surface.
The ray condition is written as two equations across the ray,
e1·(S − O) = 0 and e2·(S − O) = 0 with e1, e2 ⊥ D, whose Jacobian is
[[e1·S_u, e1·S_v], [e2·S_u, e2·S_v]]; t = D·(S − O) follows. Where Newton fails
(grazing rays, degenerate points, silhouettes) the mesh hit is kept and flagged.
A refinement that runs off its patch's edge restarts once on the neighbouring patch
across the seam, where the exact hit then lies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .accelerator import Accelerator
from ..clock import NULL_CLOCK, StageClock
from ..geometry.surfaces import SurfaceDerivatives, SurfaceSet
from ..geometry.tessellation import Tessellation

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


@dataclass
class Hits:
    """Exact hits of N rays; rows where ``hit`` is False hold NaN (patch −1)."""

    hit: np.ndarray  # bool
    patch: np.ndarray  # int, −1 on a miss
    u: np.ndarray
    v: np.ndarray
    t: np.ndarray  # ray distance
    P: np.ndarray  # (N, 3) exact surface point S(u, v) (mesh point where Newton failed)
    N: np.ndarray  # (N, 3) exact unit normal, turned to face the incoming ray
    fallback: np.ndarray  # bool: Newton failed, mesh hit kept

    @classmethod
    def blank(cls, n: int, hit: np.ndarray) -> "Hits":
        """Rows for n rays flagged ``hit``, every value still that of a miss: to be filled in where hit."""
        return cls(hit, np.full(n, -1), np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan),
                   np.full((n, 3), np.nan), np.full((n, 3), np.nan), np.zeros(n, dtype=bool))


def facing(normals: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The normals turned to face the incoming rays, in place: the surface is a two-sided mirror."""
    normals[np.einsum("ij,ij->i", normals, directions) > 0] *= -1.0
    return normals


def _across(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors e1, e2 spanning the plane normal to each direction."""
    helper = np.zeros_like(directions)
    helper[np.arange(len(directions)), np.argmin(np.abs(directions), axis=1)] = 1.0
    e1 = np.cross(directions, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(directions, e1)


def refine(surfaces: SurfaceSet, patch, u, v, origins, directions, t_mesh, tolerance_distance):
    """Newton on S(u, v) = O + tD from the mesh hit.

    Returns (u, v, derivatives at the final (u, v), converged); the derivatives serve the normals.
    """
    u, v = u.copy(), v.copy()
    u0, u1, v0, v1 = surfaces.domains(patch)
    e1, e2 = _across(directions)
    magnitude = np.abs(origins + t_mesh[:, None] * directions).max(axis=1)  # |S| near the mesh hit
    tol = NEWTON_TOLERANCE * np.maximum(np.maximum(t_mesh, tolerance_distance), magnitude)
    converged = np.zeros(len(u), dtype=bool)
    singular = np.zeros(len(u), dtype=bool)
    active = np.arange(len(u))
    S, Su_all, Sv_all = (np.empty((len(u), 3)) for _ in range(3))
    for step in range(NEWTON_MAX_STEPS + 1):
        d = surfaces.evaluate(patch[active], u[active], v[active])
        S[active], Su_all[active], Sv_all[active] = d.S, d.Su, d.Sv
        rel = d.S - origins[active]
        r1 = np.einsum("ij,ij->i", e1[active], rel)
        r2 = np.einsum("ij,ij->i", e2[active], rel)
        done = np.hypot(r1, r2) <= tol[active]
        converged[active[done]] = True
        if step == NEWTON_MAX_STEPS:
            break
        keep = ~done
        active, r1, r2 = active[keep], r1[keep], r2[keep]
        if len(active) == 0:
            break
        Su, Sv = d.Su[keep], d.Sv[keep]
        a = np.einsum("ij,ij->i", e1[active], Su)
        b = np.einsum("ij,ij->i", e1[active], Sv)
        c = np.einsum("ij,ij->i", e2[active], Su)
        dd = np.einsum("ij,ij->i", e2[active], Sv)
        det = a * dd - b * c
        # det = D·(S_u × S_v): tiny at grazing rays and degenerate points, where Newton is not to be trusted.
        ok = np.abs(det) > 1e-12 * np.linalg.norm(Su, axis=1) * np.linalg.norm(Sv, axis=1)
        singular[active[~ok]] = True
        active, a, b, c, dd, det, r1, r2 = (x[ok] for x in (active, a, b, c, dd, det, r1, r2))
        u[active] = np.clip(u[active] - (dd * r1 - b * r2) / det, u0[active], u1[active])
        v[active] = np.clip(v[active] - (a * r2 - c * r1) / det, v0[active], v1[active])
    converged &= ~singular
    return u, v, SurfaceDerivatives(S, Su_all, Sv_all), converged


def _near_mesh_hit(derivs: SurfaceDerivatives, O, D, mesh_point, chord) -> tuple[np.ndarray, np.ndarray]:
    """Whether refined hits lie ahead and within reach of the mesh hit (not on another sheet), and their t = (S − O)·D."""
    S = derivs.S
    t = np.einsum("ij,ij->i", S - O, D)
    jump = np.linalg.norm(S - mesh_point, axis=1)
    near = jump <= JUMP_LIMIT * chord
    # The grazing allowance (≥ 1) only matters for the few hits beyond the plain limit: the normal only for those.
    far = np.flatnonzero(~near)
    if len(far):
        cross = np.cross(derivs.Su[far], derivs.Sv[far])
        with np.errstate(divide="ignore", invalid="ignore"):
            cos = np.abs(np.einsum("ij,ij->i", cross, D[far])) / np.linalg.norm(cross, axis=1)
        allowance = np.clip(np.nan_to_num(1.0 / cos, nan=1.0), 1.0, GRAZING_ALLOWANCE)
        near[far] = jump[far] <= JUMP_LIMIT * chord[far] * allowance
    return (t > 0) & near, t


def _on_domain_edge(surfaces: SurfaceSet, patch, u, v) -> np.ndarray:
    u0, u1, v0, v1 = surfaces.domains(patch)
    return (u == u0) | (u == u1) | (v == v0) | (v == v1)


def trace(accelerator: Accelerator, tessellation: Tessellation, surfaces: SurfaceSet,
          origins: np.ndarray, directions: np.ndarray, clock: StageClock = NULL_CLOCK) -> Hits:
    """Exact hits of rays (origins, unit directions), both (N, 3) float64."""
    n = len(origins)
    with clock.stage("intersect (Embree)"):
        mesh = accelerator.intersect(origins, directions)
    hits = Hits.blank(n, mesh.prim >= 0)
    patch, u, v, t, P, normal, fallback = hits.patch, hits.u, hits.v, hits.t, hits.P, hits.N, hits.fallback
    idx = np.flatnonzero(hits.hit)
    if len(idx):
        O, D, tm = origins[idx], directions[idx], mesh.t[idx]
        mesh_point = O + tm[:, None] * D
        pk, us, vs = tessellation.start_parameters(mesh.prim[idx], mesh.b1[idx], mesh.b2[idx])
        with clock.stage("newton (exact hit)"):
            ur, vr, derivs, ok = refine(surfaces, pk, us, vs, O, D, tm, tessellation.extent)
            near, tr = _near_mesh_hit(derivs, O, D, mesh_point, tessellation.chord_error[pk] + 1e-6 * tessellation.extent)
            ok &= near
            seam = np.flatnonzero(~ok & _on_domain_edge(surfaces, pk, ur, vr))
            if len(seam):
                pn, un, vn, gap = tessellation.across_seam(derivs.S[seam], pk[seam])
                # A neighbour shares the edge: its boundary vertex lies within a mesh edge of the point.
                near = (pn >= 0) & (gap <= 2.0 * tessellation.edge_length[pk[seam]])
                seam, pn, un, vn = (x[near] for x in (seam, pn, un, vn))
                u2, v2, d2, ok2 = refine(surfaces, pn, un, vn, O[seam], D[seam], tm[seam], tessellation.extent)
                near2, tr2 = _near_mesh_hit(d2, O[seam], D[seam], mesh_point[seam],
                                            tessellation.chord_error[pn] + 1e-6 * tessellation.extent)
                ok2 &= near2
                won = seam[ok2]
                pk[won], ur[won], vr[won], ok[won], tr[won] = pn[ok2], u2[ok2], v2[ok2], True, tr2[ok2]
                for have, new in zip(derivs[:3], d2[:3]):
                    have[won] = new[ok2]
        S = derivs.S
        patch[idx] = pk
        u[idx] = np.where(ok, ur, us)
        v[idx] = np.where(ok, vr, vs)
        t[idx] = np.where(ok, tr, tm)
        P[idx] = np.where(ok[:, None], S, mesh_point)
        with clock.stage("exact normals"):
            lost = np.flatnonzero(~ok)  # fallbacks: derivatives at the mesh hit's (u, v) instead
            if len(lost):
                again = surfaces.evaluate(pk[lost], us[lost], vs[lost])
                for have, new in zip(derivs[:3], again):
                    have[lost] = new
            normal[idx] = facing(surfaces.normals(pk, u[idx], v[idx], derivs), D)
        fallback[idx] = ~ok
    return hits
