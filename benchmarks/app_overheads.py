"""Two costs of an API process that docs/deploy.md gives, in this process on a fresh SQLite file:

1. ``gc``: one full ``gc.collect()`` once the app has started and served a few requests
   (the app, SQLAlchemy, pydantic, NumPy and SciPy imported), as it was before the service
   froze them (``gc_full_ms``) and after :func:`server.api.app.freeze_garbage`
   (``gc_frozen_ms``); the median of 5 each.
2. ``routes``: the same reads (``PATHS``, one route in each of several routers) answered by
   the app as it is, its routes its own (``deps.add_routes``), and by the same app with each
   router included whole (``app.include_router``, the endpoints wrapped alike): the per-request
   wall time of each, the smallest of ``--rounds`` interleaved rounds of ``--requests``
   requests, and the difference (``route_extra_ms``: what included routers cost a request).

The last line::

    gc_full_ms=… gc_frozen_ms=… route_flat_ms=… route_included_ms=… route_extra_ms=…

    PYTHONPATH=$PWD python benchmarks/app_overheads.py [--requests 200] [--rounds 5]
"""

from __future__ import annotations

import argparse
import gc
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

TOKEN = "pdt_app-overheads-benchmark-0123456789abcdef"
# reads whose routes sit in different routers (controllers, tool, base, sessions, external,
# webhooks): with included routers a request is matched through the routers before its own
PATHS = ("/controllers/1", "/controllers/1/tools/1", "/controllers/1/bases/1",
         "/controllers/1/sessions", "/controllers/1/external-kinematics", "/webhooks")


def client(db_url: str, included: bool):  # noqa: ANN201
    """A started TestClient of the app; ``included``: each router included whole."""
    from fastapi import APIRouter
    from fastapi.testclient import TestClient

    from server.api import app as app_module
    from server.api import deps
    from server.api.app import create_app
    from server.settings import Settings

    flat = deps.add_routes

    def include(app, router) -> None:  # noqa: ANN001
        whole = APIRouter()
        for route in router.routes:
            whole.add_api_route(route.path, deps.one_thread(route.endpoint),
                                **{k: getattr(route, k) for k in deps.ROUTE_FIELDS})
        app.include_router(whole)

    app_module.deps.add_routes = include if included else flat
    try:
        app = create_app(Settings(db_url=db_url, bootstrap_token=TOKEN))
    finally:
        app_module.deps.add_routes = flat
    c = TestClient(app, base_url="http://127.0.0.1", headers={"Authorization": f"Bearer {TOKEN}"})
    c.__enter__()
    for path in PATHS:
        r = c.get(path)
        assert r.status_code == 200, f"{path}: {r.status_code} {r.text[:200]}"
    return c


def collect_ms(repeat: int = 5) -> float:
    """The median wall time of a full ``gc.collect()``, in ms (also benchmarks/opcua_cells.py)."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        gc.collect()
        times.append((time.perf_counter() - t) * 1000)
    return statistics.median(times)


def per_request_ms(c, n: int) -> float:  # noqa: ANN001
    t = time.perf_counter()
    for k in range(n):
        c.get(PATHS[k % len(PATHS)])
    return (time.perf_counter() - t) * 1000 / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=200, help="requests per app and round")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    from server.api.app import freeze_garbage

    with tempfile.TemporaryDirectory(prefix="pendant-app-overheads-") as tmp:
        flat = client(f"sqlite:///{Path(tmp) / 'flat.db'}", included=False)
        per_request_ms(flat, 50)
        gc_full = collect_ms()
        freeze_garbage()  # what a service process does once it has started
        gc_frozen = collect_ms()
        gc.unfreeze()
        print(f"gc: a full collection {gc_full:.0f} ms; frozen {gc_frozen:.1f} ms")
        whole = client(f"sqlite:///{Path(tmp) / 'included.db'}", included=True)
        assert len(whole.app.router.routes) < len(flat.app.router.routes)  # routers kept whole
        times: dict[str, list[float]] = {"flat": [], "included": []}
        for _ in range(args.rounds):
            for name, c in (("flat", flat), ("included", whole)):
                times[name].append(per_request_ms(c, args.requests))
        for c in (flat, whole):
            c.__exit__(None, None, None)
            c.app.state.engine.dispose()
    f, i = min(times["flat"]), min(times["included"])
    print(f"routes: {f:.2f} ms a request with the app's own routes, {i:.2f} ms with the "
          f"routers included whole ({len(PATHS)} reads, smallest of {args.rounds} rounds of "
          f"{args.requests})")
    print(f"gc_full_ms={gc_full:.0f} gc_frozen_ms={gc_frozen:.1f} route_flat_ms={f:.3f} "
          f"route_included_ms={i:.3f} route_extra_ms={i - f:.3f}")


if __name__ == "__main__":
    main()
