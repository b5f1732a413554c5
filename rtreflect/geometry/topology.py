"""B-rep topology carried from a CAD reader to the seam finder: which faces share which edge, and where.

In a B-rep (Open CASCADE's TopoDS, Rhino's Brep) two faces that meet share one EDGE: one 3D
curve C(t), and on each face a pcurve γ(t) in that face's (u, v) with S(γ(t)) = C(t) to the
edge's tolerance, over the **same** parameter t (OCCT's SameParameter property). So the seam
between them is known exactly and completely, with no geometric matching: at every t the two
sides' points are S_A(γ_A(t)) and S_B(γ_B(t)).

A reader records, per face, one `FaceEdge` per edge it uses: the edge's key (unique across
every file of a scene), the common parameters t, and the face's pcurve sampled at them (the
same t on every face of the edge, so sample i of one side is sample i of the other). A seam
edge of a periodic face (the same edge used twice by one face) and a degenerate edge (a pole)
are recorded with their flags and are no seam between faces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class FaceEdge:
    """One B-rep edge as face ``(the face carrying this record)`` sees it.

    ``key``: the edge's identity, equal on every face that shares it (and distinct across files and
    instances). ``t`` (m,): the edge's parameters, increasing, the same array on each face of the edge.
    ``uv`` (m, 2): the face's pcurve γ(t) at them, exact (read from the pcurve, not interpolated);
    ``duv`` (m, 2): γ'(t), the pcurve's tangent. ``length``: the edge's 3D arc length.
    ``closed``: the edge is a seam of this face (used twice by it: both sides of a periodic surface's
    seam line); ``degenerated``: the edge collapses to a point (a pole).
    """

    key: str
    t: np.ndarray
    uv: np.ndarray
    duv: np.ndarray
    length: float
    closed: bool = False
    degenerated: bool = False


def shared_edges(faces_edges: list[tuple[FaceEdge, ...]]) -> list[tuple[str, int, int]]:
    """(key, face A, face B) for every edge two different faces share, each pair once, A < B, in first-seen order.

    ``faces_edges[k]`` is face k's records. An edge used twice by one face (a periodic seam) pairs that
    face with no other; a degenerate edge shares nothing. An edge on more than two faces (non-manifold)
    gives every pair of them.
    """
    users: dict[str, list[int]] = {}
    for face, edges in enumerate(faces_edges):
        for edge in edges:
            if edge.degenerated:
                continue
            faces = users.setdefault(edge.key, [])
            if face not in faces:
                faces.append(face)
    pairs = []
    for key, faces in users.items():
        for i, a in enumerate(faces):
            for b in faces[i + 1:]:
                pairs.append((key, min(a, b), max(a, b)))
    return pairs


def edge_record(edges: tuple[FaceEdge, ...], key: str) -> FaceEdge:
    """The record of edge ``key`` among a face's ``edges`` (its first use, for a seam used twice)."""
    return next(e for e in edges if e.key == key)


__all__ = ["FaceEdge", "shared_edges", "edge_record"]
