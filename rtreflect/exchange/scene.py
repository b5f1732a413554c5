"""Scene files (TOML) → a validated, immutable `Scene`.

The schema is the contract in DESIGN.md ("Scene files"): tables ``[image]``,
``[camera]``, ``[lights]``, one or more ``[[surface]]``, ``[render]``, ``[output]``.
Every problem is reported as a `SceneError` naming the file and the field, so a
user can fix it from a single line.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .bpt import read_bpt
from .cad import CAD_SUFFIXES, is_cad_path
from ..errors import SceneError, quote, read_text
from ..geometry.surfaces import NurbsSurface

#: Largest image side. The film keeps 17 float32 planes per pixel, and beyond this
#: the planes alone pass the memory of a workstation.
MAX_SIDE = 16384
#: Largest pixel count (8192 × 16384): 17 planes × 4 bytes × 2^27 ≈ 9 GB of film.
MAX_PIXELS = 1 << 27
#: Why the two limits above exist, for the messages that enforce them.
FILM_LIMIT_REASON = "17 float32 channels per pixel: about 9 GB of EXR at 8192×16384, and validate keeps it in memory"
#: Most light tubes: every sample is tested against every tube, so more only slows the render;
#: no image shows this many stripes apart.
MAX_TUBES = 10000
#: Most mesh vertices over all patches (tessellation × knot spans, squared): about 1.5 GB of mesh,
#: (u, v) table and Embree copy. Newton refines hits onto the surface, so a finer mesh buys nothing.
MAX_MESH_VERTICES = 1 << 23
#: Narrowest non-empty knot span, relative to the largest knot magnitude (at least 1): below it the
#: basis functions keep fewer than 4 of float64's 16 digits, and their derivatives overflow.
MIN_KNOT_SPAN = 1e-12
#: Longest output name in UTF-8 bytes: file names stop at 255 bytes, and the temporary name
#: written first adds a dot, a random part and the extension.
MAX_NAME_BYTES = 200
#: Largest s (s×s samples per pixel); 256 samples per pixel is far past visible gains.
MAX_SAMPLES = 16
#: Largest tessellation per knot span; hits are refined by Newton, so more buys nothing.
MAX_TESSELLATION = 256
#: |c·m| above this means the tube direction is not in the light plane.
IN_PLANE_TOLERANCE = 1e-6
#: `[render] normals`: the exact NURBS normal, or the analysis-mesh normal CAD tools use (for comparison).
NORMALS_MODES = ("exact", "mesh")
#: Largest magnitude of any number in a scene. Embree intersects in float32 and forms
#: products of up to three coordinates (a triangle's plane offset); beyond this they
#: overflow float32's 3.4e38 and the image turns to noise without any error.
MAX_MAGNITUDE = 1e12


@dataclass(frozen=True)
class ImageSpec:
    width: int = 960
    height: int = 540
    samples: int = 4  # s: s×s stratified samples per pixel


@dataclass(frozen=True)
class CameraSpec:
    projection: str = "perspective"
    eye: np.ndarray = field(default_factory=lambda: np.array([0.0, -3.2, 2.4]))
    look_at: np.ndarray = field(default_factory=lambda: np.zeros(3))
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    fov: float = 40.0
    view_height: float = 3.0


@dataclass(frozen=True)
class LightSpec:
    """Parallel tubes in one plane: through Q with unit normal m, along unit c, at c_k along e = c × m."""

    point: np.ndarray  # Q
    normal: np.ndarray  # m (unit)
    direction: np.ndarray  # c (unit)
    positions: np.ndarray  # c_k
    radius: float
    length: float = math.inf


@dataclass(frozen=True)
class RenderSettings:
    tessellation: int = 16
    surface_color: np.ndarray = field(default_factory=lambda: np.array([0.18, 0.18, 0.2]))
    line_color: np.ndarray = field(default_factory=lambda: np.array([1.0, 1.0, 1.0]))
    background: np.ndarray = field(default_factory=lambda: np.zeros(3))
    overlay: bool = False  # draw the analytic contours over the PNG, write NAME.contours.json
    overlay_color: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.2, 0.1]))
    normals: str = "exact"  # "exact": NURBS normal at the exact hit; "mesh": interpolated vertex normals on the mesh


@dataclass(frozen=True)
class OutputSpec:
    name: str
    exr: bool = True
    png: bool = True


@dataclass(frozen=True)
class Scene:
    path: Path
    image: ImageSpec
    camera: CameraSpec
    lights: LightSpec
    surfaces: tuple[NurbsSurface, ...]
    render: RenderSettings
    output: OutputSpec
    sha256: str  # of the scene file's bytes
    inputs_sha256: str  # of the scene file and every geometry file it reads
    notes: tuple[str, ...] = ()  # what CAD files gave: faces, unit, bounding box, skipped faces (printed by the CLI)

    @property
    def output_key(self) -> str:
        """What the rendered files depend on: every input file, and the settings the command line can override."""
        image, render = self.image, self.render
        return (f"{self.inputs_sha256}-{image.width}x{image.height}x{image.samples}-{render.normals}"
                f"{'-overlay' if render.overlay else ''}")

    def with_image(self, width: int | None = None, height: int | None = None, samples: int | None = None) -> "Scene":
        """The same scene with some `[image]` values overridden (command-line options), validated alike."""
        values = {"width": width, "height": height, "samples": samples}
        table = {k: v for k, v in vars(self.image).items()}
        table.update({k: v for k, v in values.items() if v is not None})
        return replace(self, image=_parse_image(_Table(self.path, "image", table)))

    def with_render(self, overlay: bool | None = None, normals: str | None = None) -> "Scene":
        """The same scene with `[render] overlay` and/or `normals` overridden (command-line options), validated alike."""
        values = {"overlay": overlay, "normals": normals}
        # Back to TOML's own types (colours as lists) so the table reads as the scene file's did.
        table = {k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in vars(self.render).items()}
        table.update({k: v for k, v in values.items() if v is not None})
        return replace(self, render=_parse_render(_Table(self.path, "render", table)))


class _Table:
    """One TOML table being read: tracks which keys were used so unknown ones are errors."""

    def __init__(self, file: Path, prefix: str, data: Any):
        self.file = file
        self.prefix = prefix
        if not isinstance(data, dict):
            raise SceneError(file, prefix, f"must be a table, got {_kind(data)}")
        self.data = data
        self.used: set[str] = set()

    def name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, message: str) -> SceneError:
        return SceneError(self.file, self.name(key), message)

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = ..., required: bool = False) -> Any:
        self.used.add(key)
        if key in self.data:
            return self.data[key]
        if required or default is ...:
            raise self.error(key, "required field is missing")
        return default

    def number(self, key: str, default: Any = ..., *, low: float | None = None, high: float | None = None,
               open_low: bool = False, open_high: bool = False, integer: bool = False,
               infinite_ok: bool = False) -> Any:
        """``infinite_ok``: +inf is accepted as "unbounded" (the default of such fields)."""
        value = self.raw(key, default)
        if value is default and default is not ...:
            return value
        if infinite_ok and value == math.inf:
            return math.inf
        return _number(self, key, value, low, high, open_low, open_high, integer)

    def boolean(self, key: str, default: bool) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.error(key, f"must be true or false, got {_kind(value)}")
        return value

    def string(self, key: str, default: Any = ..., choices: tuple[str, ...] | None = None) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise self.error(key, f"must be a string, got {_kind(value)}")
        if choices and value not in choices:
            raise self.error(key, f"must be one of {', '.join(repr(c) for c in choices)}, got {value!r}")
        return value

    def array(self, key: str, shape: tuple[int | None, ...], default: Any = ...) -> np.ndarray:
        """A nested list of finite numbers with the given shape (None: any positive length)."""
        value = self.raw(key, default)
        if value is default and default is not ...:
            return np.asarray(value, dtype=np.float64)
        return _array(self, key, value, shape)

    def vector(self, key: str, default: Any = ..., nonzero: bool = False) -> np.ndarray:
        vec = self.array(key, (3,), default)
        if nonzero and not np.any(vec != 0):
            raise self.error(key, "must not be the zero vector")
        return vec

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.error(unknown[0], "unknown key (check the spelling; see DESIGN.md for the scene schema)")


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return f"the number {value!r}"
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def _unit(vec: np.ndarray) -> np.ndarray:
    """vec / |vec| for a non-zero vec; scaled first so tiny components do not underflow to a zero norm."""
    scaled = vec / np.max(np.abs(vec))
    return scaled / np.linalg.norm(scaled)


def _check_bounded(table: _Table, key: str, value: float) -> None:
    if not math.isfinite(value):
        raise table.error(key, f"must be finite, got {value}")
    if abs(value) > MAX_MAGNITUDE:
        raise table.error(key, f"must be at most {MAX_MAGNITUDE:g} in magnitude (float32 tracing and images overflow beyond it), got {value:g}")


def _number(table: _Table, key: str, value: Any, low, high, open_low, open_high, integer) -> Any:
    if integer:
        if isinstance(value, bool) or not isinstance(value, int):
            raise table.error(key, f"must be an integer, got {_kind(value)}")
    else:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise table.error(key, f"must be a number, got {_kind(value)}")
        value = float(value)
        _check_bounded(table, key, value)
    if low is not None and (value < low or (open_low and value == low)):
        raise table.error(key, f"must be {'>' if open_low else '>='} {low:g}, got {value}")
    if high is not None and (value > high or (open_high and value == high)):
        raise table.error(key, f"must be {'<' if open_high else '<='} {high:g}, got {value}")
    return value


def _array(table: _Table, key: str, value: Any, shape: tuple[int | None, ...]) -> np.ndarray:
    """A nested list of numbers with the given shape; a None length is set by the first list at that depth.

    Every list at one depth must have the same length, so numpy never sees a ragged
    nesting (which it refuses with a ValueError) and the message names the odd row.
    """
    lengths = list(shape)

    def walk(item: Any, depth: int, where: str) -> None:
        if depth == len(shape):
            if isinstance(item, bool) or not isinstance(item, (int, float)):
                raise table.error(key + where, f"must be a number, got {_kind(item)}")
            _check_bounded(table, key + where, item)
            return
        if not isinstance(item, list):
            expected = shape[depth]
            raise table.error(key + where, f"must be an array{f' of {expected}' if expected else ''}, got {_kind(item)}")
        if not item:
            raise table.error(key + where, "must not be empty")
        if lengths[depth] is None:
            lengths[depth] = len(item)
        elif len(item) != lengths[depth]:
            like = "" if shape[depth] else f" like {table.name(key)}{where[:where.rfind('[')]}[0]"
            raise table.error(key + where, f"must have {lengths[depth]} entries{like}, got {len(item)}")
        for i, sub in enumerate(item):
            walk(sub, depth + 1, f"{where}[{i}]")

    walk(value, 0, "")
    return np.asarray(value, dtype=np.float64)


def _parse_image(t: _Table) -> ImageSpec:
    sides = {}
    for key, default in (("width", ImageSpec.width), ("height", ImageSpec.height)):
        sides[key] = t.number(key, default, low=1, integer=True)
        if sides[key] > MAX_SIDE:
            raise t.error(key, f"must be at most {MAX_SIDE} pixels ({FILM_LIMIT_REASON}), got {sides[key]}")
    width, height = sides["width"], sides["height"]
    samples = t.number("samples", ImageSpec.samples, low=1, high=MAX_SAMPLES, integer=True)
    t.finish()
    if width * height > MAX_PIXELS:
        raise t.error("width", f"{width}×{height} pixels is more than the maximum {MAX_PIXELS} ({FILM_LIMIT_REASON})")
    return ImageSpec(width, height, samples)


def _parse_camera(t: _Table) -> CameraSpec:
    projection = t.string("projection", "perspective", ("perspective", "orthographic"))
    eye = t.vector("eye", CameraSpec().eye)
    look_at = t.vector("look_at", CameraSpec().look_at)
    up = _unit(t.vector("up", CameraSpec().up, nonzero=True))
    fov = t.number("fov", 40.0, low=0, high=180, open_low=True, open_high=True)
    view_height = t.number("view_height", 3.0, low=0, open_low=True)
    t.finish()
    forward = look_at - eye
    if not np.linalg.norm(forward) > 0:
        raise t.error("look_at", "must differ from camera.eye")
    if np.linalg.norm(np.cross(_unit(forward), up)) < 1e-9:
        raise t.error("up", "must not be parallel to the view direction (look_at - eye)")
    return CameraSpec(projection, eye, look_at, up, fov, view_height)


def _parse_lights(t: _Table) -> LightSpec:
    point = t.vector("point", required_default())
    normal = t.vector("normal", required_default(), nonzero=True)
    direction = t.vector("direction", required_default(), nonzero=True)
    m = _unit(normal)
    c = _unit(direction)
    if abs(float(c @ m)) > IN_PLANE_TOLERANCE:
        raise t.error("direction", f"must lie in the light plane (perpendicular to lights.normal); c·m = {float(c @ m):.3g}")
    if t.has("positions"):
        for key in ("spacing", "count"):
            if t.has(key):
                raise t.error(key, "give either lights.positions or lights.spacing with lights.count, not both")
        positions = t.array("positions", (None,))
        if len(positions) > MAX_TUBES:
            raise t.error("positions", f"at most {MAX_TUBES} tubes (every ray is tested against every tube), got {len(positions)}")
    elif t.has("spacing") or t.has("count"):
        spacing = t.number("spacing", required_default(), low=0, open_low=True)
        count = t.number("count", required_default(), low=1, high=MAX_TUBES, integer=True)
        positions = (np.arange(count) - 0.5 * (count - 1)) * spacing
    else:
        raise t.error("positions", "required field is missing (or give lights.spacing and lights.count)")
    radius = t.number("radius", 0.05, low=0, open_low=True)
    length = t.number("length", math.inf, low=0, open_low=True, infinite_ok=True)
    t.finish()
    return LightSpec(point, m, c, positions, radius, length)


def required_default() -> Any:
    """Marker for `_Table` readers: the field has no default."""
    return ...


def _parse_render(t: _Table) -> RenderSettings:
    defaults = RenderSettings()
    tess = t.number("tessellation", defaults.tessellation, low=1, high=MAX_TESSELLATION, integer=True)
    colors = {}
    for key in ("surface_color", "line_color", "background", "overlay_color"):
        colors[key] = t.array(key, (3,), getattr(defaults, key))
        if np.any(colors[key] < 0):
            raise t.error(key, f"colour components must be >= 0, got {colors[key].tolist()}")
    overlay = t.boolean("overlay", defaults.overlay)
    normals = t.string("normals", defaults.normals, NORMALS_MODES)
    t.finish()
    return RenderSettings(tess, **colors, overlay=overlay, normals=normals)


def _parse_output(t: _Table, path: Path) -> OutputSpec:
    name = t.string("name", path.stem)
    if not name or name in (".", "..") or "/" in name or "\\" in name or not name.isprintable():
        raise t.error("name", f"must be a plain file stem without path separators or control characters, got {quote(name)}")
    if len(name.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES:
        raise t.error("name", f"must be at most {MAX_NAME_BYTES} bytes long (file names stop at 255 bytes), "
                              f"got {len(name.encode('utf-8', 'surrogatepass'))}")
    exr = t.boolean("exr", True)
    png = t.boolean("png", True)
    t.finish()
    if not (exr or png):
        raise SceneError(t.file, t.prefix, "exr and png are both false: the render would write nothing")
    return OutputSpec(name, exr, png)


def _check_knots(t: _Table, key: str, knots: np.ndarray, degree: int, n_ctrl: int) -> None:
    if knots.size != n_ctrl + degree + 1:
        raise t.error(key, f"needs {n_ctrl + degree + 1} knots for degree {degree} and {n_ctrl} control points, got {knots.size}")
    if np.any(np.diff(knots) < 0):
        i = int(np.flatnonzero(np.diff(knots) < 0)[0])
        raise t.error(key, f"knots must not decrease (knot {i + 1} = {knots[i + 1]:g} < knot {i} = {knots[i]:g})")
    values, counts = np.unique(knots, return_counts=True)
    if counts.max() > degree + 1:
        k = int(np.argmax(counts))
        where = "an end knot" if k in (0, len(values) - 1) else "an inner knot"
        raise t.error(key, f"{where} ({values[k]:g}) is repeated {counts[k]} times; at most degree + 1 = {degree + 1} allowed")
    if not knots[n_ctrl] > knots[degree]:
        raise t.error(key, "the parameter domain is empty (knot[degree] == knot[count])")
    inside = knots[degree:n_ctrl + 1]
    spans = np.diff(inside)
    narrowest = MIN_KNOT_SPAN * max(1.0, float(np.max(np.abs(knots))))
    thin = np.flatnonzero((spans > 0) & (spans < narrowest))
    if len(thin):
        i = degree + int(thin[0])
        raise t.error(key, f"knots {i} and {i + 1} differ by only {spans[thin[0]]:.3g}, too little for float64 "
                           f"(at least {narrowest:.3g}): merge them or rescale the knot vector")


ZERO_AREA = "the control points lie on a point or a line: the patch has zero area"


def _has_area(surface: NurbsSurface) -> bool:
    """False when the control points all lie on a point or a line: no area to reflect in."""
    pts = surface.points.reshape(-1, 3)
    centred = pts - pts.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    return bool(sv[1] > 1e-12 * max(sv[0], 1e-300))


def _check_geometry_patch(file: Path, index: int, surface: NurbsSurface) -> None:
    """What `_parse_inline_surface` checks of its numbers, for a patch read from a geometry file."""
    largest = float(np.max(np.abs(surface.points)))
    if largest > MAX_MAGNITUDE:
        raise SceneError(file, f"patch {index}", f"coordinates must be at most {MAX_MAGNITUDE:g} in magnitude "
                                                 f"(float32 tracing overflows beyond it), got {largest:g}")
    if not _has_area(surface):
        raise SceneError(file, f"patch {index}", ZERO_AREA)


def _parse_inline_surface(t: _Table, index: int) -> NurbsSurface:
    name = t.string("name", f"surface{index}")
    degree = t.raw("degree", required=True)
    if isinstance(degree, int) and not isinstance(degree, bool):
        degree = [degree, degree]
    if not (isinstance(degree, list) and len(degree) == 2 and all(isinstance(d, int) and not isinstance(d, bool) for d in degree)):
        raise t.error("degree", f"must be an integer or [degree_u, degree_v], got {degree!r}")
    p, q = degree
    if p < 1 or q < 1 or p > 30 or q > 30:
        raise t.error("degree", f"degrees must be between 1 and 30, got {degree}")
    points = t.array("points", (None, None, 3))
    nu, nv = points.shape[:2]
    if nu < p + 1 or nv < q + 1:
        raise t.error("points", f"degree {p}×{q} needs at least {p + 1}×{q + 1} control points, got {nu}×{nv}")
    knots_u = t.array("knots_u", (None,))
    knots_v = t.array("knots_v", (None,))
    _check_knots(t, "knots_u", knots_u, p, nu)
    _check_knots(t, "knots_v", knots_v, q, nv)
    if t.has("weights"):
        weights = t.array("weights", (nu, nv))
        if np.any(weights <= 0):
            i, j = np.argwhere(weights <= 0)[0]
            raise t.error(f"weights[{i}][{j}]", f"weights must be > 0, got {weights[i, j]:g}")
    else:
        weights = np.ones((nu, nv))
    t.finish()
    surface = NurbsSurface(p, q, knots_u, knots_v, points, weights, name)
    if not _has_area(surface):
        raise t.error("points", ZERO_AREA)
    return surface


def _check_mesh_size(path: Path, surfaces: list[NurbsSurface], per_span: int) -> None:
    """Refuse, before any allocation, a tessellation that cannot fit (tessellation.py: per_span segments a span)."""
    vertices = 0
    for surface in surfaces:
        breaks_u, breaks_v = surface.span_breaks()
        vertices += ((len(breaks_u) - 1) * per_span + 1) * ((len(breaks_v) - 1) * per_span + 1)
    if vertices > MAX_MESH_VERTICES:
        raise SceneError(path, "render.tessellation",
                         f"{per_span} segments per knot span make {vertices} mesh vertices over {len(surfaces)} patches, "
                         f"more than the {MAX_MESH_VERTICES} that fit in memory: lower render.tessellation")


def _hash_files(paths: list[Path]) -> tuple[str, str]:
    try:
        digests = [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths]
    except OSError as exc:  # read a moment ago: moved or removed since
        raise SceneError(exc.filename or paths[0], "", f"cannot read it again to hash it ({exc.strerror or exc})") from None
    combined = hashlib.sha256("\n".join(digests).encode()).hexdigest()
    return digests[0], combined


def _long_number_position(text: str) -> str:
    """``line L, column C`` of the first run of thousands of digits in ``text``, or "" if there is none."""
    found = re.search(r"[0-9_]{4000,}", text)
    if not found:
        return ""
    line_start = text.rfind("\n", 0, found.start()) + 1
    return f"line {text.count(chr(10), 0, found.start()) + 1}, column {found.start() - line_start + 1}"


def load_scene(path: str | Path, skip_bad_faces: bool = False) -> Scene:
    """Read and validate a scene file; raises `SceneError` naming the file and field.

    A CAD file (STEP, IGES, .3dm) in place of the scene file gets the default scene around the
    part (exchange/partscene.py). ``skip_bad_faces``: CAD faces that cannot be read are left out
    (and listed in `Scene.notes`) instead of failing the scene.
    """
    path = Path(path)
    if is_cad_path(path):
        from .partscene import load_part_scene

        return load_part_scene(path, skip_bad_faces)
    text = read_text(path, "scene file")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        # tomllib puts the position at the end ("... (at line 3, column 7)"); lead with it instead.
        where = re.fullmatch(r"(.*) \((at line \d+, column \d+|at end of document)\)", str(exc), re.S)
        if where:
            raise SceneError(path, where[2].removeprefix("at "), f"TOML syntax error: {where[1]}") from None
        raise SceneError(path, "", f"TOML syntax error: {exc}") from None
    except RecursionError:  # tomllib reads nested arrays and inline tables recursively
        raise SceneError(path, "", "TOML syntax error: arrays or inline tables nested too deeply to read") from None
    except ValueError as exc:
        # int() refuses more than 4300 digits (Python's guard against slow conversions); tomllib passes that on.
        raise SceneError(path, _long_number_position(text), "TOML syntax error: a number with more than 4300 digits") from None

    root = _Table(path, "", doc)
    image = _parse_image(_Table(path, "image", root.raw("image", {})))
    camera = _parse_camera(_Table(path, "camera", root.raw("camera", {})))
    lights = _parse_lights(_Table(path, "lights", root.raw("lights", required=True)))
    render = _parse_render(_Table(path, "render", root.raw("render", {})))
    output = _parse_output(_Table(path, "output", root.raw("output", {})), path)

    entries = root.raw("surface", required=True)
    if not isinstance(entries, list) or not entries:
        raise SceneError(path, "surface", "needs one or more [[surface]] tables")
    surfaces: list[NurbsSurface] = []
    geometry_files: list[Path] = []
    notes: list[str] = []
    faces_skipped = False
    for i, entry in enumerate(entries):
        t = _Table(path, f"surface[{i}]", entry)
        if t.has("file"):
            given = t.string("file")
            if not given.strip() or "\0" in given:
                raise t.error("file", f"must name a geometry file (.bpt{''.join(', ' + s for s in CAD_SUFFIXES)}), got {quote(given)}")
            try:
                file = (path.parent / given).resolve()
            except (OSError, RuntimeError):  # a symlink loop (RuntimeError before Python 3.13): reading will say so
                file = Path(os.path.abspath(path.parent / given))
            name = t.string("name", "")
            t.finish()
            try:
                if is_cad_path(file):
                    from .partscene import read_part

                    patches, summary, skipped = read_part(file, name, skip_bad_faces)
                    notes.extend(summary)
                    faces_skipped = faces_skipped or skipped
                else:
                    patches = read_bpt(file, name)
                    for k, patch in enumerate(patches):
                        _check_geometry_patch(file, k, patch)
            except SceneError as exc:
                raise SceneError(exc.file, exc.field, f"{exc.reason} (from {path}: {t.name('file')})") from None
            surfaces.extend(patches)
            geometry_files.append(file)
        else:
            surfaces.append(_parse_inline_surface(t, i))
    root.finish()
    _check_mesh_size(path, surfaces, render.tessellation)
    sha, inputs = _hash_files([path, *geometry_files])
    if faces_skipped:  # the pixels lack those faces: not the output of the same inputs without --skip-bad-faces
        inputs = hashlib.sha256(f"{inputs}\nskip-bad-faces".encode()).hexdigest()
    return Scene(path, image, camera, lights, tuple(surfaces), render, output, sha, inputs, tuple(notes))
