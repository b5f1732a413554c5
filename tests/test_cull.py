"""Ray culling (integrator/cull.py): a culled ray meets no triangle Embree knows, and culling changes no pixel.

Independent witnesses: Embree's own answer on every ray (the coarse mesh's nearest hit and the second
look's shell), and the same scene rendered with culling off (a box of nothing culls nothing).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rtreflect.exchange.scene import ANALYTIC, load_scene
from rtreflect.integrator.cull import RayBox
from rtreflect.integrator.renderer import Renderer

ROOT = Path(__file__).resolve().parent.parent


def small(path: Path, samples, width=96, height=54):
    scene = load_scene(path)
    return replace(scene, image=replace(scene.image, width=width, height=height, samples=samples))


@pytest.mark.parametrize("name", ["teapot.toml", "cylinder.toml"])
def test_culled_rays_meet_no_triangle_of_the_mesh_or_the_shell(name):
    renderer = Renderer(small(ROOT / "scenes" / name, 1))
    rng = np.random.default_rng(3)
    # Rays from around the part, in every direction: many pass it, many go away from it, some graze its box.
    low, high = renderer.ray_box.low, renderer.ray_box.high
    centre, size = 0.5 * (low + high), float(np.linalg.norm(high - low))
    origins = centre + rng.normal(size=(20000, 3)) * size
    aim = centre + (rng.uniform(size=(20000, 3)) - 0.5) * (high - low) * 1.2
    directions = np.where(rng.uniform(size=(20000, 1)) < 0.5, aim - origins, rng.normal(size=(20000, 3)))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    kept = np.zeros(len(origins), dtype=bool)
    kept[renderer.ray_box.may_hit(origins, directions)] = True
    mesh = renderer.accelerator.intersect(origins, directions).prim >= 0
    shell = renderer.second_look.shell.intersect(origins, directions).prim >= 0
    assert 0.2 < kept.mean() < 0.9  # the test culls rays, and keeps some
    assert not (mesh & ~kept).any() and not (shell & ~kept).any()
    assert mesh.any() and shell.any()


@pytest.mark.parametrize("samples", [ANALYTIC, 1, 2])
def test_culling_changes_no_byte_of_the_film(samples):
    scene = small(ROOT / "bench" / "peer.toml", samples)
    culled = Renderer(scene)
    plain = Renderer(scene)
    plain.ray_box = RayBox()  # no box: every ray traced
    a, b = culled.render(threads=1).film.pixels, plain.render(threads=1).film.pixels
    assert len(culled.ray_box.may_hit(*culled.camera.rays(*np.divmod(np.arange(96 * 54), 96)))) < 96 * 54
    assert a.tobytes() == b.tobytes()


def test_nothing_to_hit_culls_nothing_and_a_ray_inside_the_box_is_kept():
    origins, directions = np.zeros((2, 3)), np.array([[1.0, 0, 0], [0, 0, -1.0]])
    assert RayBox().may_hit(origins, directions).tolist() == [0, 1]
    box = RayBox(np.array([[-1.0, -1, -1], [1, 1, 1]]))
    assert box.may_hit(origins, directions).tolist() == [0, 1]
    # Along an axis (zero direction components) beside the box, and away from it: culled; towards it: kept.
    beside = np.array([[0.0, 5, 0], [5.0, 0, 0], [5.0, 0, 0]])
    along = np.array([[1.0, 0, 0], [1.0, 0, 0], [-1.0, 0, 0]])
    assert box.may_hit(beside, along).tolist() == [2]


@pytest.mark.parametrize("name, camera", [("peer.toml", {}), ("peer.toml", {"projection": "orthographic", "view_height": 3.0}),
                                          ("peer.toml", {"eye": [0.0, -0.5, 0.3]}), ("hood.toml", {})])
def test_every_centre_ray_the_box_keeps_is_in_the_pixel_window(name, camera):
    """The window the analytic path forms rays in (`RayBox.pixel_window`) holds every pixel whose centre ray the
    slab test keeps, each at least a pixel inside it (the ring the edge test reads), for a perspective and an
    orthographic camera, and an eye close over the surface (the box partly behind it: the whole image)."""
    path = ROOT / ("bench" if name == "peer.toml" else "scenes") / name
    scene = small(path, ANALYTIC, 192, 108)
    scene = replace(scene, camera=replace(scene.camera, **{k: np.asarray(v) if k == "eye" else v for k, v in camera.items()}))
    renderer = Renderer(scene)
    rows, cols = renderer.window
    kept = renderer.ray_box.keep(*renderer.camera.rays(*np.divmod(np.arange(192 * 108), 192))).reshape(108, 192)
    assert kept.any()
    assert not (kept & ~_ringed(rows, cols, kept.shape)).any()
    if "eye" in camera:
        assert (rows, cols) == (slice(0, 108), slice(0, 192))
    else:
        assert (rows.stop - rows.start) * (cols.stop - cols.start) < 0.5 * kept.size  # it does cut the image


def _ringed(rows: slice, cols: slice, shape) -> np.ndarray:
    """Pixels of the window one pixel in from its sides, except where a side is the image's border."""
    inner = np.zeros(shape, dtype=bool)
    r0 = rows.start if rows.start == 0 else rows.start + 1
    r1 = rows.stop if rows.stop == shape[0] else rows.stop - 1
    c0 = cols.start if cols.start == 0 else cols.start + 1
    c1 = cols.stop if cols.stop == shape[1] else cols.stop - 1
    inner[r0:r1, c0:c1] = True
    return inner
