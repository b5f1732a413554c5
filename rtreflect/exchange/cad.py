"""CAD geometry files by extension: STEP (.step .stp), IGES (.igs .iges) and Rhino (.3dm).

The extension chooses the reader (case-insensitive); the first bytes must agree with it, so a
file whose extension lies about its content is one clear error instead of a parser's confusion.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import WARNING, SceneError, one_line
from .occt import CadModel

#: Extension (lower case) → format name.
CAD_SUFFIXES = {".step": "STEP", ".stp": "STEP", ".igs": "IGES", ".iges": "IGES", ".3dm": "3DM"}
#: Bytes read to recognise a format: a STEP header or the first 80-column IGES line fit easily.
SNIFF_BYTES = 4096
#: Bytes read to look past comments before a STEP file's header (a licence block).
COMMENT_BYTES = 1 << 20
#: IGES: every line is 80 columns, column 73 the section letter; the first section is Start (S),
#: or C for the compressed form.
IGES_LINE = 80
#: Names users know the formats by, for messages.
FORMAT_NAMES = {"STEP": "STEP", "IGES": "IGES", "3DM": "Rhino .3dm"}
#: Each format with its article, for "a STEP file was expected".
ARTICLES = {"STEP": "a STEP", "IGES": "an IGES", "3DM": "a Rhino .3dm"}


def is_cad_path(path: str | Path) -> bool:
    """True when ``path``'s extension names a CAD format rtreflect reads."""
    return Path(path).suffix.lower() in CAD_SUFFIXES


def sniff(data: bytes) -> str | None:
    """The CAD format ``data`` (a file's first bytes) is in: "STEP", "IGES", "3DM", or None."""
    if data.startswith(b"3D Geometry File Format "):
        return "3DM"
    text = data.removeprefix(b"\xef\xbb\xbf").lstrip()
    while text.startswith(b"/*"):  # comments may come before the header (OCCT's bug25169_box-openshell.stp)
        end = text.find(b"*/")
        if end < 0:
            return None
        text = text[end + 2:].lstrip()
    if text.startswith(b"ISO-10303-21"):
        return "STEP"
    # The first record: a line, or the first 80 columns of a file written without line breaks (HP ME's 2D
    # translator, OCCT's Disc.igs, which Open CASCADE reads).
    first = data.split(b"\n", 1)[0].rstrip(b"\r")[:IGES_LINE]
    if len(first) >= IGES_LINE - 7 and first[IGES_LINE - 8:IGES_LINE - 7] in (b"S", b"C") and first[IGES_LINE - 7:].strip().isdigit():
        return "IGES"
    return None


def read_cad(path: Path, name: str = "", skip_bad_faces: bool = False) -> CadModel:
    """Every face of a CAD file as a trimmed `NurbsSurface`, with the model's unit and bounding box.

    Raises `SceneError` (one line naming the file, and the face where one face is at fault).
    """
    path = Path(path)
    expected = CAD_SUFFIXES[path.suffix.lower()]
    try:
        with open(path, "rb") as stream:
            head = stream.read(SNIFF_BYTES)
    except FileNotFoundError:
        raise SceneError(path, "", "geometry file not found") from None
    except IsADirectoryError:
        raise SceneError(path, "", "is a folder, not a geometry file") from None
    except OSError as exc:
        raise SceneError(path, "", f"cannot read geometry file ({exc.strerror or exc})") from None
    except ValueError as exc:  # a NUL character in the path
        raise SceneError(path, "", f"cannot read geometry file ({exc})") from None
    if not head:
        raise SceneError(path, "", f"empty file: {ARTICLES[expected]} file was expected")
    found = sniff(_past_comments(path, head))
    if found is None:
        raise SceneError(path, "", f"not {ARTICLES[expected]} file: its content is not in that format "
                                   "(corrupt, binary garbage, or another kind of file)")
    if found != expected:
        raise SceneError(path, "", f"the extension says {FORMAT_NAMES[expected]} but the content is {FORMAT_NAMES[found]}: "
                                   "rename the file to match its content")
    if expected == "STEP":
        from .step import read_step

        return read_step(path, name, skip_bad_faces)
    if expected == "IGES":
        from .iges import read_iges

        return read_iges(path, name, skip_bad_faces)
    from .rhino import read_3dm

    return read_3dm(path, name, skip_bad_faces)


def _past_comments(path: Path, head: bytes) -> bytes:
    """A file's first bytes, read on past comments where it starts with one (a STEP file's licence block)."""
    if head.removeprefix(b"\xef\xbb\xbf").lstrip().startswith(b"/*"):
        with open(path, "rb") as stream:
            return stream.read(COMMENT_BYTES)
    return head


def refuse_misnamed_cad_file(path: Path) -> None:
    """A `SceneError` where a file read as a scene or a .bpt (its extension names no CAD format) holds a CAD file
    (`sniff`): 'expected the patch count, got ISO-10303-21;' told nothing. Unreadable: the reader says why."""
    try:
        with open(path, "rb") as stream:
            found = sniff(_past_comments(path, stream.read(SNIFF_BYTES)))
    except (OSError, ValueError):
        return
    if found is not None:
        names = " or ".join(suffix for suffix, kind in CAD_SUFFIXES.items() if kind == found)
        raise SceneError(path, "", f"holds {ARTICLES[found]} file, but its extension is not a CAD file's: rename it "
                                   f"to {names} to read it as a part")


def read_part(path: Path, name: str = "", skip_bad_faces: bool = False) -> tuple[list, list[str], bool]:
    """A CAD file's faces for a scene's ``[[surface]] file``: surfaces, summary lines, and whether faces were skipped."""
    model = read_cad(path, name, skip_bad_faces)
    return model.surfaces, model_summary(path, model), bool(model.skipped)


def model_summary(path: Path, model: CadModel) -> list[str]:
    """Lines telling what was read: faces, unit, bounding box, skipped faces, the reader's notes (`CadModel.notes`:
    a .3dm file's blocks placed and objects left out; printed before a render), and a
    warning line per face read short of the reader's promise (`CadModel.warnings`, starting with `errors.WARNING`)."""
    lo, hi = model.bounds
    fmt = lambda v: "[" + ", ".join(f"{x:.4g}" for x in v) + "]"  # noqa: E731
    unit = model.unit + (f" ({model.unit_note})" if model.unit_note else "")
    lines = [f"{path}: {len(model.surfaces)} faces, unit {unit}, bounding box {fmt(lo)} .. {fmt(hi)}"]
    if model.skipped:
        lines.append(f"{path}: skipped {len(model.skipped)} of {model.faces} faces (--skip-bad-faces): "
                     + "; ".join(f"face {index}: {reason}" for index, reason in model.skipped))
    if model.no_area:
        faces = f"{len(model.no_area)} face{'s' if len(model.no_area) > 1 else ''}"
        lines.append(f"{path}: left out {faces} enclosing no area (each loop runs out along a curve and back): "
                     + ", ".join(map(str, model.no_area)))
    lines.extend(f"{path}: {note}" for note in model.notes)
    lines.extend(f"{WARNING}{path}: face {index}: {one_line(reason)}" for index, reason in model.warnings)
    return lines
