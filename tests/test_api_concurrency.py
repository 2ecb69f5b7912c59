"""Optimistic concurrency for people (issue 8): ETag on reads, If-Match on writes (412 with the
current value, 428 on a slot write without it), the session whose target slot changed after
compute, Idempotency-Key on POST commands, ids and seeds in the backend's range, and the
schema step (``pendant db upgrade``; ``serve --no-migrate`` refuses an old schema)."""

from __future__ import annotations

from api_helpers import C, edit_slot, ok, open_session, walk

from db.session import alembic_config as _alembic_config
from alembic.script import ScriptDirectory as _Scripts

HEAD = _Scripts.from_config(_alembic_config("sqlite://")).get_current_head()  # the code's schema

JOG = {"mode": "joint", "axis": "A1", "increment": 0.5}


def test_a_slot_carries_its_version_as_etag(client):  # noqa: ANN001
    r = client.get(f"{C}/tools/3")
    first = r.headers["ETag"]
    w = client.put(f"{C}/tools/3", json={"name": "pointer"}, headers={"If-Match": first})
    assert w.status_code == 200 and w.headers["ETag"] != first
    assert client.get(f"{C}/tools/3").headers["ETag"] == w.headers["ETag"]


def test_a_stale_if_match_is_412_with_the_current_slot(client):  # noqa: ANN001
    old = client.get(f"{C}/tools/3").headers["ETag"]
    ok(client.put(f"{C}/tools/3", json={"name": "alice"}, headers={"If-Match": old}))
    r = client.put(f"{C}/tools/3", json={"name": "bob"}, headers={"If-Match": old})
    assert r.status_code == 412
    body = r.json()
    assert body["detail"][0]["loc"] == ["header", "If-Match"]
    assert "tool 3" in body["detail"][0]["msg"]
    assert body["current"]["name"] == "alice"  # what bob would have overwritten
    assert r.headers["ETag"] == client.get(f"{C}/tools/3").headers["ETag"]
    assert ok(client.get(f"{C}/tools/3"))["name"] == "alice"


def test_a_slot_write_without_if_match_is_428(client):  # noqa: ANN001
    for r in (client.put(f"{C}/bases/2", json={"name": "blind"}),
              client.post(f"{C}/tools/1/restore/1")):
        assert r.status_code in (404, 428)
    r = client.put(f"{C}/bases/2", json={"name": "blind"})
    assert r.status_code == 428
    assert r.json()["detail"][0]["loc"] == ["header", "If-Match"]
    assert ok(client.get(f"{C}/bases/2"))["name"] == ""
    assert ok(client.put(f"{C}/bases/2", json={"name": "mine"}, headers={"If-Match": "*"}))


def test_restore_needs_if_match_too(client):  # noqa: ANN001
    ok(edit_slot(client, f"{C}/tools/2", {"name": "first"}))
    h = ok(client.get(f"{C}/tools/2/history"))[0]["id"]
    assert client.post(f"{C}/tools/2/restore/{h}").status_code == 428
    r = client.post(f"{C}/tools/2/restore/{h}", headers={"If-Match": '"999"'})
    assert r.status_code == 412 and r.json()["current"]["name"] == "first"
    etag = client.get(f"{C}/tools/2").headers["ETag"]
    assert ok(client.post(f"{C}/tools/2/restore/{h}", headers={"If-Match": etag}))["name"] == ""


def test_session_and_robot_commands_honour_if_match(client):  # noqa: ANN001
    s = open_session(client, "tool.xyz_4point", target_no=4)
    etag = client.get(s).headers["ETag"]
    ok(client.post(f"{s}/touch-up", json={}, headers={"If-Match": etag}))
    r = client.post(f"{s}/touch-up", json={}, headers={"If-Match": etag})  # the session moved on
    assert r.status_code == 412 and len([x for x in r.json()["current"]["steps"]
                                         if x["filled"]]) == 1
    robot = client.get(f"{C}/robot")
    ok(client.post(f"{C}/robot/jog", json=JOG, headers={"If-Match": robot.headers["ETag"]}))
    r = client.post(f"{C}/robot/jog", json=JOG, headers={"If-Match": robot.headers["ETag"]})
    assert r.status_code == 412 and "joints_deg" in r.json()["current"]
    assert client.get(f"{C}").headers["ETag"] == client.get(f"{C}/robot").headers["ETag"]


def test_save_refuses_a_target_slot_changed_after_compute(client):  # noqa: ANN001
    s = open_session(client, "tool.xyz_4point", target_no=6)
    walk(client, s)  # approach and touch up every step
    ok(client.post(f"{s}/compute"))  # computed, not saved
    ok(edit_slot(client, f"{C}/tools/6", {"name": "by hand", "pose": {"x": 1, "y": 2, "z": 3}}))
    r = client.post(f"{s}/save")
    assert r.status_code == 409
    msg = r.json()["detail"][0]["msg"]
    assert "tool 6 changed after session" in msg and "edit" in msg and "compute again" in msg
    assert ok(client.get(f"{C}/tools/6"))["pose"]["x"] == 1.0  # the hand edit stands
    ok(client.post(f"{s}/compute"))  # computed again on the slot as it is now: saving is fine
    # (a slot named by hand asks first: issue 24, tests/test_menu_slots.py)
    saved = ok(client.post(f"{s}/save", params={"confirm": "true"}))
    assert saved["provenance"]["method"] == "tool.xyz_4point"


def test_two_sessions_into_one_slot_the_second_save_is_refused(client):  # noqa: ANN001
    a = open_session(client, "tool.xyz_4point", target_no=7)
    b = open_session(client, "tool.xyz_4point", target_no=7)
    for s in (a, b):
        walk(client, s)
        ok(client.post(f"{s}/compute"))
    ok(client.post(f"{a}/save"))
    r = client.post(f"{b}/save")
    assert r.status_code == 409
    assert f"session {a.rsplit('/', 1)[1]}" in r.json()["detail"][0]["msg"]


def test_idempotency_key_replays_the_stored_answer(client):  # noqa: ANN001
    a1 = ok(client.get(f"{C}/robot"))["joints_deg"][0]
    key = {"Idempotency-Key": '"7c1f-jog-1"'}
    first = client.post(f"{C}/robot/jog", json=JOG, headers=key)
    again = client.post(f"{C}/robot/jog", json=JOG, headers=key)
    assert first.status_code == again.status_code == 200
    assert again.content == first.content and again.headers["ETag"] == first.headers["ETag"]
    assert ok(client.get(f"{C}/robot"))["joints_deg"][0] - a1 == 0.5  # moved once
    other = client.post(f"{C}/robot/jog", json={**JOG, "increment": 1.0}, headers=key)
    assert other.status_code == 422
    assert other.json()["detail"][0]["loc"] == ["header", "Idempotency-Key"]
    elsewhere = client.post(f"{C}/robot/home", headers=key)
    assert elsewhere.status_code == 422
    assert client.post(f"{C}/robot/jog", json=JOG,
                       headers={"Idempotency-Key": ""}).status_code == 400


def test_a_refused_command_stores_no_key(client):  # noqa: ANN001
    key = {"Idempotency-Key": "retry-me"}
    bad = client.post(f"{C}/robot/jog", json={**JOG, "axis": "X", "mode": "joint"},
                      headers=key)
    assert bad.status_code == 422 and "axis" in bad.text
    # the same key with the same (bad) request runs again, and is refused again the same way
    assert client.post(f"{C}/robot/jog", json={**JOG, "axis": "X", "mode": "joint"},
                       headers=key).status_code == 422
    # a refusal stored nothing, so the key is free for the request the person meant
    assert client.post(f"{C}/robot/jog", json=JOG, headers=key).status_code == 200


def test_ids_and_seeds_beyond_32_bits(client):  # noqa: ANN001
    for big in (2**31, 2**40, 2**63 - 1):
        for path in (f"/controllers/{big}", f"{C}/sessions/{big}", f"/analysis/{big}",
                     f"/recordings/{big}"):
            assert client.get(path).status_code == 404, path
        assert client.post(f"{C}/tools/1/restore/{big}",
                           headers={"If-Match": "*"}).status_code == 404
    c = ok(client.post("/controllers", json={"name": "big-seed", "cell_seed": 2**32 - 1}))
    assert ok(client.get(f"/controllers/{c['id']}/cell"))  # the cell of that seed is built
    assert client.post("/controllers", json={"name": "big-seed", "cell_seed": 2**32 - 1}
                       ).status_code == 409


def test_healthz(client):  # noqa: ANN001
    assert ok(client.get("/healthz")) == {"status": "ok", "schema": HEAD}


def test_db_upgrade_then_serve_without_migrating(tmp_path, capsys):  # noqa: ANN001
    from server.api.app import SchemaOutOfDate, create_app
    from server.cli.main import main
    from server.settings import Settings

    url = f"sqlite:///{tmp_path / 'fresh.db'}"
    try:
        create_app(Settings(db_url=url, migrate=False))
        raise AssertionError("an empty schema was served")
    except SchemaOutOfDate as err:
        assert "pendant db upgrade" in str(err)
    assert main(["serve", "--no-migrate", "--db", url, "--port", "1"]) == 2
    assert "pendant db upgrade" in capsys.readouterr().err
    assert main(["db", "upgrade", "--db", url]) == 0
    assert f"empty -> {HEAD}" in capsys.readouterr().out
    assert main(["db", "upgrade", "--db", url]) == 0
    assert "nothing to do" in capsys.readouterr().out
    create_app(Settings(db_url=url, migrate=False))  # the schema is the code's: it serves


def test_the_cli_edits_a_slot_with_if_match(db_url, capsys, monkeypatch):  # noqa: ANN001
    """``pendant slot`` against a running service: reads the ETag, writes with If-Match, and
    refuses (exit 3, nothing written) when the ETag it is given is stale. The CLI's token
    comes from $PENDANT_TOKEN."""
    import httpx

    from api_helpers import ADMIN_TOKEN
    from browser_helpers import serve
    from server.cli.main import main

    monkeypatch.setenv("PENDANT_TOKEN", ADMIN_TOKEN)
    auth = {"Authorization": f"Bearer {ADMIN_TOKEN}"}
    with serve(db_url) as url:
        first = httpx.get(f"{url}{C}/tools/8", headers=auth).headers["ETag"]
        assert main(["slot", "tool", "8", "--url", url, "--name", "pointer",
                     "--pose", "1,2,180,0,0,0"]) == 0
        assert "'pointer'" in capsys.readouterr().out
        assert main(["slot", "tool", "8", "--url", url, "--name", "late", "--etag", first]) == 3
        err = capsys.readouterr().err
        assert "changed since it was read" in err and "'pointer'" in err
        assert httpx.get(f"{url}{C}/tools/8", headers=auth).json()["name"] == "pointer"
        assert main(["slot", "tool", "8", "--url", url]) == 0
        assert "z 180.000" in capsys.readouterr().out
