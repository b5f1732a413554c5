"""Tile sizes from a memory budget: big images in bounded memory.

A render streams its image tile by tile (`Renderer.stream` → `ImageWriter`), so its
working memory is the tiles in flight plus one partial row, not the image. A tile's
memory grows with its rays, and a ray's with the number of tubes K (the (N, K) arrays
of skew-line distances, eq. 4) and the surface degree (basis functions). The cost per
ray below was measured with tracemalloc on the shipped scenes (about 1.3 kB plus 43 B
per tube for bicubic patches) and rounded up; it is an estimate, not a hard limit.
"""

from __future__ import annotations

import os
import re

from .camera import rays_per_pixel
from .errors import RtreflectError
from .film import CHANNELS
from .render import RAYS_PER_TILE
from .scene import Scene

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


def bytes_per_ray(scene: Scene) -> int:
    """Estimated peak working memory of one ray through shading: fixed arrays, per-tube distances, basis functions."""
    tubes = len(scene.lights.positions)
    basis = max((s.degree_u + 1) * (s.degree_v + 1) for s in scene.surfaces)
    return 1024 + 48 * tubes + 16 * basis


def rays_per_tile(scene: Scene, max_memory: int, tiles_in_flight: int) -> int:
    """Rays per tile so that ``tiles_in_flight`` tiles and the output rows fit in ``max_memory`` bytes.

    At most `RAYS_PER_TILE` (larger tiles buy no speed) and at least one pixel's rays;
    a budget that cannot hold even one pixel per tile is an `RtreflectError`, raised
    before anything is built or allocated.
    """
    per_pixel = rays_per_pixel(scene.image.samples)
    per_ray = bytes_per_ray(scene)
    pixel_bytes = len(CHANNELS) * 4
    # The writer holds a partial row; OpenImageIO's EXR writer holds scanline buffers (`WRITER_ROWS`).
    rows = (2 + WRITER_ROWS) * scene.image.width * pixel_bytes
    usable = (max_memory - rows) // max(1, tiles_in_flight)
    rays = usable // (per_ray + pixel_bytes // per_pixel + 1)
    if rays < per_pixel:
        need = rows + tiles_in_flight * per_pixel * (per_ray + pixel_bytes)
        raise RtreflectError(
            f"{scene.path}: image: needs about {format_size(need)} of working memory even with one-pixel tiles "
            f"({per_pixel} rays/pixel, {len(scene.lights.positions)} tubes, {scene.image.width} px rows, "
            f"{tiles_in_flight} tiles in flight); the memory budget is {format_size(max_memory)} (--max-memory)")
    return int(min(rays, RAYS_PER_TILE))
