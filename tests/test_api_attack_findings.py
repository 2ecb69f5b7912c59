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


def test_the_last_administrator_cannot_be_revoked(client, db_url):
    """DELETE /users/admin by the only Administrator answered 204: nobody could administer
    users any more, and a restart with PENDANT_ADMIN_TOKEN (the revoked admin's token) failed
    with an IntegrityError (the first start made admin2 with the same token's hash)."""
    r = client.delete("/users/admin")
    assert r.status_code == 409, r.text
    assert r.json()["detail"][0]["loc"] == ["path", "user_name"]
    assert ok(client.get("/auth/me"))["user"] == "admin"
    _user(client, "ada", "Administrator")  # with a second one, either may go
    assert client.delete("/users/admin").status_code == 204
    with make_client(db_url) as again:  # the fixed token starts the service as before
        assert again.get("/healthz").status_code == 200


def test_an_external_kinematic_keeps_its_etag_moving_through_a_restore(client):
    """A JSON restore deleted and re-made the EX_KIN rows, so their version (the ETag) fell back
    to "1": a client holding the ETag of an older state could write over a later one blind
    (ABA). Measured: "2" after an edit, "1" after the restore, "2" again after the next edit."""
    x = f"{C}/external-kinematics/1"
    text = client.get(f"{C}/export", params={"format": "json"}).text
    ok(edit_slot(client, x, {"name": "edited"}))
    read = client.get(x).headers["ETag"]  # Alice reads EX_KIN 1: "edited"
    assert finish_job(client, client.post(f"{C}/import", json={"format": "json",
                                                              "text": text}))["state"] == "done"
    after = client.get(x)
    assert after.json()["name"] != "edited"  # the restore put the old one back
    assert after.headers["ETag"] != read
    ok(edit_slot(client, x, {"name": "bob"}))  # Bob edits the restored one
    r = client.put(x, json={"name": "alice"}, headers={"If-Match": read})
    assert r.status_code == 412, r.text  # Alice's stale ETag must not match Bob's version
    assert ok(client.get(x))["name"] == "bob"


def test_put_cell_external_honours_if_match(client):
    """PUT .../cell/external ignored If-Match: a stale one ("999") answered 200 and wrote the
    hidden errors (and an audit record). Now 412 as every other controller write, and its
    answer carries the controller's new ETag."""
    before = len(ok(client.get("/audit")))
    r = client.put(f"{C}/cell/external", json={}, headers={"If-Match": '"999"'})
    assert r.status_code == 412, r.text
    assert r.json()["detail"][0]["loc"] == ["header", "If-Match"]
    assert len(ok(client.get("/audit"))) == before
    etag = client.get(C).headers["ETag"]
    r = client.put(f"{C}/cell/external", json={}, headers={"If-Match": etag})
    assert r.status_code == 200, r.text
    assert r.headers["ETag"] == client.get(C).headers["ETag"]


@pytest.mark.parametrize("method,path", [("DELETE", "/webhooks/5"), ("POST", "/webhooks/5/test"),
                                         ("GET", "/webhooks/5/deliveries")])
def test_an_unknown_webhook_is_named_once(client, method, path):
    """The 404 of an unknown webhook said loc ["path", "path", "webhook_id"]."""
    r = client.request(method, path)
    assert r.status_code == 404
    assert r.json()["detail"][0]["loc"] == ["path", "webhook_id"]


@pytest.mark.parametrize("char", ["\u202e", "\u202d", "\u2066", "\u2067", "\u2068", "\u2069"])
def test_a_slot_name_with_a_bidi_override_is_refused(client, char):
    """A tool name "pointer\\u202etxt.ini" was stored (200): the pendant page, the exported
    controller files and the audit then showed it reordered ("pointerini.txt"). NUL and the
    other control characters were refused already; the bidi embeddings, overrides and
    isolates are now too."""
    r = client.put(f"{C}/tools/2", json={"name": f"pointer{char}txt.ini"},
                   headers={"If-Match": "*"})
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == ["body", "name"]
    assert ok(client.get(f"{C}/tools/2"))["name"] == ""
    ok(client.put(f"{C}/tools/2", json={"name": "Greifer-\u00e4\u05d0"},
                  headers={"If-Match": "*"}))  # letters of any script stay


KUKA_FILE = "tests/data/kuka_config.dat"


@pytest.mark.parametrize("method,path,body,params,loc", [
    ("POST", "/users/pat/tokens", {"label": "a\x00b"}, None, ["body", "label"]),
    ("POST", "/users", {"name": "q", "role": "Operator\x00"}, None, ["body", "role"]),
    ("GET", "/audit", None, {"user": "a\x00b"}, ["query", "user"]),
    ("POST", "/webhooks", {"url": "http://127.0.0.1:9/\x00"}, None, ["body", "url"]),
    ("POST", "/webhooks", {"url": "http://127.0.0.1:9/x", "secret": "s" * 20 + "\x00"}, None,
     ["body", "secret"]),
    ("POST", f"{C}/import", "kuka-with-nul", None, ["body", "text"]),
    ("POST", "/controllers", {"name": "c2", "custom_robot": {
        "name": "arm\x00", "dh_convention": "standard",
        "joints": [{"a_mm": 0.0, "alpha_deg": 90.0, "d_mm": 400.0}] * 6}}, None,
     ["body", "custom_robot", "name"]),
])
def test_a_nul_character_is_a_422_naming_the_field(client, method, path, body, params, loc):
    """A NUL (U+0000) in a token label, a role, the audit's user filter, a webhook URL or
    secret, or an imported controller file (in a comment) was a 500 DataError on PostgreSQL
    ("text fields cannot contain NUL"), and SQLite stored it. A custom arm's name with one was
    stored on both (201), and the controller's JSON backup then did not restore. Now 422
    naming the field."""
    ok(client.post("/users", json={"name": "pat", "role": "Programmer"}))
    if body == "kuka-with-nul":
        with open(KUKA_FILE, encoding="latin-1") as f:
            body = {"format": "kuka", "text": f.read().replace("\n", "\n;\x00\n", 1)}
    before = len(ok(client.get("/audit")))
    r = client.request(method, path, json=body, params=params)
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == loc, r.text
    assert len(ok(client.get("/audit"))) == before


@pytest.mark.parametrize("where", ["files", "history"])
def test_a_backup_with_a_nul_is_refused_before_the_restore(client, where):
    """A JSON backup whose kept controller file or history reason held a NUL passed the check
    (202) and its restore job failed with a 500 DataError on PostgreSQL; SQLite restored it.
    The check now refuses it at once, naming the field."""
    import json

    with open(KUKA_FILE, encoding="latin-1") as f:
        ok(client.post(f"{C}/import", json={"format": "kuka", "text": f.read()}))
    doc = json.loads(client.get(f"{C}/export", params={"format": "json"}).text)
    if where == "files":
        doc["files"][0]["text"] += "\x00"
        loc = ["body", "text", "files", 0, "text"]
    else:
        doc["history"][0]["reason"] = "edit\x00"
        loc = ["body", "text", "history", 0, "reason"]
    r = client.post(f"{C}/import", json={"format": "json", "text": json.dumps(doc)})
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == loc


def test_a_beam_id_with_a_nul_is_refused(client):
    """A light-barrier session took a beam id "bx\\u0000" (201) from its params and from a posted
    beam recording (200): the session then sat in the controller's JSON backup, which no
    longer restored (a 500 on PostgreSQL; now the backup check's 422). Both are refused at
    the door, naming the field."""
    from test_menu_light_barrier import beam_recording

    beam = {"id": "bx\x00", "point_mm": [0, 0, 0], "direction": [1, 0, 0]}
    r = client.post(f"{C}/sessions", json={"method": "tool.light_barrier", "target_no": 8,
                                           "params": {"beams": [beam]}})
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == ["body", "params", "beams", 0, "id"]
    doc = beam_recording(client)
    first = doc["sensor"]["beams"][0]["id"]
    doc["sensor"]["beams"][0]["id"] = first + "\x00"
    for sample in doc["samples"]:
        if sample["beam"] == first:
            sample["beam"] = first + "\x00"
    s = ok(client.post(f"{C}/sessions", json={"method": "tool.light_barrier", "target_no": 7}))
    r = client.post(f"{C}/sessions/{s['id']}/beam-recording", json=doc)
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"][-1] == "id", r.text
    assert all(not st["filled"] for st in ok(client.get(f"{C}/sessions/{s['id']}"))["steps"])


def test_plan_recording_honours_the_idempotency_key(client):
    """POST /plan/recording stores a recording, but ignored Idempotency-Key: a retry with the
    same key stored a second one (ids 1 and 2, measured) and a 300-character key passed. Now
    the retry answers the first one's stored answer, and a bad key is a 400."""
    body = {"robot": "ur10", "joints_deg": [[0.0, -90.0, 90.0, 0.0, 90.0, 0.0]] * 4}
    key = {"Idempotency-Key": "plan-rec-1"}
    first = client.post("/plan/recording", json=body, headers=key)
    assert first.status_code == 201, first.text
    again = client.post("/plan/recording", json=body, headers=key)
    assert again.status_code == 201 and again.json() == first.json()
    assert client.get(f"/recordings/{first.json()['id'] + 1}").status_code == 404
    other = client.post("/plan/recording", json={**body, "seed": 1}, headers=key)
    assert other.status_code == 422 and other.json()["detail"][0]["loc"] == \
        ["header", "Idempotency-Key"]
    r = client.post("/plan/recording", json=body, headers={"Idempotency-Key": "k" * 300})
    assert r.status_code == 400, r.text
