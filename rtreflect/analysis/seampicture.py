"""Pictures of the continuity check: the seams drawn over a render, and per-edge charts along each seam.

The seams are drawn with the overlay's anti-aliased line coverage (`overlay.coverage`,
`overlay.blend`), coloured by the class each reaches; a seam short of G2 gets its worst value written beside
its worst visible point (one label where symmetric copies would overlap);
a legend names the colours where it fits (text scaled to the image). Points of a seam hidden from the eye (Embree occlusion, as
for the contours) are not drawn. The charts plot G0 (gap), G1 (angle) and the two
sides' normal curvatures against arc length, one row of three panels per edge. Text is
drawn by OpenImageIO's ``render_text`` (its built-in font), so no plotting library is needed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ..errors import RtreflectError
from ..output.imagefiles import atomic_path, write_png
from .contours import ContourLine, ContourLines, Polyline, UlmetField
from .overlay import blend, coverage
from ..trace.tracing import occluded

#: Linear RGB per class: red open, orange G0, yellow-green G1, blue G2 (distinct for the usual colour blindness).
CLASS_COLOURS = {"open": (0.9, 0.0, 0.0), "G0": (1.0, 0.45, 0.0), "G1": (0.75, 0.75, 0.0), "G2": (0.0, 0.35, 1.0)}
SEAM_WIDTH_PX = 3.0
#: Text size of labels and legend: the image width over this, within [MIN_FONT_PX, FONT_PX] (fixed-size text on a
#: 160×90 render covered the whole picture).
FONT_PER_WIDTH = 40
FONT_PX = 14
MIN_FONT_PX = 8
#: Width of a character of the built-in font over its size, for keeping labels apart.
CHAR_PER_FONT = 8 / 14
#: The legend is drawn only where its box takes at most these fractions of the image's width and height: on a small
#: render it would hide the seams it explains (their colours are listed in `rtreflect continuity --help`).
LEGEND_WIDTH, LEGEND_HEIGHT = 0.6, 0.3
#: Labels stop once their boxes cover this fraction of the image (the worst seams are labelled first).
LABEL_AREA = 0.1
PANEL = (240, 120)  # width, height of one chart panel in pixels
MARGIN = 28


def _text(rgba: np.ndarray, x: int, y: int, text: str, colour=(0.0, 0.0, 0.0), size: int = FONT_PX) -> np.ndarray:
    """``rgba`` with ``text`` written at (x, y) (baseline), via OpenImageIO's render_text."""
    buf = oiio.ImageBuf(np.ascontiguousarray(rgba, dtype=np.float32))
    oiio.ImageBufAlgo.render_text(buf, int(x), int(y), text, size, "", (*colour, 1.0))
    return buf.get_pixels(oiio.FLOAT).reshape(rgba.shape)


def _seen_from_eye(field: UlmetField, patches: tuple[int, int], P: np.ndarray, n_a: np.ndarray,
                   n_b: np.ndarray) -> np.ndarray:
    """True where the seam point P is not hidden from the eye by the part (origin off the surface, as for rays).

    The origin leaves the edge along the bisector of both faces' normals (each turned to the eye), by the larger
    of their offsets: off one face alone it may still lie on the other (a cap's rim on a cylinder), whose
    triangles then hide it. The occlusion is trim-aware, as the contours' visibility (`tracing.occluded`).
    """
    cam = field.camera
    a = cam.eye_vectors(P)
    turned = [np.where((np.sum(n * a, axis=1) >= 0)[:, None], n, -n) for n in (n_a, n_b)]
    bisector = turned[0] + turned[1]
    length = np.linalg.norm(bisector, axis=1, keepdims=True)
    n = np.where(length > 0, bisector / np.where(length > 0, length, 1.0), turned[0])
    origins = [field.accelerator.surface_origins(P, n, np.full(len(P), patch)) for patch in patches]
    farther = np.linalg.norm(origins[1] - P, axis=1) > np.linalg.norm(origins[0] - P, axis=1)
    origin = np.where(farther[:, None], origins[1], origins[0])
    to_eye = np.linalg.norm(cam.spec.eye - origin, axis=1) if not cam.orthographic else (origin - cam.spec.eye) @ cam.basis[0]
    depth = (P - cam.spec.eye) @ cam.basis[0]
    seen = depth > 0
    idx = np.flatnonzero(seen)
    seen[idx] &= ~occluded(field.accelerator, field.tessellation, field.surfaces, origin[idx], a[idx],
                           np.abs(to_eye[idx]))
    return seen


def _label(e) -> str:
    if e.cls == "open":
        return f"open, gap {e.g0_max:.2g}"
    if e.cls == "G0":
        return f"G0, {e.g1_max_deg:.2g} deg"
    if e.cls == "G1":
        return f"G1, dk {e.g2_max_rel:.0%}"
    return "G2"


def write_seam_picture(path: Path, result) -> None:
    """Render the scene and write the PNG with the seams, labels and legend drawn over it."""
    from ..integrator.renderer import Renderer

    renderer = Renderer(result.scene)
    rgba = renderer.render().rgba.copy()
    background = rgba[..., 3:4]  # composite over white so the black text and coloured seams read everywhere
    rgba[..., :3] = rgba[..., :3] * background + (1.0 - background)
    rgba[..., 3] = 1.0
    _save(path, draw_seams(rgba, UlmetField.of(renderer), result))


def seam_filter(renderer, result):
    """The PNG filter (`imagefiles.PngFilter`) of `render --seams`: `draw_seams` applied to rows as they stream out.

    Every drawing step of `draw_seams` (coverage blends, the font's blends, the legend's
    swatches) maps a pixel's value v to v·M + C, per channel, with M and C set by the seams
    alone; so drawing once over 0 (gives C) and once over 1 (gives M + C) captures the
    whole picture, and rows are drawn before the render exists, as the overlay's are.
    Alpha is the exception (`overlay.blend` keeps the larger of pixel and line coverage):
    it is the larger of the render's and the drawing's own, exact wherever the render is
    opaque or empty, i.e. everywhere but the silhouette's anti-aliased edge.
    """
    scene = renderer.scene
    W, H = scene.image.width, scene.image.height
    field = UlmetField.of(renderer)
    C = draw_seams(np.zeros((H, W, 4), np.float32), field, result)
    M = draw_seams(np.ones((H, W, 4), np.float32), field, result) - C

    def draw(row0: int, rgba_rows: np.ndarray) -> np.ndarray:
        rows = slice(row0, row0 + len(rgba_rows))
        out = (rgba_rows * M[rows] + C[rows]).astype(np.float32)
        out[..., 3] = np.maximum(rgba_rows[..., 3], C[rows, :, 3])
        return out

    return draw


def draw_seams(rgba: np.ndarray, field: UlmetField, result) -> np.ndarray:
    """``rgba`` (H, W, 4 linear) with the seams of ``result`` drawn by class, their labels and the legend."""
    W, H = rgba.shape[1], rgba.shape[0]
    labels = []
    for cls, colour in CLASS_COLOURS.items():
        polylines = []
        for e in (e for e in result.edges if e.cls == cls):
            s = e.samples
            seen = _seen_from_eye(field, e.seam.patches, s.P, s.n_a, s.n_b)
            px = field.camera.project(s.P)
            px[~seen] = np.nan  # hidden pieces are cut out
            polylines.append(Polyline(e.seam.a.patch, s.uv_a, px))
            if np.any(seen) and e.cls != "G2":  # label the seams that fall short of G2, at their worst visible point
                quantity = {"open": s.g0, "G0": s.g1, "G1": s.jump}[e.cls]
                at = np.flatnonzero(seen)[np.argmax(quantity[seen])]
                labels.append((px[at], _label(e), list(CLASS_COLOURS).index(cls), -float(quantity[at])))
        if polylines:
            alpha = coverage(ContourLines(W, H, [ContourLine(0, 0.0, polylines)]), W, H, SEAM_WIDTH_PX)
            rgba = blend(rgba, alpha.astype(np.float32), colour)
    font = int(np.clip(W // FONT_PER_WIDTH, MIN_FONT_PX, FONT_PX))
    char = CHAR_PER_FONT * font
    # Legend, top left: a swatch and the class's meaning, where it fits (`LEGEND_WIDTH`, `LEGEND_HEIGHT`).
    th = result.thresholds
    meaning = {"open": f"open: gap > {th.g0:.2g}", "G0": f"G0: gap closed, normals > {th.g1_deg:g} deg apart",
               "G1": f"G1: tangent, curvature jump > {th.g2:.0%}", "G2": f"G2: curvature jump <= {th.g2:.0%}"}
    longest = max(map(len, meaning.values()))

    def legend_box(size: int) -> tuple[float, float, float, float]:
        return 0.0, 0.0, 16 + round(1.4 * size) + CHAR_PER_FONT * size * longest, 10.0 + len(meaning) * (size + 6)

    # The largest text size up to the labels' whose legend fits: it fits at some size exactly when it fits at the
    # smallest, so whether a render gets a legend grows monotonically with its size.
    fits = [f for f in range(font, MIN_FONT_PX - 1, -1)
            if legend_box(f)[2] <= LEGEND_WIDTH * W and legend_box(f)[3] <= LEGEND_HEIGHT * H]
    placed: list[tuple[float, float, float, float]] = []
    if fits:
        size = fits[0]
        placed.append(legend_box(size))
        swatch = round(1.4 * size)
        for i, (cls, colour) in enumerate(CLASS_COLOURS.items()):
            y = 10 + i * (size + 6)
            rgba[y:y + size, 10:10 + swatch] = (*colour, 1.0)  # opaque, also over a render's transparent background
            rgba = _text(rgba, 16 + swatch, y + size - 2, meaning[cls], size=size)
    # Labels by class (open first) and within one by their value, worst first, until they cover `LABEL_AREA`; above
    # and right of their point, else flipped left or below where that would leave the image.
    labels.sort(key=lambda label: label[2:])
    area = 0.0
    for (x, y), text, _, _ in labels:
        if not (0 <= x < W and 0 <= y < H):
            continue
        width = char * len(text)
        left = x + 6 if x + 6 + width <= W else x - 6 - width
        base = y - 6 if y - 6 - font >= 0 else y + 6 + font
        box = (left, base - font, left + width, base)
        clash = any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in placed)
        if clash or box[0] < 0 or box[3] > H or area + width * font > LABEL_AREA * W * H:
            continue  # symmetric copies' labels once; none over the legend or another label
        area += width * font
        placed.append(box)
        rgba[int(y) - 2:int(y) + 3, int(x) - 2:int(x) + 3] = (0.0, 0.0, 0.0, 1.0)  # the point the label refers to
        rgba = _text(rgba, int(left), int(base), text, size=font)
    return rgba


def _save(path: Path, rgba: np.ndarray) -> None:
    """Write the PNG atomically (a complete file or none), its folder created; errors name the file."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            write_png(tmp, rgba, final=path)
    except OSError as exc:
        raise RtreflectError(f"{path}: cannot write picture ({exc.strerror or exc})") from None


def charts_path(report_path: Path) -> Path:
    """Where `--json REPORT` puts its companion charts: REPORT's stem + ``.charts.png``, beside it."""
    report_path = Path(report_path)
    return report_path.with_name(report_path.stem + ".charts.png")


def _panel(values: list[np.ndarray], s: np.ndarray, colours, title: str) -> np.ndarray:
    """One chart: each series in ``values`` against arc length s, scaled to the panel, with its range written."""
    w, h = PANEL
    img = np.ones((h, w, 4), dtype=np.float32)
    x0, x1, y0, y1 = 8, w - 8, MARGIN, h - 10
    img[y0:y1 + 1, x0] = img[y1, x0:x1 + 1] = (0.5, 0.5, 0.5, 1.0)
    finite = np.concatenate([v[np.isfinite(v)] for v in values]) if values else np.zeros(1)
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if hi - lo <= 1e-300:
        lo, hi = lo - 1.0, hi + 1.0 if hi == 0 else hi + abs(hi)
    span = max(s[-1] - s[0], 1e-300)
    for v, colour in zip(values, colours):
        px = np.stack([x0 + (s - s[0]) / span * (x1 - x0), y1 - (v - lo) / (hi - lo) * (y1 - y0)], axis=1)
        alpha = coverage(ContourLines(w, h, [ContourLine(0, 0.0, [Polyline(0, px, px)])]), w, h, 1.5)
        img = blend(img, alpha.astype(np.float32), colour)
    img = _text(img, 6, 13, title, size=12)
    return _text(img, 6, 25, f"{lo:.3g} .. {hi:.3g}", (0.3, 0.3, 0.3), size=11)


def write_charts(path: Path, results) -> None:
    """Per edge a row of three panels along the seam's length: G0 gap, G1 angle, κ_A and κ_B."""
    rows = []
    for result in results:
        for e in result.edges:
            s = e.samples
            head = f"{result.name} {e.seam.a.patch}-{e.seam.b.patch} ({e.cls})"
            rows.append(np.concatenate([
                _panel([s.g0], s.s, [(0.8, 0, 0)], f"{head}: G0 gap"),
                _panel([np.degrees(s.g1)], s.s, [(0.9, 0.45, 0)], "G1 angle (deg)"),
                _panel([s.kappa_a, s.kappa_b], s.s, [(0, 0.3, 1), (0.8, 0, 0.6)], "G2: kA (blue), kB (purple)"),
            ], axis=1))
    if not rows:
        return
    _save(path, np.concatenate(rows, axis=0))
