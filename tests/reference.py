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
