"""The small frictions a new user met (issue 10), each as it was reported.

README's diff example after the quick start; `render` of a folder; `render` and `batch`
agreeing on duplicates and the output folder; a short row of control points blamed on
itself; the samples-per-pixel summary; all of a scene's errors at once; a PNG diffed
against an EXR.
"""

from __future__ import annotations

import copy
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from rtreflect.cli import cli
from test_scene_errors import control_net, toml_document, valid_scene

ROOT = Path(__file__).resolve().parent.parent
RTREFLECT = Path(sys.executable).parent / "rtreflect"
SMALL = ["--width", "32", "--height", "18", "--samples", "1"]


def run(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """The command line as users run it (`python -m`-free: the project's `main` in this interpreter)."""
    return subprocess.run([sys.executable, "-c", "from rtreflect.cli import main; main()", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, env={**os.environ, "PYTHONPATH": str(ROOT)})


def write(path: Path, scene: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(toml_document(scene))
    return path


def test_readme_diff_example_works_after_the_quick_start(tmp_path: Path) -> None:
    """The commands of README's `rtreflect diff A B` block, as written, in a fresh copy of the project folder."""
    readme = (ROOT / "README.md").read_text()
    block = re.search(r"### `rtreflect diff A B`.*?```\n(.*?)```", readme, re.S)[1]
    commands = [shlex.split(line) for line in block.splitlines() if line.startswith("rtreflect ")]
    assert [c[1] for c in commands] == ["render", "diff"]
    for folder in ("scenes", "golden_images"):
        shutil.copytree(ROOT / folder, tmp_path / folder)
    # The quick start first (full size), then the block.
    assert run("render", "scenes/hood.toml", "-o", "out/", cwd=tmp_path).returncode == 0
    for command in commands:
        done = run(*command[1:], cwd=tmp_path)
        assert done.returncode == 0, (command, done.stdout, done.stderr)
    assert "MATCH" in done.stdout and (tmp_path / "out" / "hood.json").is_file()
    # `diff --help` shows the same working commands.
    help_text = CliRunner().invoke(cli, ["diff", "--help"]).output
    for command in commands:
        assert " ".join(command) in help_text


def test_render_of_a_folder_says_to_use_batch(tmp_path: Path) -> None:
    scenes = tmp_path / "scenes"
    write(scenes / "a.toml", valid_scene())
    done = run("render", scenes, cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        f"rtreflect: error: {scenes}: is a folder; `rtreflect render` takes scene files: render every scene in a "
        f"folder with `rtreflect batch {scenes} -o out`"]
    assert not (tmp_path / "out").exists()


def test_render_renders_a_scene_named_twice_once_like_batch(tmp_path: Path) -> None:
    scene = write(tmp_path / "a.toml", valid_scene())
    result = CliRunner().invoke(cli, ["render", str(scene), str(tmp_path / "." / "a.toml"), "-o", str(tmp_path / "out"),
                                      *SMALL])
    assert result.exit_code == 0, result.output
    assert len(result.stdout.splitlines()) == 1  # one summary line: rendered once
    batch = CliRunner().invoke(cli, ["batch", str(scene), str(scene), "-o", str(tmp_path / "out2"), "-j", "1"])
    assert batch.exit_code == 0, batch.output
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(p.name for p in (tmp_path / "out2").iterdir())


def test_batch_writes_to_out_by_default_like_render(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    write(tmp_path / "scenes" / "a.toml", valid_scene())
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli, ["batch", "scenes", "-j", "1"])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["base.exr", "base.png"]


@pytest.mark.parametrize("short_row", [0, 2, 3])
def test_a_short_row_of_control_points_is_blamed_on_itself(short_row: int, tmp_path: Path) -> None:
    scene = valid_scene()
    points = control_net()
    points[short_row] = points[short_row][:3]
    scene["surface"][0]["points"] = points
    result = CliRunner().invoke(cli, ["render", str(write(tmp_path / "s.toml", scene)), "-o", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert result.stderr == (f"rtreflect: error: {tmp_path / 's.toml'}: surface[0].points[{short_row}]: must have 4 "
                             f"entries like the other 3 rows, got 3\n")


def test_a_short_row_of_two_is_blamed_against_the_first(tmp_path: Path) -> None:
    """No majority in two rows: the second is named, against the first (as before)."""
    scene = valid_scene()
    scene["surface"][0].update(degree=[1, 3], knots_u=[0.0, 0.0, 1.0, 1.0], weights=[[1.0] * 4, [1.0] * 4],
                               points=[control_net()[0], control_net()[1][:3]])
    result = CliRunner().invoke(cli, ["render", str(write(tmp_path / "s.toml", scene)), "-o", str(tmp_path / "o")])
    assert "surface[0].points[1]: must have 4 entries like surface[0].points[0], got 3" in result.stderr


@pytest.mark.parametrize("samples, text", [(1, "1×1 = 1 sample/px"), (3, "3×3 = 9 samples/px"),
                                           ("analytic", "analytic AA")])
def test_summary_says_the_sample_grid(samples: int | str, text: str, tmp_path: Path) -> None:
    scene = write(tmp_path / "a.toml", valid_scene())
    result = CliRunner().invoke(cli, ["render", str(scene), "-o", str(tmp_path / "out"), "--width", "32", "--height",
                                      "18", "--samples", str(samples)])
    assert result.exit_code == 0, result.output
    assert f"base: 32×18, {text}, " in result.stdout


def test_all_independent_errors_of_a_scene_at_once(tmp_path: Path) -> None:
    scene = copy.deepcopy(valid_scene())
    scene["image"]["width"] = 0
    scene["camera"]["fov"] = 200.0
    scene["lights"]["raduis"] = 0.1
    scene["lights"]["colour"] = [1.0, 1.0, 1.0]
    scene["surface"][0]["weights"][1][1] = -1.0
    scene["surface"].append({"file": "missing.bpt"})
    scene["output"]["name"] = "a/b"
    path = write(tmp_path / "s.toml", scene)
    done = subprocess.run([str(RTREFLECT), "render", str(path), "-o", str(tmp_path / "out")], capture_output=True,
                          text=True) if RTREFLECT.exists() else run("render", path, "-o", tmp_path / "out")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.splitlines() == [f"rtreflect: error: {path}: {line}" for line in [
        "image.width: must be >= 1, got 0",
        "camera.fov: must be < 180, got 200.0",
        "lights.colour: unknown key; see docs/scene-format.md for the keys of this table",
        "lights.raduis: unknown key; did you mean radius?",
        "output.name: must be a plain file stem without path separators or control characters, got 'a/b'",
        "surface[0].weights[1][1]: weights must be > 0, got -1",
    ]] + [f"rtreflect: error: {tmp_path / 'missing.bpt'}: geometry file not found (from {path}: surface[1].file)"]
    assert not (tmp_path / "out").exists()


def test_png_against_exr_compares_like_values(tmp_path: Path) -> None:
    """An EXR and the PNG rtreflect wrote of it match; an EXR whose colour changed by 2 codes does not; before,
    the two were refused (different channel sets) or, with --channels R,G,B,A, compared linear with sRGB."""
    scene = write(tmp_path / "a.toml", valid_scene())
    assert CliRunner().invoke(cli, ["render", str(scene), "-o", str(tmp_path), "--width", "64", "--height", "36",
                                    "--samples", "2"]).exit_code == 0
    exr, png = tmp_path / "base.exr", tmp_path / "base.png"
    for a, b in ((png, exr), (exr, png)):
        for extra in ([], ["--channels", "R,G,B,A"]):
            result = CliRunner().invoke(cli, ["diff", str(a), str(b), *extra])
            assert result.exit_code == 0, result.output
            assert f"{exr} (linear float) converted to 8-bit sRGB" in result.output
    # A mid-grey surface pixel brightened by two sRGB code values fails as a PNG would. The surface is shaded
    # (`[render] shading`), so its grey is 0.18 scaled by the pixel's shade: any surface pixel off the lines.
    buf = oiio.ImageBuf(str(exr))
    pixels = buf.get_pixels(oiio.FLOAT)
    y, x = np.argwhere((pixels[..., 3] == 1) & (pixels[..., 0] > 0.05) & (pixels[..., 0] <= 0.18 + 1e-6))[0]
    srgb = lambda v: 1.055 * v ** (1 / 2.4) - 0.055  # noqa: E731 (closed form of the sRGB curve, v > 0.0031308)
    linear = lambda e: ((e + 0.055) / 1.055) ** 2.4  # noqa: E731
    pixels[y, x, 0] = linear(srgb(pixels[y, x, 0]) + 2 / 255)
    changed = tmp_path / "changed.exr"
    spec = buf.spec()
    out = oiio.ImageOutput.create(str(changed))
    assert out.open(str(changed), spec) and out.write_image(pixels) and out.close()
    result = CliRunner().invoke(cli, ["diff", str(png), str(changed)])
    assert result.exit_code == 1, result.output
    assert re.search(rf"max error 0\.00784\d* at pixel \(x={x}, y={y}\) channel R", result.output), result.output
    assert "failing pixels (error > 0.00392257): 1 of 2304" in result.output
    # An EXR without colour cannot be compared with a PNG.
    aov_only = tmp_path / "aov.exr"
    spec = oiio.ImageSpec(64, 36, 1, oiio.FLOAT)
    spec.channelnames = ("f",)
    out = oiio.ImageOutput.create(str(aov_only))
    assert out.open(str(aov_only), spec) and out.write_image(np.zeros((36, 64, 1), np.float32)) and out.close()
    result = CliRunner().invoke(cli, ["diff", str(png), str(aov_only)])
    assert result.exit_code == 2 and "needs the channels R,G,B,A to encode as sRGB; it has no R,G,B,A" in result.stderr


def test_batch_lists_every_problem_of_a_scene_on_its_one_line(tmp_path: Path) -> None:
    scene = valid_scene()
    scene["image"]["width"] = 0
    scene["lights"]["raduis"] = 0.1
    path = write(tmp_path / "s.toml", scene)
    result = CliRunner().invoke(cli, ["batch", str(path), "-o", str(tmp_path / "out"), "--json", str(tmp_path / "r.json")])
    assert result.exit_code == 1
    error = __import__("json").loads((tmp_path / "r.json").read_text())["scenes"][0]["error"]
    assert error == (f"{path}: image.width: must be >= 1, got 0; "
                     f"{path}: lights.raduis: unknown key; did you mean radius?")
