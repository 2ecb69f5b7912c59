"""Controller file formats: read and write tool, base, workpiece and fixed-tool tables.

Pure functions (text in, dataclasses out; no database, no web):

- :func:`export_kuka` / :func:`read_kuka`: KUKA KR C4 ``$config.dat`` (TOOL_DATA, BASE_DATA ...);
- :func:`export_abb` / :func:`read_abb`: ABB RAPID module with ``tooldata`` / ``wobjdata``;
- :func:`export_fanuc` / :func:`read_fanuc`: FANUC UTOOL / UFRAME table and ``$MNUTOOL`` /
  ``$MNUFRAME`` listing;
- :func:`export_ur` / :func:`read_ur`: Universal Robots URScript with ``set_tcp`` /
  ``set_payload`` and features.

See docs/formats.md for the mapping of entry kinds onto each controller.
"""

from typing import Callable, Iterable, Literal

from server.formats.abb import export_abb, import_abb, read_abb
from server.formats.fanuc import export_fanuc, read_fanuc
from server.formats.kuka import export_kuka, import_kuka, read_kuka
from server.formats.encoding import (
    ENCODINGS,
    decode_file,
    encode_file,
    unwrap_kept,
    wrap_kept,
)
from server.formats.model import (
    FRAME_KINDS,
    LOADED,
    FormatError,
    FrameEntry,
    FrameKind,
    LoadData,
    ParsedFile,
    Skipped,
    canonical_order,
)
from server.formats.ur import export_ur, read_ur

ControllerFormat = Literal["kuka", "abb", "fanuc", "ur"]

#: format -> writer (entries in, text out); every format can be written.
EXPORTERS: dict[str, Callable[[Iterable[FrameEntry]], str]] = {
    "kuka": export_kuka, "abb": export_abb, "fanuc": export_fanuc, "ur": export_ur,
}
BOM = "\ufeff"


def _bom_kept(patch: Callable[[Iterable[FrameEntry], str], str]
              ) -> Callable[[Iterable[FrameEntry], str], str]:
    """A patcher that leaves a leading byte order mark where it is."""
    def patched(entries: Iterable[FrameEntry], text: str) -> str:
        text = unwrap_kept(text)[0]
        if text.startswith(BOM):
            return BOM + patch(entries, text[1:])
        return patch(entries, text)
    return patched


def _bom_read(read: Callable[[str], ParsedFile]) -> Callable[[str], ParsedFile]:
    """A reader that ignores a leading byte order mark (and a kept file's encoding mark)."""
    def reader(text: str) -> ParsedFile:
        if isinstance(text, str):
            text = unwrap_kept(text)[0]
            text = text[1:] if text.startswith(BOM) else text
        return read(text)
    reader.__doc__ = read.__doc__
    return reader


#: format -> writer into an imported file (entries, the imported text -> patched text).
PATCHERS: dict[str, Callable[[Iterable[FrameEntry], str], str]] = {
    "kuka": _bom_kept(lambda entries, text: export_kuka(entries, template=text)),
    "abb": _bom_kept(lambda entries, text: export_abb(entries, template=text)),
}
#: format -> reader of a whole file (text in, ParsedFile out).
READERS: dict[str, Callable[[str], ParsedFile]] = {
    fmt: _bom_read(read) for fmt, read in
    (("kuka", read_kuka), ("abb", read_abb), ("fanuc", read_fanuc), ("ur", read_ur))
}
#: format -> reader (text in, entries out in canonical_order).
IMPORTERS: dict[str, Callable[[str], list[FrameEntry]]] = {
    fmt: (lambda text, read=read: read(text).entries) for fmt, read in READERS.items()
}
#: the file name a controller expects (or a sensible one), for a download.
FILE_NAMES: dict[str, str] = {
    "kuka": "$config.dat", "abb": "CalibData.mod", "fanuc": "frames.txt", "ur": "frames.script",
}

__all__ = [
    "ENCODINGS", "decode_file", "encode_file", "unwrap_kept", "wrap_kept",
    "EXPORTERS", "FILE_NAMES", "FRAME_KINDS", "IMPORTERS", "LOADED", "PATCHERS", "READERS",
    "ControllerFormat", "FormatError", "FrameEntry", "FrameKind", "LoadData", "ParsedFile",
    "Skipped", "canonical_order", "export_abb", "import_abb", "read_abb", "export_fanuc",
    "export_kuka", "import_kuka", "read_kuka", "export_ur", "read_fanuc", "read_ur",
]
