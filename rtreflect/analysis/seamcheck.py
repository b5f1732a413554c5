"""`rtreflect continuity`: the per-scene check behind the command — seams, their figures, the table, the JSON.

Seams come from `geometry.seams` (B-rep topology for CAD faces, found geometrically otherwise), the exact G0/G1/G2 figures from
`analysis.continuity`, the reflection lines' kinks from `analysis.seamlines`. Nothing here
imports the command line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import RtreflectError
from ..geometry.seams import FIND_FRACTION, part_size, scene_seams
from .continuity import CLASSES, EdgeReport, Thresholds, class_rank, continuity

#: Default G0 tolerance as a fraction of the part's size (model units then follow the part): 1e-6 of a 1 m part
#: is 1 µm, finer than any CAD exchange tolerance, coarser than the rounding of exact evaluation (~1e-15).
DEFAULT_G0_FRACTION = 1e-6
#: Default G1 tolerance in degrees: the tangency tolerance CAD checkers commonly default to is 0.1° to 0.5°.
DEFAULT_G1_DEG = 0.1
#: Default G2 tolerance: a relative curvature jump of 5 % (|κA − κB| / max(|κA|, |κB|)).
DEFAULT_G2 = 0.05
REQUIRE_CHOICES = ("G0", "G1", "G2")


def check_tolerances(g0: float | None, g1: float, g2: float) -> None:
    """Negative or non-finite tolerances are bad input (one line, exit 2)."""
    for name, value in (("--g0", g0), ("--g1", g1), ("--g2", g2)):
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise RtreflectError(f"{name}: a tolerance must be a finite number ≥ 0, got {value!r}")


@dataclass
class SceneContinuity:
    name: str
    path: str
    size: float
    thresholds: Thresholds
    edges: list[EdgeReport]
    scene: object = field(repr=False, default=None)

    def counts(self) -> dict[str, int]:
        return {c: sum(e.cls == c for e in self.edges) for c in CLASSES}

    def meets(self, require: str) -> bool:
        return all(class_rank(e.cls) >= class_rank(require) for e in self.edges)

    def summary(self, require: str) -> dict:
        worst = min((e.cls for e in self.edges), key=class_rank, default=None)
        return {"scene": self.name, "edges": len(self.edges), **{f"count_{c}": n for c, n in self.counts().items()},
                "worst_class": worst, "require": require, "passed": self.meets(require),
                "g0_tolerance": self.thresholds.g0, "g1_tolerance_deg": self.thresholds.g1_deg,
                "g2_tolerance": self.thresholds.g2, "size": self.size}


def check_scene(scene, g0: float | None = None, g1: float = DEFAULT_G1_DEG, g2: float = DEFAULT_G2,
                lines: bool = True) -> SceneContinuity:
    """Find the scene's seams, measure them, and (``lines``) the reflection lines' kinks where they cross them."""
    from ..integrator.autorig import resolve

    scene = resolve(scene)  # the automatic camera and tubes (a CAD part, a scene without [lights]) made concrete
    patches = list(scene.surfaces)
    size = part_size(patches)
    th = Thresholds(DEFAULT_G0_FRACTION * size if g0 is None else g0, g1, g2)
    # Find seams with a tolerance above the G0 one, so a seam with a gap is still found (and reported open).
    seams = scene_seams(patches, max(FIND_FRACTION * size, 10.0 * th.g0))
    edges = continuity(patches, seams, th, size)
    if lines and edges:
        from ..integrator.renderer import Renderer
        from .contours import UlmetField
        from .seamlines import attach_line_kinks

        attach_line_kinks(UlmetField.of(Renderer(scene)), edges, size)
    return SceneContinuity(scene.output.name, str(scene.path), size, th, edges, scene)


def _g(x: float) -> str:
    return f"{x:.3g}"


def table(result: SceneContinuity) -> list[str]:
    """The printed table: one row per shared edge, then nothing (the caller prints the summary line)."""
    if not result.edges:
        return [f"{result.name}: no shared edges ({len(result.scene.surfaces)} patch"
                f"{'' if len(result.scene.surfaces) == 1 else 'es'}, none sharing a boundary)"]
    head = (f"  {'patches':>9} {'length':>8} {'samples':>7} {'g0_max':>9} {'g1_max°':>9} {'g2_abs':>9} "
            f"{'g2_rel':>7} {'kink°':>7} {'class':>5}  worst g0 / g1 / g2 at (x, y, z)")
    rows = [f"{result.name} ({result.path})", head]
    for e in result.edges:
        kink = "-" if e.line_kink_max_deg is None else f"{e.line_kink_max_deg:.3g}"
        where = " / ".join("(" + ", ".join(f"{c:.3g}" for c in e.worst(k)) + ")" for k in ("g0", "g1", "g2"))
        rows.append(f"  {f'{e.seam.a.patch}-{e.seam.b.patch}':>9} {_g(e.seam.length):>8} {len(e.samples.t):>7} "
                    f"{e.g0_max:>9.2e} {e.g1_max_deg:>9.2e} {e.g2_max_abs:>9.3g} {e.g2_max_rel:>7.3g} {kink:>7} "
                    f"{e.cls:>5}  {where}")
    return rows


def summary_line(result: SceneContinuity, require: str) -> str:
    counts = result.counts()
    th = result.thresholds
    tally = ", ".join(f"{counts[c]} {c}" for c in reversed(CLASSES) if counts[c])
    verdict = "PASS" if result.meets(require) else "FAIL"
    return (f"{result.name}: {len(result.edges)} shared edge{'' if len(result.edges) == 1 else 's'}"
            f"{': ' + tally if tally else ''}; {verdict} (require {require}; tolerances G0 {th.g0:.3g}, "
            f"G1 {th.g1_deg:g}°, G2 {th.g2:g} relative)")


def document(results: list[SceneContinuity], require: str) -> dict:
    """The `--json` report: every edge (with its scene's name), and a summary over all scenes."""
    edges = []
    for result in results:
        for e in result.edges:
            edges.append({"scene": result.name, **e.to_json()})
    all_edges = [e for r in results for e in r.edges]
    summary = {"edges": len(all_edges), **{f"count_{c}": sum(e.cls == c for e in all_edges) for c in CLASSES},
               "require": require, "passed": all(r.meets(require) for r in results),
               "scenes": [r.summary(require) for r in results],
               "g2_rel_definition": "|kA - kB| / max(|kA|, |kB|) (= |rA - rB| / max(|rA|, |rB|) with signed radii); "
                                    "g2_max_rel_mean: |kA - kB| / ((|kA| + |kB|) / 2)"}
    return {"edges": edges, "summary": summary}
