"""Ray culling: camera rays that cannot meet any mesh the tracer asks need not be traced.

Every Embree query costs about as much per ray whether it hits or not (embreex builds each ray in
turn), and a camera ray is asked of the coarse mesh and of the second look's shell
(`trace.secondlook`) even where it misses both: with the surface in a fifth of the image, most of
the tracing went to rays that hit nothing. A ray misses every triangle when it misses a box
holding all of them; the slab test (Kay and Kajiya, "Ray tracing complex scenes", SIGGRAPH 1986)
decides that in one compiled pass (`kernels.pixels.box_keep`), and the renderer gives such rays the miss values of
`tracing.Hits.blank` (what the tracer itself leaves there: the same bits).
Where the box keeps most of a batch (`renderer.TRACE_ALL`), the renderer traces the whole batch instead: the
culled rays then miss at Embree's root, with the same values, and nothing has to be spread back. (A batch of
camera rays whose pixels lie that much inside the box's picture, `RayBox.pixel_window`, is traced whole without
asking the box ray by ray: `Renderer.supersample`.)

The box is the meshes' bounding box grown by `BOX_MARGIN` of its diagonal, plus `ORIGIN_MARGIN` of the
ray origins' distance to it, so Embree's float32 rounding (of the vertices and of the moved origins,
`Accelerator`) cannot put a hit just outside it.

Before any ray is formed, the box's picture bounds which pixels' camera rays it may keep (`RayBox.pixel_window`):
a camera ray meets the box only at a point that projects to its own pixel's centre, and the projection of the box
lies in the rectangle around its 8 corners' projections (perspective maps the convex box, in front of the eye, to
the convex hull of its corners' images). The analytic path forms, traces and shades the rays of that window only;
every pixel outside it is a miss, whose values do not depend on the ray (`Renderer._miss_pixel`). With the peer
scene's surface in a sixth of the image, the rays outside the window (formed, culled, given miss rows, coloured
and written) had cost half of the render.
"""

from __future__ import annotations

import numpy as np

from ..kernels.pixels import box_keep, origin_reach

#: Growth of the box, relative to its diagonal: float32 holds a vertex to ~6e-8 of the part's size,
#: so 1e-3 is four orders of margin.
BOX_MARGIN = 1e-3
#: Growth of the box per unit of the farthest origin's distance from its centre: a float32 direction is
#: off by ~6e-8 radians, a sideways error of that times the distance travelled; 1e-5 is two orders over it.
ORIGIN_MARGIN = 1e-5
#: Pixels added around the box's projected rectangle (`pixel_window`): one for a pixel whose centre is within
#: half a pixel of it, one for the analytic path's neighbour ring around the hits (`Renderer._render_analytic`),
#: one against rounding.
WINDOW_PAD = 3
#: Stands in for a zero direction component (whose slab is then all or nothing, without 0·∞ = NaN).
TINY = 1e-300


class RayBox:
    """The bounding box of a scene's meshes (``vertices``: (V, 3) arrays) for `may_hit`."""

    def __init__(self, *vertices: np.ndarray):
        points = [v for v in vertices if len(v)]
        if points:
            stacked = np.concatenate([np.asarray(v, dtype=np.float64).reshape(-1, 3) for v in points])
            self.low, self.high = stacked.min(axis=0), stacked.max(axis=0)
        else:  # nothing to hit: no box, nothing culled (the tracer answers as it always did)
            self.low = self.high = None

    def may_hit(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Indices of the rays (origins, directions: (N, 3)) that meet the grown box ahead of their origin."""
        n = len(origins)
        if self.low is None or n == 0:
            return np.arange(n)
        return np.flatnonzero(self.keep(origins, directions))

    def keep(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) True where `may_hit` keeps the ray: the slab test in one compiled pass (`kernels.pixels.box_keep`)."""
        n = len(origins)
        if self.low is None or n == 0:
            return np.ones(n, dtype=bool)
        origins = np.ascontiguousarray(origins, dtype=np.float64)
        directions = np.ascontiguousarray(directions, dtype=np.float64)
        centre = 0.5 * (self.low + self.high)
        reach = origin_reach(origins, centre)
        grow = BOX_MARGIN * float(np.linalg.norm(self.high - self.low)) + ORIGIN_MARGIN * reach
        keep = np.empty(n, dtype=bool)
        # NaN (a NaN ray) compares False both ways: such a ray is kept, for the tracer to answer.
        box_keep(origins, directions, self.low - grow, self.high + grow, TINY, keep)
        return keep

    def pixel_window(self, camera) -> tuple[slice, slice]:
        """(rows, columns) of the pixels whose centre rays `keep` may keep, padded by `WINDOW_PAD` (module doc): a
        centre ray outside them misses the box. The whole image where no box bounds them: nothing to cull, a corner
        of the box at or behind a perspective camera's eye plane (its picture is then unbounded), or NaN."""
        width, height = camera.width, camera.height
        everything = (slice(0, height), slice(0, width))
        if self.low is None:
            return everything
        eye = np.asarray(camera.spec.eye, dtype=np.float64)
        centre = 0.5 * (self.low + self.high)
        # `keep`'s growth for the farthest origin any pixel's ray has: the eye, or on an orthographic camera's
        # image plane up to its half diagonal from the eye (the Chebyshev reach is at most the distance).
        half_w, half_h = camera._half_extents()
        reach = float(np.linalg.norm(eye - centre)) + (float(np.hypot(half_w, half_h)) if camera.orthographic else 0.0)
        grow = 2.0 * (BOX_MARGIN * float(np.linalg.norm(self.high - self.low)) + ORIGIN_MARGIN * reach)
        low, high = self.low - grow, self.high + grow
        corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
        if not camera.orthographic and not np.all((corners - eye) @ camera.basis[0] > 0):
            return everything
        picture = camera.project(corners)  # (column, row), pixel centres at half-integers
        if not np.all(np.isfinite(picture)):
            return everything
        (c_low, r_low), (c_high, r_high) = picture.min(axis=0), picture.max(axis=0)
        cols = slice(int(np.clip(np.floor(c_low) - WINDOW_PAD, 0, width)), int(np.clip(np.ceil(c_high) + WINDOW_PAD, 0, width)))
        rows = slice(int(np.clip(np.floor(r_low) - WINDOW_PAD, 0, height)), int(np.clip(np.ceil(r_high) + WINDOW_PAD, 0, height)))
        return rows, cols
