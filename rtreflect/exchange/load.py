"""Load what a user names as a scene: a TOML scene file, or a CAD file rendered in the default scene around it.

The one entry point for the command line, `batch` and the Python API (as trimesh's
``exchange/load.py`` dispatches by extension): a STEP, IGES or .3dm file goes to
`partscene.load_part_scene`, anything else is read as a TOML scene (`scene.load_scene`).
"""

from __future__ import annotations

from pathlib import Path

from .cad import is_cad_path, refuse_misnamed_cad_file
from .partscene import load_part_scene
from .scene import Scene
from .scene import load_scene as load_scene_file


def load_scene(path: str | Path, skip_bad_faces: bool = False) -> Scene:
    """The `Scene` of a scene file or of a CAD file given as one; raises `SceneError` naming the file and field.

    ``skip_bad_faces``: CAD faces that cannot be read are left out (and listed in `Scene.notes`)
    instead of failing the scene.
    """
    path = Path(path)
    if is_cad_path(path) and not path.is_dir():
        return load_part_scene(path, skip_bad_faces)
    if path.suffix.lower() != ".toml" and path.is_file():
        refuse_misnamed_cad_file(path)
    return load_scene_file(path, skip_bad_faces)
