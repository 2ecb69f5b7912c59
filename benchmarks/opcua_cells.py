"""The OPC UA face with many cells: how long it takes to serve them, how long one added cell
blocks the face's event loop, what a poll costs when nothing moves.

A SQLite file with ``--cells`` controllers (300; made straight through ``db.crud``, each with
its 16 tool and 32 base slots), then in this process:

1. ``start``: :meth:`PendantOpcUa.start` (nodesets, every cell, the endpoint) until it serves.
2. ``add``: ``--add`` (5) more controllers, one at a time; each is picked up by one ``sync``
   while a probe task on the same loop notes the longest gap between its 10 ms ticks: the
   time the face could answer no client.
3. ``poll``: ``--polls`` (20) syncs with nothing changed: the wall and CPU time of one
   (the database read included).
4. ``gc``: one full ``gc.collect()`` as the face runs (its nodesets and cells frozen, as
   :meth:`PendantOpcUa.start` and ``sync`` leave them) and, after ``gc.unfreeze()``, as it
   would be without ``gc.freeze`` (the median of 3 each).

The last line::

    cells=300 start_s=… add_ms=… add_block_ms=… poll_ms=… poll_cpu_ms=… nodesets_s=… gc_ms=… gc_unfrozen_ms=…

(``add_ms``/``add_block_ms``: the median of the added cells; ``nodesets_s``: the part of
``start_s`` that loads the DI and Robotics nodesets, ``space.load_nodesets``.)

    PYTHONPATH=$PWD python benchmarks/opcua_cells.py [--cells 300] [--profile start|add]
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import gc
import pstats
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

TOKEN = "pdt_opcua-cells-benchmark-0123456789abcdef"


def make_db(folder: Path, cells: int):
    """A migrated SQLite file with ``cells`` controllers; its sessionmaker."""
    from fastapi.testclient import TestClient

    from server.api.app import create_app
    from server.settings import Settings

    app = create_app(Settings(db_url=f"sqlite:///{folder / 'cells.db'}", bootstrap_token=TOKEN))
    with TestClient(app):  # migrations, the first Administrator, the demo controller
        pass
    add_controllers(app.state.sessionmaker, cells - 1, start=2)
    return app.state.sessionmaker


def add_controllers(make_session, n: int, start: int) -> None:
    from db import crud
    from db.session import write_session

    with write_session(make_session) as db:
        for k in range(start, start + n):
            crud.create_controller(db, f"plant-{k:04d}", "kuka_kr6_r900_sixx", None, k,
                                   [0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
        db.commit()


async def longest_gap(stop: asyncio.Event, gaps: list[float], tick_s: float = 0.01) -> None:
    """The longest time between ticks of ``tick_s`` while ``stop`` is unset: the loop blocked."""
    last = time.perf_counter()
    while not stop.is_set():
        await asyncio.sleep(tick_s)
        now = time.perf_counter()
        gaps.append(now - last - tick_s)
        last = now


async def run(args: argparse.Namespace, folder: Path) -> dict[str, float]:
    from benchmarks.app_overheads import collect_ms
    from server.opcua import service
    from server.opcua.service import PendantOpcUa

    nodesets_s: list[float] = []
    load_nodesets = service.space.load_nodesets

    async def timed_load_nodesets(server):  # noqa: ANN001, ANN202
        t = time.perf_counter()
        try:
            return await load_nodesets(server)
        finally:
            nodesets_s.append(time.perf_counter() - t)

    service.space.load_nodesets = timed_load_nodesets
    make_session = make_db(folder, args.cells)
    face = PendantOpcUa(make_session, "opc.tcp://127.0.0.1:0/pendant/", poll_s=3600,
                        pki_dir=folder / "pki")
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    if args.profile == "start":
        prof.enable()
    await face.start()
    prof.disable()
    start_s = time.perf_counter() - t0
    assert len(face.cells) == args.cells, f"{len(face.cells)} of {args.cells} cells served"
    add_ms, block_ms = [], []
    for k in range(args.add):
        await asyncio.to_thread(add_controllers, make_session, 1, 10_000 + k)
        stop, gaps = asyncio.Event(), []
        probe = asyncio.create_task(longest_gap(stop, gaps))
        await asyncio.sleep(0.05)
        t = time.perf_counter()
        if args.profile == "add":
            prof.enable()
        await face.sync()
        prof.disable()
        add_ms.append((time.perf_counter() - t) * 1000)
        stop.set()
        await probe
        block_ms.append(max(gaps) * 1000)
    assert len(face.cells) == args.cells + args.add
    polls, cpus = [], []
    for _ in range(args.polls):
        t, c = time.perf_counter(), time.process_time()
        await face.sync()
        polls.append((time.perf_counter() - t) * 1000)
        cpus.append((time.process_time() - c) * 1000)
    gc_ms = collect_ms(3)  # the face's objects frozen, as it runs
    gc.unfreeze()
    gc_unfrozen_ms = collect_ms(3)  # what each full collection would cost without gc.freeze
    await face.stop()
    service.space.load_nodesets = load_nodesets
    if args.profile:
        pstats.Stats(prof).sort_stats("cumulative").print_stats(40)
    return {"cells": args.cells, "start_s": start_s, "add_ms": statistics.median(add_ms),
            "add_block_ms": statistics.median(block_ms), "poll_ms": statistics.median(polls),
            "poll_cpu_ms": statistics.median(cpus), "nodesets_s": nodesets_s[0],
            "gc_ms": gc_ms, "gc_unfrozen_ms": gc_unfrozen_ms}



def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=300)
    ap.add_argument("--add", type=int, default=5)
    ap.add_argument("--polls", type=int, default=20)
    ap.add_argument("--profile", choices=("start", "add"), default=None,
                    help="print cProfile's top functions of the face's start or of the adds")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="pendant-opcua-cells-") as tmp:
        out = asyncio.run(run(args, Path(tmp)))
    print(f"cells={out['cells']} start_s={out['start_s']:.1f} add_ms={out['add_ms']:.0f} "
          f"add_block_ms={out['add_block_ms']:.0f} poll_ms={out['poll_ms']:.1f} "
          f"poll_cpu_ms={out['poll_cpu_ms']:.1f} nodesets_s={out['nodesets_s']:.1f} "
          f"gc_ms={out['gc_ms']:.0f} gc_unfrozen_ms={out['gc_unfrozen_ms']:.0f}")


if __name__ == "__main__":
    main()
