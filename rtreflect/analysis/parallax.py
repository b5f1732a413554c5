"""Zebra's parallax: how far environment-mapped stripes lie from the reflection lines of physical tubes, in pixels.

Zebra (paper section 3.2) lights a point by its reflected direction s alone: stripe k where
ψ = atan2(s·e, s·m) = ψ_k. Physical tubes at a finite distance light it by where its reflected
ray meets their plane (Ulmet's f, eq. 5–6), which depends on the point R too: the eye and
surface parallax that the environment map leaves out. The equivalent tubes lie in the scene's
light plane (through Q, normal m, along c), where the directions ψ_k seen from the part's centre
O (the middle of its mesh's bounding box) meet it: c_k = e·(O − Q) + h tan ψ_k with
h = m·(Q − O), for the levels whose direction reaches the plane ahead (t = h/(m·d) > 0 with
d = cos ψ_k m + sin ψ_k e) within `MAX_ANGLE` of the plane's normal. Seen from O the two
agree; elsewhere they part by the parallax. Per level, every vertex of zebra's analytic
contour ψ = ψ_k (`contours.ModeField`) is measured to the nearest segment of the projected
analytic reflection line f = c_k of its tube (`contours.UlmetField`, same camera and
visibility): the per-image figures no CAD tool reports. Vertices with no reflection line of
their tube in view (cut by visibility, or the tube reflected elsewhere) are counted apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .contours import ContourLines, UlmetField, analytic_contours
from .nearest import nearest_segment

#: Levels farther than this from the plane's normal get no tube: tan ψ puts it far out, grazing the plane.
MAX_ANGLE = 75.0


@dataclass
class ParallaxLine:
    level: float  # ψ_k, degrees
    tube: float  # c_k of the equivalent tube
    points: int  # zebra contour vertices measured
    unmatched: int  # zebra contour vertices with no reflection line of the tube in view
    mean_px: float | None
    p95_px: float | None
    max_px: float | None


@dataclass
class ParallaxReport:
    reference: np.ndarray  # O
    lines: list[ParallaxLine]
    distances: np.ndarray  # every measured vertex, px

    def to_json(self) -> dict:
        stats = _stats(self.distances)
        return {"reference": self.reference.tolist(), "points": int(len(self.distances)),
                "unmatched": sum(line.unmatched for line in self.lines),
                "mean_px": stats[0], "p95_px": stats[1], "max_px": stats[2],
                "lines": [dict(vars(line)) for line in self.lines]}


def _stats(d: np.ndarray) -> tuple[float | None, float | None, float | None]:
    if len(d) == 0:
        return None, None, None
    return float(d.mean()), float(np.percentile(d, 95)), float(d.max())


def equivalent_tubes(levels: np.ndarray, lights, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(indices of the levels that have a tube, their tube positions c_k) for zebra levels ψ_k in degrees (module doc)."""
    psi = np.radians(np.asarray(levels, dtype=np.float64))
    h = float(lights.m @ (lights.Q - reference))
    d_m = np.cos(psi)  # m·d
    with np.errstate(divide="ignore", invalid="ignore"):
        t = h / d_m
    keep = np.flatnonzero((t > 0) & (np.abs(np.degrees(np.arctan2(np.sin(psi), np.abs(d_m)))) <= MAX_ANGLE))
    return keep, float(lights.e @ (reference - lights.Q)) + h * np.tan(psi[keep])


def zebra_parallax(renderer, zebra: ContourLines) -> ParallaxReport:
    """The parallax of a zebra render's stripes (``zebra``: the analytic contours of ψ) against equivalent tubes."""
    vertices = renderer.tessellation.vertices
    reference = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    keep, positions = equivalent_tubes([line.position for line in zebra.lines], renderer.lights, reference)
    lines, every = [], []
    if len(keep):
        tubes = replace(renderer.lights, c_k=positions)
        field = UlmetField(renderer.surfaces, renderer.tessellation, renderer.accelerator, renderer.camera, tubes)
        reflection = analytic_contours(field)
        far = math.hypot(renderer.camera.width, renderer.camera.height)
        for j, k in enumerate(keep):
            points = [p.px for p in zebra.lines[k].polylines]
            pts = np.concatenate(points) if points else np.zeros((0, 2))
            segs = [(p.px[:-1], p.px[1:]) for p in reflection.lines[j].polylines if len(p.px) >= 2]
            a = np.concatenate([s[0] for s in segs]) if segs else np.zeros((0, 2))
            b = np.concatenate([s[1] for s in segs]) if segs else np.zeros((0, 2))
            dist, _ = nearest_segment(pts, a, b, far)
            found = dist[np.isfinite(dist)]
            every.append(found)
            mean, p95, top = _stats(found)
            lines.append(ParallaxLine(float(zebra.lines[k].position), float(positions[j]), int(len(found)),
                                      int(len(dist) - len(found)), mean, p95, top))
    return ParallaxReport(reference, lines, np.concatenate(every) if every else np.zeros(0))
