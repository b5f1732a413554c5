"""The exact hit's compiled kernels alone, per hit (issue 14 goal 2): Newton and the curvature AOVs.

On the primary mesh hits of `render_bench.py`'s scene (a 10×10 bicubic patch, 1920×1080): CPU
seconds of one thread, best of ``--repeat``, per hit of

* `kernels.nurbs.refine_mesh_hits` (start from the mesh hit, Newton, near test, t, unit normal, and K, H, κ1, κ2
  where Newton converged at its order-2 evaluation, `kernels.nurbs.CURVATURE_EVALUATION`, or its next step was
  finished by that evaluation's Taylor polynomials, `taylor_finish_lanes`);
* `kernels.nurbs.curvatures_at` (the order-2 evaluation and K, H, κ1, κ2 of the K, H, k1, k2 AOVs: what the tracer
  still computes for the hits where the Newton kernel had no curvature);
* one evaluation of S, S_u, S_v (`point_at`, order 1, one point at a time: the scalar path, which the lane
  blocks of the two kernels above vectorise) at the same points,

and how many evaluations Newton made per hit (steps + 1, less a step finished by Taylor; counted by re-running it
step-capped). Per-hit
figures compare between checkouts in the same minute (run both back to back; on a loaded machine
other jobs still inflate CPU time through the shared caches):

    python bench/newton_bench.py [--width 1920 --height 1080 --repeat 5]

``--save FILE.npz`` keeps every output of the Newton kernel (``newton_curvature``: its K, H, κ1, κ2) and of the
curvature kernel (``curvatures_at``, with the normal facing the ray), ``--compare FILE.npz`` says field by field whether they are the same bits as those saved (e.g. by
another checkout).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parent))
from render_bench import bench_scene_text  # noqa: E402

from rtreflect.exchange.scene import load_scene  # noqa: E402
from rtreflect.geometry import surfaces as surface_module  # noqa: E402
from rtreflect.integrator.renderer import Renderer  # noqa: E402
from rtreflect.kernels import nurbs  # noqa: E402
from rtreflect.kernels.compiled import jit_namespace  # noqa: E402
from rtreflect.trace import tracing  # noqa: E402

#: The nurbs kernels as numba dispatchers (`kernels.compiled.jit_namespace`): with the AOT module loaded, the module's
#: own names are `Kernel` wrappers, which a jitted function cannot call.
_NURBS = jit_namespace(nurbs.__name__)
new_scratch, point_at = _NURBS["new_scratch"], _NURBS["point_at"]

FIELDS = ("patch", "u_start", "v_start", "u", "v", "S", "Su", "Sv", "t", "normal", "cosine", "converged", "near",
          "edge", "degenerate", "newton_curvature")


@njit(nogil=True)
def evaluations(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, max_degree, patch, u, v):
    """`point_at` of order 1 at each (patch, u, v), the sum of the results kept so nothing is optimised away."""
    scratch = new_scratch(max_degree)
    d = np.empty((6, 3))
    total = 0.0
    for i in range(patch.shape[0]):
        point_at(degree, count, knot_offset, knots, pw_offset, pw, domain, power_offset, power, patch[i], u[i],
                       v[i], 1, d, scratch)
        total += d[0, 0] + d[1, 1] + d[2, 2]
    return total


def best_of(repeat: int, run) -> float:
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        run()
        best = min(best, time.process_time() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--repeat", type=int, default=5, help="best of N calls")
    ap.add_argument("--save", type=Path, help="keep the Newton kernel's outputs in this .npz")
    ap.add_argument("--compare", type=Path, help="compare the Newton kernel's outputs with this .npz")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.toml"
        path.write_text(bench_scene_text(args.width, args.height))
        renderer = Renderer(load_scene(path))
    rows, cols = np.divmod(np.arange(args.width * args.height), args.width)
    O, D = renderer.camera.rays(rows, cols)
    mesh = renderer.accelerator.intersect(O, D)
    found = mesh.prim >= 0
    O, D = np.ascontiguousarray(O[found]), np.ascontiguousarray(D[found])
    prim = np.ascontiguousarray(mesh.prim[found], dtype=np.int64)
    b1, b2, tm = (np.ascontiguousarray(x[found], dtype=np.float64) for x in (mesh.b1, mesh.b2, mesh.t))
    tess, table = renderer.tessellation, renderer.surfaces.table
    band = tess.chord_error + 1e-6 * tess.extent
    n = len(prim)

    def newton(max_steps: int = tracing.NEWTON_MAX_STEPS) -> dict[str, np.ndarray]:
        out = dict(patch=np.empty(n, dtype=np.int64), u_start=np.empty(n), v_start=np.empty(n), u=np.empty(n),
                   v=np.empty(n), S=np.empty((n, 3)), Su=np.empty((n, 3)), Sv=np.empty((n, 3)), t=np.empty(n),
                   normal=np.empty((n, 3)), cosine=np.empty(n), newton_curvature=np.empty((n, 4)),
                   **{name: np.empty(n, dtype=bool) for name in ("converged", "near", "edge", "degenerate")})
        nurbs.refine_mesh_hits(*table.args, table.scale, *tess.start_arrays, band, prim, b1, b2, O, D, tm, tess.extent,
                               tracing.NEWTON_TOLERANCE, max_steps, tracing.JUMP_LIMIT, tracing.GRAZING_ALLOWANCE,
                               surface_module.DEGENERATE_SINE, surface_module.VANISHING_PARTIAL,
                               *(out[name] for name in FIELDS))
        return out

    hits = newton()
    # Converged after s steps = s + 1 evaluations: the least max_steps with which the hit converges.
    steps = np.full(n, tracing.NEWTON_MAX_STEPS + 1)
    for s in range(tracing.NEWTON_MAX_STEPS, -1, -1):
        steps[newton(s)["converged"]] = s
    newton_s = best_of(args.repeat, newton)
    curv = np.empty((4, n))
    turned = hits["normal"] * np.where(hits["cosine"] > 0, -1.0, 1.0)[:, None]  # facing the ray, as the tracer's
    curvature = lambda: nurbs.curvatures_at(*table.args, hits["patch"], hits["u"], hits["v"], turned, curv)  # noqa: E731
    curvature()
    curvature_s = best_of(args.repeat, curvature)
    evaluate = lambda: evaluations(*table.args, hits["patch"], hits["u"], hits["v"])  # noqa: E731
    evaluate()
    evaluation_s = best_of(args.repeat, evaluate)

    print(f"{n} primary mesh hits of render_bench's scene at {args.width}×{args.height}; CPU of one thread, best of "
          f"{args.repeat}")
    # A last step the order-2 evaluation's Taylor polynomials finished (`taylor_finish_lanes`) took no evaluation.
    fused = ~np.isnan(hits["newton_curvature"][:, 0])
    finished = fused & (steps == nurbs.CURVATURE_EVALUATION + 1)
    mean_evaluations = np.mean(np.minimum(steps, tracing.NEWTON_MAX_STEPS) + 1 - finished)
    label = lambda s: str(s) if s <= tracing.NEWTON_MAX_STEPS else "not converged"  # noqa: E731
    print("Newton steps to converge: " + ", ".join(f"{label(s)}: {100 * np.mean(steps == s):.3g} %" for s in np.unique(steps))
          + f" (mean evaluations per hit {mean_evaluations:.2f})")
    print(f"refine_mesh_hits:          {newton_s:.3f} s, {1e6 * newton_s / n:.3f} µs per hit")
    print(f"curvatures_at (AOVs):      {curvature_s:.3f} s, {1e6 * curvature_s / n:.3f} µs per hit")
    print(f"S, S_u, S_v (scalar):      {evaluation_s:.3f} s, {1e6 * evaluation_s / n:.3f} µs per evaluation; "
          f"Newton's evaluations at that cost: {100 * mean_evaluations * evaluation_s / newton_s:.0f} % of its kernel")
    hits["curvatures_at"] = curv
    # Newton's curvatures are those of its order-2 evaluation's point: Newton stopped there, the reference's.
    at = newton(nurbs.CURVATURE_EVALUATION)
    at_turned = at["normal"] * np.where(at["cosine"] > 0, -1.0, 1.0)[:, None]
    there = np.empty((4, n))
    nurbs.curvatures_at(*table.args, at["patch"], at["u"], at["v"], at_turned, there)
    same = np.array_equal(hits["newton_curvature"][fused].view(np.uint64), there.T[fused].view(np.uint64))
    print(f"curvatures from Newton:    {100 * np.mean(fused):.2f} % of hits (last step finished by Taylor: "
          f"{100 * np.mean(finished):.2f} %), the same bits as curvatures_at's at its evaluation: {same}")
    if args.save:
        np.savez(args.save, **hits)
        print(f"saved {args.save}")
    if args.compare:
        saved = np.load(args.compare)
        same = {name: np.array_equal(hits[name].view(np.uint8), saved[name].view(np.uint8))
                for name in FIELDS + ("curvatures_at",) if name in saved}
        print("same bits as " + str(args.compare) + ": "
              + ("every field" if all(same.values()) else "NOT " + ", ".join(k for k, v in same.items() if not v)))


if __name__ == "__main__":
    main()
