"""The default scene around a CAD part, for a STEP, IGES or .3dm file given where a scene file is expected.

Built from the part's bounding box (DESIGN.md, "CAD input"): a perspective camera on a 3/4 view
from the front-right, above, at the distance that fits every corner of the box in the frame;
a bank of parallel tubes in a horizontal plane above the part, running front to back (the
direction the camera looks along, as in the shipped scenes), spanning twice the part's diagonal.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from ..geometry.surfaces import NurbsSurface
from .cad import model_summary, read_cad
from .occt import CadModel
from .scene import CameraSpec, ImageSpec, LightSpec, OutputSpec, RenderSettings, Scene, _hash_files

#: Bumped when the default scene changes, so resumable outputs of CAD files given as scenes re-render.
DEFAULT_SCENE_VERSION = 1
#: 3/4 view: from the front (−y), right (+x) and above (+z); z is up.
VIEW_FROM = np.array([0.55, -1.0, 0.75])
#: Vertical field of view in degrees (the scenes' default).
FOV = 40.0
#: Frame margin: the box corners fill at most 1/1.1 of the frame's half-height and half-width.
FRAME_MARGIN = 1.1
#: Image: the scenes' default size; 3×3 samples a pixel keeps a few-hundred-face part's render short.
IMAGE = ImageSpec(width=960, height=540, samples=3)
#: Tubes in the bank (odd: one over the centre) and their spacing as a fraction of the part's half-diagonal R:
#: 17 tubes at R/4 span 4R, twice the diagonal, so the stripes cover the part from any face's tilt.
TUBE_COUNT = 17
TUBE_SPACING = 0.25
#: Tube radius relative to the spacing: thin stripes, as in the shipped scenes (0.05 at spacing 0.5).
TUBE_RADIUS = 0.1
#: Height of the light plane above the part's top, in R.
LIGHT_HEIGHT = 1.5


def fit_camera(lo: np.ndarray, hi: np.ndarray, aspect: float) -> CameraSpec:
    """A perspective camera on `VIEW_FROM` through the box centre, at the distance fitting all 8 corners.

    A corner at offset p from the centre, seen from the eye at distance d along the unit view
    direction f, lies at depth d + p·f and height p·up: it fits when
    |p·up| ≤ t (d + p·f) with t = tan(fov/2) / margin, i.e. d ≥ |p·up| / t − p·f (likewise
    p·right with t · aspect).
    """
    centre = 0.5 * (lo + hi)
    forward = -VIEW_FROM / np.linalg.norm(VIEW_FROM)
    z = np.array([0.0, 0.0, 1.0])
    right = np.cross(forward, z)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    corners = np.array([[x, y, w] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for w in (lo[2], hi[2])]) - centre
    t = math.tan(math.radians(FOV) / 2) / FRAME_MARGIN
    depth = corners @ forward
    need = np.maximum(np.abs(corners @ up) / t, np.abs(corners @ right) / (t * aspect)) - depth
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    distance = max(float(need.max()), radius * 1e-3)
    # The eye must also stay in front of every corner (positive depth), or the near corners fall behind it.
    distance = max(distance, float(-depth.min()) + radius * 0.1)
    eye = centre - distance * forward
    return CameraSpec("perspective", eye, centre, z, FOV, 3.0)


def bank_above(lo: np.ndarray, hi: np.ndarray) -> LightSpec:
    """`TUBE_COUNT` tubes along y in the plane `LIGHT_HEIGHT`·R above the part, spaced `TUBE_SPACING`·R along x."""
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    centre = 0.5 * (lo + hi)
    spacing = TUBE_SPACING * radius
    point = np.array([centre[0], centre[1], hi[2] + LIGHT_HEIGHT * radius])
    positions = (np.arange(TUBE_COUNT) - 0.5 * (TUBE_COUNT - 1)) * spacing
    return LightSpec(point, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), positions, TUBE_RADIUS * spacing)


def load_part_scene(path: Path, skip_bad_faces: bool = False) -> Scene:
    """A CAD file given where a scene file is expected: the part in the default scene (`part_scene`)."""
    model = read_cad(path, "", skip_bad_faces)
    digest, _ = _hash_files([path])
    return part_scene(path, model, digest)


def part_scene(path: Path, model: CadModel, digest: str) -> Scene:
    """The default `Scene` around ``model`` read from ``path`` (sha256 ``digest`` of its bytes)."""
    lo, hi = model.bounds
    camera = fit_camera(lo, hi, IMAGE.width / IMAGE.height)
    lights = bank_above(lo, hi)
    surfaces: tuple[NurbsSurface, ...] = tuple(model.surfaces)
    # What the pixels depend on: the file, the default scene's version, and which faces were left out.
    skipped = ",".join(str(index) for index, _ in model.skipped)
    inputs = hashlib.sha256(f"{digest}\ndefault-scene-{DEFAULT_SCENE_VERSION}\nskipped:{skipped}".encode()).hexdigest()
    return Scene(path, IMAGE, camera, lights, surfaces, RenderSettings(), OutputSpec(path.stem), digest, inputs,
                 notes=tuple(model_summary(path, model)))
