"""Exact first hits on real CAD parts against Open CASCADE (issue 12, "Shipped examples and tests").

Each shipped part is rendered in its default scene; on sampled pixels (every pixel on a
silhouette or trim edge — a 4-neighbour hits another face or nothing — and as many inside)
the pixel-centre ray's hit is compared with OCCT's own answers, computed on the shape read
by OCP directly (not through rtreflect):

- coverage: the ray hits the part exactly where OCCT's exact ray/shape intersection
  (``IntCurvesFace_ShapeIntersector.PerformNearest``) finds a hit;
- first hit: the hit point equals OCCT's nearest intersection along the ray;
- on the face: ``GeomAPI_ProjectPointOnSurf`` puts the point on its face's surface, and
  ``BRepClass_FaceClassifier`` puts the projected (u, v) inside the face;
- normal: parallel to OCCT's surface normal there (the renderer is two-sided: up to sign).

OCCT's intersector itself misses some entries of rays that meet a face at grazing incidence
(measured on revolved.step: a ray entering at 83° from the normal, OCCT reporting only its exit
2.5 units farther). Where our hit is nearer than OCCT's (or OCCT has none), our point must pass the
projection and classifier tests (it is on the face) and lie on the ray: an intersection OCCT did
not report. Where OCCT hits and we do not, the ray must graze OCCT's face there (`GRAZING_COS`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

OCP = pytest.importorskip("OCP")
pytest.importorskip("shapely")

from rtreflect.exchange.load import load_scene  # noqa: E402
from rtreflect.integrator.autorig import resolve  # noqa: E402
from rtreflect.integrator.renderer import Renderer  # noqa: E402

from test_cad_reader import occt_faces  # noqa: E402

PARTS = Path(__file__).resolve().parents[1] / "parts"
#: revolved.step: seen from the automatic camera, one sampled grazing ray on the vase stored a hit 2.5 units behind
#: OCCT's nearer one until the tracer's second look (issue 11 item 2, trace/secondlook.py).
CAD_PARTS = ["trimmed_face.step", "filleted_block.step", "plate.step", "assembly.step", "revolved.step"]
WIDTH, HEIGHT = 160, 90
EDGE_SAMPLES, INSIDE_SAMPLES = 200, 100
#: Hit points agree with OCCT's to this fraction of the part's diagonal (OCCT's intersector works to
#: its own tolerance, ~1e-7 of the model).
POINT_TOLERANCE = 1e-6
#: |cos| of the angle between ray and normal below which a hit is grazing (84°).
GRAZING_COS = 0.1


def sample_pixels(patch: np.ndarray, rng) -> np.ndarray:
    """Flat indices: pixels whose 4-neighbours hit another face or nothing, and others at random."""
    p = np.pad(patch, 1, mode="edge")
    edge = ((p[1:-1, :-2] != patch) | (p[1:-1, 2:] != patch) | (p[:-2, 1:-1] != patch) | (p[2:, 1:-1] != patch)).ravel()
    on_edge, others = np.flatnonzero(edge), np.flatnonzero(~edge & (patch.ravel() >= 0))
    pick = lambda pool, n: rng.choice(pool, size=min(n, len(pool)), replace=False)  # noqa: E731
    return np.sort(np.concatenate([pick(on_edge, EDGE_SAMPLES), pick(others, INSIDE_SAMPLES)]))


def occt_nearest(shape, origins: np.ndarray, directions: np.ndarray):
    """OCCT's nearest exact intersection of each ray with the shape: points (NaN where none) and ray t."""
    from OCP.gp import gp_Dir, gp_Lin, gp_Pnt
    from OCP.IntCurvesFace import IntCurvesFace_ShapeIntersector

    intersector = IntCurvesFace_ShapeIntersector()
    intersector.Load(shape, 1e-9)
    points = np.full((len(origins), 3), np.nan)
    for k, (o, d) in enumerate(zip(origins, directions)):
        intersector.PerformNearest(gp_Lin(gp_Pnt(*map(float, o)), gp_Dir(*map(float, d))), 0.0, 1e300)
        if intersector.IsDone() and intersector.NbPnt() > 0:
            p = intersector.Pnt(1)
            points[k] = p.X(), p.Y(), p.Z()
    return points


def assert_first_hits_are_occt(path: Path, renderer, origins: np.ndarray, directions: np.ndarray):
    """The rays' traced first hits lie at OCCT's nearest intersection (`occt_nearest`) with the shape read from
    ``path``, to `POINT_TOLERANCE` of the scene; returns the hits."""
    hits = renderer.trace(origins, directions)
    shape = occt_faces(path)[0]
    expected = np.einsum("ij,ij->i", occt_nearest(shape, origins, directions) - origins, directions)
    np.testing.assert_allclose(hits.t, expected, rtol=0, atol=POINT_TOLERANCE * renderer.tessellation.extent)
    return hits


def on_face_checks(face, p: np.ndarray, n: np.ndarray, tolerance: float) -> float:
    """Asserts p lies on the face (projection, classifier) and n is its normal; returns |cos| of n with the face normal's axis."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepClass import BRepClass_FaceClassifier
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.GeomLProp import GeomLProp_SLProps
    from OCP.gp import gp_Pnt, gp_Pnt2d
    from OCP.TopAbs import TopAbs_IN, TopAbs_ON

    surface = BRep_Tool.Surface_s(face)
    projection = GeomAPI_ProjectPointOnSurf(gp_Pnt(*map(float, p)), surface)
    assert projection.NbPoints() > 0 and projection.LowerDistance() <= tolerance, projection.LowerDistance()
    u, v = projection.LowerDistanceParameters()
    assert BRepClass_FaceClassifier(face, gp_Pnt2d(u, v), 1e-7).State() in (TopAbs_IN, TopAbs_ON), (u, v)
    props = GeomLProp_SLProps(surface, u, v, 1, 1e-9)
    if props.IsNormalDefined():
        m = props.Normal()
        assert abs(abs(n @ np.array([m.X(), m.Y(), m.Z()])) - 1.0) <= 1e-7


@pytest.mark.parametrize("name", CAD_PARTS)
def test_first_hits_match_open_cascade(name):
    path = PARTS / name
    renderer = Renderer(resolve(load_scene(path).with_image(WIDTH, HEIGHT, 1)))
    rows, cols = np.divmod(np.arange(WIDTH * HEIGHT), WIDTH)
    origins, directions = renderer.camera.rays(rows, cols)
    hits = renderer.trace(origins, directions)
    assert not hits.fallback.any(), f"{hits.fallback.sum()} fallbacks"
    pixels = sample_pixels(hits.patch.reshape(HEIGHT, WIDTH), np.random.default_rng(12))
    O, D = origins[pixels], directions[pixels]
    shape, _, _, faces = occt_faces(path)
    one_face_per_patch = len(faces) == len(renderer.surfaces)  # an assembly's instances are located copies
    tolerance = POINT_TOLERANCE * renderer.tessellation.extent
    reference = occt_nearest(shape, O, D)
    ours_hit, occt_hit = hits.hit[pixels], np.isfinite(reference[:, 0])
    P, N, patch = hits.P[pixels], hits.N[pixels], hits.patch[pixels]
    t_ours = np.einsum("ij,ij->i", P - O, D)
    t_occt = np.einsum("ij,ij->i", reference - O, D)

    # Every hit of ours is on its face, inside it, with the face's normal.
    if one_face_per_patch:
        for k in np.flatnonzero(ours_hit):
            on_face_checks(faces[int(patch[k])], P[k], N[k], tolerance)
    # The same first hit as OCCT's where both hit; nearer only where OCCT missed a grazing entry.
    both = np.flatnonzero(ours_hit & occt_hit)
    assert len(both) > 0.5 * len(pixels)
    same = np.linalg.norm(P[both] - reference[both], axis=1) <= tolerance
    nearer = both[~same]
    assert np.all(t_ours[nearer] < t_occt[nearer]), (name, pixels[nearer][t_ours[nearer] >= t_occt[nearer]])
    only_ours = np.flatnonzero(ours_hit & ~occt_hit)
    assert one_face_per_patch or len(nearer) + len(only_ours) == 0, (name, pixels[nearer], pixels[only_ours])
    # Such a point is on the face (checked above) and on the ray: a nearer intersection OCCT did not report.
    off_ray = np.linalg.norm(np.cross(P - O, D), axis=1)
    assert np.all(off_ray[np.concatenate([nearer, only_ours])] <= tolerance)
    # Where OCCT hits and we do not, its ray grazes the face there.
    only_occt = np.flatnonzero(~ours_hit & occt_hit)
    cos = np.array([abs(occt_normal(faces, reference[k]) @ D[k]) for k in only_occt])
    assert np.all(cos <= GRAZING_COS), (name, pixels[only_occt], cos)


def occt_normal(faces, p: np.ndarray) -> np.ndarray:
    """OCCT's unit surface normal at p, on the face whose surface passes nearest to p."""
    from OCP.BRep import BRep_Tool
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.GeomLProp import GeomLProp_SLProps
    from OCP.gp import gp_Pnt

    best = None
    for face in faces:
        surface = BRep_Tool.Surface_s(face)
        projection = GeomAPI_ProjectPointOnSurf(gp_Pnt(*map(float, p)), surface)
        if projection.NbPoints() and (best is None or projection.LowerDistance() < best[0]):
            best = (projection.LowerDistance(), surface, *projection.LowerDistanceParameters())
    _, surface, u, v = best
    m = GeomLProp_SLProps(surface, u, v, 1, 1e-9).Normal()
    return np.array([m.X(), m.Y(), m.Z()])


# --- Issue 11 item 2: shipped pixels that stored a hit behind a nearer exact surface point ------------------

#: Pixel-centre rays (row, column) of the default scenes at 480×270 that validate's nearer-hit check failed on
#: before the tracer refined the faces across a rim and the nearer crossing of a grazing sheet (tracing.py).
TRIMMED_3DM_PIXELS = [(19, 171), (20, 207), (26, 124), (39, 253), (43, 90), (44, 89), (217, 125)]
ASSEMBLY_PIXELS = [(133, 219)]


def part_rays(name: str, pixels):
    renderer = Renderer(resolve(load_scene(PARTS / name).with_image(480, 270, 1)))
    rows, cols = np.array(pixels).T
    origins, directions = renderer.camera.rays(rows, cols)
    return renderer, origins, directions


def capped_cylinder_t(origins: np.ndarray, directions: np.ndarray, centre, radius: float, height: float) -> np.ndarray:
    """Closed form: the nearest t > 0 where each ray meets the solid cylinder about the vertical axis through
    ``centre`` (x, y), 0 ≤ z ≤ height, side and caps (inf where it does not)."""
    q = origins[:, :2] - np.asarray(centre)
    d = directions[:, :2]
    a, b, c = (d * d).sum(1), 2.0 * (q * d).sum(1), (q * q).sum(1) - radius**2
    root = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
    side = np.stack([(-b - root) / (2.0 * a), (-b + root) / (2.0 * a)])
    side = np.where(b * b - 4.0 * a * c >= 0.0, side, np.inf)
    z = origins[:, 2] + side * directions[:, 2]
    side = np.where((z >= 0.0) & (z <= height), side, np.inf)
    caps = np.stack([(h - origins[:, 2]) / directions[:, 2] for h in (0.0, height)])
    at = origins[None, :, :2] + caps[..., None] * directions[None, :, :2] - np.asarray(centre)
    caps = np.where((at * at).sum(-1) <= radius**2, caps, np.inf)
    every = np.concatenate([side, caps])
    return np.where(every > 0.0, every, np.inf).min(axis=0)


def test_trimmed_3dm_boss_pixels_keep_the_nearer_face():
    """trimmed.3dm's capped cylinder (tools/make_parts.py: centre (70, 0), radius 10, height 25): rays entering a
    cap next to its rim stored the wall's hit 0.03–0.12 behind it (the wall's mesh has a row of slivers in the
    cap's plane, met first, the cap's own triangle skipped). The hit must be the closed form's nearest."""
    renderer, origins, directions = part_rays("trimmed.3dm", TRIMMED_3DM_PIXELS)
    hits = renderer.trace(origins, directions)
    expected = capped_cylinder_t(origins, directions, (70.0, 0.0), 10.0, 25.0)
    assert np.isfinite(expected).all() and hits.hit.all() and not hits.fallback.any()
    np.testing.assert_allclose(hits.t, expected, rtol=0, atol=POINT_TOLERANCE * renderer.tessellation.extent)


def test_assembly_grazing_pixel_keeps_the_nearer_crossing():
    """assembly.step: a ray grazing a face (|N·D| = 0.02) crosses it twice 0.24 apart; it stored the farther
    crossing. OCCT's nearest intersection along the ray is the reference."""
    renderer, origins, directions = part_rays("assembly.step", ASSEMBLY_PIXELS)
    hits = renderer.trace(origins, directions)
    shape, _, _, _ = occt_faces(PARTS / "assembly.step")
    expected = np.einsum("ij,ij->i", occt_nearest(shape, origins, directions) - origins, directions)
    assert np.isfinite(expected).all() and hits.hit.all() and not hits.fallback.any()
    np.testing.assert_allclose(hits.t, expected, rtol=0, atol=POINT_TOLERANCE * renderer.tessellation.extent)


def test_plate_hole_wall_grazing_entry_is_the_first_hit():
    """plate.step at its default size, 960×551, pixel (425, 750) (validate: "1 pixels store an exact hit behind a
    nearer exact surface point"): the pixel-centre ray skims a hole's wall (|N·D| = 0.012) and met the wall's mesh at
    its top rim, between the wall's two crossings of the cylinder it lies on (t = 74.08, above the wall, and 74.2007,
    on it). Newton ran off the wall's top edge towards the first, the ray went on to the hole's floor at t = 78.97.
    OCCT's nearest intersection is the wall at 74.2007; the coarse trace must find it itself (the other crossing,
    `tracing._crossing_on_face`), not only the second look. The ray is fixed here (a small image's renderer traces
    it: the mesh does not depend on the image size)."""
    from rtreflect.trace.tracing import trace

    renderer = Renderer(resolve(load_scene(PARTS / "plate.step").with_image(96, 54, 1)))
    origins = np.array([[94.55390631719692, -50.66616988096895, 52.255039905236075]])
    directions = np.array([[-0.03440050746000912, 0.7489916745764776, -0.6616857838140527]])
    shape, _, _, faces = occt_faces(PARTS / "plate.step")
    reference = occt_nearest(shape, origins, directions)
    expected = np.einsum("ij,ij->i", reference - origins, directions)
    tolerance = POINT_TOLERANCE * renderer.tessellation.extent
    for hits in (trace(renderer.accelerator, renderer.tessellation, renderer.surfaces, origins, directions),
                 renderer.trace(origins, directions)):
        assert hits.hit.all() and not hits.fallback.any()
        np.testing.assert_allclose(hits.t, expected, rtol=0, atol=tolerance)
        on_face_checks(faces[int(hits.patch[0])], hits.P[0], hits.N[0], tolerance)


def test_a_camera_ten_thousand_parts_away_sees_what_a_near_one_does():
    """An orthographic view's rays are the same lines wherever its eye stands along the view: the filleted block seen
    from 1e4 times its size (the seventeenth sweep's view) and from 4 times it must store the same hits. From far away
    Embree's float32 rays were 0.03–0.06 mm off (origins 5e5 from the part), and hits within that of a face's edge
    landed on the face behind (6 pixels up to 8 mm farther at 320×180, 7.99 mm behind Open CASCADE's first hit at one;
    38 Newton fallbacks). Far rays are moved along themselves to the part before Embree sees them (`accelerator`)."""
    from dataclasses import replace

    scene = load_scene(PARTS / "filleted_block.step")
    look_at = np.array([20.0, 15.0, 10.0])
    view = np.array([219523.47559398922, -411035.58542346, 272872.11506258516])  # eye − look_at, ~5.4e5 long
    hits = {}
    for distance in (5.4e5, 200.0):
        camera = replace(scene.camera, projection="orthographic", eye=look_at + view / np.linalg.norm(view) * distance,
                         look_at=look_at, up=np.array([0.0, 0.0, 1.0]), view_height=40.0)
        renderer = Renderer(resolve(replace(scene, camera=camera).with_image(320, 180, 1)))
        rows, cols = np.divmod(np.arange(320 * 180), 320)
        hits[distance] = renderer.trace(*renderer.camera.rays(rows, cols))
    far, near = hits[5.4e5], hits[200.0]
    assert not far.fallback.any() and not near.fallback.any()
    assert np.array_equal(far.hit, near.hit) and far.hit.sum() > 5000
    # Newton stops within its tolerance of the root, from either start: 1e-5 of the part (the fault was 8 mm on 54).
    np.testing.assert_allclose(far.P[far.hit], near.P[near.hit], rtol=0, atol=1e-5 * renderer.tessellation.extent)
