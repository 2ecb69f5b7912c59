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

import difflib
import re
from typing import Callable, Iterable, Literal

from server.formats.abb import export_abb, import_abb, read_abb
from server.formats.encoding import (
    ENCODINGS,
    decode_file,
    encode_file,
)
from server.formats.fanuc import export_fanuc, is_controller_listing, read_fanuc
from server.formats.fanuc_sysframe import patch_sysframe
from server.formats.kuka import export_kuka, import_kuka, read_kuka
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
        if text.startswith(BOM):
            return BOM + patch(entries, text[1:])
        return patch(entries, text)
    return patched


def _bom_read(read: Callable[[str], ParsedFile]) -> Callable[[str], ParsedFile]:
    """A reader that ignores a leading byte order mark (and a kept file's encoding mark)."""
    def reader(text: str) -> ParsedFile:
        if isinstance(text, str):
            text = text[1:] if text.startswith(BOM) else text
        return read(text)
    reader.__doc__ = read.__doc__
    return reader


def _regenerating(export: Callable[[Iterable[FrameEntry]], str],
                  read: Callable[[str], ParsedFile]) -> Callable[[Iterable[FrameEntry], str], str]:
    """A patcher for a format pendant writes whole (FANUC's listing, UR's script): with no
    change the imported text itself; else pendant's listing of the new entries, in which
    every line that the listing of the imported entries also has, in the same place, keeps
    the imported file's text and line ending (a hand-edited line of an unchanged slot stays
    too), and a new or changed line takes the ending of the line it replaces."""
    def patch(entries: Iterable[FrameEntry], text: str) -> str:
        entries = canonical_order(entries)
        old = read(text).entries
        if entries == old:
            return text
        parts = re.split(r"(\r\n|\r|\n)", text)
        lines, ends = parts[0::2], parts[1::2] + [""]
        common = max(("\n", "\r\n", "\r"), key=ends.count)
        was = export(old).split("\n")
        now = export(entries).split("\n")
        out: list[str] = []
        same = difflib.SequenceMatcher(a=was, b=now, autojunk=False)
        mapped = len(was) == len(lines)  # the file is pendant's listing, line for line
        for op, a0, a1, b0, b1 in same.get_opcodes():
            if op == "equal" and mapped:
                out += [lines[i] + ends[i] for i in range(a0, a1)]
                continue
            for k, j in enumerate(range(b0, b1)):
                i = min(a0 + k, len(ends) - 1)
                end = (ends[i] or common) if mapped else common
                out.append(now[j] + (end if j < len(now) - 1 else ""))
        return "".join(out)
    return patch


#: format -> writer into an imported file (entries, the imported text -> patched text).
PATCHERS: dict[str, Callable[[Iterable[FrameEntry], str], str]] = {
    "kuka": _bom_kept(lambda entries, text: export_kuka(entries, template=text)),
    "abb": _bom_kept(lambda entries, text: export_abb(entries, template=text)),
    "fanuc": _bom_kept(lambda entries, text, listing=_regenerating(export_fanuc, read_fanuc): (
        patch_sysframe(entries, text) if is_controller_listing(text) else listing(entries, text))),
    "ur": _bom_kept(_regenerating(export_ur, read_ur)),
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
    "ENCODINGS", "decode_file", "encode_file",
    "EXPORTERS", "FILE_NAMES", "FRAME_KINDS", "IMPORTERS", "LOADED", "PATCHERS", "READERS",
    "ControllerFormat", "FormatError", "FrameEntry", "FrameKind", "LoadData", "ParsedFile",
    "Skipped", "canonical_order", "export_abb", "import_abb", "read_abb", "export_fanuc",
    "export_kuka", "import_kuka", "read_kuka", "export_ur", "read_fanuc", "read_ur",
]
