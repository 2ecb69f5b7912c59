"""Controller file formats: read and write tool, base, workpiece and fixed-tool tables.

Pure functions (text in, dataclasses out; no database, no web):

- :func:`export_kuka` / :func:`import_kuka`: KUKA KR C4 ``$config.dat`` (TOOL_DATA, BASE_DATA ...);
- :func:`export_abb` / :func:`import_abb`: ABB RAPID module with ``tooldata`` / ``wobjdata``;
- :func:`export_fanuc`: FANUC UTOOL / UFRAME table and ``$MNUTOOL`` / ``$MNUFRAME`` listing;
- :func:`export_ur`: Universal Robots URScript with ``set_tcp`` / ``set_payload`` and features.

See docs/formats.md for the mapping of entry kinds onto each controller.
"""

from typing import Callable, Iterable, Literal

from server.formats.abb import export_abb, import_abb
from server.formats.fanuc import export_fanuc
from server.formats.kuka import export_kuka, import_kuka
from server.formats.model import (
    FRAME_KINDS,
    FormatError,
    FrameEntry,
    FrameKind,
    LoadData,
    canonical_order,
)
from server.formats.ur import export_ur

ControllerFormat = Literal["kuka", "abb", "fanuc", "ur"]

#: format -> writer (entries in, text out); every format can be written.
EXPORTERS: dict[str, Callable[[Iterable[FrameEntry]], str]] = {
    "kuka": export_kuka, "abb": export_abb, "fanuc": export_fanuc, "ur": export_ur,
}
#: format -> reader (text in, entries out in canonical_order); KUKA and ABB can be read.
IMPORTERS: dict[str, Callable[[str], list[FrameEntry]]] = {"kuka": import_kuka, "abb": import_abb}
#: the file name a controller expects (or a sensible one), for a download.
FILE_NAMES: dict[str, str] = {
    "kuka": "$config.dat", "abb": "CalibData.mod", "fanuc": "frames.txt", "ur": "frames.script",
}

__all__ = [
    "EXPORTERS", "FILE_NAMES", "FRAME_KINDS", "IMPORTERS", "ControllerFormat", "FormatError",
    "FrameEntry", "FrameKind", "LoadData", "canonical_order",
    "export_abb", "import_abb", "export_fanuc", "export_kuka", "import_kuka", "export_ur",
]
