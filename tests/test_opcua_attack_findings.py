"""Findings of an attacker's review of the OPC UA face: each test failed on the code before
its fix (the commit that added it says what was measured).

1. A registered certificate's token secret is its SHA-256 fingerprint (public data): sent as
   a password (OPC UA), a bearer token or a browser login token (REST), it logged in as the
   certificate's user.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from api_helpers import C, ok
from asyncua import Client, ua
from opcua_helpers import add_user, client_certificate, namespaces, module_cell, secure_client

from server.auth import tokens


# REST and the OPC UA face (with the optional None endpoint) on one SQLite file
cell = module_cell("opcua-attack", none_endpoint=True)
user = add_user


async def read_frame(client: Client) -> list:
    ns = await namespaces(client)
    obj = await client.nodes.objects.get_child([f"{ns['pendant']}:Pendant",
                                                f"{ns['pendant']}:cell-1"])
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
