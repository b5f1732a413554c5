"""Trim loops of a CAD face in its surface's (u, v) parameter space, and the point-in-face test.

A trimmed face is the part of its (untrimmed) NURBS surface inside the **outer loop** and
inside no **hole** (DESIGN.md, CAD input). CAD readers (``rtreflect.exchange``) sample each
loop's pcurves into a closed polyline in (u, v) of the NURBS surface the face was converted to
(never of the original analytic surface: conversion moves the parameters).

The test is GEOS's prepared point-in-polygon (shapely, installed with the ``[cad]`` extra,
which is the only source of trimmed faces).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class Trim:
    """One face's loops: ``outer`` (n, 2) and ``holes`` (m_k, 2), closed polylines in (u, v).

    The last point of a loop need not repeat the first. ``u_period`` / ``v_period`` are set for
    a periodic direction whose loops were sampled in one period starting at ``u0`` / ``v0``:
    parameters are wrapped into ``[u0, u0 + period)`` before the test. ``edges``: the face's B-rep
    edges with their pcurves (`rtreflect.geometry.topology.FaceEdge`), when its reader knows them.
    """

    outer: np.ndarray
    holes: tuple[np.ndarray, ...] = ()
    u_period: float | None = None
    v_period: float | None = None
    u0: float = 0.0
    v0: float = 0.0
    edges: tuple = ()
    _polygon: object = field(init=False, repr=False)

    def __post_init__(self) -> None:
        import shapely

        polygon = shapely.Polygon(np.asarray(self.outer, dtype=np.float64),
                                  [np.asarray(h, dtype=np.float64) for h in self.holes])
        if not polygon.is_valid:
            polygon = shapely.make_valid(polygon)
        shapely.prepare(polygon)
        object.__setattr__(self, "_polygon", polygon)

    def wrap(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Periodic parameters moved into the period the loops were sampled in."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        if self.u_period:
            u = self.u0 + np.mod(u - self.u0, self.u_period)
        if self.v_period:
            v = self.v0 + np.mod(v - self.v0, self.v_period)
        return u, v

    def contains(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """True where (u, v) lies on the face: inside the outer loop and inside no hole (boundary counts as inside)."""
        import shapely

        u, v = self.wrap(u, v)
        return shapely.intersects_xy(self._polygon, u, v)
