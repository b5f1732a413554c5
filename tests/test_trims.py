"""The compiled point-in-face test (`TrimTable`, issue 12 "Speed and memory") answers as GEOS does, point for point.

The reference is each face's own `Trim.contains` (GEOS's prepared intersects: boundary counts as inside), on
random points over each face's domain, on the loops' vertices and edge midpoints (on the boundary) and a few
rounding units beside them, and on the (u, v) the tracer actually asks about when rendering a shipped part.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("shapely")

from rtreflect.exchange.load import load_scene  # noqa: E402
from rtreflect.geometry.surfaces import SurfaceSet  # noqa: E402
from rtreflect.geometry.trims import Trim, TrimTable  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PARTS = sorted(p for p in (ROOT / "parts").iterdir() if p.suffix.lower() in (".step", ".stp", ".igs", ".iges", ".3dm"))


def reference(trims, patch, u, v) -> np.ndarray:
    """GEOS, per face (True off a trim, and for patch −1, as `SurfaceSet.on_face` always answered)."""
    out = np.ones(len(patch), dtype=bool)
    for k in np.unique(patch):
        if k >= 0 and trims[k] is not None:
            at = patch == k
            out[at] = trims[k].contains(u[at], v[at])
    return out


def probes(trims, domains, rng, n=1500):
    """Random points over each domain, and on, beside and between the loops' vertices."""
    P, U, V = [], [], []
    for k, (trim, ((u0, u1), (v0, v1))) in enumerate(zip(trims, domains)):
        P.append(np.full(n, k)), U.append(rng.uniform(u0, u1, n)), V.append(rng.uniform(v0, v1, n))
        if trim is None:
            continue
        for loop in (trim.outer, *trim.holes):
            loop = np.asarray(loop, dtype=np.float64)
            mid = 0.5 * (loop + np.roll(loop, -1, axis=0))
            for pts in (loop, mid, np.nextafter(mid, np.inf), np.nextafter(mid, -np.inf), mid + 1e-12, loop - 1e-9):
                P.append(np.full(len(pts), k)), U.append(pts[:, 0]), V.append(pts[:, 1])
    return np.concatenate(P), np.concatenate(U), np.concatenate(V)


@pytest.mark.parametrize("part", PARTS, ids=lambda p: p.name)
def test_every_shipped_face_answers_as_geos(part):
    surfaces = load_scene(part).surfaces
    trims = [s.trim for s in surfaces]
    patch, u, v = probes(trims, [s.domain for s in surfaces], np.random.default_rng(12))
    want = reference(trims, patch, u, v)
    assert want.any() and not want.all()
    np.testing.assert_array_equal(TrimTable(trims).contains(patch, u, v), want)
    np.testing.assert_array_equal(SurfaceSet(surfaces).on_face(patch, u, v), want)


def test_periodic_repaired_untrimmed_and_odd_inputs():
    theta = np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False)
    ring = np.column_stack([1.0 + 0.5 * np.cos(theta), 0.5 + 0.3 * np.sin(theta)])
    periodic = Trim(np.array([[0.0, 0.0], [2.0 * np.pi, 0.0], [2.0 * np.pi, 1.0], [0.0, 1.0]]), (ring,),
                    u_period=2.0 * np.pi, u0=0.0)
    bowtie = Trim(np.array([[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]))  # self-crossing: GEOS repairs it
    closed = Trim(np.array([[0.1, 0.1], [0.9, 0.2], [0.8, 0.9], [0.1, 0.1]]))  # first point repeated at the end
    trims = [periodic, None, bowtie, closed]
    rng = np.random.default_rng(3)
    n = 4000
    patch = rng.integers(-1, len(trims), n)
    u, v = rng.uniform(-7.0, 14.0, n), rng.uniform(-0.2, 1.2, n)
    u[:5], v[:5] = np.nan, 0.5
    u[5:10], v[5:10] = 1.5, np.inf
    u[10:20], v[10:20] = 0.0, np.linspace(0.0, 1.0, 10)  # on the periodic face's seam (its loop's edge)
    u[20:30], v[20:30] = 2.0 * np.pi + np.linspace(0.0, 1.0, 10), 1.0  # on its v = 1 edge, one period on
    patch[10:30] = 0
    table = TrimTable(trims)
    assert list(table.row) == [0, -1, -2, 1]  # the repaired bowtie is GEOS's alone
    np.testing.assert_array_equal(table.contains(patch, u, v), reference(trims, patch, u, v))


def test_points_the_tracer_asks_about(monkeypatch):
    """Every (u, v) the plate's render tests (the tracer's candidates, seam restarts, rim neighbours, second look)."""
    from rtreflect.integrator.autorig import resolve
    from rtreflect.integrator.renderer import Renderer

    renderer = Renderer(resolve(load_scene(ROOT / "parts" / "plate.step").with_image(240, 135, 1)))
    asked = []
    on_face = SurfaceSet.on_face

    def spy(self, patch, u, v):
        asked.append((np.array(patch).ravel(), np.array(u, dtype=np.float64).ravel(), np.array(v, dtype=np.float64).ravel()))
        return on_face(self, patch, u, v)

    monkeypatch.setattr(SurfaceSet, "on_face", spy)
    renderer.render(threads=1)
    patch, u, v = (np.concatenate(x) for x in zip(*asked))
    trims = [s.trim for s in renderer.surfaces.patches]
    assert len(patch) > 10_000
    np.testing.assert_array_equal(on_face(renderer.surfaces, patch, u, v), reference(trims, patch, u, v))
