"""New kinds of CAD parts from the second adversarial sweep (issue 12), each a fault the sweep found.

Parts are written at test time by tools/make_sweep_parts.py; references are Open CASCADE's own answers
on the shape read by OCP directly (tests/test_cad_reader.py's `occt_faces`).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

OCP = pytest.importorskip("OCP")
pytest.importorskip("shapely")

from rtreflect.exchange.cad import read_cad  # noqa: E402

from test_cad_reader import ORIGINAL_TOLERANCE, occt_faces  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import make_sweep_parts as sweep  # noqa: E402


def test_periodic_face_cut_one_period_on_keeps_its_pcurves_parameters(tmp_path):
    """union_big.step (the fused cylinders and sphere at 10 m): the crossing cylinder's pcurves run from -1.8e-9 to
    2π, and OCCT's `Segment` of the periodic surface from there returned the knots 2π..4π. The trims and mesh
    (u, v), taken from the pcurves, lay one period before the surface's domain: the cylinder rendered as a sliver
    and the vertical cylinder not at all (validate: 12.9 px off; 65 of 300 sampled pixels hit a face 4,600 mm
    behind OCCT's first hit). At every trim-loop and mesh (u, v) our surface is OCCT's face surface there."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface

    path = tmp_path / "union_big.step"
    sweep.PARTS[path.name](path)
    model = read_cad(path)
    _, _, _, faces = occt_faces(path)
    for k, (surface, face) in enumerate(zip(model.surfaces, faces)):
        adaptor = BRepAdaptor_Surface(face)
        uv = np.concatenate([surface.trim.outer, *surface.trim.holes, surface.mesh_uv[0]])
        (u0, u1), (v0, v1) = surface.domain
        slack = 1e-6 * (u1 - u0)  # the pcurves pass the surface's bounds by OCCT's tolerances only
        assert np.all((uv[:, 0] >= u0 - slack) & (uv[:, 0] <= u1 + slack)), (k, surface.domain, uv[:, 0].min(), uv[:, 0].max())
        ours = surface.evaluate(uv[:, 0], uv[:, 1]).S
        reference = np.array([[p.X(), p.Y(), p.Z()] for p in (adaptor.Value(float(u), float(v)) for u, v in uv)])
        # Not float rounding (test_cad_reader's 1e-11): the pcurves end 1.8e-9 past the cut surface (OCCT's tolerance),
        # so the end points are 2.5e-6 mm off on the 1.4 m cylinder.
        assert np.max(np.linalg.norm(ours - reference, axis=1)) <= ORIGINAL_TOLERANCE * model.diagonal, k
