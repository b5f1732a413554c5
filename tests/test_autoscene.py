"""Issue 13: from a part to a useful picture without trial and error.

- Each shipped scene with [camera] and [lights] removed, and each shipped CAD part given as
  the scene, frames the whole part (no surface pixel on the image border, the surface on at
  least a quarter of the frame) and shows at least 8 distinct lines (pixel centres within a
  tube's radius, eq. 4) spread over the surface that reflects into the light plane.
- The four silent cases each print their one-line warning (exit 0; --strict exits 1), and a
  picture with lines prints none.
- `validate` fails lights below the surface and a camera that sees nothing, with reasons
  that tell the two apart.
- `rtreflect init` writes every key and parses back into the same scene; the EXR header
  records the rig the render used.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from rtreflect.cli import cli
from rtreflect.exchange.load import load_scene
from rtreflect.exchange.scene import TABLE_KEYS, _spec_table
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.output.imagefiles import CAMERA_ATTRIBUTE, LIGHTS_ATTRIBUTE, read_provenance

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted((ROOT / "scenes").glob("*.toml"))
PARTS = sorted(p for p in (ROOT / "parts").iterdir() if p.suffix.lower() in (".step", ".stp", ".igs", ".iges", ".3dm"))
#: Tests render at a sixth of the default size (160×90 for the scenes' 960×540), 2×2 samples.
SHRINK = 6


def without_rig(scene_file: Path, folder: Path, keep: str = "") -> Path:
    """A copy of a scene file without its [camera] and [lights] tables (geometry paths made absolute)."""
    lines, skip = [], False
    for line in scene_file.read_text().splitlines():
        if line.startswith("["):
            skip = line.strip() in ("[camera]", "[lights]")
        if not skip:
            lines.append(line.replace('file = "', f'file = "{scene_file.parent}/'))
    out = folder / scene_file.name
    out.write_text("\n".join(lines) + "\n" + keep)
    return out


def small(scene):
    return scene.with_image(scene.image.width // SHRINK, scene.image.height // SHRINK, 2)


def picture_facts(scene) -> dict:
    """Border hits, covered share, distinct drawn lines and their spread over the reflecting surface, and the share
    of the seen surface that reflects into the light plane (highlight lines: their own, ranked in their φ)."""
    renderer = Renderer(scene)
    result = renderer.render(threads=1)
    alpha, f = result.rgba[..., 3], result.aov("f")
    ids, dist = result.aov("line.id"), result.aov("line.dist")
    if scene.render.mode == "highlight":  # the tubes' highlight lines (the EXR's line.id is the reflected ray's tube)
        from rtreflect.analysis.validate import film_aovs, mode_aovs

        aovs = mode_aovs(renderer, result.film, film_aovs(renderer, result.film))
        f, ids, dist = aovs.f, aovs.line_id, aovs.line_dist
    border = np.concatenate([alpha[0], alpha[-1], alpha[:, 0], alpha[:, -1]])
    seen = alpha > 0
    drawn = seen & (ids >= 0) & (dist <= scene.lights.radius)
    lines = np.unique(ids[drawn]).astype(int)
    # Spread: each line's median rank of f among the pixels reflecting into the plane; the largest gap
    # between neighbouring lines (and the ends) is the largest share of that surface without a line.
    reflecting = seen & np.isfinite(f)
    order = np.argsort(f[reflecting], kind="stable")
    rank = np.full(f.shape, np.nan)
    ranks = np.empty(len(order))
    ranks[order] = (np.arange(len(order)) + 0.5) / len(order)
    rank[reflecting] = ranks
    medians = sorted(float(np.nanmedian(rank[drawn & reflecting & (ids == k)])) for k in lines
                     if np.any(drawn & reflecting & (ids == k)))
    gaps = np.diff([0.0, *medians, 1.0])
    return {"border": int(np.count_nonzero(border > 0)), "covered": float(seen.mean()), "lines": len(lines),
            "largest_gap": float(gaps.max()), "reaching": float(reflecting.sum() / max(seen.sum(), 1))}


@pytest.mark.parametrize("source", SCENES + PARTS, ids=[p.name for p in SCENES + PARTS])
def test_automatic_scene_frames_the_part_with_lines_spread_over_it(source: Path, tmp_path: Path) -> None:
    scene_file = without_rig(source, tmp_path) if source.suffix == ".toml" else source
    scene = resolve(small(load_scene(scene_file)))
    assert not scene.automatic
    facts = picture_facts(scene)
    assert facts["border"] == 0, facts  # the whole part in the frame
    assert facts["covered"] >= 0.25, facts  # and filling it
    assert facts["lines"] >= 8, facts
    assert facts["largest_gap"] <= 0.35, facts  # no third of the reflecting surface without a line


def test_explicit_keys_win(tmp_path: Path) -> None:
    keep = "[camera]\nview = \"top\"\nfov = 30.0\n\n[lights]\nauto = true\ncount = 9\nradius = 0.02\ndirection = [1.0, 0.0, 0.0]\n"
    scene = resolve(small(load_scene(without_rig(ROOT / "scenes" / "hood.toml", tmp_path, keep))))
    camera, lights = scene.camera, scene.lights
    assert camera.fov == 30.0 and np.allclose(np.cross(camera.look_at - camera.eye, [0, 0, 1]), 0)  # from above
    assert len(lights.positions) == 9 and lights.radius == 0.02 and np.allclose(lights.direction, [1, 0, 0])
    assert np.allclose(lights.normal, [0, 0, 1])
    # The camera given in full stays where it was.
    explicit = load_scene(ROOT / "scenes" / "hood.toml")
    assert resolve(explicit) is explicit


def test_a_trimmed_face_meshed_by_whole_cells_is_framed_by_its_trim() -> None:
    """A disc trimmed from a bicubic patch, meshed by its span grid (no reader's triangulation): the cells reach past
    the disc (at tessellation 3 the mesh's box was 2.2× the disc's, the disc 41 % of the frame). The top view is
    fitted to the disc itself: its diameter 0.6 (x = −1 + 2u, the loop's radius 0.15 in u and v) × `FRAME_MARGIN`."""
    import dataclasses

    from rtreflect import Scene, render
    from rtreflect.geometry.trims import Trim
    from rtreflect.trace.framing import FRAME_MARGIN

    t = np.linspace(-1.0, 1.0, 4)
    x, y = np.meshgrid(t, t, indexing="ij")
    bezier = [0, 0, 0, 0, 1, 1, 1, 1]
    scene = Scene(surfaces=[{"degree": 3, "points": np.stack([x, y, 0.3 * x * y], axis=-1), "knots_u": bezier,
                             "knots_v": bezier}],
                  camera={"view": "top", "projection": "orthographic"}, image={"width": 160, "height": 160,
                                                                                "samples": 1},
                  render={"tessellation": 3})
    angle = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False)
    disc = Trim(np.column_stack([0.2 + 0.15 * np.cos(angle), 0.25 + 0.15 * np.sin(angle)]))
    scene = resolve(scene.replace(surfaces=[dataclasses.replace(scene.surfaces[0], trim=disc)]))
    assert scene.camera.view_height == pytest.approx(0.6 * FRAME_MARGIN, rel=1e-3)
    assert np.allclose(scene.camera.look_at[:2], [-1.0 + 2 * 0.2, -1.0 + 2 * 0.25])
    seen = render(scene).rgba[..., 3] > 0
    rows, cols = np.flatnonzero(seen.any(axis=1)), np.flatnonzero(seen.any(axis=0))
    assert rows.min() > 0 and cols.min() > 0 and rows.max() < 159 and cols.max() < 159  # the whole disc in view
    assert min(np.ptp(rows), np.ptp(cols)) + 1 >= 160 / FRAME_MARGIN - 2  # and filling it


def test_the_part_keeps_its_faces_inside_where_they_bulge_past_their_loops() -> None:
    """`part_points` of a dome trimmed to a disc round its top: seen from the side the part reaches up to the dome's
    top, inside the disc, where only the mesh vertices on the face are (its loop lies 0.08 lower); the highest point
    is the dome's highest over the disc (sampled densely on the surface itself) to within the mesh's chord error."""
    import dataclasses

    from rtreflect.geometry.surfaces import NurbsSurface, SurfaceSet
    from rtreflect.geometry.tessellation import tessellate
    from rtreflect.geometry.trims import Trim
    from rtreflect.integrator.autorig import part_points

    t = np.linspace(-1.0, 1.0, 4)
    x, y = np.meshgrid(t, t, indexing="ij")
    dome = NurbsSurface.bezier(np.stack([x, y, 0.4 * (1 - x ** 2) * (1 - y ** 2)], axis=-1))
    angle = np.linspace(0.0, 2.0 * np.pi, 100, endpoint=False)
    face = dataclasses.replace(dome, trim=Trim(np.column_stack([0.5 + 0.3 * np.cos(angle), 0.5 + 0.3 * np.sin(angle)])))
    mesh = tessellate([face], 12, enclose=True)
    points = part_points(mesh, SurfaceSet([face]))
    radius, theta = np.meshgrid(np.linspace(0.0, 0.3, 60), angle, indexing="ij")
    top = face.evaluate(0.5 + (radius * np.cos(theta)).ravel(), 0.5 + (radius * np.sin(theta)).ravel()).S[:, 2].max()
    rim = face.evaluate(*face.loop_uv().T).S[:, 2].max()
    assert top - rim > 0.05  # the loop alone would miss the top
    assert points[:, 2].max() == pytest.approx(top, abs=2.0 * mesh.chord_error.max())
    assert face.trim.contains(*mesh.vertex_uv.T).sum() < len(mesh.vertices)  # some vertices lie past the disc: left out
    uv_of_points_inside = mesh.vertex_uv[face.trim.contains(*mesh.vertex_uv.T)]
    assert len(points) == len(uv_of_points_inside) + len(face.loop_uv())


# -- warnings ------------------------------------------------------------------------------------
HOOD = ROOT / "scenes" / "hood.toml"
WARNING_CASES = {
    "camera looks away": ("[camera]", "[camera]\nlook_at = [0.0, -20.0, 2.0]\n", "the camera sees no surface"),
    "lights below": ("point = [0.0, 0.0, 3.0]", "point = [0.0, 0.0, -3.0]", "no reflected ray reaches the light plane"),
    "one tube": ("positions = [-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0]", "positions = [0.0]",
                 "distinct reflected line"),
    "narrow bank": ("positions = [-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0]",
                    "positions = [-0.1, -0.05, 0.0, 0.05, 0.1]",
                    "of the visible surface reflects past the tube bank"),
}


def hood_variant(tmp_path: Path, old: str, new: str) -> Path:
    text = HOOD.read_text()
    if old == "[camera]":  # replace the look_at line of the camera
        text = re.sub(r"look_at = \[.*\]", "look_at = [0.0, -20.0, 2.0]", text, count=1)
    else:
        assert old in text, old
        text = text.replace(old, new, 1)
    path = tmp_path / "hood.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("case", WARNING_CASES, ids=list(WARNING_CASES))
def test_silent_cases_warn_and_strict_fails(case: str, tmp_path: Path) -> None:
    old, new, expected = WARNING_CASES[case]
    scene = hood_variant(tmp_path, old, new)
    options = ["-o", str(tmp_path / "out"), "--width", "96", "--height", "54", "--samples", "1"]
    result = CliRunner().invoke(cli, ["render", str(scene), *options])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if line.startswith("rtreflect: warning:")]
    assert warnings and all(line.startswith(f"rtreflect: warning: {scene}: ") for line in warnings), result.stderr
    assert any(expected in line for line in warnings), warnings
    strict = CliRunner().invoke(cli, ["render", str(scene), *options, "--strict"])
    assert strict.exit_code == 1 and expected in strict.stderr


@pytest.mark.parametrize("samples", ["analytic", "1", "2"])
def test_the_eye_inside_a_closed_part_warns_that_every_line_is_blocked(samples: str, tmp_path: Path) -> None:
    """The eye inside the filleted block looking at its floor: 1344 of 96×54 pixel centres see a tube within its
    radius, and the block's ceiling blocks each reflected ray before it. The picture has no line; `render` said
    nothing (the count of distinct lines took the blocked ones), now one warning says why (each render path: the
    analytic one tests occlusion itself, an even sample grid traces the centre rays apart)."""
    pytest.importorskip("OCP")
    scene = tmp_path / "inside.toml"
    scene.write_text(f"""
[camera]
eye = [20.0, 15.0, 10.0]
look_at = [20.0, 25.0, 0.0]

[lights]
point = [20.0, 35.0, 60.5]
normal = [0.0, 0.0, 1.0]
direction = [1.0, 0.0, 0.0]
spacing = 15.3
count = 12
radius = 1.53

[[surface]]
file = "{(ROOT / 'parts' / 'filleted_block.step').as_posix()}"
""")
    options = ["-o", str(tmp_path / "out"), "--width", "96", "--height", "54", "--samples", samples]
    result = CliRunner().invoke(cli, ["render", str(scene), *options])
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if line.startswith("rtreflect: warning:")]
    assert len(warnings) == 1 and "the part blocks every reflected ray that reaches a tube" in warnings[0], warnings
    assert "eye inside the part" in warnings[0]
    film = Renderer(resolve(load_scene(scene).with_image(96, 54, samples if samples == "analytic" else int(samples))))
    pixels = film.render(threads=1).film
    reaching = (pixels.channel("line.dist") <= 1.53) & (pixels.channel("A") > 0)
    assert reaching.sum() > 500  # the tubes are reflected: it is the blocking that hides them
    assert np.allclose(pixels.channel("R")[reaching], pixels.channel("R")[reaching].min(), atol=0.05)  # no line


def test_a_picture_with_lines_warns_nothing(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["render", str(HOOD), "-o", str(tmp_path), "--width", "96", "--height", "54",
                                      "--samples", "1", "--strict"])
    assert result.exit_code == 0 and "warning" not in result.stderr, result.stderr


def test_batch_reports_warnings(tmp_path: Path) -> None:
    old, new, expected = WARNING_CASES["lights below"]
    scene = hood_variant(tmp_path, old, new)
    options = ["-o", str(tmp_path / "out"), "-j", "1", "--json", str(tmp_path / "report.json")]
    variant = scene.read_text().replace("width = 960", "width = 96").replace("height = 540", "height = 54")
    scene.write_text(variant)
    result = CliRunner().invoke(cli, ["batch", str(scene), *options, "--strict"])
    assert result.exit_code == 1 and expected in result.stderr, result.output


def test_validate_fails_lights_below_and_an_empty_view_with_distinct_reasons(tmp_path: Path) -> None:
    options = ["--width", "160", "--height", "90", "--samples", "1"]
    below = hood_variant(tmp_path, *WARNING_CASES["lights below"][:2])
    result = CliRunner().invoke(cli, ["validate", str(below), *options])
    assert result.exit_code == 1, result.output
    assert "no tube is reflected where the camera sees the surface" in result.output
    away_dir = tmp_path / "away"
    away_dir.mkdir()
    away = hood_variant(away_dir, *WARNING_CASES["camera looks away"][:2])
    result = CliRunner().invoke(cli, ["validate", str(away), *options])
    assert result.exit_code == 1 and "FAIL: no traced line centre was compared (the camera sees no surface)" in result.output, result.output
    assert "no tube is reflected" not in result.output


# -- init and the header ------------------------------------------------------------------------
@pytest.mark.parametrize("source", [HOOD, ROOT / "parts" / "filleted_block.step", "hood-without-rig"],
                         ids=["hood", "filleted_block.step", "hood-without-rig"])
def test_init_writes_every_key_and_parses_back_into_the_same_scene(source, tmp_path: Path, monkeypatch) -> None:
    if source == "hood-without-rig":
        source = without_rig(HOOD, tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    result = CliRunner().invoke(cli, ["init", str(source)])
    assert result.exit_code == 0, result.output + result.stderr
    text = result.stdout
    (work / "scene.toml").write_text(text)
    for table, keys in TABLE_KEYS.items():
        if table in ("", "surface"):
            continue
        for key in keys:  # every key present (spacing and count as comments: positions stand for them)
            assert re.search(rf"^(# )?{key} = .*", text, re.M), f"{table}.{key} missing"
    settings = text.split("[[surface]]")[0]  # every key of the tables commented (the patches are numbers)
    assert all("#" in line for line in settings.splitlines() if " = " in line)
    original = resolve(load_scene(source))
    again = load_scene(work / "scene.toml")
    assert not again.automatic
    for table in ("image", "camera", "lights", "render", "output"):
        assert _tables_equal(_spec_table(getattr(again, table)), _spec_table(getattr(original, table))), table
    assert len(again.surfaces) == len(original.surfaces)
    for a, b in zip(again.surfaces, original.surfaces):
        assert np.array_equal(a.points, b.points) and np.array_equal(a.weights, b.weights)


def _tables_equal(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(np.asarray(a[k]), np.asarray(b[k])) for k in a)


def test_the_exr_header_records_the_rig_rendered(tmp_path: Path) -> None:
    source = without_rig(HOOD, tmp_path)
    result = CliRunner().invoke(cli, ["render", str(source), "-o", str(tmp_path / "out"), "--width", "96",
                                      "--height", "54", "--samples", "1"])
    assert result.exit_code == 0, result.output
    summary = next(line for line in result.output.splitlines() if line.startswith("hood: 96×54"))
    assert "; automatic camera: iso view" in summary and "; automatic lights: 12 tubes" in summary, summary
    header = read_provenance(tmp_path / "out" / "hood.exr")
    rig = tomllib.loads(f"camera = {header[CAMERA_ATTRIBUTE]}\nlights = {header[LIGHTS_ATTRIBUTE]}")
    rendered = resolve(load_scene(source).with_image(96, 54, 1))
    assert np.array_equal(rig["camera"]["eye"], rendered.camera.eye)
    assert np.array_equal(rig["lights"]["positions"], rendered.lights.positions)
    # Pasted into the scene, it renders the same picture.
    fixed = source.read_text() + "\n[camera]\n" + "\n".join(f"{k} = {v}" for k, v in _toml_items(header[CAMERA_ATTRIBUTE])) \
        + "\n\n[lights]\n" + "\n".join(f"{k} = {v}" for k, v in _toml_items(header[LIGHTS_ATTRIBUTE])) + "\n"
    (tmp_path / "fixed.toml").write_text(fixed)
    again = load_scene(tmp_path / "fixed.toml").with_image(96, 54, 1)
    assert np.array_equal(Renderer(again).render(threads=1).rgba, Renderer(rendered).render(threads=1).rgba)


def _toml_items(inline: str):
    """``key = value`` texts of a one-line TOML inline table, in order."""
    from rtreflect.exchange.scenewriter import toml_value

    return [(key, toml_value(value)) for key, value in tomllib.loads(f"t = {inline}")["t"].items()]


@pytest.mark.parametrize("name", ["loft_skin_edge_on.step", "bottle.step"])
def test_a_part_reflecting_sideways_gets_the_wall_on_the_camera_side(name: str, tmp_path: Path, monkeypatch) -> None:
    """A wall seen from above (a door skin, a bottle) reflects the 3/4 view's rays down and sideways: towards the plane
    above, 0 % (the skin) and 16 % (the bottle) of its visible surface reaches it: the skin shows no line, the bottle
    its lines crowded on its shoulder and a patch of its side. The rig takes the vertical wall on the camera's side instead, and its lines spread over the surface as on the
    shipped parts; with the choice turned off (`MIN_REACH_FRACTION` 0) the plane above comes back, as before."""
    pytest.importorskip("OCP")
    import sys

    sys.path.insert(0, str(ROOT / "tools"))
    import make_sweep_parts as sweep

    path = tmp_path / name
    sweep.PARTS[name](path)
    scene = resolve(small(load_scene(path)))
    up = np.asarray(scene.camera.up, dtype=float)
    assert abs(scene.lights.normal @ up) < 1e-12 and abs(scene.lights.direction @ up) < 1e-12  # a wall, tubes level
    facts = picture_facts(scene)
    assert facts["lines"] >= 8 and facts["largest_gap"] <= 0.35 and facts["reaching"] >= 0.6, facts
    from rtreflect.integrator import autorig

    monkeypatch.setattr(autorig, "MIN_REACH_FRACTION", 0.0)
    above = resolve(small(load_scene(path)))
    assert abs(abs(above.lights.normal @ up) - 1.0) < 1e-12
    assert picture_facts(above)["reaching"] <= 0.2


def test_a_camera_inside_the_part_gets_its_lights_inside(tmp_path: Path, monkeypatch) -> None:
    """The sweep's closed_room.step (a 60 × 50 × 30 box filleted all round) seen from inside: the bank below the part
    (the eye is below its centre) reached 0 lines, every reflected ray meeting a wall first, and nothing warned (f and
    line.id ignore what blocks a reflected ray). The rig tries the plane near the top inside and keeps it: lines on
    the floor and walls, read here from the picture's colour (white lines over a grey surface)."""
    pytest.importorskip("OCP")
    import sys

    sys.path.insert(0, str(ROOT / "tools"))
    import make_sweep_parts as sweep
    from rtreflect.integrator import autorig

    path = tmp_path / "closed_room.step"
    sweep.PARTS[path.name](path)
    inside = load_scene(path).replace(image={"width": 160, "height": 90, "samples": 1},
                                      camera={"eye": [10.0, 8.0, 12.0], "look_at": [60.0, 50.0, 5.0], "fov": 70.0})

    def lit(scene):
        result = Renderer(scene).render(threads=1)
        bright = np.all(result.rgba[..., :3] > 0.9, axis=-1)
        return float(bright.mean()), len(np.unique(result.aov("line.id")[bright]))

    scene = resolve(inside)
    assert 0.0 < scene.lights.point[2] < 30.0 and abs(scene.lights.normal[2]) == 1.0  # a level plane in the room
    share, lines = lit(scene)
    assert share > 0.05 and lines >= 6, (share, lines)
    # Blocking not looked at (as before): the plane outside stays.
    monkeypatch.setattr(autorig, "reaches_light_plane", lambda scene, lights, R, n, patch, s: np.ones(len(R), bool))
    outside = resolve(inside)
    assert outside.lights.point[2] < 0.0 and lit(outside)[0] < 0.001


@pytest.mark.parametrize("name", ["trimmed_face.step", "trimmed.3dm"])
def test_automatic_tubes_of_highlight_lines_span_the_normal_lines_field(name: str) -> None:
    """Highlight lines are where the normal line (either way) meets a tube, so the automatic bank spans that field's
    10-90 % over the visible surface, not the reflected rays'. Before, the bank sat round the reflections' range and
    every visible pixel's highlight φ lay outside it (−171° to −137° on these parts): no line on the part, and
    validate failed with nothing compared. φ here is the render's own channel, the closed form e·(R + λn − Q)."""
    from rtreflect.analysis.validate import validate_scene

    scene = load_scene(ROOT / "parts" / name).replace(image={"width": 160, "height": 90, "samples": 1},
                                                      render={"mode": "highlight"})
    resolved = resolve(scene)
    renderer = Renderer(resolved)
    phi = renderer.render(None, 1).film.channel("phi")
    seen = phi[np.isfinite(phi) & (renderer.render(None, 1).film.channel("patch") >= 0)]
    c_k = renderer.lights.c_k
    between = np.mean((seen >= c_k.min()) & (seen <= c_k.max()))
    assert between > 0.7, (between, c_k.min(), c_k.max(), np.percentile(seen, [10, 90]))
    report = validate_scene(resolved, threads=1, renderer=renderer)
    assert report.passed and report.points > 100, report.reasons


def test_a_highlight_render_with_lines_warns_nothing_of_reflected_lines(tmp_path: Path) -> None:
    """The render's warnings count reflection lines (f, line.id: the reflected ray's in every mode): a highlight
    render of trimmed_face.step with its twelve lines on the part warned "0 distinct reflected lines visible" and
    "96 % of the visible surface reflects past the tube bank". Another mode gets only "the camera sees no surface"."""
    scene = tmp_path / "highlight.toml"
    scene.write_text(f'[image]\nwidth = 160\nheight = 90\n[[surface]]\nfile = "{ROOT / "parts" / "trimmed_face.step"}"\n'
                     '[render]\nmode = "highlight"\n')
    result = CliRunner().invoke(cli, ["render", str(scene), "--threads", "1", "-o", str(tmp_path)])
    assert result.exit_code == 0, result.output
    assert "warning" not in result.output, result.output
