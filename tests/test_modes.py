"""Interrogation modes (modes/): φ, levels and stripes per `[render] mode`, and the curvature channels.

Each mode's rendered φ and stripes are checked against a closed form on a shipped or inline
scene; the curvature channels against the quarter cylinder of radius 1 (κ = −1/r around the
axis for the normal facing the camera, 0 along it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rtreflect import load_scene, render

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"


def test_reflection_phi_is_ulmet_f_and_curvature_channels_match_the_cylinder():
    result = render(load_scene(SCENES / "cylinder.toml"), 96, 54, 1)
    hit = result.aov("A") > 0
    assert hit.sum() > 500
    f, phi = result.aov("f"), result.aov("phi")
    both = hit & np.isfinite(f)
    np.testing.assert_array_equal(phi[both], f[both])
    # Radius 1, N facing the camera = outward: the surface bends away from N around the axis.
    np.testing.assert_allclose(result.aov("k2")[hit], -1.0, atol=1e-5)
    np.testing.assert_allclose(result.aov("k1")[hit], 0.0, atol=1e-5)
    np.testing.assert_allclose(result.aov("H")[hit], -0.5, atol=1e-5)
    np.testing.assert_allclose(result.aov("K")[hit], 0.0, atol=1e-5)
    for name in ("phi", "K", "H", "k1", "k2"):
        assert np.isnan(result.aov(name)[~hit]).all(), name
