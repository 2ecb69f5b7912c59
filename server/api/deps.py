"""Request dependencies: one database session and one transaction per request.

A request that writes is one transaction, committed before the answer is sent (a client that
got a 2xx finds its change in the database), and atomic whichever process or host serves it.
It is a write as every face runs one (:mod:`server.service.transaction`): a writer's session
(SQLite ``BEGIN IMMEDIATE``; on PostgreSQL the controller of the path locked at ``BEGIN``), this
process's writers' turn, and the operation's audit record (the route's name) at the commit.

The transaction lives in the route's worker thread, never on the event loop. ``SessionDep``
(:func:`get_session`) only makes the session (no statement yet); every route taking one is a
sync route wrapped by :func:`one_thread`, which in one worker thread takes the turn, claims
the request's Idempotency-Key, runs the route, commits (or rolls back) and closes the session,
so the write lock is held only while the route works. One exception: a :func:`quick_read` (a
few rows by key, what a MES polls) runs on the event loop on SQLite, where a read waits for
no writer and no network.

The load this serves: a plant of a few hundred cells, a person touching up every few seconds,
~100 writes/s at worst plus MES reads (``benchmarks/plant.py``, README "Measured").
"""

from __future__ import annotations

import asyncio
import contextvars
import functools
import inspect
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Callable
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Request
from fastapi.routing import APIRoute
from sqlalchemy.orm import Session

from db.session import read_session
from server.api import idempotency
from server.service import transaction

READ_METHODS = ("GET", "HEAD", "OPTIONS")
REQUEST_PARAM = "pendant_request_"  # the request, given to every wrapped route (one_thread)


def _controller_id(request: Request) -> int | None:
    cid = request.path_params.get("controller_id")
    try:
        return None if cid is None else int(cid)
    except ValueError:
        return None  # not an int: the route's own validation answers 422


async def get_session(request: Request) -> Session:
    """The request's session, not begun: a writer's (``BEGIN IMMEDIATE``, the controller's row
    lock at BEGIN) for any method but GET/HEAD/OPTIONS. The route's thread begins, commits and
    closes it (:func:`one_thread`); an Idempotency-Key's body is read here, on the loop, for
    the claim's fingerprint."""
    maker = request.app.state.sessionmaker
    if request.method in READ_METHODS:
        return read_session(maker)
    if idempotency.has_key(request):
        await idempotency.read_body(request)
    return transaction.writer(maker, _controller_id(request))


SessionDep = Annotated[Session, Depends(get_session)]
AUDIT_KEYS = ("controller_id", "session_id")  # path parameters an operation's record names


def _audited_commit(db: Session, operation: str, params: dict[str, Any]) -> None:
    """The write's commit (:func:`server.service.transaction.commit`), its audit record naming
    the path's controller and session."""
    ids = {k: int(v) for k in AUDIT_KEYS
           if (v := params.get(k)) is not None and str(v).isdigit()}
    transaction.commit(db, operation, **ids)


# The routes' worker threads: readers and writers apart, so a read never waits for a thread
# that writers hold while they queue for the database's write lock (SQLite: one writer at a
# time across every process; at 100 touch-ups/s from two workers the writers queued there took
# all 40 threads of a shared pool and the reads behind them waited seconds)
READER_THREADS = 40  # anyio's default
READERS = ThreadPoolExecutor(max_workers=READER_THREADS, thread_name_prefix="read")
WRITERS = ThreadPoolExecutor(max_workers=40, thread_name_prefix="write")


async def in_worker_thread(pool: ThreadPoolExecutor, fn: Callable[..., Any], *args: Any) -> Any:
    """``fn(*args)`` in one of ``pool``'s threads, with the caller's context variables (the
    request's audit context), awaited on the event loop.

    Rather than Starlette's ``run_in_threadpool``: anyio's thread hop (its capacity limiter,
    cancel scopes and backend look-ups) cost a read a quarter of its CPU (py-spy, README
    "Measured"); the event loop's own executor hop does the same job."""
    # a checkpoint first: a request cancelled before its route starts (its client left while
    # the body was parsed, server.api.limits) is cancelled here, before the thread has it;
    # once a thread runs the route, the route finishes and commits
    await asyncio.sleep(0)
    ctx = contextvars.copy_context()
    return await asyncio.get_running_loop().run_in_executor(pool, ctx.run, fn, *args)


def quick_read(endpoint: Callable[..., Any]) -> Callable[..., Any]:
    """Mark the GET route ``endpoint`` a quick read: it reads a few rows by key and computes
    little (a controller, a slot, a session, the robot's state: what a MES polls every
    second). On SQLite :func:`one_thread` runs it on the event loop rather than in a worker
    thread: a read there waits for no writer (WAL) and no network, and the hop to a thread and
    back cost more than the read. Each hop hands the GIL between threads, and a thread that
    wants it back while another computes waits up to the switch interval (5 ms): at 1000
    reads/s beside 100 touch-ups/s, 864 reads/s were answered with the hop and the touch-ups'
    p99 grew to 10 s; 989-996/s and 0.05-0.5 s without (``benchmarks/plant.py``, README
    "Measured"). A read that may take long stays in a thread, where the loop keeps answering
    while it works: a file export, an analysis, a history, a job (its row holds its
    parameters: a restore's are megabytes); so does every read on PostgreSQL, which waits
    for the network."""
    endpoint.quick_read = True  # type: ignore[attr-defined]
    return endpoint


def on_the_loop(request: Request) -> bool:
    """Whether a :func:`quick_read` of ``request`` runs on the event loop (SQLite)."""
    return request.app.state.engine.dialect.name == "sqlite"


def one_thread(endpoint: Callable[..., Any]) -> Callable[..., Any]:
    """``endpoint`` (a sync route) run in a worker thread (:func:`in_worker_thread`); when it
    takes a session, that thread is the transaction's: this process's writers' turn
    (:func:`server.service.transaction.writers_turn`), the Idempotency-Key claimed, the route,
    the audited commit, or the rollback if anything raised; then the session is closed. A
    :func:`quick_read` on SQLite does the same on the event loop.
    Async routes are returned unchanged."""
    if inspect.iscoroutinefunction(endpoint) or getattr(endpoint, "_one_thread", False):
        return endpoint
    quick = getattr(endpoint, "quick_read", False)

    def in_transaction(request: Request, args: tuple, kwargs: dict[str, Any]) -> Any:
        db = next((v for v in kwargs.values() if isinstance(v, Session)), None)
        if db is None:
            return endpoint(*args, **kwargs)
        try:
            with transaction.writers_turn(db):
                try:
                    if idempotency.has_key(request):  # a POST that sent one
                        db.connection()  # BEGIN (the controller locked), then the key claimed
                        idempotency.claim(db, request)
                    result = endpoint(*args, **kwargs)
                    _audited_commit(db, endpoint.__name__, kwargs)
                except BaseException:
                    db.rollback()
                    raise
        finally:
            db.close()
        return result

    # the endpoint's parameters (annotations evaluated in its own module: FastAPI before 0.123
    # reads string annotations in the wrapper's globals) and the request, for the key's claim
    # (FastAPI gives the request to one parameter only: the endpoint's own, if it has one)
    sig = inspect.signature(endpoint, eval_str=True)
    params = list(sig.parameters.values())
    own = next((p.name for p in params if p.annotation is Request), None)
    if own is None:
        params.append(inspect.Parameter(REQUEST_PARAM, inspect.Parameter.KEYWORD_ONLY,
                                        annotation=Request))

    @functools.wraps(endpoint)
    async def run(*args: Any, **kwargs: Any) -> Any:
        request = kwargs[own] if own else kwargs.pop(REQUEST_PARAM)
        if request.method in READ_METHODS:
            if quick and on_the_loop(request):
                return in_transaction(request, args, kwargs)
            return await in_worker_thread(READERS, in_transaction, request, args, kwargs)
        return await in_worker_thread(WRITERS, in_transaction, request, args, kwargs)

    run.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
    run._one_thread = True  # type: ignore[attr-defined]
    return run


def install(app: FastAPI) -> None:
    """The row lock at BEGIN for the writers' sessions of ``app``
    (:func:`server.service.transaction.install`)."""
    transaction.install(app.state.sessionmaker)


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
        if getattr(route.endpoint, "quick_read", False) and not route.methods <= {"GET", "HEAD"}:
            raise TypeError(f"quick_read is for reads, {route.path} answers {route.methods}")
        app.router.add_api_route(route.path, one_thread(route.endpoint),
                                 **{k: getattr(route, k) for k in ROUTE_FIELDS})
