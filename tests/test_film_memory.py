"""The film's memory (integrator/film.py `plain_pages`): not advised MADV_HUGEPAGE, whatever numpy advises.

The kernel's own record is the judge: /proc/self/smaps lists each mapping's VmFlags, "hg" where madvise
(MADV_HUGEPAGE) was asked for it. The tests run where a plain np.empty of the same size is so advised (Linux with
transparent huge pages and a numpy that advises), else they could not tell the two apart and are skipped.

Each allocation is looked at in a fresh process (`fresh`): in a pytest worker that had run hundreds of tests, the
film's mapping once showed "hg" (once in two runs of the suite in two workers; never with the file alone): what the
other tests left in the process decided it, not the film.
"""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rtreflect.integrator.film import CHANNELS

SMAPS = Path("/proc/self/smaps")
#: A film of 46 MB: above glibc's largest dynamic mmap threshold (32 MiB on 64-bit), so it is a mapping of its own
#: (not a piece of the heap an earlier array's advice may cover).
WIDTH, HEIGHT = 1024, 512


def vm_flags(array: np.ndarray) -> set[str]:
    """The VmFlags of the mapping holding ``array``'s middle byte (numpy advises from the first page boundary on, so
    the first page may be a mapping of its own)."""
    address = array.ctypes.data + array.nbytes // 2
    inside = False
    for line in SMAPS.read_text().splitlines():
        head = line.split()[0]
        if "-" in head and not head.endswith(":"):
            low, high = (int(x, 16) for x in head.split("-"))
            inside = low <= address < high
        elif inside and head == "VmFlags:":
            return set(line.split()[1:])
    raise AssertionError("no mapping holds the array")


def fresh(code: str) -> dict:
    """``code`` run in a new Python process with this file's helpers and the film's module imported; it sets ``out``
    (a dict of sets of VmFlags), returned here."""
    script = f"""
import json
from pathlib import Path
import numpy as np
from rtreflect.integrator import film
from rtreflect.integrator.film import CHANNELS, Film
SMAPS, WIDTH, HEIGHT = Path({str(SMAPS)!r}), {WIDTH}, {HEIGHT}
{inspect.getsource(vm_flags)}
{code}
print(json.dumps({{key: sorted(value) for key, value in out.items()}}))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                          env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    return {key: set(value) for key, value in json.loads(done.stdout.splitlines()[-1]).items()}


PROBE = "out = {'numpy': vm_flags(np.empty((HEIGHT, WIDTH, len(CHANNELS)), dtype=np.float32))}"


def numpy_advises() -> bool:
    return SMAPS.exists() and "hg" in fresh(PROBE)["numpy"]


pytestmark = pytest.mark.skipif(not numpy_advises(), reason="numpy does not advise huge pages here")


def test_film_pixels_are_not_advised_huge_pages():
    flags = fresh("""
pixels = Film(WIDTH, HEIGHT).pixels
assert pixels.shape == (HEIGHT, WIDTH, len(CHANNELS)) and pixels.dtype == np.float32
out = {'film': vm_flags(pixels)}""")
    assert "hg" not in flags["film"]


def test_numpy_advice_is_restored_after_the_film():
    flags = fresh("""
keep = Film(WIDTH, HEIGHT)
out = {'after': vm_flags(np.empty((HEIGHT, WIDTH, len(CHANNELS)), dtype=np.float32))}""")
    assert "hg" in flags["after"]


def test_without_numpy_switch_the_film_is_a_private_mapping():
    flags = fresh("""
film._SET_MADVISE_HUGEPAGE = None
pixels = Film(WIDTH, HEIGHT).pixels
assert pixels.shape == (HEIGHT, WIDTH, len(CHANNELS)) and pixels.flags.writeable
pixels[-1, -1] = 7.0  # the whole buffer is there and writable
assert pixels[-1, -1, 0] == 7.0
out = {'film': vm_flags(pixels)}""")
    assert "hg" not in flags["film"]
