"""Helpers of the API and menu tests: a real app on a fresh database (the fixtures ``db_url``
and ``client`` are in conftest.py), and a person at the pendant (approach a target as the
step says, touch up, compute, save). Import what a test uses by name."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from fastapi.testclient import TestClient

from server.api.app import create_app
from emulator import Cell, cell_for
from server.settings import Settings
from solvers.frames import Pose
from solvers.robots import ROBOTS

C = "/controllers/1"  # the demo controller "cell-1" (KUKA KR 6 R900 sixx, cell seed 1)
CELL: Cell = cell_for(ROBOTS["kuka_kr6_r900_sixx"], 1)  # its hidden truth, for the asserts only
TRUE_TCP_MM = CELL.T_flange_tool[:3, 3]


ADMIN_TOKEN = "pdt_test-administrator-token-0123456789abcdef"  # the first start's token
TEST_HOSTS = ("testserver", "127.0.0.1", "localhost")  # TestClient's Host is "testserver"


def app_settings(db_url: str, **kw) -> Settings:
    """Settings of a test app: its first Administrator gets ADMIN_TOKEN."""
    return Settings(db_url=db_url, bootstrap_token=ADMIN_TOKEN, allowed_hosts=TEST_HOSTS, **kw)


def make_client(db_url: str, token: str | None = ADMIN_TOKEN, **kw) -> TestClient:
    """A fresh app (migrations, demo controller) on ``db_url``: also how a restart is made.

    The client sends ``token`` as a bearer token (the first start's Administrator by
    default), so every test goes through the real authentication; ``None`` sends none."""
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return TestClient(create_app(app_settings(db_url, **kw)), raise_server_exceptions=False,
                      headers=headers)


def ok(r):  # noqa: ANN001, ANN201
    """The JSON of a 2xx response, else fail with the body (the named error)."""
    assert r.status_code < 300, \
        f"{r.request.method} {r.request.url.path} -> {r.status_code}: {r.text}"
    return r.json()


def edit_slot(client: TestClient, path: str, body: dict):  # noqa: ANN201
    """PUT a slot as a person does: read it (its ETag), then write with ``If-Match``."""
    etag = client.get(path).headers["ETag"]
    return client.put(path, json=body, headers={"If-Match": etag})


def restore_slot(client: TestClient, path: str, history_id: int):  # noqa: ANN201
    """POST ``{path}/restore/{history_id}`` with the slot's current ETag as ``If-Match``."""
    etag = client.get(path).headers.get("ETag", "*")
    return client.post(f"{path}/restore/{history_id}", headers={"If-Match": etag})
def finish_job(client: TestClient, r) -> dict:  # noqa: ANN001
    """The 202 answer ``r`` of a route that queued a job: run the queue here (what a
    ``pendant worker`` does, in this process) and return the finished job."""
    from server.jobs.worker import drain

    assert r.status_code == 202, f"{r.request.method} {r.request.url.path} -> {r.status_code}: {r.text}"
    job = r.json()
    assert r.headers["location"] == f"/jobs/{job['id']}" == job["links"]["self"]
    drain(client.app.state.sessionmaker)
    return ok(client.get(f"/jobs/{job['id']}"))


def analyze(client: TestClient, recording_id: int, **query) -> dict:
    """POST .../analyze, run the job, and return the stored ``analysis-report/1`` (+ ``id``)."""
    job = finish_job(client, client.post(f"/recordings/{recording_id}/analyze", params=query))
    assert job["state"] == "done", job
    return ok(client.get(job["links"]["result"]))


def open_session(client: TestClient, method: str, target_no: int = 1, controller: str = C,
                 **params) -> str:
    """POST a session; returns its URL."""
    body = {"method": method, "target_no": target_no, "params": params}
    s = ok(client.post(f"{controller}/sessions", json=body))
    return f"{controller}/sessions/{s['id']}"


def approach(client: TestClient, target: str, controller: str = C, **kw) -> dict:
    """POST /robot/approach with the ideal aim (``noise_mm`` 0) unless ``kw`` gives one."""
    return ok(client.post(f"{controller}/robot/approach", json={"target": target, "noise_mm": 0.0, **kw}))


def walk(client: TestClient, url: str, controller: str = C, extra: int = 0) -> dict:
    """Do every required step as its prompt says (approach its target, touch up), then
    ``extra`` optional ones; returns the session."""
    s = ok(client.get(url))
    for st in s["steps"]:
        if st["target"]:
            kw = {k: st[k] for k in ("tilt_deg", "around_deg", "spin_deg")}
            if st["tool_point_mm"]:
                kw["tool_point_mm"] = st["tool_point_mm"]
            approach(client, st["target"], controller, **kw)
        s = ok(client.post(f"{url}/touch-up", json={"step": st["index"]}))
    for k in range(extra):
        approach(client, s["steps"][0]["target"], controller, tilt_deg=25.0,
                 around_deg=45.0 + 100.0 * k, spin_deg=70.0 * k - 90.0)
        s = ok(client.post(f"{url}/touch-up"))
    return s


def calibrate(client: TestClient, method: str, target_no: int = 1, controller: str = C,
              extra: int = 0, **params) -> tuple[dict, dict]:
    """Open, walk, compute and save a session: (report, saved slot)."""
    url = open_session(client, method, target_no, controller, **params)
    walk(client, url, controller, extra)
    report = ok(client.post(f"{url}/compute"))
    slot = ok(client.post(f"{url}/save"))
    return report, slot


def pose_array(p: dict) -> np.ndarray:
    return np.array([p[k] for k in "xyzabc"], dtype=float)


def pose_matrix(p: dict) -> np.ndarray:
    return Pose(*pose_array(p)).as_matrix()


def angle_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    c = (np.trace(R1.T @ R2) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def calibrated_pointer(client: TestClient, number: int = 1) -> dict:
    """Tool ``number`` = the mounted pointer as a person calibrates it: XYZ 4-point, ABC 2-point."""
    calibrate(client, "tool.xyz_4point", number)
    return calibrate(client, "tool.abc_2point", number)[1]


__all__ = ["C", "CELL", "TRUE_TCP_MM", "ADMIN_TOKEN", "TEST_HOSTS", "app_settings", "make_client",
           "ok", "open_session", "edit_slot", "restore_slot",
           "approach", "walk", "calibrate", "pose_array", "pose_matrix", "angle_deg",
           "calibrated_pointer", "finish_job", "analyze"]


def wait_for(check: Callable[[], object], timeout: float = 10.0) -> object:
    """Poll ``check`` until it returns something true (returned), for at most ``timeout`` s:
    a test waits for a state, never for a fixed time."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        got = check()
        if got:
            return got
        time.sleep(0.02)
    raise AssertionError(f"not within {timeout} s")
