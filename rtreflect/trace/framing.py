"""The automatic camera: a view direction and the distance (or view height) that frames the part.

Views are named relative to the model's up axis z' (``camera.up``): with y' the world +y made
perpendicular to z' (world +x if +y is along z') and x' = y' × z', "front" looks from −y',
"right" from +x', "top" from +z', "iso" from the 3/4 direction (0.55, −1, 0.75) (front-right,
above), the view the default part scene always used. The fit is the projected-points one of
CAD tools' "zoom to fit": every point p (offset from look_at) must satisfy
|p·q| ≤ t (d + p·w) and |p·r| ≤ t·aspect (d + p·w) with t = tan(fov/2)/margin (perspective),
or |p·q| ≤ h/2/margin, |p·r| ≤ aspect·h/2/margin (orthographic), for forward w, right r,
image up q.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..exchange.scene import VIEW_HEIGHT, CameraSpec

#: Eye offsets from look_at in the view frame (x', y', z'), per `scene.VIEWS` name.
VIEW_FROM = {
    "iso": (0.55, -1.0, 0.75),
    "top": (0.0, 0.0, 1.0),
    "bottom": (0.0, 0.0, -1.0),
    "front": (0.0, -1.0, 0.0),
    "back": (0.0, 1.0, 0.0),
    "right": (1.0, 0.0, 0.0),
    "left": (-1.0, 0.0, 0.0),
}
#: Frame margin: the part fills at most 1/1.1 of the frame's half-height and half-width.
FRAME_MARGIN = 1.1
#: Fits of the distance, each after aiming at the middle of the previous fit's image of the part (converges in a few).
CENTRING_STEPS = 4
#: Most points the fit looks at: evenly strided points of the part (the margin absorbs what the stride skips).
MAX_FIT_POINTS = 200_000


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _middle(values: np.ndarray) -> float:
    return 0.5 * (float(values.min()) + float(values.max()))


def view_frame(up: np.ndarray) -> np.ndarray:
    """Rows x', y', z' of the model's frame with z' = up (see the module docstring)."""
    z = _unit(np.asarray(up, dtype=np.float64))
    y = np.array([0.0, 1.0, 0.0])
    if np.linalg.norm(np.cross(y, z)) < 0.1:  # +y is (nearly) up: front/back are along x instead
        y = np.array([-1.0, 0.0, 0.0]) if z[1] > 0 else np.array([1.0, 0.0, 0.0])
    y = _unit(y - (y @ z) * z)
    return np.stack([np.cross(y, z), y, z])


def iso_directions(up: np.ndarray) -> np.ndarray:
    """(4, 3) unit directions of the 3/4 view turned about the up axis in steps of 90°: front-right first, then
    back-right, back-left, front-left (`integrator.autorig` keeps the one that sees most of the part)."""
    x, y, z = VIEW_FROM["iso"]
    turns = [(x, y), (-y, x), (-x, -y), (y, -x)]
    frame = view_frame(up)
    return np.array([_unit(np.array([a, b, z]) @ frame) for a, b in turns])


#: Names of `iso_directions`' views, for the summary line.
ISO_NAMES = ("front-right", "back-right", "back-left", "front-left")


def view_direction(spec: CameraSpec) -> np.ndarray:
    """Unit direction from look_at to an automatic eye: the named view in the model frame, or the given vector."""
    if isinstance(spec.view, str):
        return _unit(np.asarray(VIEW_FROM[spec.view]) @ view_frame(spec.up))
    return _unit(np.asarray(spec.view, dtype=np.float64))


def image_up(spec: CameraSpec, from_dir: np.ndarray) -> np.ndarray:
    """The camera's up vector: the model's up, or y' when looking along it (top and bottom views)."""
    if np.linalg.norm(np.cross(from_dir, _unit(spec.up))) < 1e-3:
        return view_frame(spec.up)[1]
    return np.asarray(spec.up, dtype=np.float64)


def fit_camera(spec: CameraSpec, points: np.ndarray, aspect: float) -> CameraSpec:
    """``spec`` with its automatic values chosen so that ``points`` (the part's, `integrator.autorig.part_points`) fill
    the frame.

    Explicit values win: an explicit eye keeps its place (only look_at and an orthographic
    view height are chosen); an explicit look_at is what the eye looks at.
    """
    points = np.asarray(points, dtype=np.float64)[:: max(1, len(points) // MAX_FIT_POINTS)]
    lo, hi = points.min(axis=0), points.max(axis=0)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-12)
    look_at = spec.look_at if spec.look_at is not None else 0.5 * (lo + hi)
    if spec.eye is not None:
        eye = spec.eye
        forward = _unit(look_at - eye)
        up = np.asarray(spec.up, dtype=np.float64)
    else:
        from_dir = view_direction(spec)
        forward = -from_dir
        up = image_up(spec, from_dir)
    right = _unit(np.cross(forward, up))
    q = np.cross(right, forward)
    view_height = spec.view_height
    eye = spec.eye
    if spec.projection == "orthographic":
        if spec.eye is None and spec.look_at is None:  # aim at the middle of the part's image, not of its box
            p = points - look_at
            look_at = look_at + _middle(p @ right) * right + _middle(p @ q) * q
        p = points - look_at
        depth, across, height = p @ forward, np.abs(p @ right), np.abs(p @ q)
        if view_height is None:
            view_height = 2.0 * FRAME_MARGIN * max(float(height.max()), float(across.max()) / aspect, 1e-9 * radius)
        if spec.eye is None:  # in front of every point: rays start in the eye's plane
            eye = look_at - (float(-depth.min()) + radius) * forward
    elif spec.eye is None:
        t = math.tan(math.radians(spec.fov) / 2) / FRAME_MARGIN
        for _ in range(CENTRING_STEPS if spec.look_at is None else 1):
            p = points - look_at
            depth, across, height = p @ forward, p @ right, p @ q
            need = np.maximum(np.abs(height) / t, np.abs(across) / (t * aspect)) - depth
            # The eye must also stay in front of every point (positive depth), or the near ones fall behind it.
            distance = max(float(need.max()), float(-depth.min()) + 0.1 * radius, 1e-3 * radius)
            if spec.look_at is not None:
                break
            # Aim at the middle of the part's image (a box centre projects off it): shift the aim point by the
            # image-plane offset of that middle at the aim point's distance, then fit the distance again.
            x, y = across / (distance + depth), height / (distance + depth)
            look_at = look_at + distance * (_middle(x) * right + _middle(y) * q)
        eye = look_at - distance * forward
    return replace(spec, eye=np.asarray(eye, dtype=np.float64), look_at=np.asarray(look_at, dtype=np.float64), up=up,
                   view_height=view_height if view_height is not None else VIEW_HEIGHT)
