"""Zebra's parallax (issue 15): environment-mapped stripes against the reflection lines of physical tubes, in pixels.

Closed form on a plane mirror z = 0 (centre O at the origin) with the eye E, the light plane
z = h through Q = (0, 0, h), tubes along y (so e = x): the reflected ray from R runs from the
eye's mirror image E' = (E_x, E_y, −E_z) through R. Zebra's line ψ = ψ_k is where
(R − E')·e / (R − E')·m = tan ψ_k: the straight line x = E_x + E_z tan ψ_k. The equivalent tube,
where the direction ψ_k from O meets the plane, is c_k = h tan ψ_k; its reflection line is where
the ray meets the plane at x = c_k: x = E_x + (c_k − E_x)/λ with λ = (h + E_z)/E_z. The parallax is
the pixel distance between the two lines' images, measured here with the camera alone.
"""

from __future__ import annotations

import numpy as np

from rtreflect import NurbsSurface, Scene
from rtreflect.analysis.validate import nearest_segment, validate_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer

EYE = np.array([0.3, -2.4, 1.8])


def zebra_mirror(h: float) -> Scene:
    mirror = NurbsSurface(1, 1, np.array([0.0, 0.0, 1.0, 1.0]), np.array([0.0, 0.0, 1.0, 1.0]),
                          np.array([[[-1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]], [[1.0, -1.0, 0.0], [1.0, 1.0, 0.0]]]),
                          np.ones((2, 2)), name="mirror")
    return Scene(surfaces=[mirror], image={"width": 320, "height": 240, "samples": 1},
                 camera={"eye": EYE.tolist(), "look_at": [0.0, 0.0, 0.0], "fov": 45.0},
                 lights={"point": [0.0, 0.0, h], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0],
                         "spacing": 0.5, "count": 5, "radius": 0.02},
                 render={"mode": "zebra", "step": 6.0})


def test_zebra_parallax_on_a_plane_mirror_is_the_closed_form():
    h = 2.0
    scene = zebra_mirror(h)
    report = validate_scene(scene)
    assert report.passed, report.reasons
    camera = Renderer(resolve(scene)).camera
    lam = (h + EYE[2]) / EYE[2]
    measured = [line for line in report.parallax["lines"] if line["points"]]
    assert len(measured) >= 5
    zebra = {line.position: line for line in report.contours.lines}
    for line in measured:
        psi = np.radians(line["level"])
        np.testing.assert_allclose(line["tube"], h * np.tan(psi), atol=1e-12)
        x_zebra = EYE[0] + EYE[2] * np.tan(psi)
        x_tube = EYE[0] + (h * np.tan(psi) - EYE[0]) / lam
        pts = np.concatenate([p.px for p in zebra[line["level"]].polylines])
        # The zebra contour is the line x = x_zebra in the mirror ...
        ends = camera.project(np.array([[x_zebra, -1.0, 0.0], [x_zebra, 1.0, 0.0]]))
        on_zebra, _ = nearest_segment(pts, ends[:1], ends[1:], 1e3)
        assert on_zebra.max() < 1e-6
        # ... and its parallax the distance to the image of the tube's line x = x_tube.
        ends = camera.project(np.array([[x_tube, -1.0, 0.0], [x_tube, 1.0, 0.0]]))
        expected, _ = nearest_segment(pts, ends[:1], ends[1:], 1e3)
        assert line["points"] == len(pts) and line["unmatched"] == 0
        np.testing.assert_allclose([line["max_px"], line["mean_px"]], [expected.max(), expected.mean()], atol=1e-6)
    assert report.parallax["max_px"] > 1.0  # a light plane 2 above the part: visible parallax


def test_zebra_parallax_vanishes_as_the_tubes_recede():
    near = validate_scene(zebra_mirror(2.0)).parallax
    far = validate_scene(zebra_mirror(2000.0)).parallax
    assert far["points"] > 100 and far["max_px"] < 0.01 * near["max_px"]
