"""validate and the overlay for the other line-drawing modes (issue 15): each mode's own lines, φ = c_k.

- the analytic contours of a mode's φ (`contours.ModeField`) are checked against closed forms:
  isophotes of a sphere are circles of latitude about L, highlight lines of a cylinder under
  axis-parallel tubes are the rulings x/z = c_k/3;
- a render whose φ is shifted by 30 % of a level step (lines drawn and stored at the wrong
  place) fails validation for every mode: the check can fail. (The shipped mode scenes
  passing is tests/test_validate.py's test_shipped_scene_validates.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rtreflect import load_scene
from rtreflect.analysis.contours import ModeField, analytic_contours, field_of
from rtreflect.analysis.validate import DEFAULT_TOLERANCE_PX, compare, film_aovs, mode_aovs, validate_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.modes.profile import stripe_weight

from test_modes import SQRT_HALF, revolve, solid_scene

SCENES = Path(__file__).resolve().parent.parent / "scenes"
#: The shipped scene of each line-drawing mode but reflection, and the size it is checked at (test_validate's SIZES).
MODE_SCENES = {"isophote": ("g1_join_isophote", (320, 180)), "highlight": ("cylinder_highlight", (320, 180)),
               "zebra": ("hood_zebra", (320, 180)), "draft": ("cup_draft", (480, 270)),
               "curvature": ("hood_curvature", (320, 180))}
#: The wrong render's shift of φ, as a share of the levels' smallest gap: far beyond the tolerances.
SHIFT = 0.3


def contour_points(renderer: Renderer):
    """(level c_k, S(u, v)) of every analytic contour vertex of the renderer's mode."""
    field = field_of(renderer)
    assert isinstance(field, ModeField)
    lines = analytic_contours(field).lines
    levels, points = [], []
    for line in lines:
        for poly in line.polylines:
            S = renderer.surfaces.evaluate(np.full(len(poly.uv), poly.patch), poly.uv[:, 0], poly.uv[:, 1]).S
            levels.append(np.full(len(S), line.position))
            points.append(S)
    return np.concatenate(levels), np.concatenate(points)


def test_isophote_contours_of_a_sphere_are_circles_of_latitude_about_L():
    r = 1.5
    sphere = revolve([(r, 0.0, 1.0), (r, r, SQRT_HALF), (0.0, r, 1.0)], 2)  # upper hemisphere, rational
    L = np.array([1.0, -1.0, 2.0]) / np.sqrt(6.0)
    scene = solid_scene(sphere, {"mode": "isophote", "light": L.tolist(), "step": 15.0}).replace(
        image={"width": 320, "height": 240})
    c, P = contour_points(Renderer(resolve(scene)))
    assert len(np.unique(c)) >= 5 and len(c) > 500
    latitude = np.degrees(np.arccos(np.clip(P @ L / np.linalg.norm(P, axis=1), -1, 1)))
    np.testing.assert_allclose(latitude, c, atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(P, axis=1), r, atol=1e-9)


def test_highlight_contours_of_a_cylinder_are_its_rulings():
    """Cylinder of radius 1 about y, tubes along y in z = 3: the normal line at (x, z) meets the plane at 3x/z."""
    scene = load_scene(SCENES / "cylinder.toml").replace(render={"mode": "highlight"}).with_image(320, 180, 1)
    c, P = contour_points(Renderer(resolve(scene)))
    assert len(np.unique(c)) >= 4 and len(c) > 200
    np.testing.assert_allclose(3.0 * P[:, 0] / P[:, 2], c, atol=1e-9)


@pytest.mark.parametrize("mode", sorted(MODE_SCENES))
def test_lines_at_shifted_levels_fail_validation(mode, monkeypatch):
    stem, size = MODE_SCENES[mode]
    scene = load_scene(SCENES / f"{stem}.toml").with_image(*size, 1)
    renderer = Renderer(resolve(scene))
    assert renderer.mode.name == mode
    levels = np.unique(np.asarray(renderer.mode.levels, dtype=np.float64))
    shift = SHIFT * float(np.diff(levels).min())
    kind = type(renderer.mode)
    true_phi = kind.phi
    with monkeypatch.context() as m:  # the render (its colour and its phi channel) at the wrong φ
        m.setattr(kind, "phi", lambda self, p: true_phi(self, p) + shift)
        film = renderer.render().film
    # The analytic side sees the true φ.
    report = compare(renderer, mode_aovs(renderer, film, film_aovs(renderer, film)),
                     analytic_contours(field_of(renderer)), DEFAULT_TOLERANCE_PX)
    assert not report.passed
    assert (report.max_px or 0.0) > DEFAULT_TOLERANCE_PX or report.misses > 0


def test_validate_names_no_fallback_to_reflection_lines():
    """A mode scene's report is about its own levels (the isophotes every `step` degrees), not the tubes' positions."""
    scene = load_scene(SCENES / "g1_join_isophote.toml").with_image(320, 180, 1)
    report = validate_scene(scene)
    assert report.passed, report.reasons
    step = scene.render.step
    assert [line.position for line in report.lines] == pytest.approx(np.arange(0.0, 180.0 + step / 2, step).tolist())
    assert not any("reflection lines" in note for note in report.notes)


@pytest.mark.parametrize("mode", ["isophote", "curvature"])
def test_blur_softens_every_modes_stripes_and_validate_checks_it(mode):
    """`[render] blur` about each mode's half width (a line mode and a map mode): with one sample per pixel (the
    pixel centre) each pixel's line share is the profile's weight of the mode's distance to its level there, soft
    edges included, and the render validates."""
    stem, size = MODE_SCENES[mode]
    scene = load_scene(SCENES / f"{stem}.toml").with_image(*size, 1).replace(render={"blur": 0.5})
    renderer = Renderer(resolve(scene))
    assert renderer.soft_stripes
    film = renderer.render().film
    aovs = mode_aovs(renderer, film, film_aovs(renderer, film))
    inside = (aovs.coverage == 1) & np.isfinite(aovs.line_coverage)
    share = aovs.line_coverage[inside]
    assert np.count_nonzero((share > 0.05) & (share < 0.95)) > 100  # the soft edges
    expected = stripe_weight(aovs.line_dist[inside], renderer.mode.half_width, 0.5)
    np.testing.assert_allclose(share, expected, atol=1e-3)  # float32 colour
    report = compare(renderer, aovs, analytic_contours(field_of(renderer)), DEFAULT_TOLERANCE_PX)
    assert report.passed and report.colour_checked > 1000, report.reasons


def test_colour_check_takes_the_slope_of_the_signed_offset_across_a_crease():
    """The hood's mean curvature has a crease along each inner knot line (a bicubic is C² there: H is C⁰).
    At 480×270 a level of H runs beside the crease, where the pixels on either side of the level's centre
    have nearly equal |σ| but far apart σ: the colour check must take the pixel's slope from σ, or it
    expects a full line where the crease's own sliver leaves part of the pixel unlit (4 pixels failed)."""
    scene = resolve(load_scene(SCENES / "hood_curvature.toml").with_image(480, 270, "analytic"))
    renderer = Renderer(scene)
    film = renderer.render().film
    aovs = mode_aovs(renderer, film, film_aovs(renderer, film))
    hit = aovs.line_id >= 0
    # line.dist is |σ| of the same level, and σ changes sign between some neighbours (the folds the check meets)
    np.testing.assert_allclose(np.abs(aovs.line_offset[hit]), aovs.line_dist[hit], rtol=0, atol=1e-12)
    assert np.any(np.sign(aovs.line_offset[:, 1:]) * np.sign(aovs.line_offset[:, :-1]) < 0)
    report = compare(renderer, aovs, analytic_contours(field_of(renderer)), DEFAULT_TOLERANCE_PX)
    assert report.colour_mismatches == 0 and report.passed


def test_zebra_lines_next_to_the_wrap_of_psi_validate_on_a_cad_part():
    """ψ passes ±180° down the filleted block's vertical fillets: the levels ±176°, ±168° next to the jump are found on
    ψ unwrapped about them (`contours._unwrapped`), not lost in the cells across it (max 10.0 px before, a false FAIL)."""
    scene = load_scene(Path(__file__).resolve().parent.parent / "parts" / "filleted_block.step").replace(
        image={"width": 160, "height": 90}, render={"mode": "zebra", "step": 8.0})
    report = validate_scene(scene, threads=1)
    by_level = {line.position: line for line in report.lines}
    assert all(by_level[c].points > 0 for c in (-176.0, 168.0, 176.0))
    assert report.passed, report.reasons
    assert report.deviations.max() < 0.05


def test_both_sides_of_a_v_seam_are_contoured(tmp_path):
    """A face closed in v seen on both sides of its v seam (the sweep's torus.step, isophotes): `_seam_split`'s windows
    tile the domain, each side once (the upper side in v was dropped and the lower one contoured twice: 23 analytic
    points missing where the traced lines are, a false FAIL), and validate passes."""
    import sys

    from rtreflect.analysis.contours import _seam_split

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / "torus.step"
    sweep.PARTS[path.name](path)
    scene = load_scene(path).replace(image={"width": 160, "height": 90},
                                     render={"mode": "isophote", "step": 10.0, "light": [0.3, -0.5, 1.0]})
    renderer = Renderer(resolve(scene))
    windows = _seam_split(field_of(renderer), 0)
    (u0, u1), (v0, v1) = renderer.surfaces.patches[0].domain
    assert len(windows) > 1 and len(set(windows)) == len(windows)
    assert sum((w[1] - w[0]) * (w[3] - w[2]) for w in windows) == pytest.approx((u1 - u0) * (v1 - v0))
    report = validate_scene(scene, threads=1, renderer=renderer)
    assert report.passed, report.reasons
    assert sum(line.misses for line in report.lines) == 0


def test_a_level_set_along_a_seam_is_contoured_whole(tmp_path):
    """The isophote 90° about the axis of the sweep's torus.step (R = 30, r = 8 about z) is its outer and inner
    equators, z = 0, and the outer one is the face's v seam: φ there is 90° give or take rounding, and contourpy
    followed the rounding's signs (bits of line, vertices wandering into the next grid row that Newton then
    rejected). Snapped onto the level (`contours._snapped`), the seam is one line: every analytic vertex of level
    90° lies on z = 0 (the closed form), and the traced line is within tolerance of it (6.9 px before, 13 px of the
    equator without an analytic line: a false FAIL)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / "torus.step"
    sweep.PARTS[path.name](path)
    scene = load_scene(path).replace(image={"width": 160, "height": 90},
                                     render={"mode": "isophote", "step": 10.0, "light": [0.0, 0.0, 1.0]})
    renderer = Renderer(resolve(scene))
    report = validate_scene(scene, threads=1, renderer=renderer)
    equator = [line for line in report.contours.lines if line.position == 90.0][0]
    uv = np.concatenate([p.uv for p in equator.polylines])
    S = renderer.surfaces.evaluate(np.zeros(len(uv), dtype=int), uv[:, 0], uv[:, 1]).S
    np.testing.assert_allclose(S[:, 2], 0.0, atol=1e-9)
    assert np.ptp(np.concatenate([p.px for p in equator.polylines])[:, 0]) > 100  # across the image, not in bits
    assert report.passed, (report.reasons, report.max_px)
    assert report.lines[9].points > 30 and report.lines[9].max_px < 0.1


def test_a_contour_loop_round_no_pixel_centre_is_not_a_miss():
    """A closed contour between pixel centres (φ on one side of its level at every centre) has no pixel pair to be
    traced between. parts/trimmed_face.step's zebra at 160×90: ψ dips below 40° inside four pixel centres at
    40.01°–40.03°, a loop found by the contours' `_small_loops`; its 26 points were counted as misses (a false
    FAIL). The loop test is checked on ellipses against their closed form."""
    from rtreflect.analysis.validate import encloses_a_pixel_centre

    _holds_pixel_centre = lambda loop: encloses_a_pixel_centre(loop, 200, 100)  # noqa: E731

    t = np.linspace(0.0, 2.0 * np.pi, 60)
    t[-1] = 0.0  # closed: first point = last
    ellipse = lambda cx, cy, a, b: np.column_stack([cx + a * np.cos(t), cy + b * np.sin(t)])  # noqa: E731
    assert not _holds_pixel_centre(ellipse(89.45, 34.73, 0.25, 0.07))  # between the centres (89.5, 34.5), (89.5, 35.5)
    assert _holds_pixel_centre(ellipse(89.5, 34.6, 0.25, 0.2))  # round (89.5, 34.5)
    assert not _holds_pixel_centre(ellipse(10.0, 10.0, 0.45, 0.45))  # round a pixel corner, radius < √2/2
    assert _holds_pixel_centre(ellipse(10.0, 10.0, 0.75, 0.75))  # round the four centres about that corner
    sliver = np.array([[0.0, 10.6], [100.0, 10.6], [100.0, 11.4], [0.0, 11.4], [0.0, 10.6]])
    assert not _holds_pixel_centre(sliver)  # 100 px long between two rows of centres
    assert _holds_pixel_centre(sliver + [0.0, 0.5])
    assert not _holds_pixel_centre(sliver + [250.0, 0.5])  # its centres beyond the image's right edge (x < 200 only)
    assert _holds_pixel_centre(np.array([[-1e6, -1e6], [1e6, -1e6], [1e6, 1e6], [-1e6, 1e6], [-1e6, -1e6]]))  # round it all
    ring = ellipse(100.0, 50.0, 1e5, 1e5)  # round the whole image, a huge box: the rows are clipped to the image
    assert _holds_pixel_centre(ring)
    horseshoe = np.array([[0.2, 0.2], [5.8, 0.2], [5.8, 5.8], [3.2, 5.8], [3.2, 1.2], [2.8, 1.2], [2.8, 5.8],
                          [0.2, 5.8], [0.2, 0.2]])  # concave: its runs along row 3.5 hold centres, its notch none
    assert _holds_pixel_centre(horseshoe)
    assert not _holds_pixel_centre(np.array([[2.7, 1.0], [3.3, 1.0], [3.3, 9.0], [2.7, 9.0], [2.7, 1.0]]))
    scene = load_scene(Path(__file__).resolve().parent.parent / "parts" / "trimmed_face.step").replace(
        image={"width": 160, "height": 90}, render={"mode": "zebra", "step": 10.0})
    report = validate_scene(scene, threads=1)
    assert report.passed and report.misses == 0, (report.reasons, [(l.position, l.misses) for l in report.lines])


def test_lines_in_view_but_unresolved_are_not_reported_as_no_line_in_view(tmp_path):
    """The sweep's small_fillet.step, isophotes every 10° at 160×90: the fillet turns the normal by 88° over a few
    pixels, so its eight isophotes (351 analytic points in the image) are nowhere resolved and nothing is compared
    (FAIL). The reason said no line lay where the camera sees the surface; it now says where they are."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / "small_fillet.step"
    sweep.PARTS[path.name](path)
    scene = load_scene(path).replace(image={"width": 160, "height": 90}, render={"mode": "isophote", "step": 10.0})
    report = validate_scene(scene, threads=1)
    shown = sum(len(p.px) for line in report.contours.lines for p in line.polylines)
    assert not report.passed and shown > 100
    assert "lie where the pixels resolve no line" in report.reasons[0], report.reasons
    assert "none of the mode's lines" not in report.reasons[0]


def sweep_render(tmp_path: Path, name: str, size: tuple[int, int], render: dict):
    """A sweep part (tools/make_sweep_parts.py) written to ``tmp_path``, in a scene of ``size`` and ``render``
    settings: (the scene, its renderer, the film of one render)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / name
    sweep.PARTS[name](path)
    scene = load_scene(path).replace(image={"width": size[0], "height": size[1]}, render=render)
    renderer = Renderer(resolve(scene))
    return scene, renderer, renderer.render(None, 1).film


def test_curvature_crossings_are_not_traced_across_a_knot_line(tmp_path):
    """Curvature is only C⁰ (a crease) across a bicubic's simple knot and jumps across a doubled one: the sweep's
    near_knots.step (knots u = 0.25, 0.5 / 0.500001, v = 0.3 / 0.300001) had H = 0 traced by the cubic through four
    pixels straddling u = 0.25 and v = 0.3, 0.70 px off the analytic line at 320×180 (a false FAIL). Pixels in
    different knot spans are no smooth pair now (`validate.knot_spans`): every pair of differing keys has a knot
    between its (u, v), and validate passes."""
    from rtreflect.analysis.validate import knot_spans

    scene, renderer, film = sweep_render(tmp_path, "near_knots.step", (320, 180),
                                         {"mode": "curvature", "quantity": "mean", "bands": 8})
    key, patch = knot_spans(renderer, film), film.channel("patch")
    u, v = film.channel("u").astype(float), film.channel("v").astype(float)
    a, b = (slice(None), slice(None, -1)), (slice(None), slice(1, None))  # along rows
    pair = (patch[a] >= 0) & (patch[a] == patch[b])
    differ = pair & (key[a] != key[b])
    assert differ.sum() > 50
    breaks_u, breaks_v = renderer.surfaces.patches[0].span_breaks()
    lo_u, hi_u = np.fmin(u[a], u[b])[differ], np.fmax(u[a], u[b])[differ]
    lo_v, hi_v = np.fmin(v[a], v[b])[differ], np.fmax(v[a], v[b])[differ]
    between = (((breaks_u[1:-1, None] > lo_u) & (breaks_u[1:-1, None] <= hi_u)).any(axis=0)
               | ((breaks_v[1:-1, None] > lo_v) & (breaks_v[1:-1, None] <= hi_v)).any(axis=0))
    assert between.all()
    report = validate_scene(scene, threads=1, renderer=renderer)
    assert report.passed and report.max_px < 0.1, (report.reasons, report.max_px)


def test_max_curvature_crossings_are_not_traced_across_its_crease(tmp_path):
    """max |κ| creases where |κ1| = |κ2|: the sweep's rational_high.step (one span, degree 6 × 5, so no knot line) at
    160×90 had a column of φ = |κ2| 0.0204, 0.0204 then κ1 0.0223, 0.0257, and the cubic through them put the
    centre of the level 0.0209 0.52 px off the analytic line (a false FAIL). The branch is part of the pixel's key
    (`validate.knot_spans`): pixels either side of the crease are no smooth pair, and validate passes."""
    from rtreflect.analysis.validate import knot_spans

    scene, renderer, film = sweep_render(tmp_path, "rational_high.step", (160, 90),
                                         {"mode": "curvature", "quantity": "maxabs", "bands": 8})
    key = knot_spans(renderer, film)
    larger = np.abs(film.channel("k1")) >= np.abs(film.channel("k2"))
    hit = film.channel("patch") >= 0
    pair = hit[:-1] & hit[1:]  # down columns: one face, one span, so the key changes only with the branch
    assert np.array_equal((key[:-1] != key[1:])[pair], (larger[:-1] != larger[1:])[pair])
    assert np.count_nonzero((larger[:-1] != larger[1:])[pair]) > 20
    report = validate_scene(scene, threads=1, renderer=renderer)
    assert report.passed and report.max_px < 0.25, (report.reasons, report.max_px)


def test_curvature_map_bending_within_a_pixel_is_no_colour_mismatch(tmp_path):
    """The sweep's periodic_bspline.step, mean curvature with 8 bands at 160×90: H is only C0 across its knot u = 5 and
    peaks there; two pixels on it, far from every iso-line, show their samples' mean map colour, which the centre's
    colour misses by more than half a sample: 2 colour mismatches, a false FAIL, before `validate.map_bend`."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / "periodic_bspline.step"
    sweep.PARTS[path.name](path)
    scene = load_scene(path).replace(image={"width": 160, "height": 90},
                                     render={"mode": "curvature", "quantity": "mean", "range": "auto", "bands": 8})
    report = validate_scene(scene, threads=1)
    assert report.colour_checked > 500 and report.colour_mismatches == 0
    assert report.passed, report.reasons


def test_a_region_inside_a_face_shows_the_maps_colour_and_validates(tmp_path):
    """The sweep's kink.step is ruled (its poles linear in u on each side of the triple knot u = 0.5): K ≡ 0, one
    principal curvature is 0 everywhere, and κ1 is that one wherever the other (κ2) is negative: a region inside the
    face where κ1 is at the level 0 exactly. Its stripe painted it in the line colour, and validate traced the
    rounding of κ1 there: 15.8 px, 86 misses at 160×90 (FAIL). Now a region shows the map's colour for 0 (`regions`,
    the floor), its edge is no traced line, and validate passes."""
    scene, renderer, film = sweep_render(tmp_path, "kink.step", (160, 90),
                                         {"mode": "curvature", "quantity": "k1", "bands": 8})
    patch = film.channel("patch")
    k2 = film.channel("k2").astype(float)
    scale = renderer.mode.high - renderer.mode.low
    inside = (patch >= 0) & (k2 < -0.05 * scale)  # well inside the region: κ2 clearly negative, so κ1 = 0
    for dy in (-2, 0, 2):  # and two pixels from its edge and the face's
        for dx in (-2, 0, 2):
            inside &= np.roll(np.roll((patch >= 0) & (k2 < -0.05 * scale), dy, axis=0), dx, axis=1)
    assert inside.sum() > 200
    assert np.abs(film.channel("k1")[inside]).max() < 1e-9 * scale  # κ1 there is 0 to rounding
    rgb = np.stack([film.channel(c) for c in "RGB"], axis=-1)[inside]
    np.testing.assert_allclose(rgb, np.broadcast_to(renderer.mode.colors(np.zeros(1))[0], rgb.shape), atol=1e-4)
    report = validate_scene(scene, threads=1, renderer=renderer)
    assert report.passed and report.max_px < 0.1, (report.reasons, report.max_px)


PARTS = Path(__file__).resolve().parent.parent / "parts"


def occt_face_kinds(path: Path) -> list[str]:
    """Each face's analytic kind by Open CASCADE, before conversion (the reader keeps OCCT's face order): "plane",
    "cylinder", "cone", "sphere", "torus" or "other", with "|pull" on a cylinder or cone whose axis is along +z."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.GeomAbs import GeomAbs_Cone, GeomAbs_Cylinder, GeomAbs_Plane, GeomAbs_Sphere, GeomAbs_Torus

    from test_cad_reader import occt_faces

    names = {GeomAbs_Plane: "plane", GeomAbs_Cylinder: "cylinder", GeomAbs_Cone: "cone", GeomAbs_Sphere: "sphere",
             GeomAbs_Torus: "torus"}
    kinds = []
    for face in occt_faces(path)[1]:
        surface = BRepAdaptor_Surface(face)
        kind = names.get(surface.GetType(), "other")
        if kind in ("cylinder", "cone"):
            axis = (surface.Cylinder() if kind == "cylinder" else surface.Cone()).Axis().Direction()
            kind += "|pull" if abs(abs(axis.Z()) - 1.0) < 1e-12 else ""
        kinds.append(kind)
    return kinds


@pytest.mark.parametrize("part", ["filleted_block.step", "plate.step"])
def test_map_regions_are_the_faces_where_the_closed_form_is_constant(part):
    """A map draws no line on a face where φ is constant (`modes.regions`). Which faces those are follows from each
    face's kind by Open CASCADE: K is constant on planes, cylinders, cones and spheres, H on planes, cylinders and
    spheres, the draft angle (pull +z) on planes and on cylinders and cones along the pull; never on a torus. So is
    the isophotes' angle to a light straight down (their 0° level painted the top face white, 90° every wall)."""
    pytest.importorskip("OCP")
    kinds = occt_face_kinds(PARTS / part)
    expected = {"gaussian": ("plane", "cylinder", "cylinder|pull", "cone", "cone|pull", "sphere"),
                "mean": ("plane", "cylinder", "cylinder|pull", "sphere"),
                "draft": ("plane", "cylinder|pull", "cone|pull"),
                "isophote": ("plane", "cylinder|pull", "cone|pull")}
    assert "torus" in kinds or "sphere" in kinds
    for quantity, constant in expected.items():
        render = ({"mode": "draft"} if quantity == "draft" else {"mode": "isophote", "light": [0.0, 0.0, 1.0]}
                  if quantity == "isophote" else {"mode": "curvature", "quantity": quantity, "bands": 6})
        mode = Renderer(resolve(load_scene(PARTS / part).replace(image={"width": 32, "height": 18},
                                                                 render=render))).mode
        assert mode.constant_faces.tolist() == [kind in constant for kind in kinds], quantity


def test_a_map_with_no_line_in_view_shows_its_colours_and_passes():
    """The filleted block's Gaussian curvature in 6 bands: K is 0 on its planes and cylinders (a level: the range is
    symmetric) and 1/r² on its sphere corners. A level φ equals on a whole face is a region of the map, not a line:
    those faces show the map's middle colour (K = 0), where the stripe painted them in the line colour (the picture
    was all white), and validate passes with a note, where it failed for want of a line to compare."""
    pytest.importorskip("OCP")
    scene = resolve(load_scene(PARTS / "filleted_block.step").replace(
        image={"width": 160, "height": 90}, render={"mode": "curvature", "quantity": "gaussian", "bands": 6}))
    renderer = Renderer(scene)
    result = renderer.render(threads=1)
    patch, k = result.aov("patch"), result.aov("K")
    constant = renderer.mode.constant_faces
    inside = result.film.channel("A") == 1.0  # not on the silhouette
    flat = inside & (patch >= 0) & np.isclose(k, 0.0, atol=1e-12)
    flat &= constant[np.maximum(patch, 0).astype(int)]
    assert flat.sum() > 1000
    rgb = np.stack([result.film.channel(c) for c in "RGB"], axis=-1)[flat]
    middle = renderer.mode.colors(np.zeros(1))[0]  # the diverging map's centre, K = 0
    line = np.asarray(scene.render.line_color, dtype=np.float64)
    assert np.all(line > middle + 0.05)  # the line colour is lighter in every channel: the two can be told apart
    # The map's colour, but in the pixels beside a sphere corner (its dark red mixed in, supersampled): none lighter.
    assert np.mean(np.abs(rgb - middle).max(axis=1) < 1e-3) > 0.95
    assert not np.any(np.all(rgb > middle + 1e-3, axis=1))
    report = validate_scene(scene, threads=1, renderer=renderer)
    assert report.passed, report.reasons
    assert report.colour_checked > 1000 and any("no iso-line in view" in note for note in report.notes)
    # Without bands the map has no levels: nothing to compare, a FAIL (the note is for levels crossed nowhere).
    # The reason names the setting, not lines out of view (what it said before).
    plain = validate_scene(scene.replace(render={"bands": 0}), threads=1)
    assert not plain.passed and "no traced line centre was compared" in plain.reasons[0], plain.reasons
    assert "bands = 2 or more" in plain.reasons[0] and "where the camera" not in plain.reasons[0], plain.reasons


def test_a_line_mode_with_no_line_in_view_does_not_speak_of_maps(tmp_path):
    """Highlight lines of a single tube far off the plane: none crosses it. Nothing is compared (FAIL), and the
    reason speaks of the mode's lines, neither of tubes nor of a map's faces at a level. Isophotes every 90° on a
    plane whose normal is 45° from L: φ = 45° everywhere, no level crossed, a region (`modes.regions`) with no line
    to draw: passes with a note, its pixels checked free of lines."""
    scene_text = """
[image]
width = 64
height = 36

[camera]
eye = [0.0, -3.0, 3.0]
look_at = [0.0, 0.0, 0.0]

[lights]
point = [0.0, 0.0, 3.0]
normal = [0.0, 0.0, 1.0]
direction = [0.0, 1.0, 0.0]
positions = [0.0]
radius = 0.1

[[surface]]
degree = [1, 1]
knots_u = [0.0, 0.0, 1.0, 1.0]
knots_v = [0.0, 0.0, 1.0, 1.0]
points = [[[-1.0, -1.0, -1.0], [-1.0, 1.0, -1.0]], [[1.0, -1.0, 1.0], [1.0, 1.0, 1.0]]]

[render]
"""
    scene_file = tmp_path / "plane.toml"
    scene_file.write_text(scene_text + 'mode = "isophote"\nstep = 90.0\nlight = [0.0, 0.0, 1.0]\n')
    isophotes = validate_scene(load_scene(scene_file), threads=1)
    assert isophotes.passed and isophotes.colour_checked > 200, isophotes.reasons
    assert any("no iso-line in view" in note for note in isophotes.notes), isophotes.notes
    scene_file.write_text(scene_text.replace("positions = [0.0]", "positions = [40.0]") + 'mode = "highlight"\n')
    report = validate_scene(load_scene(scene_file), threads=1)
    assert not report.passed and "no traced line centre was compared" in report.reasons[0]
    assert "tube" not in report.reasons[0] and "whole faces" not in report.reasons[0], report.reasons[0]
    assert "none of the mode's lines" in report.reasons[0], report.reasons[0]


@pytest.mark.parametrize("inward", [False, True])
def test_a_face_whose_map_is_constant_from_the_side_seen_is_a_region_whichever_way_its_normal_points(inward):
    """κ2 on a torus seen from outside is its tube's curvature −1/r all over; from inside, −κ1, which varies. With the
    range [−1, 0] in 5 bands the level −0.8 lies within a stripe of −1/1.27 = −0.787: the face is a region of the map
    (no line, the map's colour) seen from outside, whichever way its own normal points (the sides of `constant_faces`:
    with the normals pointing in, as OCCT's data/step/trj4_k1_geo-tc-214.stp's ring had them, it was painted in the
    line colour, every pixel)."""
    from dataclasses import replace

    from OCP.BRepPrimAPI import BRepPrimAPI_MakeTorus

    from rtreflect.exchange import occt

    torus = occt.read_faces(Path("torus.step"), BRepPrimAPI_MakeTorus(5.8, 1.27).Shape(), "torus", unit="mm",
                            unit_note="", what="STEP file").surfaces[0]
    torus = replace(torus, trim=None, mesh_uv=None)  # the whole torus: its domain
    if inward:  # u reversed: the same surface, its normal the other way
        (u0, u1), _ = torus.domain
        torus = replace(torus, knots_u=(u0 + u1) - torus.knots_u[::-1], points=torus.points[::-1],
                        weights=torus.weights[::-1])
    # The own normal at a point against the way out of the tube there (S − C, C on the centre circle): one case each.
    u, v = np.linspace(*torus.domain[0], 7)[1:-1], np.linspace(*torus.domain[1], 7)[1:-1]
    uu, vv = (x.ravel() for x in np.meshgrid(u, v))
    S = torus.evaluate(uu, vv).S
    centre = 5.8 * S[:, :2] / np.linalg.norm(S[:, :2], axis=1, keepdims=True)
    out = np.einsum("ij,ij->i", torus.normals(uu, vv), S - np.column_stack([centre, np.zeros(len(S))]))
    assert np.all(out < 0) if inward else np.all(out > 0)
    scene = resolve(load_scene(SCENES / "hood.toml").replace(
        image={"width": 160, "height": 90}, camera={"eye": [0.0, -16.0, 12.0], "look_at": [0.0, 0.0, 0.0]},
        render={"mode": "curvature", "quantity": "k2", "range": [-1.0, 0.0], "bands": 5}, surfaces=[torus]))
    renderer = Renderer(scene)
    result = renderer.render(threads=1)
    seen = (result.aov("patch") >= 0) & (result.film.channel("A") == 1.0)
    assert seen.sum() > 1000
    assert np.allclose(result.aov("k2")[seen], -1.0 / 1.27, atol=1e-6)  # the closed form: κ2 = −1/r
    rgb = np.stack([result.film.channel(c) for c in "RGB"], axis=-1)[seen]
    region = renderer.mode.colors(np.array([-1.0 / 1.27]))[0]
    assert np.mean(np.abs(rgb - region).max(axis=1) < 1e-3) > 0.99
    assert validate_scene(scene, threads=1, renderer=renderer).passed


def test_highlight_lines_skip_a_wall_whose_normals_lie_along_the_light_plane():
    """Highlight lines with the light plane z = 3: a wall y = 0.5 whose net leans 1e-13 (a converted plane's
    rounding) has normal lines parallel to the light plane, meeting it nowhere, and the renderer draws no band there
    (the skew-line distance). φ is NaN there (`TubeLights.normal_line_f`): it was the rounding times the distance,
    noise across the part's size, and the analytic lines drawn across the wall were misses (OCCT's
    data/step/bug32596_abc_0_13.step: 42 at 320×180). No analytic point lies on the wall; validate passes."""
    from dataclasses import replace

    from rtreflect.geometry.surfaces import NurbsSurface

    scene = load_scene(SCENES / "hood.toml")
    hood = scene.surfaces[0]
    lean = 1e-13
    wall = NurbsSurface.bezier(np.array([[[-1.0, 0.5, 0.0], [-1.0, 0.5 + lean, 1.2]],
                                         [[1.0, 0.5, 0.0], [1.0, 0.5 + lean, 1.2]]]), name="wall")
    scene = resolve(replace(scene, surfaces=(hood, wall)).replace(image={"width": 320, "height": 180},
                                                                   render={"mode": "highlight"}))
    renderer = Renderer(scene)
    report = validate_scene(scene, threads=1, renderer=renderer)
    on_wall = sum(len(p.uv) for line in report.contours.lines for p in line.polylines if p.patch == 1)
    assert on_wall == 0
    assert report.passed, report.reasons
    assert sum(line.points for line in report.lines) > 200  # the hood's lines are compared


def _wall_scene(tmp_path: Path, profile: list[float]) -> Path:
    """A wall x ∈ [−1, 1], z ∈ [−1, 1] whose depth y is a cubic in z (control values ``profile``), seen level from the
    front with z = 0 on the middle pixel row's centres (91 rows), as isophotes of the light +z every 1°."""
    thirds = [-1.0, -1 / 3, 1 / 3, 1.0]
    points = [[[x, y, z] for y, z in zip(profile, thirds)] for x in thirds]
    path = tmp_path / "wall.toml"
    path.write_text(f"""
[image]
width = 121
height = 91
samples = "analytic"
[camera]
eye = [0.0, -6.0, 0.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 30.0
[lights]
point = [0.0, 0.0, 5.0]
normal = [0.0, 0.0, 1.0]
direction = [0.0, 1.0, 0.0]
spacing = 0.5
count = 9
[render]
mode = "isophote"
light = [0.0, 0.0, 1.0]
step = 1.0
[[surface]]
degree = 3
knots_u = [0, 0, 0, 0, 1, 1, 1, 1]
knots_v = [0, 0, 0, 0, 1, 1, 1, 1]
points = {points}
""")
    return path


@pytest.mark.parametrize("kind", ["touch", "cross"])
def test_a_level_met_on_pixel_centres_is_traced_only_where_it_is_crossed(kind, tmp_path):
    """y = 0.1 z³ (control values ±0.1 alternating): the normal (0, −1, 0.3 z²)/|·| turns vertical at z = 0 and back, so
    φ = 90° − ~17° z² touches the 90° level there without crossing it: on the middle row φ is 90° to float32 rounding,
    above and below it less. That row is no line (no analytic contour: φ < 90° off it), so before `validate._touches`
    its pixels made 114 traced "crossings" (two a column) with no analytic line near, each a miss. y = −0.03 z² ((−0.03, 0.01, 0.01,
    −0.03)): φ = 90° + ~3.4° z crosses 90° at z = 0, on the same row of pixel centres; that crossing is traced (once per
    column) and compared with the contour z = 0."""
    profile = [-0.1, 0.1, -0.1, 0.1] if kind == "touch" else [-0.03, 0.01, 0.01, -0.03]
    scene = load_scene(_wall_scene(tmp_path, profile))
    report = validate_scene(scene, threads=1)
    ninety = [line for line in report.lines if line.position == 90.0][0]
    assert report.passed, (report.reasons, [(line.position, line.points, line.misses) for line in report.lines])
    if kind == "touch":
        assert ninety.points == 0 and ninety.misses == 0
    else:
        assert ninety.max_px <= 0.01
        assert 50 <= ninety.points <= 60  # one a column of the 57 the wall spans (the touch made two)


def test_a_strip_narrower_than_the_contour_grid_is_compared_with_the_exact_level_set(tmp_path):
    """y = 0.1 z³ − 1.5e-4 z: the isophote angle rises just past 90° (by ~0.009°) in a strip |z| < 0.022, about 1.3
    pixels across the middle rows, and falls back. The analytic contours' grid (cells ~2 px) steps over it: before
    `validate.exact_crossings` its 114 traced crossings (two a column, at the strip's edges) met no contour, each a miss
    (OCCT's linkrods.step: κ1 = 0 beside a knot line, 1.24 px off the contour on the strip's near side). The exact
    roots of φ = 90° between the same pixels' hits agree with the traced centres."""
    b = 1.5e-4
    profile = [0.1 * cube - b * z for cube, z in zip([-1.0, 1.0, -1.0, 1.0], [-1.0, -1 / 3, 1 / 3, 1.0])]
    report = validate_scene(load_scene(_wall_scene(tmp_path, profile)), threads=1)
    ninety = [line for line in report.lines if line.position == 90.0][0]
    assert report.passed, (report.reasons, [(line.position, line.points, line.misses) for line in report.lines])
    assert ninety.points == 114 and ninety.max_px <= 0.01


@pytest.mark.parametrize("row, expected", [
    ([88.0, 90.0, 90.0, 90.0, 88.5], [True, True]),  # a run of three on the level, the same side past it: a touch
    ([88.0, 90.0, 90.0, 90.0, 91.0], [False]),  # ... the other side past it: crossed once (the pair into the run)
    ([91.0, 90.0, 90.0, 88.0], [False]),  # crossed downwards: the pair out of the run, found walking back
    ([90.0, 90.0, 88.0, 87.0], [True]),  # the run reaches the row's start: undecided, no line
    ([89.7, 89.8, 89.7, 89.6], [True, True]),  # 89.8 as float32 stores it (above 89.8): met, not crossed
    ([89.7, 89.8, 89.9, 90.0], [False]),  # ... and crossed
])
def test_a_level_touched_on_pixels_is_told_from_one_crossed(row, expected):
    """`validate._touches` on one row of float32 film values against the level (90°, or 89.8°, which float32 rounds up):
    the pairs `traced_centres` keeps (f from below c to at least c) are crossings only where the values past the run
    on the level lie on the other side."""
    from rtreflect.analysis.validate import _touches

    c = 89.8 if 89.8 in row else 90.0
    f = np.asarray(row, dtype=np.float32).astype(np.float64)
    jump_next = np.full(len(f), np.inf)
    jump_next[:-1] = np.abs(np.diff(f))  # every neighbouring pair smooth (the last pixel has none after it)
    a = np.arange(len(f) - 1)
    b = a + 1
    counted = (np.fmin(f[a], f[b]) < c) & (c <= np.fmax(f[a], f[b]))  # as traced_centres selects them
    a, b = a[counted], b[counted]
    assert _touches(f, a, b, np.full(len(a), c), jump_next, 1).tolist() == expected
