"""Request dependencies: one DB session per request, committed when the route returns.

A request that writes is atomic in the database, whichever process or host serves it: on
SQLite its transaction starts with ``BEGIN IMMEDIATE`` (SQLite's write lock, across processes),
and on PostgreSQL it first locks its controller's row (``SELECT ... FOR UPDATE``), so every
read-modify-write of one controller (jog, touch-up, compute, save, import, restore, physics,
slot edits) runs after the previous one committed. Correctness rests on those database locks
alone, across processes and hosts.

In the process, writers pass a bulkhead first (``app.state.writers``, an ``asyncio.Semaphore``
of :func:`writer_slots`): a request waiting for a database lock holds a thread of the
threadpool, and if every thread waited, the request holding the lock could not get one to
finish and commit. The bulkhead keeps threads free for it (and for readers); it orders
nothing and protects no data.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import Depends, Request
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from db import crud
from db.session import write_session
from server import idempotency

READ_METHODS = ("GET", "HEAD", "OPTIONS")
WRITER_SLOTS = {"sqlite": 1}  # SQLite has one writer per database anyway; PostgreSQL: 8


def writer_slots(dialect: str) -> int:
    """Writers of one process inside the database at once (the rest wait without a thread)."""
    return WRITER_SLOTS.get(dialect, 8)


def _begin_write(db: Session, request: Request) -> None:
    """Lock what the request will change (PostgreSQL: its controller's row), claim its
    Idempotency-Key in the same transaction."""
    cid = request.path_params.get("controller_id")
    if cid is not None:
        try:
            crud.lock_controller(db, int(cid))
        except ValueError:
            pass  # not an int: the route's own validation answers 422
    idempotency.claim(db, request)


async def get_session(request: Request) -> AsyncIterator[Session]:
    """A session bound to this app's engine; commit on success, roll back on any error.

    Used with ``scope="function"`` so the commit happens before the response is sent: a
    client that got a 2xx finds its change in the DB.
    """
    maker = request.app.state.sessionmaker
    writes = request.method not in READ_METHODS
    slots = request.app.state.writers if writes else None
    if slots is not None:
        await slots.acquire()
    db: Session = write_session(maker) if writes else maker()
    try:
        if writes:
            await idempotency.read_body(request)
            await run_in_threadpool(_begin_write, db, request)
        yield db
        await run_in_threadpool(db.commit)
    except BaseException:
        await run_in_threadpool(db.rollback)
        raise
    finally:
        db.close()
        if slots is not None:
            slots.release()


SessionDep = Annotated[Session, Depends(get_session, scope="function")]


def install(app) -> None:  # noqa: ANN001
    """The writers' bulkhead of ``app`` (see the module's docstring)."""
    app.state.writers = asyncio.Semaphore(writer_slots(app.state.engine.dialect.name))
