"""Start-up (issue 14): what `rtreflect` imports before the first pixel, and the sRGB encoding written out for it.

colour-science took ~0.5 s of every `rtreflect render` for one formula (the sRGB encoding of
the PNG); the formula is now written out in `output.imagefiles.srgb_oetf` and checked here
against colour-science itself, byte for byte over every 8-bit code's neighbourhood.
"""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

from rtreflect.output.imagefiles import encode_srgb, srgb_oetf

ROOT = Path(__file__).resolve().parents[1]
#: Heavy modules only some commands need: none may load with the command line itself.
LAZY = ("colour", "OCP", "distributed", "dask", "rhino3dm", "jinja2", "matplotlib", "trimesh", "scipy.spatial",
        "shapely")


def test_command_line_import_leaves_heavy_modules_unloaded():
    code = f"import sys, rtreflect.cli; print(' '.join(m for m in {LAZY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT,
                         env={"PYTHONPATH": str(ROOT), "PATH": ""})
    assert out.stdout.split() == [], f"imported by `import rtreflect.cli`: {out.stdout.strip()}"


def test_srgb_encoding_matches_colour_science():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    codes = np.arange(256) / 255.0
    # Every linear value whose 8-bit code is a near tie, plus a dense sweep and the ends.
    ties = colour.cctf_decoding((np.arange(256) + 0.5) / 255.0, function="sRGB")
    L = np.unique(np.clip(np.r_[np.linspace(0, 1, 200001), ties, np.nextafter(ties, 0), np.nextafter(ties, 2),
                                colour.cctf_decoding(codes, function="sRGB")], 0, 1))
    np.testing.assert_array_equal(srgb_oetf(L), colour.cctf_encoding(L, function="sRGB"))
    rgba = np.stack([L, L[::-1], L, np.ones_like(L)], axis=-1)
    expected = np.round(colour.cctf_encoding(rgba[:, :3], function="sRGB") * 255.0).astype(np.uint8)
    np.testing.assert_array_equal(encode_srgb(rgba)[:, :3], expected)


def test_render_of_a_single_patch_scene_loads_neither_trimesh_nor_scipy_spatial(tmp_path):
    """The tessellation's own arrays replace trimesh (~0.5 s of imports with scipy); the seam search's k-d tree
    (scipy.spatial) is built only where a patch has another patch or its own far side to find."""
    code = ("import sys, rtreflect.api as api; "
            "r = api.render(api.load_scene('scenes/cylinder.toml'), width=32, height=18, samples=1); "
            "print(' '.join(m for m in ('trimesh', 'scipy.spatial') if m in sys.modules), '|', int(r.rgba[..., 3].sum() > 0))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT,
                         env={"PYTHONPATH": str(ROOT), "PATH": ""})
    loaded, _, drew = out.stdout.partition("|")
    assert drew.strip() == "1" and loaded.split() == [], out.stdout + out.stderr


def test_mesh_edge_helpers_match_trimesh():
    """`_once` (boundary edges, in trimesh's order: the skirt's vertices are numbered by it) and `unique_edges`
    against trimesh's group_rows and Trimesh.edges_unique, on a grid with holes and stray triangles."""
    import trimesh

    from rtreflect.geometry.tessellation import PatchMesh, _once, grid_faces, unique_edges

    rng = np.random.default_rng(3)
    faces = grid_faces(9, 7)
    faces = faces[rng.random(len(faces)) > 0.3]  # holes: many boundary edges
    faces = np.concatenate([faces, rng.integers(0, 63, (20, 3))])  # strays, some sharing edges with the grid
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    expected = trimesh.grouping.group_rows(np.sort(edges, axis=1), require_count=1)
    assert 20 < len(expected) < len(edges)
    np.testing.assert_array_equal(_once(edges), expected)
    vertices = rng.normal(size=(63, 3))
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
    ours = PatchMesh(vertices, faces, np.zeros((63, 2)), np.zeros(63), np.zeros(63, dtype=bool))
    np.testing.assert_array_equal(unique_edges(faces), np.unique(mesh.edges_unique, axis=0))
    assert ours.edges_unique_length.max() == mesh.edges_unique_length.max()
    assert len(_once(np.zeros((0, 2), dtype=np.int64))) == 0 and unique_edges(np.zeros((0, 3), dtype=np.int64)).shape == (0, 2)
