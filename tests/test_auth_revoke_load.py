"""Revocation is an emergency action (issue 21, items 1 and 8): under a write load it succeeds at
once, and the token stops working within a second, on both backends.

The service runs as a process of its own (its token cache is not this process'); three
threads jog its robot all along; ``pendant tokens revoke ID`` (and ``pendant users revoke``)
run here, on their own database connection, as the command does. The three tests under load
are marked ``load`` (tests/conftest.py: they run alone, and the lowest-versions pass leaves them
out: the CLI and routes they call are called there by test_auth_cli and test_auth_api)."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest
from sqlalchemy import select

from api_helpers import ADMIN_TOKEN, C
from browser_helpers import free_port
from db.auth_models import ApiToken
from server.auth import tokens
from server.cli.main import main

ROOT = Path(__file__).resolve().parent.parent
TRIES = 20
COMMAND_S = 2.0  # the command returns within this
REFUSED_S = 1.0  # the service refuses the token within this after the command returned


@contextlib.contextmanager
def service(db_url: str, **env_extra: str):
    """``pendant serve`` on ``db_url`` (no job workers), its first Administrator ADMIN_TOKEN;
    ``env_extra`` goes into its environment."""
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PENDANT_ADMIN_TOKEN": ADMIN_TOKEN,
           **env_extra}
    proc = subprocess.Popen([sys.executable, "-m", "server.cli", "serve", "--port", str(port),
                             "--db", db_url, "--job-workers", "0"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 90
        while True:
            assert proc.poll() is None, "pendant serve exited"
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                    break
            assert time.monotonic() < deadline, "pendant serve did not start"
            time.sleep(0.1)
        yield url
    finally:
        proc.terminate()
        proc.wait(timeout=30)


@contextlib.contextmanager
def jogging(url: str, threads: int = 3):
    """``threads`` clients jogging A1 back and forth; yields a list of the answers' codes."""
    stop, codes = threading.Event(), []

    def run(k: int) -> None:
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {ADMIN_TOKEN}"},
                          timeout=30) as c:
            sign = 1.0 if k % 2 else -1.0
            while not stop.is_set():
                r = c.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A1",
                                                    "increment": 0.01 * sign})
                codes.append(r.status_code)
                sign = -sign

    workers = [threading.Thread(target=run, args=(k,), daemon=True) for k in range(threads)]
    for w in workers:
        w.start()
    try:
        yield codes
    finally:
        stop.set()
        for w in workers:
            w.join(timeout=30)


def cli(*argv: str) -> tuple[int, str, str, float]:
    """``pendant ARGV`` here: (exit code, stdout, stderr, seconds)."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.monotonic()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(list(argv))
        except Exception as e:  # noqa: BLE001 -- a traceback is the failure under test
            import traceback

            traceback.print_exc(file=err)
            rc = f"raised {type(e).__name__}: {e}"
    return rc, out.getvalue(), err.getvalue(), time.monotonic() - t0


def token_id(db_url: str, secret: str) -> int:
    from db.session import make_engine, make_sessionmaker

    engine = make_engine(db_url)
    try:
        with make_sessionmaker(engine)() as db:
            return db.scalar(select(ApiToken.id).where(
                ApiToken.token_sha256 == tokens.sha256(secret)))
    finally:
        engine.dispose()


def refused_within(url: str, secret: str, seconds: float) -> float | None:
    """Seconds until ``secret`` gets 401 from the service (polled), None if not in time."""
    t0 = time.monotonic()
    with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {secret}"},
                      timeout=5) as c:
        while True:
            r = c.get(f"{C}/robot")
            if r.status_code == 401:
                return time.monotonic() - t0
            assert r.status_code == 200, r.text
            if time.monotonic() - t0 > seconds:
                return None
            time.sleep(0.02)


@pytest.mark.load
def test_cli_revoke_under_jog_load_returns_at_once_and_the_token_stops(fresh_db, tmp_path):
    db = fresh_db()
    assert cli("users", "add", "eva", "--role", "Expert", "--db", db)[0] == 0
    took_s, refused_s = [], []
    with service(db) as url, jogging(url) as codes:
        for k in range(TRIES):
            rc, secret, err, _ = cli("tokens", "create", "eva", "--db", db)
            assert rc == 0, err
            secret = secret.strip()
            assert httpx.get(f"{url}{C}/robot", headers={
                "Authorization": f"Bearer {secret}"}).status_code == 200
            jogs = len(codes)
            rc, out, err, took = cli("tokens", "revoke", str(token_id(db, secret)), "--db", db)
            assert rc == 0 and "Traceback" not in err, f"try {k}: {rc} {err}"
            assert took < COMMAND_S, f"try {k}: the revoke took {took:.2f} s"
            refused = refused_within(url, secret, REFUSED_S)
            assert refused is not None, \
                f"try {k}: the token still worked {REFUSED_S} s after the revoke"
            assert len(codes) > jogs, "no jog ran during the try"
            took_s.append(took)
            refused_s.append(refused)
    print(f"revoke: max {max(took_s):.3f} s; refused after max {max(refused_s):.3f} s; "
          f"{len(codes)} jogs")
    assert codes.count(200) > TRIES, codes[:50]
    assert set(codes) == {200}, sorted(set(codes))


@pytest.mark.load
def test_cli_user_revoke_under_jog_load(fresh_db, tmp_path):
    db = fresh_db()
    with service(db) as url, jogging(url) as codes:
        for k in range(5):
            name = f"user{k}"
            assert cli("users", "add", name, "--role", "Expert", "--db", db)[0] == 0
            rc, secret, err, _ = cli("tokens", "create", name, "--db", db)
            assert rc == 0, err
            rc, out, err, took = cli("users", "revoke", name, "--db", db)
            assert rc == 0 and "Traceback" not in err, f"try {k}: {rc} {err}"
            assert took < COMMAND_S, f"try {k}: the revoke took {took:.2f} s"
            assert refused_within(url, secret.strip(), REFUSED_S) is not None
    assert set(codes) == {200}, sorted(set(codes))


@pytest.mark.load
def test_rest_user_revoke_under_jog_load(fresh_db, tmp_path):
    """``DELETE /users/{name}`` while three clients jog: answered within 2 s, refused at once."""
    db = fresh_db()
    admin = {"Authorization": f"Bearer {ADMIN_TOKEN}"}
    with service(db) as url, jogging(url) as codes, \
            httpx.Client(base_url=url, headers=admin, timeout=30) as c:
        for k in range(10):
            name = f"rest{k}"
            assert c.post("/users", json={"name": name, "role": "Expert"}).status_code == 201
            secret = c.post(f"/users/{name}/tokens", json={}).json()["token"]
            t0 = time.monotonic()
            assert c.delete(f"/users/{name}").status_code == 204
            took = time.monotonic() - t0
            assert took < COMMAND_S, f"try {k}: the revoke took {took:.2f} s"
            assert refused_within(url, secret, REFUSED_S) is not None
    assert set(codes) == {200}, sorted(set(codes))


def test_a_lookup_between_the_revokes_flush_and_commit_caches_nothing(db_url):
    """Item 8: the revoke's flush empties the cache; a request that verifies the token before
    the revoke commits reads the still valid row. It must not leave the token trusted after the
    commit (it did, for up to the cache's lifetime)."""
    from api_helpers import make_client

    with make_client(db_url) as client:
        maker = client.app.state.sessionmaker
        with maker() as db:
            secret = tokens.create_token(db, tokens.get_user(db, "admin"), 1.0, "race")
            db.commit()
        bearer = {"Authorization": f"Bearer {secret}"}
        assert client.get(f"{C}/robot", headers=bearer).status_code == 200
        digest = tokens.sha256(secret)
        assert tokens.CACHE.get(digest) is not None
        with maker() as db:
            t = db.scalar(select(ApiToken).where(ApiToken.token_sha256 == digest))
            tokens.revoke_token(db, t.id)  # flushed: the cache is empty now
            assert tokens.CACHE.get(digest) is None
            # a request in between: its lookup reads the committed (valid) row
            assert tokens.verified_actor(maker, digest) is not None
            db.commit()
        assert tokens.CACHE.get(digest) is None
        assert client.get(f"{C}/robot", headers=bearer).status_code == 401


def test_a_verification_begun_before_the_revoke_is_not_joined_after_it(db_url):
    """Item 8, the shared verification: a request that comes after the revoke's commit never
    takes the answer of a lookup that began before it."""
    import asyncio

    from api_helpers import make_client
    from server.auth import guard

    with make_client(db_url) as client:
        maker = client.app.state.sessionmaker
        with maker() as db:
            secret = tokens.create_token(db, tokens.get_user(db, "admin"), 1.0, "race")
            db.commit()
        digest = tokens.sha256(secret)
        old_key = (None, digest, tokens.CACHE.generation)
        with maker() as db:
            t = db.scalar(select(ApiToken).where(ApiToken.token_sha256 == digest))
            tokens.revoke_token(db, t.id)
            db.commit()

        async def after_commit() -> bool:
            loop = asyncio.get_running_loop()
            stale = loop.create_future()  # the verification begun before: "valid"
            stale.set_result(tokens.Actor("admin", "Administrator", frozenset(), "api"))
            guard._VERIFYING[(loop, *old_key[1:])] = stale

            class Req:
                app = client.app

            try:
                task = guard._verification(Req(), digest)
                return task is not stale
            finally:
                guard._VERIFYING.pop((loop, *old_key[1:]), None)

        assert asyncio.run(after_commit())
