"""Image files: EXR (float32, every channel) and PNG (8-bit sRGB) through OpenImageIO.

Every file is written to a temporary name in its final folder and renamed into
place, so a failed or interrupted render leaves the old file or none, never half a file.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Iterator

import numpy as np
import OpenImageIO as oiio

from ..errors import RtreflectError
from ..exchange.scene import OVERLAY_SIDE
from ..integrator.film import CHANNELS, Film
from .sharing import NameLock, remove_dead_temporaries, temporary_prefix

if TYPE_CHECKING:
    from ..integrator.renderer import RenderResult
    from ..exchange.scene import Scene

#: EXR header attributes that record where an image came from.
SCENE_HASH_ATTRIBUTE = "rtreflect:scene_sha256"
INPUTS_HASH_ATTRIBUTE = "rtreflect:inputs_sha256"
VERSION_ATTRIBUTE = "rtreflect:version"
#: The camera and tubes rendered (TOML inline tables, ready to paste into a scene file): the automatic rig kept.
CAMERA_ATTRIBUTE = "rtreflect:camera"
LIGHTS_ATTRIBUTE = "rtreflect:lights"
#: `Scene.output_key`: the inputs' hash plus size, samples, normals and overlay (which the command line may override).
OUTPUT_KEY_ATTRIBUTE = "rtreflect:output_key"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: The last 12 bytes of every complete PNG: the empty IEND chunk (length 0, type, CRC), PNG spec 11.2.5.
PNG_END = bytes.fromhex("0000000049454e44ae426082")
#: Most bytes kept of what libpng prints while muted: its messages are one short line each.
MUTED_BYTES = 4096


@contextlib.contextmanager
def muted_stderr(active: bool = True) -> Iterator[list[str]]:
    """File descriptor 2 into a pipe while the block runs; the lines printed there are appended to the list yielded.

    libpng's default error handler, which OpenImageIO's PNG writer keeps, prints
    ``libpng error: ...`` to stderr itself (closing a PNG that got no rows, a failed write):
    lines that would break the one-line error rule. The caller turns them into its own
    message. The pipe lives in memory (a full disk cannot stop it) and is non-blocking: what
    does not fit in its buffer is dropped, never waited for.
    """
    lines: list[str] = []
    if not active:
        yield lines
        return
    with contextlib.suppress(Exception):
        sys.stderr.flush()  # Python's own buffered text goes out before the switch, not into the pipe
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    os.set_blocking(read_end, False)
    saved = os.dup(2)
    os.dup2(write_end, 2)
    os.close(write_end)
    try:
        yield lines
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        with contextlib.suppress(BlockingIOError):
            lines.extend(os.read(read_end, MUTED_BYTES).decode(errors="replace").splitlines())
        os.close(read_end)


def _png_incomplete(path: Path) -> bool:
    """True when the file does not end with PNG's IEND chunk: libpng was cut off by a write that failed.

    OpenImageIO's PNG writer reports success even when the disk filled up under it (the file
    is then cut short); checking the last 12 bytes finds it without reading the image.
    """
    try:
        with open(path, "rb") as stream:
            stream.seek(0, os.SEEK_END)
            if stream.tell() < len(PNG_END):
                return True
            stream.seek(-len(PNG_END), os.SEEK_END)
            return stream.read() != PNG_END
    except OSError:
        return True


def _png_failure(final: Path, out, muted: list[str]) -> RtreflectError:
    """The one-line error of a PNG that could not be written: OpenImageIO's reason, else libpng's, else the likely one."""
    libpng = next((line.removeprefix("libpng error: ") for line in muted if line.strip()), "")
    return RtreflectError(f"{final}: cannot write image ({out.geterror() or libpng or 'file cut short: disk full?'})")


#: Random bytes in a temporary's name: 8 hex digits, the length of mkstemp's names that `sharing` recognises.
TEMPORARY_TOKEN_BYTES = 4


@contextlib.contextmanager
def atomic_path(final: Path) -> Iterator[Path]:
    """A temporary path beside ``final`` (same extension, so OpenImageIO picks the format), renamed on success."""
    final = Path(final)
    # The name carries this host and process: a run killed before it could clean up is recognised later. It is
    # chosen before the file exists (not by mkstemp, which names it only after creating it), so a Ctrl-C that
    # lands while the file is being created still finds the name to remove.
    tmp = final.parent / f"{temporary_prefix(final)}{secrets.token_hex(TEMPORARY_TOKEN_BYTES)}{final.suffix}"
    try:
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())  # created 0600 while unfinished; a finished image gets the usual permissions
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _write(path: Path, spec: oiio.ImageSpec, pixels: np.ndarray, final: Path | None = None) -> None:
    """Write an image to ``path`` as is; errors name ``final`` (the name the user asked for)."""
    shown = final or path
    is_png = Path(path).suffix == ".png"
    with muted_stderr(is_png) as muted:  # libpng's own stderr lines (see muted_stderr)
        out = oiio.ImageOutput.create(str(path))
        if out is None or not out.open(str(path), spec):
            raise RtreflectError(f"{shown}: cannot write image ({oiio.geterror() or 'unknown OpenImageIO error'})")
        ok = out.write_image(pixels)
        ok = out.close() and ok
    if not ok or (is_png and _png_incomplete(path)):
        raise _png_failure(shown, out, muted) if is_png else \
            RtreflectError(f"{shown}: cannot write image ({out.geterror() or 'disk full?'})")


def _exr_spec(width: int, height: int, attributes: dict[str, str]) -> oiio.ImageSpec:
    spec = oiio.ImageSpec(width, height, len(CHANNELS), oiio.FLOAT)
    spec.channelnames = CHANNELS
    spec.alpha_channel = CHANNELS.index("A")
    spec.z_channel = CHANNELS.index("Z")
    spec.attribute("compression", "zip")
    # OpenImageIO stamps the wall-clock time unless told otherwise (an empty value writes none):
    # without it the same scene gives the same bytes on every run and every cluster worker.
    spec.attribute("DateTime", "")
    for key, value in attributes.items():
        spec.attribute(key, value)
    return spec


def _png_spec(width: int, height: int, attributes: dict[str, str]) -> oiio.ImageSpec:
    spec = oiio.ImageSpec(width, height, 4, oiio.UINT8)
    spec.channelnames = ("R", "G", "B", "A")
    spec.alpha_channel = 3
    # Store the encoded colour verbatim: without this OpenImageIO would un-premultiply it by alpha.
    spec.attribute("oiio:UnassociatedAlpha", 1)
    for key, value in attributes.items():  # PNG text chunks
        spec.attribute(key, value)
    return spec


#: The sRGB encoding (IEC 61966-2-1:1999, eq. for V'): linear segment below this, slope 12.92 ...
SRGB_LINEAR_LIMIT = 0.0031308
SRGB_SLOPE = 12.92
#: ... and V' = 1.055 L^(1/2.4) − 0.055 above.
SRGB_SCALE, SRGB_OFFSET, SRGB_GAMMA = 1.055, 0.055, 2.4


def srgb_oetf(L: np.ndarray) -> np.ndarray:
    """sRGB encoding V' of linear L in [0, 1] (IEC 61966-2-1:1999; colour-science's ``eotf_inverse_sRGB``).

    Written out rather than imported: importing colour-science costs more than a small render
    (issue 14, start-up); tests/test_startup.py checks the bytes against colour-science.
    """
    with np.errstate(invalid="ignore"):
        return np.where(L <= SRGB_LINEAR_LIMIT, L * SRGB_SLOPE, SRGB_SCALE * np.power(L, 1 / SRGB_GAMMA) - SRGB_OFFSET)


def encode_srgb(rgba: np.ndarray) -> np.ndarray:
    """Linear RGBA → 8-bit sRGB RGBA, opaque (`srgb_oetf`; alpha 255).

    The film's RGB is already composited over ``background``, so the PNG is the picture as
    rendered: an opaque background, whatever a viewer does with alpha (one that honours it
    showed the white page behind the part's edge, and white lines vanished into it; issue 13).
    The coverage A stays in the EXR.
    """
    rgb = np.clip(np.nan_to_num(rgba[..., :3], nan=0.0), 0.0, 1.0)
    encoded = np.round(srgb_oetf(rgb) * 255.0).astype(np.uint8)
    return np.concatenate([encoded, np.full(encoded.shape[:-1] + (1,), 255, dtype=np.uint8)], axis=-1)


def write_json(path: Path, document: object, what: str = "report") -> None:
    """``document`` as indented JSON at ``path``, written atomically (folder created); errors name the file."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    except OSError as exc:
        raise RtreflectError(f"{path}: cannot write {what} ({exc.strerror or exc})") from None


def write_png(path: Path, rgba: np.ndarray, final: Path | None = None) -> None:
    """An 8-bit sRGB PNG of a linear (H, W, 4) RGBA image (not atomic: wrap it in `atomic_path`)."""
    height, width = rgba.shape[:2]
    _write(path, _png_spec(width, height, {}), encode_srgb(rgba), final)


def write_png_rows(path: Path, width: int, height: int, blocks: Iterable[np.ndarray], final: Path | None = None) -> None:
    """An 8-bit sRGB PNG from blocks of linear RGBA rows (k, W, 4), top to bottom, streamed: memory holds one block.

    Not atomic (wrap it in `atomic_path`); errors name ``final``, with libpng's stderr muted as in `ImageWriter`.
    """
    shown = final or path
    with muted_stderr() as muted:
        out = oiio.ImageOutput.create(str(path))
        if out is None or not out.open(str(path), _png_spec(width, height, {})):
            raise RtreflectError(f"{shown}: cannot write image ({oiio.geterror() or 'unknown OpenImageIO error'})")
        row, ok = 0, True
        try:
            for block in blocks:
                ok = ok and out.write_scanlines(row, row + len(block), 0, encode_srgb(block))
                row += len(block)
        finally:
            ok = out.close() and ok
    if not ok or row != height or _png_incomplete(path):
        raise _png_failure(shown, out, muted)


#: The second PNG of `[render] overlay = "side"`: the plain picture and the overlaid one side by side.
SIDE_SUFFIX = ".side.png"


def side_by_side(scene: "Scene") -> bool:
    """Whether the scene writes ``NAME.side.png`` (`[render] overlay = "side"` with a PNG): NAME.png then stays plain."""
    return scene.output.png and scene.render.overlay == OVERLAY_SIDE


def output_paths(scene: "Scene", outdir: Path, extra_files: dict[str, str] | None = None) -> list[Path]:
    """``outdir/NAME.exr`` and/or ``outdir/NAME.png`` (and ``NAME.side.png``) as the scene asks, then ``extra_files``'."""
    outdir = Path(outdir)
    targets = []
    if scene.output.exr:
        targets.append(outdir / f"{scene.output.name}.exr")
    if scene.output.png:
        targets.append(outdir / f"{scene.output.name}.png")
    if side_by_side(scene):
        targets.append(outdir / f"{scene.output.name}{SIDE_SUFFIX}")
    return targets + [outdir / name for name in extra_files or {}]


def check_distinct_outputs(scenes: list["Scene"], outdir: Path) -> None:
    """Two scenes of one run with one `[output] name` would overwrite each other's files: an error naming both."""
    by_name: dict[str, list[Path]] = {}
    for scene in scenes:
        by_name.setdefault(scene.output.name, []).append(scene.path)
    clashes = [(name, files) for name, files in by_name.items() if len(files) > 1]
    if clashes:
        name, files = clashes[0]
        if len(set(files)) == 1:  # one file named twice, not two scenes sharing a name
            raise RtreflectError(f"{files[0]}: scene file given more than once (its outputs {Path(outdir) / name}.* "
                                 "would be written twice)")
        more = f"; {len(clashes) - 1} more names collide" if len(clashes) > 1 else ""
        raise RtreflectError(f"{files[-1]}: output.name: outputs collide: {Path(outdir) / name}.* is also written from "
                             f"{' and '.join(map(str, files[:-1]))}{more} (give each scene its own [output] name)")


def prepare_output_folder(outdir: Path, targets: list[Path] = (), remove_dead: bool = True) -> list[Path]:
    """Create ``outdir`` if missing and prove a file can be made in it: a bad folder fails before the render, not after.

    A folder standing where one of ``targets`` goes would stop its rename after the other files were replaced.
    Temporaries left in the folder by dead runs of this host (`sharing.remove_dead_temporaries`) are removed:
    the paths removed are returned, for the caller to say so. ``remove_dead=False`` leaves them to the caller
    (a batch pool worker: its parent removes and reports a dead sibling's temporaries, see `batch.run_local`).
    """
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise RtreflectError(f"{outdir}: -o/--output: is a file, not a folder")
    for target in targets:
        if target.is_dir():
            raise RtreflectError(f"{target}: cannot write output (a folder has that name)")
    try:
        outdir.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".rtreflect-probe.", dir=outdir)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise RtreflectError(f"{outdir}: -o/--output: output folder is not writable ({exc.strerror or exc})") from None
    return remove_dead_temporaries(outdir) if remove_dead else []


def removed_note(removed: list[Path]) -> str:
    """The line saying which dead runs' temporaries were removed."""
    names = ", ".join(p.name for p in removed[:3]) + (f" and {len(removed) - 3} more" if len(removed) > 3 else "")
    return f"removed {len(removed)} temporary file{'s' if len(removed) != 1 else ''} left by dead runs: {names}"


def provenance_attributes(scene: "Scene") -> dict[str, str]:
    """What each output records of its origin: the scene file's hash, all inputs' hash, the rtreflect version."""
    from .. import __version__
    from ..exchange.scene import _spec_table
    from ..exchange.scenewriter import inline_table

    attributes = {SCENE_HASH_ATTRIBUTE: scene.sha256, INPUTS_HASH_ATTRIBUTE: scene.inputs_sha256,
                  OUTPUT_KEY_ATTRIBUTE: scene.output_key, VERSION_ATTRIBUTE: __version__}
    if not scene.automatic:  # what was rendered; a scene still automatic is resolved before any pixel is written
        attributes[CAMERA_ATTRIBUTE] = inline_table(_spec_table(scene.camera))
        attributes[LIGHTS_ATTRIBUTE] = inline_table(_spec_table(scene.lights))
    return attributes


def read_provenance(path: Path) -> dict[str, str]:
    """The ``rtreflect:*`` header attributes of an image file (EXR header or PNG text chunks); {} if unreadable."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        oiio.geterror()  # clear the message: an unreadable file is simply not up to date
        return {}
    try:
        return {a.name: str(a.value) for a in inp.spec().extra_attribs if a.name.startswith("rtreflect:")}
    finally:
        inp.close()


#: ``png_filter(row0, rgba_rows) -> rgba_rows``: linear RGBA of image rows [row0, row0 + len) before sRGB encoding.
PngFilter = Callable[[int, np.ndarray], np.ndarray]


class ImageWriter:
    """A render's EXR and PNG written scanline by scanline as pixels arrive in image order.

    Pixels come as row-major spans (a span may start or end mid-row); complete rows
    are encoded and handed to OpenImageIO at once, so memory holds one span plus at
    most one partial row, whatever the image size. The bytes equal those of writing
    the whole image in one call. ``png_filter`` draws on NAME.png's rows; with
    ``NAME.side.png`` among the paths (`side_by_side`) NAME.png stays plain and each row of
    the side PNG is the plain row and the filtered one side by side (twice the width).
    """

    def __init__(self, scene: "Scene", paths: list[tuple[Path, Path]], png_filter: PngFilter | None = None):
        self.width, self.height = scene.image.width, scene.image.height
        self.png_filter = png_filter
        self.side = side_by_side(scene)
        self.next_pixel = 0
        self._partial = np.empty((0, len(CHANNELS)), dtype=np.float32)
        self._outputs: list[tuple[oiio.ImageOutput, Path, bool]] = []
        self._side_paths = {final for _, final in paths if final.name.endswith(SIDE_SUFFIX)}
        self._temporaries = {final: Path(tmp) for tmp, final in paths}
        # libpng prints its errors to stderr itself: muted around every call into a PNG (`muted_stderr`).
        self._has_png = any(final.suffix != ".exr" for _, final in paths)
        attributes = provenance_attributes(scene)
        for tmp, final in paths:
            is_exr = final.suffix == ".exr"
            side = 2 if final in self._side_paths else 1  # the plain and the overlaid picture side by side
            spec = (_exr_spec if is_exr else _png_spec)(side * self.width, self.height, attributes)
            with muted_stderr(not is_exr):
                out = oiio.ImageOutput.create(str(tmp))
                opened = out is not None and out.open(str(tmp), spec)
            if not opened:
                self.abandon()
                raise RtreflectError(f"{final}: cannot write image ({oiio.geterror() or 'unknown OpenImageIO error'})")
            self._outputs.append((out, final, is_exr))

    def write(self, start: int, pixels: np.ndarray) -> None:
        """Pixels [start, start + len(pixels)) as (P, 22) float32 in `CHANNELS` order; spans must come in order."""
        if start != self.next_pixel:
            raise ValueError(f"pixels must arrive in order: expected pixel {self.next_pixel}, got {start}")
        self.next_pixel += len(pixels)
        if len(self._partial):
            pixels = np.concatenate([self._partial, pixels])
        first_row = (start - len(self._partial)) // self.width
        complete = len(pixels) // self.width * self.width
        self._partial = pixels[complete:].copy()
        if complete:
            self._write_rows(first_row, pixels[:complete].reshape(-1, self.width, len(CHANNELS)))

    def _write_rows(self, row0: int, rows: np.ndarray) -> None:
        rows = np.ascontiguousarray(rows, dtype=np.float32)
        row1 = row0 + len(rows)
        drawn = None  # the filtered rows, computed once for NAME.png or NAME.side.png
        for out, final, is_exr in self._outputs:
            if is_exr:
                data = rows
            else:
                plain = rows[..., :4]
                if drawn is None:
                    drawn = plain if self.png_filter is None else self.png_filter(row0, plain)
                if final in self._side_paths:
                    data = encode_srgb(np.concatenate([plain, drawn], axis=1))
                else:
                    data = encode_srgb(plain if self.side else drawn)
            with muted_stderr(not is_exr) as muted:
                ok = out.write_scanlines(row0, row1, 0, data)
            if not ok:
                raise _png_failure(final, out, muted) if not is_exr else \
                    RtreflectError(f"{final}: cannot write image ({out.geterror() or 'disk full?'})")

    def abandon(self) -> None:
        """Close the files without checks (their temporaries are about to be removed)."""
        outputs, self._outputs = self._outputs, []
        # libpng prints "No IDATs written into file" when a PNG is closed before zlib emitted any data
        # (and more on a full disk): the discarded file is closed with stderr muted.
        with muted_stderr(self._has_png):
            for out, _, _ in outputs:
                out.close()

    def close(self) -> None:
        """Finish the files; an image with pixels missing is an error (it must not be renamed into place)."""
        outputs, self._outputs = self._outputs, []
        with muted_stderr(self._has_png) as muted:
            ok = [out.close() for out, _, _ in outputs]
        if self.next_pixel != self.width * self.height:
            raise RtreflectError(f"{outputs[0][1] if outputs else 'image'}: render stopped at pixel {self.next_pixel} "
                                 f"of {self.width * self.height}")
        for (out, final, is_exr), closed in zip(outputs, ok):
            if is_exr and not closed:
                raise RtreflectError(f"{final}: cannot write image ({out.geterror() or 'disk full?'})")
            if not is_exr and (not closed or _png_incomplete(self._temporaries[final])):
                raise _png_failure(final, out, muted)


@contextlib.contextmanager
def open_outputs(scene: "Scene", outdir: Path, png_filter: PngFilter | None = None,
                 extra_files: dict[str, str] | None = None, *, remove_dead: bool = True) -> Iterator[ImageWriter]:
    """An `ImageWriter` for the scene's outputs in ``outdir``: all files appear together when the block ends, or none.

    Files are written under temporary names beside their final ones and renamed into
    place only if the block completes, so an error or Ctrl-C leaves the old files or none.
    ``png_filter(row0, rgba_rows)`` changes the linear RGBA before the PNG encodes it (the
    overlay); ``extra_files`` are text files written beside the images, by file name.
    ``remove_dead``: as in `prepare_output_folder`.
    """
    outdir = Path(outdir)
    targets = output_paths(scene, outdir)
    prepare_output_folder(outdir, output_paths(scene, outdir, extra_files), remove_dead)
    target = outdir
    # The set is renamed into place under a lock on its name (`sharing`): a concurrent run writing
    # the same NAME cannot interleave its renames with ours and leave a mixed pair.
    lock = NameLock(outdir, scene.output.name)
    try:
        with contextlib.ExitStack() as stack:
            stack.callback(lock.release)  # exits last: after every rename
            for name, text in (extra_files or {}).items():
                target = outdir / name
                stack.enter_context(atomic_path(target)).write_text(text, encoding="utf-8")
            paths = []
            for target in targets:
                paths.append((stack.enter_context(atomic_path(target)), target))
            # Exits first, before the renames, and only on success (a failure renames nothing).
            stack.push(lambda kind, value, traceback: lock.acquire() if kind is None else None)
            writer = ImageWriter(scene, paths, png_filter)
            try:
                yield writer
            except BaseException:
                writer.abandon()  # release the file handles; the temporaries are then removed
                raise
            writer.close()
    except OSError as exc:
        # Name the file the user asked for, not the temporary one the OS error may carry
        # (a failed rename carries the final name as filename2).
        raise RtreflectError(f"{exc.filename2 or target}: cannot write output ({exc.strerror or exc})") from None


def save_render(result: "RenderResult", outdir: Path, png_filter: PngFilter | None = None,
                extra_files: dict[str, str] | None = None) -> list[Path]:
    """The render's EXR and/or PNG in ``outdir`` as its `[output]` table says; all files appear together or none."""
    with open_outputs(result.scene, outdir, png_filter, extra_files) as writer:
        writer.write(0, result.film.pixels.reshape(-1, len(CHANNELS)))
    return output_paths(result.scene, outdir, extra_files)


def read_image(path: Path) -> tuple[np.ndarray, tuple[str, ...], dict[str, object]]:
    """Pixels (H, W, C) as float32 exactly as stored, channel names and header attributes of an image file."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # as stored: do not premultiply a PNG's colour by its alpha
    buf = oiio.ImageBuf(str(path), 0, 0, config)
    if buf.has_error:
        raise RtreflectError(f"{path}: cannot read image ({buf.geterror()})")
    spec = buf.spec()
    attrs = {a.name: a.value for a in spec.extra_attribs}
    return buf.get_pixels(oiio.FLOAT), tuple(spec.channelnames), attrs
