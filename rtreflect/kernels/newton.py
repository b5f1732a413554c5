"""Compiled Newton iteration for the exact ray–surface hit (DESIGN.md, "Exact hit"; `trace.tracing.refine`).

Per ray, in registers: the ray condition S(u, v) = O + tD written as two equations across
the ray, r1 = e1·(S − O) = 0 and r2 = e2·(S − O) = 0 with e1, e2 ⊥ D, whose Jacobian is
J = [[e1·S_u, e1·S_v], [e2·S_u, e2·S_v]]; each step solves J (δu, δv) = (r1, r2) by Cramer's
rule and clamps (u, v) to the patch's domain. det J = D·(S_u × S_v), so a tiny determinant
marks a grazing ray or a degenerate point, where Newton is not to be trusted (singular).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import JIT

from .nurbs import new_scratch, across_at, point_at

#: A step is refused where |det J| <= this × |S_u| |S_v| (det J = D·(S_u × S_v), a sine of the incidence).
SINGULAR_SINE = 1e-12


@njit(**JIT)
def newton(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, max_degree,
           patch, u, v, O, D, tol, max_steps, S, Su, Sv, converged):
    """Newton from (u, v) in place for each ray; S, S_u, S_v at the final (u, v); converged per ray.

    A ray is converged once |(r1, r2)| <= tol[i], checked after each evaluation (at most
    max_steps steps, max_steps + 1 evaluations); a singular Jacobian or a non-finite step
    stops it unconverged.
    """
    scratch = new_scratch(max_degree)
    d = np.empty((6, 3))
    e = np.empty((2, 3))
    for i in range(patch.shape[0]):
        k = patch[i]
        across_at(D, i, e)
        u0, u1, v0, v1 = domain[k, 0], domain[k, 1], domain[k, 2], domain[k, 3]
        ui, vi = u[i], v[i]
        ok = False
        for step in range(max_steps + 1):
            point_at(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, k, ui, vi, 1, d,
                     scratch)
            r0, r1, r2 = d[0, 0] - O[i, 0], d[0, 1] - O[i, 1], d[0, 2] - O[i, 2]
            f1 = e[0, 0] * r0 + e[0, 1] * r1 + e[0, 2] * r2
            f2 = e[1, 0] * r0 + e[1, 1] * r1 + e[1, 2] * r2
            if math.hypot(f1, f2) <= tol[i]:
                ok = True
                break
            if step == max_steps:
                break
            a = e[0, 0] * d[1, 0] + e[0, 1] * d[1, 1] + e[0, 2] * d[1, 2]
            b = e[0, 0] * d[2, 0] + e[0, 1] * d[2, 1] + e[0, 2] * d[2, 2]
            c = e[1, 0] * d[1, 0] + e[1, 1] * d[1, 1] + e[1, 2] * d[1, 2]
            dd = e[1, 0] * d[2, 0] + e[1, 1] * d[2, 1] + e[1, 2] * d[2, 2]
            det = a * dd - b * c
            len_u = math.sqrt(d[1, 0] ** 2 + d[1, 1] ** 2 + d[1, 2] ** 2)
            len_v = math.sqrt(d[2, 0] ** 2 + d[2, 1] ** 2 + d[2, 2] ** 2)
            if not abs(det) > SINGULAR_SINE * len_u * len_v:
                break
            du = (dd * f1 - b * f2) / det
            dv = (a * f2 - c * f1) / det
            if not (math.isfinite(du) and math.isfinite(dv)):  # derivatives ~1e-296 pass the test, then overflow
                break
            ui = min(max(ui - du, u0), u1)
            vi = min(max(vi - dv, v0), v1)
        u[i], v[i] = ui, vi
        converged[i] = ok
        for c in range(3):
            S[i, c], Su[i, c], Sv[i, c] = d[0, c], d[1, c], d[2, c]
