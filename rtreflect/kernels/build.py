"""The ahead-of-time build of the kernels: numba.pycc compiles every declared signature into ``kernels/_aot``.

Each kernel file's `compiled.njit` kernels with ``aot=(signature, ...)`` are exported from one
extension module, symbol ``<file>__<kernel>__<i>`` (`compiled.symbol`), beside ``source_hash()``:
the hash of the kernel sources they were built from (`compiled.sources_hash`), which the loader
compares at import so an edited kernel is never served stale machine code.

Compiled as numba's JIT compiles the same functions (`kernels.JIT`), so both give the same bits:

* the same function objects, their callees the JIT's dispatchers (`compiled.jit_namespace`);
  ``inline="always"`` helpers are inlined by numba's own pass in both;
* pycc's `Flags` with the JIT options that change code: ``error_model="numpy"`` (x/0 is inf or
  NaN, no ZeroDivisionError check) and ``release_gil`` (``nogil=True``: the renderer's tile
  threads run kernels side by side); fastmath, boundscheck and parallel are off in both;
* machine code for this machine's CPU (``target_cpu="host"``, as the JIT), not pycc's generic x86-64.

Run by ``pip install`` (setup.py: `extension`, a setuptools extension) or in place, after a kernel
edit, by ``python -m rtreflect.kernels.build`` (atomically replaces the module).
"""

from __future__ import annotations

import argparse
import importlib
import os
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

from . import compiled

#: Files of this package that are no kernel module (the loader, this build, the options).
NOT_KERNELS = ("__init__", "compiled", "build")
#: CPU the machine code is for: this machine's, as numba's JIT (pycc's default "" is generic x86-64, slower).
TARGET_CPU = "host"


def kernel_modules() -> list[str]:
    """Every kernel file of the package, as a module name (``rtreflect.kernels.nurbs``, ...)."""
    here = Path(__file__).parent
    return [f"{__package__}.{file.stem}" for file in sorted(here.glob("*.py")) if file.stem not in NOT_KERNELS]


def _use_jit_flags() -> None:
    """Make pycc compile with the JIT's code-changing options (module doc). In the build process only.

    pycc makes its flags once with ``Flags()`` (here: numba's own `Flags` with the options set) and compiles
    every export with that one object, which the compilation of one export changes: `rescue` compiled after
    `refine_mesh_hits` then failed to type a reused variable name (``c``: an int, then a float), which the
    JIT compiles. So each export gets a copy, as each JIT compilation gets its own flags.
    """
    import numba.pycc.compiler as pycc_compiler
    from numba.core.compiler import Flags

    from . import JIT

    def kernel_flags() -> Flags:
        flags = Flags()
        flags.release_gil = bool(JIT.get("nogil", False))
        flags.error_model = JIT.get("error_model", "python")
        return flags

    def compile_extra(*args, **kwargs):  # each export with its own copy of the flags, as each JIT compilation
        flags = args[5].copy()
        return plain_compile_extra(*args[:5], flags, *args[6:], **kwargs)

    if getattr(pycc_compiler, "rtreflect_flags", False):  # patched already in this process
        return
    plain_compile_extra = pycc_compiler.compile_extra
    pycc_compiler.compile_extra, pycc_compiler.Flags, pycc_compiler.rtreflect_flags = compile_extra, kernel_flags, True


def compiler():
    """A numba.pycc `CC` exporting every declared signature of every kernel module, and the sources' hash."""
    os.environ.setdefault(compiled.MODE_VARIABLE, "jit")  # kernels imported here need not load the old module
    _use_jit_flags()
    from numba.pycc import CC

    cc = CC(compiled.AOT_NAME, source_module=importlib.import_module(__name__))
    cc.target_cpu = TARGET_CPU
    for module in kernel_modules():
        importlib.import_module(module)
        namespace = compiled.jit_namespace(module, cache=False)
        for name in compiled.REGISTRY.get(module, {}):
            for index, signature in enumerate(compiled.SOURCES[module, name][2]):
                _check_parsed(signature)
                cc.export(compiled.symbol(module, name, index), signature)(namespace[name].py_func)
    source_hash = compiled.sources_hash()
    cc.export(compiled.HASH_SYMBOL, "i8()")(eval(f"lambda: {source_hash}"))  # a constant of the machine code
    return cc


def _check_parsed(text: str) -> None:
    """The loader's reading of a signature (`compiled.Signature`, no numba) is numba's: dtype, ndim, layout per argument."""
    from numba.core import sigutils, types
    from numba.np.numpy_support import as_dtype

    args, _ = sigutils.normalize_signature(text)
    theirs = [("array", as_dtype(t.dtype), t.ndim, t.layout) if isinstance(t, types.Array) else ("scalar", as_dtype(t))
              for t in args]
    if theirs != compiled.Signature(text).args:
        raise ValueError(f"AOT signature {text!r}: the loader reads {compiled.Signature(text).args}, numba {theirs}")


def extensions() -> list:
    """The setuptools extension of the AOT module (setup.py); a C compiler missing only skips it (JIT then), and so
    does a numba that cannot compile it (pycc is on numba's deprecation path): a warning, no extension."""
    try:
        return [compiler().distutils_extension(optional=True)]
    except Exception as error:  # noqa: BLE001 (any failure of pycc: the JIT serves instead)
        warnings.warn(f"rtreflect: the ahead-of-time kernels are not built ({type(error).__name__}: {error}); "
                      f"numba's JIT compiles them on first use instead")
        return []


def build(output_dir: Path | None = None) -> Path:
    """Compile the AOT module into ``output_dir`` (default: this package) and return its path.

    Built in a temporary folder, then moved over the old module in one step: a process that has the old
    one loaded keeps its file, and no half-written module is ever imported.
    """
    cc = compiler()
    target = Path(output_dir or Path(__file__).parent) / cc.output_file
    with tempfile.TemporaryDirectory(prefix="rtreflect-aot-") as tmp:
        cc.output_dir = tmp
        cc.compile()
        shutil.move(str(Path(tmp) / cc.output_file), str(target.with_suffix(".partial")))
    os.replace(target.with_suffix(".partial"), target)
    return target


def main() -> None:
    ap = argparse.ArgumentParser(prog="python -m rtreflect.kernels.build", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output-dir", type=Path, help="folder of the module (default: the package's kernels folder)")
    args = ap.parse_args()
    start = time.perf_counter()
    path = build(args.output_dir)
    print(f"{path} ({time.perf_counter() - start:.1f} s)", file=sys.stderr)


if __name__ == "__main__":
    main()
