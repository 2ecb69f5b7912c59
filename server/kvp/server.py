"""The KVP face: KUKAVARPROXY's TCP protocol (OpenShowVar) for one KUKA-kind controller.

``pendant serve --kvp-port 7000 --kvp-user NAME [--kvp-controller NAME]`` (docs/kvp.md).

A message (all integers big-endian)::

    request:  msg_id u16 | length u16 | mode u8 | name_len u16 | name [| value_len u16 | value]
    answer:   msg_id u16 | length u16 | mode u8 | value_len u16 | value | 0x00 0x01 | ok u8

``length`` counts the bytes after it; mode 0 reads, 1 writes; ``ok`` is 1 on success, 0 on a
refusal (the value then says why). The protocol has no login: the face acts as one pendant
user (its role decides what it may do, checked at every message), listens on loopback
unless told otherwise, and serves only the client addresses it is given. A message longer
than :data:`MAX_CONTENT`, or one not complete within :data:`FRAME_TIMEOUT_S`, gets its error
and the connection is closed; other connections go on.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import struct
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from server.kvp import variables
from server.rws import ops
from server.service.transaction import retry_reason

if TYPE_CHECKING:
    from server.rws.service import Running

log = logging.getLogger("pendant.kvp")
MAX_CONTENT = 4096  # bytes after the length field: a name and a value (KVP's own are < 1 KB)
FRAME_TIMEOUT_S = 5.0  # a message begun must be complete within this
IDLE_TIMEOUT_S = 600.0  # a connection silent this long is closed
MAX_CONNECTIONS = 32
READ, WRITE = 0, 1
LOOPBACK = ("127.0.0.1", "::1", "localhost")


MAX_REFUSAL = 240  # bytes of a refusal's text: the whole answer stays within the 256 bytes
# clients read in one recv (py-openshowvar's recv(256)); a longer one puts them out of step,
# and their next read returns this one's tail as another variable's value


def _cut(text: str, limit: int) -> bytes:
    """``text`` in UTF-8, at most ``limit`` bytes, cut between characters (marked "...")."""
    data = text.encode("utf-8")
    if len(data) <= limit:
        return data
    return data[:limit - 3].decode("utf-8", errors="ignore").encode("utf-8") + b"..."


def pack(msg_id: int, mode: int, value: str, ok: bool) -> bytes:
    """An answer: the value (UTF-8, cut to what fits: a refusal to :data:`MAX_REFUSAL`
    bytes) and the status."""
    data = _cut(value, MAX_CONTENT if ok else MAX_REFUSAL)
    body = struct.pack("!BH", mode, len(data)) + data + b"\x00\x01" + (b"\x01" if ok else b"\x00")
    return struct.pack("!HH", msg_id, len(body)) + body


class BadMessage(Exception):
    def __init__(self, msg_id: int, mode: int, reason: str, fatal: bool = False):
        super().__init__(reason)
        self.msg_id, self.mode, self.reason, self.fatal = msg_id, mode, reason, fatal


def unpack(msg_id: int, content: bytes) -> tuple[int, str, str | None]:
    """(mode, variable name, value or None) of a message's content; BadMessage why not."""
    if len(content) < 3:
        raise BadMessage(msg_id, 0, f"message has {len(content)} bytes after its length; "
                         "a read needs mode and name length")
    mode, name_len = struct.unpack_from("!BH", content)
    if mode not in (READ, WRITE):
        raise BadMessage(msg_id, mode, f"mode {mode}: pendant reads (0) and writes (1)")
    if 3 + name_len > len(content):
        raise BadMessage(msg_id, mode, f"name length {name_len} runs past the message")
    try:
        name = content[3:3 + name_len].decode("utf-8")
    except UnicodeDecodeError:
        raise BadMessage(msg_id, mode, "variable name: not UTF-8") from None
    rest = content[3 + name_len:]
    if mode == READ:
        if rest:
            raise BadMessage(msg_id, mode, f"{len(rest)} bytes after the name of a read")
        return mode, name, None
    if len(rest) < 2:
        raise BadMessage(msg_id, mode, "a write needs the value's length and the value")
    (value_len,) = struct.unpack_from("!H", rest)
    if 2 + value_len != len(rest):
        raise BadMessage(msg_id, mode, f"value length {value_len} does not match the message "
                         f"({len(rest) - 2} bytes)")
    try:
        return mode, name, rest[2:].decode("utf-8")
    except UnicodeDecodeError:
        raise BadMessage(msg_id, mode, "value: not UTF-8") from None


@dataclass
class KvpFace:
    """The face's settings: the database, the controller, the acting user, who may connect."""

    make_session: ops.Maker
    user: str | None  # the pendant user it acts as (None only with auth off)
    controller: str | int | None = None  # name or id; None: the lowest-id KUKA controller
    auth: bool = True
    allowed: tuple[str, ...] = ()  # client addresses served besides loopback
    server: asyncio.AbstractServer | None = field(default=None, init=False)
    connections: int = field(default=0, init=False)
    # the connections waiting for their next message, and since when
    waiting: dict[asyncio.StreamWriter, float] = field(default_factory=dict, init=False)

    def who(self, client: str | None) -> ops.Caller:
        if not self.auth:
            return ops.no_auth_caller("kvp", client)
        found = ops.caller(self.make_session, self.user or "", "kvp", client)
        if found is None:
            raise LookupError(f"the face's user {self.user!r} is unknown or revoked "
                              "(pendant serve --kvp-user)")
        return found

    def allows(self, host: str | None) -> bool:
        if host is None:
            return False
        try:
            if ipaddress.ip_address(host).is_loopback:
                return True
        except ValueError:
            pass
        return host in self.allowed

    async def start(self, host: str, port: int) -> None:
        self.server = await asyncio.start_server(self.handle, host, port, limit=MAX_CONTENT * 2)

    async def stop(self) -> None:
        if self.server is not None:
            self.server.close()
            await self.server.wait_closed()

    def _answer(self, client: str | None, name: str, value: str | None) -> tuple[str, bool]:
        try:
            try:
                cid = ops.pinned(self, "kuka")
                face = variables.Face(self.make_session, cid, lambda: self.who(client))
            except (ops.Refused, LookupError) as err:
                return str(err), False
            return variables.answer(face, name, value)
        except Exception as err:  # the database busy or gone: refused, the connection kept
            why = retry_reason(err)
            log.warning("kvp: %s from %s: %s", name, client, why)
            return why, False

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        client = peer[0] if peer else None
        if not self.allows(client):
            log.warning("kvp: refused a connection from %s (not an allowed client)", client)
            writer.close()
            return
        if self.connections >= MAX_CONNECTIONS:
            # full: the connection idle longest makes room (connections held open and silent
            # must not lock every other client out); if every one is mid-message, refused
            idle = min(self.waiting, key=self.waiting.__getitem__, default=None)
            if idle is None:
                log.warning("kvp: refused a connection from %s (%d connections, each in a "
                            "message)", client, self.connections)
                writer.close()
                return
            log.warning("kvp: closed the connection idle longest (%.0f s) for one from %s",
                        time.monotonic() - self.waiting.pop(idle), client)
            idle.close()
        self.connections += 1
        try:
            await self._serve(reader, writer, client)
        except (TimeoutError, asyncio.IncompleteReadError, ConnectionError):
            pass  # the client left, or stalled mid-message: its connection ends, nothing else
        except Exception:
            log.exception("kvp: connection from %s ended by an error", client)
        finally:
            self.connections -= 1
            writer.close()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                     client: str | None) -> None:
        while True:
            self.waiting[writer] = time.monotonic()
            try:
                first = await asyncio.wait_for(reader.readexactly(1), IDLE_TIMEOUT_S)
            finally:
                self.waiting.pop(writer, None)
            head = first + await asyncio.wait_for(reader.readexactly(3), FRAME_TIMEOUT_S)
            msg_id, length = struct.unpack("!HH", head)
            if length > MAX_CONTENT:
                await _send(writer, pack(msg_id, 0, f"message of {length} bytes; at most "
                                         f"{MAX_CONTENT}", False))
                return  # the rest of it cannot be trusted to be read: close
            content = await asyncio.wait_for(reader.readexactly(length), FRAME_TIMEOUT_S)
            try:
                mode, name, value = unpack(msg_id, content)
            except BadMessage as err:
                await _send(writer, pack(err.msg_id, err.mode, err.reason, False))
                continue
            text, ok = await asyncio.to_thread(self._answer, client, name, value)
            await _send(writer, pack(msg_id, mode, text, ok))


async def _send(writer: asyncio.StreamWriter, data: bytes) -> None:
    """An answer, taken by the client within :data:`FRAME_TIMEOUT_S`: one that never reads
    its answers fills the socket, and waiting for room without a limit held its connection
    "in a message" for ever, a place no new client could have (TimeoutError ends it)."""
    writer.write(data)
    try:
        await asyncio.wait_for(writer.drain(), FRAME_TIMEOUT_S)
    except TimeoutError:
        writer.transport.abort()  # what it holds would never be taken: dropped, not flushed
        raise


def serve_in_thread(face: KvpFace, host: str, port: int) -> Running:
    """The face on ``host:port`` in a thread and event loop of its own (beside REST)."""
    from server.rws.service import Running

    running = Running("kvp", lambda: face.start(host, port), face.stop)
    running.wait_started()
    return running
