"""The default scene around a CAD part, for a STEP, IGES or .3dm file given where a scene file is expected.

A scene with every key automatic (DESIGN.md, "CAD input"; issue 13): the camera and the light
rig are chosen by `integrator.autorig` when the scene is rendered, as for a scene file without
``[camera]`` and ``[lights]``.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ..geometry.surfaces import NurbsSurface
from .cad import model_summary, read_cad
from .occt import CadModel
from .scene import ANALYTIC, CameraSpec, ImageSpec, LightSpec, OutputSpec, RenderSettings, Scene, _hash_files

#: Bumped when the default scene changes, so resumable outputs of CAD files given as scenes re-render.
#: 2: the automatic camera and light rig (`integrator.autorig`) replace the bounding-box fit.
DEFAULT_SCENE_VERSION = 2
#: Image: the scenes' default long side; analytic anti-aliasing (one sample a pixel, face edges 4×4) keeps a
#: few-hundred-face part's render short.
LONG_SIDE = 960
SAMPLES = ANALYTIC
#: Image aspects (width / height) the default scene chooses between, to fit the part's outline in the 3/4 view:
#: from the scenes' 16:9 down to 3:4 (a tall part, a vase, in a 16:9 frame covers a fifth of it).
ASPECTS = (16 / 9, 3 / 4)
#: The 3/4 view's direction (as `trace.framing` names it "iso"), for the outline's aspect.
ISO_FROM = np.array([0.55, -1.0, 0.75])


def image_for(lo: np.ndarray, hi: np.ndarray) -> ImageSpec:
    """The default image of a part in the box [lo, hi]: the aspect of the box's outline in the 3/4 view (z up),
    clamped to `ASPECTS`, with `LONG_SIDE` pixels on the long side."""
    forward = -ISO_FROM / np.linalg.norm(ISO_FROM)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    wide, tall = np.ptp(corners @ right), np.ptp(corners @ up)
    aspect = min(max(wide / tall, ASPECTS[1]), ASPECTS[0]) if tall > 0 else ASPECTS[0]
    if aspect >= 1:
        return ImageSpec(LONG_SIDE, round(LONG_SIDE / aspect), SAMPLES)
    return ImageSpec(round(LONG_SIDE * aspect), LONG_SIDE, SAMPLES)


def format_qualified_name(path: Path) -> str:
    """A part's name with its format, ``filleted_block_step``: the output name where one part ships in several
    formats side by side (``batch``, the golden images), which would otherwise write the same ``NAME.*``."""
    path = Path(path)
    return f"{path.stem}_{path.suffix.lower().lstrip('.')}"


def load_part_scene(path: Path, skip_bad_faces: bool = False) -> Scene:
    """A CAD file given where a scene file is expected: the part in the default scene (`part_scene`)."""
    model = read_cad(path, "", skip_bad_faces)
    digest, _ = _hash_files([path])
    return part_scene(path, model, digest)


def part_scene(path: Path, model: CadModel, digest: str) -> Scene:
    """The default `Scene` around ``model`` read from ``path`` (sha256 ``digest`` of its bytes)."""
    image = image_for(*model.bounds)
    # Every key automatic: the camera frames the part, the tubes are placed where its reflections land.
    camera, lights = CameraSpec(), LightSpec(None, None, None, None, None, auto=True)
    surfaces: tuple[NurbsSurface, ...] = tuple(model.surfaces)
    # What the pixels depend on: the file, the default scene's version, and which faces were left out.
    skipped = ",".join(str(index) for index, _ in model.skipped)
    inputs = hashlib.sha256(f"{digest}\ndefault-scene-{DEFAULT_SCENE_VERSION}\nskipped:{skipped}".encode()).hexdigest()
    return Scene(path, image, camera, lights, surfaces, RenderSettings(), OutputSpec(path.stem), digest, inputs,
                 notes=tuple(model_summary(path, model)))
