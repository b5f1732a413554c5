"""Image files: EXR (float32, every channel) and PNG (8-bit sRGB) through OpenImageIO.

Every file is written to a temporary name in its final folder and renamed into
place, so a failed or interrupted render leaves the old file or none, never half a file.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Iterator

import numpy as np
import OpenImageIO as oiio

with warnings.catch_warnings():
    # colour-science warns at import about optional SciPy/Matplotlib features we do not use.
    warnings.simplefilter("ignore")
    import colour

from .errors import RtreflectError
from .film import CHANNELS, Film

if TYPE_CHECKING:
    from .render import RenderResult

#: EXR header attributes that record where an image came from.
SCENE_HASH_ATTRIBUTE = "rtreflect:scene_sha256"
INPUTS_HASH_ATTRIBUTE = "rtreflect:inputs_sha256"
VERSION_ATTRIBUTE = "rtreflect:version"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(final: Path) -> Iterator[Path]:
    """A temporary path beside ``final`` (same extension, so OpenImageIO picks the format), renamed on success."""
    final = Path(final)
    fd, tmp = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=final.suffix, dir=final.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; a finished image gets the usual permissions
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _write(path: Path, spec: oiio.ImageSpec, pixels: np.ndarray, final: Path | None = None) -> None:
    """Write an image to ``path`` as is; errors name ``final`` (the name the user asked for)."""
    shown = final or path
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        raise RtreflectError(f"{shown}: cannot write image ({oiio.geterror() or 'unknown OpenImageIO error'})")
    ok = out.write_image(pixels)
    ok = out.close() and ok
    if not ok:
        raise RtreflectError(f"{shown}: cannot write image ({out.geterror() or 'disk full?'})")


def write_exr(path: Path, film: Film, attributes: dict[str, str], final: Path | None = None) -> None:
    """All channels of the film as float32, with the given header attributes (not atomic: see `save_render`)."""
    spec = oiio.ImageSpec(film.width, film.height, len(CHANNELS), oiio.FLOAT)
    spec.channelnames = CHANNELS
    spec.alpha_channel = CHANNELS.index("A")
    spec.z_channel = CHANNELS.index("Z")
    spec.attribute("compression", "zip")
    for key, value in attributes.items():
        spec.attribute(key, value)
    _write(path, spec, np.ascontiguousarray(film.pixels), final)


def encode_srgb(rgba: np.ndarray) -> np.ndarray:
    """Linear RGBA → 8-bit sRGB RGBA (colour-science's sRGB transfer function; alpha stays linear)."""
    rgb = np.clip(np.nan_to_num(rgba[..., :3], nan=0.0), 0.0, 1.0)
    encoded = colour.cctf_encoding(rgb, function="sRGB")
    alpha = np.clip(np.nan_to_num(rgba[..., 3:4], nan=0.0), 0.0, 1.0)
    return np.round(np.concatenate([encoded, alpha], axis=-1) * 255.0).astype(np.uint8)


def write_png(path: Path, rgba: np.ndarray, final: Path | None = None) -> None:
    """An 8-bit sRGB PNG of a linear (H, W, 4) RGBA image (not atomic: see `save_render`)."""
    height, width = rgba.shape[:2]
    spec = oiio.ImageSpec(width, height, 4, oiio.UINT8)
    spec.channelnames = ("R", "G", "B", "A")
    spec.alpha_channel = 3
    # Store the encoded colour verbatim: without this OpenImageIO would un-premultiply it by alpha.
    spec.attribute("oiio:UnassociatedAlpha", 1)
    _write(path, spec, encode_srgb(rgba), final)


def output_paths(scene, outdir: Path) -> list[Path]:
    """The files a render of ``scene`` writes into ``outdir``, as its `[output]` table says."""
    return [Path(outdir) / f"{scene.output.name}{suffix}"
            for suffix, wanted in ((".exr", scene.output.exr), (".png", scene.output.png)) if wanted]


def prepare_output_folder(outdir: Path, targets: list[Path] = ()) -> None:
    """Create ``outdir`` if missing and prove a file can be made in it: a bad folder fails before the render, not after.

    A folder standing where one of ``targets`` goes would stop its rename after the other files were replaced.
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


def save_render(result: "RenderResult", outdir: Path) -> list[Path]:
    """The render's EXR and/or PNG in ``outdir`` as its `[output]` table says; all files appear together or none."""
    from . import __version__

    scene = result.scene
    outdir = Path(outdir)
    targets = output_paths(scene, outdir)
    attributes = {SCENE_HASH_ATTRIBUTE: scene.sha256, INPUTS_HASH_ATTRIBUTE: scene.inputs_sha256,
                  VERSION_ATTRIBUTE: __version__}
    target = outdir
    try:
        prepare_output_folder(outdir, targets)
        with contextlib.ExitStack() as stack:
            for target in targets:
                tmp = stack.enter_context(atomic_path(target))
                if target.suffix == ".exr":
                    write_exr(tmp, result.film, attributes, final=target)
                else:
                    write_png(tmp, result.film.pixels[..., :4], final=target)
    except OSError as exc:
        # Name the file the user asked for, not the temporary one the OS error may carry
        # (a failed rename carries the final name as filename2).
        raise RtreflectError(f"{exc.filename2 or target}: cannot write output ({exc.strerror or exc})") from None
    return targets


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
