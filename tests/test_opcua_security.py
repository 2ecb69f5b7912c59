"""The OPC UA face's doors (issue 20): who may log in, over which channel, with what proof.

Each test plays what an attacker on the plant network would try (a registered user's public
certificate, a plaintext or replayed password, an Operator's backup, someone else's
subscription, a revoked token, an untrusted or expired certificate, an open face on every
interface) and asserts the face refuses it.
"""

from __future__ import annotations

import asyncio
import logging
import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
from api_helpers import ADMIN_TOKEN, C, ok
from asyncua import Client, ua
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from browser_helpers import free_port
from cryptography import x509
from opcua_helpers import (ClientCert, Face, add_user, client_certificate, namespaces,
                           module_cell, secure_client, start_face)

from server.auth import tokens
from server.opcua.pki import KEY_NAME
from server.opcua.service import PendantOpcUa


# REST and the OPC UA face (with the optional None endpoint) on one SQLite file
cell = module_cell("opcua-security", none_endpoint=True)
user = add_user


async def pendant_obj(client: Client, ns: dict):
    return await client.nodes.objects.get_child([f"{ns['pendant']}:Pendant",
                                                 f"{ns['pendant']}:cell-1"])


def codes(err: pytest.ExceptionInfo) -> int:
    return err.value.code


# 1. a public certificate is no login -------------------------------------------------------

def test_a_channel_certificate_on_the_none_endpoint_is_no_login(
        cell: dict, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The registered user's certificate (public data) presented when opening a None channel,
    with an Anonymous token: before, the face logged in as that user."""
    from asyncua.common.connection import MessageChunk

    from server.cli.main import main

    victim = client_certificate(tmp_path, "victim-cell")
    ok(cell["rest"].post("/users", json={"name": "victim", "role": "Expert"}))
    assert main(["users", "cert", "victim", victim.cert, "--db", cell["db_url"]]) == 0

    to_chunks = MessageChunk.message_to_chunks

    def with_sender_certificate(policy, body, size, message_type=ua.MessageType.SecureMessage,
                                *args, **kwargs):
        chunks = to_chunks(policy, body, size, message_type, *args, **kwargs)
        if message_type == ua.MessageType.SecureOpen:  # asyncua sends none on None: the attacker does
            chunks[0].SecurityHeader.SenderCertificate = victim.der()
        return chunks

    monkeypatch.setattr(MessageChunk, "message_to_chunks", staticmethod(with_sender_certificate))

    async def attack() -> object:
        client = Client(cell["face"].endpoint, timeout=10)
        client.security_policy.host_certificate = victim.der()  # CreateSession's ClientCertificate
        async with client:
            ns = await namespaces(client)
            return await (await pendant_obj(client, ns)).call_method(
                f"{ns['pendant']}:ReadFrame", "tool", 1)

    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(attack())
    assert codes(err) in (ua.StatusCodes.BadUserAccessDenied,
                          ua.StatusCodes.BadIdentityTokenRejected)


def test_an_x509_token_without_a_signature_is_refused(cell: dict, tmp_path: Path) -> None:
    """The certificate in an X509 identity token, without the proof of its private key."""
    from server.cli.main import main

    victim = client_certificate(tmp_path, "victim-2")
    ok(cell["rest"].post("/users", json={"name": "victim2", "role": "Expert"}))
    assert main(["users", "cert", "victim2", victim.cert, "--db", cell["db_url"]]) == 0

    class NoProof(Client):
        def _add_certificate_auth(self, params, certificate, challenge, chain=None):
            super()._add_certificate_auth(params, certificate, challenge, chain)
            params.UserTokenSignature = ua.SignatureData()

    async def attack() -> None:
        client = NoProof(cell["face"].endpoint, timeout=10)
        client.application_uri = cell["face"].client.uri
        await client.set_security(SecurityPolicyBasic256Sha256, cell["face"].client.cert,
                                  cell["face"].client.key)
        await client.load_client_certificate(victim.cert)
        await client.load_private_key(cell["face"].client.key)  # not the victim's key
        async with client:
            pass

    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(attack())
    assert codes(err) in (ua.StatusCodes.BadIdentityTokenInvalid,
                          ua.StatusCodes.BadIdentityTokenRejected)


# 2. no plaintext, no replay -----------------------------------------------------------------

class PlainPassword(Client):
    """Sends the password as plaintext, whatever the endpoint's token policy asks."""

    def _add_user_auth(self, params, username, password):
        params.UserIdentityToken = ua.UserNameIdentityToken(
            UserName=username, Password=password.encode(), EncryptionAlgorithm=None,
            PolicyId=self.server_policy(ua.UserTokenType.UserName).PolicyId)


class Replayer(Client):
    """Keeps the encrypted password token of its first session and sends it in the next."""

    captured: ua.UserNameIdentityToken | None = None

    def _add_user_auth(self, params, username, password):
        if Replayer.captured is None:
            super()._add_user_auth(params, username, password)
            Replayer.captured = params.UserIdentityToken
        else:
            params.UserIdentityToken = Replayer.captured


async def login_with(cls: type[Client], face: Face, password: str) -> str:
    client = cls(face.endpoint, timeout=10)
    client.application_uri = face.client.uri
    await client.set_security(SecurityPolicyBasic256Sha256, face.client.cert, face.client.key)
    client.set_user("admin")
    client.set_password(password)
    async with client:
        return (await client.nodes.server.read_browse_name()).Name


def test_a_plaintext_password_is_refused(cell: dict) -> None:
    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(login_with(PlainPassword, cell["face"], ADMIN_TOKEN))
    assert codes(err) == ua.StatusCodes.BadIdentityTokenInvalid


def test_a_password_token_of_another_session_is_refused(cell: dict) -> None:
    """Encrypted with the first session's nonce: replayed in a second session, refused."""
    Replayer.captured = None
    assert asyncio.run(login_with(Replayer, cell["face"], ADMIN_TOKEN)) == "Server"
    assert Replayer.captured is not None
    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(login_with(Replayer, cell["face"], ADMIN_TOKEN))
    assert codes(err) == ua.StatusCodes.BadIdentityTokenInvalid


def test_no_password_or_certificate_login_on_the_none_endpoint(cell: dict) -> None:
    async def endpoints() -> list[ua.EndpointDescription]:
        return await Client(cell["face"].endpoint, timeout=10).connect_and_get_server_endpoints()

    eps = asyncio.run(endpoints())
    modes = {(e.SecurityPolicyUri.rsplit("#", 1)[-1], e.SecurityMode): e for e in eps}
    none = modes[("None", ua.MessageSecurityMode.None_)]
    assert [t.TokenType for t in none.UserIdentityTokens] == []  # login required: no Anonymous
    enc = modes[("Basic256Sha256", ua.MessageSecurityMode.SignAndEncrypt)]
    (pw,) = [t for t in enc.UserIdentityTokens if t.TokenType == ua.UserTokenType.UserName]
    assert pw.SecurityPolicyUri == SecurityPolicyBasic256Sha256.URI  # encrypted with the nonce

    class PlainOnNone(PlainPassword):
        def server_policy(self, token_type):
            return ua.UserTokenPolicy(PolicyId="username", TokenType=token_type)

    async def plain_on_none() -> None:
        client = PlainOnNone(cell["face"].endpoint, timeout=10)
        client.set_user("admin")
        client.set_password(ADMIN_TOKEN)
        async with client:
            pass

    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(plain_on_none())
    assert codes(err) in (ua.StatusCodes.BadIdentityTokenInvalid,
                          ua.StatusCodes.BadIdentityTokenRejected)


# 3. one permission table: a backup needs backup:write ----------------------------------------

def test_an_operator_gets_no_json_backup_but_the_controller_file(cell: dict) -> None:
    token = user(cell, "olaf", "Operator")
    assert cell["rest"].get(f"{C}/export", params={"format": "json"},
                            headers={"Authorization": f"Bearer {token}"}).status_code == 403

    async def export(fmt: str) -> object:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "olaf", token)
        async with client:
            ns = await namespaces(client)
            return await (await pendant_obj(client, ns)).call_method(
                f"{ns['pendant']}:ExportFile", fmt)

    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(export("json"))
    assert codes(err) == ua.StatusCodes.BadUserAccessDenied
    assert "TOOL_DATA" in asyncio.run(export("kuka"))


def test_an_operators_refused_commit_fails_only_its_own_call(cell: dict) -> None:
    token = user(cell, "opal", "Operator")
    pre = ok(cell["rest"].get(f"{C}/tools/5"))

    async def batch() -> list[ua.CallMethodResult]:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "opal", token)
        async with client:
            ns = await namespaces(client)
            obj = await pendant_obj(client, ns)
            read = (await obj.get_child(f"{ns['pendant']}:ReadFrame")).nodeid
            write = (await obj.get_child(f"{ns['pendant']}:CommitFrame")).nodeid
            req = [ua.CallMethodRequest(ObjectId=obj.nodeid, MethodId=read, InputArguments=[
                       ua.Variant("tool"), ua.Variant(5, ua.VariantType.Int32)]),
                   ua.CallMethodRequest(ObjectId=obj.nodeid, MethodId=write, InputArguments=[
                       ua.Variant("tool"), ua.Variant(5, ua.VariantType.Int32),
                       ua.Variant([0.0] * 6, ua.VariantType.Double), ua.Variant("x"),
                       ua.Variant(1, ua.VariantType.UInt64)])]
            return await client.uaclient.call(req)

    reads, commits = asyncio.run(batch())
    assert reads.StatusCode.is_good() and reads.OutputArguments[0].Value == pre["name"]
    assert commits.StatusCode.value == ua.StatusCodes.BadUserAccessDenied
    assert ok(cell["rest"].get(f"{C}/tools/5")) == pre


# 4. subscriptions are their owner's ---------------------------------------------------------

def test_an_operator_cannot_take_an_experts_subscription(cell: dict) -> None:
    expert, operator = user(cell, "exa", "Expert"), user(cell, "opi", "Operator")

    async def scene() -> tuple[list[int], object]:
        ex = await secure_client(cell["face"].endpoint, cell["face"].client, "exa", expert)
        op = await secure_client(cell["face"].endpoint, cell["face"].client, "opi", operator)
        async with ex, op:
            subs = [await ex.create_subscription(100, None) for _ in range(3)]
            ids = [s.subscription_id for s in subs]
            try:
                outcome = await op.uaclient.transfer_subscriptions(
                    ua.TransferSubscriptionsParameters(SubscriptionIds=ids[:1]))
            except ua.UaStatusCodeError as err:
                outcome = err
            return ids, outcome

    ids, outcome = asyncio.run(scene())
    assert isinstance(outcome, ua.UaStatusCodeError), outcome
    assert outcome.code == ua.StatusCodes.BadUserAccessDenied
    assert sorted(ids) != list(range(min(ids), min(ids) + 3))  # not counted up


# 5. a revoked token ends its session's rights within a second ---------------------------------

def test_a_revoked_token_is_refused_within_a_second(cell: dict) -> None:
    ok(cell["rest"].post("/users", json={"name": "rev", "role": "Expert"}))
    made = ok(cell["rest"].post("/users/rev/tokens", json={}))
    sm = cell["rest"].app.state.sessionmaker

    async def scene() -> float:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "rev",
                                     made["token"])
        async with client:
            ns = await namespaces(client)
            obj = await pendant_obj(client, ns)
            await obj.call_method(f"{ns['pendant']}:ReadFrame", "tool", 1)
            with sm() as db:
                (t,) = [t for t in tokens.list_tokens(db) if t.token_sha256 ==
                        tokens.sha256(made["token"])]
                tokens.revoke_token(db, t.id)
                db.commit()
            revoked = time.monotonic()
            while time.monotonic() - revoked < 5.0:
                try:
                    await obj.call_method(f"{ns['pendant']}:ReadFrame", "tool", 1)
                except ua.UaStatusCodeError as err:  # the session is ended
                    assert err.code == ua.StatusCodes.BadSessionIdInvalid
                    return time.monotonic() - revoked
                await asyncio.sleep(0.05)
            return float("inf")

    assert asyncio.run(scene()) < 1.0


# 6. the PKI folder: private, a trust list, only valid certificates ------------------------------

def test_the_pki_folder_is_the_instances_own_and_private(cell: dict) -> None:
    pki = cell["face"].pki
    assert stat.S_IMODE(pki.stat().st_mode) == 0o700
    assert stat.S_IMODE((pki / "own" / KEY_NAME).stat().st_mode) == 0o600
    assert pki.is_relative_to(cell["folder"])


async def read_server_name(cell: dict, cert: ClientCert, timeout: float = 10) -> str:
    client = await secure_client(cell["face"].endpoint, cert, "admin", ADMIN_TOKEN,
                                 timeout=timeout)
    async with client:
        return (await client.nodes.server.read_browse_name()).Name


REFUSED_WAIT_S = 3.0  # a client gives up on a refused channel after this


def refused_channel(cell: dict, cert: ClientCert, why: str,
                    caplog: pytest.LogCaptureFixture) -> None:
    """A channel with ``cert`` gets no session, and the face says it refused the channel,
    naming the certificate and ``why``. The face drops a refused channel without an answer:
    the client waits out its timeout, so a short one here (an accepted channel answers in
    well under a second; the face's log, polled for, tells a refusal from a slow face)."""
    subject = x509.load_der_x509_certificate(cert.der()).subject.rfc4514_string()

    def said() -> bool:
        return any(subject in r.getMessage() and why in r.getMessage()
                   for r in caplog.records)

    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="pendant.opcua"):
        with pytest.raises((ua.UaError, OSError, asyncio.TimeoutError)):
            asyncio.run(read_server_name(cell, cert, timeout=REFUSED_WAIT_S))
        deadline = time.monotonic() + 30
        while not said() and time.monotonic() < deadline:
            time.sleep(0.05)
    assert said(), caplog.text


def test_an_untrusted_client_is_refused_until_trusted_once(
        cell: dict, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    from server.cli.main import main

    stranger = client_certificate(tmp_path, "new-cell-pc")

    refused_channel(cell, stranger, "is not trusted", caplog)
    (kept,) = (cell["face"].pki / "rejected").glob("new-cell-pc-*.der")
    assert kept.read_bytes() == stranger.der()
    assert main(["opcua", "trust", str(kept), "--pki", str(cell["face"].pki)]) == 0
    assert asyncio.run(read_server_name(cell, stranger)) == "Server"


def test_expired_and_not_yet_valid_certificates_are_refused(
        cell: dict, tmp_path: Path, capsys: pytest.CaptureFixture,
        caplog: pytest.LogCaptureFixture) -> None:
    from server.cli.main import main

    old = client_certificate(tmp_path / "old", "old-pc", valid_from_days=-30, valid_days=10)
    early = client_certificate(tmp_path / "early", "early-pc", valid_from_days=5)
    for cert, why in ((old, "refused: expired on"), (early, "refused: not valid before")):
        assert main(["opcua", "trust", cert.cert, "--pki", str(cell["face"].pki)]) == 2
        assert "CERT:" in capsys.readouterr().err
        # placed in the trust list by hand: the channel is still refused
        (cell["face"].pki / "trusted" / Path(cert.cert).name).write_bytes(cert.der())
        refused_channel(cell, cert, why, caplog)

    # registering an expired certificate for a user is refused, naming why
    ok(cell["rest"].post("/users", json={"name": "oldie", "role": "Expert"}))
    assert main(["users", "cert", "oldie", old.cert, "--db", cell["db_url"]]) == 2
    assert "expired on" in capsys.readouterr().err
    # and one registered while it was valid does not log in once it has expired
    with cell["rest"].app.state.sessionmaker() as db:
        tokens.create_token(db, tokens.get_user(db, "oldie"), 30, "opcua certificate",
                            secret=tokens.certificate_secret(old.der()))
        db.commit()

    async def as_oldie() -> str:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, identity=old)
        async with client:
            return (await client.nodes.server.read_browse_name()).Name

    with pytest.raises(ua.UaStatusCodeError):
        asyncio.run(as_oldie())


# 7. no login only on loopback, however the face is started -------------------------------------

def test_no_auth_on_another_interface_is_refused(tmp_path: Path) -> None:
    env = {**os.environ, "PENDANT_NO_AUTH": "1"}
    db = f"sqlite:///{tmp_path / 'p.db'}"
    r = subprocess.run([sys.executable, "-m", "server.cli", "opcua", "--host", "0.0.0.0",
                        "--port", str(free_port()), "--db", db], env=env, capture_output=True,
                       text=True, timeout=120, check=False)
    assert r.returncode == 2, r.stderr
    assert "--host" in r.stderr and "loopback" in r.stderr
    face = PendantOpcUa(None, f"opc.tcp://0.0.0.0:{free_port()}/pendant/", auth=False,  # type: ignore[arg-type]
                        pki_dir=tmp_path / "pki")
    with pytest.raises(ValueError, match="loopback"):
        asyncio.run(face.start())


# 8. the endpoint set ----------------------------------------------------------------------------

def test_by_default_only_the_encrypted_endpoint(cell: dict, tmp_path: Path) -> None:
    face = start_face(cell["rest"].app.state.sessionmaker, tmp_path)
    try:
        async def endpoints() -> list[tuple[str, ua.MessageSecurityMode]]:
            eps = await Client(face.endpoint, timeout=10).connect_and_get_server_endpoints()
            return [(e.SecurityPolicyUri.rsplit("#", 1)[-1], e.SecurityMode) for e in eps]

        assert asyncio.run(endpoints()) == [("Basic256Sha256",
                                             ua.MessageSecurityMode.SignAndEncrypt)]

        async def none_session() -> None:  # a session on the discovery channel: refused
            client = Client(face.endpoint, timeout=10)
            client.set_user("admin")
            client.set_password(ADMIN_TOKEN)
            async with client:
                pass

        with pytest.raises((ua.UaError, OSError)):
            asyncio.run(none_session())
    finally:
        face.stop()


def test_an_operator_may_call_get_monitored_items(cell: dict) -> None:
    """A standard method that only reads needs frames:read, as reading does: an Operator's
    GetMonitoredItems passes the access check (asyncua has no implementation behind it and
    answers BadNothingToDo; before, the face refused it with BadUserAccessDenied)."""
    token = user(cell, "ozzy", "Operator")

    async def body() -> None:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "ozzy", token)
        async with client:
            sub = await client.create_subscription(100, None)
            await sub.subscribe_data_change(client.nodes.server_state)
            await client.nodes.server.call_method(
                "0:GetMonitoredItems", ua.Variant(sub.subscription_id, ua.VariantType.UInt32))

    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(body())
    assert codes(err) == ua.StatusCodes.BadNothingToDo


def test_the_no_auth_demo_on_loopback_serves_anonymous_on_the_none_endpoint(
        cell: dict, tmp_path: Path) -> None:
    """`--no-auth --none-endpoint` on loopback: an anonymous client without a certificate
    reads a frame (the demo); a password still never travels on that endpoint."""
    face = start_face(cell["rest"].app.state.sessionmaker, tmp_path, auth=False,
                      none_endpoint=True)
    try:
        async def read() -> str:
            async with Client(face.endpoint, timeout=10) as client:
                ns = await namespaces(client)
                return (await (await pendant_obj(client, ns)).call_method(
                    f"{ns['pendant']}:ReadFrame", "tool", 1))[1]

        assert asyncio.run(read()) == "tool"
    finally:
        face.stop()
