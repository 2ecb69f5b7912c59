"""What an attacker's probe of the REST API found (a valid low-privilege token, or a confused
client), each kept as a regression test that failed on the code before its fix."""

from __future__ import annotations

import pytest

from api_helpers import C, edit_slot, finish_job, make_client, ok


def _user(client, name: str, role: str) -> dict[str, str]:
    """A user with ``role``; the headers of a fresh token of theirs."""
    ok(client.post("/users", json={"name": name, "role": role}))
    return {"Authorization": "Bearer " + ok(client.post(f"/users/{name}/tokens", json={}))["token"]}


def test_a_programmer_cannot_cancel_an_administrators_restore(client):
    """POST /jobs/{id}/cancel needed only sessions:run whatever the job: a Programmer cancelled
    the JSON restore an Administrator had queued (200, state cancelled). Cancelling a job needs
    what starting it needed: a restore, backup:restore."""
    programmer = _user(client, "pat", "Programmer")
    text = client.get(f"{C}/export", params={"format": "json"}).text
    queued = client.post(f"{C}/import", json={"format": "json", "text": text})
    assert queued.status_code == 202, queued.text
    job = queued.json()["id"]
    r = client.post(f"/jobs/{job}/cancel", headers=programmer)
    assert r.status_code == 403, r.text
    assert r.json()["detail"][0]["loc"] == ["path"]
    assert "backup:restore" in r.json()["detail"][0]["msg"]
    assert ok(client.get(f"/jobs/{job}"))["state"] == "queued"
    assert ok(client.post(f"/jobs/{job}/cancel"))["state"] == "cancelled"  # its owner's role may
