"""Who may change a frame, over REST (issue 9): 401 without a credential, 403 without the
permission, the audit naming the user, the browser login's CSRF and idle timeout, the Host and
Origin guard, the page headers, and an audit that survives a restore and a delete."""

from __future__ import annotations

import json
import time
from datetime import datetime, timedelta, timezone

import pytest
from fastapi.testclient import TestClient

from api_helpers import ADMIN_TOKEN, C, calibrate, finish_job, make_client, ok, open_session, walk


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def add_user(client: TestClient, name: str, role: str, **token) -> dict[str, str]:
    """A user with ``role`` and the headers of a fresh token of theirs."""
    ok(client.post("/users", json={"name": name, "role": role}))
    return bearer(ok(client.post(f"/users/{name}/tokens", json=token))["token"])


def anonymous(client: TestClient) -> TestClient:
    return TestClient(client.app, raise_server_exceptions=False)


def audit(client: TestClient, **query) -> list[dict]:
    return ok(client.get("/audit", params=query))


# ------------------------------------------------------------------------- the acceptance

def test_unauthenticated_write_is_401_and_changes_nothing(client):
    before = ok(client.get(f"{C}/tools/1"))
    r = anonymous(client).put(f"{C}/tools/1", json={"name": "forged"}, headers={"If-Match": "*"})
    assert r.status_code == 401
    assert r.json()["detail"][0]["loc"] == ["header", "authorization"]
    assert r.headers["www-authenticate"].startswith("Bearer")
    assert anonymous(client).delete("/controllers/1").status_code == 401
    assert anonymous(client).post(f"{C}/robot/home").status_code == 401
    assert ok(client.get(f"{C}/tools/1")) == before
    assert ok(client.get("/controllers"))[0]["name"] == "cell-1"


def test_bad_expired_and_revoked_tokens_are_401(client):
    assert client.get(C, headers=bearer("pdt_nonsense")).status_code == 401
    assert client.get(C, headers={"Authorization": "Basic abc"}).status_code == 401
    eva = add_user(client, "eva", "Expert", days=0.00001)  # < 1 s
    time.sleep(1.1)
    r = client.put(f"{C}/tools/1", json={"name": "x"}, headers={**eva, "If-Match": "*"})
    assert r.status_code == 401 and "expired" in r.json()["detail"][0]["msg"]
    bob = bearer(ok(client.post("/users/eva/tokens", json={}))["token"])
    assert client.get(C, headers=bob).status_code == 200
    assert client.delete("/users/eva").status_code == 204
    assert client.get(C, headers=bob).status_code == 401  # the user's tokens go with the user
    assert client.post("/users/eva/tokens", json={}).status_code == 409


def test_operator_save_is_403_expert_save_is_audited_with_quality(client):
    """The issue's acceptance: an Operator's save 403, an Expert's save works and the audit
    names the Expert, with the calibration's RMS, max and 95 % bound."""
    olga = add_user(client, "olga", "Operator")
    eva = add_user(client, "eva", "Expert")
    url = open_session(client, "tool.xyz_4point", 1)
    walk(client, url)
    report = ok(client.post(f"{url}/compute", headers=eva))
    r = client.post(f"{url}/save", headers=olga)
    assert r.status_code == 403
    assert r.json()["detail"][0]["msg"] == "needs permission frames:commit; olga acts as Operator"
    assert ok(client.get(f"{C}/tools/1"))["provenance"]["method"] is None  # nothing saved
    r = client.post(f"{url}/save", headers=eva)
    slot = ok(r)
    assert slot["provenance"]["updated_by"] == "eva"
    [rec] = audit(client, user="eva", table="tool", number=1)
    assert rec["action"] == "frame.calibration" and rec["source"] == "api"
    assert rec["role"] == "Expert" and rec["controller_id"] == 1
    assert rec["session_id"] == int(url.rsplit("/", 1)[1])
    assert rec["after"]["x_mm"] == pytest.approx(report["frame"]["x"], abs=1e-6)
    assert rec["before"]["x_mm"] == 0.0
    assert rec["quality"] == {"rms_error_mm": report["rms_error_mm"],
                              "max_error_mm": report["max_error_mm"],
                              "position_bound95_mm": report["position_bound95_mm"]}
    assert rec["request_id"] == r.headers["x-request-id"] and rec["client"] == "testclient"
    r = client.put(f"{C}/tools/2", json={"name": "b"},
                   headers={**eva, "X-Request-ID": "mes-42", "If-Match": "*"})
    assert r.headers["x-request-id"] == "mes-42"
    assert audit(client, number=2)[0]["request_id"] == "mes-42"
    r = client.put(f"{C}/tools/3", json={"name": "c"},
                   headers={**eva, "X-Request-ID": "x" * 65, "If-Match": "*"})
    assert r.headers["x-request-id"] != "x" * 65  # too long: a new id
    hist = ok(client.get(f"{C}/tools/1/history"))
    assert hist[-1]["changed_by"] == "eva"


def test_audit_survives_restore_and_delete(client):
    """After a history restore, a JSON restore that replaces the history with a forged row,
    and the controller's delete, the audit still shows every change and who made it."""
    eva = add_user(client, "eva", "Expert")
    calibrate(client, "tool.xyz_4point", 1)  # admin
    ok(client.put(f"{C}/tools/1", json={"name": "pointer"}, headers={**eva, "If-Match": "*"}))
    ok(client.put(f"{C}/tools/2", json={"pose": {"x": 10}}, headers={**eva, "If-Match": "*"}))
    hist = ok(client.get(f"{C}/tools/1/history"))
    ok(client.post(f"{C}/tools/1/restore/{hist[-1]['id']}",
                   headers={**eva, "If-Match": "*"}))  # back to "tool1"
    backup = json.loads(client.get(f"{C}/export?format=json").text)
    backup["history"] = [dict(backup["history"][0], changed_at="2001-01-01T00:00:00+00:00")]
    backup["entries"] = [dict(e, name="forged") if e["table"] == "tool" and e["number"] == 1
                         else e for e in backup["entries"]]
    job = finish_job(client, client.post(f"{C}/import",
                                         json={"format": "json", "text": json.dumps(backup)}))
    assert job["state"] == "done", job  # the restore runs as a job, audited as who asked
    assert len(ok(client.get(f"{C}/tools/1/history"))) == 1  # the controller's history: forged
    assert client.delete("/controllers/1").status_code == 204
    assert client.get(C).status_code == 404

    recs = [r for r in audit(client, controller_id=1)  # the frame and controller changes;
            if not r["action"].startswith("op.")]   # the menu run's steps are op.* records
    actions = [(r["action"], r["user"], r["table"], r["number"]) for r in recs]
    assert actions == [
        ("controller.create", None, None, None),  # the demo controller at first start
        ("frame.calibration", "admin", "tool", 1),
        ("frame.edit", "eva", "tool", 1),
        ("frame.edit", "eva", "tool", 2),
        ("frame.restore", "eva", "tool", 1),
        ("backup.restore", "admin", "tool", 1),  # the slot the backup changed
        ("backup.restore", "admin", None, None),  # the summary
        ("controller.delete", "admin", None, None),
    ]
    assert recs[2]["before"] == {"name": "tool1"} and recs[2]["after"] == {"name": "pointer"}
    assert recs[4]["after"] == {"name": "tool1"}
    assert recs[5]["before"]["name"] == "tool1" and recs[5]["after"]["name"] == "forged"
    assert recs[6]["before"] == {"history_rows": 4} and recs[6]["after"]["history_rows"] == 1
    assert recs[7]["before"]["name"] == "cell-1"


def test_audit_filters_and_csv(client):
    eva = add_user(client, "eva", "Expert")
    t0 = datetime.now(timezone.utc)
    ok(client.put(f"{C}/tools/1", json={"name": "a"}, headers={**eva, "If-Match": "*"}))
    ok(client.put(f"{C}/bases/3", json={"name": "b"}, headers={"If-Match": "*"}))
    assert [r["user"] for r in audit(client, table="base", number=3)] == ["admin"]
    assert [r["number"] for r in audit(client, user="eva")] == [1]
    assert len(audit(client, since=t0.isoformat(), controller_id=1)) == 2
    assert audit(client, until=(t0 - timedelta(days=1)).isoformat()) == []
    r = client.get("/audit", params={"format": "csv", "user": "eva"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    lines = r.text.strip().splitlines()
    assert lines[0].startswith("id,at,user,role,source") and len(lines) == 2
    assert ',eva,Expert,api,' in lines[1] and '"{""name"": ""a""}"' in lines[1]
    assert client.get("/audit", params={"number": True}).status_code == 422
    assert client.get("/audit", params={"format": "xml"}).status_code == 422


def test_audit_records_import_physics_controllers_and_users(client):
    from pathlib import Path

    eva = add_user(client, "eva", "Expert")
    text = (Path(__file__).parent / "data" / "kuka_config.dat").read_text()
    n = ok(client.post(f"{C}/import", json={"format": "kuka", "text": text}, headers=eva))["entries"]
    imports = audit(client, user="eva")
    assert len(imports) == n and {r["action"] for r in imports} == {"frame.import"}
    assert all(r["after"]["method"] == "import.kuka" for r in imports)
    ok(client.put(f"{C}/cell/physics", json={"noise_mm": 0.01}))
    c = ok(client.post("/controllers", json={"name": "cell-2", "robot": "kuka_kr6_r900_sixx"}))
    add_user(client, "olga", "Operator")
    acts = {(r["action"], r["controller_id"]) for r in audit(client)}
    assert ("emulator.physics", 1) in acts and ("controller.create", c["id"]) in acts
    assert ("user.add", None) in acts and ("token.create", None) in acts
    tokens_json = json.dumps(audit(client))
    assert "pdt_" not in tokens_json  # no secret in the audit


# ----------------------------------------------------------------------- browser login

def login(client: TestClient, token: str) -> str:
    """Log ``client`` in with a token as the login page does; returns the CSRF token."""
    r = client.post("/auth/login", json={"token": token})
    assert r.status_code == 200, r.text
    set_cookie = r.headers.get_list("set-cookie")
    session = next(c for c in set_cookie if c.startswith("pendant_session="))
    assert "HttpOnly" in session and "SameSite=strict" in session and "Path=/" in session
    return client.cookies["pendant_csrf"]


def test_cookie_login_needs_the_csrf_token_for_commands(db_url):
    with make_client(db_url, token=None) as c:
        assert c.get(C).status_code == 401
        csrf = login(c, ADMIN_TOKEN)
        assert ok(c.get("/auth/me"))["source"] == "pendant"
        assert c.get(C).status_code == 200  # reads need no CSRF token
        r = c.post(f"{C}/robot/home")
        assert r.status_code == 403 and r.json()["detail"][0]["type"] == "csrf"
        r = c.put(f"{C}/tools/1", json={"name": "x"}, headers={"X-CSRF-Token": "wrong", "If-Match": "*"})
        assert r.status_code == 403
        assert ok(c.put(f"{C}/tools/1", json={"name": "x"}, headers={"X-CSRF-Token": csrf, "If-Match": "*"}))
        assert audit(c, user="admin")[-1]["source"] == "pendant"
        assert c.post("/auth/logout", headers={"X-CSRF-Token": csrf}).status_code == 204
        assert c.get(C).status_code == 401


def idle_for(client: TestClient, seconds: float) -> None:
    """Make every browser login's last command ``seconds`` old (as if the person walked away)."""
    from sqlalchemy import update

    from db.auth_models import WebSession

    with client.app.state.sessionmaker() as db:
        db.execute(update(WebSession).values(
            last_seen_at=datetime.now(timezone.utc) - timedelta(seconds=seconds)))
        db.commit()


def test_idle_login_drops_to_operator(db_url):
    with make_client(db_url) as admin:
        eva = add_user(admin, "eva", "Expert")["Authorization"].split()[1]
    with make_client(db_url, token=None) as c:  # idle timeout: 600 s
        csrf = {"X-CSRF-Token": login(c, eva)}
        assert ok(c.put(f"{C}/tools/1", json={"name": "a"}, headers={**csrf, "If-Match": "*"}))
        idle_for(c, 590)
        assert ok(c.get("/auth/me"))["role"] == "Expert"  # not yet
        ok(c.put(f"{C}/tools/1", json={"name": "a"}, headers={**csrf, "If-Match": "*"}))  # a command: awake again
        assert ok(c.get("/auth/me"))["idle"] is False
        idle_for(c, 601)
        me = ok(c.get("/auth/me"))
        assert me["role"] == "Operator" and me["idle"] is True and me["user"] == "eva"
        r = c.put(f"{C}/tools/1", json={"name": "b"}, headers={**csrf, "If-Match": "*"})
        assert r.status_code == 403 and "idle" in r.json()["detail"][0]["msg"]
        ok(c.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A1", "increment": 1},
                  headers=csrf))  # an Operator may still jog
        assert ok(c.get(f"{C}/tools/1"))["name"] == "a"
        login(c, eva)  # logging in again restores the role
        assert ok(c.get("/auth/me"))["role"] == "Expert"


def test_a_command_keeps_its_login_awake_while_another_writer_commits(db_url, monkeypatch):
    """Another process commits a write between the guard's read of the browser login and its
    note of the command: the command still answers (noted in the reading transaction, SQLite
    refused the note at once, 'database is locked', and the command got a 503)."""
    import sqlite3

    from server.auth import guard, tokens

    if not db_url.startswith("sqlite"):
        pytest.skip("SQLite's snapshot upgrade; PostgreSQL's transactions write after reading")
    with make_client(db_url, token=None) as c:
        csrf = {"X-CSRF-Token": login(c, ADMIN_TOKEN)}
        read_login = tokens.web_actor

        def and_another_writer_commits(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            actor = read_login(*args, **kwargs)
            other = sqlite3.connect(c.app.state.engine.url.database, isolation_level=None)
            other.execute("UPDATE controller SET name = name")
            other.close()
            return actor

        monkeypatch.setattr(tokens, "web_actor", and_another_writer_commits)
        monkeypatch.setattr(guard, "TOUCH_EVERY_S", 0.0)
        idle_for(c, 30)
        r = c.put(f"{C}/tools/1", json={"name": "x"}, headers={**csrf, "If-Match": "*"})
        assert r.status_code == 200, r.text
        from sqlalchemy import select

        from db.auth_models import WebSession

        with c.app.state.sessionmaker() as db:
            seen = db.scalar(select(WebSession.last_seen_at))
        assert datetime.now(timezone.utc) - seen.replace(tzinfo=timezone.utc) < timedelta(seconds=10)


def test_login_with_a_bad_token_is_401(client):
    r = anonymous(client).post("/auth/login", json={"token": "pdt_wrong"})
    assert r.status_code == 401 and r.json()["detail"][0]["loc"] == ["body", "token"]
    assert "set-cookie" not in r.headers


# ---------------------------------------------------------------------------- cross-site

def test_host_outside_the_allow_list_is_400(client):
    r = client.get(C, headers={"Host": "evil.example:8000"})
    assert r.status_code == 400 and r.json()["detail"][0]["loc"] == ["header", "host"]
    assert client.get(C, headers={"Host": "localhost:8000"}).status_code == 200


def test_command_from_another_origin_is_403_whatever_the_credential(client):
    r = client.post(f"{C}/robot/home", headers={"Origin": "http://127.0.0.1:9999"})
    assert r.status_code == 403 and r.json()["detail"][0]["loc"] == ["header", "origin"]
    assert client.post(f"{C}/robot/home", headers={"Origin": "null"}).status_code == 403
    assert client.post(f"{C}/robot/home", headers={"Origin": "http://testserver"}).status_code \
        == 200
    assert client.get(C, headers={"Origin": "http://127.0.0.1:9999"}).status_code == 200


def test_cors_closed_unless_configured(db_url, tmp_path):
    pre = {"Origin": "http://cell-pc:3000", "Access-Control-Request-Method": "PUT"}
    with make_client(db_url) as c:
        r = c.options(f"{C}/tools/1", headers=pre)
        assert "access-control-allow-origin" not in r.headers
        assert "access-control-allow-origin" not in c.get(C, headers={"Origin": pre["Origin"]}).headers
    with make_client(f"sqlite:///{tmp_path / 'b.db'}", cors_origins=("http://cell-pc:3000",)) as c:
        r = c.options(f"{C}/tools/1", headers=pre)
        assert r.headers["access-control-allow-origin"] == "http://cell-pc:3000"
        assert c.put(f"{C}/tools/1", json={"name": "x"}, headers={"Origin": pre["Origin"], "If-Match": "*"}) \
            .status_code == 200


@pytest.mark.parametrize("path", ["/", "/login.html", "/controllers/1"])
def test_pages_send_csp_frame_and_nosniff_headers(client, path):
    r = client.get(path)
    assert r.status_code == 200
    assert r.headers["x-frame-options"] == "DENY"
    assert r.headers["x-content-type-options"] == "nosniff"
    assert "frame-ancestors 'none'" in r.headers["content-security-policy"]
    assert "default-src 'self'" in r.headers["content-security-policy"]


# ------------------------------------------------------------------------ first start

def test_first_start_makes_an_administrator_once(db_url):
    from server.api.app import create_app
    from server.settings import Settings

    app = create_app(Settings(db_url=db_url, bootstrap_token=None, allowed_hosts=("testserver",)))
    token = app.state.first_token
    assert token.startswith("pdt_")
    with TestClient(app, headers=bearer(token)) as c:
        assert ok(c.get("/auth/me"))["role"] == "Administrator"
    again = create_app(Settings(db_url=db_url, bootstrap_token=None))
    assert again.state.first_token is None  # an administrator exists: nothing new is printed


def test_no_auth_demo_mode_acts_as_administrator(db_url):
    with make_client(db_url, token=None, auth=False) as c:
        assert ok(c.put(f"{C}/tools/1", json={"name": "demo"}, headers={"If-Match": "*"}))["name"] == "demo"
        assert audit(c)[-1]["user"] == "no-auth"


def test_requests_that_carry_an_expired_cache_entry_share_one_verification(client,
                                                                           monkeypatch):
    """When a token's cache entry runs out, the requests carrying it at that moment wait for
    one lookup of the token (not a thread and three queries each); a bad token is refused to
    every one of them."""
    import threading

    from server.auth import tokens

    calls: list[str] = []
    verify, cache_get = tokens.verified_actor, tokens.CACHE.get
    looked = threading.Semaphore(0)  # one release per request that looked in the cache

    def counted_get(digest):  # noqa: ANN001, ANN202
        looked.release()
        return cache_get(digest)

    def slow_verify(db_factory, digest):  # noqa: ANN001, ANN202
        calls.append(digest)
        # the lookup lasts until every request has found no entry (a bad token is never
        # cached, so a request that came after the lookup ended would make one of its own)
        for _ in range(6):
            assert looked.acquire(timeout=30), "a request never reached the token check"
        return verify(db_factory, digest)

    monkeypatch.setattr(tokens, "verified_actor", slow_verify)
    monkeypatch.setattr(tokens.CACHE, "get", counted_get)
    # the entry the first lookup makes holds for the whole test: a request that starts late on
    # a loaded machine (more than CACHE_TTL_S after it) would make a second lookup of its own
    monkeypatch.setattr(tokens.CACHE, "ttl_s", 600.0)
    for headers, status in (({}, 200), ({"Authorization": "Bearer pdt_not-a-token"}, 401)):
        tokens.CACHE.clear()
        calls.clear()
        codes: list[int] = []
        threads = [threading.Thread(target=lambda: codes.append(
            client.get(f"{C}/tools/1", headers=headers).status_code)) for _ in range(6)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        assert codes == [status] * 6
        assert len(calls) == 1, calls
