"""HTTP Digest authentication (RFC 7616, MD5, qop ``auth``) as RobotWare's RWS asks for it.

A user's RWS secret is stored only as its HA1, ``MD5(name ":" realm ":" password)``
(``pendant users rws-password NAME``): the digest needs nothing else, and the password itself
is never stored. The realm is RWS's own, ``validusers``, so an HA1 is bound to it.

Nonces are stateless: ``<unix time in µs>.<HMAC-SHA256(key, time)>`` with a key made per
process; a nonce is honoured for :data:`NONCE_TTL_S`, after which the answer is a 401 with
``stale=true`` (clients sign again without asking the user). A (nonce, cnonce, nc) seen
once is refused the second time, so a captured request cannot be replayed; past
:data:`SEEN_MAX` the oldest are forgotten, and with them every nonce made up to theirs.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets
import threading
import time
from collections import OrderedDict

REALM = "validusers"
NONCE_TTL_S = 300.0
SEEN_MAX = 100_000  # remembered (nonce, cnonce, nc) triples; the oldest go first
_KEY = secrets.token_bytes(32)
# a name starts where no word character precedes it: from every letter of "aaaa..." (no '=')
# the pattern was tried and backtracked, quadratic time in the event loop (60 000: 18 s)
_PARAM = re.compile(r'(?<!\w)(\w+)\s*=\s*(?:"((?:[^"\\]|\\.)*)"|([^\s,]+))')
MAX_HEADER = 4096  # characters of an Authorization header (a Digest one has some 300)


def md5(text: str) -> str:
    return hashlib.md5(text.encode("utf-8"), usedforsecurity=False).hexdigest()


def ha1(name: str, password: str) -> str:
    """The stored form of an RWS secret."""
    return md5(f"{name}:{REALM}:{password}")


def new_nonce(now: float | None = None) -> str:
    t = f"{int((now if now is not None else time.time()) * 1e6)}"  # µs: see Seen.floor
    return t + "." + hmac.new(_KEY, t.encode(), hashlib.sha256).hexdigest()[:32]


def nonce_age_s(nonce: str, now: float | None = None) -> float | None:
    """Seconds since this process made ``nonce``; None if it did not make it."""
    t, _, mac = nonce.partition(".")
    good = hmac.new(_KEY, t.encode(), hashlib.sha256).hexdigest()[:32]
    if not (t.isascii() and t.isdigit()) or not hmac.compare_digest(mac.encode(), good.encode()):
        return None
    return (now if now is not None else time.time()) - int(t) / 1e6


def challenge(stale: bool = False) -> str:
    """The ``WWW-Authenticate`` value of a 401."""
    return (f'Digest realm="{REALM}", qop="auth", algorithm=MD5, nonce="{new_nonce()}"'
            + (", stale=true" if stale else ""))


def parse(header: str) -> dict[str, str] | None:
    """The parameters of an ``Authorization: Digest ...`` header (None: not Digest)."""
    if len(header) > MAX_HEADER:
        return None
    scheme, _, rest = header.strip().partition(" ")
    if scheme.lower() != "digest":
        return None
    return {m.group(1).lower(): m.group(2) if m.group(2) is not None else m.group(3)
            for m in _PARAM.finditer(rest)}


class Seen:
    """The (nonce, cnonce, nc) triples already used (replays are refused).

    A triple forgotten to keep :data:`SEEN_MAX` could be replayed while its nonce is honoured,
    so ``floor`` is the newest nonce time of those forgotten and a nonce made at or before it
    is refused (stale: the client signs again with a new nonce)."""

    def __init__(self) -> None:
        # a digest of the triple: the cnonce is the client's choice, of any length
        self._seen: OrderedDict[bytes, int] = OrderedDict()
        self._lock = threading.Lock()
        self.floor = -1  # µs

    def first_use(self, triple: tuple[str, str, str]) -> bool:
        minted = int(triple[0].partition(".")[0])  # a nonce verify() checked: its digits
        key = hashlib.sha256("\n".join(triple).encode("utf-8", "surrogateescape")).digest()
        with self._lock:
            if key in self._seen or minted <= self.floor:
                return False
            self._seen[key] = minted
            while len(self._seen) > SEEN_MAX:
                self.floor = max(self.floor, self._seen.popitem(last=False)[1])
            return True


class Verdict:
    """The outcome of :func:`verify`: ``user`` on success, else why (``stale`` nonce or not)."""

    def __init__(self, user: str | None, reason: str, stale: bool = False):
        self.user, self.reason, self.stale = user, reason, stale


def verify(params: dict[str, str], method: str, ha1_of, seen: Seen) -> Verdict:
    """Check a Digest response: ``ha1_of(name)`` gives the stored HA1 (or None)."""
    need = ("username", "realm", "nonce", "uri", "response")
    missing = [k for k in need if not params.get(k)]
    if missing:
        return Verdict(None, f"Digest without {', '.join(missing)}")
    if params["realm"] != REALM:
        return Verdict(None, f"realm must be {REALM!r}")
    if params.get("algorithm", "MD5").upper() != "MD5":
        return Verdict(None, "algorithm must be MD5")
    age = nonce_age_s(params["nonce"])
    if age is None:
        return Verdict(None, "unknown nonce", stale=True)
    if age > NONCE_TTL_S or age < -5:
        return Verdict(None, "nonce expired", stale=True)
    # one answer and the same work for an unknown user and a wrong password: neither the
    # message nor the time tells which user names exist
    stored = ha1_of(params["username"]) or md5(f"{secrets.token_hex(16)}:{REALM}:")
    ha2 = md5(f"{method}:{params['uri']}")
    qop = params.get("qop")
    if qop:
        if qop != "auth" or not params.get("nc") or not params.get("cnonce"):
            return Verdict(None, "qop must be auth, with nc and cnonce")
        want = md5(f"{stored}:{params['nonce']}:{params['nc']}:{params['cnonce']}:auth:{ha2}")
    else:
        want = md5(f"{stored}:{params['nonce']}:{ha2}")
    if not hmac.compare_digest(want.encode(), params["response"].lower().encode()):
        return Verdict(None, "wrong user name or password (or no RWS secret set: pendant "
                             "users rws-password)")
    # without qop the response covers no cnonce nor nc: they are no part of the key, or a
    # captured request replays with any cnonce added
    key = (params["nonce"], params["cnonce"], params["nc"]) if qop else (params["nonce"], "", "")
    if not seen.first_use(key):
        return Verdict(None, "nonce count used before (a replay), or the nonce is older than "
                             "the replays remembered", stale=True)
    return Verdict(params["username"], "ok")
