"""The pytest plugin (entry point ``pytest11``, loaded as `rtreflect.testing`): golden-image tests in one line.

The ``rtreflect_golden`` fixture renders a scene at golden size (`render_golden`) into the
test's temporary folder and checks it against its golden EXR with `assert_matches_golden`
(rtreflect's colour and AOV checks); a failure names the diff image. The goldens live in
the ``rtreflect_goldens`` ini folder (default ``golden_images``, relative to pytest's
rootdir) as ``STEM.exr`` and ``STEM.png``::

    def test_hood(rtreflect_golden):
        rtreflect_golden("scenes/hood.toml")

``pytest --rtreflect-update-goldens`` follows the snapshot-update convention
(pytest-regressions, syrupy): instead of failing, a test whose golden is missing, does
not match or cannot be compared rewrites it (EXR and PNG, atomically) and passes; a golden
that matches is left as it is (no churn from cross-machine float noise). Only the tests
that ran touch their goldens; the end of the run lists those rewritten, to review before
committing.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from .golden import assert_matches_golden, golden_reports, render_golden
from ..errors import RtreflectError
from ..output.imagefiles import atomic_path

UPDATE_OPTION = "--rtreflect-update-goldens"
GOLDENS_INI = "rtreflect_goldens"
_UPDATED = pytest.StashKey[list]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("rtreflect", "rtreflect golden images")
    group.addoption(UPDATE_OPTION, action="store_true", default=False,
                    help="Rewrite the golden image (EXR and PNG) of every rtreflect_golden test that ran and did not "
                         "match, instead of failing it; review the new images before committing them.")
    parser.addini(GOLDENS_INI, "Folder of golden images for rtreflect_golden, relative to the rootdir.",
                  default="golden_images")


def pytest_configure(config: pytest.Config) -> None:
    config.stash[_UPDATED] = []


def pytest_terminal_summary(terminalreporter, exitstatus, config: pytest.Config) -> None:
    updated = config.stash.get(_UPDATED, [])
    if updated:
        terminalreporter.write_sep("=", f"rtreflect: {len(updated)} golden image{'s' * (len(updated) != 1)} rewritten")
        for path in updated:
            terminalreporter.write_line(f"{path}  (review it, then commit it)")


def _replace(source: Path, target: Path) -> None:
    """Copy ``source`` over ``target`` atomically (readers see the old or the new file, never half of one)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(target) as tmp:
        shutil.copyfile(source, tmp)


@pytest.fixture
def rtreflect_golden(request: pytest.FixtureRequest, tmp_path: Path):
    """``check(scene, golden=None) -> Path``: render SCENE at golden size and assert it matches its golden EXR
    (default ``<rtreflect_goldens>/STEM.exr``); with ``--rtreflect-update-goldens`` rewrite a golden that does not
    match. Relative paths are from pytest's rootdir. Returns the rendered EXR."""
    config = request.config
    root = config.rootpath
    update = config.getoption(UPDATE_OPTION)

    def check(scene: str | os.PathLike, golden: str | os.PathLike | None = None) -> Path:
        scene = root / Path(scene)
        golden = root / Path(golden) if golden is not None else root / config.getini(GOLDENS_INI) / f"{scene.stem}.exr"
        actual = render_golden(scene, tmp_path)
        if update:
            try:
                matches = golden.is_file() and all(r.passed for r in golden_reports(actual, golden).values())
            except RtreflectError:  # another size or channel set: the golden is out of date too
                matches = False
            if not matches:
                _replace(actual, golden)
                _replace(actual.with_suffix(".png"), golden.with_suffix(".png"))
                config.stash[_UPDATED].append(golden)
            return actual
        if not golden.is_file():
            pytest.fail(f"{golden}: no golden image for {scene}; create it with: pytest {UPDATE_OPTION} "
                        f"(then look at {golden.with_suffix('.png')} before committing it)", pytrace=False)
        assert_matches_golden(actual, golden)
        return actual

    return check
