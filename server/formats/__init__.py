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
    LINE_END,
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


def _file_lines(was: list[str], lines: list[str]) -> dict[int, int]:
    """Line i of pendant's listing -> the file's line that holds it: the same text, or a line
    in its place that a person edited (respaced); a line a person added maps from none."""
    out: dict[int, int] = {}
    match = difflib.SequenceMatcher(a=was, b=lines, autojunk=False)
    for op, a0, a1, b0, b1 in match.get_opcodes():
        if op == "equal" or (op == "replace" and a1 - a0 == b1 - b0):
            out.update(zip(range(a0, a1), range(b0, b1)))
        elif op == "replace":  # edited lines among added ones: each takes its closest
            free = list(range(b0, b1))
            for i in range(a0, a1):
                ratio, j = max(((difflib.SequenceMatcher(a=was[i], b=lines[k]).ratio(), k)
                                for k in free), default=(0.0, -1))
                if ratio >= 0.6:
                    out[i] = j
                    free = [k for k in free if k > j]
    return out


def _regenerating(export: Callable[[Iterable[FrameEntry]], str],
                  read: Callable[[str], ParsedFile]) -> Callable[[Iterable[FrameEntry], str], str]:
    """A patcher for a format pendant writes whole (FANUC's listing, UR's script): with no
    change the imported text itself; else the imported file with the lines of pendant's
    listing that changed replaced (each taking the ending of the line it replaces) and new
    ones added where the listing has them. Every other line keeps the file's text and ending:
    a hand-edited line of an unchanged slot, a comment line a person added, a last line
    without a line end."""
    def patch(entries: Iterable[FrameEntry], text: str) -> str:
        entries = canonical_order(entries)
        old = read(text).entries
        if entries == old:
            return text
        parts = re.split(f"({LINE_END.pattern})", text)
        lines, ends = parts[0::2], parts[1::2] + [""]
        common = max(("\n", "\r\n", "\r"), key=ends.count)
        was = export(old).split("\n")
        now = export(entries).split("\n")
        at = _file_lines(was, lines)
        instead: dict[int, list[str]] = {}  # file line -> what stands in its place
        after: dict[int, list[str]] = {}  # file line (-1: the start) -> new lines after it
        prev = -1
        for op, a0, a1, b0, b1 in difflib.SequenceMatcher(a=was, b=now, autojunk=False
                                                          ).get_opcodes():
            held = [at[i] for i in range(a0, a1) if i in at]
            if op != "equal":
                new = [now[j] for j in range(b0, b1) if j < len(now) - 1 or now[j]]
                for k in held:
                    instead[k] = []
                if held:
                    own = [ends[k] or (common if k < len(lines) - 1 else "") for k in held]
                    instead[held[0]] = [x + own[min(n, len(own) - 1)] for n, x in enumerate(new)]
                else:
                    after.setdefault(prev, []).extend(x + common for x in new)
            prev = held[-1] if held else prev
        out = after.get(-1, [])
        for k, (line, end) in enumerate(zip(lines, ends)):
            out += instead.get(k, [line + end]) + after.get(k, [])
        patched, listing = "".join(out), "\n".join(now)
        if read(patched).entries != read(listing).entries:  # too far from pendant's listing
            return listing
        return patched
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
