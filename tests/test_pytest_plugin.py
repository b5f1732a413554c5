"""The pytest plugin (issue 17): `rtreflect_golden` and `--rtreflect-update-goldens`, run in a separate pytest.

A small project is made in pytester's folder: three scenes and a test per scene. The
judge of "rewritten" is the golden file's bytes (and, for untouched goldens, that they
stay byte-identical); the judge of "matches" is a second plain run that passes.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from test_batch import small_scene

pytest_plugins = ["pytester"]
ROOT = Path(__file__).resolve().parent.parent
NAMES = ("alpha", "beta", "gamma")
SOURCES = {"alpha": "hood", "beta": "g1_join", "gamma": "cylinder"}


@pytest.fixture
def project(pytester):
    for name in NAMES:
        small_scene(SOURCES[name], pytester.path / "scenes" / f"{name}.toml", samples=1)
    pytester.makepyfile(test_parts="\n".join(
        f"def test_{name}(rtreflect_golden):\n    rtreflect_golden('scenes/{name}.toml')\n" for name in NAMES))
    return pytester


def run(pytester, *args):
    # A separate interpreter: the plugin is loaded as users load it, not from this process's imports.
    return pytester.runpytest_subprocess("-p", "rtreflect.testing", "-p", "no:cacheprovider", *args)


def goldens(path: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((path / "golden_images").glob("*"))}


def widen_tubes(scene: Path) -> None:
    """Make the light tubes half as wide again: a real change of the reflection lines' width."""
    edited, n = re.subn(r"(?m)^radius = ([-0-9.e]+)$", lambda m: f"radius = {float(m.group(1)) * 1.5!r}",
                        scene.read_text(), count=1)
    assert n == 1, "scene has no [lights] radius"
    scene.write_text(edited)


def test_missing_golden_fails_and_names_the_update_option(project):
    result = run(project)
    result.assert_outcomes(failed=3)
    result.stdout.fnmatch_lines(["*no golden image for*--rtreflect-update-goldens*"])


def test_update_rewrites_exactly_the_goldens_of_the_tests_that_ran_and_then_they_pass(project):
    run(project, "--rtreflect-update-goldens").assert_outcomes(passed=3)
    first = goldens(project.path)
    assert sorted(first) == sorted(f"{n}.{ext}" for n in NAMES for ext in ("exr", "png"))
    run(project).assert_outcomes(passed=3)

    for name in NAMES:
        widen_tubes(project.path / "scenes" / f"{name}.toml")
    result = run(project, "-k", "alpha or beta")
    result.assert_outcomes(failed=2, deselected=1)
    # the assertion message names the diff image, which exists
    diff_images = re.findall(r"diff image: (\S+\.diff\.png)", result.stdout.str())
    assert diff_images and all(Path(p).is_file() for p in diff_images), result.stdout.str()

    result = run(project, "--rtreflect-update-goldens", "-k", "alpha or beta")
    result.assert_outcomes(passed=2, deselected=1)
    result.stdout.fnmatch_lines(["*rtreflect: 2 golden images rewritten*", "*alpha.exr*", "*beta.exr*"])
    second = goldens(project.path)
    changed = {name for name in second if second[name] != first[name]}
    assert changed == {"alpha.exr", "alpha.png", "beta.exr", "beta.png"}  # gamma's did not run: untouched
    run(project, "-k", "alpha or beta").assert_outcomes(passed=2, deselected=1)
    run(project, "-k", "gamma").assert_outcomes(failed=1, deselected=2)  # still stale: it was not rewritten

    run(project, "--rtreflect-update-goldens").assert_outcomes(passed=3)
    third = goldens(project.path)
    assert {name for name in third if third[name] != second[name]} == {"gamma.exr", "gamma.png"}  # matches kept


def test_entry_point_loads_the_plugin_without_p(tmp_path, pytester, monkeypatch):
    """The pyproject's pytest11 entry point, as an install records it (the package's metadata built by setuptools),
    makes pytest load the plugin with no `-p`: the fixture is found; `-p rtreflect.testing` as well loads it once."""
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["pytest11"]
    assert declared == {"rtreflect.testing": "rtreflect.testing"}
    metadata = tmp_path / "metadata"
    metadata.mkdir()
    built = subprocess.run([sys.executable, "-c", "from setuptools import setup; setup()", "egg_info", "--egg-base",
                            str(metadata)], cwd=ROOT, capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    entry_points = (metadata / "rtreflect.egg-info" / "entry_points.txt").read_text()
    assert "[pytest11]\nrtreflect.testing = rtreflect.testing" in entry_points
    pytester.makepyfile(test_fixture="def test_found(request):\n"
                                     "    assert 'rtreflect_golden' in request.fixturenames or "
                                     "request.getfixturevalue('rtreflect_golden')\n")
    monkeypatch.setenv("PYTHONPATH", f"{metadata}:{ROOT}")
    pytester.runpytest_subprocess("-p", "no:cacheprovider").assert_outcomes(passed=1)
    pytester.runpytest_subprocess("-p", "no:cacheprovider", "-p", "rtreflect.testing").assert_outcomes(passed=1)
