"""Tile sizes from a memory budget: big images in bounded memory.

A render streams its image tile by tile (`Renderer.stream` → `ImageWriter`), so its
working memory is the tiles in flight, the pixels of the finished ones waiting their turn
(`renderer.TILES_AHEAD`) and one partial row, not the image. A tile's
memory grows with its rays (about 1 kB each, more for higher surface degrees) plus the
skew-line distances of eq. (4): rays × tubes pairs of about 48 B, computed in chunks of
at most `TUBE_ENTRIES_PER_CHUNK` pairs, so that part stops growing at about 50 MB.
The costs were measured with tracemalloc on the shipped scenes and rounded up; they are
an estimate, not a hard limit.
"""

from __future__ import annotations

import os
import re

from ..trace.camera import rays_per_pixel
from ..errors import RtreflectError
from .film import CHANNELS
from ..modes.lights import TUBE_ENTRIES_PER_CHUNK
from .renderer import RAYS_PER_TILE, TILES_AHEAD, WINDOW_TILE_PIXELS
from ..exchange.scene import ANALYTIC, Scene

#: Default budget: this fraction of the machine's physical memory.
DEFAULT_FRACTION = 0.25
#: Fallback when the physical memory cannot be read.
FALLBACK_BYTES = 2 << 30

#: Full-width float32 scanlines the EXR writer keeps: measured ~8 zip chunks of 16 rows (compressed in
#: parallel), independent of the image height (67 MB for 7680 px wide rows of 17 channels).
WRITER_ROWS = 128

_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_size(text: str) -> int:
    """Bytes from a size such as ``512M``, ``2G``, ``1.5GB`` or ``1000000`` (binary units); ValueError if malformed."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([KMGT]?)(?:i?B)?\s*", text, flags=re.IGNORECASE)
    if not match:
        raise ValueError(f"not a size like 512M or 2G: {text!r}")
    value = float(match.group(1)) * _UNITS[match.group(2).upper()]
    if value < 1:
        raise ValueError(f"must be at least one byte: {text!r}")
    return int(value)


def format_size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError


def default_max_memory() -> int:
    """A quarter of the machine's physical memory (2 GiB when it cannot be read)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") * DEFAULT_FRACTION)
    except (ValueError, OSError, AttributeError):
        return FALLBACK_BYTES


#: Bytes per point × tube pair of eq. (4)'s temporaries (distances, ray parameters, flags).
BYTES_PER_TUBE_ENTRY = 48


def bytes_per_ray(scene: Scene) -> int:
    """Estimated peak working memory of one ray through shading, apart from eq. (4)'s tube pairs."""
    basis = max((s.degree_u + 1) * (s.degree_v + 1) for s in scene.surfaces)
    return 1024 + 16 * basis


def tile_bytes(scene: Scene, rays: int) -> int:
    """Estimated working memory of a tile of ``rays`` rays: the rays, and their tube pairs up to one chunk."""
    tube_pairs = min(rays * len(scene.lights.positions), TUBE_ENTRIES_PER_CHUNK)
    return rays * bytes_per_ray(scene) + BYTES_PER_TUBE_ENTRY * tube_pairs


def rays_per_tile(scene: Scene, max_memory: int, tiles_in_flight: int) -> int:
    """Rays per tile so that ``tiles_in_flight`` tiles, the pixels of as many more finished and waiting to be taken
    (`renderer.TILES_AHEAD` per tile in flight) and the output rows fit in ``max_memory`` bytes.

    At most `RAYS_PER_TILE` (larger tiles buy no speed) and at least one pixel's rays;
    a budget that cannot hold even one pixel per tile is an `RtreflectError`, raised
    before anything is built or allocated.
    """
    per_pixel = rays_per_pixel(scene.image.samples)
    pixel_bytes = len(CHANNELS) * 4
    # The writer holds a partial row; OpenImageIO's EXR writer holds scanline buffers (`WRITER_ROWS`).
    rows = (2 + WRITER_ROWS) * scene.image.width * pixel_bytes
    usable = (max_memory - rows) // max(1, tiles_in_flight)
    # An analytic render's span of the pixel window holds up to WINDOW_TILE_PIXELS pixels per ray (`pixel_spans`).
    pixels_per_ray = WINDOW_TILE_PIXELS if scene.image.samples == ANALYTIC else 1
    per_ray = bytes_per_ray(scene) + (1 + TILES_AHEAD) * pixels_per_ray * pixel_bytes // per_pixel + 1
    tubes = max(1, len(scene.lights.positions))
    # tile_bytes is linear in the rays up to a full chunk of tube pairs, then grows by per_ray only.
    below_chunk = min(max(0, usable) // (per_ray + BYTES_PER_TUBE_ENTRY * tubes), TUBE_ENTRIES_PER_CHUNK // tubes)
    beyond_chunk = (usable - BYTES_PER_TUBE_ENTRY * TUBE_ENTRIES_PER_CHUNK) // per_ray
    rays = max(below_chunk, beyond_chunk)
    if rays < per_pixel:
        need = rows + tiles_in_flight * (tile_bytes(scene, per_pixel) + (1 + TILES_AHEAD) * per_pixel * pixel_bytes)
        raise RtreflectError(
            f"{scene.path}: image: needs about {format_size(need)} of working memory even with one-pixel tiles "
            f"({per_pixel} rays/pixel, {len(scene.lights.positions)} tubes, {scene.image.width} px rows, "
            f"{tiles_in_flight} tiles in flight); the memory budget is {format_size(max_memory)} (--max-memory)")
    return int(min(rays, RAYS_PER_TILE))
