"""Webhook signatures: HMAC-SHA256 over the exact body bytes (RFC 2104, FIPS 180-4).

The header is ``X-Pendant-Signature-256: sha256=<hex>``, as GitHub's webhooks do, so a
receiver checks it with a constant-time compare of its own HMAC of the raw body.

RFC 4231 test case 2:

>>> sign(b"Jefe", b"what do ya want for nothing?")
'sha256=5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843'
"""

from __future__ import annotations

import hashlib
import hmac

HEADER = "X-Pendant-Signature-256"


def sign(secret: bytes, body: bytes) -> str:
    return "sha256=" + hmac.new(secret, body, hashlib.sha256).hexdigest()


def verify(secret: bytes, body: bytes, header: str) -> bool:
    """True when ``header`` is the signature of ``body`` under ``secret`` (constant time)."""
    return hmac.compare_digest(sign(secret, body), header)
