"""Interrogation modes: a scalar field φ on the surface, its levels, and the distance to the nearest level.

Every line-drawing tool of the paper's section 1 is the level sets φ(u, v) = c_k of a scalar
field, shaded by a stripe around each level (DESIGN.md, "Other interrogation modes"). A mode
computes φ from the exact hit (R, unit normal n, reflected direction s of eq. 3, and its
(patch, u, v) for modes that need the surface's derivatives), and per point the nearest level,
the distance to it (in φ's unit, or the skew-line distance of eq. 4 for tubes) and whether the
point lies in its stripe. A mode whose stripes are seen along a physical ray (reflection lines)
also names the ray's reach, which the renderer tests for self-occlusion; the others are lit
where the distance says so. A map mode (curvature, draft) also colours the surface itself.

`registry.MODES` maps each ``[render] mode`` name to the function that builds it for a scene.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from .lights import reflect

#: Share of each level step a stripe covers when φ's levels are evenly spaced (isophotes, zebra,
#: curvature bands): as the automatic rig's tubes, whose radius is a tenth of their spacing.
STRIPE_SHARE = 0.2


@dataclass(frozen=True)
class SurfacePoints:
    """Exact hits handed to a mode: point R, unit normal n (facing the ray), reflected direction s, (patch, u, v)."""

    R: np.ndarray
    n: np.ndarray
    s: np.ndarray
    patch: np.ndarray
    u: np.ndarray
    v: np.ndarray


@dataclass(frozen=True)
class Stripes:
    """Per point: the nearest level, the distance to it, and whether the point lies in its stripe."""

    level_id: np.ndarray  # index of the nearest level (ahead, for tubes); −1 where none is
    level_dist: np.ndarray  # distance to it: skew-line distance d for tubes, |φ − c_k| otherwise; NaN where none is
    candidate: np.ndarray  # bool: within the stripe
    # Ray parameter along s to test for occlusion before a candidate counts as lit (reflection lines:
    # the nearest tube within its radius); None when the mode's stripes are not seen along a ray.
    occlusion_t: np.ndarray | None = None
    # The signed offset σ from the nearest level's centre (`level_offset`), NaN where none is; None where the
    # mode does not find it with its stripes (the analytic path then asks `level_offset`).
    offset: np.ndarray | None = None
    # Along the ray (`Mode.along_ray`): the ray parameter along s of the nearest level (its tube's closest
    # approach, or the light plane): how far the analytic path tests for occlusion near a stripe; else None.
    level_t: np.ndarray | None = None
    # The mode's φ where finding the stripes gave it on the way (reflection lines: Ulmet's f, from the same pass
    # over the reflected rays as the tubes), else None.
    phi: np.ndarray | None = None


def even_stripes(phi: np.ndarray, levels: np.ndarray, half_width: float, lined: np.ndarray | None = None,
                 floor: float = 0.0) -> Stripes:
    """Nearest of sorted ``levels`` to each φ, |φ − c_k|, the stripe test |φ − c_k| ≤ half_width and the signed
    offset σ = φ − c_k (NaN φ: none; nor where ``lined`` is False, a map's region face, nor where φ lies within
    ``floor`` > 0 of its level, a region inside a face: `regions`)."""
    levels = np.asarray(levels, dtype=np.float64)
    found = np.isfinite(phi) if lined is None else np.isfinite(phi) & lined
    if len(levels) == 0:
        return Stripes(np.full(len(phi), -1), np.full(len(phi), np.nan), np.zeros(len(phi), dtype=bool),
                       offset=np.full(len(phi), np.nan))
    right = np.clip(np.searchsorted(levels, np.where(found, phi, 0.0)), 0, len(levels) - 1)
    left = np.clip(right - 1, 0, len(levels) - 1)
    pick = np.where(np.abs(phi - levels[left]) <= np.abs(phi - levels[right]), left, right)
    if floor > 0.0:
        with np.errstate(invalid="ignore"):
            found &= ~(np.abs(phi - levels[pick]) <= floor)
    sigma = np.where(found, phi - levels[pick], np.nan)
    dist = np.abs(sigma)
    return Stripes(np.where(found, pick, -1), dist, found & (dist <= half_width), offset=sigma)


def seen_at(surfaces, camera, patch: np.ndarray, u: np.ndarray, v: np.ndarray):
    """What the camera sees at surface points (patch, u, v): R = S(u, v), the exact unit normal n (not turned),
    a towards the eye (`Camera.eye_vectors`) and the reflected direction s = 2(a·n)n − a (paper eq. 3).

    s does not depend on n's orientation (n → −n leaves it unchanged, bit for bit), so callers may turn n after.
    """
    derivs = surfaces.evaluate(patch, u, v)
    n = surfaces.normals(patch, u, v, derivs)
    a = camera.eye_vectors(derivs.S)
    return derivs.S, n, a, reflect(a, n)


def level_offset(mode, p: SurfacePoints, level: np.ndarray) -> np.ndarray:
    """Signed offset σ of each point from the centre of its level ``level[i]``: the stripe is |σ| ≤ half width.

    A mode whose stripe is measured otherwise than in φ (tubes: the skew-line distance of eq. 4) names it by
    an ``offset(p, level)`` method; for the rest σ = φ − c_k. Unlike `Stripes.level_dist` (|σ|), σ is smooth
    across the level, so its gradient is defined there (`integrator.analytic`).
    """
    own = getattr(mode, "offset", None)
    if own is not None:
        return own(p, level)
    return mode.phi(p) - np.asarray(mode.levels, dtype=np.float64)[level]


def neighbour_levels(levels: np.ndarray) -> np.ndarray:
    """Per level, the index of the nearest level at another position (itself where there is none)."""
    levels = np.asarray(levels, dtype=np.float64)
    gaps = np.abs(levels[:, None] - levels[None, :])
    gaps[gaps == 0.0] = np.inf
    other = np.argmin(gaps, axis=1) if len(levels) else np.zeros(0, dtype=int)
    return np.where(np.isfinite(gaps.min(axis=1, initial=np.inf)), other, np.arange(len(levels)))


class Mode(Protocol):
    """What the renderer, the EXR and the contours need of an interrogation mode (each mode subclasses it)."""

    name: str
    #: Stage name under which the renderer's clock counts the mode's time.
    stage: str
    #: Whether the stripes are seen along the reflected ray s (reflection lines of tubes or circles), so the
    #: surface may occlude them on the way; the others are lit where they are. A mode seen along the ray gives
    #: `Stripes.occlusion_t` and `Stripes.level_t` (how far the sampled and the analytic path test for occlusion),
    #: the others neither: `checked` refuses a mode that breaks this.
    along_ray: ClassVar[bool] = False
    #: φ's period where φ is an angle that wraps (zebra: 360°, cut at ±180°), else None: the contours then find each
    #: level on φ unwrapped about it (`contours._patch_chains`), not across the cut.
    period: ClassVar[float | None] = None

    def phi(self, p: SurfacePoints) -> np.ndarray:
        """φ at the points (NaN where undefined)."""

    def stripes(self, p: SurfacePoints) -> Stripes:
        """The nearest level and the stripe test at each point."""

    def surface_rgb(self, p: SurfacePoints) -> np.ndarray | None:
        """(N, 3) linear RGB of the surface where no stripe is (map modes), or None: `[render] surface_color`."""


def checked(mode: Mode) -> Mode:
    """``mode``, or a TypeError where its stripes break `Mode.along_ray`'s contract (asked of no points).

    The renderer tests occlusion along s up to `Stripes.occlusion_t` (sampled path) and `Stripes.level_t` (analytic
    path, `Renderer.centre_stripes`) exactly where the mode is seen along the ray: a missing one would light stripes
    with no occlusion test or fail deep in a tile, a superfluous one make the two paths disagree.
    """
    none = np.zeros((0, 3))
    stripes = mode.stripes(SurfacePoints(none, none, none, np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)))
    for field in ("occlusion_t", "level_t"):
        if (getattr(stripes, field) is None) == bool(mode.along_ray):
            raise TypeError(f"mode {mode.name!r} (along_ray={bool(mode.along_ray)}): its stripes' {field} is "
                            f"{'missing' if mode.along_ray else 'given'}")
    return mode
