"""Interrogation modes (modes/): φ, levels and stripes per `[render] mode`, and the curvature channels.

Each mode's rendered φ and stripes are checked against a closed form on a shipped or inline
scene; the curvature channels against the quarter cylinder of radius 1 (κ = −1/r around the
axis for the normal facing the camera, 0 along it).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from rtreflect import NurbsSurface, Scene, load_scene, render
from rtreflect.exchange.scene import RENDER_MODES
from rtreflect.geometry.surfaces import SurfaceSet
from rtreflect.modes.colormaps import DIVERGING, linear_rgb
from rtreflect.modes.curvaturemap import auto_range
from rtreflect.modes.draft import UNDERCUT_RGB
from rtreflect.modes.registry import MODES

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


SQRT_HALF = np.sqrt(0.5)
KNOTS2 = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]


def revolve(profile, degree: int) -> NurbsSurface:
    """A quarter turn about z of a profile [(x, z, w)] of the given degree (one Bézier span): u along it, v around z."""
    turn = [((1.0, 0.0), 1.0), ((1.0, 1.0), SQRT_HALF), ((0.0, 1.0), 1.0)]
    points = np.array([[[x * cx, x * cy, z] for (cx, cy), _ in turn] for x, z, _ in profile])
    weights = np.array([[w * wv for _, wv in turn] for _, _, w in profile])
    knots_u = [0.0] * (degree + 1) + [1.0] * (degree + 1)
    return NurbsSurface(degree, 2, np.array(knots_u), np.array(KNOTS2), points, weights)


def solid_scene(quarter: NurbsSurface, render_table: dict, lights: dict | None = None):
    """The four quarter turns of a surface of revolution about z, seen from the side and above."""
    turns = []
    for k in range(4):
        c, s = np.cos(k * np.pi / 2), np.sin(k * np.pi / 2)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        turns.append(NurbsSurface(quarter.degree_u, quarter.degree_v, quarter.knots_u, quarter.knots_v,
                                  quarter.points @ rot.T, quarter.weights, name=f"turn{k}"))
    lights = lights or {"point": [0.0, 0.0, 6.0], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0],
                        "spacing": 0.5, "count": 9, "radius": 0.05}
    return Scene(surfaces=turns, image={"width": 120, "height": 90, "samples": 1},
                 camera={"eye": [3.6, -4.3, 3.6], "look_at": [0.0, 0.0, 0.3], "fov": 35.0},
                 lights=lights, render=render_table)


def test_isophotes_of_a_sphere_are_circles_of_latitude_about_L():
    r = 1.5
    sphere = revolve([(r, 0.0, 1.0), (r, r, SQRT_HALF), (0.0, r, 1.0)], 2)  # upper hemisphere, rational
    L = np.array([1.0, -1.0, 2.0]) / np.sqrt(6.0)
    result = render(solid_scene(sphere, {"mode": "isophote", "light": L.tolist(), "step": 15.0}))
    hit = result.aov("A") > 0
    assert hit.sum() > 1500
    P, phi = result.aov("P")[hit], result.aov("phi")[hit]
    # The latitude about L of the point itself: the angle between its outward radius and L.
    latitude = np.degrees(np.arccos(np.clip(P @ L / np.linalg.norm(P, axis=1), -1, 1)))
    np.testing.assert_allclose(phi, latitude, atol=1e-3)
    # Lit pixels (one sample each: the line colour exactly) are those within 0.1 of a step of a circle every 15°.
    lit = np.all(result.rgba[..., :3][hit] == 1.0, axis=1)
    assert lit.sum() > 100
    off = np.abs(latitude - 15.0 * np.round(latitude / 15.0))
    assert off[lit].max() <= 1.5 + 1e-3 and off[~lit].min() >= 1.5 - 1e-3


def test_highlight_lines_of_a_cylinder_under_axis_parallel_tubes_are_straight_rulings():
    """Cylinder of radius 1 about y; tubes along y in the plane z = 3. The normal line at angle θ meets the
    plane at x = 3 cot θ, so tube c_k lights the ruling θ_k = atan2(3, c_k) whatever the eye."""
    result = render(load_scene(SCENES / "cylinder.toml").replace(render={"mode": "highlight"}), 160, 90, 1)
    hit = result.aov("A") > 0
    P, phi = result.aov("P")[hit], result.aov("phi")[hit]
    np.testing.assert_allclose(phi, 3.0 * P[:, 0] / P[:, 2], rtol=1e-6, atol=1e-6)
    scene = load_scene(SCENES / "cylinder.toml")
    c_k, radius = np.asarray(scene.lights.positions), scene.lights.radius
    lit = np.all(result.rgba[..., :3][hit] == 1.0, axis=1)  # one sample per pixel: the line colour exactly
    line = np.argmin(np.abs(3.0 * P[:, 0:1] / P[:, 2:3] - c_k[None, :]), axis=1)  # the tube the normal line nears
    assert len(np.unique(line[lit])) >= 4
    theta = np.arctan2(P[lit, 2], P[lit, 0])
    expected = np.arctan2(3.0, c_k[line[lit]])
    # Within the band: distance ≤ radius between the normal line and the tube, i.e. |Δθ| ≤ radius / distance ≈ 0.06/2.
    assert np.abs(theta - expected).max() < 0.04
    # ... and in the image each band is straight: the colour's lit pixels of one tube share one θ, any y.
    for k in np.unique(line[lit]):
        ys = P[lit][line[lit] == k, 1]
        assert np.ptp(ys) > 0.5  # the ruling runs along the cylinder


def outside(result) -> np.ndarray:
    """Pixels whose centre sees the outer side of a surface of revolution about z (N facing away from the axis)."""
    P, N = result.aov("P"), result.aov("N")
    return (result.aov("A") == 1) & (N[..., 0] * P[..., 0] + N[..., 1] * P[..., 1] > 0)


def test_draft_of_a_cone_is_90_minus_its_half_angle():
    alpha = 12.0
    base, height = 1.2, 1.0
    top = base - height * np.tan(np.radians(alpha))
    cone = revolve([(base, 0.0, 1.0), (top, height, 1.0)], 1)  # narrowing upwards: a drafted core, rational in v
    result = render(solid_scene(cone, {"mode": "draft", "pull": [0.0, 0.0, 1.0], "thresholds": [0.0, 5.0, 15.0]}))
    out = outside(result)
    assert out.sum() > 800
    np.testing.assert_allclose(result.aov("phi")[out], 90.0 - alpha, atol=1e-4)
    # δ = 12° lies in the band [5°, 15°): one colour over the whole outer side (float32 film).
    rgb = result.rgba[..., :3][out]
    assert np.ptp(rgb, axis=0).max() < 1e-6
    # The inside of the open cone, seen over its rim, faces the axis: φ = 90° + α, an undercut as seen.
    inner = (result.aov("A") == 1) & ~out
    assert inner.sum() > 100
    np.testing.assert_allclose(result.aov("phi")[inner], 90.0 + alpha, atol=1e-4)
    np.testing.assert_allclose(result.rgba[..., :3][inner], np.broadcast_to(UNDERCUT_RGB, (inner.sum(), 3)), atol=1e-6)


def test_draft_flags_the_undercut_of_a_cone_widening_upwards():
    cone = revolve([(1.0, 0.0, 1.0), (1.2, 1.0, 1.0)], 1)  # widening: the outer side hides from the pull
    result = render(solid_scene(cone, {"mode": "draft"}))
    out = outside(result)
    assert out.sum() > 500
    np.testing.assert_allclose(result.aov("phi")[out], 90.0 + np.degrees(np.arctan(0.2)), atol=1e-4)
    np.testing.assert_allclose(result.rgba[..., :3][out], np.broadcast_to(UNDERCUT_RGB, (out.sum(), 3)), atol=1e-6)


def test_curvature_map_of_a_sphere_is_one_colour_at_minus_one_over_r():
    r = 1.5
    sphere = revolve([(r, 0.0, 1.0), (r, r, SQRT_HALF), (0.0, r, 1.0)], 2)
    result = render(solid_scene(sphere, {"mode": "curvature", "quantity": "k1", "range": [-1.0, 1.0]}))
    full = result.aov("A") == 1
    np.testing.assert_allclose(result.aov("phi")[full], -1.0 / r, atol=1e-6)
    # The map at t = (−1/r + 1)/2 of the diverging map, on every full pixel.
    expected = linear_rgb(DIVERGING, np.array([(1.0 - 1.0 / r) / 2.0]))[0]
    np.testing.assert_allclose(result.rgba[..., :3][full], np.broadcast_to(expected, (full.sum(), 3)), atol=1e-6)


def test_modes_registry_matches_the_scene_reader():
    assert tuple(MODES) == RENDER_MODES


def test_map_modes_write_a_legend_with_numbers_and_units(tmp_path: Path):
    from click.testing import CliRunner

    from rtreflect.cli import cli

    scene = tmp_path / "hood_h.toml"
    text = (SCENES / "hood_curvature.toml").read_text().replace('range = "auto"', "range = [-0.4, 0.2]")
    scene.write_text(text)
    result = CliRunner().invoke(cli, ["render", str(scene), str(SCENES / "cup_draft.toml"), "-o", str(tmp_path / "out"),
                                      "--width", "64", "--height", "36", "--samples", "1"])
    assert result.exit_code == 0, result.output + result.stderr
    svg = (tmp_path / "out" / "hood_h.legend.svg").read_text()
    assert "mean curvature H (1/unit)" in svg and "fixed range" in svg
    ticks = [float(x) for x in re.findall(r">(-?[0-9.]+(?:e-?\d+)?)</text>", svg)]
    assert ticks == pytest.approx([0.2, 0.05, -0.1, -0.25, -0.4])
    # The bar's ends are the map's colours at the range's ends; the inner band edges are drawn (8 bands: 7 lines).
    assert svg.count('stroke="white"') == 7
    draft = (tmp_path / "out" / "cup_draft.legend.svg").read_text()
    assert all(label in draft for label in ("≥ 3°", "1° to 3°", "0° to 1°", "undercut"))
    assert not (tmp_path / "out" / "cup_draft.contours.json").exists()


def test_auto_range_is_symmetric_and_states_its_clipping():
    r = 1.5
    sphere = revolve([(r, 0.0, 1.0), (r, r, SQRT_HALF), (0.0, r, 1.0)], 2)
    low, high, clipped = auto_range("mean", SurfaceSet([sphere]))
    assert high == pytest.approx(1.0 / r, rel=1e-9) and low == -high  # |H| = 1/r everywhere
    assert clipped <= 0.021  # 98th percentile: at most ~2 % beyond it (rounding noise of a constant |H|)
    hood = load_scene(SCENES / "hood.toml")
    low, high, clipped = auto_range("gaussian", SurfaceSet(list(hood.surfaces)))
    assert low == -high and 0.0 < clipped <= 0.021


def test_zebra_is_the_limit_of_reflection_lines_of_tubes_at_infinity():
    """ψ = atan2(s·e, s·m) against Ulmet's f of the same scene with its light plane moved to height H: f/H → tan ψ
    (f = R·e + (H − R·m) tan ψ), a second formula through the renderer's reflection mode."""
    H = 1e4
    cylinder = load_scene(SCENES / "cylinder.toml")
    zebra = render(cylinder.replace(render={"mode": "zebra", "step": 5.0}), 96, 54, 1)
    far = render(cylinder.replace(lights={"point": [0.0, 0.0, H]}), 96, 54, 1)
    hit = zebra.aov("A") > 0
    f = far.aov("f")[hit]
    ahead = np.isfinite(f)
    assert ahead.sum() > 500
    psi = zebra.aov("phi")[hit][ahead]
    np.testing.assert_allclose(psi, np.degrees(np.arctan(f[ahead] / H)), atol=0.02)
    # Stripes every 5°, 1° wide (20 % of a step): lit exactly where ψ is within 0.5° of a multiple of 5°.
    off = np.abs(psi - 5.0 * np.round(psi / 5.0))
    lit = np.all(zebra.rgba[..., :3][hit][ahead] == 1.0, axis=1)
    assert lit.sum() > 50 and off[lit].max() <= 0.5 + 1e-4 and off[~lit].min() >= 0.5 - 1e-4


@pytest.mark.parametrize("scene, along_ray, field", [("hood.toml", True, "occlusion_t"), ("hood.toml", True, "level_t"),
                                                     ("cylinder_highlight.toml", False, "occlusion_t")])
def test_a_mode_breaking_the_along_ray_contract_is_refused(monkeypatch, scene, along_ray, field):
    """A mode seen along the reflected ray must give `Stripes.occlusion_t` (the sampled path's occlusion test: without
    it the stripes were lit with no occlusion test, silently) and `Stripes.level_t` (the analytic path's,
    `Renderer.centre_stripes`: without it a tile failed deep in the render); a mode seen where it is, neither (an
    occlusion_t would be tested by one path and not the other). The Renderer refuses such a mode when it is built."""
    from dataclasses import dataclass, replace

    from rtreflect.integrator.renderer import Renderer

    name = load_scene(SCENES / scene).render.mode
    build = MODES[name]

    @dataclass(frozen=True)
    class Broken:
        inner: object

        def __getattr__(self, attr):
            return getattr(self.inner, attr)

        def stripes(self, p):
            stripes = self.inner.stripes(p)
            return replace(stripes, **{field: None if along_ray else np.full(len(stripes.level_id), np.inf)})

    monkeypatch.setitem(MODES, name, lambda *args: Broken(build(*args)))
    with pytest.raises(TypeError, match=f"{field} is {'missing' if along_ray else 'given'}"):
        Renderer(load_scene(SCENES / scene))


def test_auto_range_of_a_curvature_that_is_zero_is_not_its_rounding():
    """K = 0 exactly on z = f(x) + g(y) with f piecewise linear (the sweep's kink.step: a degree 3 × 7 face with a C0
    crease): the auto range stays at `FLAT_RANGE` / size², so K's rounding (up to 9e-17, the whole range before) maps
    to the diverging map's middle on every pixel instead of full-range colour bands."""
    import math

    from rtreflect.modes.curvaturemap import FLAT_RANGE

    points = np.array([[(10.0 * i, 8.0 * j, 8.0 * abs(i - 3) / 3 + 3.0 * math.sin(j)) for j in range(8)]
                       for i in range(7)])
    knots_u, knots_v = np.array([0.0] * 4 + [0.5] * 3 + [1.0] * 4), np.array([0.0] * 8 + [1.0] * 8)
    kink = NurbsSurface(3, 7, knots_u, knots_v, points, np.ones(points.shape[:2]))
    scene = Scene(surfaces=[kink], image={"width": 96, "height": 54, "samples": 1},
                  camera={"eye": [30.0, -60.0, 70.0], "look_at": [30.0, 28.0, 3.0], "fov": 50.0},
                  render={"mode": "curvature", "quantity": "gaussian", "range": "auto", "bands": 0})
    low, high, _ = auto_range("gaussian", SurfaceSet([kink]))
    size = float(np.linalg.norm(np.ptp(points.reshape(-1, 3), axis=0)))
    assert high == pytest.approx(FLAT_RANGE / size**2, rel=1e-9) and low == -high
    result = render(scene)
    full = result.aov("A") == 1
    assert full.sum() > 500
    assert np.abs(result.aov("phi")[full]).max() < 1e-4 * high  # K is 0 to rounding
    # The map's middle on every pixel: between its entries just either side of t = 0.5.
    middle = linear_rgb(DIVERGING, np.array([0.499, 0.501]))
    rgb = result.rgba[..., :3][full]
    assert np.all((rgb >= middle.min(axis=0) - 1e-6) & (rgb <= middle.max(axis=0) + 1e-6))


def test_auto_range_of_max_curvature_on_a_sphere_is_not_the_rounding_at_its_umbilics():
    """max |κ| = 1/r on a sphere, but κ1,2 = H ± √(H² − K) round to ~√ε·H at an umbilic: over the 64 × 64 grid the
    sampled values spread over 2e-8 of 1/r (the sweep's sphere.3dm). The auto range was that spread, so the map drew
    the rounding as full-range colours and `validate` found lines' colours where none were (7 mismatches here, 398
    on sphere.3dm at 160×90). Now the range is [0, 2/r] (`UMBILIC_RANGE`): the sphere is a region at its middle level,
    drawn in the sequential map's middle colour, and validate passes."""
    from rtreflect.analysis.validate import validate_scene
    from rtreflect.integrator.autorig import resolve
    from rtreflect.integrator.renderer import Renderer
    from rtreflect.modes.colormaps import SEQUENTIAL

    r = 1.5
    sphere = revolve([(r, 0.0, 1.0), (r, r, SQRT_HALF), (0.0, r, 1.0)], 2)
    scene = solid_scene(sphere, {"mode": "curvature", "quantity": "maxabs", "bands": 8})
    mode = Renderer(resolve(scene)).mode
    assert mode.low == 0.0 and mode.high == pytest.approx(2.0 / r, rel=1e-7)
    assert mode.constant_faces.all()
    report = validate_scene(scene, threads=1)
    assert report.passed and report.colour_checked > 1000, (report.reasons, report.colour_mismatches)
    result = render(scene)
    full = result.aov("A") == 1
    np.testing.assert_allclose(result.aov("phi")[full], 1.0 / r, rtol=1e-6)
    # The map's middle on every pixel: between its entries just either side of t = 0.5 (φ is 1/r to rounding).
    middle = linear_rgb(SEQUENTIAL, np.array([0.499, 0.501]))
    rgb = result.rgba[..., :3][full]
    assert np.all((rgb >= middle.min(axis=0) - 1e-6) & (rgb <= middle.max(axis=0) + 1e-6))


def test_a_face_whose_curvature_is_zero_is_a_region_with_bands_at_the_flat_floor(tmp_path):
    """The sweep's kink.step (z = f(x) + g(y), f piecewise linear: K = 0 exactly) with bands: the range is the flat
    floor, ±`FLAT_RANGE`/size² = ±1.4e-12, and a line's half width (3.6e-14) put a thousandth of it below K's
    rounding (2.9e-16 over the face), so the face was not counted constant: it was one stripe of the line colour,
    and validate compared the rounding's sign changes (15.3 px off, 13 misses at 160×90). A face varying by less
    than the flat floor is a region now: drawn in the map's middle colour, and validate passes."""
    import sys

    from rtreflect.analysis.validate import validate_scene
    from rtreflect.integrator.autorig import resolve
    from rtreflect.integrator.renderer import Renderer

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / "kink.step"
    sweep.PARTS[path.name](path)
    scene = load_scene(path).replace(image={"width": 160, "height": 90, "samples": 1},
                                     render={"mode": "curvature", "quantity": "gaussian", "bands": 8})
    renderer = Renderer(resolve(scene))
    assert renderer.mode.constant_faces.all()
    result = renderer.render(None, 1)
    full = result.film.channel("A") == 1
    assert full.sum() > 500
    middle = linear_rgb(DIVERGING, np.array([0.499, 0.501]))
    rgb = result.rgba[..., :3][full]
    assert np.all((rgb >= middle.min(axis=0) - 1e-6) & (rgb <= middle.max(axis=0) + 1e-6))
    report = validate_scene(scene, threads=1, renderer=renderer)
    assert report.passed, report.reasons


def test_a_wall_drafted_exactly_at_a_threshold_is_one_colour(tmp_path):
    """A vertical wall under pull +z has δ = 0° exactly, computed as 0 ± 1e-14°: its samples fell either side of 0°,
    some flagged undercut red and some in the band [0°, 1°), a speckled wall (the sweep's huge_inch.step: 4 colour
    mismatches at 160×90 from its scene file). δ within `ON_THRESHOLD` of a threshold is on it: every pixel of every
    wall is the band above 0° (the closed form δ = 0), none red, validate passes, and δ = 1° ± 1e-12 is the band
    above 1° on both sides (the colour rule, which fails without the snap)."""
    import sys

    from rtreflect.analysis.validate import validate_scene
    from rtreflect.integrator.autorig import resolve
    from rtreflect.integrator.renderer import Renderer

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / "huge_inch.step"
    sweep.PARTS[path.name](path)
    scene = load_scene(path).replace(image={"width": 160, "height": 90},
                                     render={"mode": "draft", "pull": [0.0, 0.0, 1.0]})
    renderer = Renderer(resolve(scene))
    film = renderer.render(None, 1).film
    phi, patch = film.channel("phi"), film.channel("patch")
    inner = (film.channel("A") == 1) & (patch >= 0)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        inner &= np.roll(patch, (dy, dx), axis=(0, 1)) == patch
    wall = inner & (np.abs(phi - 90.0) < 1e-9)
    assert wall.sum() > 200
    expected = renderer.mode.colors(np.zeros(1))[0]
    assert not np.allclose(expected, UNDERCUT_RGB)
    np.testing.assert_allclose(film.pixels[..., :3][wall], np.broadcast_to(expected, (wall.sum(), 3)), atol=1e-6)
    report = validate_scene(scene, threads=1, renderer=renderer)
    assert report.passed and report.colour_mismatches == 0, report.reasons
    np.testing.assert_array_equal(renderer.mode.colors(np.array([1.0 - 1e-12, 1.0 + 1e-12])),
                                  renderer.mode.colors(np.array([1.0, 1.0])))
