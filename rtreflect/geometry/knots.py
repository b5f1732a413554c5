"""Knot vectors: what makes a full (clamped) knot vector usable for one NURBS direction.

One home for the rules, so every reader (the TOML scene reader today, CAD readers later)
refuses the same knot vectors for the same reasons. A B-spline of degree p with n control
points needs n + p + 1 non-decreasing knots (Piegl & Tiller, *The NURBS Book*, eq. 2.1,
3.2). A knot of multiplicity m inside the domain leaves the spline C^(p−m) there
(P&T section 2.5): m = p is a C0 crease, still one connected surface; m = p + 1 cuts the
basis in two, so the surface falls apart into separate pieces with nothing between them
(OpenNURBS refuses such knot vectors too). At the ends, clamping repeats a knot p + 1 times.
"""

from __future__ import annotations

import numpy as np

#: Narrowest non-empty knot span, relative to the largest knot magnitude (at least 1): below it the
#: basis functions keep fewer than 4 of float64's 16 digits, and their derivatives overflow.
MIN_KNOT_SPAN = 1e-12


def knot_vector_problem(knots: np.ndarray, degree: int, n_ctrl: int) -> str | None:
    """Why ``knots`` cannot serve as the full knot vector of degree ``degree`` over ``n_ctrl`` control points.

    Returns None for a usable vector, else a one-phrase reason for a user (the caller names
    the file and field). Checked: the count (n + p + 1), non-decreasing order, multiplicities
    (at most p + 1 at an end, at most p inside: more splits the surface), a non-empty domain
    [u_p, u_n], and spans resolvable in float64 (`MIN_KNOT_SPAN`).
    """
    knots = np.asarray(knots, dtype=np.float64)
    if knots.size != n_ctrl + degree + 1:
        return f"needs {n_ctrl + degree + 1} knots for degree {degree} and {n_ctrl} control points, got {knots.size}"
    if np.any(np.diff(knots) < 0):
        i = int(np.flatnonzero(np.diff(knots) < 0)[0])
        return f"knots must not decrease (knot {i + 1} = {knots[i + 1]:g} < knot {i} = {knots[i]:g})"
    values, counts = np.unique(knots, return_counts=True)
    # Strictly inside the domain (u_p, u_n) a knot may repeat p times (a C0 crease); p + 1 would split the surface.
    inner = (values > knots[degree]) & (values < knots[n_ctrl])
    over = np.flatnonzero(counts > np.where(inner, degree, degree + 1))
    if len(over):
        k = int(over[0])
        if inner[k]:
            return (f"an inner knot ({values[k]:g}) is repeated {counts[k]} times; at most the degree ({degree}) "
                    f"allowed: more splits the surface into separate pieces")
        return f"an end knot ({values[k]:g}) is repeated {counts[k]} times; at most degree + 1 = {degree + 1} allowed"
    if not knots[n_ctrl] > knots[degree]:
        return "the parameter domain is empty (knot[degree] == knot[count])"
    inside = knots[degree:n_ctrl + 1]
    spans = np.diff(inside)
    narrowest = MIN_KNOT_SPAN * max(1.0, float(np.max(np.abs(knots))))
    thin = np.flatnonzero((spans > 0) & (spans < narrowest))
    if len(thin):
        i = degree + int(thin[0])
        return (f"knots {i} and {i + 1} differ by only {spans[thin[0]]:.3g}, too little for float64 "
                f"(at least {narrowest:.3g}): merge them or rescale the knot vector")
    return None
