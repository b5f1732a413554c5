"""Analytic anti-aliasing of the stripes: one exact sample per pixel, its box coverage in closed form (issue 14).

A stripe is |σ| ≤ w about a level, σ the signed offset from the level's centre (`modes.base.level_offset`:
the signed skew-line distance of eq. 4 to a tube's axis, or φ − c_k) and w its half width (the tube
radius, or the mode's half width). Over a box pixel σ is taken linear, σ + g·(x, y) with (x, y) uniform on
[−½, ½]² and g = (∂σ/∂x, ∂σ/∂y) per pixel, so Z = g·(x, y) is the sum of two uniform variables of widths
a = |g_x| and b = |g_y|: a trapezoid density, whose CDF F is piecewise quadratic (`trapezoid_cdf`). The hard
stripe covers F(w − σ) − F(−w − σ) of the pixel: a stripe thinner than the pixel, or its two edges in one
pixel, included. With ``[render] blur`` the profile `modes.profile.stripe_weight` w(|σ + Z|) is averaged
over Z: integrating by parts, that mean is the hard coverage at half width v averaged over the profile's
fall −dw/dv, taken here over `BLUR_CELLS` cells of the ramp each weighted by the fall of `stripe_weight`
itself across it (`stripe_coverage`), so the profile keeps its one implementation.

g comes from ray differentials (Igehy, "Tracing ray differentials", SIGGRAPH 1999): the camera ray one
pixel over meets the tangent plane at the exact hit, which gives dP/dx and dP/dy; least squares on
[S_u S_v] turns them into the footprint (du, dv)/dx and /dy (`uv_footprint`). σ is then evaluated by the
renderer's own pipeline (exact surface point and normal, eye ray, reflection, the mode's offset) at
(u, v) ± ½ (du, dv)/dx and /dy: a central difference over the pixel, no second copy of any formula.

Pixels that this linear model does not describe are not stripe edges and are supersampled
(`edge_pixels`): where one of the 8 neighbours disagrees on hit or miss, on the level (near a stripe), on the
occlusion of the reflected ray (near a stripe) or on the face, where a stripe may be within the neighbours' reach
or the two hits do not continue one sheet (an occlusion edge, a crease: `JOIN_SINE`) or the shading steps
(`JOIN_COLOUR_STEP`); and where the footprint
spans about a level spacing or more, or σ bends within it (a neighbour's σ strays from the pixel's plane).
"""

from __future__ import annotations

import numpy as np

from ..geometry.surfaces import parameter_steps
from ..kernels.pixels import edge_flags
from ..kernels.pixels import hard_coverage as _hard_coverage, trapezoid_cdf as _trapezoid_cdf
from ..modes.profile import stripe_weight

#: Cells of the blur ramp [r(1 − b), r(1 + b)] over which the soft profile's coverage is summed: the midpoint
#: rule's error falls as 1/cells² and is below 1e-3 of the line colour at 16 for any footprint.
BLUR_CELLS = 16
#: Width below which a footprint axis counts as zero, relative to the half width: keeps F's divisions finite.
FLAT = 1e-9
#: Largest footprint |g_x| + |g_y| trusted, as a share of the spacing between neighbouring levels (in σ):
#: beyond it the pixel may see two stripes, or σ bends within it; it is supersampled instead.
TRUSTED_SPAN = 0.5
#: Largest departure of a neighbour's σ (one pixel away, same level) from the plane σ + g·(Δx, Δy), in half
#: widths, for the pixel's linear model to be trusted: within the pixel itself the bend is a quarter of it (σ's
#: second-order term), so a stripe edge moves by at most w/8 there.
BENDING = 0.5
#: Two neighbouring pixels' hits on different faces continue one sheet where each lies within this sine (~6°) of
#: the other's tangent plane, seen from it: a smooth sheet bends away from its tangent plane by ½κ|ΔP|², so pixels
#: less than 0.2 of a radius of curvature apart pass; across an occlusion edge the farther hit lies off the
#: nearer's plane by the depth step times |N·D|. Where faces join with no stripe near, such pixels are not edges.
JOIN_SINE = 0.1
#: ... and where their surface colours (the shade k times ``surface_color``) differ by at most this (linear RGB, the
#: brightest channel): a crease shows as a step in the shading where no stripe is near, and is supersampled.
JOIN_COLOUR_STEP = 0.01
#: Sub-pixel samples per axis (s×s) of the pixels that are supersampled (edges): as the old default.
EDGE_SAMPLES = 4
#: The 8 neighbours of a pixel as (row, column) steps.
NEIGHBOURS = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc)


def trapezoid_cdf(z: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """P(X + Y ≤ z) for independent X ~ U[−a/2, a/2], Y ~ U[−b/2, b/2] (a, b ≥ 0): the trapezoid's CDF.

    With a ≥ b and t = z + (a + b)/2: t²/(2ab) up to b, (t − b/2)/a up to a, 1 − (a + b − t)²/(2ab) up to a + b
    (compiled: `kernels.pixels.trapezoid_cdf`).

    >>> trapezoid_cdf(np.array([-1.0, 0.0, 0.25, 1.0]), np.array([1.0] * 4), np.array([0.5] * 4)).tolist()
    [0.0, 0.5, 0.75, 1.0]
    """
    return _elementwise(_trapezoid_cdf, z, a, b)


def hard_coverage(sigma: np.ndarray, a: np.ndarray, b: np.ndarray, half_width: float) -> np.ndarray:
    """Share of the box pixel where |σ + Z| ≤ w (module doc): F(w − σ) − F(−w − σ)."""
    return _elementwise(lambda x, y, z, out: _hard_coverage(x, y, z, float(half_width), out), sigma, a, b)


def _elementwise(kernel, *arrays) -> np.ndarray:
    """``kernel(*arrays, out)`` over the arrays broadcast, as 1-D float64 (the compiled forms, `kernels.pixels`)."""
    arrays = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in arrays))
    out = np.empty(arrays[0].shape)
    kernel(*(np.ascontiguousarray(x).ravel() for x in arrays), out.reshape(-1))
    return out


def stripe_coverage(sigma: np.ndarray, gx: np.ndarray, gy: np.ndarray, half_width: float, blur: float) -> np.ndarray:
    """Mean stripe weight over a box pixel of σ + g·(x, y) (module doc): the line colour's share of the pixel.

    ``blur`` = 0: the hard stripe's covered share. Otherwise Σ_i [w(v_i⁻) − w(v_i⁺)] · coverage at half width
    v_i over `BLUR_CELLS` cells [v_i⁻, v_i⁺] of the profile's ramp, w = `stripe_weight` (module doc).

    >>> stripe_coverage(np.array([0.0, 0.1, 0.15]), np.array([0.1] * 3), np.zeros(3), 0.1, 0.0).round(6).tolist()
    [1.0, 0.5, 0.0]
    """
    floor = FLAT * half_width
    a = np.maximum(np.abs(gx), floor)
    b = np.maximum(np.abs(gy), floor)
    if blur == 0:
        return hard_coverage(sigma, a, b, half_width)
    edges = np.linspace(half_width * (1.0 - blur), half_width * (1.0 + blur), BLUR_CELLS + 1)
    mass = -np.diff(stripe_weight(edges, half_width, blur))  # sums to 1: the weight falls from 1 to 0 on the ramp
    total = np.zeros(np.shape(sigma))
    for v, m in zip(0.5 * (edges[1:] + edges[:-1]), mass):
        total = total + m * hard_coverage(sigma, a, b, v)
    return total


def uv_footprint(camera, rows: np.ndarray, cols: np.ndarray, P: np.ndarray, N: np.ndarray, Su: np.ndarray,
                 Sv: np.ndarray) -> np.ndarray:
    """(N, 2, 2) parameter steps [[du/dx, dv/dx], [du/dy, dv/dy]] of one pixel (x a column, y a row) at hits P.

    The camera's rays through the next pixel's centre, right and down (`Camera.rays`), meet the tangent
    plane of the hit (P, N) at P + dP/dx and P + dP/dy (Igehy's transfer); (du, dv) solve
    [S_u S_v] (du, dv) = dP in least squares (`geometry.surfaces.parameter_steps`).
    """
    steps = np.empty((len(P), 2, 2))
    for axis, offset in enumerate(((0.5, 1.5), (1.5, 0.5))):  # (dy, dx): one column right, one row down
        origins, directions = camera.rays(rows, cols, np.asarray(offset))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", P - origins, N) / np.einsum("ij,ij->i", directions, N)
            dP = origins + t[:, None] * directions - P
        steps[:, axis, 0], steps[:, axis, 1] = parameter_steps(Su, Sv, dP)
    return steps


def neighbours(grid: np.ndarray):
    """The 8 neighbours of every pixel of a (rows, columns, ...) grid, as 8 shifted grids (`NEIGHBOURS` order).

    Beyond the grid's border a pixel's own row or column is repeated, so there a neighbour is one the
    pixel already has (or itself): the image border is no edge.
    """
    rows, cols = grid.shape[:2]
    padded = np.pad(grid, [(1, 1), (1, 1)] + [(0, 0)] * (grid.ndim - 2), mode="edge")
    for dr, dc in NEIGHBOURS:
        yield padded[1 + dr:1 + dr + rows, 1 + dc:1 + dc + cols]


def edge_pixels(hit: np.ndarray, patch: np.ndarray, level: np.ndarray, near: np.ndarray, blocked: np.ndarray,
                untrusted: np.ndarray, candidate: np.ndarray, P: np.ndarray, N: np.ndarray, shade: np.ndarray,
                brightest: float) -> np.ndarray:
    """Pixels the linear stripe model does not describe (module doc): True where any of the 8 neighbours differs.

    (rows, columns) grids of the centre rays: ``near``, the footprint reaches a stripe; ``blocked``, the
    reflected ray is occluded before the stripe (False where not tested); ``untrusted``, near a stripe but
    the footprint is too wide or the gradient unknown; ``candidate``, the neighbours' σ do not bound the pixel away
    from a stripe; ``P``, ``N`` (rows, columns, 3), the hit points and unit normals; ``shade``, the surface colour's
    factor k (1 where flat), and ``brightest``, the surface colour's brightest channel. A neighbour on another face
    counts only where either is a stripe candidate, or where the two hits do not continue one sheet (`JOIN_SINE`)
    or their colours differ by more than `JOIN_COLOUR_STEP`: where faces join with no stripe within reach, the
    pixel is the surface's colour on both.
    """
    edge = np.empty(hit.shape, dtype=bool)
    shade_step = JOIN_COLOUR_STEP / brightest if brightest > 0 else np.inf
    # one compiled pass, the neighbours as `neighbours`
    edge_flags(hit, patch, level, near, blocked, untrusted, candidate, P, N, shade, JOIN_SINE, float(shade_step), edge)
    return edge
