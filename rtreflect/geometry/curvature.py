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
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...j,...j->...", a, b)


class FundamentalForms(NamedTuple):
    """I = (E, F, G) and II = (L, M, N) at N points."""

    E: np.ndarray
    F: np.ndarray
    G: np.ndarray
    L: np.ndarray
    M: np.ndarray
    N: np.ndarray

    @property
    def det_first(self) -> np.ndarray:
        """EG − F² = |S_u × S_v|²."""
        return self.E * self.G - self.F * self.F


class Curvatures(NamedTuple):
    """Gaussian K, mean H and principal κ1 ≥ κ2 at N points, in 1/model unit."""

    K: np.ndarray
    H: np.ndarray
    k1: np.ndarray
    k2: np.ndarray


def fundamental_forms(derivs, n: np.ndarray) -> FundamentalForms:
    """E, F, G, L, M, N from `SurfaceDerivatives` of order 2 and unit normals n (N, 3)."""
    return FundamentalForms(_dot(derivs.Su, derivs.Su), _dot(derivs.Su, derivs.Sv), _dot(derivs.Sv, derivs.Sv),
                            _dot(derivs.Suu, n), _dot(derivs.Suv, n), _dot(derivs.Svv, n))


def curvatures(derivs, n: np.ndarray) -> Curvatures:
    """K, H, κ1, κ2 from the fundamental forms at each point (module doc); NaN at degenerate points."""
    f = fundamental_forms(derivs, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        det = np.where(f.det_first > 0, f.det_first, np.nan)
        K = (f.L * f.N - f.M * f.M) / det
        H = (f.E * f.N - 2.0 * f.F * f.M + f.G * f.L) / (2.0 * det)
    # H² − K = ((κ1 − κ2)/2)² ≥ 0; rounding makes it slightly negative at umbilics (a sphere): clamp.
    root = np.sqrt(np.maximum(H * H - K, 0.0))
    return Curvatures(K, H, H + root, H - root)


def normal_curvature(derivs, n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """κ(w) = II(w, w) / I(w, w) at each point, w a tangent vector written as a S_u + b S_v (do Carmo 3-2)."""
    f = fundamental_forms(derivs, n)
    wu, wv = _dot(w, derivs.Su), _dot(w, derivs.Sv)
    det = f.det_first
    a = (f.G * wu - f.F * wv) / det
    b = (f.E * wv - f.F * wu) / det
    first = f.E * a * a + 2.0 * f.F * a * b + f.G * b * b
    return (f.L * a * a + 2.0 * f.M * a * b + f.N * b * b) / first
