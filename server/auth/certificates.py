"""X.509 certificates of OPC UA logins: read a client's certificate file, and whether it is
valid now. A certificate that has expired or is not valid yet is refused where it is
registered (``pendant users cert``), trusted (``pendant opcua trust``) and presented
(``server.opcua.pki``, ``server.opcua.access``)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding


def check_time(cert: x509.Certificate) -> str | None:
    """Why ``cert`` is not valid now, or None."""
    now = datetime.now(UTC)
    if cert.not_valid_after_utc < now:
        return f"expired on {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC"
    if cert.not_valid_before_utc > now:
        return f"not valid before {cert.not_valid_before_utc:%Y-%m-%d %H:%M} UTC"
    return None


def certificate_der(path: Path) -> bytes:
    """The DER bytes of a certificate file (PEM or DER) valid now; ValueError naming the file
    and the reason (not a certificate, expired, not valid yet)."""
    data = path.read_bytes()
    try:
        cert = (x509.load_pem_x509_certificate(data) if b"-----BEGIN" in data
                else x509.load_der_x509_certificate(data))
    except ValueError:
        raise ValueError(f"{path}: not an X.509 certificate (PEM or DER)") from None
    why = check_time(cert)
    if why is not None:
        raise ValueError(f"{path}: the certificate {why}")
    return cert.public_bytes(Encoding.DER)
