"""The OPC UA face with an independent client: node-opcua (npm, tests/opcua_node/).

asyncua is both pendant's server and the other tests' client, so a mistake shared by both
sides would pass them. node-opcua logs in, reads a frame, is refused a certificate login
without the private key, and gets its data again after the face restarts.
tests/run installs node-opcua with ``npm ci`` in tests/opcua_node.
"""

from __future__ import annotations

import json
import queue
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from api_helpers import ADMIN_TOKEN, C, edit_slot, make_client, ok
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding
from opcua_helpers import ClientCert, client_certificate, start_face

from server.opcua.space import PENDANT_URI

NODE_DIR = Path(__file__).resolve().parent / "opcua_node"
NODE = shutil.which("node")
pytestmark = pytest.mark.skipif(NODE is None, reason="node (Node.js) is not installed: the "
                                                     "node-opcua client cannot run")


def pem_files(cert: ClientCert, folder: Path) -> tuple[str, str]:
    """node-opcua takes PEM: the certificate converted, the key as it is."""
    pem = folder / (Path(cert.cert).stem + ".pem")
    pem.write_bytes(x509.load_der_x509_certificate(cert.der()).public_bytes(Encoding.PEM))
    return str(pem), cert.key


@pytest.fixture(scope="module")
def cell(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:

    if not (NODE_DIR / "node_modules" / "node-opcua").is_dir():
        pytest.fail("node-opcua is not installed: run `npm ci` in tests/opcua_node (tests/run "
                    "does)")
    folder = tmp_path_factory.mktemp("opcua-node")
    db_url = fresh_db()
    with make_client(db_url) as rest:
        face = start_face(rest.app.state.sessionmaker, folder)
        cert, key = pem_files(face.client, folder)
        yield {"rest": rest, "face": face, "db_url": db_url, "folder": folder,
               "spec": {"endpoint": face.endpoint, "cert": cert, "key": key,
                        "uri": face.client.uri, "pki": str(folder / "node-pki")}}
        face.stop()


def node(spec: dict, timeout: float = 60) -> list[dict]:
    """Run client.js with ``spec``; its JSON lines."""
    r = subprocess.run([NODE, "client.js", json.dumps(spec)], cwd=NODE_DIR, capture_output=True,
                       text=True, timeout=timeout, check=False)
    lines = [json.loads(x) for x in r.stdout.splitlines() if x.startswith("{")]
    assert lines, f"node client printed nothing (rc {r.returncode}): {r.stderr[-2000:]}"
    return lines


def test_node_opcua_logs_in_and_reads_the_frame_rest_has(cell: dict) -> None:
    pose = {"x": 101.25, "y": -7.5, "z": 220.0, "a": 15.0, "b": 5.0, "c": -30.0}
    edited = edit_slot(cell["rest"], f"{C}/tools/2", {"name": "gripper", "pose": pose})
    version = int(ok(edited) and edited.headers["ETag"].strip('W/"'))
    spec = {**cell["spec"], "user": "admin", "password": ADMIN_TOKEN, "action": "read-frame",
            "controller": "cell-1", "number": 2}
    deadline = time.monotonic() + 15
    while True:  # the face takes the edit from the database at its next poll
        (got,) = node(spec)
        if got.get("version") == version or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    assert "error" not in got, got
    assert (got["name"], got["version"]) == ("gripper", version)
    assert got["frame"] == pytest.approx([101.25, -7.5, 220.0, 15.0, 5.0, -30.0])
    assert (got["x"], got["xStatus"]) == (101.25, "Good")


def test_node_opcua_with_a_users_public_certificate_is_refused(cell: dict, tmp_path: Path) -> None:
    """The registered certificate (public) in an X509 identity token, signed with another
    key: node-opcua's session is refused, as asyncua's is."""
    from server.cli.main import main

    victim = client_certificate(tmp_path, "victim-node")
    ok(cell["rest"].post("/users", json={"name": "victim", "role": "Expert"}))
    assert main(["users", "cert", "victim", victim.cert, "--db", cell["db_url"]]) == 0
    spec = {**cell["spec"], "identityCert": victim.cert,  # DER, as the token carries it "identityKey": cell["spec"]["key"],
            "action": "login"}
    (got,) = node(spec)
    assert "error" in got and "session" in got["error"], got
    # the owner, with its key, logs in
    (own,) = node({**spec, "identityKey": victim.key})
    assert own == {"ok": "Server"}


class Subscriber:
    """client.js subscribed to ``path``: its JSON lines, as they come, with their times."""

    def __init__(self, spec: dict) -> None:
        self.proc = subprocess.Popen([NODE, "client.js", json.dumps(spec)], cwd=NODE_DIR,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines: queue.Queue[tuple[float, dict]] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        for line in self.proc.stdout:  # type: ignore[union-attr]
            if line.startswith("{"):
                self.lines.put((time.monotonic(), json.loads(line)))

    def wait_for(self, pred, timeout: float) -> tuple[float, dict] | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                t, msg = self.lines.get(timeout=0.2)
            except queue.Empty:
                continue
            if pred(msg):
                return t, msg
        return None

    def request_rate(self, seconds: int = 4) -> float:
        """Requests per second the client made, from its counter printed each second."""
        counts = [self.wait_for(lambda m: "requests" in m, 5) for _ in range(seconds)]
        assert all(counts), "the client stopped printing its counter"
        (t0, first), (t1, last) = counts[0], counts[-1]  # type: ignore[misc]
        return (last["requests"] - first["requests"]) / (t1 - t0)

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=10)


def tool3_name(cell: dict, user: str, password: str) -> dict:
    return {**cell["spec"], "user": user, "password": password, "action": "subscribe",
            "path": [f"{PENDANT_URI}|Pendant", f"{PENDANT_URI}|cell-1", f"{PENDANT_URI}|Tools",
                     f"{PENDANT_URI}|Tool3", f"{PENDANT_URI}|Name"]}


def test_a_revoked_login_ends_node_opcuas_session_without_a_storm(cell: dict) -> None:
    """Revoked while subscribed: no more data, and the client is told its session ended
    (refusing each Publish made node-opcua resend at once, thousands a second)."""
    from server.auth import tokens

    ok(cell["rest"].post("/users", json={"name": "rita", "role": "Expert"}))
    made = ok(cell["rest"].post("/users/rita/tokens", json={}))
    sub = Subscriber(tool3_name(cell, "rita", made["token"]))
    try:
        assert sub.wait_for(lambda m: m.get("event") == "subscribed", 60), "never subscribed"
        with cell["rest"].app.state.sessionmaker() as db:
            (t,) = [t for t in tokens.list_tokens(db)
                    if t.token_sha256 == tokens.sha256(made["token"])]
            tokens.revoke_token(db, t.id)
            db.commit()
        ok(edit_slot(cell["rest"], f"{C}/tools/3", {"name": "after-revoke"}))
        assert sub.wait_for(lambda m: m.get("value") == "after-revoke", 3) is None
        rate = sub.request_rate()
        assert rate < 50, f"{rate:.0f} requests/s after the revoke: a request storm"
    finally:
        sub.stop()


def test_node_opcua_gets_data_again_after_the_face_restarts(cell: dict) -> None:
    """Subscribed, the face restarted: the change made after the restart arrives within
    10 s, and the client does not spin (issue 20 saw ~2,500 requests/s forever)."""
    spec = {**cell["spec"], "user": "admin", "password": ADMIN_TOKEN, "action": "subscribe",
            "path": [f"{PENDANT_URI}|Pendant", f"{PENDANT_URI}|cell-1", f"{PENDANT_URI}|Tools",
                     f"{PENDANT_URI}|Tool3", f"{PENDANT_URI}|Name"]}
    proc = subprocess.Popen([NODE, "client.js", json.dumps(spec)], cwd=NODE_DIR,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: queue.Queue[tuple[float, dict]] = queue.Queue()

    def pump() -> None:
        for line in proc.stdout:  # type: ignore[union-attr]
            if line.startswith("{"):
                lines.put((time.monotonic(), json.loads(line)))

    threading.Thread(target=pump, daemon=True).start()

    def wait_for(pred, timeout: float) -> tuple[float, dict] | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                t, msg = lines.get(timeout=0.2)
            except queue.Empty:
                continue
            assert "error" not in msg, msg
            if pred(msg):
                return t, msg
        return None

    try:
        assert wait_for(lambda m: m.get("event") == "subscribed", 60), "never subscribed"
        ok(edit_slot(cell["rest"], f"{C}/tools/3", {"name": "before-restart"}))
        assert wait_for(lambda m: m.get("value") == "before-restart", 10)
        cell["face"].restart()
        restarted = time.monotonic()
        ok(edit_slot(cell["rest"], f"{C}/tools/3", {"name": "after-restart"}))
        seen = wait_for(lambda m: m.get("value") == "after-restart", 10)
        assert seen is not None, "no data within 10 s of the restart"
        counts = []
        while len(counts) < 4:  # the request counter, printed each second
            got = wait_for(lambda m: "requests" in m, 5)
            assert got is not None
            counts.append(got)
        rate = (counts[-1][1]["requests"] - counts[0][1]["requests"]) / (counts[-1][0] - counts[0][0])
        assert rate < 50, f"{rate:.0f} requests/s after the restart: a request storm"
        assert seen[0] - restarted < 10
    finally:
        proc.terminate()
        proc.wait(timeout=10)
