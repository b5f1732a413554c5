"""Bad scene files: each case is one defect in an otherwise valid scene.

The contract (DESIGN.md, "Command line" and "Conventions"): bad input exits 2 with
one line that names the file and the field, never a traceback, and leaves no
output behind. Every case is checked in-process through click's runner (fast);
a few are also run through the installed console script to prove the real exit
path. The valid base scenes are rendered too, so each failure is the defect's.
"""

from __future__ import annotations

import copy
import json
import math
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import pytest
from click.testing import CliRunner

from rtreflect.cli import cli

EXIT_BAD_INPUT = 2
RENDER_OPTIONS = ["--width", "32", "--height", "18", "--samples", "1"]
RTREFLECT = Path(sys.executable).parent / "rtreflect"
NAN = math.nan
INF = math.inf


# --- A tiny TOML writer (tomli_w is not a dependency) -------------------------------------


class Raw(str):
    """Text written into the TOML document verbatim: how a case plants a syntax error."""


def toml_value(value: Any) -> str:
    if isinstance(value, Raw):
        return str(value)
    if isinstance(value, bool):  # before int: bool is a subclass of int
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        # JSON string escapes are valid TOML basic-string escapes; astral characters stay literal (JSON would
        # write surrogate pairs, which TOML refuses), and DEL, which JSON leaves raw, is escaped as TOML wants.
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key} = {toml_value(item)}" for key, item in value.items()) + "}"
    raise TypeError(f"no TOML form for {value!r}")


def is_table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(item, dict) for item in value)


def toml_document(scene: dict) -> str:
    """Top-level tables as ``[name]``, arrays of tables as ``[[name]]``, anything deeper inline."""
    lines = [f"{key} = {toml_value(value)}" for key, value in scene.items()
             if not isinstance(value, dict) and not is_table_array(value)]
    for key, value in scene.items():
        tables = [value] if isinstance(value, dict) else value if is_table_array(value) else []
        header = f"[{key}]" if isinstance(value, dict) else f"[[{key}]]"
        for table in tables:
            lines += ["", header, *(f"{k} = {toml_value(v)}" for k, v in table.items())]
    return "\n".join(lines) + "\n"


# --- The valid base scenes ------------------------------------------------------------------


def control_net(nu: int = 4, nv: int = 4) -> list:
    """A gentle bump over [-1, 1]²: curved both ways so the reflection lines bend."""
    net = []
    for i in range(nu):
        x = -1 + 2 * i / (nu - 1)
        net.append([[x, -1 + 2 * j / (nv - 1), 0.4 * (1 - x * x) * (1 - (-1 + 2 * j / (nv - 1)) ** 2)]
                    for j in range(nv)])
    return net


def valid_scene() -> dict:
    """Every table and most fields present, so each can be broken; degrees differ so fields are told apart."""
    return {
        "image": {"width": 64, "height": 36, "samples": 1},
        "camera": {"projection": "perspective", "eye": [0.0, -3.2, 2.4], "look_at": [0.0, 0.0, 0.0],
                   "up": [0.0, 0.0, 1.0], "fov": 40.0, "view_height": 3.0},
        "lights": {"point": [0.0, 0.0, 3.0], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0],
                   "positions": [-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5], "radius": 0.05, "length": 20.0},
        "surface": [{"name": "bump", "degree": [3, 2],
                     "knots_u": [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
                     "knots_v": [0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0],
                     "points": control_net(), "weights": [[1.0] * 4 for _ in range(4)]}],
        "render": {"tessellation": 8, "surface_color": [0.18, 0.18, 0.2], "line_color": [1.0, 1.0, 1.0],
                   "background": [0.0, 0.0, 0.0]},
        "output": {"name": "base", "exr": True, "png": True},
    }


def bpt_text(count: str = "1", degrees: str = "3 3", points: list[str] | None = None, extra: str = "") -> str:
    """A .bpt file: patch count, degrees, then one ``x y z`` line per control point (u-major)."""
    if points is None:
        points = [f"{x!r} {y!r} {z!r}" for row in control_net() for x, y, z in row]
    return "\n".join([count, degrees, *points]) + "\n" + extra


VALID_BPT = bpt_text()


def with_bpt_surface(scene: dict) -> None:
    scene["surface"] = [{"name": "bump", "file": "patch.bpt"}]


# --- Defects --------------------------------------------------------------------------------

Defect = Callable[[dict], None]


def _locate(scene: dict, path: str) -> tuple[Any, Any]:
    """The container and key that ``path`` ("surface[0].points[1][2]") names."""
    steps = [int(tok[1:-1]) if tok.startswith("[") else tok for tok in re.findall(r"\[\d+\]|[^.\[\]]+", path)]
    container = scene
    for step in steps[:-1]:
        container = container[step]
    return container, steps[-1]


def put(path: str, value: Any) -> Defect:
    def defect(scene: dict) -> None:
        container, key = _locate(scene, path)
        container[key] = value
    return defect


def drop(path: str) -> Defect:
    def defect(scene: dict) -> None:
        container, key = _locate(scene, path)
        del container[key]
    return defect


def together(*parts: Defect) -> Defect:
    """One defect that needs several edits (e.g. replace positions by an incomplete spacing/count)."""
    def defect(scene: dict) -> None:
        for part in parts:
            part(scene)
    return defect


def move(source: str, target: str) -> Defect:
    def defect(scene: dict) -> None:
        container, key = _locate(scene, source)
        value = container.pop(key)
        put(target, value)(scene)
    return defect


@dataclass(frozen=True)
class Case:
    id: str
    defect: Defect
    field: str  # what follows "FILE: " in the message
    geometry: str | bytes | None = None  # contents of patch.bpt beside the scene, if the case needs one
    blamed_file: str | None = None  # file (beside the scene) the message must name; None: the scene

    def expected_file(self, scene_path: Path) -> str:
        if self.blamed_file is None:
            return str(scene_path)
        return str((scene_path.parent / self.blamed_file).resolve())


def bpt_case(id: str, geometry: str | bytes, field: str) -> Case:
    return Case(id, with_bpt_surface, field, geometry=geometry, blamed_file="patch.bpt")


S = "surface[0]"
collapsed_to_point = [[[0.5, 0.5, 0.5]] * 4 for _ in range(4)]
collapsed_to_line = [[[t, 2 * t, 3 * t] for t in (i + 0.25 * j for j in range(4))] for i in range(4)]
ragged_net = control_net()[:3] + [control_net()[3][:3]]


def wider_v(nv: int, knots_v: list[float]) -> Defect:
    """The surface with nv control points in v (and matching weights) and the given v knots."""
    return together(put(f"{S}.points", control_net(4, nv)), put(f"{S}.weights", [[1.0] * nv for _ in range(4)]),
                    put(f"{S}.knots_v", knots_v))


def wider_u(nu: int, knots_u: list[float]) -> Defect:
    """The surface with nu control points in u (and matching weights) and the given u knots."""
    return together(put(f"{S}.points", control_net(nu, 4)), put(f"{S}.weights", [[1.0] * 4 for _ in range(nu)]),
                    put(f"{S}.knots_u", knots_u))


def fine_grid(n: int) -> Defect:
    """A bilinear surface of n×n control points: n − 1 knot spans each way."""
    knots = [0.0] + [i / (n - 1) for i in range(n)] + [1.0]
    return together(put(f"{S}.degree", [1, 1]), put(f"{S}.points", control_net(n, n)),
                    put(f"{S}.weights", [[1.0] * n for _ in range(n)]), put(f"{S}.knots_u", knots),
                    put(f"{S}.knots_v", knots))

CASES = [
    # TOML itself and the shape of the document
    Case("toml syntax error", put("camera.fov", Raw("40 40")), "line 12, column 10: TOML syntax error"),
    Case("toml unterminated string", put("output.name", Raw('"base')), "line 38, column 13: TOML syntax error"),
    Case("toml duplicate key", put("camera.fov", Raw("40.0\nfov = 30.0")), "line 13, column 11: TOML syntax error"),
    Case("toml unclosed array", put("camera.eye", Raw("[0.0, -3.2, 2.4")), "line 10, column 1: TOML syntax error"),
    Case("toml duplicate table", put("render.tessellation", Raw("8\n[render]")), "line 33, column 8: TOML syntax error"),
    Case("image as array of tables", put("image", [{"width": 64}]), "image"),
    Case("toml nested too deeply", put("camera.eye", Raw("[" * 2000 + "]" * 2000)),
         "TOML syntax error: arrays or inline tables nested too deeply"),
    Case("toml integer of 5000 digits", put("image.width", Raw("9" * 5000)),
         "line 3, column 9: TOML syntax error: a number with more than 4300 digits"),
    Case("table is a number", put("camera", 3), "camera"),
    Case("lights as array of tables", put("lights", [valid_scene()["lights"]]), "lights"),
    Case("surface as single table", put("surface", valid_scene()["surface"][0]), "surface"),
    Case("surface array empty", put("surface", []), "surface"),
    Case("surface entry not a table", put("surface", [1]), f"{S}"),
    Case("lights nested under camera", move("lights", "camera.lights"), "camera.lights"),
    Case("image keys nested one level down", move("image", "render.image"), "render.image"),
    Case("missing surface", drop("surface"), "surface"),
    # unknown keys, at the top and in every table
    Case("unknown top-level key", put("colour", "red"), "colour"),
    Case("unknown key in image", put("image.dpi", 300), "image.dpi"),
    Case("unknown key in camera", put("camera.fov_deg", 40.0), "camera.fov_deg"),
    Case("unknown key in lights", put("lights.colour", [1.0, 1.0, 1.0]), "lights.colour"),
    Case("unknown key in surface", put(f"{S}.weight", 1.0), f"{S}.weight"),
    Case("inline key beside file", together(with_bpt_surface, put(f"{S}.degree", 3)), f"{S}.degree",
         geometry=VALID_BPT),
    Case("unknown key in render", put("render.shadows", True), "render.shadows"),
    Case("unknown key in output", put("output.jpeg", True), "output.jpeg"),
    # wrong types
    Case("width is a string", put("image.width", "64"), "image.width"),
    Case("width is a float", put("image.width", 64.0), "image.width"),
    Case("samples is a bool", put("image.samples", True), "image.samples"),
    Case("fov is a string", put("camera.fov", "wide"), "camera.fov"),
    Case("eye is a table", put("camera.eye", {"x": 0.0, "y": -3.2, "z": 2.4}), "camera.eye"),
    Case("eye has two entries", put("camera.eye", [0.0, -3.2]), "camera.eye"),
    Case("unknown projection", put("camera.projection", "fisheye"), "camera.projection"),
    Case("positions is a number", put("lights.positions", 1.0), "lights.positions"),
    Case("point is a string", put("lights.point", "origin"), "lights.point"),
    Case("degree is a bool", put(f"{S}.degree", True), f"{S}.degree"),
    Case("degree is a string", put(f"{S}.degree", "3"), f"{S}.degree"),
    Case("surface name is a number", put(f"{S}.name", 3), f"{S}.name"),
    Case("knot is a string", put(f"{S}.knots_u[4]", "1"), f"{S}.knots_u"),
    Case("tessellation is a float", put("render.tessellation", 8.5), "render.tessellation"),
    Case("png is a string", put("output.png", "yes"), "output.png"),
    Case("surface file is a number", put(S, {"file": 7}), f"{S}.file"),
    # missing required fields
    Case("missing lights.point", drop("lights.point"), "lights.point"),
    Case("missing lights.normal", drop("lights.normal"), "lights.normal"),
    Case("missing lights.direction", drop("lights.direction"), "lights.direction"),
    Case("missing positions", drop("lights.positions"), "lights.positions"),
    Case("spacing without count", together(drop("lights.positions"), put("lights.spacing", 0.5)), "lights.count"),
    Case("missing degree", drop(f"{S}.degree"), f"{S}.degree"),
    Case("missing points", drop(f"{S}.points"), f"{S}.points"),
    Case("missing knots_u", drop(f"{S}.knots_u"), f"{S}.knots_u"),
    Case("missing knots_v", drop(f"{S}.knots_v"), f"{S}.knots_v"),
    # knots and degrees
    Case("knots decrease", put(f"{S}.knots_u", [0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 1.0, 1.0]), f"{S}.knots_u"),
    Case("too few knots", put(f"{S}.knots_v", [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]), f"{S}.knots_v"),
    Case("too many knots", put(f"{S}.knots_u", [0.0] * 4 + [0.5] + [1.0] * 4), f"{S}.knots_u"),
    Case("knot multiplicity above degree+1", put(f"{S}.knots_v", [0.0] * 4 + [1.0] * 3), f"{S}.knots_v"),
    Case("inner knot multiplicity above degree+1", wider_v(7, [0.0] * 3 + [0.5] * 4 + [1.0] * 3),
         f"{S}.knots_v: an inner knot (0.5) is repeated 4 times"),
    # Degree 3 in u: a knot repeated 4 times inside the domain cuts the surface in two pieces (OpenNURBS refuses it).
    Case("inner knot repeated degree+1 times", wider_u(8, [0.0] * 4 + [0.5] * 4 + [1.0] * 4),
         f"{S}.knots_u: an inner knot (0.5) is repeated 4 times; at most the degree (3) allowed"),
    Case("knot span too narrow for float64", put(f"{S}.knots_v", [0.0, 0.0, 0.0, 1e-300, 1.0, 1.0, 1.0]),
         f"{S}.knots_v: knots 2 and 3 differ by only 1e-300"),
    Case("parameter domain too narrow", put(f"{S}.knots_u", [0.0] * 4 + [1e-200] * 4), f"{S}.knots_u"),
    Case("near-duplicate inner knots", wider_v(5, [0.0] * 3 + [0.5, 0.5 + 1e-15] + [1.0] * 3), f"{S}.knots_v"),
    Case("empty parameter domain", put(f"{S}.knots_v", [0.0] * 3 + [0.0] + [0.0] * 3), f"{S}.knots_v"),
    Case("nan knot", put(f"{S}.knots_u[4]", NAN), f"{S}.knots_u"),
    Case("degree zero", put(f"{S}.degree", [0, 2]), f"{S}.degree"),
    Case("degree negative", put(f"{S}.degree", -3), f"{S}.degree"),
    Case("degree has three entries", put(f"{S}.degree", [3, 2, 1]), f"{S}.degree"),
    # control nets and weights
    Case("ragged control net", put(f"{S}.points", ragged_net), f"{S}.points"),
    Case("empty control net", put(f"{S}.points", []), f"{S}.points"),
    Case("control net of empty rows", put(f"{S}.points", [[], [], [], []]), f"{S}.points"),
    Case("control point with two coordinates", put(f"{S}.points[2][1]", [0.0, 0.0]), f"{S}.points"),
    Case("control net flat list", put(f"{S}.points", [0.0] * 48), f"{S}.points"),
    Case("fewer points than degree needs", put(f"{S}.points", control_net(3, 4)), f"{S}.points"),
    Case("nan control point", put(f"{S}.points[1][2][0]", NAN), f"{S}.points"),
    Case("inf control point", put(f"{S}.points[3][0][2]", INF), f"{S}.points"),
    Case("control point beyond float32 range", put(f"{S}.points[0][0][2]", 1e300), f"{S}.points"),
    Case("knots beyond float32 range", put(f"{S}.knots_u", [-1e308] * 4 + [1e308] * 4), f"{S}.knots_u"),
    Case("patch collapsed to a point", put(f"{S}.points", collapsed_to_point), f"{S}.points"),
    Case("patch collapsed to a line", put(f"{S}.points", collapsed_to_line), f"{S}.points"),
    Case("zero weight", put(f"{S}.weights[1][1]", 0.0), f"{S}.weights"),
    Case("negative weight", put(f"{S}.weights[0][3]", -1.0), f"{S}.weights"),
    Case("nan weight", put(f"{S}.weights[2][2]", NAN), f"{S}.weights"),
    Case("weights wrong shape", put(f"{S}.weights", [[1.0] * 3 for _ in range(4)]), f"{S}.weights"),
    Case("weights ragged", put(f"{S}.weights", [[1.0] * 4, [1.0] * 3, [1.0] * 4, [1.0] * 4]), f"{S}.weights"),
    # camera
    Case("eye equals look_at", put("camera.look_at", [0.0, -3.2, 2.4]), "camera.look_at"),
    Case("up parallel to view", put("camera.up", [0.0, 3.2, -2.4]), "camera.up"),
    Case("up zero", put("camera.up", [0.0, 0.0, 0.0]), "camera.up"),
    Case("fov zero", put("camera.fov", 0), "camera.fov"),
    Case("fov 180", put("camera.fov", 180.0), "camera.fov"),
    Case("fov negative", put("camera.fov", -30.0), "camera.fov"),
    Case("fov nan", put("camera.fov", NAN), "camera.fov"),
    Case("fov 200", put("camera.fov", 200.0), "camera.fov"),
    Case("view_height nan", put("camera.view_height", NAN), "camera.view_height"),
    Case("up reversed view direction", put("camera.up", [0.0, -3.2, 2.4]), "camera.up"),
    Case("view_height zero", put("camera.view_height", 0.0), "camera.view_height"),
    Case("view_height negative", together(put("camera.projection", "orthographic"), put("camera.view_height", -2.0)),
         "camera.view_height"),
    Case("eye infinite", put("camera.eye[1]", -INF), "camera.eye"),
    Case("eye beyond float32 range", put("camera.eye", [0.0, -1e300, 2.4]), "camera.eye"),
    # image
    Case("width zero", put("image.width", 0), "image.width"),
    Case("height negative", put("image.height", -18), "image.height"),
    Case("width absurd", put("image.width", 1_000_000),
         "image.width: must be at most 16384 pixels (22 float32 channels per pixel"),
    Case("height beyond 64 bits", put("image.height", 10**30), "image.height: must be at most 16384 pixels"),
    Case("height absurd float", put("image.height", 1e6), "image.height"),
    Case("too many pixels", together(put("image.width", 16384), put("image.height", 16384)), "image.width"),
    Case("samples zero", put("image.samples", 0), "image.samples"),
    Case("samples negative", put("image.samples", -2), "image.samples"),
    Case("samples absurd", put("image.samples", 1000), "image.samples"),
    Case("samples a misspelt word", put("image.samples", "analytc"),
         'image.samples: must be "analytic" or an integer from 1 to 16, got \'analytc\''),
    # lights
    Case("normal zero", put("lights.normal", [0.0, 0.0, 0.0]), "lights.normal"),
    Case("direction zero", put("lights.direction", [0.0, 0.0, 0.0]), "lights.direction"),
    Case("direction not in light plane", put("lights.direction", [0.0, 1.0, 0.5]), "lights.direction"),
    Case("positions empty", put("lights.positions", []), "lights.positions"),
    Case("positions with nan", put("lights.positions[2]", NAN), "lights.positions"),
    Case("positions and spacing", put("lights.spacing", 0.5), "lights.spacing"),
    Case("count zero", together(drop("lights.positions"), put("lights.spacing", 0.5), put("lights.count", 0)),
         "lights.count"),
    Case("count negative", together(drop("lights.positions"), put("lights.spacing", 0.5), put("lights.count", -3)),
         "lights.count"),
    Case("spacing beyond float32 range",
         together(drop("lights.positions"), put("lights.spacing", 1e308), put("lights.count", 100)), "lights.spacing"),
    Case("normal beyond float32 range", put("lights.normal", [0.0, 0.0, 1e200]), "lights.normal"),
    Case("spacing zero", together(drop("lights.positions"), put("lights.spacing", 0.0), put("lights.count", 5)),
         "lights.spacing"),
    Case("radius inf", put("lights.radius", INF), "lights.radius"),
    Case("radius -inf", put("lights.radius", -INF), "lights.radius"),
    Case("direction along normal", put("lights.direction", [0.0, 0.0, 2.0]), "lights.direction"),
    Case("count a float", together(drop("lights.positions"), put("lights.spacing", 0.5), put("lights.count", 5.5)),
         "lights.count"),
    Case("count absurd", together(drop("lights.positions"), put("lights.spacing", 0.5), put("lights.count", 10**7)),
         "lights.count"),
    Case("too many positions", put("lights.positions", [0.001 * k for k in range(10001)]),
         "lights.positions: at most 10000 tubes"),
    Case("positions are strings", put("lights.positions", ["left", "right"]), "lights.positions[0]"),
    Case("radius nan", put("lights.radius", NAN), "lights.radius"),
    Case("radius negative", put("lights.radius", -0.05), "lights.radius"),
    Case("radius zero", put("lights.radius", 0.0), "lights.radius"),
    Case("length zero", put("lights.length", 0.0), "lights.length"),
    # render and output
    Case("negative colour", put("render.line_color", [1.0, -0.5, 1.0]), "render.line_color"),
    Case("tessellation zero", put("render.tessellation", 0), "render.tessellation"),
    Case("tessellation beyond memory", together(fine_grid(13), put("render.tessellation", 256)),
         "render.tessellation: 256 segments per knot span make"),
    Case("colour beyond float32 range", put("render.background", [1e308, 0.0, 0.0]), "render.background"),
    Case("overlay not a boolean", put("render.overlay", "yes"), "render.overlay"),
    Case("overlay colour too short", put("render.overlay_color", [1.0, 0.2]), "render.overlay_color"),
    Case("overlay colour negative", put("render.overlay_color", [1.0, -0.2, 0.1]), "render.overlay_color"),
    Case("overlay colour not numbers", put("render.overlay_color", ["red", 0.2, 0.1]), "render.overlay_color[0]"),
    Case("normals unknown mode", put("render.normals", "smooth"), "render.normals"),
    Case("overlay unknown layout", put("render.overlay", "inset"), "render.overlay: must be true, false or 'side'"),
    Case("shading unknown mode", put("render.shading", "phong"), "render.shading: must be one of 'lambert', 'flat'"),
    Case("blur beyond 1", put("render.blur", 1.5), "render.blur: must be <= 1"),
    Case("blur negative", put("render.blur", -0.1), "render.blur: must be >= 0"),
    Case("overlay width zero", put("render.overlay_width", 0), "render.overlay_width: must be > 0"),
    Case("overlay width huge", put("render.overlay_width", 100), "render.overlay_width: must be <= 16"),
    Case("normals not a string", put("render.normals", 1), "render.normals"),
    # Interrogation modes (issue 15): unknown mode, a key of another mode, each mode's bad values.
    Case("unknown render mode", put("render.mode", "zebra-ish"), "render.mode: must be one of 'reflection'"),
    Case("quantity not of the mode", put("render.quantity", "mean"),
         "render.quantity: not used by mode 'reflection' (only by 'curvature')"),
    Case("step of another mode", together(put("render.mode", "curvature"), put("render.step", 5.0)),
         "render.step: not used by mode 'curvature'"),
    Case("isophote step zero", together(put("render.mode", "isophote"), put("render.step", 0.0)), "render.step: must be > 0"),
    Case("isophote step negative", together(put("render.mode", "isophote"), put("render.step", -5.0)), "render.step"),
    Case("isophote light zero", together(put("render.mode", "isophote"), put("render.light", [0.0, 0.0, 0.0])),
         "render.light: must not be the zero vector"),
    Case("draft pull zero", together(put("render.mode", "draft"), put("render.pull", [0.0, 0.0, 0.0])),
         "render.pull: must not be the zero vector"),
    Case("draft thresholds not ascending", together(put("render.mode", "draft"), put("render.thresholds", [3.0, 1.0])),
         "render.thresholds: must be ascending"),
    Case("curvature quantity unknown", together(put("render.mode", "curvature"), put("render.quantity", "gauss")),
         "render.quantity: must be one of"),
    Case("curvature range min above max", together(put("render.mode", "curvature"), put("render.range", [0.05, -0.05])),
         "render.range: min must be below max, got [0.05, -0.05]"),
    Case("curvature range empty", together(put("render.mode", "curvature"), put("render.range", [0.1, 0.1])),
         "render.range: min must be below max"),
    Case("curvature range a word", together(put("render.mode", "curvature"), put("render.range", "wide")),
         'render.range: must be "auto" or [min, max]'),
    Case("curvature bands negative", together(put("render.mode", "curvature"), put("render.bands", -1)), "render.bands"),
    Case("no output format", together(put("output.exr", False), put("output.png", False)), "output"),
    Case("output name climbs out", put("output.name", "../escape"), "output.name"),
    Case("output name with slash", put("output.name", "sub/base"), "output.name"),
    Case("output name with backslash", put("output.name", "sub\\base"), "output.name"),
    Case("output name empty", put("output.name", ""), "output.name"),
    Case("output name with newline", put("output.name", "base\nother"), "output.name"),
    Case("output name with NUL", put("output.name", "base\0"), "output.name"),
    Case("output name too long", put("output.name", "b" * 201), "output.name: must be at most 200 bytes"),
    Case("surface file empty", put(S, {"file": ""}), f"{S}.file"),
    Case("surface file with NUL", put(S, {"file": "patch\0.bpt"}), f"{S}.file"),
    # .bpt geometry files: the message names the resolved .bpt path, where in it, and the scene field
    Case("bpt file missing", put(S, {"file": "missing.bpt"}), "geometry file not found", blamed_file="missing.bpt"),
    Case("bpt is a folder", put(S, {"file": "."}), "cannot read geometry file", blamed_file="."),
    Case("bpt is an endless device", put(S, {"file": "/dev/zero"}), "geometry file is larger than 64 MB",
         blamed_file="/dev/zero"),
    bpt_case("bpt one point too many", bpt_text(extra="0.0 0.0 0.0\n"), "line 19"),
    bpt_case("bpt one point too few", bpt_text(points=bpt_text().splitlines()[2:-1]), "end of file"),
    bpt_case("bpt truncated mid-point", VALID_BPT[:-12], "end of file"),
    bpt_case("bpt says two patches, has one", bpt_text(count="2"), "end of file"),
    bpt_case("bpt empty", "", "end of file"),
    bpt_case("bpt non-numeric coordinate", VALID_BPT.replace("-1.0", "abc", 1), "line 3"),
    bpt_case("bpt non-integer degree", bpt_text(degrees="3 3.5"), "line 2"),
    bpt_case("bpt nan coordinate", bpt_text(points=["nan 0.0 0.0"] + bpt_text().splitlines()[3:]), "line 3"),
    bpt_case("bpt patch count zero", "0\n", "line 1"),
    bpt_case("bpt degree zero", bpt_text(degrees="0 3", points=bpt_text().splitlines()[2:6]), "patch 0"),
    bpt_case("bpt patch collapsed to a point", bpt_text(points=["0.5 0.5 0.5"] * 16), "patch 0"),
    bpt_case("bpt patch collapsed to a line", bpt_text(points=[f"{t} {t} 0.0" for t in range(16)]), "patch 0"),
    bpt_case("bpt coordinate beyond float32 range", VALID_BPT.replace("-1.0", "-1e300", 1), "patch 0"),
    bpt_case("bpt not UTF-8", b"1\n3 3\n\xff\n", "not UTF-8"),
    bpt_case("bpt patch count a float", bpt_text(count="1.0"), "line 1: expected the patch count"),
    bpt_case("bpt patch count absurd", bpt_text(count="1" + "0" * 5000), "line 1: the patch count is too large"),
    bpt_case("bpt number with underscore", VALID_BPT.replace("-1.0", "-1_0", 1), "line 3"),
    bpt_case("bpt hexadecimal count", bpt_text(count="0x1"), "line 1"),
    bpt_case("bpt Arabic-Indic digit", bpt_text(count="\u0661"), "line 1"),
    bpt_case("bpt negative degree", bpt_text(degrees="-3 3"), "patch 0"),
    bpt_case("bpt binary garbage", bytes(range(256)) * 4, "not UTF-8"),
]


def write_scene(folder: Path, case: Case) -> Path:
    scene = copy.deepcopy(valid_scene())
    case.defect(scene)
    if isinstance(case.geometry, bytes):
        (folder / "patch.bpt").write_bytes(case.geometry)
    elif case.geometry is not None:
        (folder / "patch.bpt").write_text(case.geometry)
    path = folder / "scene.toml"
    path.write_text(toml_document(scene))
    return path


def files_under(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file()] if folder.exists() else []


def check_rejection(case: Case, scene_path: Path, outdir: Path, exit_code: int, stderr: str) -> None:
    assert exit_code == EXIT_BAD_INPUT, stderr
    assert "Traceback" not in stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and stderr.endswith("\n"), f"not one line: {stderr!r}"
    assert f"{case.expected_file(scene_path)}: {case.field}" in lines[0], lines[0]
    if case.blamed_file is not None:  # the scene field that pointed at the geometry file is named too
        assert f"{scene_path}: surface[0].file" in lines[0], lines[0]
    assert files_under(outdir) == []


@pytest.mark.parametrize("case", CASES, ids=[case.id for case in CASES])
def test_bad_scene_is_rejected_in_one_line(case: Case, tmp_path: Path) -> None:
    scene_path = write_scene(tmp_path, case)
    outdir = tmp_path / "out"
    result = CliRunner().invoke(cli, ["render", str(scene_path), "-o", str(outdir), *RENDER_OPTIONS])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    check_rejection(case, scene_path, outdir, result.exit_code, result.stderr)


#: Unusual but good scenes: the validator must not be stricter than the schema.
VALID_VARIANTS = [
    Case("tiny light normal", put("lights.normal", [0.0, 0.0, 1e-200]), ""),
    Case("tiny camera up", put("camera.up", [0.0, 0.0, 1e-200]), ""),
    Case("endless tubes", put("lights.length", INF), ""),
    Case("spacing and count", together(drop("lights.positions"), put("lights.spacing", 0.5), put("lights.count", 9)), ""),
    Case("orthographic", put("camera.projection", "orthographic"), ""),
    Case("one degree for both directions",
         together(put(f"{S}.degree", 3), put(f"{S}.knots_v", [0.0] * 4 + [1.0] * 4)), ""),
    Case("no weights", drop(f"{S}.weights"), ""),
    Case("C0 crease: inner knot repeated degree times", wider_u(7, [0.0] * 4 + [0.5] * 3 + [1.0] * 4), ""),
    Case("exr only", put("output.png", False), ""),
    Case("mesh normals with overlay", together(put("render.normals", "mesh"), put("render.overlay", True),
                                               put("render.overlay_color", [0.0, 1.0, 0.0])), ""),
    Case("highlight mode", put("render.mode", "highlight"), ""),
    Case("isophote mode with its keys", together(put("render.mode", "isophote"), put("render.step", 7.5),
                                                  put("render.light", [0.0, -1.0, 1.0])), ""),
    Case("draft mode with its keys", together(put("render.mode", "draft"), put("render.pull", [0.0, 0.0, 2.0]),
                                              put("render.thresholds", [-1.0, 0.5, 2.0])), ""),
    Case("curvature mode with its keys", together(put("render.mode", "curvature"), put("render.quantity", "radius"),
                                                  put("render.range", [0.1, 10.0]), put("render.bands", 4)), ""),
]


@pytest.mark.parametrize("case", VALID_VARIANTS, ids=[case.id for case in VALID_VARIANTS])
def test_unusual_valid_scene_renders(case: Case, tmp_path: Path) -> None:
    scene_path = write_scene(tmp_path, case)
    outdir = tmp_path / "out"
    result = CliRunner().invoke(cli, ["render", str(scene_path), "-o", str(outdir), *RENDER_OPTIONS])
    assert result.exit_code == 0, result.stderr or repr(result.exception)
    assert files_under(outdir)


def test_case_ids_are_unique() -> None:
    assert len({case.id for case in CASES}) == len(CASES)


#: Cases also run through the console script: the real process exit status and stderr.
SUBPROCESS_CASES = [case for case in CASES
                    if case.id in ("toml syntax error", "fov 180", "knots decrease", "bpt truncated mid-point")]


def run_rtreflect(scene_path: Path, outdir: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(RTREFLECT), "render", str(scene_path), "-o", str(outdir), *RENDER_OPTIONS],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("case", SUBPROCESS_CASES, ids=[case.id for case in SUBPROCESS_CASES])
def test_bad_scene_is_rejected_by_console_script(case: Case, tmp_path: Path) -> None:
    scene_path = write_scene(tmp_path, case)
    outdir = tmp_path / "out"
    done = run_rtreflect(scene_path, outdir)
    check_rejection(case, scene_path, outdir, done.returncode, done.stderr)


@pytest.mark.parametrize("geometry", [None, VALID_BPT], ids=["inline surface", "bpt surface"])
def test_valid_base_scene_renders(geometry: str | None, tmp_path: Path) -> None:
    """The base scenes are good: the table above fails on its defects alone."""
    base = Case("valid", with_bpt_surface if geometry else (lambda scene: None), "", geometry=geometry)
    scene_path = write_scene(tmp_path, base)
    outdir = tmp_path / "out"
    done = run_rtreflect(scene_path, outdir)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in files_under(outdir)) == ["base.exr", "base.png"]


#: Bad command lines: the console script's own path (click's usage errors) also answers in one line.
BAD_COMMAND_LINES = [
    (["render", "{scene}", "--width", "0"], "--width"),
    (["render", "{scene}", "--samples", "many"], "--samples"),
    (["render", "{scene}", "--samples", "17"], "--samples"),
    (["render"], "SCENES"),
    (["rendr", "{scene}"], "rendr"),
    (["render", "{scene}", "--colour", "red"], "--colour"),
    (["render", "{scene}", "--overlay=top"], "--overlay takes no value but 'side'"),
]


@pytest.mark.parametrize("args, named", BAD_COMMAND_LINES, ids=[" ".join(a) for a, _ in BAD_COMMAND_LINES])
def test_bad_command_line_is_rejected_in_one_line(args: list[str], named: str, tmp_path: Path) -> None:
    scene_path = write_scene(tmp_path, Case("valid", lambda scene: None, ""))
    done = subprocess.run([str(RTREFLECT), *(a.format(scene=scene_path) for a in args), "-o", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == EXIT_BAD_INPUT, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("rtreflect: error: "), done.stderr
    assert named in lines[0] and "--help" in lines[0], lines[0]
    assert files_under(tmp_path / "out") == []


def test_geometry_symlink_loop_is_rejected_in_one_line(tmp_path: Path) -> None:
    """Path.resolve raises RuntimeError on a loop (Python < 3.13): it must still be a one-line error."""
    (tmp_path / "a.bpt").symlink_to("b.bpt")
    (tmp_path / "b.bpt").symlink_to("a.bpt")
    case = Case("symlink loop", put(S, {"file": "a.bpt"}), "cannot read geometry file", blamed_file="a.bpt")
    scene_path = write_scene(tmp_path, case)
    outdir = tmp_path / "out"
    result = CliRunner().invoke(cli, ["render", str(scene_path), "-o", str(outdir), *RENDER_OPTIONS])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code == EXIT_BAD_INPUT
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and f"{tmp_path / 'a.bpt'}: cannot read geometry file" in lines[0], result.stderr
    assert f"{scene_path}: surface[0].file" in lines[0]
    assert files_under(outdir) == []


#: Every command that reads scenes applies the same checks: a sample of the table through `validate`
#: (exit 2, one line) and `batch` (the scene fails with that one-line reason, the others go on: exit 1).
OTHER_COMMAND_CASES = CASES[::8]


@pytest.mark.parametrize("case", OTHER_COMMAND_CASES, ids=[case.id for case in OTHER_COMMAND_CASES])
def test_bad_scene_is_rejected_by_validate(case: Case, tmp_path: Path) -> None:
    scene_path = write_scene(tmp_path, case)
    result = CliRunner().invoke(cli, ["validate", str(scene_path), "--json", str(tmp_path / "out" / "r.json"),
                                      "--width", "32", "--height", "18"])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    check_rejection(case, scene_path, tmp_path / "out", result.exit_code, result.stderr)


@pytest.mark.parametrize("case", OTHER_COMMAND_CASES, ids=[case.id for case in OTHER_COMMAND_CASES])
def test_bad_scene_fails_alone_in_a_batch(case: Case, tmp_path: Path) -> None:
    scene_path = write_scene(tmp_path, case)
    good = tmp_path / "good" / "good.toml"
    good.parent.mkdir()
    good.write_text(toml_document(valid_scene()))
    report_path = tmp_path / "report.json"
    result = CliRunner().invoke(cli, ["batch", str(scene_path), str(good), "-o", str(tmp_path / "out"), "-j", "1",
                                      "--json", str(report_path)])
    assert result.exit_code == 1, result.output
    scenes = {Path(s["scene"]).name: s for s in json.loads(report_path.read_text())["scenes"]}
    assert scenes["good.toml"]["status"] == "rendered"
    bad = scenes["scene.toml"]
    assert bad["status"] == "failed" and "\n" not in bad["error"]
    assert f"{case.expected_file(scene_path)}: {case.field}" in bad["error"], bad["error"]


def test_render_overrides_are_read_like_the_scene_file(tmp_path: Path) -> None:
    """Scene.with_render re-reads [render] as load_scene does: the same settings and the same one-line messages."""
    import numpy as np

    from rtreflect.errors import SceneError
    from rtreflect.exchange.scene import load_scene

    base = load_scene(write_scene(tmp_path, Case("base", lambda scene: None, "")))
    with pytest.raises(SceneError) as override:
        base.with_render(normals="smooth")
    write_scene(tmp_path, Case("bad mode", put("render.normals", "smooth"), "render.normals"))
    with pytest.raises(SceneError) as in_file:
        load_scene(tmp_path / "scene.toml")
    assert str(override.value) == str(in_file.value)
    assert "render.normals" in str(override.value)
    with pytest.raises(SceneError, match="render.overlay"):
        base.with_render(overlay="yes")  # type: ignore[arg-type]

    write_scene(tmp_path, Case("mesh overlay", together(put("render.normals", "mesh"), put("render.overlay", True)), ""))
    expected = load_scene(tmp_path / "scene.toml").render
    got = base.with_render(overlay=True, normals="mesh").render
    assert vars(got).keys() == vars(expected).keys()
    for key, value in vars(expected).items():
        assert np.array_equal(vars(got)[key], value), key
