"""The picture's look (issue 13): Lambert shading under the stripes, soft stripe edges (`blur`), their profile.

- `stripe_weight` against its closed form (the smoothstep over [r(1 − b), r(1 + b)]) and its
  properties: ½ at the radius and symmetric about it (the stripe keeps its width), 1 and 0
  beyond the ramp, C¹ at its ends, the hard tube of eq. (4) without blur, 0 where no tube is;
- a render at one sample per pixel (the sample is the pixel-centre ray, so the EXR's AOVs
  describe it) has, at every hit pixel, exactly the colour the closed form gives from those
  AOVs: w(line.dist)·line_color + (1 − w)·(½ + ½|N·D|)·surface_color, with D the camera's
  ray (DESIGN.md's camera formulas) and w the smoothstep written out here;
- ``shading = "flat"`` gives the unshaded surface colour; shading changes no AOV.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rtreflect.exchange.scene import load_scene
from rtreflect.integrator.renderer import Renderer
from rtreflect.modes.profile import stripe_weight

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def smoothstep_weight(d: np.ndarray, r: float, b: float) -> np.ndarray:
    """The profile written out: 1 below r(1 − b), 0 above r(1 + b), 3x² − 2x³ between, x = (r(1 + b) − d)/(2rb)."""
    x = (r * (1 + b) - d) / (2 * r * b)
    return np.where(d <= r * (1 - b), 1.0, np.where(d >= r * (1 + b), 0.0, 3 * x**2 - 2 * x**3))


@pytest.mark.parametrize("blur", [0.1, 0.5, 1.0])
def test_stripe_weight_is_the_smoothstep_about_the_radius(blur):
    r = 0.05
    d = np.linspace(0.0, 3 * r, 3001)
    w = stripe_weight(d, r, blur)
    np.testing.assert_allclose(w, smoothstep_weight(d, r, blur), atol=1e-12)
    assert stripe_weight(np.array([r]), r, blur)[0] == pytest.approx(0.5, abs=1e-12)
    x = np.linspace(0, r * blur, 101)
    np.testing.assert_allclose(stripe_weight(r - x, r, blur) + stripe_weight(r + x, r, blur), 1.0, atol=1e-12)
    assert np.all(np.diff(w) <= 1e-15)  # never brighter farther from the axis
    # C¹: the slope vanishes at both ends of the ramp (no edge of its own).
    h = 1e-7 * r
    for end in (r * (1 - blur) + h, r * (1 + blur) - h):
        slope = (stripe_weight(np.array([end + h]), r, blur) - stripe_weight(np.array([end - h]), r, blur)) / (2 * h)
        assert abs(slope[0]) < 1e-3 / r
    assert stripe_weight(np.array([np.nan]), r, blur)[0] == 0.0


def test_without_blur_the_weight_is_the_hard_tube():
    d = np.array([0.0, 0.049, 0.05, 0.0501, 1.0, np.nan])
    np.testing.assert_array_equal(stripe_weight(d, 0.05, 0.0), [1, 1, 1, 0, 0, 0])


def render_hood(**render):
    scene = load_scene(SCENES / "hood.toml").with_image(160, 90, 1).replace(render=render)
    renderer = Renderer(scene)
    return renderer, renderer.render()


@pytest.mark.parametrize("blur", [0.0, 0.6])
def test_shaded_render_is_the_closed_form_of_its_aovs(blur):
    renderer, result = render_hood(shading="lambert", blur=blur)
    settings = renderer.scene.render
    hit = result.aov("patch") >= 0
    rows, cols = np.nonzero(hit)
    _, D = renderer.camera.rays(rows, cols)
    N = result.aov("N")[hit].astype(np.float64)
    k = 0.5 + 0.5 * np.abs(np.einsum("ij,ij->i", N / np.linalg.norm(N, axis=1, keepdims=True), D))
    d = result.aov("line.dist")[hit].astype(np.float64)
    r = renderer.scene.lights.radius
    w = smoothstep_weight(np.nan_to_num(d, nan=np.inf), r, blur) if blur else (d <= r).astype(float)
    expected = w[:, None] * settings.line_color + (1 - w)[:, None] * k[:, None] * settings.surface_color
    rgb = result.rgba[hit][:, :3]
    # float32 storage of d: a pixel whose d lies within its rounding of a ramp end may differ by its slope.
    close = np.all(np.abs(rgb - expected) <= 1e-5, axis=1)
    assert close.mean() >= 0.999, (close.size - close.sum(), np.abs(rgb - expected).max())
    assert (w > 0).sum() >= 200 and ((w > 0) & (w < 1)).sum() >= (150 if blur else 0), ((w > 0).sum(), ((w > 0) & (w < 1)).sum())
    # Shading is visible: the surface's shade spans a range, never below the ambient half.
    assert k.min() >= 0.5 and np.ptp(k[w == 0]) > 0.1


def test_flat_shading_is_the_surface_colour_and_shading_leaves_the_aovs():
    _, flat = render_hood(shading="flat")
    _, lambert = render_hood(shading="lambert", blur=0.5)
    hit = flat.aov("patch") >= 0
    unlit = hit & ~(flat.aov("line.dist") <= 0.05 * 1.5)
    np.testing.assert_array_equal(flat.rgba[unlit][:, :3], np.broadcast_to(
        np.float32(load_scene(SCENES / "hood.toml").render.surface_color), (unlit.sum(), 3)))
    assert unlit.sum() >= 1000
    np.testing.assert_array_equal(flat.film.pixels[..., 3:], lambert.film.pixels[..., 3:])  # A and every AOV
    assert not np.array_equal(flat.rgba[..., :3], lambert.rgba[..., :3])


# -- the overlay at 100 %: its width, and NAME.side.png -------------------------------------------


@pytest.mark.parametrize("width", [1.0, 2.0, 3.0, 4.5])
def test_overlay_line_covers_its_width(width):
    """A straight line's coverage summed across it is its width (the box filter's area per unit length)."""
    from rtreflect.analysis.contours import ContourLine, ContourLines, Polyline
    from rtreflect.analysis.overlay import coverage

    for a, b, axis in (([2.0, 20.3], [38.0, 20.3], 0), ([20.7, 2.0], [20.7, 38.0], 1)):
        px = np.array([a, b])
        lines = ContourLines(40, 40, [ContourLine(0, 0.0, [Polyline(0, np.zeros((2, 2)), px)])])
        across = coverage(lines, 40, 40, width).sum(axis=axis)
        np.testing.assert_allclose(across[8:32], width, atol=1e-9)


def render_cli(tmp_path: Path, name: str, *options: str, scene: Path = SCENES / "hood.toml") -> Path:
    from click.testing import CliRunner

    from rtreflect.cli import cli

    result = CliRunner().invoke(cli, ["render", *options, str(scene), "-o", str(tmp_path / name), "--width", "160",
                                      "--height", "90", "--samples", "1"])
    assert result.exit_code == 0, result.output
    return tmp_path / name


def test_side_overlay_keeps_the_png_plain_and_puts_both_pictures_side_by_side(tmp_path):
    from rtreflect.output.imagefiles import read_image

    plain = render_cli(tmp_path, "plain")
    drawn = render_cli(tmp_path, "drawn", "--overlay")  # the flag still comes before the scene
    side = render_cli(tmp_path, "side", "--overlay=side")
    assert sorted(p.name for p in side.iterdir()) == ["hood.contours.json", "hood.exr", "hood.png", "hood.side.png"]
    picture = read_image(plain / "hood.png")[0]
    overlaid = read_image(drawn / "hood.png")[0]
    both = read_image(side / "hood.side.png")[0]
    np.testing.assert_array_equal(read_image(side / "hood.png")[0], picture)
    assert both.shape == (90, 320, 4)
    np.testing.assert_array_equal(both[:, :160], picture)
    np.testing.assert_array_equal(both[:, 160:], overlaid)
    assert np.any(overlaid != picture)


def test_overlay_width_is_the_scenes(tmp_path):
    from rtreflect.output.imagefiles import read_image

    plain = read_image(render_cli(tmp_path, "plain") / "hood.png")[0]
    changed = {}
    for width in (2.0, 4.0):
        scene = tmp_path / f"hood{width:g}.toml"
        scene.write_text((SCENES / "hood.toml").read_text().replace("[render]\n", f"[render]\noverlay_width = {width}\n"))
        png = read_image(render_cli(tmp_path, f"w{width:g}", "--overlay", scene=scene) / f"hood{width:g}.png")[0]
        changed[width] = int(np.count_nonzero(np.any(png != plain, axis=2)))
    # A line of width w touches about w + 1 pixels across: 5/3 as many at 4 px as at 2, less where lines crowd.
    assert 1.25 * changed[2.0] < changed[4.0] < 2.0 * changed[2.0], changed
