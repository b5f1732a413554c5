"""The exact tracer where a ray leaves its face (issue 12, "Exact hit"), against Open CASCADE's first hit.

- Rays passing a fillet's silhouette a little away: the search for the ray-surface distance
  (`tracing._rescue`) used to run out of steps by the positive minimum and leave a Newton fallback;
  the tracer must decide them (`tracing._passes_by`) and agree with OCCT's answer, hit or miss.
- Rays continued across a shared edge or out of a trim (their first mesh hit on one face, their
  exact hit on another or none), and rays whose hit was found across the rim (`_rim_neighbours`,
  flagged ``aside``), which only look at the rays near the face's real boundary: OCCT's first hit.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

OCP = pytest.importorskip("OCP")

from rtreflect.exchange.load import load_scene  # noqa: E402
from rtreflect.integrator.autorig import resolve  # noqa: E402
from rtreflect.integrator.renderer import Renderer  # noqa: E402
from rtreflect.trace.tracing import trace  # noqa: E402

from test_cad_hits import POINT_TOLERANCE, occt_nearest  # noqa: E402
from test_cad_reader import occt_faces  # noqa: E402

PARTS = Path(__file__).resolve().parents[1] / "parts"
WIDTH, HEIGHT = 480, 270
#: Pixel-centre rays (row, column) of the default scenes at 480×270 that were Newton fallbacks: each passes a
#: fillet (a torus after conversion) or the vase's wall 0.01–0.06 from its silhouette.
SILHOUETTE_PIXELS = {
    "plate.step": [(122, 108), (135, 228), (137, 319), (187, 287), (204, 334), (204, 335), (222, 386)],
    "filleted_block.step": [(44, 390), (256, 311)],
    "revolved.step": [(257, 238), (257, 240)],
}
#: Rays sampled per kind in the continuation test (OCCT's intersector costs ~1 ms a ray from Python).
SAMPLES = 60


def renderer_of(name: str) -> Renderer:
    return Renderer(resolve(load_scene(PARTS / name).with_image(WIDTH, HEIGHT, 1)))


def assert_as_occt(renderer: Renderer, name: str, hits, origins, directions) -> None:
    """Each ray hits where OCCT's nearest intersection is (same point), and misses where OCCT finds none."""
    shape = occt_faces(PARTS / name)[0]
    reference = occt_nearest(shape, origins, directions)
    occt_hit = np.isfinite(reference[:, 0])
    np.testing.assert_array_equal(hits.hit, occt_hit)
    gap = np.linalg.norm(hits.P[occt_hit] - reference[occt_hit], axis=1)
    assert np.all(gap <= POINT_TOLERANCE * renderer.tessellation.extent), gap


@pytest.mark.parametrize("name", sorted(SILHOUETTE_PIXELS))
def test_rays_passing_a_silhouette_are_decided(name):
    renderer = renderer_of(name)
    rows, cols = np.array(SILHOUETTE_PIXELS[name]).T
    origins, directions = renderer.camera.rays(rows, cols)
    hits = trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions)
    assert not hits.fallback.any(), f"{hits.fallback.sum()} fallbacks"
    assert_as_occt(renderer, name, hits, origins, directions)


def test_rays_continued_across_an_edge_or_out_of_a_trim_meet_occt_first_hit():
    """parts/plate.step (206 faces, 100 filleted holes): rays whose first mesh hit lies on another face than their
    exact hit (or that miss after meeting the mesh), and rays whose hit was found across the rim."""
    name = "plate.step"
    renderer = renderer_of(name)
    rows, cols = np.divmod(np.arange(WIDTH * HEIGHT), WIDTH)
    origins, directions = renderer.camera.rays(rows, cols)
    hits = trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions)
    first = renderer.accelerator.intersect(origins, directions)
    met = first.prim >= 0
    first_face = np.where(met, renderer.tessellation.face_patch[np.maximum(first.prim, 0)], -1)
    continued = np.flatnonzero(met & (first_face != hits.patch))
    aside = np.flatnonzero(hits.aside)
    assert len(continued) >= SAMPLES and len(aside) >= 10  # the paths under test are taken on this part
    rng = np.random.default_rng(12)
    pick = np.unique(np.concatenate([rng.choice(continued, SAMPLES, replace=False),
                                     rng.choice(aside, min(SAMPLES, len(aside)), replace=False)]))
    assert not hits.fallback[pick].any()
    sub = type(hits)(*(getattr(hits, f)[pick] for f in hits.__dataclass_fields__))
    assert_as_occt(renderer, name, sub, origins[pick], directions[pick])


@pytest.mark.parametrize("name", ["scenes/teapot.toml", "parts/plate.step"])
def test_shipped_renders_decide_every_sample(name):
    """The default render at 480×270 (analytic anti-aliasing: edge pixels 4×4 samples) has no Newton fallback. Before:
    the teapot 11 samples in 10 pixels, the plate 152 in 78 (the search stalled by a positive minimum, Newton gone
    to the sheet behind a silhouette the ray passes, rays grazing a fillet still open after 8 mesh hits)."""
    renderer = Renderer(resolve(load_scene(PARTS.parent / name).with_image(WIDTH, HEIGHT)))
    stats = renderer.render(threads=1).stats
    assert stats.fallbacks == 0, f"{stats.fallbacks} fallbacks in {stats.fallback_pixels} pixels"


def _plate_trace_counting_refinements(monkeypatch, caller=None, spied="refine"):
    """A function tracing the plate (960×540 of the default view, every 4th row) that returns its hits and the faces
    `tracing.<spied>` (`refine`, or `refine_all`) was called on (only the calls from the function named ``caller``,
    where given)."""
    from rtreflect.trace import tracing

    renderer = Renderer(resolve(load_scene(PARTS / "plate.step").with_image(960, 540, 1)))
    rows, cols = np.divmod(np.arange(960 * 540), 960)
    pick = rows % 4 == 0
    origins, directions = renderer.camera.rays(rows[pick], cols[pick])
    refined = []
    refine = getattr(tracing, spied)

    def spy(surfaces, patch, *args):
        if caller is None or sys._getframe(1).f_code.co_name == caller:
            refined.append(np.asarray(patch).copy())
        return refine(surfaces, patch, *args)

    def run():
        refined.clear()
        hits = trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions)
        return hits, np.concatenate(refined) if refined else np.zeros(0, dtype=int)

    monkeypatch.setattr(tracing, spied, spy)
    return run


def test_rim_rows_dropped_on_a_planar_neighbour_could_not_win(monkeypatch):
    """`tracing._may_win_on_plane` skips refining a planar face across the rim where its plane's crossing cannot be a
    winning hit: on the plate (960×540 of the default view, every 4th row), the hits are bit for bit those with every
    row refined, and the top plane, the neighbour of its 100 holes' fillets, is no longer refined for most of them."""
    from rtreflect.trace import tracing

    run = _plate_trace_counting_refinements(monkeypatch)
    hits, faces = run()
    monkeypatch.setattr(tracing, "_may_win_on_plane", lambda tessellation, surfaces, pn, *a: np.ones(len(pn), dtype=bool))
    every, every_faces = run()
    for name in ("hit", "patch", "u", "v", "t", "P", "N", "fallback", "aside"):
        np.testing.assert_array_equal(getattr(hits, name), getattr(every, name), err_msg=name)
    assert hits.aside.sum() >= 10  # rim wins happen here
    assert (every_faces == 0).sum() > 5000 and (faces == 0).sum() < 0.05 * (every_faces == 0).sum()


def test_rim_rows_dropped_clear_of_the_neighbours_hull_could_not_win(monkeypatch):
    """`tracing._may_win_in_hull` skips refining a face across the rim where the ray's stretch that could hold a
    winning hit passes clear of that face's control net (its bounding box, its plane's slab): on the plate (960×540 of
    the default view, every 4th row) the hits are bit for bit those with every such row refined, and the fillets'
    rows from the top plane and the walls' rows from the fillets (the fillet and the wall lie below the face the ray
    meets) are no longer refined for most of them."""
    from rtreflect.trace import tracing

    run = _plate_trace_counting_refinements(monkeypatch, caller="_rim_neighbours")
    hits, faces = run()
    monkeypatch.setattr(tracing, "_may_win_in_hull",
                        lambda tessellation, surfaces, rays, pn, *a: np.ones(len(pn), dtype=bool))
    every, every_faces = run()
    for name in ("hit", "patch", "u", "v", "t", "P", "N", "fallback", "aside", "Su", "Sv"):
        np.testing.assert_array_equal(getattr(hits, name), getattr(every, name), err_msg=name)
    assert hits.aside.sum() >= 10  # rim wins happen here
    assert len(every_faces) > 10000 and len(faces) < 0.4 * len(every_faces)


def test_seam_restarts_dropped_clear_of_the_neighbour_could_not_win(monkeypatch):
    """`tracing._may_win_restart` skips a seam restart where no point it could converge to passes the restart's
    tests (the neighbour's plane crossing, or its control net's hull, clear of the ray's stretch within the reach of
    `_near_mesh_hit` from the mesh hit): on the plate (960×540 of the default view, every 4th row) the hits are bit for
    bit those with every restart run, and some restarts (the holes' walls and fillets tried from the top plane) are
    no longer run."""
    from rtreflect.trace import tracing

    # The seam restarts' Newton is the `refine_all` called from `_candidates` itself.
    run = _plate_trace_counting_refinements(monkeypatch, caller="_candidates", spied="refine_all")
    hits, restarted = run()
    monkeypatch.setattr(tracing, "_may_win_restart",
                        lambda tessellation, surfaces, rows, pn, *a: np.ones(len(pn), dtype=bool))
    every, every_restarted = run()
    restarts, every_restarts = len(restarted), len(every_restarted)
    for name in ("hit", "patch", "u", "v", "t", "P", "N", "fallback", "aside", "Su", "Sv"):
        np.testing.assert_array_equal(getattr(hits, name), getattr(every, name), err_msg=name)
    # Since the skirts are a quarter edge wide (`tessellation.SKIRT_EDGES`): 3,420 of 3,551 run (at one edge wide,
    # over 10,000 of them).
    assert every_restarts > 2000 and restarts < every_restarts - 100
