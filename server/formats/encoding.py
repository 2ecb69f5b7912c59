"""The bytes of a controller file: its encoding, found on import and used again on export.

KSS and RobotWare write their files on Windows, in Windows-1252 (``"Greifer Öl"``,
``TPWrite "Cartón detectado."``); files edited elsewhere are UTF-8. :func:`decode_file`
takes UTF-8 when the bytes are valid UTF-8 (a byte order mark stays in the text, as the
character U+FEFF) and Windows-1252 otherwise; :func:`encode_file` writes the text back in
the same encoding, so a file with no change comes back byte for byte. The five bytes
Windows-1252 leaves undefined (0x81, 0x8D, 0x8F, 0x90, 0x9D) are read as the control
characters U+0081 ... of the same number and written back as the same byte (as browsers'
``TextDecoder("windows-1252")`` does), so no byte is lost.

The kept file (the last import of a format) is stored as text with its encoding beside it
(``controller_file.encoding``, revision 0010).
"""

from __future__ import annotations

import codecs
from typing import Literal

from server.formats.model import FormatError

__all__ = ["ENCODINGS", "Encoding", "decode_file", "encode_file"]

Encoding = Literal["utf-8", "cp1252"]
ENCODINGS: tuple[str, ...] = ("utf-8", "cp1252")
_UNDEFINED = {0x81, 0x8D, 0x8F, 0x90, 0x9D}


def _c1_decode(err: UnicodeDecodeError) -> tuple[str, int]:
    bad = err.object[err.start:err.end]
    if all(b in _UNDEFINED for b in bad):
        return "".join(chr(b) for b in bad), err.end
    raise err


def _c1_encode(err: UnicodeEncodeError) -> tuple[bytes, int]:
    bad = err.object[err.start:err.end]
    if all(ord(c) in _UNDEFINED for c in bad):
        return bytes(ord(c) for c in bad), err.end
    raise err


codecs.register_error("pendant-c1", lambda e: _c1_decode(e) if isinstance(
    e, UnicodeDecodeError) else _c1_encode(e))  # type: ignore[arg-type]


def decode_file(raw: bytes) -> tuple[str, Encoding]:
    """The text of a controller file and the encoding it was written in.

    Examples
    --------
    >>> decode_file("Greifer Öl".encode("cp1252"))
    ('Greifer Öl', 'cp1252')
    >>> decode_file("Greifer Öl".encode())
    ('Greifer Öl', 'utf-8')
    """
    try:
        return raw.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="pendant-c1"), "cp1252"


def encode_file(text: str, encoding: str) -> bytes:
    """``text`` in ``encoding``; FormatError naming the line and the character that the
    encoding cannot hold (a name typed on the pendant, say).

    Examples
    --------
    >>> encode_file("Cartón", "cp1252")
    b'Cart\\xf3n'
    """
    if encoding == "utf-8":
        return text.encode("utf-8")
    try:
        return text.encode(encoding, errors="pendant-c1")
    except UnicodeEncodeError as err:
        line = text.count("\n", 0, err.start) + 1
        raise FormatError.at_line(line, "text", f"{err.object[err.start]!r} cannot be written "
                                  f"in the file's encoding {encoding}; rename it") from None
