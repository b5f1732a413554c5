"""The public Python API (issue 10): what the command line does, for scripts, notebooks and users' own CI.

    scene = rtreflect.load_scene("scenes/hood.toml")          # or rtreflect.Scene(...) built in code
    result = rtreflect.render(scene, width=960, height=540)    # film in memory: result.rgba, result.aov("f"), result.stats
    rtreflect.save(result, "out/")                             # EXR + PNG as `rtreflect render` writes them
    report = rtreflect.validate(scene)                         # the numbers `rtreflect validate --json` prints

Thin wrappers: scenes are read and checked by `exchange.scene` (the TOML reader's
checks and one-line `SceneError`s), images come from the `Renderer` into its in-memory
`Film`, files from `imagefiles.save_render` (the bytes the streaming `render` writes),
reports from `analysis.validate`. Nothing here imports the command line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from .analysis.validate import DEFAULT_TOLERANCE_PX, SceneReport, validate_scene
from .errors import RtreflectError, SceneError, SceneErrors
from .exchange.load import load_scene
from .exchange.scene import Scene
from .geometry.surfaces import NurbsSurface
from .integrator.autorig import resolve
from .integrator.film import CHANNELS
from .integrator.renderer import Renderer, RenderResult
from .output.imagefiles import save_render
from .output.streaming import overlay_for

__all__ = ["Scene", "load_scene", "render", "save", "validate", "RenderResult", "SceneReport", "NurbsSurface",
           "CHANNELS", "RtreflectError", "SceneError", "SceneErrors"]


def _overridden(scene: Scene, width: int | None, height: int | None, samples: int | None,
                normals: str | None, overlay: bool | str | None = None) -> Scene:
    """The scene (a `Scene`, or the path of a scene file) with the command line's overrides, checked alike."""
    if isinstance(scene, (str, Path)):
        scene = load_scene(scene)
    if not isinstance(scene, Scene):
        raise TypeError(f"expected an rtreflect.Scene (from rtreflect.load_scene or rtreflect.Scene(...)) or the "
                        f"path of a scene file, got {type(scene).__name__}")
    return resolve(scene.with_image(width, height, samples).with_render(overlay, normals))


def render(scene: Scene | str | Path, width: int | None = None, height: int | None = None, samples: int | str | None = None, *,
           normals: str | None = None, overlay: bool | str | None = None, threads: int | None = None,
           progress: Callable[[int], None] | None = None) -> RenderResult:
    """Render ``scene`` (or the scene file at that path) into an in-memory film, as `rtreflect render` would.

    ``width``, ``height``, ``samples`` (``"analytic"``, or s: s×s samples per pixel), ``normals`` and ``overlay``
    override the scene's values (None keeps them; ``overlay="side"`` as ``--overlay=side``). The result has ``rgba`` (H, W, 4 linear
    float32), ``aov(name)`` (an EXR channel such as ``"f"``, or ``"P"``/``"N"`` as (H, W, 3)),
    ``stats`` (rays, seconds, Newton fallbacks) and the ``scene`` rendered. The film holds
    22 float32 channels per pixel (a 1920×1080 film is 182 MB); `rtreflect render` streams
    to files instead.
    """
    scene = _overridden(scene, width, height, samples, normals, overlay)
    return Renderer(scene).render(progress=progress, threads=threads)


def save(result: RenderResult, outdir: str | Path = "out") -> list[Path]:
    """Write ``outdir/NAME.exr`` and ``.png`` (and ``NAME.contours.json`` with the overlay, ``NAME.side.png`` with
    ``overlay="side"``) as `rtreflect render` writes them, byte for byte; all files appear together or none. Returns the paths written."""
    png_filter, extra_files = overlay_for(result.scene)
    return save_render(result, Path(outdir), png_filter, extra_files)


def validate(scene: Scene | str | Path, tolerance: float = DEFAULT_TOLERANCE_PX, width: int | None = None,
             height: int | None = None, samples: int | str | None = None, *, normals: str | None = None,
             threads: int | None = None, progress: Callable[[int], None] | None = None) -> SceneReport:
    """Check the scene's render against Ulmet's analytic reflection lines, as `rtreflect validate` does.

    The report has the figures `rtreflect validate --json` prints for the scene (``max_px``,
    ``p95_px``, ``mean_px``, ``points``, ``misses``, ``colour_mismatches``, ``colour_checked``,
    ``reasons``, ``lines``; ``report.to_json()`` is that JSON) and ``passed``.
    """
    if not tolerance > 0:
        raise ValueError(f"tolerance must be > 0 pixels, got {tolerance!r}")
    scene = _overridden(scene, width, height, samples, normals)
    return validate_scene(scene, tolerance, progress=progress, threads=threads)
