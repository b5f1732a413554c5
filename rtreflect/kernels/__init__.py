"""Compiled per-point and per-ray kernels (numba, ``nogil``): the one implementation of the hot formulas.

The stage modules (geometry.surfaces, trace.tracing, modes.lights) marshal arrays and call these;
the kernels import nothing of the package but each other. The install compiles them ahead of
time (`build`, numba.pycc: the extension ``_aot``), so a render imports no numba; where that module
is missing or older than these sources, numba's JIT compiles them and caches the machine code in
``__pycache__`` beside these sources (``cache=True``), so only the first such run pays for
compilation (`compiled`: which of the two serves a call).
"""

#: numba options of every kernel: machine code cached on disk; the GIL released (the renderer's tile
#: threads run kernels side by side); numpy's division semantics (x/0 gives inf or NaN, tested for by
#: the callers, instead of a ZeroDivisionError check on every division).
JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
