"""Events for MES: signed webhooks with retries and a delivery log, and MQTT on a real broker.

A webhook receiver runs in the test on loopback (http.server); the MQTT broker is Debian's
mosquitto on a free loopback port (tests/run installs it).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import paho.mqtt.client as mqtt
import pytest
from fastapi.testclient import TestClient

from api_helpers import C, calibrate, edit_slot, make_client, ok, wait_for
from browser_helpers import free_port
from server.events.dispatcher import Dispatcher, WebhookSink
from server.events.signing import HEADER, verify


class Receiver:
    """A webhook endpoint: records every POST; ``fail_first`` answers 500 that many times."""

    def __init__(self, fail_first: int = 0) -> None:
        self.requests: list[dict] = []
        self.fail_first = fail_first
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802
                body = self.rfile.read(int(self.headers["Content-Length"]))
                receiver.requests.append({"headers": dict(self.headers), "body": body})
                failing = receiver.fail_first > 0
                receiver.fail_first -= 1
                self.send_response(500 if failing else 204)
                self.end_headers()

            def log_message(self, *args: object) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", free_port()), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_port}/hook"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()

    def bodies(self) -> list[dict]:
        return [json.loads(r["body"]) for r in self.requests]


@pytest.fixture
def service(db_url: str) -> Iterator[TestClient]:  # noqa: F811
    """The app (as its Administrator) with its dispatcher running, retries 0.2 s apart."""
    with make_client(db_url, events_backoff_s=0.2) as client:
        yield client


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    r = Receiver()
    yield r
    r.close()


def test_a_calibration_saved_over_rest_reaches_the_webhook_signed(service: TestClient,
                                                                  receiver: Receiver) -> None:
    hook = ok(service.post("/webhooks", json={"url": receiver.url, "kinds": ["frame-committed"]}))
    _, slot = calibrate(service, "tool.xyz_4point", 3)

    wait_for(lambda: receiver.requests)
    (request,) = receiver.requests
    assert verify(hook["secret"].encode(), request["body"], request["headers"][HEADER])
    assert not verify(b"another secret of sixteen", request["body"], request["headers"][HEADER])
    doc = json.loads(request["body"])
    assert request["headers"]["X-Pendant-Event"] == doc["kind"] == "frame-committed"
    assert doc["controller"] == "cell-1"
    p = doc["payload"]
    assert (p["table"], p["number"], p["reason"], p["method"]) == ("tool", 3, "calibration",
                                                                   "tool.xyz_4point")
    assert [p["x_mm"], p["y_mm"], p["z_mm"]] == pytest.approx(
        [slot["pose"][k] for k in "xyz"], abs=1e-6)  # REST rounds to 1e-6 mm
    log = ok(service.get(f"/webhooks/{hook['id']}/deliveries"))
    assert [(d["state"], d["attempts"], d["last_status"]) for d in log] == [("delivered", 1, 204)]


def test_a_delivery_that_failed_once_is_retried_and_arrives(service: TestClient) -> None:
    receiver = Receiver(fail_first=1)
    try:
        hook = ok(service.post("/webhooks", json={"url": receiver.url}))
        ok(edit_slot(service, f"{C}/tools/2", {"name": "gripper"}))
        log = wait_for(lambda: [d for d in ok(service.get(f"/webhooks/{hook['id']}/deliveries"))
                                if d["state"] == "delivered"])
        assert [(d["attempts"], d["last_status"], d["last_error"]) for d in log] == [(2, 204, None)]
        first, second = receiver.requests
        assert first["body"] == second["body"]  # the same event, the same id
        assert first["headers"]["X-Pendant-Delivery"] == second["headers"]["X-Pendant-Delivery"]
    finally:
        receiver.close()


def test_the_test_endpoint_sends_a_ping_to_that_webhook_alone(service: TestClient,
                                                            receiver: Receiver) -> None:
    other = Receiver()
    try:
        hook = ok(service.post("/webhooks", json={"url": receiver.url}))
        ok(service.post("/webhooks", json={"url": other.url}))
        sent = ok(service.post(f"/webhooks/{hook['id']}/test"))
        wait_for(lambda: receiver.requests)
        assert receiver.bodies()[0]["kind"] == "ping"
        assert receiver.bodies()[0]["id"] == sent["event_id"]
        time.sleep(0.5)
        assert other.requests == []
    finally:
        other.close()


def test_compute_sends_calibration_computed_with_its_quality_figures(service: TestClient,
                                                                    receiver: Receiver) -> None:
    ok(service.post("/webhooks", json={"url": receiver.url, "kinds": ["calibration-computed"]}))
    report, _ = calibrate(service, "tool.xyz_4point", 4)
    wait_for(lambda: receiver.requests)
    (doc,) = receiver.bodies()  # the save's frame-committed is not subscribed
    assert doc["kind"] == "calibration-computed"
    assert doc["payload"]["rms_error_mm"] == pytest.approx(report["rms_error_mm"])
    assert doc["payload"]["position_bound95_mm"] == pytest.approx(report["position_bound95_mm"])


def test_two_dispatchers_deliver_each_event_exactly_once(db_url: str,  # noqa: F811
                                                        receiver: Receiver) -> None:
    with make_client(db_url, dispatch_events=False) as service:
        app = service.app
        ok(service.post("/webhooks", json={"url": receiver.url}))
        for k in range(1, 17):
            ok(edit_slot(service, f"{C}/tools/{k}", {"name": f"t{k}"}))
        pair = [Dispatcher(app.state.sessionmaker, {"webhook": WebhookSink()}, poll_s=0.01,
                           batch=4) for _ in range(2)]
        for d in pair:
            d.start()
        try:
            wait_for(lambda: len(receiver.requests) >= 16)
            time.sleep(0.5)
        finally:
            for d in pair:
                d.stop()
    ids = [doc["id"] for doc in receiver.bodies()]
    assert sorted(ids) == sorted(set(ids)) and len(ids) == 16


@pytest.mark.parametrize("body, field", [
    ({"url": "ftp://example.org/x"}, "url"),
    ({"url": "http://127.0.0.1/x", "kinds": ["frame-deleted"]}, "kinds"),
    ({"url": "http://127.0.0.1/x", "secret": "short"}, "secret"),
    ({"url": "http://127.0.0.1/x", "colour": "red"}, "colour"),
])
def test_a_bad_subscription_is_refused_naming_the_field(service: TestClient, body: dict,
                                                        field: str) -> None:
    r = service.post("/webhooks", json=body)
    assert r.status_code == 422
    assert field in json.dumps(r.json()["detail"])
    assert ok(service.get("/webhooks")) == []


@pytest.fixture(scope="module")
def broker() -> Iterator[int]:
    """Debian's mosquitto on a free loopback port."""
    exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    port = free_port()
    proc = subprocess.Popen([exe, "-p", str(port)], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: _listening(port), timeout=10)
        yield port
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def _listening(port: int) -> bool:
    import socket

    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_events_are_published_on_unified_namespace_topics(db_url: str,  # noqa: F811
                                                          broker: int) -> None:
    got: list[tuple[str, dict]] = []
    sub = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2)
    sub.on_message = lambda _c, _u, m: got.append((m.topic, json.loads(m.payload)))
    subscribed = threading.Event()
    sub.on_subscribe = lambda *_: subscribed.set()  # the broker's SUBACK
    sub.connect("127.0.0.1", broker)
    sub.subscribe("plant1/body-shop/+/pendant/#", qos=1)
    sub.loop_start()
    try:
        assert subscribed.wait(10), "the broker did not acknowledge the subscription"
        with make_client(db_url, mqtt_url=f"mqtt://127.0.0.1:{broker}", uns_site="plant1",
                         uns_area="body-shop") as service:
            ok(edit_slot(service, f"{C}/tools/5", {"name": "welding torch"}))
            wait_for(lambda: got)
        (topic, doc), = got
        assert topic == "plant1/body-shop/cell-1/pendant/frame-committed"
        assert (doc["kind"], doc["payload"]["number"], doc["payload"]["name"]) == (
            "frame-committed", 5, "welding torch")
    finally:
        sub.loop_stop()
        sub.disconnect()


def test_an_import_and_an_analysis_send_their_events(service: TestClient,
                                                    receiver: Receiver) -> None:
    from api_helpers import analyze
    from solvers.physics import Imperfections
    from solvers.simulate import simulate_recording

    ok(service.post("/webhooks", json={"url": receiver.url,
                                       "kinds": ["import-applied", "analysis-finished"]}))
    from pathlib import Path

    kuka = (Path(__file__).parent / "data" / "kuka_cell7_config.dat").read_text(encoding="utf-8")
    ok(service.post(f"{C}/import", json={"format": "kuka", "text": kuka, "dry_run": True}))
    ok(service.post(f"{C}/import", json={"format": "kuka", "text": kuka}))
    doc = simulate_recording("touch", "ur10", Imperfections(noise_mm=0.02), 8, seed=3)
    report = analyze(service, ok(service.post("/recordings", json=doc))["id"])
    wait_for(lambda: len(receiver.requests) >= 2)
    time.sleep(0.3)
    imported, analysed = receiver.bodies()  # the dry run sent nothing
    assert (imported["kind"], imported["controller"], imported["payload"]["format"]) == (
        "import-applied", "cell-1", "kuka")
    assert analysed["kind"] == "analysis-finished"
    assert analysed["payload"]["analysis_id"] == report["id"]
    assert analysed["payload"]["verdict"] == report["verdict"]
