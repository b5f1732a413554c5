"""Camera: pixel (and sub-pixel sample) rays, exactly as DESIGN.md's camera contract.

forward w = normalize(look_at − eye), right r = normalize(w × up), image up q = r × w.
For pixel (row i, column j) of a W×H image, x = 2(j + ½)/W − 1 and y = 1 − 2(i + ½)/H;
sample offsets replace the ½ with the centres of an s×s grid inside the pixel. The rays are formed by one
compiled pass (`kernels.pixels.pixel_rays`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..exchange.scene import ANALYTIC, CameraSpec
from ..kernels.pixels import pixel_rays

#: The pixel centre's offset (dy = dx = ½), for `Camera.rays`.
_CENTRE = np.array([0.5])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def rays_per_pixel(samples: int | str) -> int:
    """Rays traced per pixel: s² samples, plus the pixel-centre ray for the AOVs when s is even (no sample is central).

    ``"analytic"`` (`integrator.analytic`): the centre ray, the edge pixels' few samples not counted (their
    share of the image is small, and they are traced in chunks of their own).
    """
    if samples == ANALYTIC:
        return 1
    return samples * samples + (1 if samples % 2 == 0 else 0)


def sample_offsets(samples: int) -> np.ndarray:
    """(s², 2) offsets (dy, dx) in [0, 1): centres of an s×s grid, row-major. Fixed, so renders are deterministic."""
    centres = (np.arange(samples) + 0.5) / samples
    dy, dx = np.meshgrid(centres, centres, indexing="ij")
    return np.stack([dy.ravel(), dx.ravel()], axis=1)


@dataclass(frozen=True)
class Camera:
    spec: CameraSpec
    width: int
    height: int

    @property
    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(w, r, q): forward, right, image up."""
        w = _unit(self.spec.look_at - self.spec.eye)
        r = _unit(np.cross(w, self.spec.up))
        return w, r, np.cross(r, w)

    @property
    def orthographic(self) -> bool:
        return self.spec.projection == "orthographic"

    def _half_extents(self) -> tuple[float, float]:
        """Half the image plane's width and height at unit distance (perspective) or in model units (orthographic)."""
        aspect = self.width / self.height
        half_h = self.spec.view_height / 2 if self.orthographic else math.tan(math.radians(self.spec.fov) / 2)
        return half_h * aspect, half_h

    def pixel_footprint(self, depth: np.ndarray) -> np.ndarray:
        """Height in model units of one pixel at distance ``depth`` from the eye (perspective), constant if orthographic."""
        half_h = self._half_extents()[1]
        if self.orthographic:
            return np.full_like(np.asarray(depth, dtype=np.float64), 2.0 * half_h / self.height)
        return np.asarray(depth, dtype=np.float64) * 2.0 * half_h / self.height

    def rays(self, rows: np.ndarray, cols: np.ndarray, offsets: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Origins and unit directions (N, 3) for pixels (rows, cols) at sub-pixel offsets (dy, dx).

        ``offsets`` defaults to the pixel centre (½, ½); it may be (N, 2) or broadcastable.
        """
        if offsets is None:
            oy = ox = _CENTRE
        else:
            offsets = np.asarray(offsets, dtype=np.float64)
            oy, ox = offsets[..., 0], offsets[..., 1]
        if np.size(oy) == 1:  # one offset for every ray: no (N,) copies of it
            rows, cols = np.broadcast_arrays(np.asarray(rows, dtype=np.float64), np.asarray(cols, dtype=np.float64))
            oy, ox = np.ravel(oy), np.ravel(ox)
        else:
            rows, cols, oy, ox = np.broadcast_arrays(np.asarray(rows, dtype=np.float64),
                                                     np.asarray(cols, dtype=np.float64), oy, ox)
        return self._pixel_rays(rows, cols, oy, ox, 1)

    def sample_rays(self, rows: np.ndarray, cols: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`rays` of every pixel (rows, cols) at each of the (s², 2) ``offsets`` in turn (pixel-major): the same as
        ``rays(np.repeat(rows, s²), np.repeat(cols, s²), np.tile(offsets, (len(rows), 1)))``, without those copies."""
        offsets = np.asarray(offsets, dtype=np.float64)
        return self._pixel_rays(np.asarray(rows, dtype=np.float64), np.asarray(cols, dtype=np.float64),
                                offsets[:, 0], offsets[:, 1], len(offsets))

    def _pixel_rays(self, rows, cols, oy, ox, repeat: int) -> tuple[np.ndarray, np.ndarray]:
        """The compiled camera contract (`kernels.pixels.pixel_rays`) over 1-D float64 rows, cols and offsets."""
        rows, cols, oy, ox = (np.ascontiguousarray(np.ravel(a)) for a in (rows, cols, oy, ox))
        w, r, q = self.basis
        half_w, half_h = self._half_extents()
        n = len(rows) * repeat if len(oy) else 0
        origins, directions = np.empty((n, 3)), np.empty((n, 3))
        if n:
            pixel_rays(rows, cols, oy, ox, repeat, np.asarray(self.spec.eye, dtype=np.float64), w, r, q, float(half_w),
                       float(half_h), float(self.width), float(self.height), self.orthographic, origins, directions)
        return origins, directions

    def eye_vectors(self, points: np.ndarray) -> np.ndarray:
        """a: unit vectors (N, 3) from 3D points towards the eye A (paper eq. 3), the reversed direction of the camera
        ray through each point; −w for an orthographic camera."""
        if self.orthographic:
            return np.broadcast_to(-self.basis[0], np.shape(points)).copy()
        a = self.spec.eye - np.asarray(points, dtype=np.float64)
        return a / np.linalg.norm(a, axis=1, keepdims=True)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Image coordinates (column, row) in pixels of 3D points — the inverse of `rays` at the centre convention.

        Pixel centres sit at half-integers: pixel (i, j)'s centre projects to (j + ½, i + ½).
        """
        w, r, q = self.basis
        half_w, half_h = self._half_extents()
        rel = np.asarray(points, dtype=np.float64) - self.spec.eye
        depth = rel @ w
        if self.orthographic:
            x = (rel @ r) / half_w
            y = (rel @ q) / half_h
        else:
            x = (rel @ r) / (depth * half_w)
            y = (rel @ q) / (depth * half_h)
        col = (x + 1.0) * self.width / 2.0
        row = (1.0 - y) * self.height / 2.0
        return np.stack([col, row], axis=-1)
