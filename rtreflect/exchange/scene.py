"""Scene files (TOML) → a validated, immutable `Scene`.

The schema is documented for users in docs/scene-format.md: tables ``[image]``,
``[camera]``, ``[lights]``, one or more ``[[surface]]``, ``[render]``, ``[output]``.
Every problem is reported as a `SceneError` naming the file and the field, so a
user can fix it from a single line; independent problems (one per table and per
surface) are reported together as `SceneErrors`. A `Scene` built in code
(`Scene(surfaces=..., lights=...)`) and `Scene.replace` go through the same readers.
"""

from __future__ import annotations

import contextlib
import difflib
import hashlib
import json
import math
import os
import re
import tomllib
from collections import Counter
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .bpt import read_bpt
from .cad import CAD_SUFFIXES, is_cad_path, read_part, refuse_misnamed_cad_file
from ..errors import SceneError, SceneErrors, quote, read_text
from ..geometry.knots import knot_vector_problem
from ..geometry.patches import MAX_MAGNITUDE, ZERO_AREA, has_area, patch_problem
from ..geometry.surfaces import NurbsSurface

#: Largest image side. The film keeps 22 float32 planes per pixel, and beyond this
#: the planes alone pass the memory of a workstation.
MAX_SIDE = 16384
#: Largest pixel count (8192 × 16384): 22 planes × 4 bytes × 2^27 ≈ 12 GB of film.
MAX_PIXELS = 1 << 27
#: Why the two limits above exist, for the messages that enforce them.
FILM_LIMIT_REASON = "22 float32 channels per pixel: about 12 GB of EXR at 8192×16384, and validate keeps it in memory"
#: Most light tubes: every sample is tested against every tube, so more only slows the render;
#: no image shows this many stripes apart.
MAX_TUBES = 10000
#: Most mesh vertices over all patches (tessellation × knot spans, squared): about 1.5 GB of mesh,
#: (u, v) table and Embree copy. Newton refines hits onto the surface, so a finer mesh buys nothing.
MAX_MESH_VERTICES = 1 << 23
#: Longest output name in UTF-8 bytes: file names stop at 255 bytes, and the temporary name
#: written first adds a dot, a random part and the extension.
MAX_NAME_BYTES = 200
#: Largest s (s×s samples per pixel); 256 samples per pixel is far past visible gains.
MAX_SAMPLES = 16
#: `[image] samples` of the analytic anti-aliasing (integrator/analytic.py): one exact sample per pixel, the
#: stripes' coverage in closed form, edge pixels supersampled. The default.
ANALYTIC = "analytic"
#: Largest tessellation per knot span; hits are refined by Newton, so more buys nothing.
MAX_TESSELLATION = 256
#: |c·m| above this means the tube direction is not in the light plane.
IN_PLANE_TOLERANCE = 1e-6
#: `[lights] shape`: parallel tubes (Ulmet), or concentric circles about a centre in the light plane (circular
#: reflection and highlight lines, Maekawa et al.), for the modes that see the light plane (`CIRCLE_MODES`).
LIGHT_SHAPES = ("tubes", "circles")
CIRCLE_MODES = ("reflection", "highlight")
#: `[camera] view` names: where an automatic eye looks from, relative to the model's up axis (`camera.up`).
VIEWS = ("iso", "top", "bottom", "front", "back", "left", "right")
#: Orthographic view height of a camera with an explicit eye and no view_height (the reader's old default).
VIEW_HEIGHT = 3.0
#: `[render] normals`: the exact NURBS normal, or the analysis-mesh normal CAD tools use (for comparison).
NORMALS_MODES = ("exact", "mesh")
#: `[render] shading`: the surface under the stripes lit from the eye (`modes.shading`), or one flat colour.
SHADING_MODES = ("lambert", "flat")
#: `[render] blur` at most 1: the stripe's soft edge runs over [r(1 − blur), r(1 + blur)] (`modes.profile`), whose
#: inner end must stay at or beyond the tube's axis.
MAX_BLUR = 1.0
#: `[render] overlay` besides true and false: NAME.png plain, the overlay drawn in NAME.side.png beside a copy of it.
OVERLAY_SIDE = "side"
#: Widest `[render] overlay_width` in pixels: wider lines hide the stripes they are there to check.
MAX_OVERLAY_WIDTH = 16.0
#: `[render] mode`: the interrogation tools (modes/registry.py builds each; the two lists must agree).
RENDER_MODES = ("reflection", "highlight", "isophote", "draft", "curvature", "zebra")
#: `[render]` keys that belong to some modes only: given with another mode they are an error.
MODE_KEYS = {"step": ("isophote", "zebra"), "light": ("isophote",), "pull": ("draft",), "thresholds": ("draft",),
             "quantity": ("curvature",), "range": ("curvature",), "bands": ("curvature",)}
#: `[render] quantity` of the curvature map (geometry/curvature.py): K, H, κ1, κ2, max(|κ1|, |κ2|), 1/max(|κ1|, |κ2|).
CURVATURE_QUANTITIES = ("gaussian", "mean", "k1", "k2", "maxabs", "radius")
#: Defaults of the mode keys, for the mode that uses them: isophotes every 10°; draft bands at 0°, 1°, 3°
#: (the usual minimum drafts of moulded parts); the mean curvature on an automatic range.
MODE_DEFAULTS = {"step": 10.0, "pull": (0.0, 0.0, 1.0), "thresholds": (0.0, 1.0, 3.0), "quantity": "mean",
                 "range": "auto", "bands": 0}
#: Most `[render] bands` of a curvature map, and most draft `thresholds`: each is a level of the map.
MAX_BANDS = 64


@dataclass(frozen=True)
class ImageSpec:
    width: int = 960
    height: int = 540
    # "analytic" (`ANALYTIC`): one exact sample per pixel, the stripes' coverage in closed form, edge pixels
    # supersampled 4×4; or s, an int: s×s stratified samples per pixel.
    samples: int | str = ANALYTIC


@dataclass(frozen=True)
class CameraSpec:
    """A camera; None marks a value chosen automatically to frame the part (`integrator.autorig`)."""

    projection: str = "perspective"
    eye: np.ndarray | None = None  # None: on `view`, at the distance that frames the part
    look_at: np.ndarray | None = None  # None: the centre of the part's bounding box
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    fov: float = 40.0
    view_height: float | None = None  # orthographic; None: fitted to the part (3.0 with an explicit eye)
    view: str | np.ndarray = "iso"  # where an automatic eye looks from: one of VIEWS, or a direction (eye − look_at)

    @property
    def automatic(self) -> bool:
        return self.eye is None or self.look_at is None or (self.projection == "orthographic" and self.view_height is None)


@dataclass(frozen=True)
class LightSpec:
    """Parallel tubes in one plane: through Q with unit normal m, along unit c, at c_k along e = c × m.

    With ``auto`` (no ``[lights]``, or ``auto = true``) the None fields are chosen by the automatic
    light rig (`integrator.autorig`) from where the reflections land; ``count`` and ``spacing``
    are then what the rig keeps of the user's wishes. A resolved spec has ``auto`` false.
    """

    point: np.ndarray | None  # Q
    normal: np.ndarray | None  # m (unit)
    direction: np.ndarray | None  # c (unit)
    positions: np.ndarray | None  # c_k
    radius: float | None
    length: float = math.inf
    auto: bool = False
    count: int | None = None  # auto: tubes across the visible range of f (default `AUTO_TUBES`)
    spacing: float | None = None  # auto: fixed spacing of the tubes (default: the range of f over count)
    shape: str = "tubes"  # `LIGHT_SHAPES`: "circles" reads positions as radii r_k about ``centre`` in the plane
    centre: np.ndarray | None = None  # circles: C, on the light plane (default: point Q)


@dataclass(frozen=True)
class RenderSettings:
    tessellation: int = 16
    surface_color: np.ndarray = field(default_factory=lambda: np.array([0.18, 0.18, 0.2]))
    line_color: np.ndarray = field(default_factory=lambda: np.array([1.0, 1.0, 1.0]))
    #: A dark neutral grey (sRGB 64, about 25 %): opaque PNGs on light slides and dark screens alike show the part's
    #: outline against it, and white lines stay visible where they leave the part (issue 13).
    background: np.ndarray = field(default_factory=lambda: np.full(3, 0.05))
    overlay: bool | str = False  # draw the analytic contours over the PNG (or OVERLAY_SIDE), write NAME.contours.json
    overlay_color: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.2, 0.1]))
    normals: str = "exact"  # "exact": NURBS normal at the exact hit; "mesh": interpolated vertex normals on the mesh
    shading: str = "lambert"  # one of SHADING_MODES: the surface colour lit from the eye, or flat
    blur: float = 0.0  # soft stripe edge, a fraction of the radius (`modes.profile`); 0: the hard tube of eq. 4
    overlay_width: float = 2.0  # pixels: the overlay's line width, anti-aliased
    mode: str = "reflection"  # `RENDER_MODES`; the keys below are None unless the mode uses them (`MODE_KEYS`)
    step: float | None = None  # isophote: degrees between levels of angle(n, L); zebra: of the angle of s about c
    light: np.ndarray | None = None  # isophote: L, unit (None: the light plane's normal m)
    pull: np.ndarray | None = None  # draft: the pull direction, unit
    thresholds: tuple | None = None  # draft: draft angles (degrees, ascending) bounding the colour bands
    quantity: str | None = None  # curvature: `CURVATURE_QUANTITIES`
    range: tuple | str | None = None  # curvature: (min, max) of the colour map, or "auto"
    bands: int | None = None  # curvature: iso-curvature lines splitting the range into this many bands (0: none)


@dataclass(frozen=True)
class OutputSpec:
    name: str
    exr: bool = True
    png: bool = True


REQUIRED_MISSING = "required field is missing"
#: The scene-format reference shipped with the package, named by messages that send users to the schema.
SCHEMA_DOC = "docs/scene-format.md"

#: Every key each table accepts (the readers below may read only these; docs/scene-format.md documents each).
#: A ``[[surface]]`` with ``file`` takes only ``file`` and ``name``.
TABLE_KEYS: dict[str, tuple[str, ...]] = {
    "": ("image", "camera", "lights", "surface", "render", "output"),
    "image": ("width", "height", "samples"),
    "camera": ("projection", "eye", "look_at", "up", "fov", "view_height", "view"),
    "lights": ("auto", "point", "normal", "direction", "positions", "spacing", "count", "radius", "length", "shape",
               "centre"),
    "surface": ("name", "degree", "points", "knots_u", "knots_v", "weights", "file"),
    "render": ("tessellation", "surface_color", "line_color", "background", "shading", "blur", "overlay",
               "overlay_color", "overlay_width", "normals", "mode", "step", "light", "pull", "thresholds", "quantity",
               "range", "bands"),
    "output": ("name", "exr", "png"),
}
#: The tables `Scene.replace` re-reads, in the order a scene file is read (so the first error is the file's first).
SCENE_TABLES = ("image", "camera", "lights", "render", "output")
#: Fields `Scene.output_key` names itself (the command line overrides them); changing any other field of a
#: scene in code changes its `inputs_sha256`, so `batch` never takes an old render for it.
KEYED_FIELDS = {"image": ("width", "height", "samples"), "render": ("overlay", "normals")}
#: Path and default output name of a scene built in code: messages read ``<scene>: lights.radius: ...``.
CODE_SCENE_PATH = Path("<scene>")
CODE_SCENE_NAME = "scene"


@dataclass(frozen=True, init=False)
class Scene:
    """A validated, immutable scene: read from a file (`load_scene`) or built in code.

    In code, pass the tables as keyword arguments, with the keys and meanings of the
    scene file (docs/scene-format.md); numpy arrays stand for TOML arrays::

        Scene(surfaces=[{"degree": 3, "points": P, "knots_u": ku, "knots_v": kv, "weights": w}],
              lights={"point": [0, 0, 3], "normal": [0, 0, 1], "direction": [0, 1, 0], "spacing": 0.4, "count": 9},
              camera={"eye": [0, -3, 2]}, image={"width": 320, "height": 180}, output={"name": "part"})

    ``surfaces`` entries may also be `NurbsSurface` objects or ``{"file": "part.bpt"}``
    (relative to ``path``'s folder, by default the working folder). Every value is checked
    by the same readers as a scene file, with the same one-line `SceneError` messages
    (FILE is ``path``, by default ``<scene>``); several independent errors come together
    as `SceneErrors`. The internal form, ``Scene(path, image, camera, lights, surfaces,
    render, output, sha256, inputs_sha256)`` with the parsed specs, is what `load_scene`
    and ``dataclasses.replace`` use.
    """

    path: Path
    image: ImageSpec
    camera: CameraSpec
    lights: LightSpec
    surfaces: tuple[NurbsSurface, ...]
    render: RenderSettings
    output: OutputSpec
    sha256: str  # of the scene file's bytes (in code: of the tables' canonical JSON)
    inputs_sha256: str  # of the scene file and every geometry file it reads (in code: with the geometry files')

    notes: tuple[str, ...] = ()  # what CAD files gave: faces, unit, bounding box, skipped faces (printed by the CLI)
    rig: tuple[str, ...] = ()  # the automatic camera and tubes chosen (`integrator.autorig`), for the summary line
    def __init__(self, path=None, image=None, camera=None, lights=None, surfaces=None, render=None, output=None,
                 sha256=None, inputs_sha256=None, notes=(), rig=()):
        parsed = (isinstance(image, ImageSpec) and isinstance(camera, CameraSpec) and isinstance(lights, LightSpec)
                  and isinstance(render, RenderSettings) and isinstance(output, OutputSpec)
                  and isinstance(surfaces, tuple) and all(isinstance(s, NurbsSurface) for s in surfaces))
        if parsed and sha256 is not None and inputs_sha256 is not None:
            values = (Path(path), image, camera, lights, surfaces, render, output, sha256, inputs_sha256, tuple(notes),
                      tuple(rig))
        else:
            if sha256 is not None or inputs_sha256 is not None:
                raise TypeError("Scene: sha256 and inputs_sha256 are computed for a scene built from tables")
            values = _scene_from_code(Path(path) if path is not None else CODE_SCENE_PATH, image, camera, lights,
                                      surfaces, render, output)
        for f, value in zip(fields(Scene), values):
            object.__setattr__(self, f.name, value)

    @property
    def automatic(self) -> bool:
        """Whether the camera or the tubes still wait for the automatic choices (`integrator.autorig.resolve`)."""
        return self.camera.automatic or self.lights.auto

    @property
    def output_key(self) -> str:
        """What the rendered files depend on: every input file, and the settings the command line can override."""
        image, render = self.image, self.render
        return (f"{self.inputs_sha256}-{image.width}x{image.height}x{image.samples}-{render.normals}"
                f"{'-overlay' if render.overlay else ''}{'-side' if render.overlay == OVERLAY_SIDE else ''}")

    def replace(self, *, image=None, camera=None, lights=None, surfaces=None, render=None, output=None) -> "Scene":
        """A copy with some tables changed, validated as a scene file is (one-line `SceneError`s naming the field).

        A mapping changes only the keys it names (``replace(camera={"fov": 30})``); a spec object
        (`CameraSpec`, ...) replaces the whole table; ``surfaces`` replaces the list (entries as for
        `Scene`). For the tubes, ``spacing`` and/or ``count`` replace ``positions`` (the one not given is the
        current row's), and ``positions`` replaces them.
        """
        changes = {"image": image, "camera": camera, "lights": lights, "render": render, "output": output}
        changes = {name: value for name, value in changes.items() if value is not None}
        tables = {}
        for name, change in changes.items():
            if isinstance(change, dict):
                table = _spec_table(getattr(self, name))
                change = _toml_value(change)
                if name == "lights" and ("spacing" in change or "count" in change) and "positions" in table:
                    # Tubes given by spacing and count: the one not given is that of the current row of tubes.
                    positions = table.pop("positions")
                    change = {"count": len(positions), **change}
                    if "spacing" not in change and len(positions) > 1:
                        change["spacing"] = positions[1] - positions[0]
                table.update(change)
            else:
                table = _toml_value(change)
            tables[name] = table
        errors = _Errors()
        specs: dict[str, Any] = {}
        for name in SCENE_TABLES:
            if name in tables:
                with errors.collect():
                    specs[name] = _PARSERS[name](_Table(self.path, name, tables[name]), self.path)
        new_surfaces, geometry_files = self.surfaces, []
        if surfaces is not None:
            read = _parse_surfaces(self.path, _toml_value(list(surfaces)), errors)
            new_surfaces, geometry_files = read.surfaces, read.files
        errors.raise_any()
        changed = replace(self, **specs, surfaces=tuple(new_surfaces))
        _check_light_shape(self.path, changed.lights, changed.render)
        if surfaces is not None or "render" in specs:
            _check_mesh_size(self.path, list(changed.surfaces), changed.render.tessellation)
        moved = {name: _unkeyed(name, specs[name]) for name in specs
                 if _unkeyed(name, specs[name]) != _unkeyed(name, getattr(self, name))}
        if moved or surfaces is not None:
            # The output no longer follows from the input files alone: mix the changes into their hash.
            digest = hashlib.sha256(self.inputs_sha256.encode())
            digest.update(_canonical(moved).encode())
            if surfaces is not None:
                digest.update(_surfaces_digest(changed.surfaces, geometry_files).encode())
            changed = replace(changed, inputs_sha256=digest.hexdigest())
        return changed

    def with_image(self, width: int | None = None, height: int | None = None, samples: int | str | None = None) -> "Scene":
        """The same scene with some `[image]` values overridden (command-line options), validated alike."""
        values = {"width": width, "height": height, "samples": samples}
        return self.replace(image={k: v for k, v in values.items() if v is not None})

    def with_render(self, overlay: bool | str | None = None, normals: str | None = None) -> "Scene":
        """The same scene with `[render] overlay` and/or `normals` overridden (command-line options), validated alike."""
        values = {"overlay": overlay, "normals": normals}
        return self.replace(render={k: v for k, v in values.items() if v is not None})


class _Table:
    """One TOML table being read: tracks which keys were used so unknown ones are errors."""

    def __init__(self, file: Path, prefix: str, data: Any, keys: tuple[str, ...] | None = None):
        self.file = file
        self.prefix = prefix
        if not isinstance(data, dict):
            raise SceneError(file, prefix, f"must be a table, got {_kind(data)}")
        self.data = data
        self.used: set[str] = set()
        #: The keys this table accepts (`TABLE_KEYS`), for the nearest-key suggestion of `finish`.
        self.keys = keys if keys is not None else TABLE_KEYS[re.sub(r"\[\d+\]$", "", prefix)]

    def name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, message: str) -> SceneError:
        return SceneError(self.file, self.name(key), message)

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = ..., required: bool = False) -> Any:
        assert key in self.keys, f"{self.name(key)} is read but not in TABLE_KEYS"  # keeps the documented list true
        self.used.add(key)
        if key in self.data:
            return self.data[key]
        if required or default is ...:
            raise self.error(key, REQUIRED_MISSING)
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
        """Every key not read is an error, each suggesting the nearest accepted key (difflib) if one is close."""
        unknown = sorted(set(self.data) - self.used, key=str)
        errors = []
        for key in unknown:
            near = difflib.get_close_matches(str(key), [k for k in self.keys if k != key], n=1)
            if near:
                hint = f"did you mean {near[0]}?"
            elif self.prefix and key in TABLE_KEYS[""]:  # a table nested one level too deep
                hint = f"[{key}] is a table of its own, not a key of [{self.prefix}]"
            else:
                hint = f"see {SCHEMA_DOC} for the keys of this table"
            errors.append(self.error(key, f"unknown key; {hint}"))
        if errors:
            raise errors[0] if len(errors) == 1 else SceneErrors(errors)


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
    """A nested list of numbers with the given shape; a None length is the one most lists at that depth have.

    Every list at one depth must have the same length, so numpy never sees a ragged
    nesting (which it refuses with a ValueError) and the message names the odd row:
    the one that differs from the majority (on a tie, from the first row), not the
    row after a short one.
    """
    lengths = list(shape)
    seen: list[Counter] = [Counter() for _ in shape]

    def count(item: Any, depth: int) -> None:
        if depth < len(shape) and isinstance(item, list):
            seen[depth][len(item)] += 1
            for sub in item:
                count(sub, depth + 1)

    count(value, 0)
    for depth, expected in enumerate(shape):
        if expected is None and seen[depth]:
            lengths[depth] = seen[depth].most_common(1)[0][0]  # ties: the first row's length (Counter keeps order)

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
        if len(item) != lengths[depth]:
            like = ""
            if not shape[depth]:
                agree = seen[depth][lengths[depth]]
                like = f" like the other {agree} rows" if agree > 1 else f" like {table.name(key)}{where[:where.rfind('[')]}[0]"
            raise table.error(key + where, f"must have {lengths[depth]} entries{like}, got {len(item)}")
        for i, sub in enumerate(item):
            walk(sub, depth + 1, f"{where}[{i}]")

    walk(value, 0, "")
    return np.asarray(value, dtype=np.float64)


def parse_samples(t: _Table, key: str) -> int | str:
    """``[image] samples``: ``"analytic"`` (the default) or an integer s from 1 to `MAX_SAMPLES`."""
    value = t.raw(key, ImageSpec.samples)
    if isinstance(value, str):
        if value != ANALYTIC:
            raise t.error(key, f'must be "{ANALYTIC}" or an integer from 1 to {MAX_SAMPLES}, got {value!r}')
        return value
    return t.number(key, ImageSpec.samples, low=1, high=MAX_SAMPLES, integer=True)


def _parse_image(t: _Table) -> ImageSpec:
    sides = {}
    for key, default in (("width", ImageSpec.width), ("height", ImageSpec.height)):
        sides[key] = t.number(key, default, low=1, integer=True)
        if sides[key] > MAX_SIDE:
            raise t.error(key, f"must be at most {MAX_SIDE} pixels ({FILM_LIMIT_REASON}), got {sides[key]}")
    width, height = sides["width"], sides["height"]
    samples = parse_samples(t, "samples")
    t.finish()
    if width * height > MAX_PIXELS:
        raise t.error("width", f"{width}×{height} pixels is more than the maximum {MAX_PIXELS} ({FILM_LIMIT_REASON})")
    return ImageSpec(width, height, samples)


def _parse_camera(t: _Table) -> CameraSpec:
    projection = t.string("projection", "perspective", ("perspective", "orthographic"))
    eye = t.vector("eye") if t.has("eye") else None
    look_at = t.vector("look_at") if t.has("look_at") else None
    up = _unit(t.vector("up", CameraSpec().up, nonzero=True))
    fov = t.number("fov", 40.0, low=0, high=180, open_low=True, open_high=True)
    view_height = t.number("view_height", None, low=0, open_low=True)
    if view_height is None and eye is not None:
        view_height = VIEW_HEIGHT
    view: str | np.ndarray = "iso"
    if t.has("view"):
        if isinstance(t.raw("view"), str):
            view = t.string("view", choices=VIEWS)
        else:
            view = _unit(t.vector("view", nonzero=True))
            if np.linalg.norm(np.cross(view, up)) < 1e-9:
                raise t.error("view", "a view along camera.up needs another camera.up: use view = \"top\" or \"bottom\"")
    t.finish()
    if eye is not None and look_at is not None:
        forward = look_at - eye
        if not np.linalg.norm(forward) > 0:
            raise t.error("look_at", "must differ from camera.eye")
        if np.linalg.norm(np.cross(_unit(forward), up)) < 1e-9:
            raise t.error("up", "must not be parallel to the view direction (look_at - eye)")
    return CameraSpec(projection, eye, look_at, up, fov, view_height, view)


def _parse_lights(t: _Table) -> LightSpec:
    # No [lights] (or an empty one) is the automatic rig; `auto = true` keeps the keys given and chooses the rest.
    if t.boolean("auto", not t.data):
        return _parse_auto_lights(t)
    point = t.vector("point", required_default())
    normal = t.vector("normal", required_default(), nonzero=True)
    direction = t.vector("direction", required_default(), nonzero=True)
    m = _unit(normal)
    c = _unit(direction)
    if abs(float(c @ m)) > IN_PLANE_TOLERANCE:
        raise t.error("direction", f"must lie in the light plane (perpendicular to lights.normal); c·m = {float(c @ m):.3g}")
    shape = t.string("shape", "tubes", LIGHT_SHAPES)
    centre = _circle_centre(t, shape, point, m)
    if t.has("positions"):
        positions = _given_positions(t)
        if shape == "circles" and np.any(positions <= 0):
            raise t.error("positions", f"circle radii must be > 0, got {positions.tolist()}")
    elif t.has("spacing") or t.has("count"):
        spacing = t.number("spacing", required_default(), low=0, open_low=True)
        count = t.number("count", required_default(), low=1, high=MAX_TUBES, integer=True)
        if shape == "circles":  # radii spacing, 2·spacing, …, count·spacing about the centre
            positions = np.arange(1, count + 1) * spacing
        else:
            positions = (np.arange(count) - 0.5 * (count - 1)) * spacing
    else:
        raise t.error("positions", "required field is missing (or give lights.spacing and lights.count)")
    radius = t.number("radius", 0.05, low=0, open_low=True)
    length = t.number("length", math.inf, low=0, open_low=True, infinite_ok=True)
    if shape == "circles" and math.isfinite(length):
        raise t.error("length", "circles have no length (only tubes do): remove it (or inf)")
    t.finish()
    return LightSpec(point, m, c, positions, radius, length, shape=shape, centre=centre)


def _circle_centre(t: _Table, shape: str, point: np.ndarray, m: np.ndarray) -> np.ndarray | None:
    """``lights.centre`` of circles: on the light plane (to `IN_PLANE_TOLERANCE` of the scene's scale), default Q."""
    if shape != "circles":
        if t.has("centre"):
            raise t.error("centre", "only circles have a centre: set lights.shape = \"circles\" or remove it")
        return None
    if not t.has("centre"):
        return np.asarray(point, dtype=np.float64)
    centre = t.vector("centre", required_default())
    off = float((centre - point) @ m)
    scale = max(1.0, float(np.abs(point).max()), float(np.abs(centre).max()))
    if abs(off) > IN_PLANE_TOLERANCE * scale:
        raise t.error("centre", f"must lie in the light plane (through lights.point, normal lights.normal); "
                                f"it is {off:.3g} off it")
    return centre


def _given_positions(t: _Table) -> np.ndarray:
    """``lights.positions`` (then neither ``spacing`` nor ``count``), at most `MAX_TUBES`."""
    for key in ("spacing", "count"):
        if t.has(key):
            raise t.error(key, "give either lights.positions or lights.spacing with lights.count, not both")
    positions = t.array("positions", (None,))
    if len(positions) > MAX_TUBES:
        raise t.error("positions", f"at most {MAX_TUBES} tubes (every ray is tested against every tube), got {len(positions)}")
    return positions


def _parse_auto_lights(t: _Table) -> LightSpec:
    """``[lights]`` for the automatic rig: every key optional, each given one kept (`integrator.autorig`)."""
    point = t.vector("point") if t.has("point") else None
    normal = _unit(t.vector("normal", nonzero=True)) if t.has("normal") else None
    direction = _unit(t.vector("direction", nonzero=True)) if t.has("direction") else None
    if normal is not None and direction is not None and abs(float(direction @ normal)) > IN_PLANE_TOLERANCE:
        raise t.error("direction", f"must lie in the light plane (perpendicular to lights.normal); "
                                   f"c·m = {float(direction @ normal):.3g}")
    positions = _given_positions(t) if t.has("positions") else None
    count = t.number("count", None, low=1, high=MAX_TUBES, integer=True)
    spacing = t.number("spacing", None, low=0, open_low=True)
    radius = t.number("radius", None, low=0, open_low=True)
    length = t.number("length", math.inf, low=0, open_low=True, infinite_ok=True)
    if t.string("shape", "tubes", LIGHT_SHAPES) != "tubes":
        raise t.error("shape", "the automatic rig places tubes: circles need lights.point, normal, direction and "
                               "their radii")
    t.finish()
    return LightSpec(point, normal, direction, positions, radius, length, True, count, spacing)


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
    overlay = t.raw("overlay", defaults.overlay)
    if not isinstance(overlay, bool) and overlay != OVERLAY_SIDE:
        raise t.error("overlay", f"must be true, false or {OVERLAY_SIDE!r}, got "
                                 f"{quote(overlay) if isinstance(overlay, str) else _kind(overlay)}")
    normals = t.string("normals", defaults.normals, NORMALS_MODES)
    shading = t.string("shading", defaults.shading, SHADING_MODES)
    blur = float(t.number("blur", defaults.blur, low=0, high=MAX_BLUR))
    overlay_width = float(t.number("overlay_width", defaults.overlay_width, low=0, high=MAX_OVERLAY_WIDTH,
                                   open_low=True))
    mode = t.string("mode", defaults.mode, RENDER_MODES)
    keys = _mode_keys(t, mode)
    t.finish()
    return RenderSettings(tess, **colors, overlay=overlay, normals=normals, shading=shading, blur=blur,
                          overlay_width=overlay_width, mode=mode, **keys)


def _mode_keys(t: _Table, mode: str) -> dict[str, Any]:
    """The `[render]` keys of ``mode`` (`MODE_KEYS`), checked, with defaults; another mode's key is an error."""
    for key, modes in MODE_KEYS.items():
        if t.has(key) and mode not in modes:
            raise t.error(key, f"not used by mode {mode!r} (only by {', '.join(repr(m) for m in modes)}): "
                               f"set render.mode or remove it")
    keys: dict[str, Any] = {}
    if mode in ("isophote", "zebra"):
        keys["step"] = t.number("step", MODE_DEFAULTS["step"], low=0, high=90, open_low=True)
    if mode == "isophote":
        keys["light"] = _unit(t.vector("light", nonzero=True)) if t.has("light") else None
    elif mode == "draft":
        keys["pull"] = _unit(t.vector("pull", MODE_DEFAULTS["pull"], nonzero=True))
        thresholds = t.array("thresholds", (None,), MODE_DEFAULTS["thresholds"])
        if len(thresholds) > MAX_BANDS:
            raise t.error("thresholds", f"at most {MAX_BANDS} thresholds, got {len(thresholds)}")
        if np.any(np.diff(thresholds) <= 0) or np.any(np.abs(thresholds) >= 90):
            raise t.error("thresholds", f"must be ascending draft angles strictly between -90 and 90 degrees, "
                                        f"got {thresholds.tolist()}")
        keys["thresholds"] = tuple(float(x) for x in thresholds)
    elif mode == "curvature":
        keys["quantity"] = t.string("quantity", MODE_DEFAULTS["quantity"], CURVATURE_QUANTITIES)
        keys["range"] = _curvature_range(t)
        keys["bands"] = t.number("bands", MODE_DEFAULTS["bands"], low=0, high=MAX_BANDS, integer=True)
    return keys


def _curvature_range(t: _Table) -> tuple | str:
    """``render.range``: "auto", or [min, max] with min < max (1/model unit; model unit for radius)."""
    if t.raw("range", MODE_DEFAULTS["range"]) == "auto":
        return "auto"
    if isinstance(t.data["range"], str):
        raise t.error("range", f'must be "auto" or [min, max], got {t.data["range"]!r}')
    low, high = t.array("range", (2,)).tolist()
    if not low < high:
        raise t.error("range", f"min must be below max, got [{low:g}, {high:g}]")
    return (low, high)


def _parse_output(t: _Table, path: Path) -> OutputSpec:
    name = t.string("name", CODE_SCENE_NAME if path == CODE_SCENE_PATH else path.stem)
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
    problem = knot_vector_problem(knots, degree, n_ctrl)
    if problem:
        raise t.error(key, problem)


def _check_geometry_patch(file: Path, index: int, surface: NurbsSurface, where: str | None = None) -> None:
    """What `_parse_inline_surface` checks of its numbers, for a patch read from a geometry file or given in code."""
    problem = patch_problem(surface)
    if problem:
        raise SceneError(file, where or f"patch {index}", problem)


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
    surface = NurbsSurface(p, q, _from_zero(knots_u, p), _from_zero(knots_v, q), points, weights, name)
    if not has_area(surface):
        raise t.error("points", ZERO_AREA)
    return surface


#: A knot vector whose domain starts farther from 0 than this many of its narrowest spans is moved to start at 0
#: (`_from_zero`): float64 places a parameter to 2.2e-16 of its magnitude, so there S is resolved along it only to
#: ~this × 2.2e-16 of a span, which must stay below Newton's 1e-12 tolerance (with margin).
KNOT_OFFSET_SPANS = 1e3


def _from_zero(knots: np.ndarray, degree: int) -> np.ndarray:
    """``knots`` moved to start the domain at 0 where it starts more than `KNOT_OFFSET_SPANS` narrowest spans from 0;
    else as written, so u, v (the AOVs, the contours' (u, v)) keep the scene's parameters. The surface is the same:
    knots 1e6 … 1e6 + 7 (spans 1–4 wide) resolved S only to ~1e-10 of the patch along u, above Newton's tolerance,
    and 1,803 of the 2,325 rays Open CASCADE sees hit the patch missed it (96×64)."""
    spans = np.diff(knots)
    narrowest = spans[spans > 0].min()
    return knots - knots[degree] if abs(knots[degree]) > KNOT_OFFSET_SPANS * narrowest else knots


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


#: Reader of each table of `SCENE_TABLES`, as (table, scene path) → spec.
_PARSERS = {
    "image": lambda t, path: _parse_image(t),
    "camera": lambda t, path: _parse_camera(t),
    "lights": lambda t, path: _parse_lights(t),
    "render": lambda t, path: _parse_render(t),
    "output": _parse_output,
}


class _Errors:
    """Collects the `SceneError`s of independent parts of a scene (tables, surfaces) to report them together."""

    def __init__(self) -> None:
        self.found: list[SceneError] = []

    @contextlib.contextmanager
    def collect(self) -> Iterator[None]:
        try:
            yield
        except SceneError as exc:
            self.found.append(exc)

    def drop_consequences(self) -> None:
        """Leave out a required table reported missing when it was found misplaced (``camera.lights``: unknown key):
        one mistake, one line."""
        leaves = [leaf for error in self.found for leaf in getattr(error, "errors", [error])]
        misplaced = {leaf.field.rsplit(".", 1)[-1] for leaf in leaves
                     if leaf.reason.startswith("unknown key") and "." in leaf.field}
        self.found = [error for error in self.found
                      if not (error.reason == REQUIRED_MISSING and error.field in misplaced)]

    def raise_any(self) -> None:
        if len(self.found) == 1:
            raise self.found[0]
        if self.found:
            raise SceneErrors(self.found)


@dataclass
class _Geometry:
    """What the ``[[surface]]`` entries gave: the patches, the geometry files read, and CAD files' notes."""

    surfaces: list[NurbsSurface] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)  # faces, unit, bounding box, skipped faces (printed by the CLI)
    faces_skipped: bool = False  # --skip-bad-faces left faces out

    def inputs_sha256(self, inputs: str) -> str:
        """The inputs' hash, told apart when faces were skipped: those pixels lack faces the files have."""
        return hashlib.sha256(f"{inputs}\nskip-bad-faces".encode()).hexdigest() if self.faces_skipped else inputs


def _parse_surfaces(path: Path, entries: Any, errors: _Errors, skip_bad_faces: bool = False) -> _Geometry:
    """The ``[[surface]]`` entries (tables, or `NurbsSurface` objects given in code) and the geometry files read.

    ``skip_bad_faces``: faces of CAD files that cannot be read are left out (and listed in the notes).
    """
    geometry = _Geometry()
    surfaces, geometry_files = geometry.surfaces, geometry.files
    if not isinstance(entries, list) or not entries:
        errors.found.append(SceneError(path, "surface", "needs one or more [[surface]] tables"))
        return geometry
    for i, entry in enumerate(entries):
        with errors.collect():
            if isinstance(entry, NurbsSurface) and entry.trim is None and entry.mesh_uv is None:
                entry = _surface_table(entry)  # built in code: read as an inline [[surface]], every check applies
            if isinstance(entry, NurbsSurface):  # a trimmed CAD face: checked as a geometry file's patch
                _check_geometry_patch(path, i, entry, f"surface[{i}]")
                surfaces.append(entry)
                continue
            t = _Table(path, f"surface[{i}]", entry)
            if not t.has("file"):
                surfaces.append(_parse_inline_surface(t, i))
                continue
            t.keys = ("file", "name")
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
                    patches, summary, skipped = read_part(file, name, skip_bad_faces)
                    geometry.notes.extend(summary)
                    geometry.faces_skipped = geometry.faces_skipped or skipped
                else:
                    refuse_misnamed_cad_file(file)
                    patches = read_bpt(file, name)
                    for k, patch in enumerate(patches):
                        _check_geometry_patch(file, k, patch)
            except SceneError as exc:
                raise SceneError(exc.file, exc.field, f"{exc.reason} (from {path}: {t.name('file')})") from None
            surfaces.extend(patches)
            geometry_files.append(file)
    return geometry


def _parse_document(path: Path, doc: Any, skip_bad_faces: bool = False) -> tuple[dict[str, Any], _Geometry]:
    """Every table of a scene document (TOML's types) read and checked; all independent errors raised together.

    One error per table and per surface (a table's unknown keys all), in the order of the
    scene file's reading, so the first line is the first problem.
    """
    errors = _Errors()
    root = _Table(path, "", doc)
    specs: dict[str, Any] = {}
    for name in SCENE_TABLES:
        with errors.collect():
            table = root.raw(name, {})
            specs[name] = _PARSERS[name](_Table(path, name, table), path)
    geometry = _Geometry()
    with errors.collect():
        geometry = _parse_surfaces(path, root.raw("surface", required=True), errors, skip_bad_faces)
    with errors.collect():
        root.finish()
    errors.drop_consequences()
    errors.raise_any()
    _check_mesh_size(path, geometry.surfaces, specs["render"].tessellation)
    _check_light_shape(path, specs["lights"], specs["render"])
    return specs, geometry


def _check_light_shape(path: Path, lights: LightSpec, render: RenderSettings) -> None:
    """Circles light only the modes that see the light plane (`CIRCLE_MODES`)."""
    if lights.shape == "circles" and render.mode not in CIRCLE_MODES:
        raise SceneError(path, "lights.shape", f"circles are seen by render.mode {' or '.join(map(repr, CIRCLE_MODES))}"
                                               f", not {render.mode!r}: set lights.shape = \"tubes\" or change the mode")


def load_scene(path: str | Path, skip_bad_faces: bool = False) -> Scene:
    """Read and validate a TOML scene file; raises `SceneError` naming the file and field (`SceneErrors`: several).

    ``skip_bad_faces``: faces of CAD files the scene names that cannot be read are left out (and
    listed in `Scene.notes`) instead of failing the scene. (`exchange.load.load_scene` also takes
    a CAD file in place of the scene file.)
    """
    path = Path(path)
    if path.is_dir():
        raise SceneError(path, "", "is a folder, not a scene file: render every scene in it with "
                                   f"`rtreflect batch {quote(str(path))[1:-1]}`")
    text = read_text(path, "scene file")
    # A file not named .toml that is no TOML either is most likely no scene at all (an Open CASCADE .brep, a mesh).
    kinds = "" if path.suffix.lower() == ".toml" else \
        " (rtreflect reads TOML scenes, .toml, and STEP, IGES and Rhino .3dm files)"
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        # tomllib puts the position at the end ("... (at line 3, column 7)"); lead with it instead.
        where = re.fullmatch(r"(.*) \((at line \d+, column \d+|at end of document)\)", str(exc), re.S)
        if where:
            raise SceneError(path, where[2].removeprefix("at "), f"TOML syntax error: {where[1]}{kinds}") from None
        raise SceneError(path, "", f"TOML syntax error: {exc}{kinds}") from None
    except RecursionError:  # tomllib reads nested arrays and inline tables recursively
        raise SceneError(path, "", "TOML syntax error: arrays or inline tables nested too deeply to read") from None
    except ValueError as exc:
        # int() refuses more than 4300 digits (Python's guard against slow conversions); tomllib passes that on.
        raise SceneError(path, _long_number_position(text), "TOML syntax error: a number with more than 4300 digits") from None

    specs, geometry = _parse_document(path, doc, skip_bad_faces)
    sha, inputs = _hash_files([path, *geometry.files])
    return Scene(path, specs["image"], specs["camera"], specs["lights"], tuple(geometry.surfaces), specs["render"],
                 specs["output"], sha, geometry.inputs_sha256(inputs), tuple(geometry.notes))


# -- scenes built in code ---------------------------------------------------------------------


def _toml_value(value: Any) -> Any:
    """A value given in code in TOML's own types, so the scene file's readers check it: arrays and tuples as
    lists, numpy scalars as Python numbers, spec objects as their tables. `NurbsSurface`s pass through."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_toml_value(item) for item in value]
    if isinstance(value, dict):
        return {key: _toml_value(item) for key, item in value.items()}
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (ImageSpec, CameraSpec, LightSpec, RenderSettings, OutputSpec)):
        return _spec_table(value)
    return value


def _spec_table(spec: Any) -> dict[str, Any]:
    """A parsed table back in TOML's types (what the scene file would say): reading it again gives ``spec``."""
    table = {f.name: _toml_value(getattr(spec, f.name)) for f in fields(spec) if getattr(spec, f.name) is not None}
    if isinstance(spec, LightSpec) and not spec.auto:
        del table["auto"]  # an explicit row of tubes: the keys of a plain [lights] table
    return table


def _surface_table(surface: NurbsSurface) -> dict[str, Any]:
    """An untrimmed patch as the ``[[surface]]`` table that describes it."""
    return {"name": surface.name, "degree": [surface.degree_u, surface.degree_v], "points": surface.points.tolist(),
            "knots_u": surface.knots_u.tolist(), "knots_v": surface.knots_v.tolist(),
            "weights": surface.weights.tolist()}


def _unkeyed(name: str, spec: Any) -> dict[str, Any]:
    """A table without the fields `Scene.output_key` names itself."""
    table = _spec_table(spec)
    for key in KEYED_FIELDS.get(name, ()):
        table.pop(key, None)
    return table


def _canonical(document: Any) -> str:
    """One text per document (sorted keys, floats by repr) to hash; +inf as the string "inf" (JSON has none)."""
    return json.dumps(document, sort_keys=True, default=str, allow_nan=True)


def _surfaces_digest(surfaces: tuple[NurbsSurface, ...], geometry_files: list[Path]) -> str:
    """sha256 of the patches' numbers (degrees, knots, points, weights) and of the geometry files read."""
    digest = hashlib.sha256()
    for surface in surfaces:
        digest.update(f"{surface.degree_u} {surface.degree_v} {surface.name}".encode())
        for array in (surface.knots_u, surface.knots_v, surface.points, surface.weights):
            digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    for file in geometry_files:
        digest.update(str(file).encode())
    return digest.hexdigest()


def _scene_from_code(path: Path, image, camera, lights, surfaces, render, output) -> tuple:
    """`Scene`'s fields from tables given in code, read by the scene file's readers (see `Scene`)."""
    doc = {name: _toml_value(value) for name, value in
           (("image", image), ("camera", camera), ("lights", lights), ("render", render), ("output", output))
           if value is not None}
    if surfaces is not None:
        doc["surface"] = _toml_value(list(surfaces)) if isinstance(surfaces, (list, tuple)) else _toml_value(surfaces)
    specs, geometry = _parse_document(path, doc)
    sha = hashlib.sha256(_canonical({k: v for k, v in doc.items() if k != "surface"}).encode()
                         + _surfaces_digest(tuple(geometry.surfaces), []).encode()).hexdigest()
    _, inputs = _hash_files(geometry.files) if geometry.files else ("", "")
    inputs = hashlib.sha256(f"{sha}\n{inputs}".encode()).hexdigest()
    return (path, specs["image"], specs["camera"], specs["lights"], tuple(geometry.surfaces), specs["render"],
            specs["output"], sha, inputs, tuple(geometry.notes), ())
