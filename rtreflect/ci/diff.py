"""Image comparison for CI: two images, OpenImageIO's ``ImageBufAlgo.compare``, a visual diff.

The statistics (mean, RMS and max error with its pixel and channel, PSNR, failing and
warning pixel counts) are OpenImageIO's, computed over the selected channels. The
pass/fail rule is OpenImageIO ``idiff``'s: a value *fails* when it differs by more than
``fail`` and (if ``failrelative`` is set) by more than ``failrelative`` times the mean of
the two values' magnitudes; a pixel fails when any selected channel fails; the images
mismatch when more than ``failpercent`` percent of the pixels fail, or when the max error
exceeds ``hardfail``; otherwise they *warn* when more than ``warnpercent`` percent of the
pixels differ by more than ``warn`` (and ``warnrelative``).

**NaN and infinities.** rtreflect's AOVs are NaN on the background (DESIGN.md, "EXR
channels"). OpenImageIO 3.2's compare treats NaN against NaN (and +Inf against +Inf)
as equal, which is what we want, but NaN against a number only sets the max error to
infinity: the pixel is *not* counted as failing, and the NaN then poisons the mean and
RMS. So non-finite values are settled here before OpenImageIO sees them: where both
images hold the same non-finite value the pair compares equal; where only one does
(a silhouette moved, a hit became a miss) the pixel fails, the max error is infinite
at the first such value (as OpenImageIO reports it), and mean, RMS and PSNR are taken
over the finite pairs only (the non-finite pair contributes 0).
"""

from __future__ import annotations

import contextlib
import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # colour-science warns at import about optional features we do not use
    import colour

from ..errors import RtreflectError
from ..integrator.film import COLOR_CHANNELS
from ..output.imagefiles import atomic_path, encode_srgb, read_image, write_png

#: Default ``fail`` for float images: float32 noise passes, any real change fails.
FLOAT_FAIL = 1e-6
#: Slack on one integer code value: OpenImageIO reads code k of 8 bits as float32(k/255),
#: and the difference of two such floats can exceed float32(1/255) by ~3e-8.
CODE_VALUE_SLACK = 1e-6
#: How far the diff image dims the copy of A that it draws under the differences.
DIM = 0.15


class DiffInputError(RtreflectError):
    """Images that cannot be compared: missing, unreadable, different sizes or channel sets (exit 2)."""


@dataclass(frozen=True)
class Tolerance:
    """Thresholds in the spirit of OpenImageIO's ``idiff``; ``None`` means the default for the files."""

    fail: float | None = None  # per-channel absolute difference that makes a pixel fail
    failrelative: float = 0.0  # ... and relative difference |a − b| / ((|a| + |b|)/2), when not 0
    failpercent: float = 0.0  # percent of pixels allowed to fail
    hardfail: float = math.inf  # any single error above this fails, whatever failpercent says
    warn: float | None = None  # per-channel difference that makes a pixel warn (default: fail)
    warnrelative: float | None = None  # default: failrelative
    warnpercent: float = 0.0  # percent of pixels allowed to warn before the result is a warning


@dataclass(frozen=True)
class PixelError:
    value: float
    x: int
    y: int
    channel: str

    def __str__(self) -> str:
        return f"{self.value:.6g} at pixel (x={self.x}, y={self.y}) channel {self.channel}"


@dataclass
class DiffReport:
    """Result of comparing A with B: OpenImageIO's statistics, the counts and the verdict."""

    a: Path
    b: Path
    width: int
    height: int
    channels: tuple[str, ...]
    fail: float
    failrelative: float
    failpercent: float
    hardfail: float
    warn: float
    warnrelative: float
    warnpercent: float
    mean_error: float
    rms_error: float
    psnr: float  # dB; inf when the images are identical
    max_error: PixelError | None  # None when no value differs
    failing_pixels: int
    warning_pixels: int
    nonfinite_mismatch_pixels: int  # pixels where only one image is NaN/Inf (counted as failing)
    first_nonfinite_mismatch: PixelError | None
    status: str  # "match", "warn" or "mismatch"
    # For the diff image, not part of the report proper: per pixel, the largest ratio over the channels
    # of |A − B| to its warn or fail threshold, whichever is lower (> 1: the pixel warns or fails; inf where
    # only one image is non-finite), and A's greyscale.
    excess: np.ndarray = field(repr=False, default=None)
    background: np.ndarray = field(repr=False, default=None)
    converted: str | None = None  # which image was converted to the other's colour encoding, and how

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def passed(self) -> bool:
        """True for "match" and "warn": the images agree within the tolerance."""
        return self.status != "mismatch"

    def summary(self) -> list[str]:
        """The human-readable report, one fact per line."""
        pct = lambda n: 100.0 * n / self.pixels  # noqa: E731
        lines = [
            f"{self.a} vs {self.b}: {self.width}×{self.height}, channels {','.join(self.channels)}",
            *([f"  {self.converted}"] if self.converted else []),
            f"  mean error {self.mean_error:.6g}, RMS error {self.rms_error:.6g}, PSNR {self.psnr:.2f} dB",
            f"  max error {self.max_error}" if self.max_error else "  max error 0 (identical)",
            f"  failing pixels (error > {_threshold(self.fail, self.failrelative)}): {self.failing_pixels} "
            f"of {self.pixels} ({pct(self.failing_pixels):.4g}%, allowed {self.failpercent:g}%)",
        ]
        if self.warn != self.fail or self.warnrelative != self.failrelative or self.warnpercent:
            lines.append(f"  warning pixels (error > {_threshold(self.warn, self.warnrelative)}): "
                         f"{self.warning_pixels} ({pct(self.warning_pixels):.4g}%, allowed {self.warnpercent:g}%)")
        if self.nonfinite_mismatch_pixels:
            lines.append(f"  NaN/Inf in one image only: {self.nonfinite_mismatch_pixels} pixels, first "
                         f"(x={self.first_nonfinite_mismatch.x}, y={self.first_nonfinite_mismatch.y}) "
                         f"channel {self.first_nonfinite_mismatch.channel}")
        if math.isfinite(self.hardfail):
            lines.append(f"  hardfail {self.hardfail:.6g}")
        lines.append({"match": "MATCH", "warn": "WARNING: differences within tolerance",
                      "mismatch": "MISMATCH"}[self.status])
        return lines

    def to_json(self) -> dict:
        """The report as JSON-ready data (infinities as null: JSON has no infinity)."""
        finite = lambda v: v if math.isfinite(v) else None  # noqa: E731
        where = lambda e: None if e is None else {"value": finite(e.value), "x": e.x, "y": e.y,  # noqa: E731
                                                  "channel": e.channel}
        return {
            "a": str(self.a), "b": str(self.b), "width": self.width, "height": self.height,
            "channels": list(self.channels),
            "tolerance": {"fail": self.fail, "failrelative": self.failrelative, "failpercent": self.failpercent,
                          "hardfail": finite(self.hardfail), "warn": self.warn, "warnrelative": self.warnrelative,
                          "warnpercent": self.warnpercent},
            "mean_error": self.mean_error, "rms_error": self.rms_error, "psnr": finite(self.psnr),
            "max_error": where(self.max_error),
            "pixels": self.pixels, "failing_pixels": self.failing_pixels, "warning_pixels": self.warning_pixels,
            "nonfinite_mismatch_pixels": self.nonfinite_mismatch_pixels,
            "first_nonfinite_mismatch": where(self.first_nonfinite_mismatch),
            "status": self.status, "converted": self.converted,
        }

    def write_diff_image(self, path: Path) -> None:
        """A PNG showing where A and B differ (see `diff_image`), written atomically (folder created)."""
        self.write_files(diff_png=path)

    def write_files(self, diff_png: Path | None = None, json_path: Path | None = None) -> None:
        """The diff image and/or the JSON report: both appear together, or neither (atomic renames)."""
        writers = []
        if diff_png is not None:
            final = Path(diff_png)
            writers.append((final, lambda tmp, final=final: write_png(tmp, diff_image(self.background, self.excess),
                                                                      final=final)))
        if json_path is not None:
            writers.append((Path(json_path), lambda tmp: tmp.write_text(json.dumps(self.to_json(), indent=2) + "\n")))
        target = None
        try:
            with contextlib.ExitStack() as stack:
                for target, write in writers:
                    target.parent.mkdir(parents=True, exist_ok=True)
                    write(stack.enter_context(atomic_path(target)))
        except OSError as exc:
            raise RtreflectError(f"{exc.filename2 or target}: cannot write ({exc.strerror or exc})") from None


def _threshold(absolute: float, relative: float) -> str:
    return f"{absolute:.6g}" + (f" and > {relative:.6g} × mean |value|" if relative else "")


# -- loading ----------------------------------------------------------------------------------


@dataclass
class _Image:
    path: Path
    pixels: np.ndarray  # (H, W, C) float32
    channels: tuple[str, ...]
    quantum: float  # default ``fail``: float noise for float data, one code value for integer data

    @property
    def size(self) -> str:
        return f"{self.pixels.shape[1]}×{self.pixels.shape[0]}"


def _load(path: Path) -> _Image:
    path = Path(path)
    if not path.exists():
        raise DiffInputError(f"{path}: no such file")
    if path.is_dir():
        raise DiffInputError(f"{path}: is a folder, not an image")
    try:
        pixels, channels, _ = read_image(path)
    except RtreflectError as exc:
        raise DiffInputError(str(exc)) from None
    source = oiio.ImageInput.open(str(path))
    stored = source.spec().format
    source.close()
    if stored.basetype in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE):
        quantum = FLOAT_FAIL
    else:
        quantum = 1.0 / (2 ** (8 * stored.size()) - 1) + CODE_VALUE_SLACK
    return _Image(path, pixels, channels, quantum)


def _same_encoding(a: _Image, b: _Image) -> tuple[_Image, _Image, str | None]:
    """A float image (EXR: linear) compared with an 8-bit one (PNG: sRGB-encoded) is first turned into the PNG
    rtreflect would write of it (`encode_srgb`: colour-science's sRGB curve, 8-bit codes, alpha linear), so like
    values are compared; its AOVs, which no PNG has, are left out. Returns both images and a note saying so."""
    a_float, b_float = a.quantum == FLOAT_FAIL, b.quantum == FLOAT_FAIL
    if a_float == b_float:
        return a, b, None
    linear, coded = (a, b) if a_float else (b, a)
    missing = [c for c in COLOR_CHANNELS if c not in linear.channels]
    if missing:
        raise DiffInputError(f"{linear.path}: a float image compared with the 8-bit sRGB {coded.path} needs the "
                             f"channels R,G,B,A to encode as sRGB; it has no {','.join(missing)}")
    rgba = np.stack([linear.pixels[..., linear.channels.index(c)] for c in COLOR_CHANNELS], axis=-1)
    codes = encode_srgb(rgba).astype(np.float32) / np.float32(255.0)
    converted = _Image(linear.path, codes, COLOR_CHANNELS, coded.quantum)
    note = (f"{linear.path} (linear float) converted to 8-bit sRGB as rtreflect writes PNGs, "
            f"to compare with {coded.path}")
    return (converted, b, note) if a_float else (a, converted, note)


def _select_channels(a: _Image, b: _Image, channels: tuple[str, ...] | None) -> tuple[str, ...]:
    """The channel names to compare; `DiffInputError` naming the file and the missing channels."""
    if channels:
        for image in (a, b):
            missing = [c for c in channels if c not in image.channels]
            if missing:
                raise DiffInputError(f"{image.path}: --channels: no channel {','.join(missing)} "
                                     f"(it has {','.join(image.channels)})")
        return tuple(channels)
    if set(a.channels) != set(b.channels):
        only_a = [c for c in a.channels if c not in b.channels]
        only_b = [c for c in b.channels if c not in a.channels]
        raise DiffInputError(f"different channel sets: only in {a.path}: {','.join(only_a) or '(none)'}; "
                             f"only in {b.path}: {','.join(only_b) or '(none)'} (use --channels to compare a subset)")
    colour_channels = tuple(c for c in COLOR_CHANNELS if c in a.channels)
    return colour_channels or a.channels


def _buffer(pixels: np.ndarray) -> oiio.ImageBuf:
    height, width, nchannels = pixels.shape
    buf = oiio.ImageBuf(oiio.ImageSpec(width, height, nchannels, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(pixels, dtype=np.float32))
    return buf


def _greyscale(image: _Image, channels: tuple[str, ...]) -> np.ndarray:
    """A's picture in [0, 1] (linear) to draw the differences over: its colour if it has any, else its first
    compared channel stretched over its finite range."""
    if all(c in image.channels for c in "RGB"):
        rgb = np.stack([image.pixels[..., image.channels.index(c)] for c in "RGB"], axis=-1).astype(np.float64)
        weights = colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ[1]  # the Y row: luminance of linear sRGB
        return np.clip(np.nan_to_num(rgb @ weights, nan=0.0), 0.0, 1.0)
    plane = image.pixels[..., image.channels.index(channels[0])].astype(np.float64)
    finite = np.isfinite(plane)
    if not finite.any():
        return np.zeros(plane.shape)
    low, high = plane[finite].min(), plane[finite].max()
    return np.where(finite, (plane - low) / (high - low) if high > low else 0.5, 0.0)


# -- comparison -------------------------------------------------------------------------------


def compare_images(a_path: Path, b_path: Path, channels: tuple[str, ...] | None = None,
                   tolerance: Tolerance = Tolerance()) -> DiffReport:
    """Compare image A with image B over ``channels`` (default: R,G,B,A, or all when the images have none
    of those); raises `DiffInputError` for missing files, different sizes or channel sets."""
    a, b = _load(a_path), _load(b_path)
    if a.pixels.shape[:2] != b.pixels.shape[:2]:
        raise DiffInputError(f"different sizes: {a.path} is {a.size}, {b.path} is {b.size}")
    a, b, converted = _same_encoding(a, b)
    names = _select_channels(a, b, channels)
    pa = np.stack([a.pixels[..., a.channels.index(c)] for c in names], axis=-1)
    pb = np.stack([b.pixels[..., b.channels.index(c)] for c in names], axis=-1)

    fail = tolerance.fail if tolerance.fail is not None else max(a.quantum, b.quantum)
    warn = tolerance.warn if tolerance.warn is not None else fail
    failrelative = tolerance.failrelative
    warnrelative = tolerance.warnrelative if tolerance.warnrelative is not None else failrelative
    if not 0.0 <= failrelative < 2.0 or not 0.0 <= warnrelative < 2.0:
        # |a − b| / mean(|a|, |b|) never exceeds 2: a larger bound would pass everything.
        raise DiffInputError(f"relative thresholds must lie in [0, 2), not {failrelative:g}/{warnrelative:g}")
    thresholds = (fail, warn, failrelative, warnrelative)

    # Non-finite values, settled before OpenImageIO sees them (module docstring).
    nonfinite_a, nonfinite_b = ~np.isfinite(pa), ~np.isfinite(pb)
    same = (np.isnan(pa) & np.isnan(pb)) | (nonfinite_a & nonfinite_b & (pa == pb))
    mismatch = (nonfinite_a | nonfinite_b) & ~same
    finite_a = np.where(nonfinite_a | nonfinite_b, 0.0, pa).astype(np.float32)
    finite_b = np.where(nonfinite_a | nonfinite_b, 0.0, pb).astype(np.float32)

    stats = oiio.ImageBufAlgo.compare(_buffer(finite_a), _buffer(finite_b), *thresholds)  # .error: "some failed"
    failing, warning = stats.nfail, stats.nwarn
    mismatch_pixels = int(mismatch.any(axis=-1).sum())
    first_mismatch = None
    if mismatch_pixels:
        # Count each pixel once whether it fails by a finite error, a non-finite mismatch or both:
        # OpenImageIO counts the pixels again with the mismatched values replaced by a sure failure
        # (against 0 it is over both absolute thresholds, and its relative difference is 2).
        sure_failure = 2.0 * max(fail, warn) + 1.0
        counts = oiio.ImageBufAlgo.compare(_buffer(finite_a), _buffer(np.where(mismatch, sure_failure, finite_b)),
                                           *thresholds)
        failing, warning = counts.nfail, counts.nwarn
        y, x, c = (int(i) for i in np.argwhere(mismatch)[0])
        first_mismatch = PixelError(math.inf, x, y, names[c])

    if first_mismatch is not None:
        max_error = first_mismatch  # non-finite errors trump finite ones, as in OpenImageIO
    elif stats.maxerror > 0:
        max_error = PixelError(float(stats.maxerror), stats.maxx, stats.maxy, names[stats.maxc])
    else:
        max_error = None

    allowed_fail = tolerance.failpercent / 100.0 * a.pixels.shape[0] * a.pixels.shape[1]
    allowed_warn = tolerance.warnpercent / 100.0 * a.pixels.shape[0] * a.pixels.shape[1]
    worst = max_error.value if max_error else 0.0
    if failing > allowed_fail or worst > tolerance.hardfail:
        status = "mismatch"
    elif warning > allowed_warn:
        status = "warn"
    else:
        status = "match"

    return DiffReport(
        a=a.path, b=b.path, width=a.pixels.shape[1], height=a.pixels.shape[0], channels=names,
        fail=fail, failrelative=failrelative, failpercent=tolerance.failpercent, hardfail=tolerance.hardfail,
        warn=warn, warnrelative=warnrelative, warnpercent=tolerance.warnpercent,
        mean_error=float(stats.meanerror), rms_error=float(stats.rms_error), psnr=float(stats.PSNR),
        max_error=max_error, failing_pixels=int(failing), warning_pixels=int(warning),
        nonfinite_mismatch_pixels=mismatch_pixels, first_nonfinite_mismatch=first_mismatch, status=status,
        excess=_excess(finite_a, finite_b, mismatch, thresholds), background=_greyscale(a, names),
        converted=converted,
    )


def _excess(a: np.ndarray, b: np.ndarray, mismatch: np.ndarray, thresholds: tuple[float, ...]) -> np.ndarray:
    """Per pixel, max over channels of |a − b| / (the lower of the warn and fail thresholds of that value).

    OpenImageIO's rule, restated for the picture: a value fails when |a − b| > fail and
    |a − b| > failrelative·(|a| + |b|)/2, that is when |a − b| > max(fail, failrelative·mean);
    so a ratio above 1 marks exactly the values that OpenImageIO counts.
    """
    # OpenImageIO takes the thresholds as float32: round them alike, so the picture agrees with the counts.
    fail, warn, failrelative, warnrelative = (float(np.float32(t)) for t in thresholds)
    a, b = a.astype(np.float64), b.astype(np.float64)
    error = np.abs(a - b)
    mean = 0.5 * (np.abs(a) + np.abs(b))
    bound = np.minimum(np.maximum(fail, failrelative * mean), np.maximum(warn, warnrelative * mean))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(error > 0, error / bound, 0.0)  # bound 0 (thresholds 0): any difference is infinite excess
    ratio[mismatch] = math.inf
    return ratio.max(axis=-1)


# -- the diff image ---------------------------------------------------------------------------


def error_colormap(t: np.ndarray) -> np.ndarray:
    """Linear sRGB colours for t in [0, 1]: a perceptually uniform ramp from red through orange to yellow.

    Built with colour-science in Oklch (lightness 0.55 → 0.92 linearly, chroma ~0.2, hue 25° → 105°),
    so equal steps in t look like equal steps in brightness, and every colour is saturated, which
    the dimmed grey image under it never is.
    """
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    lch = np.stack([0.55 + 0.37 * t, 0.21 - 0.03 * t, 25.0 + 80.0 * t], axis=-1)
    xyz = colour.Oklab_to_XYZ(colour.Oklch_to_Oklab(lch))
    rgb = colour.XYZ_to_RGB(xyz, "sRGB", apply_cctf_encoding=False)
    return np.clip(rgb, 0.0, 1.0)


def diff_image(background: np.ndarray, excess: np.ndarray) -> np.ndarray:
    """(H, W, 4) linear RGBA: A (``background``, greyscale in [0, 1]) dimmed, and every pixel whose
    ``excess`` (error over threshold, see `compare_images`) is above 1 coloured by how much, on a log
    scale from just over the threshold (red) to the largest finite excess (yellow); pixels that
    are NaN/Inf in one image only get the top colour.

    Amplified this way, a line that moved by a fraction of a pixel shows as a coloured seam along the
    line, however small the value change.
    """
    rgb = np.repeat((DIM * background)[..., None], 3, axis=-1)
    marked = excess > 1.0
    if marked.any():
        finite = excess[marked & np.isfinite(excess)]
        top = max(finite.max() if finite.size else 1.0, 10.0)  # at least a decade, so a tiny excess stays red
        t = np.log(excess[marked]) / np.log(top)
        rgb[marked] = error_colormap(np.where(np.isfinite(t), t, 1.0))
    return np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,))], axis=-1)
