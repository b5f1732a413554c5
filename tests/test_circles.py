"""`[lights] shape = "circles"`: circular reflection and highlight lines (issue 15), against closed forms.

A plane mirror z = 0 under a light plane z = h with circles of radius r about C:
- reflection: the reflected ray from R is the line from the eye's mirror image E' = (E_x, E_y, −E_z)
  through R, which meets z = h at X = E' + λ (R − E'), λ = (h + E_z)/E_z. So |X − C| = r on the
  circle of radius r/λ about E' + (C − E')/λ in the mirror;
- highlight: the normal line is vertical, X = (R_x, R_y, h): the circle of radius r about C's foot.
Both are checked on the φ channel, on the analytic contours (`contours.ModeField`), and by validate.
Bad input: a centre off the plane, circles with a mode that does not see the plane, radii ≤ 0.
"""

from __future__ import annotations

import numpy as np
import pytest

from click.testing import CliRunner

from rtreflect import NurbsSurface, Scene, load_scene, render
from rtreflect.cli import cli
from rtreflect.analysis.contours import analytic_contours, field_of
from rtreflect.analysis.validate import validate_scene
from rtreflect.errors import SceneError
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer

H = 2.0
EYE = np.array([0.3, -2.4, 1.8])
CENTRE = np.array([0.2, 0.4, H])
RADII = [0.4, 0.8, 1.2, 1.6, 2.0, 2.4]


def mirror_scene(mode: str, **lights) -> Scene:
    mirror = NurbsSurface(1, 1, np.array([0.0, 0.0, 1.0, 1.0]), np.array([0.0, 0.0, 1.0, 1.0]),
                          np.array([[[-1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]], [[1.0, -1.0, 0.0], [1.0, 1.0, 0.0]]]),
                          np.ones((2, 2)), name="mirror")
    table = {"point": [0.0, 0.0, H], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0], "shape": "circles",
             "centre": CENTRE.tolist(), "positions": RADII, "radius": 0.02, **lights}
    return Scene(surfaces=[mirror], image={"width": 320, "height": 240, "samples": 1},
                 camera={"eye": EYE.tolist(), "look_at": [0.0, 0.0, 0.0], "fov": 45.0}, lights=table,
                 render={"mode": mode})


def closed_form(mode: str, R: np.ndarray) -> np.ndarray:
    """φ = |X − C| at mirror points R (module doc)."""
    if mode == "highlight":
        return np.linalg.norm(R[:, :2] - CENTRE[:2], axis=1)
    image = EYE * np.array([1.0, 1.0, -1.0])
    lam = (H + EYE[2]) / EYE[2]
    return lam * np.linalg.norm(R[:, :2] - (image + (CENTRE - image) / lam)[:2], axis=1)


@pytest.mark.parametrize("mode", ["reflection", "highlight"])
def test_circles_phi_contours_and_validate_match_the_closed_form(mode):
    scene = mirror_scene(mode)
    result = render(scene)
    hit = result.aov("A") > 0
    assert hit.sum() > 10000
    np.testing.assert_allclose(result.aov("phi")[hit], closed_form(mode, result.aov("P")[hit]), atol=1e-5)
    renderer = Renderer(resolve(scene))
    lines = analytic_contours(field_of(renderer)).lines
    assert [line.position for line in lines] == RADII
    for line in lines:
        for poly in line.polylines:
            S = renderer.surfaces.evaluate(np.full(len(poly.uv), poly.patch), poly.uv[:, 0], poly.uv[:, 1]).S
            np.testing.assert_allclose(closed_form(mode, S), line.position, atol=1e-9)
    assert sum(len(p.uv) for line in lines for p in line.polylines) > 300
    report = validate_scene(scene)
    assert report.passed, report.reasons
    assert report.points >= 300 and report.max_px <= 0.5 and report.p95_px <= 0.1
    assert report.colour_checked >= 500


def test_circles_lit_where_the_ray_meets_the_plane_within_the_ring():
    result = render(mirror_scene("reflection"))
    hit = result.aov("A") > 0
    lit = np.all(result.rgba[..., :3][hit] == 1.0, axis=1)  # one sample: the line colour exactly
    d = closed_form("reflection", result.aov("P")[hit])
    off = np.min(np.abs(d[:, None] - np.array(RADII)[None]), axis=1)
    assert lit.sum() > 200
    assert off[lit].max() <= 0.02 + 1e-6 and off[~lit].min() >= 0.02 - 1e-6


@pytest.mark.parametrize("change, field", [
    ({"centre": [0.0, 0.0, 2.5]}, "lights.centre"),
    ({"positions": [0.5, -1.0]}, "lights.positions"),
    ({"shape": "ovals"}, "lights.shape"),
    ({"length": 3.0}, "lights.length"),
])
def test_bad_circles_name_the_field(change, field):
    with pytest.raises(SceneError) as error:
        mirror_scene("reflection", **change)
    assert error.value.field == field and "\n" not in str(error.value)


MIRROR_TOML = """
[image]
width = 320
height = 240

[camera]
eye = [0.3, -2.4, 1.8]
look_at = [0.0, 0.0, 0.0]

[lights]
point = [0.0, 0.0, 2.0]
normal = [0.0, 0.0, 1.0]
direction = [0.0, 1.0, 0.0]
shape = "circles"
centre = [0.2, 0.4, 2.0]
spacing = 0.4
count = 6

[render]
mode = "highlight"

[[surface]]
degree = [1, 1]
knots_u = [0, 0, 1, 1]
knots_v = [0, 0, 1, 1]
points = [[[-1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]], [[1.0, -1.0, 0.0], [1.0, 1.0, 0.0]]]
"""


def test_init_writes_the_circles_keys_and_reads_back(tmp_path):
    source = tmp_path / "mirror.toml"
    source.write_text(MIRROR_TOML)
    scene = load_scene(source)
    assert scene.lights.positions.tolist() == pytest.approx([0.4, 0.8, 1.2, 1.6, 2.0, 2.4])  # spacing × 1..count
    result = CliRunner().invoke(cli, ["init", str(source)])
    assert result.exit_code == 0, result.output
    assert 'shape = "circles"' in result.output and "centre = [0.2, 0.4, 2.0]" in result.output
    again = tmp_path / "again.toml"
    again.write_text(result.output)
    back = load_scene(again).lights
    assert back.shape == "circles" and back.centre.tolist() == [0.2, 0.4, 2.0]
    assert back.positions.tolist() == pytest.approx(scene.lights.positions.tolist())


def test_circles_with_a_mode_that_does_not_see_the_plane_is_an_error():
    with pytest.raises(SceneError) as error:
        mirror_scene("isophote")
    assert error.value.field == "lights.shape"
    assert "isophote" in str(error.value)


def test_circles_get_no_tube_bank_warnings(tmp_path):
    """The tube-bank warnings (f past the bank, too few tubes drawn) count tubes: not said of circles."""
    source = tmp_path / "mirror.toml"
    source.write_text(MIRROR_TOML.replace('mode = "highlight"', 'mode = "reflection"'))
    result = CliRunner().invoke(cli, ["render", str(source), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert "warning" not in result.output
