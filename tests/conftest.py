"""Shared test set-up."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _no_scene_geometry_kept():
    """Each test builds its scenes' geometry itself: none kept from another test (`integrator.scenegeometry`), which a
    test changing how geometry is built (a monkeypatched constant) would otherwise find built the old way."""
    yield
    from rtreflect.integrator import scenegeometry

    scenegeometry.forget()
