"""Analytic anti-aliasing (`samples = "analytic"`, integrator/analytic.py) against independent references.

- The box coverage formulas against brute-force averages over the pixel.
- A flat mirror under an orthographic camera turned about the view axis: the reflected rays all
  point straight up, so a tube's stripe is the band |x − c_k| ≤ r on the plane and each pixel's
  exact covered share is the area of its square clipped to the band (shapely), slanted stripes
  and stripes thinner than a pixel included.
- A curved patch (the peer scene of issue 14) against 16×16 samples: an RMSE bound.
- Silhouette pixels are supersampled: their coverage A is that of the 4×4 grid; pixels where two faces join with
  no stripe near are not, and match 16×16 samples there.
- The bytes do not depend on the tiling or the thread count.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import shapely

from rtreflect import NurbsSurface, Scene, load_scene, render
from rtreflect.exchange.scene import ANALYTIC, ImageSpec
from rtreflect.integrator.analytic import hard_coverage, stripe_coverage, trapezoid_cdf
from rtreflect.integrator.renderer import WINDOW_TILE_PIXELS, Renderer, pixel_spans
from rtreflect.modes.profile import stripe_weight

ROOT = Path(__file__).resolve().parent.parent
#: Brute-force grid per pixel axis for the formula checks: its midpoint rule errs by ~1/GRID² on smooth weights.
GRID = 400


def pixel_grid() -> tuple[np.ndarray, np.ndarray]:
    t = (np.arange(GRID) + 0.5) / GRID - 0.5
    x, y = np.meshgrid(t, t)
    return x.ravel(), y.ravel()


def test_trapezoid_cdf_is_the_distribution_of_the_footprint():
    x, y = pixel_grid()
    rng = np.random.default_rng(1)
    for a, b in [(1.0, 0.3), (0.2, 0.7), (0.5, 0.5), (0.4, 0.0), (0.0, 0.0)]:
        z = rng.uniform(-0.8, 0.8, 12)
        brute = np.array([np.mean(a * x + b * y <= zi) for zi in z])
        np.testing.assert_allclose(trapezoid_cdf(z, np.full(12, a), np.full(12, b)), brute, atol=3.0 / GRID)


@pytest.mark.parametrize("blur", [0.0, 0.5, 1.0])
def test_stripe_coverage_is_the_mean_stripe_weight_over_the_pixel(blur):
    x, y = pixel_grid()
    rng = np.random.default_rng(2)
    r = 0.1
    sigma, gx, gy = rng.uniform(-0.3, 0.3, 40), rng.uniform(-0.4, 0.4, 40), rng.uniform(-0.4, 0.4, 40)
    gx[:5] = 0.0  # one footprint axis flat
    brute = np.array([np.mean(stripe_weight(np.abs(s + a * x + b * y), r, blur)) for s, a, b in zip(sigma, gx, gy)])
    # The blur's profile is summed over cells of its ramp: within 1e-3 (the hard stripe: the grid's own error).
    np.testing.assert_allclose(stripe_coverage(sigma, gx, gy, r, blur), brute, atol=2e-3)
    assert np.all(hard_coverage(np.zeros(3), np.full(3, 0.01), np.full(3, 0.01), 0.1) == 1.0)


def flat_mirror_scene(blur: float, samples="analytic", turn: float = 0.35,
                      positions=(-0.9, -0.41, 0.13, 0.62)) -> Scene:
    """A flat mirror z = 0, an orthographic camera looking down turned by ``turn`` about z, tubes along y at z = 3."""
    plane = NurbsSurface.bezier(np.array([[[-10.0, -10.0, 0.0], [-10.0, 10.0, 0.0]],
                                          [[10.0, -10.0, 0.0], [10.0, 10.0, 0.0]]]))
    return Scene(surfaces=[plane], image={"width": 64, "height": 48, "samples": samples},
                 camera={"projection": "orthographic", "eye": [0.0, 0.0, 5.0], "look_at": [0.0, 0.0, 0.0],
                         "up": [np.sin(turn), np.cos(turn), 0.0], "view_height": 2.0},
                 lights={"point": [0.0, 0.0, 3.0], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0],
                         # radius 0.012: a stripe half a pixel wide (a pixel is 2/48 ≈ 0.042 units)
                         "positions": list(positions), "radius": 0.012 if blur == 0 else 0.05},
                 render={"surface_color": [0.0, 0.0, 0.0], "line_color": [1.0, 1.0, 1.0],
                         "background": [0.0, 0.0, 0.0], "shading": "flat", "blur": blur})


def exact_band_coverage(renderer: Renderer, positions, radius: float) -> np.ndarray:
    """(H, W) share of each pixel's square (on the plane z = 0) inside the bands |x − c_k| ≤ r: polygon clipping."""
    width, height = renderer.camera.width, renderer.camera.height
    rows, cols = np.divmod(np.arange(width * height), width)
    corners = [renderer.camera.rays(rows, cols, np.array(o))[0][:, :2] for o in ((0, 0), (0, 1), (1, 1), (1, 0))]
    squares = shapely.polygons(np.stack(corners, axis=1))
    bands = shapely.union_all([shapely.box(c - radius, -100.0, c + radius, 100.0) for c in positions])
    return (shapely.area(shapely.intersection(squares, bands)) / shapely.area(squares)).reshape(height, width)


@pytest.mark.parametrize("positions", [(-0.9, -0.41, 0.13, 0.62), (0.13,)], ids=["4 tubes", "1 tube"])
def test_flat_mirror_coverage_is_the_exact_area_of_the_band_in_the_pixel(positions):
    scene = flat_mirror_scene(blur=0.0, positions=positions)
    renderer = Renderer(scene)
    result = renderer.render()
    exact = exact_band_coverage(renderer, scene.lights.positions, scene.lights.radius)
    assert 0.0 < exact.mean() < 0.5 and np.mean((exact > 0.01) & (exact < 0.99)) > 0.01  # slanted, partial edges
    np.testing.assert_allclose(result.rgba[..., 0], exact, atol=2e-5)
    assert result.stats.supersampled == 0  # no silhouette, patch or occlusion edge anywhere in view
    # One sample per pixel alone is off by whole pixels: the test tells the analytic path from it.
    one = render(dataclasses.replace(scene, image=dataclasses.replace(scene.image, samples=1)))
    assert np.abs(one.rgba[..., 0] - exact).max() > 0.4


def test_flat_mirror_soft_stripes_are_the_mean_profile_over_the_pixel():
    scene = flat_mirror_scene(blur=0.6)
    renderer = Renderer(scene)
    result = renderer.render()
    # Brute force: the profile of the nearest tube's distance |x − c_k| at 32×32 points of each pixel.
    width, height = 64, 48
    t = (np.arange(32) + 0.5) / 32
    dy, dx = np.meshgrid(t, t, indexing="ij")
    offsets = np.stack([dy.ravel(), dx.ravel()], axis=1)
    rows, cols = np.divmod(np.arange(width * height), width)
    origins, _ = renderer.camera.rays(np.repeat(rows, len(offsets)), np.repeat(cols, len(offsets)),
                                      np.tile(offsets, (len(rows), 1)))
    d = np.abs(origins[:, 0, None] - np.asarray(scene.lights.positions)[None, :]).min(axis=1)
    brute = stripe_weight(d, scene.lights.radius, scene.render.blur).reshape(-1, len(offsets)).mean(axis=1)
    np.testing.assert_allclose(result.rgba[..., 0].ravel(), brute, atol=2e-3)


@pytest.fixture(scope="module")
def peer():
    """The peer scene at 192×108: analytic, 4×4 samples, and the 16×16 reference."""
    scene = load_scene(ROOT / "bench" / "peer.toml").with_image(192, 108)
    return {s: Renderer(scene.with_image(samples=s)).render() for s in (ANALYTIC, 4, 16)}


def test_curved_patch_matches_sixteen_by_sixteen_samples(peer):
    reference = peer[16].rgba[..., 0]
    sees = peer[16].rgba[..., 3] > 0
    errors = {s: peer[s].rgba[..., 0][sees] - reference[sees] for s in (ANALYTIC, 4)}
    rmse = {s: float(np.sqrt(np.mean(e**2))) for s, e in errors.items()}
    # Issue 14's quality bar (RMSE ≤ 0.0125, ≤ 0.3 % of the pixels off by > 0.1), and better than 4×4 samples.
    assert rmse[ANALYTIC] <= 0.0125 and rmse[ANALYTIC] < rmse[4], rmse
    assert np.mean(np.abs(errors[ANALYTIC]) > 0.1) <= 0.003


def test_silhouette_pixels_are_supersampled(peer):
    grid = peer[4].rgba[..., 3]
    edge = (grid > 0) & (grid < 1)  # the 4×4 grid sees the silhouette cross the pixel
    assert edge.sum() > 50
    analytic = peer[ANALYTIC]
    np.testing.assert_array_equal(analytic.rgba[..., 3][edge], grid[edge])
    assert edge.sum() <= analytic.stats.supersampled < 0.1 * grid.size  # only a few pixels beyond the edges


def test_faces_joined_with_no_stripe_near_are_not_supersampled(tmp_path, monkeypatch):
    """Where two faces of a part meet and no stripe is within the neighbours' reach, the pixel is the surface's colour
    on both: it is not an edge unless the hits are not one sheet continued or the shading steps there
    (`analytic.JOIN_SINE`, `JOIN_COLOUR_STEP`). Open CASCADE's bottle (fillets, a neck on the body's shoulder,
    threads) at 240×135: 87 of the pixels the patch rule alone supersampled are left to the closed form, and there
    the image is 16×16 samples' to 0.005 (linear RGB); without the tangent-plane test, occlusion edges are missed
    (0.021 off). The silhouette stays supersampled."""
    pytest.importorskip("OCP")
    import sys

    from rtreflect.integrator import analytic as analytic_module
    from rtreflect.integrator.autorig import resolve

    sys.path.insert(0, str(ROOT / "tools"))
    import make_sweep_parts

    path = tmp_path / "bottle.step"
    make_sweep_parts.PARTS[path.name](path)
    scene = resolve(load_scene(path).with_image(240, 135, ANALYTIC))
    renderer = Renderer(scene)

    def worst(colour_step: float, sine: float) -> float:
        """The largest error against 16×16 samples over the pixels these join tests leave to the closed form."""
        monkeypatch.setattr(analytic_module, "JOIN_COLOUR_STEP", colour_step)
        monkeypatch.setattr(analytic_module, "JOIN_SINE", sine)
        joined = renderer.render(threads=1)
        changed = np.flatnonzero(np.any(joined.rgba != every.rgba, axis=-1).ravel())
        assert len(changed) > 50 and joined.stats.supersampled < every.stats.supersampled
        reference = renderer.supersample(*np.divmod(changed, scene.image.width), 16)[0]
        return float(np.abs(joined.rgba.reshape(-1, 4)[changed] - reference).max())

    colour_step, sine = analytic_module.JOIN_COLOUR_STEP, analytic_module.JOIN_SINE
    monkeypatch.setattr(analytic_module, "JOIN_COLOUR_STEP", -1.0)  # no two faces' hits count as joined
    every = renderer.render(threads=1)
    assert worst(colour_step, sine) <= 0.005
    assert worst(colour_step, 10.0) > 0.005  # the tangent-plane test is needed
    # The silhouette: every pixel the 4×4 grid sees part covered is still supersampled (its A is the 4×4 grid's).
    monkeypatch.setattr(analytic_module, "JOIN_COLOUR_STEP", colour_step)
    monkeypatch.setattr(analytic_module, "JOIN_SINE", sine)
    grid = Renderer(dataclasses.replace(scene, image=dataclasses.replace(scene.image, samples=4))).render().rgba[..., 3]
    edge = (grid > 0) & (grid < 1)
    np.testing.assert_array_equal(renderer.render(threads=1).rgba[..., 3][edge], grid[edge])


def test_a_crease_the_shading_shows_is_supersampled(monkeypatch):
    """Two planes meeting at an 8° crease, seen at 45° under Lambert shading, no stripe near: the crease passes the
    tangent-plane test (`analytic.JOIN_SINE`: each hit lies within 0.1·|ΔP| of the other's plane where the crease runs
    between them), and the shade steps by 0.046. The colour test (`JOIN_COLOUR_STEP`) supersamples the pixels the
    crease crosses: within 0.005 of 16×16 samples, where the closed form alone is 0.0086 off."""
    from rtreflect.integrator import analytic as analytic_module

    rise = np.tan(np.radians(8.0))
    flat = NurbsSurface.bezier(np.array([[[-10.0, -10.0, 0.0], [-10.0, 10.0, 0.0]],
                                         [[0.0, -10.0, 0.0], [0.0, 10.0, 0.0]]]))
    tilted = NurbsSurface.bezier(np.array([[[0.0, -10.0, 0.0], [0.0, 10.0, 0.0]],
                                           [[10.0, -10.0, 10.0 * rise], [10.0, 10.0, 10.0 * rise]]]))
    scene = Scene(surfaces=[flat, tilted], image={"width": 64, "height": 48, "samples": ANALYTIC},
                  camera={"projection": "orthographic", "eye": [-5.0, 0.0, 5.0], "look_at": [0.01, 0.0, 0.0],
                          "up": [0.0, 1.0, 0.0], "view_height": 2.0},
                  lights={"point": [0.0, 0.0, 3.0], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0],
                          "positions": [-100.0, 100.0], "radius": 0.05},  # their stripes far out of view
                  render={"surface_color": [1.0, 1.0, 1.0], "line_color": [1.0, 0.0, 0.0],
                          "background": [0.0, 0.0, 0.0], "shading": "lambert"})
    renderer = Renderer(scene)
    shown = renderer.render(threads=1)
    monkeypatch.setattr(analytic_module, "JOIN_COLOUR_STEP", np.inf)
    unseen = renderer.render(threads=1)
    crossed = np.flatnonzero(np.any(shown.rgba != unseen.rgba, axis=-1).ravel())
    assert unseen.stats.supersampled == 0 and shown.stats.supersampled >= len(crossed) >= 40
    reference = renderer.supersample(*np.divmod(crossed, scene.image.width), 16)[0]
    assert np.abs(shown.rgba.reshape(-1, 4)[crossed] - reference).max() <= 0.005
    assert np.abs(unseen.rgba.reshape(-1, 4)[crossed] - reference).max() > 0.005


@pytest.mark.parametrize("scene_name", ["peer", "teapot"])
def test_bytes_do_not_depend_on_tiling_or_threads(scene_name, monkeypatch):
    from rtreflect.integrator import renderer as renderer_module

    path = ROOT / "bench" / "peer.toml" if scene_name == "peer" else ROOT / "scenes" / "teapot.toml"
    scene = load_scene(path).with_image(96, 54, ANALYTIC)
    renderer = Renderer(scene)
    whole = renderer.render(threads=1, rays_per_tile=1 << 20).film.pixels
    for threads, rays_per_tile in [(2, 397), (1, 1000), (2, 96 * 3)]:  # spans starting mid-row, and whole rows
        tiled = renderer.render(threads=threads, rays_per_tile=rays_per_tile).film.pixels
        assert tiled.tobytes() == whole.tobytes(), (threads, rays_per_tile)
    # Culled rays given the miss values, or traced to miss at Embree's root (`TRACE_ALL`): the same bytes.
    for trace_all in (0.0, 2.0):  # every batch traced whole; every batch culled
        monkeypatch.setattr(renderer_module, "TRACE_ALL", trace_all)
        assert renderer.render(threads=2, rays_per_tile=397).film.pixels.tobytes() == whole.tobytes(), trace_all
    # The renderer cuts analytic spans at rows (`pixel_spans`); `render_span` itself takes any cut: spans starting
    # mid-row, and spans shorter than a row.
    n = 96 * 54
    for size in (397, 50):
        cut = np.concatenate([renderer.render_span(a, min(a + size, n)).pixels for a in range(0, n, size)])
        assert cut.tobytes() == whole.reshape(n, -1).tobytes(), size


@pytest.mark.parametrize("scene_name", ["peer", "teapot"])
def test_pixels_between_levels_are_dropped_only_where_no_stripe_is_near(scene_name, monkeypatch):
    """`Renderer._across_levels` bounds the pixels between two levels' stripes away from their stripe with the
    neighbours' σ taken to the pixel's level: the film is the one that evaluates the gradient at all of them, bit for
    bit (the teapot's lines crowd to a level per pixel column, test_crowded_stripes_are_supersampled_not_dropped),
    and on the peer scene it spares a fifth of the gradients."""
    path = ROOT / "bench" / "peer.toml" if scene_name == "peer" else ROOT / "scenes" / "teapot.toml"
    renderer = Renderer(load_scene(path).with_image(240, 135, ANALYTIC))
    wanted = []
    centre_stripes = renderer.centre_stripes
    monkeypatch.setattr(renderer, "centre_stripes", lambda shading, rows, cols, sigma, want: (
        wanted.append(int(want.sum())), centre_stripes(shading, rows, cols, sigma, want))[1])
    pruned = renderer.render(threads=1).film.pixels
    kept = sum(wanted)
    wanted.clear()
    monkeypatch.setattr(renderer, "_across_levels", lambda *args: None)
    every = renderer.render(threads=1).film.pixels
    assert pruned.tobytes() == every.tobytes()
    if scene_name == "peer":
        assert kept < 0.85 * sum(wanted), (kept, sum(wanted))


def test_analytic_spans_hold_whole_rows():
    """Where a row fits in a tile, an analytic span holds whole rows (its own pixels are then one run of the pixel
    window's rays, taken as views: `Renderer._render_analytic`); a row longer than a tile is still cut."""
    for width, height, rays in [(96, 54, 397), (960, 540, 1 << 16), (50, 7, 50)]:
        spans = pixel_spans(ImageSpec(width, height), rays)
        assert spans[0][0] == 0 and spans[-1][1] == width * height
        assert all(b == c for (_, b), (c, _) in zip(spans, spans[1:]))
        assert all(a % width == 0 and (b - a) % width == 0 and b - a <= rays for a, b in spans), (width, rays)
    assert pixel_spans(ImageSpec(96, 54), 40)[:2] == [(0, 40), (40, 80)]  # a row longer than the tile
    assert pixel_spans(ImageSpec(96, 54, samples=1), 397)[0] == (0, 397)  # integer samples keep their cut


def test_analytic_spans_of_a_window_split_its_rays_among_the_threads():
    """Given the pixel window (`Renderer.window`), its rows are cut by the window's rays, not the image's: equal
    spans of at most the tile's rays of it, as many as a multiple of the threads, each at most `WINDOW_TILE_PIXELS`
    tiles' pixels; the rows around it keep their cut. The peer scene's window gives 4 spans for 2 threads, not 5."""
    image = ImageSpec(960, 540)
    cases = [((140, 452, 232, 728), 2, 1 << 16), ((140, 452, 232, 728), 1, 1 << 16), ((0, 540, 0, 960), 2, 1 << 16),
             ((300, 302, 0, 3), 2, 1 << 16), ((10, 530, 400, 410), 2, 1 << 12), ((0, 0, 0, 0), 2, 1 << 16)]
    for (r0, r1, c0, c1), threads, rays in cases:
        window = slice(r0, r1), slice(c0, c1)
        spans = pixel_spans(image, rays, window, threads)
        assert spans[0][0] == 0 and spans[-1][1] == image.width * image.height
        assert all(b == c for (_, b), (c, _) in zip(spans, spans[1:])) and all(a < b for a, b in spans)
        rows = [(a // image.width, b // image.width) for a, b in spans]
        assert all(a % image.width == 0 and b % image.width == 0 for a, b in spans)
        inside = [(a, b) for a, b in rows if window[0].start <= a and b <= window[0].stop]
        outside = [(a, b) for a, b in rows if (a, b) not in inside]
        wide = window[1].stop - window[1].start
        per_tile = rays // image.width
        assert sum(b - a for a, b in inside) == window[0].stop - window[0].start
        assert all((b - a) * wide <= rays and b - a <= WINDOW_TILE_PIXELS * per_tile for a, b in inside), rows
        assert len(inside) % threads == 0 or len(inside) == window[0].stop - window[0].start, rows
        assert all(b - a <= per_tile for a, b in outside), rows
    peer = pixel_spans(image, 1 << 16, (slice(140, 452), slice(232, 728)), 2)
    assert [(a // 960, b // 960) for a, b in peer if 140 <= a // 960 < 452] == [(140, 218), (218, 296), (296, 374),
                                                                               (374, 452)]


def test_analytic_is_the_default_and_integers_keep_their_grid():
    assert ImageSpec().samples == ANALYTIC
    scene = load_scene(ROOT / "scenes" / "hood.toml")
    assert scene.image.samples == ANALYTIC
    assert scene.with_image(samples=2).image.samples == 2
    assert scene.with_image(samples=2).output_key != scene.output_key  # resumable batches tell them apart


def test_crowded_stripes_are_supersampled_not_dropped():
    """Where the teapot's lines crowd (a level per pixel column), a pixel's vertical neighbours share its level
    and σ while its horizontal ones do not: the footprint bound from same-level neighbours alone said 'no stripe
    near' and left 7 pixels unlit (0.42 below 4×4 samples). Rows 128–166 of the teapot at 480×270."""
    scene = load_scene(ROOT / "scenes" / "teapot.toml").with_image(480, 270)
    start, stop = 128 * 480, 167 * 480
    analytic = Renderer(scene).render_span(start, stop).pixels[:, 0]
    grid = Renderer(scene.with_image(samples=4)).render_span(start, stop).pixels[:, 0]
    assert np.abs(analytic - grid).max() < 0.2
    assert np.sqrt(np.mean((analytic - grid) ** 2)) < 0.01


# -- the quantities the analytic path reads rather than computes again (one implementation of each) ----------------


def test_reach_gives_the_nearest_tubes_signed_distance_and_ray_parameter():
    """`TubeLights.reach`'s line_sigma and line_t against the closest approach by least squares: |σ| = d, σ's sign
    the side of the tube's axis, (R + t s − B)·(s × c) / |s × c| (tests/reference.py); and σ bit for bit as
    `signed_distance`, the offset the gradient's ends are evaluated with."""
    from reference import closest_line_distance

    from rtreflect.modes.lights import TubeLights

    rng = np.random.default_rng(11)
    c, m = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    tubes = TubeLights(np.array([0.0, 0.0, 5.0]), m, c, np.cross(c, m), np.array([-2.0, -0.5, 0.0, 1.0, 3.0]), 0.4, 30.0)
    R = rng.uniform(-2, 2, (60, 3))
    s = rng.normal(size=(60, 3))
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    reach = tubes.reach(R, s)
    found = np.flatnonzero(reach.line_id >= 0)
    assert 20 < len(found) < len(R)
    assert np.isnan(reach.line_sigma[reach.line_id < 0]).all() and np.isnan(reach.line_t[reach.line_id < 0]).all()
    for row in found:
        B = tubes.points[reach.line_id[row]]
        d, t = closest_line_distance(R[row], s[row], B, c)
        x = np.cross(s[row], c)
        side = np.dot(R[row] - B, x) / np.linalg.norm(x)  # signed distance of the line R + t s to the axis
        assert reach.line_sigma[row] == pytest.approx(side, abs=1e-9) and abs(side) == pytest.approx(d, abs=1e-9)
        assert reach.line_t[row] == pytest.approx(t, rel=1e-9, abs=1e-9)
    signed = tubes.signed_distance(R[found], s[found], reach.line_id[found])
    assert signed.tobytes() == reach.line_sigma[found].tobytes()


def test_level_sets_give_their_signed_offset_with_the_stripes():
    """`even_stripes`: σ = φ − c_k of the nearest level, |σ| the distance it reports, NaN where φ is."""
    from rtreflect.modes.base import even_stripes

    levels = np.array([-1.0, 0.0, 2.5])
    phi = np.array([-3.0, -0.6, -0.4, 0.2, 1.1, 9.0, np.nan])
    stripes = even_stripes(phi, levels, 0.25)
    assert stripes.level_id.tolist() == [0, 0, 1, 1, 1, 2, -1]
    np.testing.assert_array_equal(stripes.offset, phi - np.append(levels, np.nan)[stripes.level_id])
    np.testing.assert_array_equal(np.abs(stripes.offset), stripes.level_dist)


@pytest.mark.parametrize("scene_name", ["peer", "hood_zebra", "cylinder_highlight", "hood_curvature", "circles"])
def test_every_mode_declares_whether_it_is_seen_along_the_ray(scene_name):
    """`Mode.along_ray` (one declaration, no duck typing): True exactly where the mode's stripes name an occlusion
    distance along s, for the occlusion test (`Stripes.occlusion_t`) and the analytic path's (`Stripes.level_t`)."""
    if scene_name == "peer":
        scene = load_scene(ROOT / "bench" / "peer.toml")
    elif scene_name == "circles":
        scene = load_scene(ROOT / "scenes" / "hood.toml")
        scene = dataclasses.replace(scene, lights=dataclasses.replace(scene.lights, shape="circles"))
    else:
        scene = load_scene(ROOT / "scenes" / f"{scene_name}.toml")
    renderer = Renderer(scene.with_image(48, 27))
    shading = renderer.shade(*renderer.camera.rays(*np.divmod(np.arange(48 * 27), 48)))
    assert isinstance(renderer.mode.along_ray, bool)
    assert renderer.mode.along_ray == (shading.level_t is not None)
    expect = {"peer": True, "hood_zebra": False, "cylinder_highlight": False, "hood_curvature": False, "circles": True}
    assert renderer.mode.along_ray is expect[scene_name]


def test_parameter_steps_are_the_least_squares_tangent_step():
    """`parameter_steps` against numpy's least squares of [S_u S_v] (du, dv) = w."""
    from rtreflect.geometry.surfaces import parameter_steps

    rng = np.random.default_rng(3)
    Su, Sv, w = (rng.normal(size=(50, 3)) for _ in range(3))
    du, dv = parameter_steps(Su, Sv, w)
    for i in range(50):
        expected = np.linalg.lstsq(np.column_stack([Su[i], Sv[i]]), w[i], rcond=None)[0]
        np.testing.assert_allclose([du[i], dv[i]], expected, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_eye_vectors_reverse_the_camera_rays(projection):
    """`Camera.eye_vectors` at points on the pixel-centre rays: −D, the unit vector back along the ray to the eye."""
    scene = load_scene(ROOT / "scenes" / "hood.toml").with_image(40, 30)
    scene = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, projection=projection))
    camera = Renderer(scene).camera
    origins, directions = camera.rays(*np.divmod(np.arange(40 * 30), 40))
    points = origins + np.linspace(0.5, 20.0, len(origins))[:, None] * directions
    np.testing.assert_allclose(camera.eye_vectors(points), -directions, atol=1e-12)


def test_hits_carry_the_derivatives_the_footprint_needs():
    """`Hits.Su`, `Hits.Sv` are S_u, S_v at the stored (patch, u, v) as `SurfaceSet.evaluate` gives them (to 1e-10 of
    their length: Newton's last step may be finished by Taylor polynomials, `kernels.nurbs.taylor_finish_lanes`), also
    where the second look replaced a hit (teapot rows 50–112 at 480×270: it does there)."""
    scene = load_scene(ROOT / "scenes" / "teapot.toml").with_image(480, 270)
    renderer = Renderer(scene)
    rows, cols = np.divmod(np.arange(50 * 480, 112 * 480), 480)
    origins, directions = renderer.camera.rays(rows, cols)
    hits = renderer.trace(origins, directions)
    idx = np.flatnonzero(hits.hit)
    assert hits.aside[idx].sum() > 0  # the second look (or a hit beside its mesh hit) is exercised
    derivs = renderer.surfaces.evaluate(hits.patch[idx], hits.u[idx], hits.v[idx])
    for got, want in ((hits.Su[idx], derivs.Su), (hits.Sv[idx], derivs.Sv)):
        assert np.all(np.linalg.norm(got - want, axis=1) <= 1e-10 * np.linalg.norm(want, axis=1))
    assert np.isnan(hits.Su[~hits.hit]).all()
