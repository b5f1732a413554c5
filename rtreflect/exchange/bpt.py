"""Reader of `.bpt` Bézier patch files (the Newell teapot's format).

Text of whitespace-separated numbers: the patch count, then per patch its degrees
``du dv`` and (du+1)(dv+1) points, u-major: point ``i·(dv+1) + j`` is control
point (i, j), i the u index.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import SceneError, quote, read_text
from ..geometry.surfaces import NurbsSurface

#: The numbers a .bpt file may hold: plain ASCII decimals (Python's int and float would also take
#: "1_000", non-ASCII digits and surrounding blanks). nan and inf are matched so they can be named as such.
INTEGER = re.compile(r"[+-]?[0-9]+")
NUMBER = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?|[+-]?(nan|inf|infinity)", re.IGNORECASE)
#: Digits of an integer token beyond this are refused before int() (which refuses above 4300 digits itself).
MAX_INTEGER_DIGITS = 9

#: Degrees above this are refused: no real file has them and they would only cost memory.
MAX_DEGREE = 30


def read_bpt(path: Path, name: str = "") -> list[NurbsSurface]:
    """All patches of a `.bpt` file, in file order, as NURBS surfaces on [0, 1]²."""
    text = read_text(path, "geometry file")

    tokens: list[tuple[str, int]] = [(tok, number) for number, line in enumerate(text.split("\n"), 1) for tok in line.split()]
    position = 0

    def take(what: str, integer: bool = False) -> float:
        nonlocal position
        if position >= len(tokens):
            raise SceneError(path, "end of file", f"truncated: expected {what}")
        tok, line = tokens[position]
        position += 1
        if not (INTEGER if integer else NUMBER).fullmatch(tok):
            raise SceneError(path, f"line {line}", f"expected {what}, got {quote(tok)}")
        if integer and len(tok.lstrip("+-")) > MAX_INTEGER_DIGITS:
            raise SceneError(path, f"line {line}", f"{what} is too large ({quote(tok)})")
        value = int(tok) if integer else float(tok)
        if not np.isfinite(value):
            raise SceneError(path, f"line {line}", f"{what} is not finite ({quote(tok)})")
        return value

    count = int(take("the patch count", integer=True))
    if count < 1:
        raise SceneError(path, "line 1", f"patch count must be at least 1, got {count}")
    patches = []
    stem = name or path.stem
    for k in range(count):
        du = int(take(f"patch {k} degree u", integer=True))
        dv = int(take(f"patch {k} degree v", integer=True))
        if not (1 <= du <= MAX_DEGREE and 1 <= dv <= MAX_DEGREE):
            raise SceneError(path, f"patch {k}", f"degrees must be between 1 and {MAX_DEGREE}, got {du} {dv}")
        pts = np.array([take(f"patch {k} coordinate") for _ in range((du + 1) * (dv + 1) * 3)])
        patches.append(NurbsSurface.bezier(pts.reshape(du + 1, dv + 1, 3), name=f"{stem}[{k}]"))
    if position != len(tokens):
        tok, line = tokens[position]
        raise SceneError(path, f"line {line}", f"unexpected data after {count} patches ({quote(tok)}): wrong patch count or point count")
    return patches
