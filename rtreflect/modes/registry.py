"""The interrogation modes by their ``[render] mode`` name (`base.Mode`), and the one that renders a scene."""

from __future__ import annotations

from typing import Callable

from .base import Mode
from .lights import TubeLights
from .reflection import reflection_mode

#: ``[render] mode`` name → builder of the mode from (scene, tubes). exchange/scene.py's `RENDER_MODES`
#: lists the same names (the scene reader sits upstream of the modes); tests check the two agree.
MODES: dict[str, Callable[..., Mode]] = {
    "reflection": reflection_mode,
}


def mode_of(scene, lights: TubeLights) -> Mode:
    """The mode ``scene.render.mode`` names, built for the scene's tubes."""
    return MODES[getattr(scene.render, "mode", "reflection")](scene, lights)
