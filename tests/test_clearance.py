"""The clearance cones (trace/clearance.py) skip only the any-hit queries past a mesh hit that find nothing.

Embree is the independent judge: every segment the cones clear is asked of it anyway. The meshes are built so
that the query is what finds the next sheet: a crease folding the sheet back under a grazing ray, a second sheet
just behind the first, a neighbouring face whose corners coincide with the first's (other indices, same points)
and bends away; a skip that dropped any of those queries fails here.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from rtreflect.exchange.load import load_scene
from rtreflect.integrator.autorig import resolve
from rtreflect.integrator.renderer import Renderer
from rtreflect.trace import clearance
from rtreflect.trace.accelerator import Accelerator
from rtreflect.trace.tracing import float32_rounding, trace

ROOT = Path(__file__).resolve().parent.parent


def grid(x0, x1, y0, y1, height, n=24):
    """A (n+1)² grid over [x0, x1] × [y0, y1] at z = height(x, y), two triangles a cell."""
    x, y = np.meshgrid(np.linspace(x0, x1, n + 1), np.linspace(y0, y1, n + 1), indexing="ij")
    vertices = np.column_stack([x.ravel(), y.ravel(), height(x, y).ravel()])
    k = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    a, b, c, d = k.ravel(), (k + n + 1).ravel(), (k + n + 2).ravel(), (k + 1).ravel()
    return vertices, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def folded_scene(chord: float):
    """Three meshes in one BVH: a sheet creased along x = 0 (bent down by 50°), a second sheet `chord` under its
    right part, and a neighbour face beyond y = 1 (its own copies of the seam's points) bent down by 40°."""
    crease = lambda x, y: 0.05 * np.sin(3 * y) - np.tan(np.radians(50)) * np.maximum(x, 0.0)  # noqa: E731
    parts = [grid(-1, 1, -1, 1, crease),
             grid(0.3, 1, -1, 1, lambda x, y: crease(x, y) - chord, n=12),
             grid(-1, 1, 1, 1.5, lambda x, y: crease(x, y) - np.tan(np.radians(40)) * (y - 1.0), n=24)]
    vertices, faces, offset = [], [], 0
    for v, f in parts:
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    vertices, faces = np.concatenate(vertices), np.concatenate(faces)
    extent = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    return SimpleNamespace(vertices=vertices, faces=faces, chord_error=np.array([chord]), extent=extent)


def segments(accelerator, rounding, reach, rng, count=40000):
    """Rays from above at every incidence down to grazing onto the meshes, and segments past their first mesh hit
    up to 1.2 × the cones' reach long: (origins, directions, prim, start, limit)."""
    target = np.column_stack([rng.uniform(-1, 1, count), rng.uniform(-1, 1.5, count), np.zeros(count)])
    polar = np.arccos(rng.uniform(0.02, 1.0, count))  # |D·z| from 0.02 (88.9°) to 1
    azimuth = rng.uniform(0, 2 * np.pi, count)
    D = -np.column_stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)])
    O = target - 3.0 * D
    mesh = accelerator.intersect(O, D)
    hit = mesh.prim >= 0
    O, D, prim, t = O[hit], D[hit], mesh.prim[hit], mesh.t[hit]
    start = t + rounding
    limit = start + rng.uniform(0.0, 1.2, len(t)) * reach
    return O, D, prim, start, limit


@pytest.mark.parametrize("chord", [0.002, 0.02])
def test_every_cleared_segment_is_one_embree_finds_nothing_on(chord):
    scene = folded_scene(chord)
    accelerator = Accelerator(scene)
    rounding = float32_rounding(scene)
    cones = clearance.build(accelerator, scene, rounding)
    O, D, prim, start, limit = segments(accelerator, rounding, cones.reach, np.random.default_rng(7))
    go = np.ones(len(prim), dtype=bool)
    cones.drop(O, D, prim, start, limit, go)
    found = accelerator.occluded(O + start[:, None] * D, D, limit - start)
    assert not (found & ~go).any(), f"{int((found & ~go).sum())} cleared segments meet a triangle"
    # Not vacuous: most segments are cleared, and Embree does find the fold, the sheet behind, the neighbour.
    assert (~go).mean() > 0.3
    assert found.sum() > 100


def test_a_triangle_whose_neighbour_folds_over_it_has_no_cone():
    """Two triangles sharing an edge, the second folded back over the first (150°): no cone bounds it (slope ∞)."""
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 0.1]])
    scene = SimpleNamespace(vertices=vertices, faces=np.array([[0, 1, 2], [1, 2, 3]]), chord_error=np.array([0.1]),
                            extent=2.0)
    accelerator = Accelerator(scene)
    cones = clearance.build(accelerator, scene, float32_rounding(scene))
    assert cones.slope[0] == np.inf


def test_traces_with_and_without_the_cones_are_bit_identical(monkeypatch):
    """The teapot (spout and handle meet the body: sheets closer than the band) at 96×64 = 6144 rays, its cones
    built whatever their cost (`clearance.REACH_PER_RADIUS`: the teapot's reach is 2 median radii)."""
    monkeypatch.setattr(clearance, "REACH_PER_RADIUS", np.inf)
    monkeypatch.setattr(clearance, "PAYBACK_RAYS_PER_TRIANGLE", 0)
    renderer = Renderer(resolve(load_scene(ROOT / "scenes" / "teapot.toml").with_image(96, 64, 1)))
    rows, cols = np.divmod(np.arange(96 * 64), 96)
    origins, directions = renderer.camera.rays(rows, cols)
    assert len(origins) >= clearance.MIN_RAYS
    args = renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions
    cleared = []
    drop = clearance.Cones.drop

    def counted(self, origins, directions, prim, start, limit, go):
        before = int(go.sum())
        drop(self, origins, directions, prim, start, limit, go)
        cleared.append(before - int(go.sum()))

    monkeypatch.setattr(clearance.Cones, "drop", counted)
    with_cones, without = trace(*args), trace(*args, clear=False)
    assert sum(cleared) > 100  # queries were skipped (849 of 1,670 segments when written)
    for name in ("hit", "patch", "u", "v", "t", "P", "N", "fallback", "aside", "Su", "Sv", "curvature"):
        a, b = getattr(with_cones, name), getattr(without, name)
        assert a.tobytes() == b.tobytes(), name


def test_a_scene_whose_reach_spans_many_triangles_builds_no_cones():
    """parts/plate.step-like cost: the reach (16 chord errors) beyond `REACH_PER_RADIUS` median radii: None."""
    scene = folded_scene(0.5)
    assert clearance.build(Accelerator(scene), scene, float32_rounding(scene), clearance.REACH_PER_RADIUS) is None
    scene = folded_scene(0.002)
    assert clearance.build(Accelerator(scene), scene, float32_rounding(scene), clearance.REACH_PER_RADIUS) is not None


def test_cones_are_built_once_the_bvh_has_traced_their_payback(monkeypatch):
    """Ski rental (`clearance.PAYBACK_RAYS_PER_TRIANGLE`): no cones while the BVH's traced rays stay below the payback
    a triangle (traces under `MIN_RAYS` do not count), then built once and kept."""
    scene = folded_scene(0.002)
    accelerator = Accelerator(scene)
    triangles = len(accelerator._faces)
    monkeypatch.setattr(clearance, "PAYBACK_RAYS_PER_TRIANGLE", 3 * clearance.MIN_RAYS / triangles)
    rounding = float32_rounding(scene)
    assert clearance.cones(accelerator, scene, rounding, clearance.MIN_RAYS) is None
    assert clearance.cones(accelerator, scene, rounding, clearance.MIN_RAYS) is None
    built = clearance.cones(accelerator, scene, rounding, clearance.MIN_RAYS)
    assert built is not None and np.isfinite(built.slope).any()
    assert clearance.cones(accelerator, scene, rounding, clearance.MIN_RAYS) is built


def test_a_render_that_will_trace_their_payback_builds_them_at_its_first_trace(monkeypatch):
    """`clearance.expect`: the rays a render is about to trace count ahead, so its first trace builds the cones; a
    render that will trace fewer leaves them to the ski rental."""
    scene = folded_scene(0.002)
    small, large = Accelerator(scene), Accelerator(scene)
    monkeypatch.setattr(clearance, "PAYBACK_RAYS_PER_TRIANGLE", 3 * clearance.MIN_RAYS / len(small._faces))
    rounding = float32_rounding(scene)
    clearance.expect(small, 2 * clearance.MIN_RAYS)
    assert clearance.cones(small, scene, rounding, clearance.MIN_RAYS) is None
    clearance.expect(large, 3 * clearance.MIN_RAYS)
    assert clearance.cones(large, scene, rounding, clearance.MIN_RAYS) is not None
