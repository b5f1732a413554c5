"""The interrogation modes by their ``[render] mode`` name (`base.Mode`), and the one that renders a scene."""

from __future__ import annotations

from typing import Callable

from .base import Mode, checked
from .lights import TubeLights
from .curvaturemap import curvature_mode
from .draft import draft_mode
from .highlight import highlight_mode
from .isophote import isophote_mode
from .reflection import reflection_mode
from .zebra import zebra_mode

#: ``[render] mode`` name → builder of the mode from (scene, tubes, surfaces). exchange/scene.py's `RENDER_MODES`
#: lists the same names (the scene reader sits upstream of the modes); tests check the two agree.
MODES: dict[str, Callable[..., Mode]] = {
    "reflection": reflection_mode,
    "highlight": highlight_mode,
    "isophote": isophote_mode,
    "draft": draft_mode,
    "curvature": curvature_mode,
    "zebra": zebra_mode,
}


def mode_of(scene, lights: TubeLights, surfaces) -> Mode:
    """The mode ``scene.render.mode`` names, built for the scene's tubes and patches (a `SurfaceSet`), `checked`."""
    return checked(MODES[scene.render.mode](scene, lights, surfaces))
