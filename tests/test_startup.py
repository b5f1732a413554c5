"""Start-up (issue 14): what `rtreflect` imports before the first pixel, and the sRGB encoding written out for it.

colour-science took ~0.5 s of every `rtreflect render` for one formula (the sRGB encoding of
the PNG); the formula is now written out in `output.imagefiles.srgb_oetf` and checked here
against colour-science itself, byte for byte over every 8-bit code's neighbourhood.
"""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

from rtreflect.output.imagefiles import encode_srgb, srgb_oetf

ROOT = Path(__file__).resolve().parents[1]
#: Heavy modules only some commands need: none may load with the command line itself.
LAZY = ("colour", "OCP", "distributed", "dask", "rhino3dm", "jinja2", "matplotlib")


def test_command_line_import_leaves_heavy_modules_unloaded():
    code = f"import sys, rtreflect.cli; print(' '.join(m for m in {LAZY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT,
                         env={"PYTHONPATH": str(ROOT), "PATH": ""})
    assert out.stdout.split() == [], f"imported by `import rtreflect.cli`: {out.stdout.strip()}"


def test_srgb_encoding_matches_colour_science():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    codes = np.arange(256) / 255.0
    # Every linear value whose 8-bit code is a near tie, plus a dense sweep and the ends.
    ties = colour.cctf_decoding((np.arange(256) + 0.5) / 255.0, function="sRGB")
    L = np.unique(np.clip(np.r_[np.linspace(0, 1, 200001), ties, np.nextafter(ties, 0), np.nextafter(ties, 2),
                                colour.cctf_decoding(codes, function="sRGB")], 0, 1))
    np.testing.assert_array_equal(srgb_oetf(L), colour.cctf_encoding(L, function="sRGB"))
    rgba = np.stack([L, L[::-1], L, np.ones_like(L)], axis=-1)
    expected = np.round(colour.cctf_encoding(rgba[:, :3], function="sRGB") * 255.0).astype(np.uint8)
    np.testing.assert_array_equal(encode_srgb(rgba)[:, :3], expected)
