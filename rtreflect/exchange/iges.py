"""IGES reader (IGES 5.3: trimmed surfaces 144, B-spline surfaces 128, manifold solids 186)
through Open CASCADE's ``IGESControl_Reader``.

The transferred shape goes to `occt.read_faces`, which converts, trims and meshes each face.
Open CASCADE converts lengths to millimetres (the global section's unit is reported).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from .isolation import read_isolated
from .occt import CadModel, import_ocp, read_faces, read_xstep, transferred_shape

#: What Open CASCADE converts every IGES length to.
READ_UNIT = "mm"


def read_iges(path: Path, name: str = "", skip_bad_faces: bool = False) -> CadModel:
    """Every face of an IGES file as a trimmed NURBS surface (see `occt.read_faces`)."""
    import_ocp(path, "IGES files")
    # The reader's model of the file's entities (hundreds of MB for a large file) ends with the child.
    shape, info = read_isolated(path, "IGES file", partial(transfer, path))
    unit, note = info["unit"], ""
    if unit and unit not in ("mm", "millimeter", "millimetre"):
        note = f"file in {unit}, read in {READ_UNIT}"
    return read_faces(path, shape, name, unit=READ_UNIT, unit_note=note, what="IGES file", skip_bad_faces=skip_bad_faces)


def transfer(path: Path) -> tuple[object, dict]:
    """The file's transferred shape and its global section's unit name: run in the reading child (isolation.py;
    OCCT crashes on some corrupt files), by name, so a child that does not share this process's memory can run it."""
    from OCP.IGESControl import IGESControl_Reader

    reader = IGESControl_Reader()
    read_xstep(reader, path, "IGES")
    try:
        unit = str(reader.IGESModel().GlobalSection().UnitName().ToCString()).strip().lower()
    except Exception:  # a global section without a unit name: nothing to report
        unit = ""
    return transferred_shape(reader), {"unit": unit}
