"""STEP reader (ISO 10303-21; AP203, AP214, AP242) through Open CASCADE's ``STEPControl_Reader``.

The file's shape (assemblies: a compound of every located instance) goes to `occt.read_faces`,
which converts, trims and meshes each face. Open CASCADE reads lengths in millimetres whatever
the file's unit (its ``xstep.cascade.unit`` default): a STEP in inches comes out in mm, and the
model summary says so.
"""

from __future__ import annotations

import re
from functools import partial
from pathlib import Path

from ..errors import SceneError
from .isolation import read_isolated
from .occt import CadModel, count_entities, import_ocp, read_faces, read_xstep, transferred_shape

#: What Open CASCADE converts every STEP length to.
READ_UNIT = "mm"


def read_step(path: Path, name: str = "", skip_bad_faces: bool = False) -> CadModel:
    """Every face of a STEP file as a trimmed NURBS surface (see `occt.read_faces`)."""
    import_ocp(path, "STEP files")
    # The reader's model of the file's entities (hundreds of MB for a large file) ends with the child.
    shape, info = read_isolated(path, "STEP file", partial(transfer, path))
    file_units = info["units"]
    note = ""
    if file_units and file_units != ["millimetre"]:
        note = f"file in {', '.join(file_units)}, read in {READ_UNIT}"
    if shape is None or shape.IsNull() or count_entities(shape)["faces"] == 0:
        others = external_parts(path)
        if others:
            listed = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
            raise SceneError(path, "", f"no surfaces to render: the STEP file is an assembly whose parts lie in other "
                                       f"files ({listed}): render those files, or export the assembly with its parts")
    return read_faces(path, shape, name, unit=READ_UNIT, unit_note=note, what="STEP file", skip_bad_faces=skip_bad_faces)


#: The entities of a STEP assembly that name its parts' files (the CAx-IF's external references), and such a name.
_REFERENCE = re.compile(r"(?:EXTERNAL_SOURCE|DOCUMENT_FILE)\s*\(([^;]*)", re.IGNORECASE)
_PART_FILE = re.compile(r"'([^']*\.(?:stp|step|p21|stpz))'", re.IGNORECASE)


def external_parts(path: Path) -> list[str]:
    """The STEP files an assembly names for its parts (EXTERNAL_SOURCE, also as IDENTIFIER('...'), and DOCUMENT_FILE
    entities), in order of first mention, or none. Other names there (a font, the CAD system, '/NULL') are no part."""
    text = Path(path).read_bytes().decode("latin-1")
    return list(dict.fromkeys(name for entity in _REFERENCE.finditer(text) for name in _PART_FILE.findall(entity[1])))


def transfer(path: Path) -> tuple[object, dict]:
    """The file's transferred shape and its length units: run in the reading child (isolation.py; OCCT crashes on
    some corrupt files), by name, so a child that does not share this process's memory can run it too."""
    from OCP.STEPControl import STEPControl_Reader
    from OCP.collections import Sequence_TCollection_AsciiString as Names

    reader = STEPControl_Reader()
    read_xstep(reader, path, "STEP")
    lengths, angles, solid_angles = Names(), Names(), Names()
    reader.FileUnits(lengths, angles, solid_angles)
    return transferred_shape(reader), {"units": sorted({str(n.ToCString()).lower() for n in lengths})}
