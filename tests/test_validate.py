"""`rtreflect validate`: traced line centres against the analytic contours (the issue's proof).

- every shipped scene validates in exact mode (max ≤ 0.5 px, p95 ≤ 0.1 px, no misses), at a
  reduced size for test time with the same thresholds;
- on the hood with tessellation 4 exact mode still validates while mesh normals are at least
  5× worse;
- a deliberately wrong renderer (normals turned by half a degree) fails: the check can fail;
- the colour image is checked: lines drawn 30% of a spacing off (the f AOV untouched) fail, and so
  do tubes seen through the surface (no occlusion test);
- missing traced lines fail (misses), and so does a scene where nothing could be compared;
- tubes sharing a position count once overall;
- the command line: table, `--json` keys, exit statuses.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from rtreflect.cli import cli
from rtreflect.integrator.renderer import Renderer
from rtreflect.exchange.scene import load_scene
from rtreflect.analysis.validate import (TracedCentres, _filter_unblocked, film_aovs, line_coverage, nearest_segment,
                                traced_centres, validate_scene)

SCENES = Path(__file__).resolve().parent.parent / "scenes"
SCENE_FILES = sorted(SCENES.glob("*.toml"))
WIDTH, HEIGHT = 320, 180
#: Scenes whose lines need more pixels than WIDTH × HEIGHT to be resolved: cup_draft's draft band edges (0°, 1°, 3°)
#: lie 1° apart in φ, and at 320 px the 0° and 1° edges crowd within 3 px over most of the cup (217 points).
SIZES = {"cup_draft": (480, 270)}


def assert_passes_every_check(report, name: str) -> None:
    """Every shipped scene passes, the teapot included: its grazing rays where the spout meets the body stored
    hits behind a nearer exact surface point until the tracer's second look (issue 11 item 2)."""
    assert report.passed and not report.reasons, report.reasons


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: p.stem)
def test_shipped_scene_validates(path: Path):
    report = validate_scene(load_scene(path).with_image(*SIZES.get(path.stem, (WIDTH, HEIGHT)), 1))
    assert report.points >= 300, "too few traced centres for the check to mean anything"
    assert report.misses == 0
    assert report.max_px <= 0.5
    assert report.p95_px <= 0.1
    assert report.colour_checked >= 500 and report.colour_mismatches == 0
    assert_passes_every_check(report, path.stem)


def test_colour_check_holds_with_supersampling():
    """s = 2: the colour comes from 4 samples per pixel, the AOVs from a separate pixel-centre ray."""
    report = validate_scene(load_scene(SCENES / "teapot.toml").with_image(WIDTH, HEIGHT, 2))
    assert report.colour_checked >= 500 and report.colour_mismatches == 0
    assert_passes_every_check(report, "teapot")


def test_orthographic_camera_tilted_light_plane_and_short_tubes_validate():
    """The general case: parallel rays (a = −w), a light plane not parallel to the xy-plane, finite tubes."""
    scene = load_scene(SCENES / "hood.toml").with_image(WIDTH, HEIGHT, 1)
    normal = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    direction = np.cross(normal, [1.0, 0.0, 0.0])
    scene = replace(scene, camera=replace(scene.camera, projection="orthographic", view_height=2.6),
                    lights=replace(scene.lights, normal=normal, direction=direction / np.linalg.norm(direction),
                                   length=3.0))
    report = validate_scene(scene)
    assert report.points >= 100
    assert report.passed and report.p95_px <= 0.1 and report.colour_checked >= 1000


def hood_with_tessellation(normals: str, tessellation: int = 4):
    scene = load_scene(SCENES / "hood.toml").with_image(WIDTH, HEIGHT, 1)
    return replace(scene, render=replace(scene.render, tessellation=tessellation, normals=normals))


def test_exact_normals_beat_mesh_normals_on_a_coarse_mesh():
    exact = validate_scene(hood_with_tessellation("exact"))
    mesh = validate_scene(hood_with_tessellation("mesh"))
    assert exact.passed and exact.p95_px <= 0.1
    assert mesh.points >= 0.9 * exact.points
    assert 5 * exact.max_px <= mesh.max_px


def test_mesh_mode_hits_the_mesh_with_interpolated_vertex_normals():
    """Mesh mode: P on the Embree triangle, N within the vertex normals' spread, (u, v) near the exact hit's."""
    exact = Renderer(hood_with_tessellation("exact"))
    mesh = Renderer(hood_with_tessellation("mesh"))
    rows, cols = np.divmod(np.arange(0, WIDTH * HEIGHT, 37), WIDTH)
    a, b = exact.pixel_aovs(rows, cols), mesh.pixel_aovs(rows, cols)
    hit = a["shading"].hits.hit & b["shading"].hits.hit
    assert hit.sum() > 100
    chord = exact.tessellation.chord_error.max()
    gap = np.linalg.norm(a["P"][hit] - b["P"][hit], axis=1)
    assert gap.max() <= 20 * chord and gap.max() > 1e-6 * chord  # near the surface, yet not on it
    cos = np.einsum("ij,ij->i", a["N"][hit], b["N"][hit])
    assert np.all(cos > np.cos(np.radians(3))) and np.any(cos < np.cos(np.radians(0.01)))
    np.testing.assert_allclose(np.linalg.norm(b["N"][hit], axis=1), 1.0, atol=1e-12)


@pytest.fixture
def wrong_renderer(monkeypatch):
    """Every normal turned by 0.5° about the y axis: a renderer with a small, systematic error."""
    angle = np.radians(0.5)
    original = Renderer.trace

    def turned(self, origins, directions, *args, **kwargs):
        hits = original(self, origins, directions, *args, **kwargs)
        n = hits.N
        axis = np.array([0.0, 1.0, 0.0])
        hits.N[:] = (n * np.cos(angle) + np.cross(axis, n) * np.sin(angle)
                     + axis * (n @ axis)[:, None] * (1 - np.cos(angle)))
        return hits

    monkeypatch.setattr(Renderer, "trace", turned)


def test_wrong_renderer_fails_validation(wrong_renderer, tmp_path):
    result = CliRunner().invoke(cli, ["validate", str(SCENES / "hood.toml"), "--width", str(WIDTH),
                                      "--height", str(HEIGHT), "--json", str(tmp_path / "report.json")])
    assert result.exit_code == 1, result.output
    report = json.loads((tmp_path / "report.json").read_text())["scenes"]["hood"]
    assert report["max_px"] > 0.5 and report["p95_px"] > 0.1
    assert "FAIL" in result.output


def test_validate_command_reports_and_passes(tmp_path):
    target = tmp_path / "reports" / "validate.json"
    result = CliRunner().invoke(cli, ["validate", str(SCENES / "hood.toml"), str(SCENES / "cylinder.toml"),
                                      "--width", "160", "--height", "90", "--json", str(target)])
    assert result.exit_code == 0, result.output + (result.stderr or "")
    assert "PASS" in result.output and "max_px" in result.output
    doc = json.loads(target.read_text())
    assert set(doc) == {"scenes"} and set(doc["scenes"]) == {"hood", "cylinder"}
    for name, scene in doc["scenes"].items():
        assert set(scene) == {"max_px", "p95_px", "mean_px", "points", "misses", "colour_mismatches",
                              "colour_checked", "reasons", "lines"}
        assert len(scene["lines"]) == len(load_scene(SCENES / f"{name}.toml").lights.positions)
        assert scene["points"] == sum(line["points"] for line in scene["lines"])
        assert scene["colour_mismatches"] == 0 and scene["colour_checked"] > 0 and scene["reasons"] == []
        assert all(line["colour_mismatches"] == 0 for line in scene["lines"])
    assert [p.name for p in target.parent.iterdir()] == ["validate.json"]  # no temporary left behind


def test_validate_fails_on_tight_tolerance_and_rejects_bad_input(tmp_path):
    options = ["--width", "160", "--height", "90"]
    tight = CliRunner().invoke(cli, ["validate", str(SCENES / "hood.toml"), "--tolerance", "1e-9", *options])
    assert tight.exit_code == 1
    missing = CliRunner().invoke(cli, ["validate", str(tmp_path / "nope.toml"), *options])
    assert missing.exit_code == 2
    assert len(missing.stderr.splitlines()) == 1 and "nope.toml" in missing.stderr


def test_nearest_segment_is_the_point_to_segment_distance():
    rng = np.random.default_rng(3)
    a = rng.uniform(0, 50, (300, 2))
    b = a + rng.uniform(-2, 2, (300, 2))
    points = rng.uniform(0, 50, (200, 2))
    dist, seg = nearest_segment(points, a, b, radius=5.0, chunk=16)
    # Reference: the closest point found by sampling each segment finely.
    t = np.linspace(0, 1, 501)[:, None]
    brute = np.column_stack([np.min(np.linalg.norm(points[:, None, :] - (a[j] + t * (b[j] - a[j]))[None], axis=2),
                                    axis=1) for j in range(len(a))])
    best = brute.min(axis=1)
    within = best <= 5.0
    np.testing.assert_allclose(dist[within], best[within], atol=5e-3)
    assert np.all(np.isinf(dist[best > 5.0 + 5e-3]))
    np.testing.assert_allclose(brute[np.flatnonzero(within), seg[within]], best[within], atol=5e-3)


@pytest.fixture
def shifted_lines(monkeypatch):
    """The reviewer's repro: the colour ('lit', eq. 4) uses tubes shifted by 30% of the spacing, AOVs untouched."""
    original = Renderer.shade

    def shade(self, origins, directions, *args, **kwargs):
        shading = original(self, origins, directions, *args, **kwargs)
        lights = replace(self.lights, c_k=self.lights.c_k + 0.3 * self.lights.spacing)
        idx = np.flatnonzero(shading.hits.hit)
        shading.lit[:] = False
        if len(idx):
            shading.lit[idx] = lights.candidates(lights.distances(shading.hits.P[idx], shading.s[idx]))[0]
        return shading

    monkeypatch.setattr(Renderer, "shade", shade)


def test_lines_drawn_in_the_wrong_place_fail_validation(shifted_lines, tmp_path):
    result = CliRunner().invoke(cli, ["validate", str(SCENES / "hood.toml"), "--width", str(WIDTH), "--height",
                                      str(HEIGHT), "--samples", "2", "--json", str(tmp_path / "report.json")])
    assert result.exit_code == 1, result.output
    report = json.loads((tmp_path / "report.json").read_text())["scenes"]["hood"]
    # The f AOV still agrees with the analytic lines: only the colour check sees the error.
    assert report["max_px"] <= 0.5 and report["misses"] == 0
    assert report["colour_mismatches"] >= 100
    assert sum(line["colour_mismatches"] > 0 for line in report["lines"]) >= 5
    assert "FAIL" in result.output


@pytest.fixture
def no_occlusion(monkeypatch):
    """A renderer that forgets the occlusion test: tubes shine through the teapot's own body."""
    original = Renderer.shade

    def shade(self, origins, directions, *args, **kwargs):
        shading = original(self, origins, directions, *args, **kwargs)
        idx = np.flatnonzero(shading.hits.hit)
        if len(idx):
            shading.lit[idx] = self.lights.candidates(self.lights.distances(shading.hits.P[idx], shading.s[idx]))[0]
        return shading

    monkeypatch.setattr(Renderer, "shade", shade)


def test_lines_seen_through_the_surface_fail_validation(no_occlusion):
    report = validate_scene(load_scene(SCENES / "teapot.toml").with_image(WIDTH, HEIGHT, 1))
    assert report.max_px <= 0.5 and report.misses == 0  # the centres are filtered for occlusion on their own
    assert report.colour_mismatches > 0 and not report.passed


@pytest.fixture
def lost_line(monkeypatch):
    """A renderer whose line.id never names tube 4: that tube's traced centres vanish."""
    original = Renderer.aovs

    def aovs(self, shading):
        out = original(self, shading)
        out["line.id"] = np.where(out["line.id"] == 4, -1.0, out["line.id"])
        return out

    monkeypatch.setattr(Renderer, "aovs", aovs)


def test_missing_traced_lines_fail_validation(lost_line):
    report = validate_scene(load_scene(SCENES / "hood.toml").with_image(WIDTH, HEIGHT, 1))
    assert report.lines[4].points == 0 and report.lines[4].misses >= 20
    assert all(line.misses == 0 for line in report.lines if line.light != 4)
    assert not report.passed and any(reason.startswith("light 4:") for reason in report.reasons)


def test_nothing_compared_fails(tmp_path):
    """Surface behind the camera, or the light plane below the surface: 0 points is a failure, not a pass."""
    hood = (SCENES / "hood.toml").read_text()
    behind = tmp_path / "behind.toml"
    behind.write_text(hood.replace("look_at = [0.0, 0.0, 0.0]", "look_at = [0.0, -6.4, 4.8]"))
    below = tmp_path / "below.toml"
    below.write_text(hood.replace("point = [0.0, 0.0, 3.0]", "point = [0.0, 0.0, -3.0]"))
    for scene in (behind, below):
        result = CliRunner().invoke(cli, ["validate", str(scene), "--width", "160", "--height", "90",
                                          "--samples", "1"])
        assert result.exit_code == 1, result.output
        assert "FAIL: no traced line centre was compared" in result.output


def test_close_up_of_a_big_curved_face_validates(tmp_path):
    """The analytic lines of a close-up come from a grid of the face's visible window, not of the whole face.

    revolved.step's automatic view narrowed to fov 0.2°: the automatic tubes fit the few millimetres seen, 12 lines
    cross the image. The contour grid was sized from a probe of the whole face, whose points all fell outside the
    image: cells hundreds of pixels wide, 1,300 analytic points missing against the traced lines."""
    scene = tmp_path / "close.toml"
    scene.write_text(f"""
[camera]
eye = [39.8212, -72.4591, 85.6889]
look_at = [-0.344032, 0.568508, 30.9182]
up = [0.0, 0.0, 1.0]
fov = 0.2

[[surface]]
file = "{(SCENES.parent / "parts" / "revolved.step").as_posix()}"
""")
    report = validate_scene(load_scene(scene).with_image(WIDTH, HEIGHT, 1))
    assert report.points >= 3000 and report.misses == 0
    assert sum(line.points >= 200 for line in report.lines) >= 10  # most of the 12 lines compared along the image
    assert report.max_px <= 0.5 and report.passed, report.reasons


def test_tubes_sharing_a_position_count_once():
    scene = load_scene(SCENES / "hood.toml").with_image(WIDTH, HEIGHT, 1)
    twice = validate_scene(replace(scene, lights=replace(scene.lights, positions=np.array([0.5, -0.5, 0.5]))))
    once = validate_scene(replace(scene, lights=replace(scene.lights, positions=np.array([0.5, -0.5]))))
    assert once.points >= 100 and once.passed and twice.passed
    assert twice.lines[0].points == twice.lines[2].points == once.lines[0].points
    assert (twice.points, twice.misses, twice.max_px) == (once.points, once.misses, once.max_px)


def test_both_pixels_of_a_centre_are_occlusion_checked_even_on_a_pixel_centre():
    """A centre exactly on pixel a's centre (δ = 0) still needs pixel b's reflected ray to reach the light plane."""
    renderer = Renderer(load_scene(SCENES / "hood.toml").with_image(160, 90, 1))
    aovs = film_aovs(renderer, renderer.render().film)
    centres = _filter_unblocked(renderer, aovs, traced_centres(renderer, aovs))
    a, b = centres.pixel_a[:1], centres.pixel_b[:1]
    row, col = np.divmod(a, 160)
    on_a = TracedCentres(np.column_stack([col + 0.5, row + 0.5]), centres.light[:1], a, b)
    assert len(_filter_unblocked(renderer, aovs, on_a).px) == 1
    aovs.s.reshape(-1, 3)[b] = -renderer.lights.m  # pixel b's reflected ray now turns away from the light plane
    assert len(_filter_unblocked(renderer, aovs, on_a).px) == 0


def test_line_coverage_inverts_the_films_colour_blend():
    from rtreflect.integrator.film import coverage_color

    rng = np.random.default_rng(5)
    hit = rng.random((200, 9)) < 0.8
    lit = rng.random((200, 9)) < 0.4
    surface, line, background = [0.18, 0.18, 0.2], [1.0, 0.9, 0.3], [0.05, 0.0, 0.1]
    rgba = coverage_color(hit, lit, surface, line, background)
    np.testing.assert_allclose(line_coverage(rgba, surface, line, background), (hit & lit).sum(axis=1) / 9, atol=1e-12)
    assert np.all(np.isnan(line_coverage(rgba, surface, surface, background)))


@pytest.mark.parametrize("offset", [0.001, 0.1])
def test_resolution_is_decided_per_line(offset, tmp_path):
    """An extra tube `offset` from tube 5 (c = 0.5) of the hood (spacing 0.5): only that pair's lines crowd.
    The render is correct, so it passes; every other line is checked exactly as without the extra tube, and
    the pair, whose lines the pixels cannot tell apart, is reported (issue 11: the smallest spacing anywhere
    was applied to every line, so 0.001 failed the scene and 0.1 checked a tenth of the points)."""
    scene = load_scene(SCENES / "hood.toml").with_image(WIDTH, HEIGHT, 1)
    baseline = validate_scene(scene)
    crowded = replace(scene, lights=replace(scene.lights, positions=np.append(scene.lights.positions, 0.5 + offset)))
    report = validate_scene(crowded)
    assert report.passed and not report.reasons, report.reasons
    pair = (5, len(report.lines) - 1)
    for line, before in zip(report.lines, baseline.lines):
        if line.light not in pair:
            assert (line.points, line.misses, line.unresolved_points) == (before.points, before.misses, 0)
    for k in pair:
        assert report.lines[k].neighbour_gap == pytest.approx(offset)
        assert report.lines[k].unresolved_points > 0.5 * report.lines[k].clean_points
        assert any(note.startswith(f"light {k} ") for note in report.notes), report.notes
    assert report.points >= baseline.points - baseline.lines[5].points
    if offset == 0.1:  # the command line shows the notes, and the JSON the per-line counts
        path = tmp_path / "crowded.toml"
        path.write_text((SCENES / "hood.toml").read_text().replace("2.0]\nradius", f"2.0, {0.5 + offset}]\nradius"))
        result = CliRunner().invoke(cli, ["validate", str(path), "--width", str(WIDTH), "--height", str(HEIGHT),
                                          "--json", str(tmp_path / "r.json")])
        assert result.exit_code == 0, result.output
        assert "note: light 5 (c_k = 0.5)" in result.output and "note: light 9 (c_k = 0.6)" in result.output
        lines = json.loads((tmp_path / "r.json").read_text())["scenes"]["crowded"]["lines"]
        assert lines[9]["unresolved_points"] > 0 and lines[0]["unresolved_points"] == 0


# --- Issue 11 item 2: a stored hit that is not the nearest exact surface point on its ray -------------------


@pytest.mark.parametrize("part", ["plate.step", "trimmed.3dm", "tiny_on_huge.step"])
def test_the_nearer_check_meshes_a_cad_face_finely_enough(part, tmp_path):
    """The nearer-hit check's own mesh (`validate.fine_mesh`) lies within `FINE_CHORD_SHARE` of the renderer's chord
    error of every face its reader meshed (the chord errors measured on both meshes, `tessellation._chord_error`),
    where it no longer takes the span grid at `fine_tessellation_factor` on every face: fewer vertices. A face whose
    reader mesh the renderer dropped (tiny_on_huge.step's pin, `reader_mesh`) is meshed by the span grid there, the
    second look's at 4×: the check's is at the full factor, never that one."""
    pytest.importorskip("OCP")
    import sys

    from rtreflect.analysis import validate as V
    from rtreflect.exchange.load import load_scene as load_any
    from rtreflect.geometry.tessellation import reader_mesh, tessellate
    from rtreflect.integrator.autorig import resolve

    path = Path(__file__).resolve().parents[1] / "parts" / part
    if not path.exists():  # a sweep part (tools/make_sweep_parts.py)
        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
        import make_sweep_parts as sweep

        path = tmp_path / part
        sweep.PARTS[part](path)
    renderer = Renderer(resolve(load_any(path).with_image(64, 36, 1)))
    fine = V.fine_mesh(renderer)
    coarse = renderer.tessellation.chord_error
    read = np.array([reader_mesh(s) is not None for s in renderer.scene.surfaces])
    assert read.any() and (coarse[read] > 0).any()
    slack = 1e-12 * renderer.tessellation.extent
    assert np.all(fine.chord_error[read] <= V.FINE_CHORD_SHARE * coarse[read] + slack)
    grids = [replace(s, mesh_uv=None) for s in renderer.scene.surfaces]
    most = V.fine_tessellation_factor(renderer) * renderer.scene.render.tessellation
    assert len(fine.vertices) < len(tessellate(grids, most, enclose=True).vertices)
    dropped = np.flatnonzero(~read & np.array([s.mesh_uv is not None for s in renderer.scene.surfaces]))
    assert (part == "tiny_on_huge.step") == (len(dropped) > 0)
    for k in dropped:
        assert len(fine.meshes[k].uv) == len(tessellate([grids[k]], most, enclose=True).vertices)


def test_validate_fails_a_hit_behind_a_nearer_surface(monkeypatch):
    """The hood and a plane cutting through it (tests/test_exact_hits.py), rendered as the old tracer did (the first
    mesh hit's refinement kept, no candidate behind it examined): near the intersection curve some pixels store the
    farther surface. `validate` flags exactly the pixels whose stored Z lies beyond the correct render's (the
    reference: the tracer that keeps the nearest candidate, itself tested against each surface alone and the
    plane's closed form), fails that render and passes the correct one."""
    from dataclasses import replace

    from test_exact_hits import hood_scene, plane_patch

    from rtreflect.analysis import validate as V
    from rtreflect.integrator.renderer import Renderer
    from rtreflect.trace import tracing
    from rtreflect.trace.secondlook import SecondLook

    scene = hood_scene(tessellation=8)  # at 4 the analytic check itself misses lines near the cut: keep this apart
    cut = plane_patch([-1.3, -1.2, 0.05], [2.6, 0.0, 0.55], [0.0, 2.4, 0.0], name="cut")
    scene = replace(scene, surfaces=(scene.surfaces[0], cut))
    # Both without the second look (secondlook.py): it also finds a hood point 3e-6 (in u) from its edge on one
    # pixel, right by tessellation 128 but closer to the edge than validate's margin (`_well_inside`) lets it judge.
    monkeypatch.setattr(SecondLook, "apply", lambda self, hits, *args, **kwargs: hits)
    right = Renderer(scene)
    good = V.film_aovs(right, right.render().film)
    with monkeypatch.context() as m:  # the old tracer: no band behind the first hit, so no later candidate
        # NaN, not −inf: every comparison with the limit is False either way, but −inf added to the t = inf of a ray
        # with no valid candidate yet warned "invalid value encountered in add" (tracing.trace).
        m.setattr(tracing, "_band", lambda tessellation, cos: np.full(len(cos), np.nan))
        wrong = Renderer(scene)
        bad = V.film_aovs(wrong, wrong.render().film)
    tol = V.ON_SURFACE * right.tessellation.extent + 2.0 * V.FLOAT32_ROUNDOFF * np.abs(good.Z)
    stored = 4.0 * V.FLOAT32_ROUNDOFF * np.abs(good.Z)  # the reference's own float32 Z: either way within this
    with np.errstate(invalid="ignore"):
        both = (bad.patch >= 0) & (good.patch >= 0)
        behind = both & (bad.Z > good.Z + tol + stored)
        maybe = both & (bad.Z > good.Z + tol - stored)
    assert behind.sum() >= 10 and not bad.fallback.any()  # wrong pixels that no fallback reports
    assert not (behind & ~bad.nearer).any() and not (bad.nearer & ~maybe).any(), \
        (np.argwhere(bad.nearer != behind), behind.sum())
    assert not good.nearer.any()
    contours = V.analytic_contours(V.UlmetField.of(right))
    report_bad = V.compare(wrong, bad, contours, V.DEFAULT_TOLERANCE_PX)
    report_good = V.compare(right, good, contours, V.DEFAULT_TOLERANCE_PX)
    assert not report_bad.passed
    assert any(f"{int(bad.nearer.sum())} pixels store an exact hit behind a nearer" in r for r in report_bad.reasons)
    assert report_good.passed, (report_good.max_px, report_good.misses, report_good.colour_mismatches,
                                report_good.reasons)


# -- the colour check under shading and soft stripe edges (issue 13) ---------------------------

BLURRED = {"shading": "lambert", "blur": 0.5}


def blurred_hood(samples: int = 2):
    """The hood with tubes 3× as wide (radius 0.15 of the 0.5 spacing): soft edges several pixels across."""
    return load_scene(SCENES / "hood.toml").with_image(WIDTH, HEIGHT, samples).replace(render=BLURRED,
                                                                                      lights={"radius": 0.15})


def test_shaded_blurred_render_validates():
    """The correct render with Lambert shading and soft edges passes, with the ramps' pixels checked too."""
    report = validate_scene(blurred_hood())
    assert report.passed, (report.reasons, report.colour_mismatches)
    assert report.colour_checked >= 500 and report.colour_mismatches == 0


@pytest.fixture
def shifted_blurred_lines(monkeypatch):
    """Lines drawn 30% of a spacing off with soft edges: the colour's 'lit' and d from shifted tubes, AOVs untouched."""
    original_shade, original_aovs = Renderer.shade, Renderer.aovs

    def shade(self, origins, directions, *args, **kwargs):
        shading = original_shade(self, origins, directions, *args, **kwargs)
        shifted = replace(self.stripe_lights, c_k=self.lights.c_k + 0.3 * self.lights.spacing)
        idx = np.flatnonzero(shading.hits.hit)
        if len(idx):
            tubes = shifted.reach(shading.hits.P[idx], shading.s[idx])
            shading.lit[idx], shading.line_dist[idx] = tubes.candidate, tubes.line_dist
        return shading

    def aovs(self, shading):  # the AOVs as the correct renderer stores them
        out = original_aovs(self, shading)
        idx = np.flatnonzero(shading.hits.hit)
        if len(idx):
            tubes = self.stripe_lights.reach(shading.hits.P[idx], shading.s[idx])
            out["line.id"], out["line.dist"] = out["line.id"].copy(), out["line.dist"].copy()
            out["line.id"][idx], out["line.dist"][idx] = tubes.line_id, tubes.line_dist
        return out

    monkeypatch.setattr(Renderer, "shade", shade)
    monkeypatch.setattr(Renderer, "aovs", aovs)


def test_shifted_lines_fail_validation_under_shading_and_blur(shifted_blurred_lines):
    report = validate_scene(blurred_hood())
    assert report.max_px <= 0.5 and report.misses == 0  # f is untouched: only the colour check sees the error
    assert report.colour_mismatches >= 100 and not report.passed
    assert sum(line.colour_mismatches > 0 for line in report.lines) >= 5


def test_line_coverage_inverts_shaded_weighted_blends():
    from rtreflect.integrator.film import coverage_color

    rng = np.random.default_rng(7)
    hit = rng.random((200, 9)) < 0.8
    weight = np.where(rng.random((200, 9)) < 0.5, rng.random((200, 9)), 0.0)
    k = rng.uniform(0.5, 1.0, 200)  # one shade per pixel: the pixel-centre's, as validate reads it
    surface, line, background = np.array([0.18, 0.18, 0.2]), [1.0, 0.9, 0.3], [0.05, 0.05, 0.05]
    rgba = coverage_color(hit, weight, surface, line, background, np.repeat(k[:, None], 9, axis=1))
    expected = np.where(hit, weight, 0).sum(axis=1) / 9
    np.testing.assert_allclose(line_coverage(rgba, k[:, None] * surface, line, background), expected, atol=1e-12)


def _within(mask: np.ndarray, r: int) -> np.ndarray:
    """Pixels within Chebyshev distance r of a True pixel of mask (the square neighbourhood `clean_pixels` grows)."""
    height, width = mask.shape
    padded = np.pad(mask, r)
    return np.any([padded[r + dy:r + dy + height, r + dx:r + dx + width]
                   for dy in range(-r, r + 1) for dx in range(-r, r + 1)], axis=0)


def test_misses_beside_a_blocked_reflected_ray_are_not_counted_and_only_there(monkeypatch):
    """The blocked-margin rule: an analytic point within CLEAN_MARGIN_PX of a pixel whose reflected ray is blocked
    is no miss; one farther from every blocked pixel still is.

    Tube 4's traced centres are removed (as `lost_line`), so each of its analytic points in clean view is a
    miss. Blocked pixels on the ring exactly CLEAN_MARGIN_PX from its points' pixels clear every miss (fails if
    the rule is dropped or its margin shrunk); blocked pixels everywhere at least CLEAN_MARGIN_PX + 1 away leave
    the misses as they were (fails if the margin reached farther, or applied to misses away from a blocked pixel).
    """
    from rtreflect.analysis import validate as V
    from rtreflect.analysis.contours import analytic_contours, field_of

    renderer = Renderer(load_scene(SCENES / "hood.toml").with_image(WIDTH, HEIGHT, 1))
    aovs = film_aovs(renderer, renderer.render().film)
    aovs.line_id[aovs.line_id == 4] = -1.0
    contours = analytic_contours(field_of(renderer))
    real_blocked = V.blocked_pixels(renderer, aovs)
    assert not real_blocked.any(), "the hood's reflected rays all reach the light plane: the only blocked pixels are ours"
    line4 = np.zeros(aovs.f.shape, dtype=bool)
    px = np.concatenate([p.px for p in contours.lines[4].polylines])
    inside = (px[:, 0] >= 0) & (px[:, 0] < WIDTH) & (px[:, 1] >= 0) & (px[:, 1] < HEIGHT)
    line4[np.floor(px[inside, 1]).astype(int), np.floor(px[inside, 0]).astype(int)] = True
    margin = V.CLEAN_MARGIN_PX

    def misses_with(blocked: np.ndarray) -> int:
        monkeypatch.setattr(V, "blocked_pixels", lambda renderer, aovs: blocked)
        return V.compare(renderer, aovs, contours, V.DEFAULT_TOLERANCE_PX).lines[4].misses

    alone = misses_with(real_blocked)
    assert alone >= 20, "tube 4 without traced centres must miss"
    ring = _within(line4, margin) & ~_within(line4, margin - 1)
    assert misses_with(ring) == 0
    assert misses_with(~_within(line4, margin)) == alone


def test_colour_bound_reaches_the_corner_samples_a_diagonal_neighbour_shows():
    """σ may bend across a pixel's diagonal (σ_xy) where its four axis neighbours are smooth: the corner samples lie
    halfway to the diagonal neighbours, so their steps bound the move too, and a pixel whose diagonal neighbour is
    another tube's is not checked (the sweep's dense_net.step at 320×180: σ 1.2 at a pixel, within 1.4 at its axis
    neighbours, −4.7 at a diagonal one; 4 of its 16 samples off the stripe a bound from the axes alone kept on).

    The hood's film with one pixel inside a line drawn as bare surface: flagged where σ is smooth all round, not once a
    diagonal neighbour's σ lies 6 radii off, nor where a diagonal neighbour sees another tube."""
    from rtreflect.analysis.validate import colour_mismatches, neighbour_gaps

    renderer = Renderer(load_scene(SCENES / "hood.toml").with_image(WIDTH, HEIGHT, 1))
    aovs = film_aovs(renderer, renderer.render().film)
    checked, _ = colour_mismatches(renderer, aovs)
    radius = renderer.lights.radius
    sigma = aovs.line_offset
    # A checked pixel well inside a line (all samples lit) and its 3 × 3 block of one tube.
    inner = checked & (np.abs(sigma) < 0.3 * radius) & (aovs.line_coverage > 0.99)
    y, x = next((y, x) for y, x in zip(*np.nonzero(inner))
                if 2 <= y < HEIGHT - 2 and 2 <= x < WIDTH - 2 and (aovs.line_id[y - 1:y + 2, x - 1:x + 2] == aovs.line_id[y, x]).all())
    aovs.line_coverage[y, x] = 0.0
    assert colour_mismatches(renderer, aovs)[1][y, x]  # the check can fail here
    aovs.line_offset[y - 1, x - 1] = sigma[y, x] - 6.0 * radius
    assert not colour_mismatches(renderer, aovs)[1][y, x]
    aovs.line_offset[y - 1, x - 1] = sigma[y, x]
    aovs.line_id[y - 1, x + 1] = aovs.line_id[y, x] + 1
    checked, wrong = colour_mismatches(renderer, aovs)
    assert not checked[y, x] and not wrong[y, x]
    # Nor where f moves by over half the spacing to the next level to an axis neighbour on the same tube: another tube
    # may be nearest between them (the sweep's dense_net.step at 160×90: f 35 apart, levels 25 apart).
    aovs.line_id[y - 1, x + 1] = aovs.line_id[y, x]
    assert colour_mismatches(renderer, aovs)[1][y, x]
    gap = neighbour_gaps(renderer.lights.c_k)[int(aovs.line_id[y, x])]
    aovs.f[y, x + 1] = aovs.f[y, x] + 0.51 * gap
    checked, wrong = colour_mismatches(renderer, aovs)
    assert not checked[y, x] and not wrong[y, x]
    aovs.f[y, x + 1] = aovs.f[y, x] + 0.49 * gap
    assert colour_mismatches(renderer, aovs)[1][y, x]


def test_a_crease_with_a_sliver_beside_it_is_no_line_of_its_own():
    """A sheet folded across a sliver: degree 1 in v, knots 0.45 and 0.55 (creases: the normal jumps there), the
    middle span 0.006 wide and rising 0.01, so the normal turns by ~60° across it (OCCT's data/iges/PRO20359-L2.igs:
    a degree-5 face's v knots, multiplicity 5, turn it by up to 7° about a sliver 0.018 wide). The pixels either side
    of the sliver hit different spans of f; pairs across it counted as smooth, and their cubic put traced centres
    2.99 px from any analytic line (a false FAIL). Pairs across a crease (a knot line where the normal jumps:
    `NurbsSurface.creases`, `normal_breaks`) are no smooth pair: validate passes, with the lines either side compared."""
    from rtreflect.analysis.validate import validate_scene
    from rtreflect.geometry.surfaces import NurbsSurface

    scene = load_scene(SCENES / "hood.toml").with_image(320, 180, 1)
    ys, zs = [-1.0, -0.003, 0.003, 1.0], [0.0, 0.12, 0.13, 0.0]
    points = np.array([[[x, y, z + 0.1 * x * x] for y, z in zip(ys, zs)] for x in np.linspace(-1.0, 1.0, 4)])
    fold = NurbsSurface(3, 1, np.array([0, 0, 0, 0, 1, 1, 1, 1.0]), np.array([0, 0, 0.45, 0.55, 1, 1.0]), points,
                        np.ones((4, 4)), name="fold")
    renderer = Renderer(replace(scene, surfaces=(fold,)))
    report = validate_scene(renderer.scene, renderer=renderer).to_json()
    assert report["reasons"] == [] and report["misses"] == 0
    assert report["points"] > 400 and report["max_px"] <= 0.01


def test_level_set_normals_match_the_closed_form_of_an_affine_view():
    """φ = a·u + b·v seen through an affine projection x = (u, v) A + x0 (A's rows x_u, x_v): the image gradient of φ is
    A⁻¹ (a, b), so the
    level set's unit normal is that, normalised (`validate.level_set_normals`, which `compare` measures the distance of
    a traced centre to an exact root across the level set by: along the pixel axis it is longer by 1/sin of the slant).
    Near the domain's edge the differences are taken inside it."""
    from types import SimpleNamespace

    from rtreflect.analysis.validate import level_set_normals

    A = np.array([[3.0, 0.4], [-1.2, 2.5]])  # rows: x_u, x_v
    a, b = 0.7, -2.0

    class AffineField:
        surfaces = SimpleNamespace(domains=lambda patch: (np.zeros(len(patch)), np.ones(len(patch)),
                                                          np.zeros(len(patch)), np.ones(len(patch))))

        @staticmethod
        def f(patch, u, v):
            return a * u + b * v

        @staticmethod
        def project(patch, u, v):
            return np.stack([u, v], 1) @ A + np.array([5.0, 7.0]), None

    u = np.array([0.3, 0.0, 1.0, 0.5])
    v = np.array([0.6, 0.2, 1.0, 1.0])
    normals = level_set_normals(AffineField(), np.zeros(4, dtype=int), u, v)
    g = np.linalg.solve(A, np.array([a, b]))
    assert np.allclose(normals, g / np.linalg.norm(g), atol=1e-9)
