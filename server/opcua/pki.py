"""The OPC UA face's PKI folder: its own certificate and key, and the clients it trusts.

One folder per instance (``--pki DIR``; by default beside the SQLite file, else per database
URL in the user data directory), mode 0700, the key 0600::

    DIR/own/pendant-server-key.pem   the private key (0600)
    DIR/own/pendant-server-cert.der  the self-signed application certificate
    DIR/trusted/*.der                client application certificates allowed to open a channel
    DIR/rejected/*.der               the last certificates refused as untrusted: accept one with
                                     ``pendant opcua trust DIR/rejected/NAME.der``

A client's certificate must be in ``trusted/`` (compared by SHA-256 of its DER) and valid now
(not expired, not yet valid), else its secure channel is refused (``BadCertificateUntrusted``,
``BadCertificateTimeInvalid``). ``trusted/`` is read on each new channel: trusting a
certificate takes effect without a restart.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import stat
from pathlib import Path

from asyncua import ua
from asyncua.common.utils import ServiceError
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding

from server.auth.certificates import check_time

log = logging.getLogger("pendant.opcua")
KEY_NAME, CERT_NAME = "pendant-server-key.pem", "pendant-server-cert.der"
REJECTED_KEEP = 50  # the newest refused certificates kept for `pendant opcua trust`


class PkiError(ValueError):
    """A certificate file that cannot be trusted: names the file and the reason."""


def default_pki_dir(db_url: str) -> Path:
    """The instance's PKI folder: ``<db file>-opcua-pki`` beside a SQLite file, else
    ``opcua-pki-<hash of the URL>`` in the user data directory (one per database)."""
    import platformdirs
    from sqlalchemy.engine import make_url

    url = make_url(db_url)
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        db = Path(url.database).resolve()  # type: ignore[arg-type]
        return db.with_name(db.name + "-opcua-pki")
    digest = hashlib.sha256(url.render_as_string(hide_password=True).encode()).hexdigest()[:12]
    return Path(platformdirs.user_data_dir("pendant")) / f"opcua-pki-{digest}"


def private_folder(path: Path) -> Path:
    """``path`` made (or narrowed) to mode 0700."""
    path.mkdir(parents=True, exist_ok=True, mode=0o700)
    if stat.S_IMODE(path.stat().st_mode) != 0o700:
        path.chmod(0o700)
    return path


async def server_certificate(pki: Path, app_uri: str) -> tuple[Path, Path]:
    """(certificate, key) of the server, made on first start; the folders 0700, the key 0600."""
    import socket

    from asyncua.crypto.cert_gen import (
        dump_private_key_as_pem,
        generate_private_key,
        generate_self_signed_app_certificate,
    )
    from cryptography.x509.oid import ExtendedKeyUsageOID

    private_folder(pki)
    own = private_folder(pki / "own")
    for name in ("trusted", "rejected"):
        private_folder(pki / name)
    key, cert = own / KEY_NAME, own / CERT_NAME
    if key.exists() and cert.exists():
        if stat.S_IMODE(key.stat().st_mode) != 0o600:
            log.warning("OPC UA: %s was readable by others; now 0600", key)
            key.chmod(0o600)
        return cert, key
    host = socket.gethostname()
    pk = generate_private_key()
    der = generate_self_signed_app_certificate(
        pk, app_uri, {"organizationName": "pendant", "commonName": "pendant OPC UA"},
        [x509.UniformResourceIdentifier(app_uri), x509.DNSName(host)],
        [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
    ).public_bytes(Encoding.DER)
    fd = os.open(key, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(dump_private_key_as_pem(pk))
    cert.write_bytes(der)
    return cert, key


def fingerprint(der: bytes) -> str:
    return hashlib.sha256(der).hexdigest()


def load_certificate(data: bytes) -> x509.Certificate:
    """A DER or PEM certificate (the first of a chain)."""
    if data.lstrip().startswith(b"-----BEGIN"):
        return x509.load_pem_x509_certificate(data)
    return x509.load_der_x509_certificate(data)


class TrustList:
    """The client application certificates of ``pki/trusted``; refused ones go to ``rejected``."""

    def __init__(self, pki: Path) -> None:
        self.trusted, self.rejected = pki / "trusted", pki / "rejected"

    def fingerprints(self) -> set[str]:
        found = set()
        for f in self.trusted.glob("*"):
            try:
                found.add(fingerprint(load_certificate(f.read_bytes()).public_bytes(Encoding.DER)))
            except (OSError, ValueError):
                log.warning("OPC UA: %s in the trust list is not a certificate; ignored", f)
        return found

    def check(self, der: bytes | None) -> None:
        """Raise the OPC UA status that refuses a channel with this client certificate."""
        if not der:
            raise ServiceError(ua.StatusCodes.BadCertificateInvalid)
        try:
            cert = x509.load_der_x509_certificate(der)
        except ValueError:
            raise ServiceError(ua.StatusCodes.BadCertificateInvalid) from None
        why = check_time(cert)
        if why is not None:
            log.warning("OPC UA: client certificate %s refused: %s", _subject(cert), why)
            raise ServiceError(ua.StatusCodes.BadCertificateTimeInvalid)
        if fingerprint(der) not in self.fingerprints():
            self._keep_rejected(cert, der)
            raise ServiceError(ua.StatusCodes.BadCertificateUntrusted)

    def _keep_rejected(self, cert: x509.Certificate, der: bytes) -> None:
        path = self.rejected / _file_name(cert, der)
        log.warning("OPC UA: client certificate %s is not trusted; to accept it once: "
                    "pendant opcua trust %s", _subject(cert), path)
        try:
            path.write_bytes(der)
            old = sorted(self.rejected.glob("*.der"), key=lambda p: p.stat().st_mtime)
            for p in old[:-REJECTED_KEEP]:
                p.unlink(missing_ok=True)
        except OSError:
            pass


def trust(pki: Path, cert_file: Path) -> Path:
    """Copy ``cert_file`` into the trust list; refused if not a certificate or not valid now."""
    try:
        cert = load_certificate(cert_file.read_bytes())
    except OSError as err:
        raise PkiError(f"{cert_file}: cannot read: {err.strerror}") from None
    except ValueError:
        raise PkiError(f"{cert_file}: not a DER or PEM X.509 certificate") from None
    why = check_time(cert)
    if why is not None:
        raise PkiError(f"{cert_file}: {why}")
    private_folder(pki)
    der = cert.public_bytes(Encoding.DER)
    target = private_folder(pki / "trusted") / _file_name(cert, der)
    target.write_bytes(der)
    return target


def _subject(cert: x509.Certificate) -> str:
    return cert.subject.rfc4514_string() or "(no subject)"


def _file_name(cert: x509.Certificate, der: bytes) -> str:
    cn = cert.subject.get_attributes_for_oid(x509.NameOID.COMMON_NAME)
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(cn[0].value) if cn else "client")[:40]
    return f"{name}-{fingerprint(der)[:16]}.der"
