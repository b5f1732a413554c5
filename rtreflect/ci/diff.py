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
over the pairs where both values are finite (a pair with a non-finite value is not counted at all).

**Windows.** An EXR's pixels cover its data window, which need not start at (0, 0). Two images
whose data or display windows differ hold their values at different image positions: that is
bad input (one line, exit 2), not a comparison of the stored arrays.

**Bounded memory.** The files are read in chunks of scanlines (`CHUNK_VALUES` values per
image) and OpenImageIO compares chunk by chunk; counts, sums and maxima add up across
chunks. The diff image is drawn in further passes over the files (its colour scale, then
its pixels), chunk by chunk, and streamed to its PNG, so no whole image is ever held.
"""

from __future__ import annotations

import contextlib
import json
import math
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterator

import numpy as np
import OpenImageIO as oiio

with warnings.catch_warnings():
    warnings.simplefilter("ignore")  # colour-science warns at import about optional features we do not use
    import colour

from ..errors import RtreflectError
from ..integrator.film import COLOR_CHANNELS
from ..output.imagefiles import atomic_path, encode_srgb, write_png_rows

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
    # For the diff image, not part of the report proper: drawn from the files again, chunk by chunk.
    picture: "_Picture" = field(repr=False, default=None)

    @property
    def excess(self) -> np.ndarray:
        """(H, W): per pixel, the largest ratio over the channels of |A − B| to its warn or fail threshold,
        whichever is lower (> 1: the pixel warns or fails; inf where only one image is non-finite).
        Assembled whole from the files: for small images and tests; the diff image streams it."""
        return np.concatenate([excess for _, _, excess in self.picture.rows()])

    @property
    def background(self) -> np.ndarray:
        """(H, W): A's greyscale in [0, 1] under the diff image (assembled whole, as `excess`)."""
        return np.concatenate([grey for _, grey, _ in self.picture.rows()])
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
            top = self.picture.top if diff_png is not None else None
            rows = lambda: (diff_image(grey, excess, top) for _, grey, excess in self.picture.rows())  # noqa: E731
            writers.append((final, lambda tmp, final=final: write_png_rows(tmp, self.width, self.height, rows(),
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

#: Values read per image and chunk of scanlines (float32: 16 MiB): memory stays bounded whatever the image size.
CHUNK_VALUES = 1 << 22


def _open_input(path: Path) -> oiio.ImageInput:
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # as stored: do not premultiply a PNG's colour by its alpha
    source = oiio.ImageInput.open(str(path), config)
    if source is None:
        raise DiffInputError(f"{path}: cannot read image ({' '.join(oiio.geterror().split()) or 'unknown format'})")
    return source


@dataclass
class _Image:
    """An image file's header; its pixels are read in chunks of scanlines (`rows`), never whole."""

    path: Path
    spec: oiio.ImageSpec
    channels: tuple[str, ...]
    quantum: float  # default ``fail``: float noise for float data, one code value for integer data
    srgb_from: tuple[int, ...] | None = None  # linear R,G,B,A at these stored channels, read as 8-bit sRGB codes

    @property
    def size(self) -> str:
        return f"{self.spec.width}×{self.spec.height}"

    @property
    def window(self) -> tuple[int, int, int, int, int, int, int, int]:
        """Data window (x, y, width, height) and display (full) window, as stored."""
        s = self.spec
        return s.x, s.y, s.width, s.height, s.full_x, s.full_y, s.full_width, s.full_height

    def describe_window(self) -> str:
        x, y, w, h, fx, fy, fw, fh = self.window
        return f"{self.path} has data window {w}×{h} at ({x}, {y}), display window {fw}×{fh} at ({fx}, {fy})"

    def chunk_rows(self) -> int:
        return max(1, CHUNK_VALUES // max(1, self.spec.width * self.spec.nchannels))

    def rows(self, chunk_rows: int) -> Iterator[tuple[int, np.ndarray]]:
        """(first row, pixels (rows, W, C) float32) down the data window; row 0 is the window's top."""
        spec = self.spec
        source = _open_input(self.path)
        try:
            for row in range(0, spec.height, chunk_rows):
                end = min(spec.height, row + chunk_rows)
                data = source.read_scanlines(0, 0, spec.y + row, spec.y + end, spec.z, 0, spec.nchannels, oiio.FLOAT)
                if data is None or not isinstance(data, np.ndarray):
                    raise DiffInputError(f"{self.path}: cannot read image ({' '.join(source.geterror().split())})")
                data = data.reshape(end - row, spec.width, spec.nchannels)
                if self.srgb_from is not None:
                    data = encode_srgb(data[..., list(self.srgb_from)]).astype(np.float32) / np.float32(255.0)
                yield row, data
        finally:
            source.close()


def _load(path: Path) -> _Image:
    path = Path(path)
    if not path.exists():
        raise DiffInputError(f"{path}: no such file")
    if path.is_dir():
        raise DiffInputError(f"{path}: is a folder, not an image")
    source = _open_input(path)
    spec = oiio.ImageSpec(source.spec())
    source.close()
    stored = spec.format
    if stored.basetype in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE):
        quantum = FLOAT_FAIL
    else:
        quantum = 1.0 / (2 ** (8 * stored.size()) - 1) + CODE_VALUE_SLACK
    return _Image(path, spec, tuple(spec.channelnames), quantum)


def _same_encoding(a: _Image, b: _Image) -> tuple[_Image, _Image, str | None]:
    """A float image (EXR: linear) compared with an 8-bit one (PNG: sRGB-encoded) is first turned into the PNG
    rtreflect would write of it (`encode_srgb`: colour-science's sRGB curve, 8-bit codes, opaque), so like
    values are compared; its AOVs, which no PNG has, are left out. Returns both images and a note saying so."""
    a_float, b_float = a.quantum == FLOAT_FAIL, b.quantum == FLOAT_FAIL
    if a_float == b_float:
        return a, b, None
    linear, coded = (a, b) if a_float else (b, a)
    missing = [c for c in COLOR_CHANNELS if c not in linear.channels]
    if missing:
        raise DiffInputError(f"{linear.path}: a float image compared with the 8-bit sRGB {coded.path} needs the "
                             f"channels R,G,B,A to encode as sRGB; it has no {','.join(missing)}")
    converted = replace(linear, channels=COLOR_CHANNELS, quantum=coded.quantum,
                        srgb_from=tuple(linear.channels.index(c) for c in COLOR_CHANNELS))
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


# -- comparison -------------------------------------------------------------------------------


@dataclass
class _Pair:
    """A and B read side by side, chunk by chunk, over the compared channels, with non-finite values settled."""

    a: _Image
    b: _Image
    names: tuple[str, ...]
    thresholds: tuple[float, float, float, float]  # fail, warn, failrelative, warnrelative

    def chunks(self) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]]:
        """(first row, A's chunk with all its channels, finite A, finite B, mismatch, finite pairs) per chunk of rows.

        Non-finite values are settled before OpenImageIO sees them (module docstring): where either
        image is non-finite both become 0; ``mismatch`` marks the values non-finite in one image only
        (or non-finite in both but different, such as +Inf against −Inf); the last item counts the
        values finite in both images.
        """
        chunk_rows = min(self.a.chunk_rows(), self.b.chunk_rows())
        ia = [self.a.channels.index(c) for c in self.names]
        ib = [self.b.channels.index(c) for c in self.names]
        for (row, a_all), (_, b_all) in zip(self.a.rows(chunk_rows), self.b.rows(chunk_rows)):
            pa, pb = a_all[..., ia], b_all[..., ib]
            nonfinite_a, nonfinite_b = ~np.isfinite(pa), ~np.isfinite(pb)
            either = nonfinite_a | nonfinite_b
            same = (np.isnan(pa) & np.isnan(pb)) | (nonfinite_a & nonfinite_b & (pa == pb))
            mismatch = either & ~same
            yield (row, a_all, np.where(either, np.float32(0), pa).astype(np.float32),
                   np.where(either, np.float32(0), pb).astype(np.float32), mismatch, int(either.size - either.sum()))


def compare_images(a_path: Path, b_path: Path, channels: tuple[str, ...] | None = None,
                   tolerance: Tolerance = Tolerance()) -> DiffReport:
    """Compare image A with image B over ``channels`` (default: R,G,B,A, or all when the images have none
    of those); raises `DiffInputError` for missing files, different sizes, windows or channel sets.

    The images are read in chunks of scanlines (`CHUNK_VALUES` values each) and OpenImageIO compares
    chunk by chunk; the counts and sums add up, so memory does not grow with the image size.
    """
    a, b = _load(a_path), _load(b_path)
    if (a.spec.width, a.spec.height) != (b.spec.width, b.spec.height):
        raise DiffInputError(f"different sizes: {a.path} is {a.size}, {b.path} is {b.size}")
    if a.window != b.window:
        # The same values at other image positions are not the same image (idiff counts them as failing).
        raise DiffInputError(f"different image windows: {a.describe_window()}; {b.describe_window()}")
    a, b, converted = _same_encoding(a, b)
    names = _select_channels(a, b, channels)

    fail = tolerance.fail if tolerance.fail is not None else max(a.quantum, b.quantum)
    warn = tolerance.warn if tolerance.warn is not None else fail
    failrelative = tolerance.failrelative
    warnrelative = tolerance.warnrelative if tolerance.warnrelative is not None else failrelative
    if not 0.0 <= failrelative < 2.0 or not 0.0 <= warnrelative < 2.0:
        # |a − b| / mean(|a|, |b|) never exceeds 2: a larger bound would pass everything.
        raise DiffInputError(f"relative thresholds must lie in [0, 2), not {failrelative:g}/{warnrelative:g}")
    thresholds = (fail, warn, failrelative, warnrelative)
    pair = _Pair(a, b, names, thresholds)
    x0, y0 = a.spec.x, a.spec.y  # pixel positions are reported in the file's coordinates

    failing = warning = mismatch_pixels = finite_values = 0
    error_sum = error_squares = 0.0
    max_error: PixelError | None = None
    first_mismatch: PixelError | None = None
    grey = _GreyRange(a, names)
    for row, a_all, finite_a, finite_b, mismatch, finite_pairs in pair.chunks():
        stats = oiio.ImageBufAlgo.compare(_buffer(finite_a), _buffer(finite_b), *thresholds)  # .error: "some failed"
        nfail, nwarn = stats.nfail, stats.nwarn
        if mismatch.any():
            # Count each pixel once whether it fails by a finite error, a non-finite mismatch or both:
            # OpenImageIO counts the pixels again with the mismatched values replaced by a sure failure
            # (against 0 it is over both absolute thresholds, and its relative difference is 2).
            sure_failure = 2.0 * max(fail, warn) + 1.0
            counts = oiio.ImageBufAlgo.compare(_buffer(finite_a), _buffer(np.where(mismatch, sure_failure, finite_b)),
                                               *thresholds)
            nfail, nwarn = counts.nfail, counts.nwarn
            mismatch_pixels += int(mismatch.any(axis=-1).sum())
            if first_mismatch is None:
                y, x, c = (int(i) for i in np.argwhere(mismatch)[0])
                first_mismatch = PixelError(math.inf, x0 + x, y0 + row + y, names[c])
        failing, warning = failing + nfail, warning + nwarn
        # OpenImageIO's mean and RMS are over every value of the chunk; settled pairs contributed 0 to its sums.
        values = finite_a.size
        error_sum += float(stats.meanerror) * values
        error_squares += float(stats.rms_error) ** 2 * values
        finite_values += finite_pairs
        if stats.maxerror > 0 and (max_error is None or stats.maxerror > max_error.value):
            max_error = PixelError(float(stats.maxerror), x0 + stats.maxx, y0 + row + stats.maxy, names[stats.maxc])
        grey.update(a_all)

    if first_mismatch is not None:
        max_error = first_mismatch  # non-finite errors trump finite ones, as in OpenImageIO
    # Mean and RMS over the pairs where both values are finite (the contract in docs/ci.md, "How `diff` compares").
    mean_error = error_sum / finite_values if finite_values else 0.0
    rms_error = math.sqrt(error_squares / finite_values) if finite_values else 0.0
    psnr = 20.0 * math.log10(1.0 / rms_error) if rms_error > 0 else math.inf  # OpenImageIO's definition (peak 1)

    pixels = a.spec.width * a.spec.height
    worst = max_error.value if max_error else 0.0
    if failing > tolerance.failpercent / 100.0 * pixels or worst > tolerance.hardfail:
        status = "mismatch"
    elif warning > tolerance.warnpercent / 100.0 * pixels:
        status = "warn"
    else:
        status = "match"

    return DiffReport(
        a=a.path, b=b.path, width=a.spec.width, height=a.spec.height, channels=names,
        fail=fail, failrelative=failrelative, failpercent=tolerance.failpercent, hardfail=tolerance.hardfail,
        warn=warn, warnrelative=warnrelative, warnpercent=tolerance.warnpercent,
        mean_error=mean_error, rms_error=rms_error, psnr=psnr,
        max_error=max_error, failing_pixels=int(failing), warning_pixels=int(warning),
        nonfinite_mismatch_pixels=mismatch_pixels, first_nonfinite_mismatch=first_mismatch, status=status,
        picture=_Picture(pair, grey),
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


class _GreyRange:
    """What A's greyscale needs beyond one chunk: for an image without colour, its first compared channel's
    finite range (gathered chunk by chunk)."""

    def __init__(self, image: _Image, names: tuple[str, ...]):
        self.rgb = [image.channels.index(c) for c in "RGB"] if all(c in image.channels for c in "RGB") else None
        self.plane = image.channels.index(names[0])
        self.low, self.high = math.inf, -math.inf

    def update(self, a_all: np.ndarray) -> None:
        if self.rgb is None:
            plane = a_all[..., self.plane]
            finite = plane[np.isfinite(plane)]
            if finite.size:
                self.low, self.high = min(self.low, float(finite.min())), max(self.high, float(finite.max()))

    def grey(self, a_all: np.ndarray) -> np.ndarray:
        """A's picture in [0, 1] (linear) to draw the differences over: its colour's luminance if it has
        colour, else its first compared channel stretched over its finite range."""
        if self.rgb is not None:
            rgb = a_all[..., self.rgb].astype(np.float64)
            weights = colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ[1]  # the Y row: luminance of linear sRGB
            return np.clip(np.nan_to_num(rgb @ weights, nan=0.0), 0.0, 1.0)
        plane = a_all[..., self.plane].astype(np.float64)
        finite = np.isfinite(plane)
        if self.high < self.low:
            return np.zeros(plane.shape)
        stretched = (plane - self.low) / (self.high - self.low) if self.high > self.low else np.full(plane.shape, 0.5)
        return np.where(finite, stretched, 0.0)


@dataclass
class _Picture:
    """The diff image, drawn chunk by chunk from the files on demand: a pass for the colour scale (`top`),
    then one for the pixels. Only a diff image pays for them."""

    pair: _Pair
    grey: _GreyRange
    _top: float | None = None

    @property
    def top(self) -> float:
        """The largest finite excess over a threshold anywhere: the top of the diff image's colour scale."""
        if self._top is None:
            self._top = 0.0
            for _, _, excess in self.rows():
                marked = excess[(excess > 1.0) & np.isfinite(excess)]
                self._top = max(self._top, float(marked.max()) if marked.size else 0.0)
        return self._top

    def rows(self) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
        """(first row, A's greyscale, excess) per chunk of rows."""
        for row, a_all, finite_a, finite_b, mismatch, _ in self.pair.chunks():
            yield row, self.grey.grey(a_all), _excess(finite_a, finite_b, mismatch, self.pair.thresholds)


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


def diff_image(background: np.ndarray, excess: np.ndarray, top: float | None = None) -> np.ndarray:
    """(H, W, 4) linear RGBA: A (``background``, greyscale in [0, 1]) dimmed, and every pixel whose
    ``excess`` (error over threshold, see `compare_images`) is above 1 coloured by how much, on a log
    scale from just over the threshold (red) to the largest finite excess (yellow); pixels that
    are NaN/Inf in one image only get the top colour. ``top``: that largest excess when ``excess`` is
    one chunk of a larger image (from the first pass); by default the chunk's own.

    Amplified this way, a line that moved by a fraction of a pixel shows as a coloured seam along the
    line, however small the value change.
    """
    rgb = np.repeat((DIM * background)[..., None], 3, axis=-1)
    marked = excess > 1.0
    if marked.any():
        if top is None:  # the whole image is here: its own largest finite excess
            finite = excess[marked & np.isfinite(excess)]
            top = finite.max() if finite.size else 1.0
        top = max(top, 10.0)  # at least a decade, so a tiny excess stays red
        t = np.log(excess[marked]) / np.log(top)
        rgb[marked] = error_colormap(np.where(np.isfinite(t), t, 1.0))
    return np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,))], axis=-1)
