"""Warnings for renders that succeed but show nothing useful (issue 13): the four silent cases.

Tallied from the rendered pixels as tiles arrive (`ImageTally.add`, vectorised per tile, a few
counters and a set of tube indices kept), so a streamed render needs no second pass:

- no pixel sees the surface (alpha 0 everywhere);
- no reflected ray reaches the light plane (Ulmet's f, eq. 5, is NaN at every surface pixel:
  the plane is behind the surface as seen through its reflections);
- every pixel centre that sees a tube within its radius (eq. 4) has the reflected ray blocked by the part
  (the eye inside a closed part): no line shows, however many tubes are reflected;
- fewer than two distinct lines are drawn (tubes k with some pixel centre within the radius, eq. 4, and the
  reflected ray not blocked: `Tile.blocked`);
- most of the visible surface reflects past the tube bank: its reflected rays meet the light plane
  (f finite) more than one spacing beyond the outermost tubes at more than `PAST_BANK_SHARE` of the
  surface pixels (a wider bank would light them; rays leaving away from the plane it would not).

The last two count tubes: circles (`[lights] shape`) get the first two only. All but the first are of
reflection lines (f, line.id and line.dist are the reflected ray's in every mode): another mode gets the first only.
"""

from __future__ import annotations

import numpy as np

from ..exchange.scene import Scene
from .film import CHANNELS

#: Share of the surface pixels reflecting past the bank above which the bank is said to miss most of it.
PAST_BANK_SHARE = 0.5
#: Share of the surface pixels seeing a tube, all blocked, from which the picture is said to show no line because the
#: part blocks them (a few pixels in a groove, all blocked, are a line too few: the distinct-lines warning says so).
MIN_BLOCKED_SHARE = 0.01
#: Distinct lines below which the picture shows no pattern to read.
MIN_LINES = 2

_A, _F, _ID, _DIST = (CHANNELS.index(name) for name in ("A", "f", "line.id", "line.dist"))


class ImageTally:
    """Counts over a render's pixels (rows of `CHANNELS` values) for `warnings`."""

    def __init__(self, scene: Scene):
        self.scene = scene
        positions = np.asarray(scene.lights.positions, dtype=np.float64)
        gaps = np.diff(np.unique(positions))
        reach = float(gaps.min()) if len(gaps) else float(scene.lights.radius)
        # The bank covers f in [c_min − spacing, c_max + spacing] (a single tube: its radius either side).
        self.bank = (float(positions.min()) - reach, float(positions.max()) + reach)
        self.radius = float(scene.lights.radius)
        self.surface = 0  # pixels some sample of which hits the surface
        self.reaching = 0  # of those, pixel centres whose reflected ray meets the light plane (f finite)
        self.in_bank = 0  # of those, f within the bank
        self.lines: set[int] = set()
        self.towards_tubes = 0  # pixel centres that see a tube within its radius, blocked or not
        self.blocked = 0  # of those, the reflected ray blocked by the part

    def add(self, pixels: np.ndarray, blocked: np.ndarray | None = None) -> None:
        """Count a span of pixels, (N, len(CHANNELS)) in channel order; ``blocked``: `Tile.blocked` (None: none)."""
        seen = pixels[:, _A] > 0
        f = pixels[seen, _F].astype(np.float64)
        finite = np.isfinite(f)
        self.surface += int(seen.sum())
        self.reaching += int(finite.sum())
        self.in_bank += int(np.count_nonzero((f[finite] >= self.bank[0]) & (f[finite] <= self.bank[1])))
        drawn = (pixels[:, _DIST] <= self.radius) & (pixels[:, _ID] >= 0)
        self.towards_tubes += int(np.count_nonzero(drawn))
        if blocked is not None:
            self.blocked += int(np.count_nonzero(drawn & blocked))
            drawn &= ~blocked
        self.lines.update(np.unique(pixels[drawn, _ID]).astype(int).tolist())

    def warnings(self) -> list[str]:
        """The one-line warnings (without the ``rtreflect: warning: SCENE:`` prefix) for what the counts show."""
        if self.surface == 0:
            return ["the camera sees no surface: the image is empty (check [camera], or remove it to frame the part "
                    "automatically)"]
        if self.scene.render.mode != "reflection":
            # f, line.id and line.dist are the reflected ray's in every mode: they say nothing of another mode's lines
            # (a highlight render with twelve lines on the part warned "0 distinct reflected lines visible").
            return []
        if self.reaching == 0:
            return ["no reflected ray reaches the light plane (it lies behind the surface as the camera sees it): "
                    "no line can show (move [lights] to the camera's side, or remove it for the automatic rig)"]
        if self.towards_tubes >= MIN_BLOCKED_SHARE * self.surface and self.blocked == self.towards_tubes:
            return [f"the part blocks every reflected ray that reaches a tube ({self.blocked} pixels): no line shows "
                    f"(is the eye inside the part? check [camera], or remove it to frame the part automatically)"]
        found = []
        if self.scene.lights.shape == "circles":  # the two counts below are of the tube bank (f, line.id)
            return found
        if len(self.lines) < MIN_LINES:
            found.append(f"{len(self.lines)} distinct reflected line{'' if len(self.lines) == 1 else 's'} visible: "
                         f"too few to read the surface (widen lights.spacing or add tubes, or use [lights] auto = true)")
        past = (self.reaching - self.in_bank) / self.surface
        if past > PAST_BANK_SHARE:
            found.append(f"{100 * past:.0f} % of the visible surface reflects past the tube bank (f outside "
                         f"[{self.bank[0]:.4g}, {self.bank[1]:.4g}]): widen it, or use [lights] auto = true")
        return found
