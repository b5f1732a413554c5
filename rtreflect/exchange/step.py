"""STEP reader (ISO 10303-21; AP203, AP214, AP242) through Open CASCADE's ``STEPControl_Reader``.

The file's shape (assemblies: a compound of every located instance) goes to `occt.read_faces`,
which converts, trims and meshes each face. Open CASCADE reads lengths in millimetres whatever
the file's unit (its ``xstep.cascade.unit`` default): a STEP in inches comes out in mm, and the
model summary says so.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from .isolation import read_isolated
from .occt import CadModel, import_ocp, read_faces, read_xstep, transferred_shape

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
    return read_faces(path, shape, name, unit=READ_UNIT, unit_note=note, what="STEP file", skip_bad_faces=skip_bad_faces)


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
