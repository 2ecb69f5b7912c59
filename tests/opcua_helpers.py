"""The OPC UA face in a test: the server in a thread of its own, clients on its encrypted
endpoint with a client certificate in the face's trust list (tests/test_opcua*.py)."""

from __future__ import annotations

import asyncio
import datetime as dt
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from asyncua import Client, ua
from api_helpers import make_client, ok
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from browser_helpers import free_port
from cryptography import x509
from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives.asymmetric import rsa
from cryptography.hazmat.primitives.serialization import Encoding, NoEncryption, PrivateFormat
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from server.opcua import pki
from server.opcua.service import PendantOpcUa
from server.opcua.space import DI_URI, PENDANT_URI, ROBOTICS_URI

CLIENT_URI = "urn:pendant:tests:mes-client"


@dataclass
class ClientCert:
    cert: str  # DER file
    key: str  # PEM file
    uri: str = CLIENT_URI

    def der(self) -> bytes:
        return Path(self.cert).read_bytes()


def client_certificate(folder: Path, name: str = "mes-client", uri: str = CLIENT_URI,
                       valid_from_days: float = -1, valid_days: float = 365) -> ClientCert:
    """A client's self-signed application certificate and key (as a cell PC would have),
    valid from now + ``valid_from_days`` for ``valid_days``."""
    folder.mkdir(parents=True, exist_ok=True)
    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name),
                         x509.NameAttribute(NameOID.ORGANIZATION_NAME, "pendant tests")])
    start = dt.datetime.now(dt.UTC) + dt.timedelta(days=valid_from_days)
    cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(start).not_valid_after(start + dt.timedelta(days=valid_days))
            .add_extension(x509.SubjectAlternativeName(
                [x509.UniformResourceIdentifier(uri), x509.DNSName(socket.gethostname())]),
                critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=True,
                                         key_encipherment=True, data_encipherment=True,
                                         key_agreement=False, key_cert_sign=False,
                                         crl_sign=False, encipher_only=False,
                                         decipher_only=False), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.CLIENT_AUTH]),
                           critical=False)
            .sign(key, hashes.SHA256()))
    cert_path, key_path = folder / f"{name}-cert.der", folder / f"{name}-key.pem"
    cert_path.write_bytes(cert.public_bytes(Encoding.DER))
    key_path.write_bytes(key.private_bytes(Encoding.PEM, PrivateFormat.TraditionalOpenSSL,
                                           NoEncryption()))
    return ClientCert(str(cert_path), str(key_path), uri)


@dataclass
class Face:
    """A running OPC UA face (its own event loop in a thread) and a trusted client cert."""

    server: PendantOpcUa
    pki: Path
    client: ClientCert
    loop: asyncio.AbstractEventLoop = field(repr=False)
    thread: threading.Thread = field(repr=False)

    @property
    def endpoint(self) -> str:
        return self.server.endpoint

    def run(self, coro, timeout: float = 120):
        """Run ``coro`` on the face's loop (its address space is not thread-safe)."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout=timeout)

    def restart(self) -> None:
        """Stop the face and start a new one on the same port, database and PKI folder (as a
        `pendant serve` restart does)."""
        old = self.server
        self.run(old.stop(), timeout=30)
        self.server = PendantOpcUa(old.make_session, old.endpoint, poll_s=old.poll_s,
                                   auth=old.auth, pki_dir=old.pki_dir,
                                   none_endpoint=old.none_endpoint)
        self.run(self.server.start())

    def stop(self) -> None:
        self.run(self.server.stop(), timeout=30)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=10)


def start_face(make_session, folder: Path, port: int | None = None,
               **kwargs) -> Face:
    """The face on ``make_session``'s database, its PKI in ``folder/pki`` with one trusted
    client certificate (``face.client``)."""
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, name="opcua", daemon=True)
    thread.start()
    server = PendantOpcUa(make_session, f"opc.tcp://127.0.0.1:{port or free_port()}/pendant/",
                          poll_s=0.1, pki_dir=folder / "pki", **kwargs)
    client = client_certificate(folder / "client")
    pki.trust(folder / "pki", Path(client.cert))
    face = Face(server, folder / "pki", client, loop, thread)
    face.run(server.start())
    return face


@contextmanager
def rest_and_face(db_url: str, folder: Path, **kwargs) -> Iterator[dict]:
    """REST (a TestClient, the Administrator) and the face (:func:`start_face`, ``kwargs``)
    on one database: {rest, face, db_url, folder}."""
    with make_client(db_url) as rest:
        face = start_face(rest.app.state.sessionmaker, folder, **kwargs)
        try:
            yield {"rest": rest, "face": face, "db_url": db_url, "folder": folder}
        finally:
            face.stop()


def module_cell(folder: str, **kwargs):  # noqa: ANN201
    """A module's fixture ``cell``: :func:`rest_and_face` on a fresh database, the face's
    files in a new folder named ``folder``, ``kwargs`` to :func:`start_face`."""
    @pytest.fixture(scope="module")
    def cell(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:  # noqa: ANN001
        with rest_and_face(fresh_db(), tmp_path_factory.mktemp(folder), **kwargs) as running:
            yield running
    return cell


def add_user(cell: dict, name: str, role: str) -> str:
    """A new user of ``role`` made over REST (``cell["rest"]``); its API token."""
    ok(cell["rest"].post("/users", json={"name": name, "role": role}))
    return ok(cell["rest"].post(f"/users/{name}/tokens", json={}))["token"]


async def secure_client(endpoint: str, cert: ClientCert, user: str | None = None,
                        password: str | None = None, identity: ClientCert | None = None,
                        timeout: float = 10) -> Client:
    """An asyncua client on the Basic256Sha256 SignAndEncrypt endpoint with ``cert``; a
    username/password login, or an X509 identity token of ``identity``."""
    client = Client(endpoint, timeout=timeout)
    client.application_uri = cert.uri
    await client.set_security(SecurityPolicyBasic256Sha256, cert.cert, cert.key,
                              mode=ua.MessageSecurityMode.SignAndEncrypt)
    if user is not None:
        client.set_user(user)
        client.set_password(password)
    if identity is not None:
        await client.load_client_certificate(identity.cert)
        await client.load_private_key(identity.key)
    return client


async def namespaces(client: Client) -> dict[str, int]:
    return {"di": await client.get_namespace_index(DI_URI),
            "rob": await client.get_namespace_index(ROBOTICS_URI),
            "pendant": await client.get_namespace_index(PENDANT_URI)}
