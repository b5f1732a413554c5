"""Curvature from the first and second fundamental forms (do Carmo, sections 3-2 and 3-3).

With E = S_u·S_u, F = S_u·S_v, G = S_v·S_v and L = S_uu·n, M = S_uv·n, N = S_vv·n
(DESIGN.md, "Other interrogation modes"):

    K = (LN − M²)/(EG − F²)                       Gaussian curvature
    H = (EN − 2FM + GL)/(2(EG − F²))              mean curvature
    κ1,2 = H ± √(H² − K),  κ1 ≥ κ2                principal curvatures
    κ(w) = II(w, w)/I(w, w)                        normal curvature in the tangent direction w

Signs follow the normal n given: a curvature is positive where the surface bends towards n
(a bowl seen from the side n points to), so flipping n negates H, κ1, κ2 and κ(w) (and swaps
κ1 and κ2), while K keeps its sign. Units: 1/model unit. Rational surfaces need nothing extra:
S_uu, S_uv, S_vv of `NurbsSurface.evaluate(order=2)` are already those of the rational surface.
At a degenerate point (EG − F² = 0: a pole, a collapsed edge) the forms do not define the
curvature and the values are NaN.

The formulas live in one place, the compiled kernel (`kernels.nurbs.fundamental_forms_at`,
`curvature_of`); this module marshals arrays. `curvatures_at` fuses them with the order-2
evaluation, per point in registers (the renderer's K, H, k1, k2 AOVs).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..kernels import nurbs as kernel


class Curvatures(NamedTuple):
    """Gaussian K, mean H and principal κ1 ≥ κ2 at N points, in 1/model unit."""

    K: np.ndarray
    H: np.ndarray
    k1: np.ndarray
    k2: np.ndarray


def _f64(x: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64)


def curvatures(derivs, n: np.ndarray) -> Curvatures:
    """K, H, κ1, κ2 from `SurfaceDerivatives` of order 2 and unit normals n (N, 3) (module doc); NaN at degenerate points.

    The formulas are the kernel's (`kernels.nurbs.curvature_of`), point by point.
    """
    n = _f64(n).reshape(-1, 3)
    out = np.empty((4, n.shape[0]))
    kernel.curvatures(_f64(derivs.Su), _f64(derivs.Sv), _f64(derivs.Suu), _f64(derivs.Suv), _f64(derivs.Svv), n, out)
    return Curvatures(*out)


def curvatures_at(surfaces, patch: np.ndarray, u: np.ndarray, v: np.ndarray, n: np.ndarray) -> Curvatures:
    """K, H, κ1, κ2 at points (patch, u, v) of a `SurfaceSet` with unit normals n: `curvatures` of the order-2
    derivatives there, evaluated and reduced in one kernel pass (`kernels.nurbs.curvatures_at`). NaN where patch < 0."""
    patch = np.ascontiguousarray(patch, dtype=np.int64).ravel()
    out = np.empty((4, patch.shape[0]))
    kernel.curvatures_at(*surfaces.table.args, patch, _f64(u).ravel(), _f64(v).ravel(), _f64(n).reshape(-1, 3), out)
    return Curvatures(*out)


def normal_curvature(derivs, n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """κ(w) = II(w, w) / I(w, w) at each point, w a tangent vector written as a S_u + b S_v (do Carmo 3-2).

    By the kernel `kernels.nurbs.normal_curvatures`, from the same fundamental forms as `curvatures`.
    """
    n = _f64(n).reshape(-1, 3)
    out = np.empty(n.shape[0])
    kernel.normal_curvatures(_f64(derivs.Su), _f64(derivs.Sv), _f64(derivs.Suu), _f64(derivs.Suv), _f64(derivs.Svv),
                             n, _f64(w).reshape(-1, 3), out)
    return out
