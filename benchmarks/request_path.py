"""Where a request's CPU goes, in-process: the ASGI app called directly, no HTTP, no load generator.

``benchmarks/api.py`` measures the service as a user meets it; this measures what the app itself
costs per request, and how long a touch-up holds SQLite's writers' turn (the writers' lock), on
a fresh SQLite file:

- ``touch-up``: ``POST .../sessions/{sid}/touch-up`` with recorded joints (four steps in turn);
- ``GET tool``: ``GET /controllers/1/tools/1``;
- ``GET controllers``: ``GET /controllers``.

For each, requests go one after another through the whole app (middleware, auth, routing,
dependencies, the route, the commit, the answer's JSON) in blocks of ``--block``; it prints the
CPU time per request (``time.process_time``) of the fastest of ``--blocks`` blocks, since this
machine's speed varies between runs, and the median. Then, for touch-ups, the time the writers'
turn was held per touch-up (from taking it to letting it go: ``db.writers.WriterQueue``) and the
longest collection of Python's cyclic garbage collector during the run (``gc.callbacks``), with
the app's start-up objects frozen as a service process does (``server.app.freeze_garbage``).

    python benchmarks/request_path.py [--block 400] [--blocks 5]
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.api import TOKEN, touch_joints  # noqa: E402
from db import writers  # noqa: E402
from server.app import create_app, freeze_garbage  # noqa: E402
from server.settings import Settings  # noqa: E402

HEADERS = [(b"host", b"127.0.0.1:8000"), (b"authorization", f"Bearer {TOKEN}".encode()),
           (b"content-type", b"application/json")]


class Held:
    """How long the writers' turn is held, summed over turns (wraps ``WriterQueue``)."""

    def __init__(self) -> None:
        self.total_s, self.turns, self._t0 = 0.0, 0, None
        take, give = writers.WriterQueue.acquire_async, writers.WriterQueue.release
        held = self

        async def acquire_async(queue: writers.WriterQueue) -> None:
            await take(queue)
            held._t0 = time.perf_counter()

        def release(queue: writers.WriterQueue) -> None:
            if held._t0 is not None:
                held.total_s += time.perf_counter() - held._t0
                held.turns, held._t0 = held.turns + 1, None
            give(queue)

        writers.WriterQueue.acquire_async, writers.WriterQueue.release = acquire_async, release


class Pauses:
    """The longest garbage collection (``gc.callbacks``)."""

    def __init__(self) -> None:
        self.longest_s, self.count, self._t0 = 0.0, 0, 0.0
        gc.callbacks.append(self._tick)

    def _tick(self, phase: str, _info: dict) -> None:
        if phase == "start":
            self._t0 = time.perf_counter()
        else:
            self.longest_s = max(self.longest_s, time.perf_counter() - self._t0)
            self.count += 1


async def call(app, method: str, path: str, body: bytes = b"") -> tuple[int, bytes]:  # noqa: ANN001
    """One request through the ASGI app: (status, body)."""
    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1",
             "method": method, "scheme": "http", "path": path, "raw_path": path.encode(),
             "query_string": b"", "root_path": "", "client": ("127.0.0.1", 5000),
             "server": ("127.0.0.1", 8000), "state": {},
             "headers": HEADERS + [(b"content-length", str(len(body)).encode())]}
    sent, done, out = False, asyncio.Event(), {"status": 0, "body": b""}

    async def receive() -> dict:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        await done.wait()
        return {"type": "http.disconnect"}

    async def send(message: dict) -> None:
        if message["type"] == "http.response.start":
            out["status"] = message["status"]
        elif message["type"] == "http.response.body":
            out["body"] += message.get("body", b"")

    await app(scope, receive, send)
    done.set()
    return out["status"], out["body"]


async def phase(app, method: str, path: str, bodies: list[bytes], block: int,  # noqa: ANN001
                blocks: int) -> list[float]:
    """CPU ms per request of each block."""
    per_request = []
    for b in range(blocks + 1):  # the first block warms up
        t0 = time.process_time()
        for i in range(block):
            status, answer = await call(app, method, path, bodies[i % len(bodies)])
            if status != 200:
                raise RuntimeError(f"{method} {path} -> {status}: {answer[:200]!r}")
        if b:
            per_request.append((time.process_time() - t0) * 1e3 / block)
    return per_request


async def main(args: argparse.Namespace) -> None:
    app = create_app(Settings(db_url=f"sqlite:///{Path(args.tmp) / 'bench.db'}",
                              bootstrap_token=TOKEN))
    held, pauses = Held(), Pauses()
    async with app.router.lifespan_context(app):
        freeze_garbage()
        status, answer = await call(app, "POST", "/controllers/1/sessions", json.dumps(
            {"method": "tool.xyz_4point", "target_no": 1}).encode())
        touch = f"/controllers/1/sessions/{json.loads(answer)['id']}/touch-up"
        bodies = [json.dumps({"step": k, "joints_deg": q}).encode()
                  for k, q in enumerate(touch_joints())]
        print(f"{'request':18s} {'best_ms':>8s} {'median_ms':>9s}   (CPU per request, "
              f"{args.blocks} blocks of {args.block})")
        for name, method, path, body in (("touch-up", "POST", touch, bodies),
                                         ("GET tool", "GET", "/controllers/1/tools/1", [b""]),
                                         ("GET controllers", "GET", "/controllers", [b""])):
            turns0, held0, pauses0 = held.turns, held.total_s, pauses.count
            pauses.longest_s = 0.0
            ms = await phase(app, method, path, body, args.block, args.blocks)
            print(f"{name:18s} {min(ms):8.3f} {statistics.median(ms):9.3f}")
            if method == "POST":
                n = held.turns - turns0
                print(f"{'':18s} writers' turn held {(held.total_s - held0) * 1e3 / max(n, 1):.3f}"
                      f" ms per touch-up ({n} turns); {pauses.count - pauses0} garbage "
                      f"collections, the longest {pauses.longest_s * 1e3:.1f} ms")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--block", type=int, default=400)
    ap.add_argument("--blocks", type=int, default=5)
    with tempfile.TemporaryDirectory() as tmp:
        ap.set_defaults(tmp=tmp)
        asyncio.run(main(ap.parse_args()))
