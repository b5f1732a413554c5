"""The argument types the kernels are called with, for their ``aot=(...)`` declarations (rtreflect.kernels.compiled).

Runs work under numba's JIT (``RTREFLECT_KERNELS=jit``) in this process, then prints each kernel's
dispatcher signatures (one per type tuple numba compiled) in the decorator's syntax, and marks those
no ``aot=`` declares yet. The work: renders and ``validate`` of every shipped scene and part at a
small size, and, with ``--pytest ARGS``, the given tests in-process.

    python tools/kernel_signatures.py [--size 96x54] [--pytest "-q tests/test_kernels.py"]
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

os.environ["RTREFLECT_KERNELS"] = "jit"  # before any kernel module is imported

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: numba's type names in the signature syntax.
SCALAR = {"float64": "f8", "float32": "f4", "int64": "i8", "int32": "i4", "uint8": "u1", "bool": "b1", "boolean": "b1"}


def spelled(numba_type) -> str:
    """A numba type in signature syntax: ``f8[:, ::1]``, ``i8``."""
    from numba.core import types

    if isinstance(numba_type, types.Array):
        dims = [":"] * numba_type.ndim
        if numba_type.layout == "C":
            dims[-1] = "::1"
        elif numba_type.layout == "F":
            dims[0] = "::1"
        text = f"{SCALAR[str(numba_type.dtype)]}[{', '.join(dims)}]"
        return text + ("" if numba_type.mutable else " READONLY") + ("" if numba_type.aligned else " UNALIGNED")
    return SCALAR.get(str(numba_type), str(numba_type))


def work(size: str, pytest_args: str | None) -> None:
    import rtreflect

    width, height = map(int, size.split("x"))
    inputs = sorted((ROOT / "scenes").glob("*.toml")) + sorted(p for p in (ROOT / "parts").iterdir()
                                                               if p.suffix in (".step", ".igs", ".3dm"))
    for path in inputs:
        print(f"render {path.name}", file=sys.stderr)
        result = rtreflect.render(rtreflect.load_scene(path), width=width, height=height)
        del result
    for path in sorted((ROOT / "scenes").glob("*.toml")):
        print(f"validate {path.name}", file=sys.stderr)
        rtreflect.validate(path, width=width, height=height)
    if pytest_args:
        import pytest

        pytest.main(shlex.split(pytest_args))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="96x54", help="WIDTHxHEIGHT of the renders")
    ap.add_argument("--pytest", help="pytest arguments to run in-process as well")
    args = ap.parse_args()
    os.chdir(ROOT)
    work(args.size, args.pytest)
    from rtreflect.kernels import compiled

    for module, kernels in sorted(compiled.REGISTRY.items()):
        for name, dispatcher in kernels.items():
            declared = set(compiled.SOURCES[module, name][2])
            for signature in dispatcher.signatures:
                returned = dispatcher.overloads[signature].signature.return_type
                result = "void" if str(returned) == "none" else spelled(returned)
                text = f"{result}({', '.join(spelled(t) for t in signature)})"
                print(f"{module}.{name}: {text!r}{'' if text in declared else '   <- not declared'}")


if __name__ == "__main__":
    main()
