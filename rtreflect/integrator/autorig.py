"""The automatic camera and light rig: a scene without ``[camera]``/``[lights]`` (or a CAD part) made concrete.

The camera is fitted to the part's mesh (`trace.framing`). The tubes are placed from where the
reflections land, not guessed from the bounding box: a coarse preview traces the pixel-centre
rays of the fitted camera (`Renderer.trace`, exact hits), reflects them (Ulmet eq. 3) and takes
Ulmet's f (eq. 5, the e-coordinate where the reflected ray meets the light plane) over the
visible surface. ``count`` tubes then span the central `F_QUANTILES` of f, so the reflected
lines spread over the whole visible surface whatever its normals. The plane lies above the part
(on the camera's side of it along the model's up axis), `LIGHT_HEIGHT` part radii over its top;
the tubes run along the part's longest horizontal extent. Where under `MIN_REACH_FRACTION` of the
visible surface reflects towards that plane (a wall, a door skin, a bottle seen from above: its
reflected rays go down or sideways) and more reflects towards a wall on the camera's side, the
plane is that wall instead: vertical, facing the part from the camera's horizontal direction,
as far out, with horizontal tubes. A camera inside the part's box (a cabin, a room, a housing seen
from within) may see a part that walls that plane off: where under `MIN_REACH_FRACTION` of the
visible surface reflects towards it unblocked, the level plane near the part's top inside
(`INSIDE_HEIGHT`) is tried and kept if more reaches it (reflection lines: what blocks the reflected
rays matters to them alone). For highlight lines (`[render] mode = "highlight"`) the tubes span
the same quantiles of the highlight's own field, where the normal line (either way) meets the plane:
the reflected rays' range missed it (the sweep's sliver.step, trimmed_face.step, offset_cylinder.step
and parts/trimmed.3dm: highlight φ from −171 to −137 under a bank round 0, no line on the part).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..exchange.scene import CameraSpec, ImageSpec, LightSpec, Scene
from ..geometry.surfaces import SurfaceSet
from ..geometry.tessellation import Tessellation
from ..modes.lights import TubeLights, reaches_light_plane, reflect
from ..trace.camera import Camera
from ..trace.framing import ISO_NAMES, fit_camera, iso_directions, view_frame
from .renderer import Renderer

#: Long side in pixels of the coarse preview that finds the range of f: 160×90 pixel-centre rays
#: resolve the f range of a part filling the frame to a few per cent, in well under a second.
PREVIEW_SIDE = 160
#: Tubes of the automatic rig: about a dozen lines, as CAD zebra analyses show.
AUTO_TUBES = 12
#: Tube radius as a fraction of the spacing: stripes a fifth of the period wide (0.05 at spacing 0.5 in the scenes).
RADIUS_FRACTION = 0.1
#: Height of the light plane over the part's top, in part radii (half the bounding-box diagonal).
LIGHT_HEIGHT = 1.5
#: Quantiles (per cent) of f over the visible surface that the tubes span: grazing reflections near
#: silhouettes send f to ±∞, so the extreme values would stretch the bank over nothing (with 2-98 % the lines
#: of the shipped parts bunched up, leaving 40-50 % of the lit surface between two lines; with 10-90 %, 30 % at most).
F_QUANTILES = (10.0, 90.0)
#: Fewer preview pixels than this reaching the light plane: f's range is unknown, the bank spans 2 part radii.
MIN_REACHING = 10
#: The plane above is kept unless fewer than this part of the visible preview pixels reflect towards it (and more
#: reflect towards the wall on the camera's side). Measured over the 50 shipped and sweep parts at 960×540: the
#: parts under it had 2-20 % of their visible surface lit by lines at all (a wall seen from above: 0 %), and 66-100 %
#: towards the wall; those kept range from 37 % up.
MIN_REACH_FRACTION = 0.25
#: A camera inside the part (`light_rig`): the bank's plane this share of the way from the eye up to the part's top.
#: Where the plane cuts a wall its reflected rays start on it (t ≈ 0) and f there is the wall's own e-coordinate: a tube
#: near it draws a wide band. Through the eye, the walls at eye level made one band across the picture; halfway up
#: (closed_room.step) a band along the left wall; near the top the cut lies along the ceiling's edge, as a room's lights.
INSIDE_HEIGHT = 0.9


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{float(x):.6g}" for x in v) + "]"


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def preview_size(image: ImageSpec) -> tuple[int, int]:
    """The coarse preview's (width, height): the image's aspect, `PREVIEW_SIDE` on the long side (or the image's)."""
    scale = min(1.0, PREVIEW_SIDE / max(image.width, image.height))
    return max(1, round(image.width * scale)), max(1, round(image.height * scale))


def part_points(tessellation: Tessellation, surfaces: SurfaceSet) -> np.ndarray:
    """Points of the part as its faces bound it, which the camera and the bank are fitted to: the mesh vertices that lie
    on their faces, and every trim loop's points on its surface (`NurbsSurface.loop_uv`); all the vertices where no
    face is trimmed.

    A trimmed face's mesh reaches past its trim: a reader's triangulation by its skirt (a quarter of a boundary edge
    out, `tessellation.SKIRT_EDGES`: Open CASCADE's xr1-tc-nut.stp, a 20 × 15 plate, had its top and bottom meshes 2.5
    past it on two sides, and the camera stood 13 % farther than the part needs), a span grid by whole cells. The
    loops bound the face where no vertex of it lies inside (a face smaller than a cell)."""
    if not surfaces.trimmed:
        return tessellation.vertices
    on = surfaces.on_face(tessellation.vertex_patch, tessellation.vertex_uv[:, 0], tessellation.vertex_uv[:, 1])
    loops = [surface.loop_uv() for surface in surfaces.patches]
    uv = np.concatenate(loops)
    patch = np.repeat(np.arange(len(loops)), [len(loop) for loop in loops])
    points = np.concatenate([tessellation.vertices[on], surfaces.evaluate(patch, uv[:, 0], uv[:, 1]).S])
    points = points[np.all(np.isfinite(points), axis=1)]
    return points if len(points) else tessellation.vertices


def resolve(scene: Scene) -> Scene:
    """``scene`` with its automatic camera and tubes chosen (itself if nothing is automatic).

    The choices are described in ``scene.rig`` (the command line's summary line) and written
    into the EXR header by `imagefiles.provenance_attributes`; they depend only on the scene's
    inputs and image size, so ``inputs_sha256`` is kept.
    """
    if not scene.automatic:
        return scene
    width, height = preview_size(scene.image)
    placeholder_camera = CameraSpec(eye=np.array([0.0, -1.0, 0.0]), look_at=np.zeros(3), view_height=1.0)
    placeholder_lights = LightSpec(np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), np.zeros(1), 1.0)
    preview = Renderer(replace(scene, image=ImageSpec(width, height, 1), camera=placeholder_camera,
                               lights=placeholder_lights))
    vertices = part_points(preview.tessellation, preview.surfaces)
    notes = []
    camera = scene.camera
    if camera.automatic:
        aspect = scene.image.width / scene.image.height
        how = f"{camera.view} view" if isinstance(camera.view, str) else f"view {_vec(camera.view)}"
        if camera.view == "iso" and camera.eye is None:
            camera, quadrant = best_iso(preview, camera, vertices, aspect)
            how = f"iso view from the {quadrant}"
        else:
            camera = fit_camera(camera, vertices, aspect)
        lens = (f"fov {camera.fov:g}°" if camera.projection == "perspective"
                else f"orthographic, view_height {camera.view_height:.6g}")
        notes.append(f"automatic camera: {how}, eye {_vec(camera.eye)}, "
                     f"look_at {_vec(camera.look_at)}, up {_vec(camera.up)}, {lens}")
    lights = scene.lights
    if lights.auto:
        preview.camera = Camera(camera, width, height)
        lights, note = light_rig(preview, vertices, scene.camera.up, lights)
        notes.append(f"automatic lights: {note}")
    return replace(scene, camera=camera, lights=lights, rig=tuple(notes))


#: Part of the preview's surface pixels by which another 3/4 view must beat the front-right one to be chosen.
ISO_PREFERENCE = 0.1


def best_iso(preview: Renderer, camera: CameraSpec, points: np.ndarray, aspect: float) -> tuple[CameraSpec, str]:
    """The fitted 3/4 view (of the four turned about the up axis) whose preview sees most surface pixels.

    A quarter cylinder seen along its axis, or a plate seen along its long side, shows a
    sliver; turned by 90° it fills the frame. The front-right view is kept unless another
    sees `ISO_PREFERENCE` more.
    """
    width, height = preview.camera.width, preview.camera.height
    rows, cols = np.divmod(np.arange(width * height), width)
    best, best_seen, best_name = None, -1.0, ""
    for direction, name in zip(iso_directions(camera.up), ISO_NAMES):
        fitted = replace(fit_camera(replace(camera, view=direction), points, aspect), view="iso")
        seen = float(np.count_nonzero(_seen(preview, Camera(fitted, width, height), rows, cols)))
        if best is None or seen > best_seen * (1 + ISO_PREFERENCE):
            best, best_seen, best_name = fitted, seen, name
    return best, best_name


def _seen(preview: Renderer, camera: Camera, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Which preview pixel-centre rays of ``camera`` hit the part's mesh (Embree only: the mesh is close enough)."""
    origins, directions = camera.rays(rows, cols)
    return preview.accelerator.intersect(origins, directions).prim >= 0


def camera_side(vertices: np.ndarray, eye: np.ndarray, model_up: np.ndarray) -> np.ndarray | None:
    """The unit horizontal direction from the part's centre towards the camera (None: the camera is straight above
    or below it): the normal of the automatic wall (module doc)."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    up = _unit(np.asarray(model_up, dtype=np.float64))
    towards = eye - 0.5 * (lo + hi)
    towards = towards - (towards @ up) * up
    length = float(np.linalg.norm(towards))
    return towards / length if length > 1e-6 * float(np.linalg.norm(hi - lo)) else None


def light_plane(vertices: np.ndarray, eye: np.ndarray, model_up: np.ndarray, spec: LightSpec,
                wall: np.ndarray | None = None, inside: bool = False) -> tuple[np.ndarray, ...]:
    """(Q, m, c) of the automatic bank: the given values, else above the part on the camera's side, along its longest
    horizontal extent (y' on a tie: front to back, as in the shipped scenes); or, with ``wall`` (a horizontal unit
    normal, `camera_side`), the vertical plane of that normal as far out, its tubes horizontal; or, ``inside``, the
    horizontal plane `INSIDE_HEIGHT` of the way from the eye up to the part's top (a camera inside the part,
    `light_rig`)."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre, radius = 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-12)
    up = _unit(np.asarray(model_up, dtype=np.float64))
    if spec.normal is not None:
        m = spec.normal
    elif wall is not None:
        m = wall
    else:
        m = up if (eye - centre) @ up >= 0 else -up
    if spec.direction is not None:
        c = spec.direction
    elif wall is not None and spec.normal is None:
        c = np.cross(up, wall)
    else:
        x, y, _ = view_frame(up)
        offsets = vertices - centre
        c = x if np.ptp(offsets @ x) > np.ptp(offsets @ y) * (1 + 1e-9) else y
    c = c - (c @ m) * m  # in the plane (an explicit direction already is)
    if np.linalg.norm(c) < 1e-9:
        c = view_frame(m)[1]
    c = _unit(c)
    if spec.point is not None:
        Q = spec.point
    elif inside:  # near the top, as a room's lights: the plane cuts the walls there (`INSIDE_HEIGHT`)
        Q = np.asarray(eye, dtype=np.float64) + INSIDE_HEIGHT * float(((vertices - eye) @ up).max(initial=0.0)) * up
    else:
        Q = centre + (float(((vertices - centre) @ m).max()) + LIGHT_HEIGHT * radius) * m
    return np.asarray(Q, dtype=np.float64), np.asarray(m, dtype=np.float64), c


def light_rig(preview: Renderer, vertices: np.ndarray, model_up: np.ndarray, spec: LightSpec) -> tuple[LightSpec, str]:
    """The tubes of an automatic ``spec`` from the preview's visible f range (``vertices``: the part's points,
    `part_points`), and the line saying what was chosen."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    radius_part = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-12)
    eye = preview.camera.spec.eye
    rows, cols = np.divmod(np.arange(preview.camera.width * preview.camera.height), preview.camera.width)
    origins, directions = preview.camera.rays(rows, cols)
    hits = preview.trace(origins, directions)
    idx = np.flatnonzero(hits.hit)
    P, R = hits.P[idx], reflect(-directions[idx], hits.N[idx])

    def plane_and_f(wall, inside=False):
        """(Q, m, c), the bank's frame, and Ulmet's f of the preview's visible pixels (inf: not reaching the plane)."""
        Q, m, c = light_plane(vertices, eye, model_up, spec, wall, inside)
        tubes = TubeLights.from_spec(LightSpec(Q, m, c, np.zeros(1), 1.0))
        return (Q, m, c), tubes, tubes.ulmet_f(P, R) if len(idx) else np.zeros(0)

    (Q, m, c), tubes, f = plane_and_f(None)
    wall = camera_side(vertices, eye, model_up) if spec.normal is None and spec.point is None else None
    if wall is not None and len(idx) and np.isfinite(f).mean() < MIN_REACH_FRACTION:
        beside = plane_and_f(wall)
        if np.isfinite(beside[2]).sum() > np.isfinite(f).sum():
            (Q, m, c), tubes, f = beside
    if (preview.scene.render.mode == "reflection" and spec.normal is None and spec.point is None and len(idx)
            and np.all((eye >= lo) & (eye <= hi))):
        # A camera inside the part's box (a cabin, a room, the inside of a housing): the plane outside it may be
        # walled off, every reflected ray meeting the part on its way (the sweep's closed_room.step: lines nowhere,
        # and no warning, as f and line.id ignore what blocks them). The level plane near the part's top inside is
        # tried too, and the one that more reflected rays reach unblocked is kept.
        reaching_from = lambda lights: reaches_light_plane(preview, lights, P, hits.N[idx], hits.patch[idx], R)  # noqa: E731
        open_now = reaching_from(tubes)
        if open_now.mean() < MIN_REACH_FRACTION:
            within = plane_and_f(None, inside=True)
            open_within = reaching_from(within[1])
            if open_within.sum() > open_now.sum():
                (Q, m, c), tubes, f = within
                f = np.where(open_within, f, np.nan)
    name = "f"
    if preview.scene.render.mode == "highlight" and getattr(spec, "shape", None) != "circles" and len(idx):
        # Highlight lines are where the normal line meets a tube, not the reflected ray: the bank spans that field.
        f = tubes.normal_line_f(P, hits.N[idx])  # the highlight's own φ (`HighlightMode.phi`)
        name = "the normal lines' plane coordinate"
    reaching = f[np.isfinite(f)]
    if len(reaching) >= MIN_REACHING:
        f_lo, f_hi = np.percentile(reaching, F_QUANTILES)
        seen = f"{name} over the visible surface {f_lo:.4g} to {f_hi:.4g} ({F_QUANTILES[0]:g}-{F_QUANTILES[1]:g} %)"
    else:
        f_lo, f_hi = -radius_part, radius_part
        seen = "few reflected rays of the preview reach the light plane: the bank spans the part's diameter"
    if spec.positions is not None:
        positions = np.asarray(spec.positions, dtype=np.float64)
        spacing = TubeLights.from_spec(LightSpec(Q, m, c, positions, 1.0)).spacing
        if not np.isfinite(spacing):
            spacing = f_hi - f_lo
    else:
        count = spec.count or AUTO_TUBES
        spacing = spec.spacing or (f_hi - f_lo) / count
        # Three significant digits: a rig a user copies into a scene file reads as typed.
        spacing = float(f"{max(spacing, 1e-6 * radius_part):.3g}")
        if spec.point is None:  # the bank centred on the visible range of f
            Q = Q + 0.5 * (f_lo + f_hi) * tubes.e
        positions = (np.arange(count) - 0.5 * (count - 1)) * spacing
    radius = spec.radius or float(f"{RADIUS_FRACTION * spacing:.3g}")
    rig = LightSpec(Q, m, c, positions, radius, spec.length)
    note = (f"{len(positions)} tubes along {_vec(c)} spaced {spacing:.6g}, radius {radius:.6g}, in the plane through "
            f"{_vec(Q)} with normal {_vec(m)}; {seen}")
    return rig, note
