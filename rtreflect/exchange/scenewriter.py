"""A `Scene` written back as a scene file (TOML): every key present and commented (`rtreflect init`).

Numbers are written with Python's ``repr`` (the shortest text that reads back as the same
double), so reading the text gives the same scene: the same specs and the same patches
(`_spec_table` is the inverse of the readers). Geometry is written as the source gave it:
``file = ...`` entries (paths relative to ``base``, the folder the scene file will live in) and
inline patches with their numbers.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .scene import MODE_DEFAULTS, MODE_KEYS, Scene, _spec_table

#: Values shown for the commented-out mode keys that have no fixed default (isophote's L defaults to lights.normal).
_MODE_EXAMPLES = {"light": [0.0, 0.0, 1.0]}

#: The comment after each key (docs/scene-format.md has the full reference).
COMMENTS = {
    "image": {
        "width": "pixels",
        "height": "pixels",
        "samples": '"analytic": stripes anti-aliased in closed form, edges 4×4; or s: s×s stratified samples per pixel',
    },
    "camera": {
        "projection": '"perspective" or "orthographic"',
        "view": "without eye: where the eye looks from (iso, top, bottom, front, back, left, right, or a vector)",
        "eye": "remove eye to place the camera on view again, framing the part",
        "look_at": "remove it to look at the centre of the part's bounding box",
        "up": "the model's up axis (image up)",
        "fov": "perspective: vertical field of view, degrees",
        "view_height": "orthographic: height of the view in model units",
    },
    "lights": {
        "auto": "true: choose the keys left out from where the reflections land (no [lights] at all: all of them); "
                "fitted to [render] mode's lines: after changing mode, remove [lights] to fit them again",
        "point": "Q: a point of the light plane",
        "normal": "m: the light plane's normal",
        "direction": "c: the tubes' direction, in the plane",
        "positions": "c_k: tube k passes through Q + c_k e, e = c × m (or give spacing and count)",
        "radius": "tube radius: the stripes' width",
        "length": "tube length (inf: unbounded)",
        "shape": '"tubes", or "circles": positions are radii of circles about centre (reflection, highlight)',
        "centre": "circles: C, the circles' centre, in the light plane (default: point)",
    },
    "render": {
        "tessellation": "mesh segments per knot span (hits are refined onto the exact surface)",
        "surface_color": "linear RGB",
        "line_color": "linear RGB",
        "background": "linear RGB (the PNG is opaque; A stays in the EXR)",
        "shading": '"lambert": the surface lit from the eye under the stripes, or "flat"',
        "blur": "soft stripe edge, 0-1, a fraction of the radius (0: hard edges)",
        "overlay": 'draw the analytic lines over the PNG, write NAME.contours.json ("side": beside the plain PNG)',
        "overlay_color": "linear RGB",
        "overlay_width": "pixels",
        "normals": '"exact" NURBS normals, or "mesh" (CAD analysis-mesh normals, to compare)',
        "mode": "reflection, highlight, isophote, draft, curvature or zebra (docs/scene-format.md, The other modes)",
        "step": "isophote, zebra: degrees between lines",
        "light": "isophote: the light direction L",
        "pull": "draft: the mould's pull direction",
        "thresholds": "draft: draft angles (degrees) bounding the colour bands; below 0: undercut, red",
        "quantity": "curvature: gaussian, mean, k1, k2, maxabs or radius",
        "range": 'curvature: [min, max] of the colour map, or "auto"',
        "bands": "curvature: iso-curvature lines cutting the range into this many bands (0: none)",
    },
    "output": {
        "name": "NAME of NAME.exr and NAME.png",
        "exr": "write NAME.exr (linear RGBA and the AOVs)",
        "png": "write NAME.png (8-bit sRGB)",
    },
}
#: Table order of the file, as docs/scene-format.md lists them.
TABLES = ("image", "camera", "lights", "render", "output")


def toml_value(value: Any) -> str:
    """One TOML value: booleans, integers, floats (repr; inf and nan as TOML spells them), strings, arrays."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
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
        return json.dumps(value, ensure_ascii=False)  # a TOML basic string: the same escapes
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    raise TypeError(f"no TOML form for {type(value).__name__}")


def inline_table(table: dict[str, Any]) -> str:
    """``{ key = value, ... }``: a table on one line (the rig recorded in the EXR header)."""
    return "{ " + ", ".join(f"{key} = {toml_value(value)}" for key, value in table.items()) + " }"


def _table_lines(name: str, table: dict[str, Any]) -> list[str]:
    lines = [f"[{name}]"]
    for key, comment in COMMENTS[name].items():
        if key in table:
            lines.append(f"{key} = {toml_value(table[key])}  # {comment}")
        elif name == "render" and key in MODE_KEYS:  # another mode's key: shown, commented out, at its default
            lines.append(f"# {key} = {toml_value(_MODE_EXAMPLES.get(key, MODE_DEFAULTS.get(key)))}  # {comment}")
    if name == "lights":
        lines.insert(lines.index(next(line for line in lines if line.startswith("positions"))) + 1,
                     "# spacing = 0.5  # with count, instead of positions: count tubes spacing apart, centred on Q")
        lines.insert(lines.index(next(line for line in lines if line.startswith("# spacing"))) + 1,
                     "# count = 12")
        if "centre" not in table and "point" in table:  # tubes: the circles' key shown, commented out
            lines.insert(lines.index(next(line for line in lines if line.startswith("shape"))) + 1,
                         f"# centre = {toml_value(table['point'])}  # {COMMENTS['lights']['centre']}")
    return lines


def scene_text(scene: Scene, source: Path, surfaces: list[dict[str, Any]], base: Path, header: str) -> str:
    """The scene file of a resolved ``scene`` (no automatic value left) read from ``source``.

    ``surfaces``: the ``[[surface]]`` tables of the source (``file`` paths relative to the source's
    folder), rewritten relative to ``base``. ``header``: the opening comment lines.
    """
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    for name in TABLES:
        table = _spec_table(getattr(scene, name))
        if name == "lights":
            table = {"auto": False, **table}
        lines += ["", *_table_lines(name, table)]
    for entry in surfaces:
        lines += ["", "[[surface]]"]
        for key, value in entry.items():
            if key == "file":
                target = (source.parent / value).resolve()
                value = os.path.relpath(target, base.resolve())
            lines.append(f"{key} = {toml_value(value)}")
    return "\n".join(lines) + "\n"


def source_surfaces(source: Path) -> list[dict[str, Any]]:
    """The ``[[surface]]`` tables of a scene file as written (a CAD part given as the scene: ``file`` = the part)."""
    import tomllib

    from .cad import is_cad_path

    if is_cad_path(source):
        return [{"file": source.name}]
    return list(tomllib.loads(source.read_text(encoding="utf-8"))["surface"])
