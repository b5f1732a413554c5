"""The legend of a map mode (curvature, draft): a colour bar with numbers and units, as ``NAME.legend.svg``.

Written beside the PNG (the picture itself stays the render, pixel for pixel, so `diff` and the
goldens compare renders only), as SVG: text in any font the viewer has, opened by every browser
and image viewer, and plain text that the output folder writes atomically with the images.
Colours are the map's sRGB values (the film's linear values encoded as the PNG encodes them).
"""

from __future__ import annotations

import html
import warnings

import numpy as np

from .curvaturemap import SIGNED, CurvatureMode
from .draft import UNDERCUT_RGB, DraftMode

#: Size of the legend in SVG user units (pixels): a bar tall enough for five readable ticks.
WIDTH, HEIGHT = 380, 440
BAR = (24, 60, 40, 300)  # x, y, width, height of the colour bar
#: Colour stops along a continuous bar: finer than a 300 px bar shows.
STOPS = 256
TICKS = 5
NAMES = {"gaussian": "Gaussian curvature K", "mean": "mean curvature H", "k1": "principal curvature κ1",
         "k2": "principal curvature κ2", "maxabs": "largest |κ|", "radius": "smallest radius of curvature 1/max |κ|"}


#: The `[render] mode`s that colour the surface with a map, and so write a legend.
LEGEND_MODES = ("curvature", "draft")


def legend_file_name(scene) -> str:
    return f"{scene.output.name}.legend.svg"


def _hex(linear: np.ndarray) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # colour-science's import-time notes; imported here: start-up stays light
        import colour
    srgb = np.clip(colour.cctf_encoding(np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0), function="sRGB"), 0, 1)
    r, g, b = np.round(srgb * 255).astype(int)
    return f"#{r:02x}{g:02x}{b:02x}"


def _text(x: float, y: float, text: str, size: int = 14, anchor: str = "start") -> str:
    return (f'<text x="{x:g}" y="{y:g}" font-family="sans-serif" font-size="{size}" text-anchor="{anchor}" '
            f'fill="#111">{html.escape(text)}</text>')


def _svg(body: list[str]) -> str:
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" '
            f'viewBox="0 0 {WIDTH} {HEIGHT}">\n<rect width="100%" height="100%" fill="white"/>\n'
            + "\n".join(body) + "\n</svg>\n")


def curvature_legend(mode: CurvatureMode) -> str:
    """A continuous bar from ``mode.high`` (top) to ``mode.low``, ticks, units, the range's origin and clipping."""
    x, y, w, h = BAR
    t = np.linspace(1.0, 0.0, STOPS)  # top of the bar = high
    rgb = mode.colors(mode.low + t * (mode.high - mode.low))
    stops = "".join(f'<stop offset="{i / (STOPS - 1):.4f}" stop-color="{_hex(c)}"/>' for i, c in enumerate(rgb))
    body = [f'<defs><linearGradient id="bar" x1="0" y1="0" x2="0" y2="1">{stops}</linearGradient></defs>',
            _text(x, 28, f"{NAMES[mode.quantity]} ({mode.units})", 16),
            f'<rect x="{x}" y="{y}" width="{w}" height="{h}" fill="url(#bar)" stroke="#111"/>']
    for k in range(TICKS):
        value = mode.high - k * (mode.high - mode.low) / (TICKS - 1)
        ty = y + k * h / (TICKS - 1)
        body += [f'<line x1="{x + w}" y1="{ty:g}" x2="{x + w + 6}" y2="{ty:g}" stroke="#111"/>',
                 _text(x + w + 10, ty + 5, f"{value:.3g}")]
    for level in mode.levels:  # iso-curvature lines, where the bands meet
        ly = y + (mode.high - level) / (mode.high - mode.low) * h
        body.append(f'<line x1="{x}" y1="{ly:g}" x2="{x + w}" y2="{ly:g}" stroke="white" stroke-width="2"/>')
    if mode.clipped is None:
        note = "fixed range (render.range); values beyond it take the end colours"
    else:
        kind = "|value|, symmetric about 0" if mode.quantity in SIGNED else "2nd to 98th percentile"
        note = f"auto range: 98th percentile of {kind}; {100 * mode.clipped:.1f} % of the sampled surface clipped"
    # One clause a line: the 360-unit-wide legend clipped the range note as one line.
    lines = [*note.split("; "), "signed with the normal facing the camera (positive: bends towards it)"]
    body += [_text(x, y + h + 28 + 18 * i, line, 11) for i, line in enumerate(lines)]
    return _svg(body)


def draft_legend(mode: DraftMode) -> str:
    """One swatch per band, from the most draft (top) down to the undercut flag."""
    x, y = BAR[0], BAR[1]
    edges = list(mode.thresholds)
    # A draft angle inside each band, from the most draft down: above t_m, between each pair, below t_1 (if ≥ 0).
    probe, labels = [edges[-1] + 1.0], [f"≥ {edges[-1]:g}°"]
    for low, high in zip(edges[-2::-1], edges[:0:-1]):
        probe.append(0.5 * (low + high))
        labels.append(f"{low:g}° to {high:g}°")
    if edges[0] > 0:
        probe.append(0.5 * edges[0])
        labels.append(f"0° to {edges[0]:g}°")
    body = [_text(x, 28, "draft angle δ = 90° − angle(n, pull)", 16)]
    rows = [(label, rgb) for label, rgb, d in zip(labels, mode.colors(np.array(probe)), probe) if d >= 0]
    rows.append(("undercut (δ < 0°)", UNDERCUT_RGB))
    for k, (label, rgb) in enumerate(rows):
        ry = y + 34 * k
        body += [f'<rect x="{x}" y="{ry}" width="40" height="26" fill="{_hex(rgb)}" stroke="#111"/>',
                 _text(x + 52, ry + 18, label)]
    return _svg(body)


def legend_svg(mode) -> str | None:
    """The legend of a map mode, or None for a mode that draws lines only."""
    if isinstance(mode, CurvatureMode):
        return curvature_legend(mode)
    if isinstance(mode, DraftMode):
        return draft_legend(mode)
    return None
