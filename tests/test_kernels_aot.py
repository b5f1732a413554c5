"""The ahead-of-time kernels (issue 14, goal 3; rtreflect.kernels.compiled, rtreflect.kernels.build).

* a render with the AOT module built and fresh does not import numba, and its pixels are the JIT's bit for bit;
* a module built from other kernel sources (stale) is not used: the render imports numba and gives the same pixels;
* the sources' hash changes with any kernel file's text;
* a call whose argument types no AOT signature declares (a strided view, another dtype) goes to the JIT and gives
  the JIT's answer, where the raw AOT function misreads the array (pycc checks only the item size);
  ``RTREFLECT_KERNELS=aot`` makes it an error naming the types;
* the loader reads every declared signature as numba does.

The first three need the module (``python -m rtreflect.kernels.build``, or ``pip install``); without it they skip.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rtreflect.kernels import compiled, tubes

ROOT = Path(__file__).resolve().parents[1]
KERNELS = ROOT / "rtreflect" / "kernels"

#: A render of a small scene in its own process: JSON of whether numba was imported, the loader's verdict on the
#: AOT module, the JIT fallbacks, and the RGBA and f bytes' hash. Optional argv[1] "stale": the sources' hash is
#: taken as another (what an edited kernel gives) before any kernel is imported.
RENDER = r"""
import hashlib, json, sys
from rtreflect.kernels import compiled
if sys.argv[1:] == ["stale"]:
    compiled.sources_hash = lambda: -1
import rtreflect
result = rtreflect.render(rtreflect.load_scene("scenes/cylinder.toml"), width=48, height=27, samples=1)
digest = hashlib.sha256(result.rgba.tobytes() + result.aov("f").tobytes() + result.aov("N").tobytes()).hexdigest()
print(json.dumps({"numba": "numba" in sys.modules, "why": compiled._state.get("why"), "aot": compiled._state["aot"] is not None,
                  "fallbacks": compiled.FALLBACKS, "pixels": digest}))
"""


def render(*args: str, mode: str = "auto") -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT), compiled.MODE_VARIABLE: mode}
    out = subprocess.run([sys.executable, "-c", RENDER, *args], capture_output=True, text=True, cwd=ROOT, env=env)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def built() -> bool:
    """Whether the AOT module exists in the source tree (fresh or not)."""
    return any(KERNELS.glob(f"{compiled.AOT_NAME}.*.so")) or any(KERNELS.glob(f"{compiled.AOT_NAME}.*.pyd"))


needs_module = pytest.mark.skipif(not built(), reason="AOT kernels not built (python -m rtreflect.kernels.build)")

#: With test_kernels.py on one xdist worker: the JIT compiles once (see there).
pytestmark = pytest.mark.xdist_group("numba-jit")


@needs_module
def test_render_with_fresh_module_does_not_import_numba_and_matches_the_jit():
    aot = render()
    assert aot["aot"], f"the AOT module is not used: {aot['why']} (rebuild: python -m rtreflect.kernels.build)"
    assert not aot["numba"] and aot["fallbacks"] == [], aot
    jit = render(mode="jit")
    assert jit["numba"] and not jit["aot"]
    assert aot["pixels"] == jit["pixels"]


@needs_module
def test_cad_part_render_calls_only_the_aot_kernels():
    """A CAD part's render takes the tracer's rare paths (seam restarts, crossings beside the mesh hit, the walk past a
    passing minimum), whose kernels must be called with the argument types the AOT module declares: a read-only
    broadcast of `tracing._into_domain` went to the JIT on every plate render (numba imported, its compile paid)."""
    script = RENDER.replace('"scenes/cylinder.toml"), width=48, height=27', '"parts/plate.step"), width=160, height=90')
    env = {**os.environ, "PYTHONPATH": str(ROOT), compiled.MODE_VARIABLE: "auto"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, env=env)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["aot"] and not result["numba"] and result["fallbacks"] == [], result


@needs_module
def test_stale_module_falls_back_to_the_jit():
    stale = render("stale")
    assert not stale["aot"] and stale["numba"] and "stale" in stale["why"], stale
    assert stale["pixels"] == render(mode="jit")["pixels"]


def test_sources_hash_follows_every_kernel_file(tmp_path, monkeypatch):
    for file in KERNELS.glob("*.py"):
        shutil.copy(file, tmp_path / file.name)
    monkeypatch.setattr(compiled, "source_files", lambda: sorted(tmp_path.glob("*.py")))
    before = compiled.sources_hash()
    assert before == compiled.sources_hash() and 0 <= before < 2**63
    for name in ("tubes.py", "__init__.py"):
        file = tmp_path / name
        text = file.read_text()
        file.write_text(text + "\n# an edit\n")
        assert compiled.sources_hash() != before, name
        file.write_text(text)
    assert compiled.sources_hash() == before
    # Machine code for another CPU (a venv or image copied from a newer machine) is stale too, not run (SIGILL).
    host = compiled.host_cpu()
    assert host.split()[0] and "+" in host  # LLVM's CPU name and its +feature list
    monkeypatch.setattr(compiled, "host_cpu", lambda: host.replace("+", "-", 1))
    assert compiled.sources_hash() != before


def householder(a: np.ndarray, n: np.ndarray) -> np.ndarray:
    return np.einsum("nij,nj->ni", 2 * n[:, :, None] * n[:, None, :] - np.eye(3), a)


def test_wrongly_typed_call_goes_to_the_jit():
    """A strided view and float32 arrays (declared: f8[:, ::1]): the JIT's answer, bit for bit, and right."""
    rng = np.random.default_rng(3)
    a, n = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    wide = np.zeros((50, 6))
    wide[:, ::2] = n
    jit = compiled.jit_namespace(tubes.__name__)["reflect"]
    for args in ((a, wide[:, ::2]), (a.astype(np.float32), n.astype(np.float32))):
        out, expected = np.full((50, 3), np.nan, dtype=args[0].dtype), np.full((50, 3), np.nan, dtype=args[0].dtype)
        before = len(compiled.FALLBACKS)
        tubes.reflect(*args, out)
        jit(*args, expected)
        assert np.array_equal(out, expected)
        assert np.allclose(out, householder(a, n), atol=1e-5)
        if isinstance(tubes.reflect, compiled.Kernel):  # served by the AOT module: this call was not
            assert compiled.FALLBACKS[before:] == [(f"{tubes.__name__}.reflect", ", ".join(map(compiled.describe,
                                                                                               (*args, out))))]


@pytest.mark.skipif(compiled.aot_module() is None, reason="AOT kernels not built or stale")
def test_aot_function_alone_misreads_a_strided_array_so_the_kernel_checks_types(monkeypatch):
    rng = np.random.default_rng(4)
    a, n = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    wide = np.zeros((20, 6))
    wide[:, ::2] = n
    raw = getattr(compiled.aot_module(), compiled.symbol(tubes.__name__, "reflect", 0))
    out, checked = np.zeros((20, 3)), np.zeros((20, 3))
    raw(a, wide[:, ::2], out)  # pycc's wrapper: only the item size is checked
    assert not np.allclose(out, householder(a, n))
    tubes.reflect(a, wide[:, ::2], checked)
    assert np.allclose(checked, householder(a, n))
    monkeypatch.setenv(compiled.MODE_VARIABLE, "aot")
    with pytest.raises(TypeError, match=r"tubes\.reflect: no ahead-of-time signature for \(f8\[:, ::1\], f8\[:, :\]"):
        tubes.reflect(a, wide[:, ::2], checked)


def test_loader_reads_each_declared_signature_as_numba():
    from rtreflect.kernels import build, nurbs, rims  # noqa: F401 (every kernel module registered)

    declared = [text for (_, _), (_, _, aot) in compiled.SOURCES.items() for text in aot]
    assert len(declared) >= 19
    for text in declared:
        build._check_parsed(text)
