"""What real .3dm files hold besides Breps (issue 12): block instances, hidden objects, objects that are not surfaces.

The sweep part blocks.3dm (tools/make_sweep_parts.py `write_blocks_3dm`) places a definition of a box, a sphere and a
capped cylinder extrusion five times (rotated, mirrored, scaled uniformly and not, and twice through a nested block
that is mirrored). References: the same model exploded by rhino3dm (each placed Brep transformed and written as
itself), Open CASCADE's first hits on the same solids built from its own primitives (`blocks_occt`), and the closed
form of convex solids (every face's outward normal points away from the solid's centre).
"""

from __future__ import annotations

import dataclasses
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OCP")
pytest.importorskip("shapely")
rhino3dm = pytest.importorskip("rhino3dm")

from rtreflect.errors import SceneError  # noqa: E402
from rtreflect.exchange import rhino  # noqa: E402
from rtreflect.exchange.cad import model_summary, read_cad  # noqa: E402
from rtreflect.exchange.load import load_scene  # noqa: E402
from rtreflect.integrator.autorig import resolve  # noqa: E402
from rtreflect.integrator.renderer import Renderer  # noqa: E402

from test_cad_hits import assert_first_hits_are_occt, sample_pixels  # noqa: E402
from test_cad_reader import inside_samples  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import make_sweep_parts as sweep  # noqa: E402
from make_parts import write_step  # noqa: E402

WIDTH, HEIGHT = 160, 90
#: Faces of the definition "part" in file order (box, sphere, extrusion: wall and two caps), with each solid's centre.
PART_FACES = ((6, np.array([5.0, 2.5, 1.5])), (1, np.array([16.0, 2.5, 1.5])), (3, np.array([-6.0, 2.5, 3.0])))


@pytest.fixture(scope="module")
def blocks(tmp_path_factory):
    """blocks.3dm, written once."""
    path = tmp_path_factory.mktemp("blocks") / "blocks.3dm"
    sweep.write_blocks_3dm(path)
    return path


def placed_solids(instances=sweep.BLOCK_INSTANCES):
    """(4×4 transform, faces, centre) of every solid a blocks.3dm of ``instances`` shows, in its faces' order: each
    instance's parts (a nested block's composed outer first), then the loose box."""
    inner = {"part": [np.eye(4)], "pair": list(sweep.BLOCK_PAIR)}
    solids = [(matrix @ m, faces, centre) for name, matrix in instances for m in inner[name]
              for faces, centre in PART_FACES]
    lo, hi = np.array(sweep.LOOSE_BOX, dtype=float)
    return solids + [(np.eye(4), 6, 0.5 * (lo + hi))]


def test_blocks_render_as_their_exploded_copy(tmp_path):
    """Block instances render every pixel (colour, coverage, hit point, normal, patch) as the same objects transformed
    one by one by rhino3dm and written as Breps: each instance at its place, the definition's objects not at the
    definition's origin, nested transforms composed in order, mirrored ones included. (Without the non-uniformly scaled
    instance, which rhino3dm cannot explode: `test_blocks_first_hits_are_open_cascades` checks it.) Before, the file
    read as 28 faces: the definition at its origin and the two hidden boxes, no instance.

    Both are seen by the block file's automatic camera and lights: the exploded copy's sphere is meshed with a few
    nodes more (its surface differs from the reader's placed one by 7e-15), which moves the automatic framing."""
    similar = tuple((name, m) for name, m in sweep.BLOCK_INSTANCES
                    if np.ptp(np.linalg.svd(m[:3, :3], compute_uv=False)) < 1e-12)  # equal stretch every way
    assert len(similar) == len(sweep.BLOCK_INSTANCES) - 1
    paths = tmp_path / "blocks.3dm", tmp_path / "exploded.3dm"
    for path, exploded in zip(paths, (False, True)):
        sweep.write_blocks_3dm(path, exploded, similar)
    faces = sum(faces for _, faces, _ in placed_solids(similar))
    assert [len(read_cad(path).surfaces) for path in paths] == [faces, faces] == [56, 56]
    scene = resolve(load_scene(paths[0]).with_image(WIDTH, HEIGHT, 1))
    exploded = dataclasses.replace(resolve(load_scene(paths[1]).with_image(WIDTH, HEIGHT, 1)),
                                   camera=scene.camera, lights=scene.lights)
    films = [Renderer(s).render().film for s in (scene, exploded)]
    patch = films[0].channel("patch")
    first = np.cumsum([0] + [faces for _, faces, _ in placed_solids(similar)])
    assert all(np.any((patch >= a) & (patch < b)) for a, b in zip(first[:-1], first[1:]))  # every solid in view
    for name in ("patch", "A"):
        np.testing.assert_array_equal(films[0].channel(name), films[1].channel(name))
    # The rest to float32's resolution (measured: normals 1.5e-8 apart on 2 pixels, k1 3e-8, the rest equal).
    np.testing.assert_allclose(films[0].pixels, films[1].pixels, rtol=1e-6, atol=1e-6)


def test_blocks_first_hits_are_open_cascades(blocks, tmp_path):
    """Sampled pixel-centre rays (silhouette and trim edges, and inside) first hit blocks.3dm where Open CASCADE's
    nearest intersection with the same placed solids lies (built there from OCCT's primitives and placed by
    ``BRepBuilderAPI_GTransform``: the mirrored, the non-uniformly scaled and the nested instances included)."""
    path = blocks
    renderer = Renderer(resolve(load_scene(path).with_image(WIDTH, HEIGHT, 1)))
    rows, cols = np.divmod(np.arange(WIDTH * HEIGHT), WIDTH)
    origins, directions = renderer.camera.rays(rows, cols)
    patch = renderer.trace(origins, directions).patch
    pixels = sample_pixels(patch.reshape(HEIGHT, WIDTH), np.random.default_rng(5))
    reference = tmp_path / "blocks.step"
    write_step(sweep.blocks_occt(), reference)
    mirrored = np.concatenate([np.full(faces, np.linalg.det(m[:3, :3]) < 0) for m, faces, _ in placed_solids()])
    assert mirrored[patch[pixels][patch[pixels] >= 0]].sum() > 50  # the mirrored instances are well sampled
    hits = assert_first_hits_are_occt(reference, renderer, origins[pixels], directions[pixels])
    assert hits.hit.sum() > 0.5 * len(pixels)


def test_placed_faces_face_out(blocks):
    """Every face's oriented normal (S_u × S_v, negated where the face is reversed) points out of its solid: away from
    the centre of the convex solid it bounds (the centre placed by the same transform). A mirrored instance
    (determinant < 0) maps S_u × S_v inwards; its faces are flipped as a STEP assembly's mirrored location is."""
    model = read_cad(blocks)
    rng = np.random.default_rng(3)
    k = 0
    for matrix, faces, centre in placed_solids():
        inside = matrix[:3, :3] @ centre + matrix[:3, 3]
        for _ in range(faces):
            surface = model.surfaces[k]
            uv = inside_samples(surface, 20, rng)
            ev = surface.evaluate(uv[:, 0], uv[:, 1])
            normal = np.cross(ev.Su, ev.Sv) * (-1.0 if model.reversed[k] else 1.0)
            assert np.all(np.einsum("ij,ij->i", ev.S - inside, normal) > 0), (k, np.linalg.det(matrix[:3, :3]))
            k += 1
    assert k == len(model.surfaces)


def test_summary_says_what_the_file_held_and_was_left_out(blocks):
    path = blocks
    lines = model_summary(path, read_cad(path))
    assert lines[1:] == [f"{path}: placed 7 block instances (4 mirrored)",
                         f"{path}: left out 1 LineCurve, 1 Mesh: not surfaces",
                         f"{path}: left out 2 hidden objects (hidden, or on a layer that is off)"]


def _model_with_layers(tmp_path: Path, shown: bool) -> Path:
    """A box on a child layer of a layer that is off, a hidden box, and (``shown``) a box on a layer that is on."""
    model = rhino3dm.File3dm()
    corners = rhino3dm.Point3d(0, 0, 0), rhino3dm.Point3d(1, 2, 3)
    box = rhino3dm.Brep.CreateFromBoundingBox(rhino3dm.BoundingBox(*corners))
    on, off, child = rhino3dm.Layer(), rhino3dm.Layer(), rhino3dm.Layer()
    on.Name, off.Name, off.Visible, child.Name = "on", "off", False, "child"
    indices = [model.Layers.Add(layer) for layer in (on, off)]
    child.ParentLayerId = model.Layers.FindIndex(indices[1]).Id
    indices.append(model.Layers.Add(child))
    assert model.Layers.FindIndex(indices[2]).Visible  # on itself: hidden only by its parent
    for layer, mode in ((indices[2], rhino3dm.ObjectMode.Normal), (indices[0], rhino3dm.ObjectMode.Hidden),
                        *([(indices[0], rhino3dm.ObjectMode.Normal)] if shown else [])):
        attributes = rhino3dm.ObjectAttributes()
        attributes.LayerIndex, attributes.Mode = layer, mode
        model.Objects.AddBrep(box, attributes)
    path = tmp_path / f"layers_{shown}.3dm"
    assert model.Write(str(path), 7)
    return path


def test_hidden_objects_and_layers_are_left_out(tmp_path):
    """What Rhino does not show is not rendered: a hidden object, an object on a layer whose parent layer is off.
    With nothing shown the file is one error line that says why."""
    path = _model_with_layers(tmp_path, shown=True)
    model = read_cad(path)
    assert len(model.surfaces) == 6 and model.notes == ["left out 2 hidden objects (hidden, or on a layer that is off)"]
    path = _model_with_layers(tmp_path, shown=False)
    with pytest.raises(SceneError, match="no surfaces to render: the .3dm file holds 2 hidden objects .*show them"):
        read_cad(path)


def test_instance_of_a_missing_definition_is_named(tmp_path):
    model = rhino3dm.File3dm()
    model.Objects.AddBrep(rhino3dm.Brep.CreateFromSphere(rhino3dm.Sphere(rhino3dm.Point3d(0, 0, 0), 2.0)))
    model.Objects.AddInstanceObject(rhino3dm.InstanceReference(uuid.uuid4(), rhino3dm.Transform.Translation(5, 0, 0)))
    path = tmp_path / "missing_block.3dm"
    assert model.Write(str(path), 7)
    read = read_cad(path)
    assert len(read.surfaces) == 1
    assert read.notes == ["left out block instances: 1 whose block definition is not in the file"]


def test_nesting_deeper_than_the_limit_is_left_out(blocks, monkeypatch):
    """A block nested deeper than `MAX_BLOCK_DEPTH` (a cycle, in a damaged file) is left out and named, not followed
    for ever: with the limit at 1, the nested block's two inner instances (20 faces) are."""
    monkeypatch.setattr(rhino, "MAX_BLOCK_DEPTH", 1)
    model = read_cad(blocks)
    assert len(model.surfaces) == 46
    assert "left out block instances: 2 nested over 1 deep" in model.notes


def test_scaled_sphere_entry_across_its_seam_is_the_first_hit(blocks, tmp_path):
    """blocks.3dm at 480×270: two pixels see the non-uniformly scaled sphere (an ellipsoid) near its seam, with the
    ray's entry across the seam from the mesh hit. The second crossing's Newton start was clamped to the domain's
    edge, on the seam's far side, and Newton went to the exit: both stored it, up to 0.69 behind the entry. A start
    predicted past a closed face's seam is now wrapped one period round (`tracing._into_domain`): 5×5 rays across
    each pixel first hit where Open CASCADE's nearest intersection lies (the ellipsoid's entry, or past its
    silhouette nothing)."""
    scene = load_scene(blocks).with_image(480, 270, 1)
    camera = dataclasses.replace(scene.camera, projection="perspective", eye=np.array([44.348, -60.1397049, 43.2559597]),
                                 look_at=np.array([12.7711947, -2.7273312, 0.1966794]), up=np.array([0.0, 0.0, 1.0]),
                                 fov=40.0)  # the file's automatic view when found: fixed, so it does not follow the file
    renderer = Renderer(resolve(dataclasses.replace(scene, camera=camera)))
    grid = np.linspace(0.1, 0.9, 5)
    offsets = np.stack(np.meshgrid(grid, grid, indexing="ij"), axis=-1).reshape(-1, 2)
    rows = np.repeat([134, 136], len(offsets))
    cols = np.repeat([447, 446], len(offsets))
    origins, directions = renderer.camera.rays(rows, cols, np.tile(offsets, (2, 1)))
    reference = tmp_path / "blocks.step"
    write_step(sweep.blocks_occt(), reference)
    hits = assert_first_hits_are_occt(reference, renderer, origins, directions)
    sphere = next(k for k, (m, faces, _) in enumerate(placed_solids()) if faces == 1 and m[1, 1] == 0.6)
    first = np.cumsum([0] + [faces for _, faces, _ in placed_solids()])[sphere]
    on_it = hits.patch == first
    assert on_it[[12, 37]].all() and on_it.sum() >= 30  # the pixels lie at its silhouette: some rays pass it


class _Object:
    """A model object as `rhino.placed_breps` reads it (rhino3dm cannot write a block that holds itself)."""

    def __init__(self, geometry, mode=rhino3dm.ObjectMode.Normal):
        self.Geometry = geometry
        self.Attributes = type("Attributes", (), {"Id": uuid.uuid4(), "Mode": mode, "Visible": True, "LayerIndex": 0,
                                               "ActiveSpace": rhino3dm.ActiveSpace.ModelSpace})()


class _Definition:
    def __init__(self, name: str, members: list[_Object]):
        self.Id, self.Name, self.members = uuid.uuid4(), name, members

    def GetObjectIds(self):
        return [member.Attributes.Id for member in self.members]


def test_block_inside_itself_and_empty_block_are_named():
    """A damaged file's cycle (block "a" holds a sphere and an instance of "b", which holds an instance of "a") is left
    out where it closes, the sphere placed once, and named; so is an instance of a block with no objects. Before,
    the cycle was followed to `MAX_BLOCK_DEPTH` (16 spheres placed) and the empty block called linked."""
    inside = rhino3dm.ObjectMode.InstanceDefinitionObject
    sphere = _Object(rhino3dm.Brep.CreateFromSphere(rhino3dm.Sphere(rhino3dm.Point3d(0, 0, 0), 1.0)), inside)
    a, b, empty = _Definition("a", [sphere]), _Definition("b", []), _Definition("empty", [])
    move = rhino3dm.Transform.Translation(3, 0, 0)
    b_in_a, a_in_b = _Object(rhino3dm.InstanceReference(b.Id, move), inside), _Object(rhino3dm.InstanceReference(a.Id, move), inside)
    a.members.append(b_in_a)
    b.members.append(a_in_b)
    shown = [_Object(rhino3dm.InstanceReference(a.Id, move)), _Object(rhino3dm.InstanceReference(empty.Id, move))]
    model = type("Model", (), {"Objects": [sphere, b_in_a, a_in_b, *shown], "InstanceDefinitions": [a, b, empty],
                               "Layers": []})()
    placed = rhino.placed_breps(model, rhino3dm)
    assert len(placed.breps) == 1 and placed.instances == 2
    assert placed.unplaced == {"of block 'a' inside itself": 1, "of block 'empty', which holds no objects": 1}


def test_objects_on_layout_pages_are_left_out(tmp_path):
    """A surface on a layout page (page space: at the sheet's coordinates) is not part of the model: left out and
    counted, as hidden ones are; a file holding only such objects is the one-line error saying so. Before, the
    page's sphere rendered beside the model's."""
    page = rhino3dm.ObjectAttributes()
    page.ActiveSpace = rhino3dm.ActiveSpace.PageSpace
    model = rhino3dm.File3dm()
    model.Objects.AddBrep(rhino3dm.Brep.CreateFromSphere(rhino3dm.Sphere(rhino3dm.Point3d(200, 100, 0), 50.0)), page)
    only_page = tmp_path / "only_page.3dm"
    assert model.Write(str(only_page), 7)
    model.Objects.AddBrep(rhino3dm.Brep.CreateFromSphere(rhino3dm.Sphere(rhino3dm.Point3d(0, 0, 0), 2.0)))
    both = tmp_path / "both.3dm"
    assert model.Write(str(both), 7)
    read = read_cad(both)
    assert len(read.surfaces) == 1
    assert np.abs(read.surfaces[0].points[..., :3]).max() < 3.0  # the model's sphere, radius 2 about the origin
    assert read.notes == ["left out 1 object on layout pages (page space, not the model)"]
    with pytest.raises(SceneError, match=r"no surfaces to render: the \.3dm file holds 1 object on layout pages"):
        read_cad(only_page)
