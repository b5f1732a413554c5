"""The ahead-of-time kernels against numba's JIT, pixel for pixel (issue 14, goal 3; rtreflect.kernels.compiled).

Renders every scenes/*.toml (or the inputs given) at 480×270 twice, each in its own process: once with
``RTREFLECT_KERNELS=jit`` (numba's JIT, the kernels' cache) and once with ``RTREFLECT_KERNELS=aot``
(the built module ``kernels/_aot``, required: the run fails where it is missing, stale, or a call
has no AOT signature). Compares every channel of the film (RGBA and all AOVs) bit for bit (NaN
equal to NaN) and prints, per input, the channels that differ and their largest difference.

    python -m rtreflect.kernels.build     # first, where the module is not built
    python bench/kernels_aot_vs_jit.py [--size 480x270] [scenes/hood.toml ...]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: The child: render one input and save the film's pixels (all channels) and the channel names.
CHILD = r"""
import sys, numpy as np, rtreflect
from rtreflect.integrator.film import CHANNELS
path, width, height, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
result = rtreflect.render(rtreflect.load_scene(path), width=width, height=height)
np.savez(out, pixels=result.film.pixels, channels=np.array(CHANNELS), numba="numba" in sys.modules)
"""


def render(path: Path, size: tuple[int, int], mode: str, out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RTREFLECT_KERNELS": mode}
    subprocess.run([sys.executable, "-c", CHILD, str(path), *map(str, size), str(out)], cwd=ROOT, env=env, check=True)
    with np.load(out) as data:
        return {key: data[key] for key in data.files}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("inputs", nargs="*", type=Path)
    ap.add_argument("--size", default="480x270", help="WIDTHxHEIGHT")
    args = ap.parse_args()
    size = tuple(map(int, args.size.split("x")))
    inputs = args.inputs or sorted((ROOT / "scenes").glob("*.toml"))
    differing = 0
    with tempfile.TemporaryDirectory() as tmp:
        for path in inputs:
            jit = render(path, size, "jit", Path(tmp) / "jit.npz")
            aot = render(path, size, "aot", Path(tmp) / "aot.npz")
            a, b = jit["pixels"], aot["pixels"]
            same = (a == b) | (np.isnan(a) & np.isnan(b))
            bad = [(str(name), float(np.nanmax(np.abs(a[..., i] - b[..., i]))), int((~same[..., i]).sum()))
                   for i, name in enumerate(jit["channels"]) if not same[..., i].all()]
            differing += bool(bad)
            note = "" if not aot["numba"] else " (the AOT process imported numba!)"
            print(f"{path.name}: " + ("bit-identical" if not bad else
                                      "; ".join(f"{n}: {c} px, max |Δ| {d:.3g}" for n, d, c in bad)) + note)
    print(f"{len(inputs) - differing} of {len(inputs)} inputs bit-identical (AOT against JIT, {size[0]}×{size[1]})")
    sys.exit(1 if differing else 0)


if __name__ == "__main__":
    main()
