"""The film's memory (integrator/film.py `plain_pages`): not advised MADV_HUGEPAGE, whatever numpy advises.

The kernel's own record is the judge: /proc/self/smaps lists each mapping's VmFlags, "hg" where madvise
(MADV_HUGEPAGE) was asked for it. The tests run where a plain np.empty of the same size is so advised (Linux with
transparent huge pages and a numpy that advises), else they could not tell the two apart and are skipped.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rtreflect.integrator import film
from rtreflect.integrator.film import CHANNELS, Film

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


def numpy_advises() -> bool:
    if not SMAPS.exists():
        return False
    probe = np.empty((HEIGHT, WIDTH, len(CHANNELS)), dtype=np.float32)
    return "hg" in vm_flags(probe)


pytestmark = pytest.mark.skipif(not numpy_advises(), reason="numpy does not advise huge pages here")


def test_film_pixels_are_not_advised_huge_pages():
    pixels = Film(WIDTH, HEIGHT).pixels
    assert pixels.shape == (HEIGHT, WIDTH, len(CHANNELS)) and pixels.dtype == np.float32
    assert "hg" not in vm_flags(pixels)


def test_numpy_advice_is_restored_after_the_film():
    Film(WIDTH, HEIGHT)
    after = np.empty((HEIGHT, WIDTH, len(CHANNELS)), dtype=np.float32)
    assert "hg" in vm_flags(after)


def test_without_numpy_switch_the_film_is_a_private_mapping(monkeypatch):
    monkeypatch.setattr(film, "_SET_MADVISE_HUGEPAGE", None)
    pixels = Film(WIDTH, HEIGHT).pixels
    assert pixels.shape == (HEIGHT, WIDTH, len(CHANNELS)) and pixels.flags.writeable
    assert "hg" not in vm_flags(pixels)
    pixels[-1, -1] = 7.0  # the whole buffer is there and writable
    assert pixels[-1, -1, 0] == 7.0
