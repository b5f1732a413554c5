"""Independent references for the tests: rhino3dm (OpenNURBS) surfaces and small geometric helpers."""

from __future__ import annotations

import numpy as np
import rhino3dm

from rtreflect.geometry.surfaces import NurbsSurface


def to_rhino(surface: NurbsSurface) -> rhino3dm.NurbsSurface:
    """The same surface in rhino3dm: homogeneous control points, knots without the two outermost."""
    nu, nv = surface.weights.shape
    rational = bool(np.any(surface.weights != 1.0))
    rh = rhino3dm.NurbsSurface.Create(3, rational, surface.degree_u + 1, surface.degree_v + 1, nu, nv)
    for i in range(nu):
        for j in range(nv):
            w = float(surface.weights[i, j])
            x, y, z = surface.points[i, j] * w  # rhino3dm takes homogeneous control points
            rh.Points[i, j] = rhino3dm.Point4d(x, y, z, w)
    # OpenNURBS leaves out the two outermost knots of the full clamped vector.
    for k, t in enumerate(surface.knots_u[1:-1]):
        rh.KnotsU[k] = float(t)
    for k, t in enumerate(surface.knots_v[1:-1]):
        rh.KnotsV[k] = float(t)
    assert rh.IsValid, "test set-up: rhino3dm rejects the converted surface"
    return rh


def xyz(p) -> np.ndarray:
    return np.array([p.X, p.Y, p.Z])


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between rows of a and b, accurate for tiny angles (unlike arccos of a dot)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("ij,ij->i", a, b))


def rhino_points_normals(surfaces, patch, u, v) -> tuple[np.ndarray, np.ndarray]:
    """rhino3dm's PointAt and NormalAt for each (patch, u, v)."""
    cache: dict[int, rhino3dm.NurbsSurface] = {}
    points, normals = [], []
    for k, uu, vv in zip(patch, u, v):
        rh = cache.setdefault(int(k), to_rhino(surfaces[int(k)]))
        points.append(xyz(rh.PointAt(float(uu), float(vv))))
        normals.append(xyz(rh.NormalAt(float(uu), float(vv))))
    return np.array(points), np.array(normals)


def closest_line_distance(R: np.ndarray, s: np.ndarray, B: np.ndarray, c: np.ndarray) -> tuple[float, float]:
    """Distance between the ray R + t s and the line B + τ c by least squares, and the ray's t there."""
    A = np.column_stack([s, -c])
    (t, tau), *_ = np.linalg.lstsq(A, B - R, rcond=None)
    return float(np.linalg.norm(R + t * s - (B + tau * c))), float(t)


def levenberg_marquardt(surfaces, patch, u, v, origins, directions, tol, steps, stationary_cosine, stalled_damping,
                        crawl_steps=0, crawl_gain=0.0):
    """The ray–surface distance search of `trace.tracing._rescue`, in numpy over all rays (its implementation before
    it was compiled), as the reference of the kernel `kernels.nurbs.rescue`.

    Levenberg–Marquardt on r = (e1·(S − O), e2·(S − O)), Marquardt's scaling (JᵀJ + λ diag JᵀJ), λ from
    1e-3, /3 on a step that lowers |r|, ×4 otherwise; stops undecided where ``crawl_steps`` accepted steps lowered
    |r| by less than the fraction ``crawl_gain`` (checked at the start and every crawl_steps-th accepted point).
    Returns (u, v, S, converged, stationary, edge, crawled).
    Dot products summed in coordinate order, as the kernel's.
    """
    def dot(a, b):
        return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]

    n = len(u)
    u, v = u.copy(), v.copy()
    dom = np.array([[*p.domain[0], *p.domain[1]] for p in surfaces.patches])[patch]
    u0, u1, v0, v1 = dom.T
    helper = np.eye(3)[np.argmin(np.abs(directions), axis=1)]  # the axis along D's smallest component
    e1 = np.cross(directions, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(directions, e1)
    lam = np.full(n, 1e-3)
    d = surfaces.evaluate(patch, u, v)
    S, Su, Sv = d.S.copy(), d.Su.copy(), d.Sv.copy()
    converged, stationary, crawled = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    accepted, fresh, mark = np.ones(n, dtype=int), np.ones(n, dtype=bool), np.zeros(n)
    active = np.arange(n)
    for _ in range(steps):
        rel = S[active] - origins[active]
        r1, r2 = dot(e1[active], rel), dot(e2[active], rel)
        a, b = dot(e1[active], Su[active]), dot(e1[active], Sv[active])
        c, dd = dot(e2[active], Su[active]), dot(e2[active], Sv[active])
        rn = np.hypot(r1, r2)
        done = rn <= tol[active]
        converged[active[done]] = True
        g1, g2 = a * r1 + c * r2, b * r1 + dd * r2
        with np.errstate(divide="ignore", invalid="ignore"):
            cosine = np.hypot(g1, g2) / (np.sqrt(a * a + b * b + c * c + dd * dd) * rn)
        flat = ~done & (~(cosine > stationary_cosine) | (lam[active] > stalled_damping))
        stationary[active[flat]] = True
        keep = ~done & ~flat
        if crawl_steps > 0:
            check = keep & fresh[active] & (accepted[active] % crawl_steps == 1 % crawl_steps)
            crawl = check & (accepted[active] > 1) & (rn > (1.0 - crawl_gain) * mark[active])
            crawled[active[crawl]] = True
            mark[active[check & ~crawl]] = rn[check & ~crawl]
            keep &= ~crawl
        fresh[active] = False
        active, a, b, c, dd, g1, g2, rn = (x[keep] for x in (active, a, b, c, dd, g1, g2, rn))
        if len(active) == 0:
            break
        A11, A12, A22 = a * a + c * c, a * b + c * dd, b * b + dd * dd
        M11, M22 = A11 * (1.0 + lam[active]), A22 * (1.0 + lam[active])
        det = M11 * M22 - A12 * A12
        with np.errstate(divide="ignore", invalid="ignore"):
            du, dv = -(M22 * g1 - A12 * g2) / det, -(M11 * g2 - A12 * g1) / det
        good = np.isfinite(du) & np.isfinite(dv)
        tu = np.clip(u[active] + np.where(good, du, 0.0), u0[active], u1[active])
        tv = np.clip(v[active] + np.where(good, dv, 0.0), v0[active], v1[active])
        trial = surfaces.evaluate(patch[active], tu, tv)
        rel = trial.S - origins[active]
        better = good & (np.hypot(dot(e1[active], rel), dot(e2[active], rel)) < rn)
        take = active[better]
        u[take], v[take] = tu[better], tv[better]
        S[take], Su[take], Sv[take] = trial.S[better], trial.Su[better], trial.Sv[better]
        accepted[take] += 1
        fresh[take] = True
        lam[active] = np.where(better, lam[active] / 3.0, lam[active] * 4.0)
    edge = ~converged & ((u == u0) | (u == u1) | (v == v0) | (v == v1))
    return u, v, S, converged, stationary & ~edge, edge, crawled
