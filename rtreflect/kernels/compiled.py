"""Where a kernel's machine code comes from: the ahead-of-time module or numba's JIT (issue 14, goal 3).

Every kernel file decorates its functions with this module's `njit` instead of numba's, with the
same options plus ``aot=(signature, ...)``: the argument types (numba's signature syntax) under
which the installed package compiles the kernel ahead of time (`rtreflect.kernels.build`,
numba.pycc, run by ``pip install``). One Python source, two compilers:

* **AOT** (the extension ``rtreflect.kernels._aot``, present and *fresh*: built from exactly
  these kernel sources, checked by a hash of ``kernels/*.py`` the build embeds): the decorator
  returns a `Kernel` that calls the AOT function whose signature matches the arguments. numba is
  not imported at all, which is what makes a small render start in well under a second (its
  import and registry load alone took 0.65 s).
* **JIT** (the extension missing, stale, or ``RTREFLECT_KERNELS=jit``): the decorator returns
  ``numba.njit(**options)(func)``, cached on disk (``cache=True``) as before.

pycc's wrapper checks only an array argument's item size: an int64 array passed as float64, a
1-D array as 2-D or a strided view as contiguous would be read as garbage. So `Kernel` checks
each argument against the signature as numba's dispatcher would type it (dtype, ndim, layout,
writeable, aligned; the exact scalar type) and calls the JIT-compiled kernel where no signature
matches (numba imported then, for that call only: the AOT functions serve every other call).
``RTREFLECT_KERNELS=aot`` makes that an error instead, and a missing or stale module an
ImportError: how the tests find a signature the code uses but no decorator declares.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import os
import re
import sys
import threading
import types
from pathlib import Path

import numpy as np

#: Environment variable choosing the kernels' compiler: "auto" (AOT where fresh, else JIT), "jit", "aot" (required).
MODE_VARIABLE = "RTREFLECT_KERNELS"
MODES = ("auto", "jit", "aot")
#: Name of the ahead-of-time extension module inside this package.
AOT_NAME = "_aot"
#: Exported function of the AOT module returning the sources' hash it was built from.
HASH_SYMBOL = "source_hash"
#: Hex digits of the SHA-256 kept: 60 bits, so the hash is an int64 the AOT module can return.
HASH_DIGITS = 15

#: Kernels by module and name, whatever the mode (the build reads them here).
REGISTRY: dict[str, dict[str, "Kernel | object"]] = {}
#: The options and Python function of each registered kernel: (module, name) -> (func, options, aot).
SOURCES: dict[tuple[str, str], tuple[types.FunctionType, dict, tuple[str, ...]]] = {}
#: Calls that found no AOT signature and went to the JIT: (module.kernel, argument types), each once (diagnostics, tests).
FALLBACKS: list[tuple[str, str]] = []

_lock = threading.Lock()
_state: dict[str, object] = {}


def mode() -> str:
    value = os.environ.get(MODE_VARIABLE, "auto") or "auto"
    if value not in MODES:
        raise ValueError(f"{MODE_VARIABLE}={value!r}: expected one of {', '.join(MODES)}")
    return value


def source_files() -> list[Path]:
    """The files whose text decides the compiled kernels: every ``kernels/*.py`` (this one too: a changed loader
    asks for a rebuild rather than for a reason why not)."""
    return sorted(Path(__file__).parent.glob("*.py"))


def host_cpu() -> str:
    """LLVM's name and features of this CPU: the AOT build compiles for the host's CPU (as numba's JIT, whose
    cache is keyed alike), so a module built on another CPU (a copied venv or image) could run instructions this
    one lacks (SIGILL). llvmlite's binding alone, not numba (~0.03 s)."""
    import llvmlite.binding as llvm  # noqa: PLC0415

    return f"{llvm.get_host_cpu_name()} {llvm.get_host_cpu_features().flatten()}"


def sources_hash() -> int:
    """SHA-256 of the kernel sources (`source_files`, names and bytes) and of the CPU they are compiled for
    (`host_cpu`), as a non-negative int64: a module built from other sources or for another CPU is stale."""
    digest = hashlib.sha256(host_cpu().encode() + b"\0")
    for file in source_files():
        digest.update(file.name.encode() + b"\0" + file.read_bytes() + b"\0")
    return int(digest.hexdigest()[:HASH_DIGITS], 16)


def aot_module():
    """The AOT extension where it is present, importable and built from the current sources; else None.

    Decided once per process. ``RTREFLECT_KERNELS=jit``: None; ``=aot``: ImportError instead of None.
    """
    if "aot" not in _state:
        chosen, module, why = mode(), None, "disabled (RTREFLECT_KERNELS=jit)"
        if chosen != "jit":
            try:
                module = importlib.import_module(f"{__package__}.{AOT_NAME}")
                why = ""
            except ImportError as error:
                why = f"not built ({error})"
            if module is not None and getattr(module, HASH_SYMBOL)() != sources_hash():
                module, why = None, "stale (built from other kernel sources)"
        if module is None and chosen == "aot":
            raise ImportError(f"rtreflect: the ahead-of-time kernels are {why}: run `python -m rtreflect.kernels.build` "
                              f"(or unset {MODE_VARIABLE})")
        _state["aot"], _state["why"] = module, why
    return _state["aot"]


def symbol(module: str, name: str, index: int) -> str:
    """Name of a kernel's index-th AOT signature in the extension: ``nurbs__evaluate__0``."""
    return f"{module.rsplit('.', 1)[-1]}__{name}__{index}"


def njit(*args, aot: tuple[str, ...] = (), **options):
    """numba.njit's decorator (``@njit`` or ``@njit(**options)``), compiled ahead of time where fresh (module doc).

    ``aot``: the signatures of the calls the code makes (every argument's type exactly: numba's dispatcher
    compiles one machine code per type tuple, and a call matching none of them goes to the JIT).
    """
    if args:  # bare @njit
        return njit(aot=aot, **options)(args[0])

    def decorate(func):
        module, name = func.__module__, func.__name__
        SOURCES[module, name] = (func, dict(options), tuple(aot))
        compiled = aot_module()
        if compiled is None:
            import numba  # noqa: PLC0415 (the JIT path only)

            kernel = numba.njit(**options)(func)
        else:
            kernel = Kernel(func, module, [(Signature(text), getattr(compiled, symbol(module, name, i), None))
                                           for i, text in enumerate(aot)])
        REGISTRY.setdefault(module, {})[name] = kernel
        return kernel

    return decorate


class Kernel:
    """A kernel served by the AOT module: the AOT function whose signature matches the call, else the JIT's."""

    def __init__(self, func, module: str, calls: list):
        functools.update_wrapper(self, func)
        self.py_func = func
        self.module = module
        self.calls = [(signature.matches, function) for signature, function in calls if function is not None]

    def __call__(self, *args):
        for matches, function in self.calls:
            if matches(args):
                return function(*args)
        return self.jit(*args)

    def jit(self, *args):
        """The call compiled by numba's JIT (`jit_namespace`): arguments no AOT signature takes."""
        types_ = ", ".join(describe(a) for a in args)
        if mode() == "aot":
            raise TypeError(f"{self.module}.{self.__name__}: no ahead-of-time signature for ({types_}) "
                            f"(add it to the kernel's aot=...)")
        call = (f"{self.module}.{self.__name__}", types_)
        if call not in FALLBACKS:  # each kind of call once: a per-tile fallback must not grow the list without end
            FALLBACKS.append(call)
        return jit_namespace(self.module)[self.__name__](*args)


def jit_namespace(module: str, cache: bool = True) -> dict:
    """The module's kernels compiled by numba's JIT, in a copy of the module's globals: each kernel's globals
    name the other kernels' dispatchers (numba types a callee by its global), while the module itself keeps
    its `Kernel` objects for the AOT calls. Built once per module (``cache``: numba's on-disk cache; the
    build turns it off, so callees are compiled to IR it can link)."""
    key = (module, cache)
    with _lock:
        if key not in _state:
            import numba  # noqa: PLC0415

            namespace = dict(vars(sys.modules[module]))
            for name in REGISTRY.get(module, {}):
                func, options, _ = SOURCES[module, name]
                copy = types.FunctionType(func.__code__, namespace, func.__name__, func.__defaults__, func.__closure__)
                copy.__kwdefaults__, copy.__qualname__, copy.__doc__ = func.__kwdefaults__, func.__qualname__, func.__doc__
                namespace[name] = numba.njit(**{**options, "cache": cache and options.get("cache", False)})(copy)
            _state[key] = namespace
    return _state[key]


# -- Argument types as numba's dispatcher sees them ------------------------------------------------------------

#: numba's scalar type names (the spellings a signature uses) -> the numpy dtype.
DTYPES = {name: np.dtype(dtype) for names, dtype in [
    (("f8", "float64", "double"), "f8"), (("f4", "float32"), "f4"), (("i8", "int64", "intp"), "i8"),
    (("i4", "int32", "intc"), "i4"), (("i2", "int16"), "i2"), (("i1", "int8"), "i1"), (("u8", "uint64"), "u8"),
    (("u4", "uint32"), "u4"), (("u1", "uint8"), "u1"), (("b1", "boolean", "bool_"), "?")] for name in names}
#: Python scalar types numba types as each dtype (typeof: int -> int64, float -> float64, bool -> boolean).
SCALARS = {np.dtype("f8"): (float, np.float64), np.dtype("i8"): (int, np.int64), np.dtype("?"): (bool, np.bool_)}
#: numpy's flag bits (``ndarray.flags.num``, NPY_ARRAY_*) a signature's array needs: writeable and aligned, and its
#: layout's contiguity ('A': none).
_BEHAVED = 0x0100 | 0x0400
_LAYOUT_BITS = {"C": 0x0001, "F": 0x0002, "A": 0}
#: The two-character spelling of each dtype (messages).
SHORT = {dtype: name for name, dtype in DTYPES.items() if len(name) == 2}


class Signature:
    """A signature string such as ``void(f8[:, ::1], i8)`` as argument checks, without numba.

    Arrays: ``dtype[dims]`` with ``::1`` on the last dimension for C order (layout 'C'), on the first
    for Fortran order ('F'), on none for any strides ('A'), as numba's syntax; ``readonly(...)``
    is not supported (an array not writeable goes to the JIT, which types it readonly).
    """

    _ARRAY = re.compile(r"^(\w+)\[(.*)\]$")

    def __init__(self, text: str):
        self.text = text
        head = re.match(r"^\s*\w+\s*\((.*)\)\s*$", text, re.S)
        if head is None:
            raise ValueError(f"AOT signature {text!r}: expected 'return_type(arg, ...)'")
        self.args = [self._parse(arg) for arg in _split(head[1])]
        # Per argument what `matches` tests, in its cheapest form: a scalar's Python types; an array's dtype, ndim and
        # the flag bits it needs (`ndarray.flags.num`: one attribute read, not four; ~30 % of the check per call).
        self._checks = [(None, SCALARS.get(spec[1], (spec[1].type,)), 0, 0) if spec[0] == "scalar" else
                        (spec[1], None, spec[2], _BEHAVED | _LAYOUT_BITS[spec[3]]) for spec in self.args]

    @classmethod
    def _parse(cls, arg: str) -> tuple:
        arg = arg.replace(" ", "")
        array = cls._ARRAY.match(arg)
        if array is None:
            return ("scalar", DTYPES[arg])
        dims = array[2].split(",")
        contiguous = [d == "::1" for d in dims]
        if not all(d in (":", "::1") for d in dims) or sum(contiguous) > 1:
            raise ValueError(f"AOT signature: array {arg!r}: dimensions ':' with at most one '::1'")
        layout = "C" if contiguous[-1] else "F" if contiguous[0] else "A"
        return ("array", DTYPES[array[1]], len(dims), layout)

    def matches(self, args: tuple) -> bool:
        """Whether numba would type ``args`` as this signature: scalars' exact types; arrays' dtype, ndim, layout,
        writeable and aligned."""
        if len(args) != len(self._checks):
            return False
        for value, (dtype, kinds, ndim, bits) in zip(args, self._checks):
            if dtype is None:
                if type(value) not in kinds:
                    return False
            elif type(value) is not np.ndarray or value.ndim != ndim or value.dtype != dtype or \
                    value.flags.num & bits != bits:
                return False
        return True


def _split(args: str) -> list[str]:
    """Top-level comma-separated items of an argument list (commas inside brackets kept)."""
    items, depth, start = [], 0, 0
    for i, ch in enumerate(args):
        depth += ch == "["
        depth -= ch == "]"
        if ch == "," and depth == 0:
            items.append(args[start:i])
            start = i + 1
    if args[start:].strip():
        items.append(args[start:])
    return [item.strip() for item in items]


def describe(value) -> str:
    """A value's type in signature syntax (for messages): ``f8[:, ::1]``, ``i8``, or the Python type's name."""
    if isinstance(value, np.ndarray):
        dims = [":"] * value.ndim
        if value.ndim and value.flags.c_contiguous:
            dims[-1] = "::1"
        elif value.ndim and value.flags.f_contiguous:
            dims[0] = "::1"
        return f"{SHORT.get(value.dtype, value.dtype)}[{', '.join(dims)}]" + ("" if value.flags.writeable else " readonly")
    for dtype, kinds in SCALARS.items():
        if type(value) in kinds:
            return SHORT[dtype]
    return SHORT.get(np.dtype(type(value)), type(value).__name__) if isinstance(value, np.generic) else type(value).__name__
