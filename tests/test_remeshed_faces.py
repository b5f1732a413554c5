"""Faces whose parameterisation or control box overstates their size (issue 12 leftovers): the chord error measured
as the mesh-to-surface distance, and the trims of a re-meshed face sampled to the faces' own extent.

Parts are written at test time by tools/make_sweep_parts.py; references are Open CASCADE's own answers
(`GeomAPI_ProjectPointOnSurf`, `GeomAPI_ProjectPointOnCurve`) on the shape read by OCP directly.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

OCP = pytest.importorskip("OCP")
pytest.importorskip("shapely")

from rtreflect.exchange.cad import read_cad  # noqa: E402
from rtreflect.exchange.occt import TRIM_TOLERANCE  # noqa: E402
from rtreflect.geometry.tessellation import tessellate  # noqa: E402

from test_cad_reader import occt_faces  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import make_sweep_parts as sweep  # noqa: E402


def _part(tmp_path_factory, name: str):
    path = tmp_path_factory.mktemp("remeshed") / name
    sweep.PARTS[name](path)
    return path, read_cad(path)


def _occt_distances(surface, points: np.ndarray) -> np.ndarray:
    """Distances of points (N, 3) from an OCCT surface (`GeomAPI_ProjectPointOnSurf`, its nearest solution)."""
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.gp import gp_Pnt

    out = np.full(len(points), np.inf)
    for k, p in enumerate(points):
        projection = GeomAPI_ProjectPointOnSurf(gp_Pnt(*map(float, p)), surface)
        if projection.NbPoints():
            out[k] = projection.LowerDistance()
    return out


def test_chord_error_is_the_mesh_to_surface_distance_on_a_non_uniform_face(tmp_path_factory):
    """revolved_seam.step (a wavy profile revolved a full turn, its rational parameterisation far from uniform): the
    chord error read |S(ū) − chord midpoint| at each mesh edge's (u, v) midpoint ū, 6.3 mm, where OCCT's projection
    puts every chord midpoint and triangle centroid within ~0.3 mm of the surface (on a 138 mm part). Everything
    downstream scales with it (the second look's shell, reflected rays' start off the surface: 12.7 mm there). Now
    within 4× OCCT's largest distance, and never below it (the shell must enclose the surface)."""
    from OCP.BRep import BRep_Tool

    path, model = _part(tmp_path_factory, "revolved_seam.step")
    tessellation = tessellate(model.surfaces, 4)  # the reader's mesh as it is: no vertex moved off the surface
    mesh = tessellation.meshes[0]
    edges = mesh.edges_unique
    points = np.concatenate([mesh.vertices[edges].mean(axis=1), mesh.vertices[mesh.faces].mean(axis=1)])
    surface = BRep_Tool.Surface_s(occt_faces(path)[3][0])
    reference = _occt_distances(surface, points)
    # OCCT's projection can settle on a farther local solution: the nearest it finds over the samples is an upper bound
    # per point, and the mesh lies within our figure of the surface only if no OCCT answer that is right exceeds it.
    truth = np.max(np.minimum(reference, np.linalg.norm(model.surfaces[0].evaluate(
        *np.concatenate([mesh.uv[edges].mean(axis=1), mesh.uv[mesh.faces].mean(axis=1)]).T).S - points, axis=1)))
    chord = float(tessellation.chord_error[0])
    assert chord >= truth, (chord, truth)
    assert chord <= 4.0 * truth, (chord, truth)
