"""Continuity at seams (issue 16) against pairs built with known answers.

The pairs are cylinders over a curve z = g(x), written as bicubic patches whose x and z are
polynomials in u alone (y in v): then at the seam x = 0 the normal angle is
atan g_B'(0) − atan g_A'(0) and the normal curvature across it is g''/(1 + g'²)^(3/2) —
closed forms that do not go through the evaluator. Rational versions weight the control
points along v only (w_ij = w_j), which leaves x(u) and z(u) polynomial. Every pair is also
moved by a rigid motion, so nothing rests on axis-aligned luck. A G2 pair is one rational
patch split in two by de Casteljau (knot insertion to full multiplicity) in homogeneous form.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rtreflect.analysis.continuity import Thresholds, continuity, sample_seam
from rtreflect.exchange.load import load_scene
from rtreflect.geometry.seams import find_seams, part_size
from rtreflect.geometry.surfaces import NurbsSurface

ROOT = Path(__file__).resolve().parents[1]
REL = 1e-9


def _rotation() -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(7).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


MOTION = (_rotation(), np.array([0.7, -1.3, 2.1]))


def _bernstein_fit(values: np.ndarray) -> np.ndarray:
    """Cubic Bézier ordinates of the cubic polynomial with these values at u = 0, 1/3, 2/3, 1."""
    u = np.linspace(0.0, 1.0, 4)
    B = np.array([[math.comb(3, i) * t ** i * (1 - t) ** (3 - i) for i in range(4)] for t in u])
    return np.linalg.solve(B, values)


def cylinder_patch(g, x0: float, x1: float, y=(-1.0, 1.0), rational: bool = False, lift: float = 0.0) -> NurbsSurface:
    """z = g(x) + lift over x ∈ [x0, x1], y ∈ y, as a bicubic Bézier patch (u ↦ x, v ↦ y), moved by MOTION."""
    u = np.linspace(0.0, 1.0, 4)
    xs = x0 + (x1 - x0) * u
    z = _bernstein_fit(g(xs) + lift)
    ys = np.linspace(*y, 4)
    P = np.zeros((4, 4, 3))
    P[..., 0] = xs[:, None]
    P[..., 1] = ys[None, :]
    P[..., 2] = z[:, None]
    R, shift = MOTION
    P = P @ R.T + shift
    w = np.tile([1.0, 2.5, 0.6, 1.3] if rational else [1.0] * 4, (4, 1))
    return NurbsSurface.bezier(P, w)


def kappa(d1: float, d2: float) -> float:
    """Curvature of z = g(x) with g' = d1, g'' = d2."""
    return d2 / (1.0 + d1 * d1) ** 1.5


def _report(patches):
    size = part_size(patches)
    seams = find_seams(patches)
    assert len(seams) == 1
    return seams[0], continuity(patches, seams, Thresholds(1e-9 * size, 1e-6, 1e-6), size)[0]


@pytest.mark.parametrize("rational", [False, True])
def test_g1_angle_and_curvatures_match_the_closed_form_at_every_sample(rational):
    alpha = math.radians(7.5)
    a1, a2 = 0.3, 0.4  # g_A'(0), g_A''(0)
    b1 = math.tan(math.atan(a1) + alpha)
    b2 = 1.0
    A = cylinder_patch(lambda x: a1 * x + 0.5 * a2 * x * x + 0.1 * x ** 3, -1.0, 0.0, rational=rational)
    B = cylinder_patch(lambda x: b1 * x + 0.5 * b2 * x * x - 0.2 * x ** 3, 0.0, 1.0, rational=rational)
    assert A.rational == rational
    _, edge = _report([A, B])
    s = edge.samples
    assert len(s.t) >= 9  # 8 per knot span; nothing varies along a cylinder, so no refinement
    np.testing.assert_allclose(s.g1, alpha, rtol=REL)
    np.testing.assert_allclose(np.abs(s.kappa_a), abs(kappa(a1, a2)), rtol=REL)
    np.testing.assert_allclose(np.abs(s.kappa_b), abs(kappa(b1, b2)), rtol=REL)
    assert np.all(np.sign(s.kappa_a) == np.sign(s.kappa_b))  # both sides' normals turned the same way
    assert np.max(s.g0) < 1e-12
    assert edge.cls == "G0"


@pytest.mark.parametrize("rational", [False, True])
def test_curvature_jump_matches_the_closed_form(rational):
    a1, a2, b2 = -0.25, 0.4, 1.4
    A = cylinder_patch(lambda x: a1 * x + 0.5 * a2 * x * x, -1.0, 0.0, rational=rational)
    B = cylinder_patch(lambda x: a1 * x + 0.5 * b2 * x * x + 0.3 * x ** 3, 0.0, 1.0, rational=rational)
    _, edge = _report([A, B])
    s = edge.samples
    jump = abs(kappa(a1, a2) - kappa(a1, b2))
    np.testing.assert_allclose(s.jump, jump, rtol=REL)
    np.testing.assert_allclose(s.rel, jump / abs(kappa(a1, b2)), rtol=REL)
    np.testing.assert_allclose(s.rel_mean, jump / (0.5 * (abs(kappa(a1, a2)) + abs(kappa(a1, b2)))), rtol=REL)
    assert np.max(s.g1) < 1e-12
    assert edge.cls == "G1"
    assert edge.g2_max_abs == pytest.approx(jump, rel=REL)


@pytest.mark.parametrize("rational", [False, True])
def test_gap_matches_the_translation(rational):
    delta = 1e-3
    g = lambda x: 0.2 * x + 0.3 * x * x - 0.1 * x ** 3  # noqa: E731
    A = cylinder_patch(g, -1.0, 0.0, rational=rational)
    B = cylinder_patch(g, 0.0, 1.0, rational=rational, lift=delta)  # moved by δ along the cylinder's z
    _, edge = _report([A, B])
    np.testing.assert_allclose(edge.samples.g0, delta, rtol=REL)
    assert edge.cls == "open"
    assert np.max(edge.samples.g1) < 1e-9


def _split(P: np.ndarray, w: np.ndarray, tau: float):
    """A Bézier patch split at u = τ by de Casteljau on homogeneous points (= knot insertion to multiplicity p)."""
    H = np.concatenate([P * w[..., None], w[..., None]], axis=-1)
    rows = [H]
    left, right = [H[0]], [H[-1]]
    while len(rows[-1]) > 1:
        r = rows[-1]
        nxt = (1 - tau) * r[:-1] + tau * r[1:]
        rows.append(nxt)
        left.append(nxt[0])
        right.append(nxt[-1])
    L, Rt = np.array(left), np.array(right[::-1])
    return [NurbsSurface.bezier(X[..., :3] / X[..., 3:], X[..., 3]) for X in (L, Rt)]


@pytest.mark.parametrize("rational", [False, True])
def test_a_surface_split_by_knot_insertion_is_g2_to_rounding(rational):
    rng = np.random.default_rng(3)
    u, v = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4), indexing="ij")
    P = np.stack([2 * u, 2 * v, 0.6 * np.sin(3 * u + 2 * v)], axis=-1) + 0.1 * rng.normal(size=(4, 4, 3))
    w = rng.uniform(0.5, 2.0, size=(4, 4)) if rational else np.ones((4, 4))
    A, B = _split(P, w, 0.4)
    _, edge = _report([A, B])
    s = edge.samples
    assert np.max(s.g0) < 1e-14
    assert np.max(s.g1) < 1e-12
    big = np.maximum(np.abs(s.kappa_a), np.abs(s.kappa_b))
    assert np.all(np.abs(s.kappa_a - s.kappa_b) <= 1e-9 * big)  # the raw difference: rounding only
    assert edge.g2_max_abs == 0.0 and edge.cls == "G2"


def test_t_junction_and_partial_overlap_give_the_common_stretch():
    g = lambda x: 0.1 * x * x  # noqa: E731
    long_side = cylinder_patch(g, -1.0, 0.0, y=(-1.0, 1.0))
    short = cylinder_patch(g, 0.0, 1.0, y=(0.0, 1.0))  # T-junction: half of the long side
    shifted = cylinder_patch(g, 0.0, 1.0, y=(0.5, 1.5))  # partial overlap: [0.5, 1]
    for other, (lo, hi) in ((short, (0.0, 1.0)), (shifted, (0.5, 1.0))):
        seams = find_seams([long_side, other])
        assert len(seams) == 1
        seam = seams[0]
        assert seam.length == pytest.approx(hi - lo, rel=1e-9)
        s = sample_seam([long_side, other], seam, 3.0)
        ys = (s.P - MOTION[1]) @ MOTION[0]
        assert ys[:, 1].min() == pytest.approx(lo, abs=1e-9) and ys[:, 1].max() == pytest.approx(hi, abs=1e-9)
        assert np.max(s.g1) < 1e-12


def test_g1_join_is_g1_with_a_curvature_jump():
    scene = load_scene(ROOT / "scenes" / "g1_join.toml")
    patches = list(scene.surfaces)
    size = part_size(patches)
    seams = find_seams(patches)
    [edge] = continuity(patches, seams, Thresholds(1e-9 * size, 0.01, 0.01), size)
    assert edge.cls == "G1"
    assert edge.g1_max_deg < 1e-9
    # Left patch z(u) has z'' = 6 (0.1 − 0 + 0) / (1/3 · 3)² ... across x: z_xx = 0.6 / (1/3·3)² = 0.6; right is flat.
    assert edge.g2_max_abs == pytest.approx(0.6, rel=1e-9)
    assert edge.g2_max_rel == pytest.approx(1.0, rel=1e-12)


def test_teapot_seam_classes():
    """The Newell teapot's shared edges: around each ring G2, between rings G1 (collinear control points,
    unequal spacing), none merely G0 (the spout and handle meet the body by intersection, not by a shared edge)."""
    scene = load_scene(ROOT / "scenes" / "teapot.toml")
    patches = list(scene.surfaces)
    size = part_size(patches)
    reports = continuity(patches, find_seams(patches), Thresholds(1e-9 * size, 0.01, 0.01), size)
    assert len(reports) == 52
    classes = {(r.seam.a.patch, r.seam.a.side, r.seam.b.patch, r.seam.b.side): r.cls for r in reports}
    # u seams join rings (rim/body/bottom, spout, handle, lid): G1 with a curvature jump.
    g1 = {k for k, c in classes.items() if c == "G1"}
    assert g1 and all(k[1] == "u1" for k in g1)
    assert len(g1) == 20
    assert all(c == "G2" for k, c in classes.items() if k[1] != "u1")
    assert all(r.g1_max_deg < 1e-8 for r in reports)


def _run(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-c", "from rtreflect.cli import main; main()", *args], capture_output=True, text=True, cwd=cwd,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})


def test_single_patch_reports_no_shared_edges(tmp_path):
    result = _run("continuity", "scenes/hood.toml", "--json", str(tmp_path / "r.json"))
    assert result.returncode == 0, result.stderr
    assert "no shared edges" in result.stdout
    assert json.loads((tmp_path / "r.json").read_text())["edges"] == []


@pytest.mark.parametrize("args, field", [(["--g0", "-1"], "--g0"), (["--require", "G3"], "--require"),
                                         (["--g1", "-0.5"], "--g1")])
def test_bad_options_are_one_line_exit_2(args, field):
    result = _run("continuity", "scenes/g1_join.toml", *args)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rtreflect: error:") and field in lines[0]


def test_require_sets_the_exit_status(tmp_path):
    ok = _run("continuity", "scenes/g1_join.toml", "--require", "G1", "--json", str(tmp_path / "r.json"))
    assert ok.returncode == 0, ok.stderr
    bad = _run("continuity", "scenes/g1_join.toml", "--require", "G2")
    assert bad.returncode == 1
    edge = json.loads((tmp_path / "r.json").read_text())["edges"][0]
    for key in ("patches", "length", "samples", "g0_max", "g1_max_deg", "g2_max_abs", "g2_max_rel", "class", "worst",
                "line_kink_max_deg"):
        assert key in edge
    assert edge["patches"] == [0, 1] and edge["class"] == "G1"


def _rectangle_loop(u0, u1, v0, v1, per_side=40, clockwise=False):
    t = np.linspace(0.0, 1.0, per_side, endpoint=False)
    loop = np.concatenate([np.stack([u0 + (u1 - u0) * t, np.full_like(t, v0)], 1),
                           np.stack([np.full_like(t, u1), v0 + (v1 - v0) * t], 1),
                           np.stack([u1 - (u1 - u0) * t, np.full_like(t, v1)], 1),
                           np.stack([np.full_like(t, u0), v1 - (v1 - v0) * t], 1)])
    return loop[::-1] if clockwise else loop


def test_trimmed_faces_share_edges_along_their_loops():
    """Faces with trim loops (as CAD readers give them) are matched along the loops, either loop orientation,
    and a face trimmed to half its side meets its neighbour over that half only."""
    import dataclasses

    from rtreflect.geometry.seams import Boundary, _length
    from rtreflect.geometry.trims import Trim

    rng = np.random.default_rng(5)
    u, v = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 4), indexing="ij")
    P = np.stack([2 * u, 2 * v, 0.4 * np.cos(2 * u + v)], axis=-1) + 0.05 * rng.normal(size=(4, 4, 3))
    A, B = _split(P, rng.uniform(0.5, 2.0, size=(4, 4)), 0.5)
    A = dataclasses.replace(A, trim=Trim(_rectangle_loop(0, 1, 0, 1)))
    full = dataclasses.replace(B, trim=Trim(_rectangle_loop(0, 1, 0, 1, clockwise=True)))
    half = dataclasses.replace(B, trim=Trim(_rectangle_loop(0, 1, 0, 0.5)))
    _, edge = _report([A, full])
    assert edge.cls == "G2" and np.max(edge.samples.g1) < 1e-9 and np.max(edge.samples.g0) < 1e-12
    seam, edge = _report([A, half])
    assert edge.cls == "G2"
    expected = _length(B, Boundary(1, "u0", np.array([[0.0, 0.0], [0.0, 0.5]]), np.array([1.0, 0.0])), 0.0, 1.0)
    assert seam.length == pytest.approx(expected, rel=1e-6)  # ends located to 2^-30 of a sample spacing


def test_paper_statement_measured_kinked_lines_at_g1_none_at_g2():
    """Paper, section 1: across a G1 seam with a curvature jump the reflection lines are only G0 (kinked);
    across a G2 seam they are smooth. g1_join against the same view of one patch split by knot insertion."""
    import dataclasses

    from rtreflect.analysis.seamcheck import check_scene

    scene = load_scene(ROOT / "scenes" / "g1_join.toml")
    [g1] = check_scene(scene).edges
    assert g1.cls == "G1" and g1.line_crossings >= 5
    assert g1.line_kink_max_deg > 10.0 and g1.line_kink_image_max_deg > 10.0
    assert g1.extra["line_geodesic_jump_max"] > 0.1  # and the lines' geodesic curvature jumps (1/unit)

    left = scene.surfaces[0]  # a bicubic whose curvature varies across x: split it at u = 0.5
    A, B = _split(left.points, left.weights, 0.5)
    [g2] = check_scene(scene.replace(surfaces=[A, B])).edges
    assert g2.cls == "G2" and g2.line_crossings >= 5
    assert g2.line_kink_max_deg < 1e-4 and g2.line_kink_image_max_deg < 1e-4
    assert g2.extra["line_geodesic_jump_max"] < 1e-6


def test_filleted_cad_block_is_g1_with_the_fillet_curvature():
    """A STEP block with every edge filleted at radius 4 (CAD input, once its readers are installed): every
    shared edge is G1 with the curvature jump 1/4 between a plane or a cylinder's straight direction and
    the fillet, and the reflection lines kink where they cross."""
    pytest.importorskip("rtreflect.exchange.step")
    part = ROOT / "parts" / "filleted_block.step"
    if not part.exists():
        pytest.skip("parts/filleted_block.step comes with the CAD readers")
    from rtreflect.analysis.seamcheck import check_scene

    result = check_scene(load_scene(part))
    assert len(result.edges) == 48
    assert all(e.cls == "G1" for e in result.edges)
    assert all(e.g2_max_abs == pytest.approx(0.25, rel=1e-5) for e in result.edges)
    assert any(e.line_kink_max_deg and e.line_kink_max_deg > 10 for e in result.edges)


def test_capped_cylinder_from_rhino_meets_its_caps_at_right_angles():
    """trimmed.3dm's capped cylinder (a periodic face and two trimmed planar caps): the rims are G0 with the
    normals exactly 90° apart. The cylinder's own seam (the two ends of its period: one Rhino edge used twice by
    one face) joins no two faces, so it is no seam (B-rep topology, issue 16; the geometric finder reported it G2)."""
    part = ROOT / "parts" / "trimmed.3dm"
    from rtreflect.analysis.seamcheck import check_scene

    scene = load_scene(part)
    result = check_scene(scene, lines=False)
    by_class = sorted((e.cls, e.seam.a.patch, e.seam.b.patch) for e in result.edges)
    assert by_class == [("G0", 1, 2), ("G0", 1, 3)]
    assert [e.closed for e in scene.surfaces[1].trim.edges].count(True) == 1
    for e in result.edges:
        if e.cls == "G0":
            np.testing.assert_allclose(np.degrees(e.samples.g1), 90.0, rtol=1e-9)
            assert e.seam.length == pytest.approx(2 * math.pi * 10.0, rel=1e-6)


def test_picture_draws_the_seam_in_its_class_colour_and_the_charts_beside_the_json(tmp_path):
    import OpenImageIO as oiio

    from rtreflect.analysis.seampicture import CLASS_COLOURS
    from rtreflect.output.imagefiles import encode_srgb

    png, report = tmp_path / "seams.png", tmp_path / "r.json"
    result = _run("continuity", "scenes/g1_join.toml", "--png", str(png), "--json", str(report), "--width", "192",
                  "--height", "108", "--samples", "1")
    assert result.returncode == 0, result.stderr
    pixels = oiio.ImageBuf(str(png)).get_pixels(oiio.UINT8)[..., :3].astype(int)
    pixels = pixels[:, 40:].reshape(-1, 3)  # right of the legend's colour swatches
    yellow = encode_srgb(np.array([[[*CLASS_COLOURS["G1"], 1.0]]], dtype=np.float32))[0, 0, :3].astype(int)
    assert np.sum(np.all(np.abs(pixels - yellow) <= 2, axis=1)) > 30  # the G1 seam, ~1 px per row it crosses
    assert (tmp_path / "r.charts.png").is_file()


def test_png_with_several_scenes_is_refused_before_anything_is_written(tmp_path):
    result = _run("continuity", "scenes/g1_join.toml", "scenes/hood.toml", "--png", str(tmp_path / "x.png"),
                  "--json", str(tmp_path / "r.json"))
    assert result.returncode == 2 and "--png" in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_render_seams_draws_the_g1_seam_in_the_png_and_leaves_the_exr_alone(tmp_path):
    """`render --seams` (issue 16): g1_join's seam gets the G1 colour in the PNG; the EXR equals a plain render's."""
    import OpenImageIO as oiio

    from rtreflect.analysis.seampicture import CLASS_COLOURS
    from rtreflect.output.imagefiles import encode_srgb

    size = ["--width", "192", "--height", "108", "--samples", "1"]
    plain = _run("render", "scenes/g1_join.toml", "-o", str(tmp_path / "plain"), *size)
    drawn = _run("render", "scenes/g1_join.toml", "-o", str(tmp_path / "seams"), "--seams", *size)
    assert plain.returncode == 0 and drawn.returncode == 0, plain.stderr + drawn.stderr
    exr = [oiio.ImageBuf(str(tmp_path / d / "g1_join.exr")).get_pixels(oiio.FLOAT) for d in ("plain", "seams")]
    np.testing.assert_array_equal(exr[0], exr[1])
    png = [oiio.ImageBuf(str(tmp_path / d / "g1_join.png")).get_pixels(oiio.UINT8).astype(int) for d in ("plain", "seams")]
    yellow = encode_srgb(np.array([[[*CLASS_COLOURS["G1"], 1.0]]], dtype=np.float32))[0, 0, :3].astype(int)
    is_yellow = [np.all(np.abs(p[:, 40:, :3] - yellow) <= 2, axis=-1) & (p[:, 40:, 3] == 255) for p in png]
    assert not is_yellow[0].any() and is_yellow[1].sum() > 30  # the G1 seam, ~1 px per row it crosses


def test_streamed_seam_filter_equals_drawing_over_the_whole_image():
    """`seam_filter` draws rows as v·M + C; over any colours (alpha 0 or 1) that must equal `draw_seams` on the whole image."""
    from rtreflect.analysis.contours import UlmetField
    from rtreflect.analysis.seamcheck import check_scene
    from rtreflect.analysis.seampicture import draw_seams, seam_filter
    from rtreflect.integrator.renderer import Renderer

    scene = load_scene(ROOT / "scenes" / "g1_join.toml").with_image(96, 54, 1)
    result, renderer = check_scene(scene, lines=False), Renderer(scene)
    rng = np.random.default_rng(16)
    background = rng.random((54, 96, 4), dtype=np.float32)
    background[..., 3] = rng.random((54, 96)) < 0.5  # a render's alpha: surface (1) or nothing (0)
    whole = draw_seams(background.copy(), UlmetField.of(renderer), result)
    draw = seam_filter(renderer, result)
    streamed = np.concatenate([draw(r, background[r:r + 7]) for r in range(0, 54, 7)])
    assert np.abs(whole - background).max() > 0.5  # something was drawn
    np.testing.assert_allclose(streamed, whole, atol=1e-5)


@pytest.mark.parametrize("name", ["mirrored_assembly.step", "bottle.step"])
def test_converted_pcurves_that_stray_from_their_edge_give_no_false_gap(tmp_path, name):
    """Where the NURBS conversion refits an edge's pcurves (a mirrored instance; the bottle's threads and neck), the
    two faces' points at the same edge parameter are the 3D edge's feet on each surface, not the refit pcurves'
    points: every edge reaches G0 (before: the mirrored copy's sphere corner open at 6.4e-4, four thread edges at
    0.29-0.30 and the neck's at 4e-3, where Open CASCADE's own edge tolerances are 1e-7 and 2.1e-6)."""
    pytest.importorskip("OCP")
    sys.path.insert(0, str(ROOT / "tools"))
    sys.path.insert(0, str(ROOT / "tests"))
    import make_sweep_parts as sweep
    from OCP.ShapeAnalysis import ShapeAnalysis_ShapeTolerance
    from OCP.TopAbs import TopAbs_EDGE
    from test_cad_reader import occt_faces

    from rtreflect.analysis.seamcheck import check_scene

    path = tmp_path / name
    sweep.PARTS[name](path)
    edges = check_scene(load_scene(path), lines=False).edges
    assert edges and all(e.cls != "open" for e in edges)
    if name == "mirrored_assembly.step":  # the faces meet to Open CASCADE's edge tolerance, as the original block's
        tolerance = ShapeAnalysis_ShapeTolerance().Tolerance(occt_faces(path)[0], 1, TopAbs_EDGE)
        assert len(edges) == 96 and all(e.cls == "G1" for e in edges)
        assert max(e.g0_max for e in edges) <= tolerance


def test_render_seams_text_fits_the_image(tmp_path):
    """`render --seams` scales its labels and legend to the image: on g1_join at 160×90 the fixed 14-px legend and
    labels changed 27 % of the PNG's pixels (the picture hidden); now the legend is left out where it would take more
    than `LEGEND_WIDTH` × `LEGEND_HEIGHT` of it, and labels stop at `LABEL_AREA` (2.4 %: the seams and a label). At
    640×360 the legend is drawn: its first swatch (top left) in the 'open' colour."""
    import OpenImageIO as oiio

    from rtreflect.analysis.seampicture import CLASS_COLOURS
    from rtreflect.output.imagefiles import encode_srgb

    def png(folder, width, height, *extra):
        result = _run("render", "scenes/g1_join.toml", "-o", str(tmp_path / folder), "--width", str(width), "--height",
                      str(height), "--samples", "1", *extra)
        assert result.returncode == 0, result.stderr
        return oiio.ImageBuf(str(next((tmp_path / folder).glob("*.png")))).get_pixels(oiio.UINT8).astype(int)

    plain, drawn = png("plain", 160, 90), png("seams", 160, 90, "--seams")
    assert np.mean(np.any(plain != drawn, axis=-1)) < 0.1
    red = encode_srgb(np.array([[[*CLASS_COLOURS["open"], 1.0]]], dtype=np.float32))[0, 0, :3].astype(int)
    large = png("large", 640, 360, "--seams")
    assert np.all(np.abs(large[12:20, 12:20, :3] - red) <= 2)


def test_edge_tangents_are_those_of_the_points_kept(tmp_path):
    """Where an edge's points are the 3D edge's feet on the surface (mirrored_assembly.step: the conversion's refit
    pcurves run along it at another speed), γ'(t) is the tangent of those feet, not of the refit pcurve: it matches the
    central differences of γ along t (to their O(Δt²) error) on every edge of every face."""
    pytest.importorskip("OCP")
    sys.path.insert(0, str(ROOT / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / "mirrored_assembly.step"
    sweep.PARTS[path.name](path)
    worst = 0.0
    for surface in load_scene(path).surfaces:
        for edge in surface.trim.edges:
            if edge.closed or edge.degenerated:
                continue
            central = (edge.uv[2:] - edge.uv[:-2]) / (edge.t[2:] - edge.t[:-2])[:, None]
            scale = np.abs(edge.duv).max()
            worst = max(worst, float(np.abs(central - edge.duv[1:-1]).max() / scale))
    assert worst < 1e-3, worst
