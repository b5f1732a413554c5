"""One scene straight to its image files, tile by tile: the path shared by `rtreflect render` and `batch`.

Tiles of pixels are rendered (`Renderer.stream`) and handed in image order to the
`ImageWriter`, which writes finished scanlines to the EXR and PNG under temporary
names; the files are renamed into place only when the last tile is written. Peak
memory is set by the tile size (`tiling.rays_per_tile`), not by the image size, and
the bytes equal those of an in-memory render saved with `save_render`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .imagefiles import PngFilter, open_outputs, output_paths
from ..analysis.overlay import overlay_outputs
from ..integrator.autorig import resolve
from ..integrator.checks import ImageTally
from ..integrator.renderer import Renderer, RenderStats, default_threads
from ..exchange.scene import Scene
from ..modes.legend import LEGEND_MODES, legend_file_name, legend_svg
from ..integrator.tiling import default_max_memory, rays_per_tile


@dataclass
class SceneOutput:
    files: list[Path]
    stats: RenderStats
    scene: Scene  # as rendered: automatic camera and tubes chosen (`autorig.resolve`)
    warnings: list[str]  # what `checks.ImageTally` found wrong with the picture (empty, renders, ...)


def render_to_files(scene: Scene, outdir: Path, *, threads: int | None = None, max_memory: int | None = None,
                    progress: Callable[[int], None] | None = None, remove_dead: bool = True,
                    seams=None) -> SceneOutput:
    """Render ``scene`` into ``outdir/NAME.exr|.png`` within ``max_memory`` bytes of working memory.

    ``progress(pixels)`` is called as tiles are written. Raises `RtreflectError` (before
    building anything) when even one-pixel tiles would not fit the budget, and on
    write errors; on any error or interrupt no output file is left half-written.
    ``remove_dead``: as in `imagefiles.prepare_output_folder`. ``seams``: a continuity result
    (`analysis.seamcheck.check_scene`) whose seams are drawn into the PNG after the overlay
    (`render --seams`; the EXR is unchanged).
    """
    threads = threads or default_threads()
    scene = resolve(scene)
    tile_rays = rays_per_tile(scene, max_memory or default_max_memory(), threads)
    renderer = Renderer(scene)
    png_filter, extra_files = overlay_for(scene, renderer)
    if seams is not None and scene.output.png:
        from ..analysis.seampicture import seam_filter

        png_filter = then(png_filter, seam_filter(renderer, seams))
    tally = ImageTally(scene)

    def sink(tile) -> None:
        writer.write(tile.start, tile.pixels)
        tally.add(tile.pixels, tile.blocked)

    with open_outputs(scene, outdir, png_filter, extra_files, remove_dead=remove_dead) as writer:
        stats = renderer.run(sink, threads, tile_rays, progress)
    return SceneOutput(output_paths(scene, outdir, extra_files), stats, scene, tally.warnings())


def overlay_for(scene: Scene, renderer: Renderer | None = None) -> tuple[PngFilter | None, dict[str, str] | None]:
    """The PNG filter and extra files of a scene: the contours JSON with `[render] overlay`, the legend
    (``NAME.legend.svg``) of a map mode (curvature, draft); (None, None) with neither."""
    legend = None
    if scene.render.mode in LEGEND_MODES:
        renderer = renderer or Renderer(scene)
        legend = {legend_file_name(scene): legend_svg(renderer.mode)}
    if not scene.render.overlay:
        return None, legend
    draw, files = overlay_outputs(renderer or Renderer(scene))
    return draw, {**files, **(legend or {})}


def then(first: PngFilter | None, second: PngFilter) -> PngFilter:
    """``second`` applied to the rows ``first`` (if any) has drawn."""
    if first is None:
        return second
    return lambda row0, rows: second(row0, first(row0, rows))
