"""Findings of an attacker's review of the OPC UA face: each test failed on the code before
its fix (the commit that added it says what was measured).

1. A certificate's token secret (its public fingerprint) logged in as a password or bearer.
2. A guessed AuthenticationToken and a failed ActivateSession took over another's session.
3. Sessions never activated piled up (CreateSession again and again on one channel).
4. and 5. One user took all of the face's subscriptions, or all of its sessions.
6. CreateSession's ApplicationUri was not checked against the certificate.
7. Anyone registered a server that FindServers then listed.
8. A CommitFrame's audit record had no client address.
9. One host's idle connections locked every client out.
10. A 0.001 ms publishing interval was granted (a core for 100 subscriptions).
11. A Publish acknowledged another user's notifications.
12. A role with frames:commit but not frames:read could commit on REST, not on OPC UA.
13. One user's monitored items had no bound (143 MB for 100 000).
"""

from __future__ import annotations

import asyncio
import socket
import time
from pathlib import Path
from urllib.parse import urlparse

import pytest
from api_helpers import ADMIN_TOKEN, C, ok
from asyncua import Client, ua
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from opcua_helpers import add_user, client_certificate, namespaces, module_cell, secure_client

from server.auth import tokens
from server.opcua import access


# REST and the OPC UA face (with the optional None endpoint) on one SQLite file
cell = module_cell("opcua-attack", none_endpoint=True)
user = add_user


async def cell_1(client: Client) -> tuple[dict, object]:
    """pendant's namespaces and the object of cell-1 under Pendant (its methods)."""
    ns = await namespaces(client)
    return ns, await client.nodes.objects.get_child([f"{ns['pendant']}:Pendant",
                                                     f"{ns['pendant']}:cell-1"])


async def read_frame(client: Client) -> list:
    ns, obj = await cell_1(client)
    return await obj.call_method(f"{ns['pendant']}:ReadFrame", "tool", 1)


# 1. a certificate's fingerprint is no password ----------------------------------------------

def test_a_registered_certificates_fingerprint_is_no_password(cell: dict, tmp_path: Path) -> None:
    from server.cli.main import main

    victim = client_certificate(tmp_path, "fp-victim")
    ok(cell["rest"].post("/users", json={"name": "fpv", "role": "Expert"}))
    assert main(["users", "cert", "fpv", victim.cert, "--db", cell["db_url"]]) == 0
    fingerprint = tokens.certificate_secret(victim.der())  # computed from the public certificate

    async def login() -> list:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "fpv",
                                     fingerprint)
        async with client:
            return await read_frame(client)

    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(login())
    assert err.value.code == ua.StatusCodes.BadUserAccessDenied
    rest = cell["rest"]
    assert rest.get(C, headers={"Authorization": f"Bearer {fingerprint}"}).status_code == 401
    assert rest.post("/auth/login", json={"token": fingerprint}).status_code == 401

    async def certificate_login() -> list:  # the certificate with its key still logs in
        client = await secure_client(cell["face"].endpoint, cell["face"].client,
                                     identity=victim)
        async with client:
            return await read_frame(client)
    assert asyncio.run(certificate_login())[1] == "tool"


# 2. a session stays on its channel -----------------------------------------------------------

async def activate_on_new_channel(cell: dict, token: ua.NodeId, secure: bool) -> object:
    """A client with no login opens its own channel (the trusted application certificate, or
    no certificate on the None endpoint), sends ActivateSession naming ``token`` with a
    signature it cannot make, then calls ReadFrame: the outcome (or the status raised)."""
    face = cell["face"]
    attacker = Client(face.endpoint, timeout=10)
    if secure:
        attacker.application_uri = face.client.uri
        await attacker.set_security(SecurityPolicyBasic256Sha256, face.client.cert,
                                    face.client.key)
    await attacker.connect_socket()
    try:
        await attacker.send_hello()
        await attacker.open_secure_channel()
        attacker.uaclient.protocol.authentication_token = token
        params = ua.ActivateSessionParameters()
        params.ClientSignature.Algorithm = SecurityPolicyBasic256Sha256.AsymmetricSignatureURI
        params.ClientSignature.Signature = b"\0" * 256
        params.UserIdentityToken = ua.AnonymousIdentityToken()
        try:
            await attacker.uaclient.activate_session(params)
        except ua.UaStatusCodeError:
            pass
        try:
            return await read_frame(attacker)
        except ua.UaStatusCodeError as err:
            return err.code
    finally:
        attacker.disconnect_socket()


@pytest.mark.parametrize("secure", [True, False], ids=["trusted-channel", "none-endpoint"])
def test_a_failed_activation_on_another_channel_takes_no_session(cell: dict, secure: bool) -> None:
    name = f"hij{int(secure)}"
    secret = user(cell, name, "Expert")

    async def scene() -> tuple[object, list]:
        victim = await secure_client(cell["face"].endpoint, cell["face"].client, name, secret)
        async with victim:
            token = victim.uaclient.protocol.authentication_token
            outcome = await activate_on_new_channel(cell, token, secure)
            return outcome, await read_frame(victim)  # the victim's session still serves it

    outcome, victims = asyncio.run(scene())
    assert outcome == ua.StatusCodes.BadSessionIdInvalid, outcome
    assert victims[1] == "tool"


def test_authentication_tokens_are_not_counted_up(cell: dict) -> None:
    secret = user(cell, "tok", "Operator")

    async def token() -> ua.NodeId:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "tok", secret)
        async with client:
            return client.uaclient.protocol.authentication_token

    a, b = asyncio.run(token()), asyncio.run(token())
    assert a != b
    for t in (a, b):  # 128 random bits or more, not a small number
        assert t.NodeIdType in (ua.NodeIdType.ByteString, ua.NodeIdType.Guid), t


# 3. sessions that are never activated do not pile up -----------------------------------------

def test_sessions_never_activated_end_with_their_channel(cell: dict) -> None:
    """CreateSession after CreateSession on one channel, with no certificate and no login (the
    None endpoint): each new one left the one before registered for ever (asyncua watches a
    session's timeout only once it is activated, and closes only the channel's last one)."""
    face = cell["face"]
    sessions = face.server.server.iserver._external_sessions

    async def flood() -> int:
        client = Client(face.endpoint, timeout=10)
        await client.connect_socket()
        try:
            await client.send_hello()
            await client.open_secure_channel()
            for _ in range(50):
                await client.create_session()
            return len(sessions)
        finally:
            client.disconnect_socket()

    before = face.run(asyncio.sleep(0, len(sessions)))
    during = asyncio.run(flood())
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and face.run(asyncio.sleep(0, len(sessions))) > before:
        time.sleep(0.1)
    assert during <= before + 1
    assert face.run(asyncio.sleep(0, len(sessions))) == before


# 4. one user cannot take every subscription ---------------------------------------------------

def test_one_user_cannot_take_the_servers_subscriptions(cell: dict) -> None:
    """asyncua caps subscriptions at 1000 for the whole server: one Operator took them all,
    and every other user's CreateSubscription was BadTooManySubscriptions."""
    hog, other = add_user(cell, "hog", "Operator"), add_user(cell, "other", "Operator")

    async def scene() -> tuple[int, object]:
        a = await secure_client(cell["face"].endpoint, cell["face"].client, "hog", hog)
        b = await secure_client(cell["face"].endpoint, cell["face"].client, "other", other)
        async with a, b:
            made = 0
            with pytest.raises(ua.UaStatusCodeError) as err:
                while made < 1000:
                    await a.create_subscription(1000, None)
                    made += 1
            assert err.value.code == ua.StatusCodes.BadTooManySubscriptions
            return made, await b.create_subscription(1000, None)

    made, others = asyncio.run(scene())
    assert made == access.SUBSCRIPTIONS_PER_USER
    assert others.subscription_id


# 5. one user cannot take every session ------------------------------------------------------

def test_one_user_cannot_take_the_servers_sessions(cell: dict) -> None:
    """asyncua caps activated sessions at 1000 for the whole server: one Operator made them
    all on one channel (CreateSession and ActivateSession again and again, 4 s), and the
    Administrator's login was then BadMaxConnectionsReached."""
    hog = add_user(cell, "shog", "Operator")
    face = cell["face"]

    async def scene() -> tuple[int, int, str]:
        client = await secure_client(face.endpoint, face.client, "shog", hog)
        await client.connect_socket()
        try:
            await client.send_hello()
            await client.open_secure_channel()
            made = 0
            with pytest.raises(ua.UaStatusCodeError) as err:
                while made < 1000:
                    await client.create_session()
                    await client.activate_session("shog", hog)
                    made += 1
            admin = await secure_client(face.endpoint, face.client, "admin", ADMIN_TOKEN)
            async with admin:
                return made, err.value.code, (await admin.nodes.server.read_browse_name()).Name
        finally:
            client.disconnect_socket()

    made, code, name = asyncio.run(scene())
    assert (made, code) == (access.SESSIONS_PER_USER, ua.StatusCodes.BadTooManySessions)
    assert name == "Server"


# 6. the application says who it is as its certificate does -----------------------------------

def test_an_application_uri_not_in_the_certificate_is_refused(cell: dict) -> None:
    """CreateSession's ApplicationUri must be the certificate's (OPC 10000-4 §5.6.2,
    BadCertificateUriInvalid); any URI was accepted."""
    async def login() -> list:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "admin",
                                     ADMIN_TOKEN)
        client.application_uri = "urn:somebody:else"
        async with client:
            return await read_frame(client)

    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(login())
    assert err.value.code == ua.StatusCodes.BadCertificateUriInvalid


# 7. nobody registers servers with the face ----------------------------------------------------

def test_register_server_is_refused_without_a_session(cell: dict) -> None:
    """access.ADMIN_TYPES meant RegisterServer for nobody, but asyncua serves it without a
    session and asks no permission: a client with no certificate and no login (the None
    endpoint) registered a server of its own, which FindServers then handed to every client."""
    rogue = ua.RegisteredServer(ServerUri="urn:rogue:server", ProductUri="urn:rogue",
                                ServerNames=[ua.LocalizedText("pendant")],
                                ServerType=ua.ApplicationType.Server,
                                DiscoveryUrls=["opc.tcp://rogue.example:4840/pendant/"],
                                IsOnline=True)

    async def scene() -> tuple[object, list[str]]:
        client = Client(cell["face"].endpoint, timeout=10)
        await client.connect_socket()
        try:
            await client.send_hello()
            await client.open_secure_channel()
            try:
                outcome: object = await client.uaclient.register_server(rogue)
            except ua.UaStatusCodeError as err:
                outcome = err.code
            return outcome, [s.ApplicationUri for s in await client.find_servers()]
        finally:
            client.disconnect_socket()

    outcome, listed = asyncio.run(scene())
    assert outcome == ua.StatusCodes.BadServiceUnsupported
    assert "urn:rogue:server" not in listed


# 8. the audit says where a commit came from, as REST's and RWS's do ---------------------------

def test_a_commit_is_one_audit_record_naming_the_user_and_the_client(cell: dict) -> None:
    secret = add_user(cell, "auditee", "Expert")

    async def commit() -> tuple[int, int]:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "auditee",
                                     secret)
        async with client:
            ns, obj = await cell_1(client)
            name, _kind, frame, version = await obj.call_method(f"{ns['pendant']}:ReadFrame",
                                                                "tool", 6)
            frame[2] += 1.0
            new = await obj.call_method(f"{ns['pendant']}:CommitFrame", "tool", 6,
                                        ua.Variant(frame, ua.VariantType.Double), name,
                                        ua.Variant(version, ua.VariantType.UInt64))
            return version, new

    version, new = asyncio.run(commit())
    assert new == version + 1
    (rec,) = ok(cell["rest"].get("/audit", params={"user": "auditee"}))
    assert (rec["source"], rec["role"], rec["table"], rec["number"]) == ("opcua", "Expert",
                                                                         "tool", 6)
    assert rec["client"] == "127.0.0.1"


# 9. one host's idle connections do not lock everyone out --------------------------------------

def test_idle_connections_of_one_host_leave_room_for_others(cell: dict) -> None:
    """asyncua accepts 1000 connections in all, and one that never activates a session is
    closed after 30 s: 1000 TCP connections that sent nothing (no certificate, no login) from
    one host refused every other client's connection for those 30 s, again and again."""
    face = cell["face"]
    url = urlparse(face.endpoint)
    idle: list[socket.socket] = []
    try:
        for _ in range(1000):
            try:
                idle.append(socket.create_connection((url.hostname, url.port), timeout=5,
                                                     source_address=("127.0.0.2", 0)))
            except OSError:
                break

        async def login() -> str:
            client = await secure_client(face.endpoint, face.client, "admin", ADMIN_TOKEN)
            async with client:
                return (await client.nodes.server.read_browse_name()).Name

        assert asyncio.run(login()) == "Server"
    finally:
        for s in idle:
            s.close()


# 10. a subscription publishes no faster than the face's minimum ------------------------------

def test_a_publishing_interval_below_the_minimum_is_revised_up(cell: dict) -> None:
    """asyncua grants any interval: 100 subscriptions of one Operator at 0.001 ms kept the
    face's process at 1.1 cores (0.04 idle), each one's loop publishing without a pause."""
    secret = add_user(cell, "quick", "Operator")

    async def revised() -> float:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "quick", secret)
        async with client:
            params = ua.CreateSubscriptionParameters(
                RequestedPublishingInterval=0.001, RequestedLifetimeCount=10_000,
                RequestedMaxKeepAliveCount=3_000, PublishingEnabled=True)
            result = await client.uaclient.create_subscription(params, lambda *_: None)
            return result.RevisedPublishingInterval

    assert asyncio.run(revised()) == access.MIN_PUBLISHING_MS


# 11. a Publish acknowledges only its own user's notifications ---------------------------------

def test_a_publish_cannot_acknowledge_another_users_notifications(cell: dict) -> None:
    """A Publish's SubscriptionAcknowledgements were applied to any subscription: an Operator
    naming an Expert's subscription dropped the notifications the Expert's client had not
    acknowledged yet (what it would Republish after a lost message)."""
    expert, operator = add_user(cell, "acked", "Expert"), add_user(cell, "acker", "Operator")
    face = cell["face"]
    subs = face.server.server.iserver.subscription_service.subscriptions

    async def scene() -> object:
        ex = await secure_client(face.endpoint, face.client, "acked", expert)
        op = await secure_client(face.endpoint, face.client, "acker", operator)
        async with ex, op:
            sid = (await ex.create_subscription(60_000, None)).subscription_id
            subs[sid]._not_acknowledged_results[4242] = "kept for a Republish"  # noqa: SLF001
            publish = ua.PublishRequest(Parameters=ua.PublishParameters(
                SubscriptionAcknowledgements=[ua.SubscriptionAcknowledgement(sid, 4242)]))
            try:
                await op.uaclient.protocol.send_request(publish, timeout=2)
            except ua.UaStatusCodeError as err:
                return err.code, 4242 in subs[sid]._not_acknowledged_results  # noqa: SLF001
            except TimeoutError:
                pass
            return None, 4242 in subs[sid]._not_acknowledged_results  # noqa: SLF001

    assert asyncio.run(scene()) == (ua.StatusCodes.BadUserAccessDenied, True)


# 12. one permission table: a commit needs frames:commit, as REST's PUT does ------------------

def test_a_role_that_may_commit_but_not_read_commits_as_on_rest(cell: dict) -> None:
    """A site role with frames:commit but not frames:read may PUT a slot on REST; on OPC UA
    every request needed frames:read first, so its CommitFrame was refused
    (BadUserAccessDenied) while its REST PUT of the same slot passed. pendant's methods check
    their own permission: its CommitFrame commits (with NodeIds stored before, as the docs
    allow: browsing still needs frames:read), and its ReadFrame is still refused."""
    from sqlalchemy.orm import sessionmaker

    from db.session import make_engine

    maker = sessionmaker(bind=make_engine(cell["db_url"]))
    with maker() as db:
        tokens.add_role(db, "Committer", ["frames:commit"])
        db.commit()
    secret = add_user(cell, "committer", "Committer")
    admin = add_user(cell, "nodeids", "Administrator")

    async def stored_ids() -> tuple:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "nodeids",
                                     admin)
        async with client:
            ns, obj = await cell_1(client)
            commit = await obj.get_child(f"{ns['pendant']}:CommitFrame")
            read = await obj.get_child(f"{ns['pendant']}:ReadFrame")
            return obj.nodeid, commit.nodeid, read.nodeid, await obj.call_method(read, "tool", 7)

    obj_id, commit_id, read_id, (name, _kind, frame, version) = asyncio.run(stored_ids())

    async def as_committer() -> tuple[object, object]:
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "committer",
                                     secret)
        async with client:
            obj = client.get_node(obj_id)
            frame[2] += 1.0
            new = await obj.call_method(commit_id, "tool", 7,
                                        ua.Variant(frame, ua.VariantType.Double), name,
                                        ua.Variant(version, ua.VariantType.UInt64))
            try:
                read = await obj.call_method(read_id, "tool", 7)
            except ua.UaStatusCodeError as err:
                read = err.code
            return new, read

    new, read = asyncio.run(as_committer())
    assert new == version + 1
    assert read == ua.StatusCodes.BadUserAccessDenied
    (rec,) = ok(cell["rest"].get("/audit", params={"user": "committer"}))
    assert (rec["source"], rec["table"], rec["number"]) == ("opcua", "tool", 7)
    rest = cell["rest"]
    headers = {"Authorization": f"Bearer {secret}"}
    assert rest.get(f"{C}/tools/7", headers=headers).status_code == 403  # as on REST


# 13. one user's monitored items are bounded ---------------------------------------------------

def test_one_users_monitored_items_are_bounded(cell: dict, monkeypatch) -> None:  # noqa: ANN001
    """asyncua has no cap on monitored items: ~1.5 KB each, 100 000 from one Operator took
    143 MB of the face (and 12 s). One user's subscriptions hold at most
    MONITORED_ITEMS_PER_USER items in all (here lowered to 30); another user's are not
    counted against it."""
    monkeypatch.setattr(access, "MONITORED_ITEMS_PER_USER", 30, raising=False)
    hog, other = add_user(cell, "ihog", "Operator"), add_user(cell, "iother", "Operator")

    async def scene() -> tuple[int, object, int]:
        a = await secure_client(cell["face"].endpoint, cell["face"].client, "ihog", hog)
        b = await secure_client(cell["face"].endpoint, cell["face"].client, "iother", other)
        async with a, b:
            node = a.get_node(ua.NodeId(ua.ObjectIds.Server_ServerStatus_CurrentTime))
            first = await a.create_subscription(1000, None)
            second = await a.create_subscription(1000, None)
            made = len(await first.subscribe_data_change([node] * 20))
            with pytest.raises(ua.UaStatusCodeError) as err:  # 20 + 11 > 30, across two
                await second.subscribe_data_change([node] * 11)
            made += len(await second.subscribe_data_change([node] * 10))  # 30: still allowed
            others = await b.create_subscription(1000, None)
            return made, err.value.code, len(await others.subscribe_data_change([node] * 30))

    made, code, others = asyncio.run(scene())
    assert (made, code, others) == (30, ua.StatusCodes.BadTooManyMonitoredItems, 30)
