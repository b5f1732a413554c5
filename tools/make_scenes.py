"""Regenerate the inline-NURBS scenes in scenes/ (hood, g1_join, cylinder, and one per interrogation mode).

Run: python tools/make_scenes.py   — the .toml files are committed; this records how they were made.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def fmt(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(fmt(v) for v in value) + "]"
    return repr(float(value)) if isinstance(value, float) else str(value)


def net(name: str, value) -> str:
    rows = ",\n  ".join(fmt(row) for row in np.asarray(value).tolist())
    return f"{name} = [\n  {rows},\n]\n"


def surface(name, degree, knots_u, knots_v, points, weights=None) -> str:
    text = f'\n[[surface]]\nname = "{name}"\ndegree = {fmt(list(degree))}\n'
    text += f"knots_u = {fmt(list(knots_u))}\nknots_v = {fmt(list(knots_v))}\n" + net("points", points)
    if weights is not None:
        text += net("weights", weights)
    return text


def header(comment, image, camera, lights) -> str:
    text = f"# {comment}\n"
    for table, values in (("image", image), ("camera", camera), ("lights", lights)):
        text += f"\n[{table}]\n" + "".join(f"{k} = {fmt(v)}\n" for k, v in values.items())
    return text


def footer(render) -> str:
    return "\n[render]\n" + "".join(f"{k} = {fmt(v)}\n" for k, v in render.items())


def hood() -> str:
    """A single bicubic B-spline patch, 6×6 control points: a crowned hood sloping to the front."""
    xs = np.linspace(-1.0, 1.0, 6)
    ys = np.linspace(-1.0, 1.0, 6)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    Z = 0.1 + 0.22 * (1 - X**2) + 0.18 * (Y + 1) / 2 - 0.06 * (Y**2)
    knots = [0, 0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1, 1]
    return (header("A car hood: one bicubic B-spline patch under 9 overhead tubes.",
                   {"width": 960, "height": 540, "samples": 4},
                   {"projection": "perspective", "eye": [0.0, -3.2, 2.4], "look_at": [0.0, 0.0, 0.0],
                    "up": [0.0, 0.0, 1.0], "fov": 40.0},
                   {"point": [0.0, 0.0, 3.0], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0],
                    "positions": [-2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0], "radius": 0.05})
            + surface("hood", (3, 3), knots, knots, np.stack([X, Y, Z], -1))
            + footer({"tessellation": 16, "surface_color": [0.18, 0.18, 0.2], "line_color": [1.0, 1.0, 1.0]}))


def g1_join() -> str:
    """Two bicubic Bézier patches meeting along x = 0 with tangent (G1) but not curvature (G2) continuity.

    Left: z = 0.3·x² (curved), right: flat-ish z = 0.0 continuation with matching tangent (slope 0 at x = 0):
    the second derivative jumps from 0.6 to 0 across the join, so reflection lines bend there.
    """
    ys = np.linspace(-1.0, 1.0, 4)
    # Cubic Bézier in x on [-1, 0] for z = 0.3 x² + 0.1 y² (exact: a quadratic raised to degree 3).
    xl = np.linspace(-1.0, 0.0, 4)
    zl_ctrl = np.array([0.3, 0.1, 0.0, 0.0])  # control values of 0.3·x² on [-1, 0] in cubic Bernstein form
    xr = np.linspace(0.0, 1.0, 4)
    zr_ctrl = np.array([0.0, 0.0, 0.0, 0.0])
    left = np.array([[[x, y, z] for y in ys] for x, z in zip(xl, zl_ctrl)])
    right = np.array([[[x, y, z] for y in ys] for x, z in zip(xr, zr_ctrl)])
    # Give both a gentle common bulge in y (identical on both sides, so the join stays G1 and not G2).
    bulge = np.array([0.0, 0.08, 0.08, 0.0])
    left[:, :, 2] += bulge[None, :]
    right[:, :, 2] += bulge[None, :]
    bez = [0, 0, 0, 0, 1, 1, 1, 1]
    return (header("Two bicubic patches joined with G1 but not G2 continuity along x = 0: the lines bend at the join.",
                   {"width": 960, "height": 540, "samples": 4},
                   {"projection": "perspective", "eye": [0.0, -3.0, 2.6], "look_at": [0.0, 0.0, 0.0],
                    "up": [0.0, 0.0, 1.0], "fov": 40.0},
                   {"point": [0.0, 0.0, 3.0], "normal": [0.0, 0.0, 1.0], "direction": [1.0, 1.0, 0.0],
                    "spacing": 0.4, "count": 15, "radius": 0.05})
            + surface("left", (3, 3), bez, bez, left)
            + surface("right", (3, 3), bez, bez, right)
            + footer({"tessellation": 16}))


def cylinder() -> str:
    """A quarter cylinder of radius 1 about the y axis: the exact rational quadratic NURBS arc × a line."""
    w = np.sqrt(0.5)
    arc = [(1.0, 0.0, 1.0), (1.0, 1.0, w), (0.0, 1.0, 1.0)]  # (x, z, weight): x = cos θ, z = sin θ, θ ∈ [0, π/2]
    ys = [-1.0, 0.0, 1.0]
    points = [[[x, y, z] for y in ys] for x, z, _ in arc]
    weights = [[wt for _ in ys] for _, _, wt in arc]
    return (header("A quarter cylinder (radius 1, axis y): an exact rational quadratic NURBS.",
                   {"width": 960, "height": 540, "samples": 4},
                   {"projection": "perspective", "eye": [2.6, -2.8, 2.2], "look_at": [0.45, 0.0, 0.45],
                    "up": [0.0, 0.0, 1.0], "fov": 40.0},
                   {"point": [0.0, 0.0, 3.0], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0],
                    "spacing": 0.5, "count": 13, "radius": 0.06})
            + surface("quarter_cylinder", (2, 1), [0, 0, 0, 1, 1, 1], [0, 0, 0.5, 1, 1], points, weights)
            + footer({"tessellation": 16}))


def with_mode(text: str, comment: str, render: dict) -> str:
    """A scene's text with its first comment line replaced and ``render`` keys added to its [render] table."""
    first, rest = text.split("\n", 1)
    return f"# {comment}\n" + rest + "".join(f"{k} = {fmt(v)}\n" for k, v in render.items())


def cup() -> list[tuple[int, int, list, list, np.ndarray, np.ndarray]]:
    """A moulded cup-like boss about z, as four rational quarter turns of one cubic profile.

    The profile (x, z) bulges out a little above the base (an undercut for a pull along +z), rises
    almost vertically (under 1° of draft) and rounds over into the flat top (plenty of draft).
    """
    profile = [(1.0, 0.0), (1.03, 0.2), (1.0, 0.55), (0.98, 0.9), (0.9, 1.12), (0.0, 1.15)]
    knots_u = [0, 0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1, 1]
    w = np.sqrt(0.5)
    turn = [((1.0, 0.0), 1.0), ((1.0, 1.0), w), ((0.0, 1.0), 1.0)]
    patches = []
    for k in range(4):
        c, s = np.cos(k * np.pi / 2), np.sin(k * np.pi / 2)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        points = np.array([[[x * cx, x * cy, z] for (cx, cy), _ in turn] for x, z in profile]) @ rot.T
        weights = np.array([[wv for _, wv in turn] for _ in profile])
        patches.append((3, 2, knots_u, [0, 0, 0, 1, 1, 1], points, weights))
    return patches


def cup_draft() -> str:
    text = header("Draft analysis of a moulded boss (pull +z): an undercut bulge above the base (red), a side under "
                  "1° of draft, a rounded top with plenty.",
                  {"width": 960, "height": 540, "samples": 4},
                  {"projection": "perspective", "eye": [2.4, -2.7, 2.3], "look_at": [0.0, 0.0, 0.55],
                   "up": [0.0, 0.0, 1.0], "fov": 38.0},
                  {"point": [0.0, 0.0, 4.0], "normal": [0.0, 0.0, 1.0], "direction": [0.0, 1.0, 0.0],
                   "spacing": 0.2, "count": 61, "radius": 0.02})
    for k, (p, q, ku, kv, points, weights) in enumerate(cup()):
        text += surface(f"quarter{k}", (p, q), ku, kv, points, weights)
    return text + footer({"tessellation": 16, "mode": "draft", "pull": [0.0, 0.0, 1.0], "thresholds": [0.0, 1.0, 3.0]})


def mode_scenes() -> list[tuple[str, str]]:
    """One scene per interrogation mode besides reflection (issue 15), each showing what the mode is for."""
    return [
        ("cylinder_highlight", with_mode(cylinder(), "Highlight lines (Beier-Chen) of the quarter cylinder: straight "
                                         "rulings where the normal lines meet the tubes, whatever the eye.",
                                         {"mode": "highlight"})),
        ("g1_join_isophote", with_mode(g1_join(), "Isophotes of the G1 join: the curvature jump at x = 0 shows as a "
                                       "kink in every isophote (they are one order less smooth than the surface).",
                                       {"mode": "isophote", "step": 4.0, "light": [0.4, -0.6, 1.0]})),
        ("hood_curvature", with_mode(hood(), "The hood's mean curvature map (signed with the normal facing the "
                                     "camera: negative where it bends away), with 8 iso-curvature bands.",
                                     {"mode": "curvature", "quantity": "mean", "range": "auto", "bands": 8})),
        ("cup_draft", cup_draft()),
        ("hood_zebra", with_mode(hood(), "Zebra stripes on the hood: the environment-mapped stripes of CAD tools, a "
                                 "function of the reflected direction only (tubes at infinity, no parallax).",
                                 {"mode": "zebra", "step": 6.0})),
    ]


def main() -> None:
    for name, text in (("hood", hood()), ("g1_join", g1_join()), ("cylinder", cylinder()), *mode_scenes()):
        (SCENES / f"{name}.toml").write_text(text)
        print(f"wrote scenes/{name}.toml")


if __name__ == "__main__":
    main()
