"""End-to-end checks of rendered AOVs against independent computations.

For sample pixels of every shipped scene: P lies on the pixel-centre ray, P = S(u, v)
and N equal rhino3dm's PointAt / NormalAt, f and line.dist match values recomputed
from P, the independent normal and the eye (the paper's eq. 5 where the light plane is
z = z0 with tubes along y, a brute-force ray/plane intersection otherwise; least-squares
line distances); and the same relations hold on the EXR read back.
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from reference import angle_between, closest_line_distance, rhino_points_normals
from rtreflect import __version__
from rtreflect.integrator.film import CHANNELS
from rtreflect.output.imagefiles import read_image, save_render
from rtreflect.integrator.renderer import Renderer
from rtreflect.exchange.scene import load_scene

SCENES = Path(__file__).resolve().parent.parent / "scenes"
SCENE_FILES = sorted(SCENES.glob("*.toml"))
WIDTH, HEIGHT = 160, 90
SAMPLE_PIXELS = 60


def sample_pixels(aovs: dict, count: int = SAMPLE_PIXELS, seed: int = 0) -> np.ndarray:
    """Flat indices of pixel centres that hit the surface with a converged Newton refinement."""
    good = np.flatnonzero(aovs["shading"].hits.hit & ~aovs["shading"].hits.fallback)
    rng = np.random.default_rng(seed)
    return np.sort(rng.choice(good, size=min(count, len(good)), replace=False))


def eye_vectors(renderer: Renderer, P: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """a: unit vectors from P to the eye (perspective) or the reversed view direction (orthographic)."""
    if renderer.camera.orthographic:
        return -np.broadcast_to(renderer.camera.basis[0], P.shape)
    a = renderer.scene.camera.eye - P
    return a / np.linalg.norm(a, axis=1, keepdims=True)


def reference_f(renderer: Renderer, P: np.ndarray, s: np.ndarray) -> np.ndarray:
    lights = renderer.scene.lights
    i, j, k = np.eye(3)
    if np.allclose(lights.normal, k) and np.allclose(lights.direction, j):
        # Paper eq. (5): f = [(s × r)·j + z0 (s·i)] / (s·k), light plane z = z0, lights x = c.
        z0 = lights.point[2]
        f = (np.cross(s, P) @ j + z0 * (s @ i)) / (s @ k)
        return f - lights.point[0]  # positions c_k are measured from Q along e = i
    # Brute force: walk along the reflected ray to the light plane, read the coordinate across the tubes.
    m, c, Q = lights.normal, lights.direction, lights.point
    e = np.cross(c, m) / np.linalg.norm(np.cross(c, m))
    t = ((Q - P) @ m) / (s @ m)
    return (P + t[:, None] * s - Q) @ e


def orthographic(scene):
    return replace(scene, camera=replace(scene.camera, projection="orthographic", view_height=2.4))


# Every shipped scene, plus the hood through an orthographic camera (parallel rays, a = −w).
CASES = [(path, None) for path in SCENE_FILES] + [(SCENES / "hood.toml", orthographic)]


@pytest.fixture(scope="module", params=CASES, ids=lambda case: case[0].stem + ("-ortho" if case[1] else ""))
def rendered(request):
    path, variant = request.param
    scene = load_scene(path).with_image(WIDTH, HEIGHT, 1)
    if variant:
        scene = variant(scene)
    renderer = Renderer(scene)
    rows, cols = np.divmod(np.arange(WIDTH * HEIGHT), WIDTH)
    aovs = renderer.pixel_aovs(rows, cols)
    return renderer, aovs, sample_pixels(aovs)


def test_scene_has_enough_exact_hits(rendered):
    renderer, aovs, pick = rendered
    assert len(pick) == SAMPLE_PIXELS, f"{renderer.scene.path.name}: too few converged hits to test"
    hits = aovs["shading"].hits
    assert hits.fallback.sum() <= 0.01 * hits.hit.sum(), "more than 1% of hits fell back to the mesh"


def test_hit_point_lies_on_the_pixel_centre_ray(rendered):
    _, aovs, pick = rendered
    sh = aovs["shading"]
    rel = aovs["P"][pick] - sh.origins[pick]
    along = np.einsum("ij,ij->i", rel, sh.directions[pick])
    off_ray = np.linalg.norm(rel - along[:, None] * sh.directions[pick], axis=1)
    assert np.all(off_ray <= 1e-9 * along)
    np.testing.assert_allclose(aovs["Z"][pick], along, rtol=1e-12)


def test_point_and_normal_match_rhino3dm(rendered):
    renderer, aovs, pick = rendered
    ref_P, ref_N = rhino_points_normals(renderer.scene.surfaces, aovs["patch"][pick].astype(int), aovs["u"][pick],
                                        aovs["v"][pick])
    scale = renderer.tessellation.extent
    assert np.max(np.linalg.norm(aovs["P"][pick] - ref_P, axis=1)) <= 1e-9 * scale
    ours = aovs["N"][pick]
    angle = np.minimum(angle_between(ours, ref_N), angle_between(ours, -ref_N))  # ours faces the camera
    assert np.max(angle) <= 1e-9


def test_f_and_line_distance_match_recomputation(rendered):
    renderer, aovs, pick = rendered
    _, ref_N = rhino_points_normals(renderer.scene.surfaces, aovs["patch"][pick].astype(int), aovs["u"][pick],
                                    aovs["v"][pick])
    P = aovs["P"][pick]
    a = eye_vectors(renderer, P, aovs["shading"].directions[pick])
    n = ref_N / np.linalg.norm(ref_N, axis=1, keepdims=True)
    s = 2 * np.einsum("ij,ij->i", a, n)[:, None] * n - a  # the sign of n does not matter here
    lights = renderer.scene.lights
    toward_plane = (s @ lights.normal) * ((lights.point - P) @ lights.normal)
    away = toward_plane < 0
    assert np.all(np.isnan(aovs["f"][pick][away])), "f must be NaN where the reflected ray never meets the light plane"
    well_ahead = toward_plane > 1e-3  # not grazing the plane, where f is ill-conditioned
    assert well_ahead.sum() > 0.3 * len(pick), "test set-up: too few reflected rays reach the light plane"
    np.testing.assert_allclose(aovs["f"][pick][well_ahead], reference_f(renderer, P, s)[well_ahead], rtol=1e-7, atol=1e-7)

    tubes = renderer.lights
    for row, (R, sr) in enumerate(zip(P, s)):
        found = [closest_line_distance(R, sr, B, tubes.c) for B in tubes.points]
        ahead = [(d, k) for k, (d, t) in enumerate(found) if t > 0]
        k = int(aovs["line.id"][pick[row]])
        if not ahead:
            assert k == -1 and np.isnan(aovs["line.dist"][pick[row]])
            continue
        d_best, k_best = min(ahead)
        assert k == k_best
        assert abs(aovs["line.dist"][pick[row]] - d_best) <= 1e-8 * (1 + d_best)


def test_exr_read_back_keeps_the_relations(rendered, tmp_path):
    renderer, aovs, pick = rendered
    result = renderer.render()
    files = save_render(result, tmp_path)
    pixels, names, attrs = read_image(files[0])
    assert set(names) == set(CHANNELS)
    flat = pixels.reshape(-1, len(names))
    ch = {name: flat[:, names.index(name)].astype(np.float64) for name in names}
    P = np.column_stack([ch["P.X"], ch["P.Y"], ch["P.Z"]])[pick]
    N = np.column_stack([ch["N.X"], ch["N.Y"], ch["N.Z"]])[pick]
    scale = renderer.tessellation.extent + np.abs(aovs["P"][pick]).max()
    assert np.max(np.abs(P - aovs["P"][pick])) <= 1e-6 * scale
    assert np.max(angle_between(N, aovs["N"][pick])) <= 1e-6
    sh = aovs["shading"]
    rel = P - sh.origins[pick]
    along = np.einsum("ij,ij->i", rel, sh.directions[pick])
    assert np.all(np.linalg.norm(rel - along[:, None] * sh.directions[pick], axis=1) <= 1e-6 * scale)
    for name in ("u", "v", "Z", "f", "line.dist"):
        np.testing.assert_allclose(ch[name][pick], aovs[name][pick], rtol=2e-6, atol=1e-6 * scale, equal_nan=True)
    np.testing.assert_array_equal(ch["patch"][pick], aovs["patch"][pick])
    np.testing.assert_array_equal(ch["line.id"][pick], aovs["line.id"][pick])
    background = ch["A"] == 0
    assert np.all(ch["patch"][background] == -1) and np.all(np.isnan(ch["P.X"][background]))
    assert np.all(np.isfinite(flat[:, :4]))
    assert attrs["rtreflect:scene_sha256"] == hashlib.sha256(renderer.scene.path.read_bytes()).hexdigest()
    assert attrs["rtreflect:version"] == __version__


def test_cylinder_reflects_like_a_circle():
    """Closed form: the quarter cylinder x² + z² = 1 has the radial normal (x, 0, z); s = 2(a·n)n − a."""
    scene = load_scene(SCENES / "cylinder.toml").with_image(WIDTH, HEIGHT, 1)
    renderer = Renderer(scene)
    rows, cols = np.divmod(np.arange(WIDTH * HEIGHT), WIDTH)
    aovs = renderer.pixel_aovs(rows, cols)
    pick = sample_pixels(aovs, count=400)
    P = aovs["P"][pick]
    np.testing.assert_allclose(np.hypot(P[:, 0], P[:, 2]), 1.0, atol=1e-12)
    radial = np.column_stack([P[:, 0], np.zeros(len(P)), P[:, 2]])
    a = -aovs["shading"].directions[pick]
    s_circle = 2 * np.einsum("ij,ij->i", a, radial)[:, None] * radial - a
    assert np.max(angle_between(aovs["shading"].s[pick], s_circle)) <= 1e-9


@pytest.mark.parametrize("pole, eye", [((0.0, 0.0, 3.15), (1.5, -2.0, 9.0)), ((0.0, 0.0, 0.0), (2.0, -2.0, -6.0))],
                         ids=["lid-apex", "bottom-centre"])
def test_teapot_poles_render_without_holes(pole, eye):
    """Degenerate patch corners: every sample around the pole hits, with finite colour and normals."""
    scene = load_scene(SCENES / "teapot.toml").with_image(320, 180, 2)
    scene = replace(scene, camera=replace(scene.camera, eye=np.array(eye), look_at=np.array([0.0, 0.0, 1.4])))
    renderer = Renderer(scene)
    result = renderer.render()
    col, row = renderer.camera.project(np.array([pole]))[0]
    r0, c0 = int(row), int(col)
    window = result.film.pixels[r0 - 4:r0 + 5, c0 - 4:c0 + 5]
    assert window.shape[:2] == (9, 9), "pole outside the image: test set-up"
    assert np.all(window[..., CHANNELS.index("A")] == 1.0), "a hole or crack at the pole"
    assert np.all(np.isfinite(result.film.pixels[..., :4]))
    normals = window[..., CHANNELS.index("N.X"):CHANNELS.index("N.Z") + 1]
    assert np.all(np.isfinite(normals))
    assert np.all(np.abs(np.linalg.norm(normals, axis=-1) - 1) < 1e-5)


def test_command_line_render_writes_exr_and_png(tmp_path):
    exe = Path(sys.executable).parent / "rtreflect"
    run = subprocess.run([str(exe), "render", str(SCENES / "hood.toml"), "-o", str(tmp_path), "--width", "64",
                          "--height", "36", "--samples", "2"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hood.exr", "hood.png"]
    summary = run.stdout.strip().splitlines()[-1]
    assert "64×36" in summary and "4 samples/px" in summary and "Mrays/s" in summary
    png, names, _ = read_image(tmp_path / "hood.png")
    assert png.shape == (36, 64, 4) and names == ("R", "G", "B", "A")
    exr, exr_names, _ = read_image(tmp_path / "hood.exr")
    # PNG is the sRGB encoding of the EXR's linear colour.
    from rtreflect.output.imagefiles import encode_srgb

    expected = encode_srgb(np.stack([exr[..., exr_names.index(c)] for c in "RGBA"], axis=-1))
    assert np.array_equal(np.round(png * 255).astype(np.uint8), expected)


def test_hits_across_teapot_seams_refine_on_the_neighbour_patch():
    """A mesh hit near a patch edge whose exact hit lies on the neighbouring patch restarts Newton there.

    Without the seam restart 0.42% of the teapot's hits at this size fell back to the mesh
    (120 of 28,826); what remains are silhouette and grazing rays (0.11%).
    """
    width, height = 480, 270
    renderer = Renderer(load_scene(SCENES / "teapot.toml").with_image(width, height, 1))
    rows, cols = np.divmod(np.arange(width * height), width)
    aovs = renderer.pixel_aovs(rows, cols)
    hits = aovs["shading"].hits
    assert hits.fallback.sum() <= 0.002 * hits.hit.sum()
    # The restarted hits are exact: on the ray and on the (new) patch's surface.
    exact = hits.hit & ~hits.fallback
    P_ref = renderer.surfaces.evaluate(hits.patch[exact], hits.u[exact], hits.v[exact]).S
    assert np.max(np.linalg.norm(aovs["P"][exact] - P_ref, axis=1)) <= 1e-9 * renderer.tessellation.extent


def test_tube_reach_in_chunks_matches_least_squares_closest_approach(monkeypatch):
    """TubeLights.reach (eq. 4 in chunks of a few points) against a least-squares closest approach per ray and tube."""
    import rtreflect.modes.lights as lights_module
    from rtreflect.modes.lights import TubeLights

    rng = np.random.default_rng(7)
    c = np.array([0.0, 1.0, 0.0])
    m = np.array([0.0, 0.0, 1.0])
    tubes = TubeLights(np.array([0.0, 0.0, 5.0]), m, c, np.cross(c, m), np.array([-2.0, -0.5, 0.0, 1.0, 3.0]),
                       0.4, float("inf"))
    R = rng.uniform(-2, 2, (40, 3))
    s = rng.normal(size=(40, 3))
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    tube = rng.integers(0, len(tubes.c_k), 40)
    monkeypatch.setattr(lights_module, "TUBE_ENTRIES_PER_CHUNK", 12)  # chunks of two points
    reach = tubes.reach(R, s, tube=tube)
    for row in range(len(R)):
        found = [closest_line_distance(R[row], s[row], B, c) for B in tubes.points]
        ahead = [(d, t, k) for k, (d, t) in enumerate(found) if t > 0]
        within = [t for d, t, _ in ahead if d <= tubes.radius]
        if ahead:
            d_best, _, k_best = min(ahead)
            assert reach.line_id[row] == k_best
            assert abs(reach.line_dist[row] - d_best) <= 1e-9
        else:
            assert reach.line_id[row] == -1 and np.isnan(reach.line_dist[row])
        assert reach.candidate[row] == bool(within)
        assert reach.t_candidate[row] == pytest.approx(min(within, default=np.inf), rel=1e-9)
        assert reach.t_of[row] == pytest.approx(found[tube[row]][1], rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("samples", [1, 2])
def test_fallback_count_includes_the_pixel_centre_rays(monkeypatch, samples):
    """At even s the AOVs come from separate pixel-centre rays: their Newton fallbacks count too (issue 11).

    Every hit is flagged as a fallback, so the count must equal the hit rays counted from the
    film: s² × A per pixel for the samples, plus one per pixel whose centre ray hits (patch ≥ 0)
    when s is even (at odd s the centre ray is one of the samples).
    """
    original = Renderer.trace

    def all_fallbacks(self, origins, directions, *args, **kwargs):
        hits = original(self, origins, directions, *args, **kwargs)
        hits.fallback[:] = hits.hit
        return hits

    monkeypatch.setattr(Renderer, "trace", all_fallbacks)
    scene = load_scene(SCENES / "hood.toml").with_image(48, 27, samples)
    result = Renderer(scene).render()
    sample_hits = int(np.rint(result.film.channel("A").astype(np.float64) * samples**2).sum())
    centre_hit = result.film.channel("patch") >= 0
    expected = sample_hits + (int(centre_hit.sum()) if samples % 2 == 0 else 0)
    assert result.stats.fallbacks == expected
    assert result.stats.fallback_pixels == int(((result.film.channel("A") > 0) | centre_hit).sum())


def test_renders_of_one_scene_share_its_geometry_and_give_a_fresh_builds_pixels(monkeypatch):
    """The automatic rig's preview, the render after it and validate's each built the scene's tessellation, BVH and
    second look (`integrator.scenegeometry`): on the plate 2 s of a 14 s `rtreflect render`. Now they share the last
    one built for the same surfaces and settings; the film is the same bytes as a renderer's that built its own,
    and other settings (``normals``) get their own."""
    from rtreflect.exchange.load import load_scene as load_part
    from rtreflect.integrator import scenegeometry
    from rtreflect.integrator.autorig import resolve

    pytest.importorskip("OCP")
    scene = resolve(load_part(Path(__file__).resolve().parent.parent / "parts" / "filleted_block.step")
                    .with_image(160, 90, 1))
    shared = Renderer(scene)
    assert shared.second_look is not None and Renderer(scene).second_look is shared.second_look  # the rig's preview's
    film = shared.render(threads=1).film.pixels.copy()
    monkeypatch.setattr(scenegeometry, "_last", None)  # forgotten: the next renderer builds its own
    fresh = Renderer(scene)
    assert fresh.second_look is not shared.second_look and fresh.accelerator is not shared.accelerator
    assert fresh.render(threads=1).film.pixels.tobytes() == film.tobytes()  # bit for bit, NaN AOVs of misses too
    mesh = Renderer(scene.with_render(normals="mesh"))
    assert mesh.second_look is None and mesh.tessellation is not fresh.tessellation
