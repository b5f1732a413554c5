"""`rtreflect diff` and `rtreflect.testing.assert_images_match`: exit codes, the report, the
tolerance options, NaN handling and the diff image, on small images written here (whose
differences are known by construction) and on a golden image with one pixel changed.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from rtreflect.cli import cli
from rtreflect.ci.diff import DiffInputError, Tolerance, compare_images
from rtreflect.output.imagefiles import read_image
from rtreflect.testing import assert_images_match

GOLDEN_HOOD = Path(__file__).resolve().parent.parent / "golden_images" / "hood.exr"
RGBA = ("R", "G", "B", "A")


def write_exr(path: Path, pixels: np.ndarray, channels=RGBA) -> Path:
    pixels = np.ascontiguousarray(pixels, dtype=np.float32)
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.FLOAT)
    spec.channelnames = tuple(channels)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels) and out.close()
    return path


def write_png8(path: Path, codes: np.ndarray) -> Path:
    spec = oiio.ImageSpec(codes.shape[1], codes.shape[0], codes.shape[2], oiio.UINT8)
    spec.channelnames = RGBA[: codes.shape[2]]
    spec.attribute("oiio:UnassociatedAlpha", 1)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(np.ascontiguousarray(codes, dtype=np.uint8)) and out.close()
    return path


def run(*args: object):
    return CliRunner().invoke(cli, ["diff", *map(str, args)])


@pytest.fixture
def pair(tmp_path):
    """A 40×20 RGBA image and a copy with pixel (x=7, y=3) channel G raised by 0.01."""
    rng = np.random.default_rng(1)
    a = rng.uniform(0.0, 1.0, (20, 40, 4)).astype(np.float32)
    b = a.copy()
    b[3, 7, 1] += 0.01
    return write_exr(tmp_path / "a.exr", a), write_exr(tmp_path / "b.exr", b)


# -- verdicts and exit codes ---------------------------------------------------------------------------


def test_identical_images_exit_0(pair):
    result = run(pair[0], pair[0])
    assert result.exit_code == 0, result.output
    assert "MATCH" in result.output and "failing pixels (error > 1e-06): 0 of 800" in result.output


def test_one_changed_pixel_exits_1_and_is_named(pair, tmp_path):
    report_path = tmp_path / "report.json"
    result = run(*pair, "--json", report_path)
    assert result.exit_code == 1
    assert "max error 0.01 at pixel (x=7, y=3) channel G" in result.output
    assert "failing pixels (error > 1e-06): 1 of 800" in result.output and "MISMATCH" in result.output
    report = json.loads(report_path.read_text())
    assert report["max_error"]["x"] == 7 and report["max_error"]["y"] == 3 and report["max_error"]["channel"] == "G"
    assert report["max_error"]["value"] == pytest.approx(0.01, rel=1e-4)
    assert report["failing_pixels"] == 1 and report["status"] == "mismatch"
    # OpenImageIO's statistics over 800 pixels × 4 channels with a single error of 0.01.
    assert report["mean_error"] == pytest.approx(0.01 / 3200, rel=1e-4)
    assert report["rms_error"] == pytest.approx(np.sqrt(0.01**2 / 3200), rel=1e-4)
    assert report["psnr"] == pytest.approx(20 * np.log10(1.0 / report["rms_error"]), rel=1e-3)


def test_golden_with_one_pixel_changed(tmp_path):
    pixels, channels, _ = read_image(GOLDEN_HOOD)
    pixels[100, 200, channels.index("B")] += 0.25
    changed = write_exr(tmp_path / "hood.exr", pixels, channels)
    result = run(changed, GOLDEN_HOOD)
    assert result.exit_code == 1
    assert "at pixel (x=200, y=100) channel B" in result.output
    assert "failing pixels (error > 1e-06): 1 of" in result.output
    assert run(changed, GOLDEN_HOOD, "--channels", "N.X,N.Y,N.Z").exit_code == 0  # the AOVs are untouched


def test_fail_threshold(pair):
    assert run(*pair, "--fail", "0.02").exit_code == 0
    assert run(*pair, "--fail", "0.005").exit_code == 1


def test_failpercent(tmp_path):
    a = np.zeros((10, 10, 4))
    b = a.copy()
    b[0, :3, 0] = 0.5  # 3 of 100 pixels fail
    pa, pb = write_exr(tmp_path / "a.exr", a), write_exr(tmp_path / "b.exr", b)
    assert run(pa, pb, "--failpercent", "3").exit_code == 0  # at most 3% may fail
    assert run(pa, pb, "--failpercent", "2.9").exit_code == 1
    # hardfail: one error above it fails, whatever failpercent allows.
    assert run(pa, pb, "--failpercent", "5", "--hardfail", "0.4").exit_code == 1
    assert run(pa, pb, "--failpercent", "5", "--hardfail", "0.6").exit_code == 0


def test_warn_is_reported_but_exits_0(pair):
    result = run(*pair, "--fail", "0.1", "--warn", "0.001")
    assert result.exit_code == 0
    assert "warning pixels (error > 0.001): 1" in result.output and "WARNING" in result.output
    assert "WARNING" not in run(*pair, "--fail", "0.1", "--warn", "0.001", "--warnpercent", "1").output


def test_failrelative(tmp_path):
    a = np.full((4, 4, 1), 1000.0)
    b = a.copy()
    b[1, 1, 0] = 1000.05  # 5e-5 relative
    pa, pb = write_exr(tmp_path / "a.exr", a, ("f",)), write_exr(tmp_path / "b.exr", b, ("f",))
    assert run(pa, pb, "--fail", "1e-3").exit_code == 1
    assert run(pa, pb, "--fail", "1e-3", "--failrelative", "1e-4").exit_code == 0
    assert run(pa, pb, "--fail", "1e-3", "--failrelative", "1e-5").exit_code == 1
    assert run(pa, pb, "--failrelative", "2").exit_code == 2  # a relative difference never exceeds 2


def test_png_default_is_one_code_value(tmp_path):
    codes = np.full((8, 8, 4), 128, dtype=np.uint8)
    one, two = codes.copy(), codes.copy()
    one[2, 2, 0] += 1
    two[2, 2, 0] += 2
    base = write_png8(tmp_path / "base.png", codes)
    assert run(base, write_png8(tmp_path / "one.png", one)).exit_code == 0
    result = run(base, write_png8(tmp_path / "two.png", two))
    assert result.exit_code == 1 and "error > 0.00392" in result.output


def test_png_rounding_of_every_code_value_passes(tmp_path):
    """k/255 and (k+1)/255 read back as float32 can differ by a hair more than float32(1/255)."""
    k = np.arange(256 * 4, dtype=np.int64).reshape(16, 16, 4) % 255
    a = write_png8(tmp_path / "a.png", k.astype(np.uint8))
    b = write_png8(tmp_path / "b.png", (k + 1).astype(np.uint8))
    assert run(a, b).exit_code == 0


# -- NaN and infinities ------------------------------------------------------------------------------


def test_nan_against_nan_is_equal_and_against_a_number_fails(tmp_path):
    a = np.zeros((6, 8, 2))
    a[:, :4] = np.nan  # background AOVs
    b = a.copy()
    pa = write_exr(tmp_path / "a.exr", a, ("Z", "f"))
    assert run(pa, write_exr(tmp_path / "same.exr", b, ("Z", "f"))).exit_code == 0
    b[2, 5, 1] = np.nan  # a hit became a miss
    b[4, 1, 0] = 3.0  # a miss became a hit
    b[0, 6, 0] = 0.5  # an ordinary difference
    report = compare_images(pa, write_exr(tmp_path / "b.exr", b, ("Z", "f")))
    assert report.failing_pixels == 3 and report.nonfinite_mismatch_pixels == 2
    # The max error is infinite, at the first such value in scan order (rows from the top).
    assert report.max_error.value == np.inf
    assert (report.max_error.x, report.max_error.y, report.max_error.channel) == (5, 2, "f")
    # Mean and RMS stay finite: over the finite pairs only (OpenImageIO alone would make them NaN). Of the
    # 96 values, 47 are NaN in both images and 2 in one only: 47 finite pairs (issue 11: the count was 96).
    assert report.mean_error == pytest.approx(0.5 / 47, rel=1e-6)
    assert report.rms_error == pytest.approx(np.sqrt(0.5**2 / 47), rel=1e-6)
    assert report.status == "mismatch"
    # A pixel that fails both ways is counted once.
    b[2, 5, 0] = 7.0
    assert compare_images(pa, write_exr(tmp_path / "c.exr", b, ("Z", "f"))).failing_pixels == 3


def test_infinities(tmp_path):
    a = np.zeros((2, 2, 1))
    a[0, 0, 0] = np.inf
    b = a.copy()
    pa = write_exr(tmp_path / "a.exr", a, ("Z",))
    assert compare_images(pa, write_exr(tmp_path / "b.exr", b, ("Z",))).failing_pixels == 0
    b[0, 0, 0] = -np.inf
    assert compare_images(pa, write_exr(tmp_path / "c.exr", b, ("Z",))).failing_pixels == 1


# -- bad input ---------------------------------------------------------------------------------------


def test_missing_file_exits_2(pair, tmp_path):
    result = run(pair[0], tmp_path / "nope.exr")
    assert result.exit_code == 2
    assert result.output.strip() == f"rtreflect: error: {tmp_path / 'nope.exr'}: no such file"


def test_different_sizes_exit_2(tmp_path):
    a = write_exr(tmp_path / "a.exr", np.zeros((4, 8, 4)))
    b = write_exr(tmp_path / "b.exr", np.zeros((4, 4, 4)))
    result = run(a, b)
    assert result.exit_code == 2
    assert f"different sizes: {a} is 8×4, {b} is 4×4" in result.output


def test_different_channel_sets_exit_2(tmp_path):
    a = write_exr(tmp_path / "a.exr", np.zeros((4, 4, 5)), RGBA + ("Z",))
    b = write_exr(tmp_path / "b.exr", np.zeros((4, 4, 4)))
    result = run(a, b)
    assert result.exit_code == 2
    assert f"different channel sets: only in {a}: Z; only in {b}: (none)" in result.output
    assert run(a, b, "--channels", "R,G,B,A").exit_code == 0  # a subset both have
    result = run(a, b, "--channels", "R,Z")
    assert result.exit_code == 2 and f"{b}: --channels: no channel Z (it has R,G,B,A)" in result.output
    assert run(a, b, "--channels", "R,,G").exit_code == 2


def test_unreadable_file_exits_2(tmp_path, pair):
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"not an image")
    result = run(pair[0], junk)
    assert result.exit_code == 2 and str(junk) in result.output and "Traceback" not in result.output


def test_bad_input_writes_nothing(tmp_path, pair):
    out = tmp_path / "out"
    out.mkdir()
    run(pair[0], tmp_path / "nope.exr", "--diff-image", out / "d.png", "--json", out / "r.json")
    assert list(out.iterdir()) == []


# -- the diff image ----------------------------------------------------------------------------------


def test_diff_image_highlights_the_changed_region(tmp_path):
    grey = np.full((30, 60, 4), 0.5)
    grey[..., 3] = 1.0
    changed = grey.copy()
    changed[10:14, 40:46, :3] = 0.9  # a 6×4 block
    changed[2, 2, 0] = 0.5 + 5e-7  # below --fail: not marked
    a, b = write_exr(tmp_path / "a.exr", grey), write_exr(tmp_path / "b.exr", changed)
    out = tmp_path / "new folder" / "diff.png"  # the folder is created
    assert run(a, b, "--diff-image", out).exit_code == 1
    picture, channels, _ = read_image(out)
    assert picture.shape == (30, 60, 4) and channels == RGBA
    rgb = picture[..., :3]
    inside = np.zeros((30, 60), dtype=bool)
    inside[10:14, 40:46] = True
    # Elsewhere: a dimmed grey copy of A (R = G = B, darker than A's 0.5 linear, i.e. 0.735 in sRGB).
    assert np.all(rgb[~inside].max(axis=-1) == rgb[~inside].min(axis=-1))
    assert rgb[~inside].max() < 0.5
    # In the changed block: saturated colour, brighter than anything outside.
    chroma = rgb[inside].max(axis=-1) - rgb[inside].min(axis=-1)
    assert chroma.min() > 0.5 and rgb[inside].max(axis=-1).min() > rgb[~inside].max()


def test_diff_image_marks_exactly_the_counted_pixels(tmp_path):
    report_args = Tolerance(fail=0.05, failrelative=0.1)
    rng = np.random.default_rng(7)
    a = rng.uniform(-2, 2, (16, 16, 3))
    b = a + rng.normal(0, 0.05, a.shape)
    report = compare_images(write_exr(tmp_path / "a.exr", a, ("x", "y", "z")),
                            write_exr(tmp_path / "b.exr", b, ("x", "y", "z")), None, report_args)
    assert 0 < report.failing_pixels < 256
    assert int((report.excess > 1).sum()) == report.failing_pixels


@settings(max_examples=25, deadline=None)
@given(st.floats(0, 0.2), st.floats(0, 0.5), st.integers(0, 2**32 - 1))
def test_excess_map_agrees_with_openimageio(tmp_path_factory, fail, failrelative, seed):
    """Our per-value restatement of the failure rule (for the picture) agrees with OpenImageIO's count."""
    folder = tmp_path_factory.mktemp("excess")
    rng = np.random.default_rng(seed)
    a = rng.uniform(-1, 1, (8, 8, 2)).astype(np.float32)
    b = (a + rng.normal(0, 0.1, a.shape) * (rng.uniform(size=a.shape) < 0.3)).astype(np.float32)
    report = compare_images(write_exr(folder / "a.exr", a, ("p", "q")), write_exr(folder / "b.exr", b, ("p", "q")),
                            None, Tolerance(fail=fail, failrelative=failrelative))
    assert int((report.excess > 1).sum()) == report.failing_pixels


# -- assert_images_match -----------------------------------------------------------------------------


def test_assert_images_match_passes_and_returns_the_report(pair):
    report = assert_images_match(pair[0], pair[1], fail=0.02)
    assert report.passed and report.max_error.channel == "G"


def test_assert_images_match_failure_writes_diff_image_next_to_actual(pair):
    actual, golden = pair
    with pytest.raises(AssertionError) as failure:
        assert_images_match(actual, golden)
    diff_png = actual.with_name("a.diff.png")
    assert diff_png.exists()
    message = str(failure.value)
    assert f"diff image: {diff_png}" in message and "(x=7, y=3) channel G" in message


def test_assert_images_match_bad_input(tmp_path, pair):
    with pytest.raises(AssertionError, match="no such file"):
        assert_images_match(pair[0], tmp_path / "missing.exr")
    with pytest.raises(DiffInputError):
        compare_images(pair[0], tmp_path / "missing.exr")


def test_channels_as_comma_string(tmp_path, pair):
    copy = shutil.copy(pair[0], tmp_path / "copy.exr")
    assert assert_images_match(copy, pair[0], channels="R,G").channels == ("R", "G")


def test_console_script_exit_codes(pair, tmp_path):
    """The installed command, not just the click group: stdout report, stderr error line, exit codes."""
    command = [str(Path(sys.executable).parent / "rtreflect")]  # this venv's, whatever PATH says
    same = subprocess.run(command + ["diff", str(pair[0]), str(pair[0])], capture_output=True, text=True)
    differ = subprocess.run(command + ["diff", *map(str, pair)], capture_output=True, text=True)
    missing = subprocess.run(command + ["diff", str(pair[0]), str(tmp_path / "x.exr")], capture_output=True, text=True)
    assert (same.returncode, differ.returncode, missing.returncode) == (0, 1, 2)
    assert "MISMATCH" in differ.stdout and missing.stdout == ""
    assert missing.stderr.strip().endswith("x.exr: no such file") and len(missing.stderr.strip().splitlines()) == 1


# -- windows and bounded memory (issue 11) -----------------------------------------------------------


def test_data_window_offset_is_not_identical(tmp_path):
    """The same pixels with the data window moved by 10 px sit elsewhere in the image: bad input, not "identical"."""
    pixels = np.random.default_rng(4).uniform(0, 1, (20, 40, 4)).astype(np.float32)
    a = write_exr(tmp_path / "a.exr", pixels)
    spec = oiio.ImageSpec(40, 20, 4, oiio.FLOAT)
    spec.channelnames = RGBA
    spec.x, spec.y = 10, 10
    spec.full_x, spec.full_y, spec.full_width, spec.full_height = 0, 0, 40, 20
    out = oiio.ImageOutput.create(str(tmp_path / "b.exr"))
    assert out.open(str(tmp_path / "b.exr"), spec) and out.write_image(pixels) and out.close()
    result = run(a, tmp_path / "b.exr")
    assert result.exit_code == 2, result.output
    assert result.output.count("\n") == 1 and "different image windows" in result.output
    assert "data window 40×20 at (10, 10)" in result.output


@pytest.mark.parametrize("chunk_values", [1, 37 * 4, 1 << 22])
def test_chunked_comparison_equals_the_whole_image_result(tmp_path, monkeypatch, chunk_values):
    """Any chunking gives the whole-image numbers: counts, max error and its pixel, the first NaN mismatch
    (in a later chunk than a finite error), mean and RMS over the finite pairs (recomputed here with numpy),
    the excess map and the diff image."""
    import rtreflect.ci.diff as diffing

    rng = np.random.default_rng(11)
    a = rng.uniform(0, 1, (31, 37, 4)).astype(np.float32)
    a[:, :5] = np.nan  # background
    b = a.copy()
    b[3, 20, 1] += 0.25  # the max error, early
    b[17:19, 8:30, 0] += rng.normal(0, 0.01, (2, 22)).astype(np.float32)
    b[25, 30, 2] = np.nan  # a hit became a miss, later
    pa, pb = write_exr(tmp_path / "a.exr", a), write_exr(tmp_path / "b.exr", b)
    monkeypatch.setattr(diffing, "CHUNK_VALUES", chunk_values)
    report = compare_images(pa, pb)
    assert report.failing_pixels == 1 + int((np.abs(b[17:19, 8:30, 0] - a[17:19, 8:30, 0]) > 1e-6).sum()) + 1
    assert report.nonfinite_mismatch_pixels == 1
    first = report.first_nonfinite_mismatch
    assert (first.x, first.y, first.channel) == (30, 25, "B") and report.max_error == first
    finite = np.isfinite(a) & np.isfinite(b)
    error = np.abs(a[finite].astype(np.float64) - b[finite])
    assert report.mean_error == pytest.approx(error.mean(), rel=1e-5)
    assert report.rms_error == pytest.approx(np.sqrt((error**2).mean()), rel=1e-5)
    whole = tmp_path / "whole.png"
    monkeypatch.setattr(diffing, "CHUNK_VALUES", 1 << 30)
    reference = compare_images(pa, pb)
    reference.write_diff_image(whole)
    np.testing.assert_array_equal(report.excess, reference.excess)
    report.write_diff_image(tmp_path / "chunked.png")
    assert (tmp_path / "chunked.png").read_bytes() == whole.read_bytes()
    b[25, 30, 2] = a[25, 30, 2]  # no mismatch now: the max error is the finite one, at its pixel
    monkeypatch.setattr(diffing, "CHUNK_VALUES", chunk_values)
    report = compare_images(pa, write_exr(tmp_path / "c.exr", b))
    assert (report.max_error.x, report.max_error.y, report.max_error.channel) == (20, 3, "G")
    assert report.max_error.value == pytest.approx(0.25, rel=1e-5)
