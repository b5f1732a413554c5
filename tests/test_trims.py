"""The compiled point-in-face test (`TrimTable`, issue 12 "Speed and memory"): against GEOS, point for point.

On chords, the reference is each face's own `Trim.contains` (GEOS's prepared intersects: boundary counts as
inside), on random points over each face's domain, on the loops' vertices and edge midpoints (on the boundary)
and a few rounding units beside them, and on the (u, v) the tracer actually asks about when rendering a shipped
part. Where a segment carries its cubic Hermite piece (`Trim.tangents`), the reference is GEOS on the pieces
sampled densely, away from the curves by more than that sampling's error; and on a circle, the circle itself.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("shapely")

from rtreflect.exchange.load import load_scene  # noqa: E402
from rtreflect.geometry.surfaces import SurfaceSet  # noqa: E402
from rtreflect.geometry.trims import Trim, TrimTable, segment_table  # noqa: E402
from rtreflect.kernels import trims as kernel  # noqa: E402

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


#: Points per Hermite piece of the dense reference loops (`densified`): their chords lie within 1/(8·64²) of the
#: piece's bend from it, far inside the margin `assert_as_the_curves` leaves.
DENSE = 64


def densified(trim: Trim | None) -> tuple[Trim | None, float]:
    """The trim with each Hermite piece (as `TrimTable` uses it: `segment_table`) replaced by `DENSE` chords, and
    the largest distance those chords may lie from the pieces (the margin within which GEOS on them is no reference)."""
    if trim is None:
        return None, 0.0
    s = np.arange(DENSE) / DENSE
    loops, margin = [], 0.0
    for i, ring in enumerate((trim.outer, *trim.holes)):
        ring = np.asarray(ring, dtype=np.float64)
        tangents = trim.tangents[i] if i < len(trim.tangents) else np.full((len(ring), 4), np.nan)
        table = segment_table(ring, np.roll(ring, -1, axis=0), tangents)
        pieces = []
        for row in table:
            if np.isnan(row[kernel.CURVE]):
                pieces.append(row[None, 0:2])
                continue
            c = row[kernel.CURVE:kernel.BOX].reshape(2, 3)
            pieces.append(np.column_stack([row[k] + s * (c[k, 0] + s * (c[k, 1] + s * c[k, 2])) for k in (0, 1)]))
            bend = np.hypot(*(2.0 * np.abs(c[:, 1]) + 6.0 * np.abs(c[:, 2])))  # |H''| ≤ this on [0, 1]
            margin = max(margin, bend / (8.0 * DENSE**2))
        loops.append(np.concatenate(pieces))
    return Trim(loops[0], tuple(loops[1:]), trim.u_period, trim.v_period, trim.u0, trim.v0), margin


def assert_as_the_curves(trims, patch, u, v) -> np.ndarray:
    """`TrimTable` with the trims' Hermite pieces answers as GEOS on their dense sampling (`densified`), at every
    point farther from the loops than that sampling's error (and a rounding margin); returns its answers."""
    import shapely

    got = TrimTable(trims).contains(patch, u, v)
    dense = [densified(t) for t in trims]
    want = reference([t for t, _ in dense], patch, u, v)
    checked = np.ones(len(patch), dtype=bool)
    for k in np.unique(patch):
        if k < 0 or trims[k] is None:
            continue
        at = np.flatnonzero(patch == k)
        trim, margin = dense[k]
        uu, vv = trim.wrap(u[at], v[at])
        extent = float(np.ptp(np.concatenate([trim.outer, *trim.holes]), axis=0).max())
        boundary = shapely.MultiLineString([np.vstack([r, r[:1]]) for r in (trim.outer, *trim.holes)])
        shapely.prepare(boundary)  # GEOS's prepared distance-within: the plate's faces 48× faster than distance()
        near = shapely.dwithin(boundary, shapely.points(uu, vv), 2.0 * margin + 1e-12 * extent)
        checked[at[near]] = False
    assert checked.mean() > 0.5
    np.testing.assert_array_equal(got[checked], want[checked])
    return got


@pytest.mark.parametrize("part", PARTS, ids=lambda p: p.name)
def test_every_shipped_face_answers_as_geos(part):
    """On chords alone (the trims without their tangents) GEOS's answers, bit for bit; with them, the curves'."""
    surfaces = load_scene(part).surfaces
    trims = [s.trim for s in surfaces]
    patch, u, v = probes(trims, [s.domain for s in surfaces], np.random.default_rng(12))
    chords = [dataclasses.replace(t, tangents=()) if t is not None else None for t in trims]
    want = reference(chords, patch, u, v)
    assert want.any() and not want.all()
    np.testing.assert_array_equal(TrimTable(chords).contains(patch, u, v), want)
    got = assert_as_the_curves(trims, patch, u, v)
    np.testing.assert_array_equal(SurfaceSet(surfaces).on_face(patch, u, v), got)
    for k, trim in enumerate(trims):  # the samples themselves lie on the loops: on the face
        if trim is not None:
            ring = np.concatenate([trim.outer, *trim.holes])
            assert TrimTable(trims).contains(np.full(len(ring), k), ring[:, 0], ring[:, 1]).all()


def circle_loop(centre, radius, n, phase=0.0, reverse=False):
    """A circle sampled at n angles with its exact Hermite tangents per segment (Δθ·γ'(θ) at both ends)."""
    theta = phase + 2.0 * np.pi * np.arange(n) / n
    if reverse:
        theta = theta[::-1]
    step = 2.0 * np.pi / n * (-1.0 if reverse else 1.0)
    ring = np.column_stack([centre[0] + radius * np.cos(theta), centre[1] + radius * np.sin(theta)])
    d = step * radius * np.column_stack([-np.sin(theta), np.cos(theta)])
    return ring, np.column_stack([d, np.roll(d, -1, axis=0)])


@pytest.mark.parametrize("phase", [0.0, 0.5, 0.123])
def test_points_between_chord_and_circle_are_classified_as_the_circle(phase):
    """A disc of radius 2 with a hole of radius 0.7, each sampled at only 16 and 12 angles (chords 0.04 and 0.024
    inside the circles): between chord and circle the polygon is wrong (GEOS), the Hermite pieces (their radial
    error ≤ 2e-4 of the radius here) right. ``phase`` (of a step) puts the circles' v-extrema on a sample or inside a piece, where
    it crosses a line of constant v twice; points on the lines v = a sample's v test the half-open rule."""
    rng = np.random.default_rng(7)
    (c, r, n), (hc, hr, hn) = ((0.3, -0.7), 2.0, 16), ((0.5, -0.4), 0.7, 12)
    outer, t_outer = circle_loop(c, r, n, phase * 2.0 * np.pi / n)
    hole, t_hole = circle_loop(hc, hr, hn, phase * 2.0 * np.pi / hn, reverse=True)
    trim = Trim(outer, (hole,), tangents=(t_outer, t_hole))
    polygon = dataclasses.replace(trim, tangents=())
    m = 40_000
    angle = rng.uniform(0.0, 2.0 * np.pi, m)
    for centre, radius, steps, sign in ((c, r, n, 1.0), (hc, hr, hn, -1.0)):
        chord = radius * np.cos(np.pi / steps)  # the chords' nearest approach to the centre
        depth = rng.uniform(chord, radius * (1.0 + (1.0 - chord / radius)), m)  # across the chord band
        sure = np.abs(depth - radius) > 5e-4 * radius
        u, v = centre[0] + depth * np.cos(angle), centre[1] + depth * np.sin(angle)
        # points at the samples' v (half-open crossings at a shared sample), across the band
        at = rng.integers(0, steps, m // 4)
        v[: m // 4] = centre[1] + radius * np.sin(2.0 * np.pi * at / steps + phase * 2.0 * np.pi / steps)
        reach = np.sqrt(np.maximum(depth[: m // 4] ** 2 - (v[: m // 4] - centre[1]) ** 2, 0.0))
        u[: m // 4] = centre[0] + np.where(angle[: m // 4] < np.pi, 1.0, -1.0) * reach
        depth = np.hypot(u - centre[0], v - centre[1])
        sure = np.abs(depth - radius) > 5e-4 * radius
        other = (np.hypot(u - hc[0], v - hc[1]) > hr) if sign > 0 else (np.hypot(u - c[0], v - c[1]) <= r)
        want = (depth <= radius if sign > 0 else depth >= radius) & other
        patch = np.zeros(m, dtype=np.int64)
        got = TrimTable([trim]).contains(patch, u, v)
        np.testing.assert_array_equal(got[sure], want[sure])
        assert np.count_nonzero(polygon.contains(u, v)[sure] != want[sure]) > m // 10  # the chords' band: wrong
    ring = np.concatenate([outer, hole])
    assert TrimTable([trim]).contains(np.zeros(len(ring), dtype=np.int64), ring[:, 0], ring[:, 1]).all()


def test_a_piece_crossing_a_line_three_times():
    """A loop whose lower side is one Hermite piece v(s) = 3s(1 − s)(1 − 2s) from (0, 0) to (1, 0) (it crosses each
    line |v| < 0.29 three times): every point farther than its dense sampling's error answers as GEOS on that."""
    loop = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    tangents = np.full((4, 4), np.nan)
    tangents[0] = [1.0, 3.0, 1.0, 3.0]
    trim = Trim(loop, tangents=(tangents,))
    rng = np.random.default_rng(5)
    m = 50_000
    u, v = rng.uniform(-0.1, 1.1, m), rng.uniform(-0.4, 0.4, m)
    v[:1000] = np.repeat(np.linspace(-0.28, 0.28, 10), 100)  # lines crossing three times
    got = assert_as_the_curves([trim], np.zeros(m, dtype=np.int64), u, v)
    assert not got[(v < -0.3) | (u < 0.0) | (u > 1.0)].any()
    s = rng.uniform(0.0, 1.0, 2000)  # on the curve: the boundary, inside
    on = TrimTable([trim]).contains(np.zeros(2000, dtype=np.int64), s, 3.0 * s * (1.0 - s) * (1.0 - 2.0 * s))
    assert on.mean() > 0.95  # (the rest within rounding of it, either side)


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
    """Every (u, v) the plate's render tests (the tracer's candidates, seam restarts, rim neighbours, second look),
    against the curves (`assert_as_the_curves`)."""
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
    got = assert_as_the_curves(trims, patch, u, v)
    np.testing.assert_array_equal(on_face(renderer.surfaces, patch, u, v), got)



#: One face with many segments and a hole, 64 points and 64 small triangles about it.
A_FACE = """
import numpy as np, shapely
from rtreflect.geometry.trims import Trim
t = np.linspace(0.0, 2.0 * np.pi, 4000, endpoint=False)
r = 1.0 + 0.05 * np.sin(37.0 * t)
outer = np.column_stack([r * np.cos(t), r * np.sin(t)])
u, v = np.random.default_rng(0).uniform(-1.2, 1.2, (2, 64))
triangles = shapely.polygons(np.stack([np.column_stack([u, v]), np.column_stack([u + 0.1, v]),
                                       np.column_stack([u, v + 0.1]), np.column_stack([u, v])], axis=1))
new_face = lambda: Trim(outer, (0.3 * outer[::10],))
"""
#: Two threads ask GEOS about each of 200 new faces at once, as two render threads do (`GEOS_LOCK`), in a subprocess
#: whose crash the test reports. Without the lock the heap broke in every run (5 of 5, within the first rounds).
CONCURRENT_ASKS = A_FACE + """
import threading
answers = set()
for _ in range(200):
    trim = new_face()  # GEOS builds a face's index on first use
    start = threading.Barrier(2)
    def ask():
        start.wait()
        for k in range(50):
            answers.add(int(trim.contains(u, v).sum() if k < 25 else trim.overlaps(triangles).sum()))
    threads = [threading.Thread(target=ask) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
print(sorted(answers))
"""


def test_geos_is_asked_about_a_face_from_two_threads_at_once_without_a_crash():
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", CONCURRENT_ASKS], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    alone = {}
    exec(A_FACE, alone)  # the answers one thread gets
    trim = alone["new_face"]()
    expected = sorted({int(trim.contains(alone["u"], alone["v"]).sum()), int(trim.overlaps(alone["triangles"]).sum())})
    assert done.stdout.strip() == str(expected)


def test_roundness_is_the_isoperimetric_ratio_in_the_domains_unit_square():
    """4πA/P² of the trim in its domain's unit square: 1 for a circle (a 4096-gon: to 1e-6), π/4 for a square, whatever
    the domain's scale, 4πw/(2(1 + w))² for a strip w × 1; a loop out along an arc and back encloses nothing."""
    angle = np.linspace(0.0, 2.0 * np.pi, 4096, endpoint=False)
    circle = Trim(np.column_stack([0.5 + 0.5 * np.cos(angle), 0.5 + 0.5 * np.sin(angle)]))
    assert circle.roundness(((0.0, 1.0), (0.0, 1.0))) == pytest.approx(1.0, abs=1e-6)
    square = Trim(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]))
    assert square.roundness(((0.0, 1.0), (0.0, 1.0))) == pytest.approx(np.pi / 4)
    stretched = Trim(np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 1e-3], [0.0, 1e-3]]))
    assert stretched.roundness(((0.0, 1000.0), (0.0, 1e-3))) == pytest.approx(np.pi / 4)  # the unit square again
    strip = Trim(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1e-3], [0.0, 1e-3]]))
    assert strip.roundness(((0.0, 1.0), (0.0, 1.0))) == pytest.approx(4 * np.pi * 1e-3 / (2 * 1.001) ** 2)
    arc = np.column_stack([np.linspace(0.0, 1.0, 50), 0.5 * np.sin(np.linspace(0.0, np.pi, 50))])
    there_and_back = Trim(np.concatenate([arc, arc[-2:0:-1]]))
    assert there_and_back.roundness(((0.0, 1.0), (0.0, 1.0))) < 1e-12


def test_boundary_distance_is_to_the_loops_even_where_geos_repaired_the_polygon():
    """A square whose loop runs out along a spike and back (a dangling piece, as the sweep's periodic_trimmed.step's
    6e-9 one): GEOS repairs it into a collection of the square and a line, which has no boundary to measure from
    (the distances were NaN, and the face's reader mesh was refused). The distances are to the loops: the spike
    counts, a point on it is at 0."""
    spiked = Trim(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 1.0], [1.0, 1.0], [0.0, 1.0]]))
    assert type(spiked._polygon).__name__ == "GeometryCollection" and spiked._polygon.boundary is None
    distance = spiked.boundary_distance(np.array([0.5, 0.5, 1.5, 1.5]), np.array([0.5, 0.9, 1.2, 1.0]))
    assert np.allclose(distance, [0.5, 0.1, 0.2, 0.0], rtol=0, atol=1e-15)


def test_loop_points_of_a_periodic_trim_are_moved_into_the_surfaces_domain():
    """`NurbsSurface.loop_uv`: a trim sampled in the period from u0 = 0.5 (u 0.5 … 1.45) on a surface whose domain is
    [0, 1]: its points past 1 are those one period back (u − 1), where the surface is, not clamped onto u = 1; the
    points are on the face as `Trim.contains` reads them (from the trim's own period)."""
    from rtreflect.geometry.surfaces import NurbsSurface

    t = np.linspace(0.0, 1.0, 4)
    x, y = np.meshgrid(t, t, indexing="ij")
    patch = NurbsSurface.bezier(np.stack([x, y, x * (1 - x)], axis=-1))
    u = np.linspace(0.5, 1.45, 20)
    loop = np.concatenate([np.column_stack([u, np.full(20, 0.2)]), np.column_stack([u[::-1], np.full(20, 0.8)])])
    surface = dataclasses.replace(patch, trim=Trim(loop, u_period=1.0, u0=0.5))
    uv = surface.loop_uv()
    assert np.allclose(uv[:, 0], np.where(loop[:, 0] >= 1.0, loop[:, 0] - 1.0, loop[:, 0]))
    assert np.array_equal(uv[:, 1], loop[:, 1])
    assert surface.trim.contains(uv[:, 0], uv[:, 1]).all()
    assert len(dataclasses.replace(patch, trim=None).loop_uv()) == 0
