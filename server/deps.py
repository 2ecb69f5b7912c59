"""Request dependencies: one DB session per request, committed when the route returns."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import Depends, Request
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

READ_METHODS = ("GET", "HEAD", "OPTIONS")


async def get_session(request: Request) -> AsyncIterator[Session]:
    """A session bound to this app's engine; commit on success, roll back on any error.

    Used with ``scope="function"`` so the commit happens before the response is sent: a
    client that got a 2xx finds its change in the DB. A request that writes first takes the
    app's write lock (an ``asyncio.Lock``: waiting holds no worker thread): SQLite allows one
    writer, and queueing in-process is fairer and faster than SQLite's busy-wait back-off.
    """
    lock = None if request.method in READ_METHODS else request.app.state.write_lock
    if lock is not None:
        await lock.acquire()
    db: Session = request.app.state.sessionmaker()
    try:
        yield db
        await run_in_threadpool(db.commit)
    except BaseException:
        db.rollback()
        raise
    finally:
        db.close()
        if lock is not None:
            lock.release()


SessionDep = Annotated[Session, Depends(get_session, scope="function")]
