"""Whose a session is (issue 27, "List open sessions (whose, which menu, how many points)"):
a session records the user who opened it -- the name the audit records for the request --
the session list says it, and a JSON backup carries it (a backup from before it was recorded
still restores, its sessions then whose-unknown). Revision 0011 leaves older rows NULL."""

from __future__ import annotations

import json

import sqlalchemy as sa
from alembic import command
from api_helpers import C, finish_job, make_client, ok
from migration_helpers import add_controller, at_revision, utc_now


def bearer(client, name: str, role: str) -> dict[str, str]:  # noqa: ANN001
    """A new user with ``role``, and the Authorization header of a fresh token of theirs."""
    ok(client.post("/users", json={"name": name, "role": role}))
    return {"Authorization": "Bearer " + ok(client.post(f"/users/{name}/tokens", json={}))["token"]}


def open_as(client, headers: dict | None, target_no: int) -> dict:  # noqa: ANN001
    body = {"method": "tool.xyz_4point", "target_no": target_no, "params": {}}
    return ok(client.post(f"{C}/sessions", json=body, headers=headers or {}))


def restore(client, doc: dict) -> dict:  # noqa: ANN001
    job = finish_job(client, client.post(f"{C}/import", json={"format": "json",
                                                              "text": json.dumps(doc)}))
    assert job["state"] == "done", job
    return job


def test_each_session_says_who_opened_it(client):  # noqa: ANN001
    olga = bearer(client, "olga", "Programmer")
    mine = open_as(client, None, 3)
    hers = open_as(client, olga, 4)
    assert mine["opened_by"] == "admin" and hers["opened_by"] == "olga"
    listed = {s["id"]: s["opened_by"] for s in ok(client.get(f"{C}/sessions?state=open"))}
    assert listed == {mine["id"]: "admin", hers["id"]: "olga"}
    assert ok(client.get(f"{C}/sessions/{hers['id']}", headers=olga))["opened_by"] == "olga"
    # the same name as the audit's record of the opening
    audit = ok(client.get("/audit", params={"user": "olga"}))
    assert [a["action"] for a in audit] == ["op.open_session"], audit


def test_the_backup_carries_whose_and_an_older_backup_still_restores(client):  # noqa: ANN001
    olga = bearer(client, "olga", "Programmer")
    open_as(client, olga, 4)
    open_as(client, None, 5)
    doc = ok(client.get(f"{C}/export", params={"format": "json"}))
    assert sorted(s["opened_by"] for s in doc["sessions"]) == ["admin", "olga"]

    restore(client, doc)  # restored by the Administrator: each session stays whose it was
    got = {s["target_no"]: s["opened_by"] for s in ok(client.get(f"{C}/sessions"))}
    assert got == {4: "olga", 5: "admin"}

    for s in doc["sessions"]:  # a backup written before sessions recorded who opened them
        del s["opened_by"]
    restore(client, doc)
    got = {s["target_no"]: s["opened_by"] for s in ok(client.get(f"{C}/sessions"))}
    assert got == {4: None, 5: None}

    doc["sessions"][0]["opened_by"] = "x" * 65  # a user name is at most 64 characters
    r = client.post(f"{C}/import", json={"format": "json", "text": json.dumps(doc)})
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"][-3:] == ["sessions", 0, "opened_by"], r.text


def test_with_auth_off_the_session_records_what_the_audit_records(db_url):  # noqa: ANN001
    with make_client(db_url, token=None, auth=False) as c:
        s = open_as(c, None, 2)
        audit = ok(c.get("/audit"))
    opened = [a for a in audit if a["action"] == "op.open_session"]
    assert opened and s["opened_by"] == opened[-1]["user"] == "no-auth", audit


def test_revision_0011_leaves_older_sessions_whose_unknown(fresh_db):  # noqa: ANN001
    cfg, engine, meta = at_revision(fresh_db, "0010_file_encoding")
    with engine.begin() as conn:
        cid = add_controller(conn, meta)
        conn.execute(meta.tables["calib_session"].insert().values(
            controller_id=cid, method="tool.xyz_4point", target_table="tool", target_no=1,
            params={}, state="open", created_at=utc_now()))
    command.upgrade(cfg, "head")
    with engine.connect() as conn:
        got = conn.execute(sa.text("SELECT target_no, opened_by FROM calib_session")).all()
    engine.dispose()
    assert [tuple(r) for r in got] == [(1, None)]
