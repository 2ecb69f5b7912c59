"""Request dependencies: one database session and one transaction per request.

A request that writes is one transaction, committed before the answer is sent (a client that
got a 2xx finds its change in the database), and atomic whichever process or host serves it:

- **SQLite** (WAL): the transaction begins with ``BEGIN IMMEDIATE`` (the database's write
  lock, across processes) and waits for it in SQLite's busy handler (``db.session``);
- **PostgreSQL**: the transaction first locks its controller's row (``SELECT ... FOR
  UPDATE``, :func:`_lock_at_begin`), so every read-modify-write of one controller (jog,
  touch-up, compute, save, import, restore, slot edits) runs after the previous one committed.

The transaction runs in the route's worker thread, never on the event loop: a sync route
taking a session (``SessionDep``) is wrapped by :func:`one_thread`, which commits (or rolls
back) in that thread as the route returns, so the write lock is held only while the route
works. On SQLite a process's writing routes also take turns on one ``threading.Lock``
(:func:`sqlite_turn`): SQLite has one writer at a time anyway, and a thread that loses
``BEGIN IMMEDIATE`` to a thread of its own process would otherwise wait in SQLite's busy
handler, which sleeps 1, 2, 5, 10 ... up to 100 ms between tries (a touch-up's p99 of
hundreds of ms at a few hundred writes/s); on the lock it runs as soon as the other commits.
Writers of other processes (a second worker, the CLI, a job) still meet in the busy handler. An async route, or an Idempotency-Key claimed before the route, commits in
:func:`get_session` (in the threadpool too).

The load this serves: a plant of a few hundred cells, a person touching up every few seconds,
~100 writes/s at worst plus MES reads (``benchmarks/plant.py``, README "Measured").
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import threading
from collections.abc import AsyncIterator, Callable, Iterator
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Request
from fastapi.routing import APIRoute
from sqlalchemy import event
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from db import crud
from db.session import write_session
from server.api import idempotency
from server.auth import audit

READ_METHODS = ("GET", "HEAD", "OPTIONS")
LOCK_ON_BEGIN = "pendant_lock_controller"  # Session.info: the controller to lock at BEGIN
WRITER = "pendant_writer"  # Session.info: a writing request's session (BEGIN IMMEDIATE)


def _controller_id(request: Request) -> int | None:
    cid = request.path_params.get("controller_id")
    try:
        return None if cid is None else int(cid)
    except ValueError:
        return None  # not an int: the route's own validation answers 422


def _lock_at_begin(db: Session, _transaction: object, connection: Any) -> None:
    """``after_begin`` of every request session: a writer locks its controller's row first
    (PostgreSQL; SQLite's ``BEGIN IMMEDIATE`` has already locked the database)."""
    cid = db.info.pop(LOCK_ON_BEGIN, None)
    if cid is not None and connection.dialect.name != "sqlite":
        crud.lock_controller(connection, cid)


def _begin_write(db: Session, request: Request) -> None:
    """Begin the transaction now (its ``after_begin`` hook locks the controller), and claim the
    request's Idempotency-Key in it (``server.api.idempotency``)."""
    db.connection()
    idempotency.claim(db, request)


async def get_session(request: Request) -> AsyncIterator[Session]:
    """A session of this app's engine: a writer's (``BEGIN IMMEDIATE``, the controller's row
    lock) for any method but GET/HEAD/OPTIONS; committed after the route (what
    :func:`one_thread` did not commit already), rolled back on any error.

    Used with ``scope="function"`` so the commit happens before the response is sent."""
    maker = request.app.state.sessionmaker
    writes = request.method not in READ_METHODS
    db = write_session(maker) if writes else maker()
    db.info[WRITER] = writes
    try:
        cid = _controller_id(request) if writes else None
        if cid is not None:
            db.info[LOCK_ON_BEGIN] = cid
        if writes and idempotency.has_key(request):
            await idempotency.read_body(request)
            await run_in_threadpool(_begin_write, db, request)
        yield db
        if db.in_transaction():
            if writes:
                route = request.scope.get("route")
                await run_in_threadpool(_audited_commit, db, getattr(route, "name", "request"),
                                        request.path_params)
            else:
                await run_in_threadpool(db.commit)
    except BaseException:
        if db.in_transaction():
            await run_in_threadpool(db.rollback)
        raise
    finally:
        db.close()


SessionDep = Annotated[Session, Depends(get_session, scope="function")]
AUDIT_KEYS = ("controller_id", "session_id")  # path parameters an operation's record names


def _audited_commit(db: Session, operation: str, params: dict[str, Any]) -> None:
    """Commit, with the operation's audit record when it changed rows no hook recorded
    (``server.auth.audit.operation``): every write request leaves one."""
    ids = {k: int(v) for k in AUDIT_KEYS
           if (v := params.get(k)) is not None and str(v).isdigit()}
    audit.operation(db, operation, **ids)
    db.commit()


_SQLITE_TURNS: dict[str, threading.Lock] = {}  # database URL -> its writers' turn, per process
_TURNS_LOCK = threading.Lock()


@contextlib.contextmanager
def sqlite_turn(db: Session) -> Iterator[None]:
    """This process's turn to write ``db``'s SQLite database, held until the block ends (the
    transaction committed or rolled back). Nothing on PostgreSQL (row locks), nor when the
    session's transaction has begun already (an Idempotency-Key claimed in
    :func:`get_session`): it holds SQLite's write lock, and waiting for a turn while holding it
    would deadlock with the thread whose turn it is."""
    bind = db.get_bind()
    if bind.dialect.name != "sqlite" or db.in_transaction():
        yield
        return
    key = str(bind.url)
    with _TURNS_LOCK:
        turn = _SQLITE_TURNS.setdefault(key, threading.Lock())
    with turn:
        yield


def one_thread(endpoint: Callable[..., Any]) -> Callable[..., Any]:
    """``endpoint`` (a sync route) committing the session it was given in its own worker
    thread as it returns (rolled back if it raises). Async routes are returned unchanged.
    A writing route on SQLite runs in its process's turn (:func:`sqlite_turn`)."""
    if inspect.iscoroutinefunction(endpoint) or getattr(endpoint, "_one_thread", False):
        return endpoint

    @functools.wraps(endpoint)
    def run(*args: Any, **kwargs: Any) -> Any:
        db = next((v for v in kwargs.values() if isinstance(v, Session)), None)
        if db is None:
            return endpoint(*args, **kwargs)
        with sqlite_turn(db) if db.info.get(WRITER) else contextlib.nullcontext():
            try:
                result = endpoint(*args, **kwargs)
                _audited_commit(db, endpoint.__name__, kwargs)
            except BaseException:
                db.rollback()
                raise
        return result

    # the endpoint's annotations, evaluated in its own module: FastAPI before 0.123 reads string
    # annotations (``from __future__ import annotations``) in the wrapper's globals
    run.__signature__ = inspect.signature(endpoint, eval_str=True)  # type: ignore[attr-defined]
    run._one_thread = True  # type: ignore[attr-defined]
    return run


def install(app: FastAPI) -> None:
    """The row lock at BEGIN for every session of ``app`` (see the module's docstring)."""
    maker: sessionmaker = app.state.sessionmaker
    if not event.contains(maker, "after_begin", _lock_at_begin):
        event.listen(maker, "after_begin", _lock_at_begin)


ROUTE_FIELDS = ("response_model", "status_code", "tags", "dependencies", "summary", "description",
                "response_description", "responses", "deprecated", "methods", "operation_id",
                "response_model_include", "response_model_exclude", "response_model_by_alias",
                "response_model_exclude_unset", "response_model_exclude_defaults",
                "response_model_exclude_none", "include_in_schema", "response_class", "name",
                "callbacks", "openapi_extra", "generate_unique_id_function")


def add_routes(app: FastAPI, router: Any) -> None:
    """Serve the routes of ``router`` as the app's own, each sync route wrapped with
    :func:`one_thread`.

    Rather than ``app.include_router``: recent FastAPI (0.165 here) keeps an included router
    whole and matches a request through each included router in turn, a few tenths of a
    millisecond per request with fourteen routers (older FastAPI copied the routes, as this
    does). A router added here needs nothing else to get :func:`one_thread`.
    """
    for route in router.routes:
        if not isinstance(route, APIRoute):  # a websocket or a mount would skip the app's auth
            raise TypeError(f"add_routes serves HTTP routes only, got {route!r}")
        app.router.add_api_route(route.path, one_thread(route.endpoint),
                                 **{k: getattr(route, k) for k in ROUTE_FIELDS})
