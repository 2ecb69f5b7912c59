"""``pendant users|tokens|roles`` and the first start of ``pendant serve`` (issue 9)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import httpx

from api_helpers import ADMIN_TOKEN, make_client
from browser_helpers import free_port
from server.cli.main import main

ROOT = Path(__file__).resolve().parent.parent


def test_users_tokens_roles(tmp_path, capsys):
    db = f"sqlite:///{tmp_path / 'p.db'}"
    assert main(["users", "add", "eva", "--role", "Expert", "--db", db]) == 0
    assert main(["users", "add", "eva", "--role", "Expert", "--db", db]) == 2
    assert "a user named 'eva' exists already" in capsys.readouterr().err
    assert main(["users", "add", "bob", "--role", "Boss", "--db", db]) == 2
    assert "role: unknown role 'Boss'" in capsys.readouterr().err
    assert main(["roles", "add", "Measurer", "frames:read", "sessions:run", "--db", db]) == 0
    assert main(["users", "add", "mia", "--role", "Measurer", "--db", db]) == 0
    capsys.readouterr()
    assert main(["tokens", "create", "eva", "--days", "2", "--db", db]) == 0
    out = capsys.readouterr()
    token = out.out.strip()
    assert re.fullmatch(r"pdt_[A-Za-z0-9_-]{43}", token) and "valid 2 days" in out.err

    with make_client(db, token=token) as c:
        assert c.get("/auth/me").json()["user"] == "eva"
        assert c.put("/controllers/1/tools/1", json={"name": "x"}, headers={"If-Match": "*"}).status_code == 200
        assert main(["users", "revoke", "eva", "--db", db]) == 0
        assert c.get("/controllers/1").status_code == 401
        audit = c.get("/audit", headers={"Authorization": "Bearer " + ADMIN_TOKEN}).json()
    capsys.readouterr()
    assert main(["tokens", "create", "mia", "--label", "cell-pc", "--db", db]) == 0
    mia = capsys.readouterr().out.strip()
    assert main(["tokens", "list", "mia", "--db", db]) == 0
    listing = capsys.readouterr().out
    assert "cell-pc" in listing and "pdt_" not in listing
    token_id = int(listing.splitlines()[1].split()[0])
    with make_client(db, token=mia) as c:
        assert c.get("/controllers/1").status_code == 200
        assert main(["tokens", "revoke", str(token_id), "--db", db]) == 0
        assert c.get("/controllers/1").status_code == 401
    assert main(["tokens", "revoke", "999", "--db", db]) == 2
    assert "no token 999" in capsys.readouterr().err
    assert main(["users", "revoke", "zed", "--db", db]) == 2
    assert "no user 'zed'" in capsys.readouterr().err
    assert main(["users", "list", "--db", db]) == 0
    listing = capsys.readouterr().out
    assert re.search(r"eva\s+Expert\s+\S+ \S+\s+\d{4}-", listing)  # revoked, with its time
    assert re.search(r"mia\s+Measurer", listing)
    cli = [r for r in audit if r["source"] == "cli"]
    assert [r["action"] for r in cli][:4] == ["user.add", "role.add", "user.add", "token.create"]
    assert cli[0]["user"].startswith("cli:")
    assert [r["user"] for r in audit if r["action"] == "frame.edit"] == ["eva"]


def test_first_serve_prints_a_login_link_that_works(tmp_path):
    """The README's first command: a new user gets a working pendant in one step."""
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PENDANT_DB_URL": f"sqlite:///{tmp_path / 'p.db'}"}
    env.pop("PENDANT_ADMIN_TOKEN", None)
    proc = subprocess.Popen([sys.executable, "-m", "server.cli", "serve", "--port", str(port)],
                            env=env, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    try:
        lines = []
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            lines.append(line)
            if "Uvicorn running" in line or not line:
                break
        text = "".join(lines)
        m = re.search(rf"http://127\.0\.0\.1:{port}/login\.html#token=(pdt_\S+)", text)
        assert m, text
        with httpx.Client(base_url=f"http://127.0.0.1:{port}") as c:
            assert c.delete("/controllers/1").status_code == 401
            r = c.post("/auth/login", json={"token": m.group(1)})
            assert r.status_code == 200 and r.json()["role"] == "Administrator"
            assert c.get("/controllers/1/tools").status_code == 200
            assert c.get("/login.html").status_code == 200
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def test_no_auth_refuses_a_non_loopback_host(capsys):
    assert main(["serve", "--host", "0.0.0.0", "--no-auth"]) == 2
    assert "--no-auth serves loopback only" in capsys.readouterr().err


def test_a_busy_database_is_one_line_to_try_again(tmp_path, capsys, monkeypatch):
    """Another writer (the service's long restore) holds the database past the writers' wait:
    `pendant users add` says so in one line and exits 75 (EX_TEMPFAIL: try again), adding
    nobody; it was a traceback. Once the database is free the same command adds the user."""
    from db import session as db_session
    from server.service import transaction

    db = f"sqlite:///{tmp_path / 'p.db'}"
    assert main(["users", "add", "eva", "--role", "Expert", "--db", db]) == 0
    capsys.readouterr()
    monkeypatch.setattr(transaction, "TURN_TIMEOUT_S", 0.3)
    engine = db_session.make_engine(db)
    holder = transaction.writer(db_session.make_sessionmaker(engine))
    with holder, transaction.writers_turn(holder):  # the other writer's turn
        assert main(["users", "add", "bob", "--role", "Operator", "--db", db]) == 75
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("pendant: the database was locked by another writer") and \
        "nothing was written: retry" in err, err
    assert main(["users", "list", "--db", db]) == 0
    assert "bob" not in capsys.readouterr().out
    assert main(["users", "add", "bob", "--role", "Operator", "--db", db]) == 0
    engine.dispose()
