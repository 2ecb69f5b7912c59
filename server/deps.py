"""Request dependencies: one DB session per request, committed before the answer is sent.

A request that writes is atomic in the database, whichever process or host serves it: on
SQLite its transaction starts with ``BEGIN IMMEDIATE`` (SQLite's write lock, across processes),
and on PostgreSQL it first locks its controller's row (``SELECT ... FOR UPDATE``, run by the
session's ``after_begin`` hook as the transaction starts), so every read-modify-write of one
controller (jog, touch-up, compute, save, import, restore, physics, slot edits) runs after the
previous one committed. Correctness rests on those database locks alone, across processes and
hosts.

**One thread per transaction.** A sync route that takes a session (``SessionDep``) runs its
whole transaction in its one worker thread: the transaction begins at the route's first query
and :func:`one_thread` commits it (or rolls it back) in that thread as the route returns. The
write lock is then held only while the route computes, never while a request waits for the
event loop to hand it its next thread. What is left for :func:`get_session` (an async route,
an Idempotency-Key claim) still takes its own thread.

**The SQLite writers' queue.** On SQLite a writer takes its turn in ``db.writers.WriterQueue``
(first come first served in the process, then a ``flock`` shared by the processes of the
host) in the route's thread, just before its ``BEGIN IMMEDIATE``, and gives it up after its
commit: the next writer goes at once, instead of polling in SQLite's busy handler. It orders
writers and guards nothing (``BEGIN IMMEDIATE`` does).

**Short routes** (:func:`short`: a touch-up, the reads of a slot, a controller, a session).
On SQLite a short read runs on the event loop, without a thread. A short writer waits for
its turn without a thread and runs in a batch with the writers that waited with it, in one
transaction (``db.batch``): on SQLite the writers of the process, on the event loop; on
PostgreSQL those of its controller, in one thread under one row lock.

**PostgreSQL: one writer of a controller at a time per process.** The writers of a controller
queue on the event loop (:func:`_controller_turn`) before they take a thread and a connection:
they would wait for its row lock in the server anyway.

In the process, writers pass a bulkhead first (``app.state.writers``, an ``asyncio.Semaphore``
of :func:`writer_slots`): a request waiting for a database lock holds a thread of the
threadpool, and if every thread waited, none would be left for readers. The bulkhead keeps
threads free; it orders nothing and protects no data.
"""

from __future__ import annotations

import asyncio
import functools
import inspect
import typing
import weakref
from collections.abc import AsyncIterator, Callable
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Request, Response
from fastapi.datastructures import DefaultPlaceholder
from fastapi.routing import APIRoute
from pydantic import BaseModel, TypeAdapter
from sqlalchemy import Connection, event
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from db import crud
from db.batch import IN_A_THREAD, ControllerBatch, OneTransaction, SQLiteBatch
from db.session import write_engine, write_session
from db.writers import TURN_AT_BEGIN, WriterTurn, writer_queue
from server import idempotency

READ_METHODS = ("GET", "HEAD", "OPTIONS")
LOCK_ON_BEGIN = "pendant_lock_controller"  # Session.info: the controller to lock at BEGIN
TURN = "pendant_writer_turn"  # Session.info: the request's db.session.WriterTurn (SQLite)
PLAN = "pendant_plan"  # Session.info: what a short route's plan returned (see short)
BATCH = "pendant_batch"  # Session.info: (its db.batch batch, sessionmaker) of a short writer
WRITER_SLOTS = {"sqlite": 4}  # threads of one process waiting in SQLite's writer queue; PG: 8


def writer_slots(dialect: str) -> int:
    """Writers of one process inside the database at once (the rest wait without a thread)."""
    return WRITER_SLOTS.get(dialect, 8)


def _controller_id(request: Request) -> int | None:
    cid = request.path_params.get("controller_id")
    try:
        return None if cid is None else int(cid)
    except ValueError:
        return None  # not an int: the route's own validation answers 422


def _turn(db: Session) -> WriterTurn | None:
    return db.info.get(TURN)


def _take_turn(db: Session) -> None:
    turn = _turn(db)
    if turn is not None:
        turn.take()


def _give_turn(db: Session) -> None:
    turn = _turn(db)
    if turn is not None:
        turn.give()


def _begin_write(db: Session, request: Request) -> None:
    """Begin the transaction now (its ``after_begin`` hook locks the controller), and claim the
    request's Idempotency-Key in it."""
    _take_turn(db)
    db.connection()
    idempotency.claim(db, request)


def lock_here(db: Session) -> bool:
    """For a route whose first query reads its controller: that read takes the row lock itself
    (``SELECT ... FOR UPDATE``), one round trip less than the lock at BEGIN, which is skipped.
    True when the route should lock (a writer); call before the transaction begins."""
    return db.info.pop(LOCK_ON_BEGIN, None) is not None


def _lock_at_begin(db: Session, _transaction: object, connection: Any) -> None:
    """``after_begin`` of every request session: a writer locks its controller's row first
    (PostgreSQL; SQLite's ``BEGIN IMMEDIATE`` has already locked the database)."""
    cid = db.info.pop(LOCK_ON_BEGIN, None)
    if cid is not None and connection.dialect.name != "sqlite":
        crud.lock_controller(connection, cid)


async def get_session(request: Request) -> AsyncIterator[Session]:
    """A session bound to this app's engine; commit on success, roll back on any error.

    Used with ``scope="function"`` so the commit happens before the response is sent: a
    client that got a 2xx finds its change in the DB. A sync route's own thread commits
    (:func:`one_thread`); this dependency commits what is still open after the route.
    """
    maker = request.app.state.sessionmaker
    writes = request.method not in READ_METHODS
    cid = _controller_id(request) if writes else None
    batch = _batch_of(request, cid) if writes else None
    slots = request.app.state.writers if writes and batch is None else None
    turn = None
    if cid is not None and batch is None and request.app.state.writer_queue is None:  # PG
        turn = _controller_turn(request.app, cid)
        await turn.acquire()
    if slots is not None:
        try:
            await slots.acquire()
        except BaseException:
            if turn is not None:
                turn.release()
            raise
    db: Session | None = None
    try:
        db = write_session(maker) if writes else maker()
        if writes:
            if cid is not None:
                db.info[LOCK_ON_BEGIN] = cid
            if batch is not None:
                db.info[BATCH] = batch, maker
            queue = request.app.state.writer_queue
            if queue is not None:
                db.info[TURN] = WriterTurn(queue)
            if idempotency.has_key(request):
                await idempotency.read_body(request)
                await run_in_threadpool(_begin_write, db, request)
        yield db
        if db.in_transaction():
            await run_in_threadpool(_end, db, db.commit)
    except BaseException:
        if db is not None and db.in_transaction():
            await run_in_threadpool(_end, db, db.rollback)
        raise
    finally:
        if db is not None:
            _give_turn(db)  # a turn taken by a route that never ended its transaction
            db.close()
        if slots is not None:
            slots.release()
        if turn is not None:
            turn.release()


def _controller_turn(app: FastAPI, controller_id: int) -> asyncio.Lock:
    """PostgreSQL: the turn of one controller's writers in this process.

    Writers of one controller run one after another anyway (each locks the controller's row).
    Waiting for the row lock in PostgreSQL, each held a thread, a pooled connection and a
    server process; they contended for the GIL and the row lock together. Queued here on the
    event loop instead, a process sends one writer of a controller at a time: touch-ups with
    2 workers went from 259-284 to 415-508 req/s, p99 202-222 -> 68-89 ms, CPU 3.7-4.1 ->
    2.7-3.3 ms each (``benchmarks/api.py``, alternating runs). Writers of other controllers
    are not held up. It orders writers and guards nothing: the row lock does, across
    processes and hosts.
    """
    turns = app.state.controller_turns
    turn = turns.get(controller_id)
    if turn is None:
        turn = turns[controller_id] = asyncio.Lock()
    return turn


def _batch_of(request: Request, controller_id: int | None) -> OneTransaction | None:
    """The batch a :func:`short` writer joins (``db.batch``: SQLite, the writers of this
    process; PostgreSQL, those of its controller), or None (another route, or a request whose
    Idempotency-Key is claimed in its own transaction)."""
    app = request.app
    endpoint = getattr(request.scope.get("route"), "endpoint", None)
    queue = app.state.writer_queue
    if (not getattr(endpoint, "_short", False) or idempotency.has_key(request)
            or (queue is None and controller_id is None)):
        return None
    key = controller_id if queue is None else None
    batches = app.state.batches.setdefault(asyncio.get_running_loop(), {})
    batch = batches.get(key)
    if batch is None:
        engine = app.state.engine
        batch = batches[key] = (
            ControllerBatch(engine, key, _controller_turn(app, key)) if queue is None  # type: ignore[arg-type]
            else SQLiteBatch(queue, write_engine(engine)))
    return batch


def _end(db: Session, finish: Callable[[], None]) -> None:
    """Commit or roll back (``finish``), then give the writer's turn to the next."""
    try:
        finish()
    finally:
        _give_turn(db)


def _model_of(route: APIRoute) -> type[BaseModel] | None:
    """The model of a route answering a model or a list of one (else None)."""
    model = route.response_model
    if typing.get_origin(model) is list:
        (model,) = typing.get_args(model) or (None,)
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


@functools.lru_cache(maxsize=512)
def _adapter(model: Any) -> TypeAdapter:
    return TypeAdapter(model)


def _answer(result: Any, route: APIRoute, kwargs: dict[str, Any]) -> Any:
    """``result`` as the JSON response FastAPI would send (same bytes, status and headers of
    the route's ``response`` parameter), when it is exactly the route's response model (or a
    list of exactly its model); else ``result`` unchanged for FastAPI to serialize."""
    model = _model_of(route)
    if (model is None or not route.response_model_by_alias
            or route.response_model_include is not None
            or route.response_model_exclude is not None or route.response_model_exclude_unset
            or route.response_model_exclude_defaults or route.response_model_exclude_none
            or not isinstance(route.response_class, DefaultPlaceholder)):
        return result
    if model is route.response_model:
        if type(result) is not model:
            return result
    elif type(result) is not list or any(type(item) is not model for item in result):
        return result
    sub = next((v for v in kwargs.values() if isinstance(v, Response)), None)
    status = (sub.status_code if sub is not None else None) or route.status_code or 200
    answer = Response(_adapter(route.response_model).dump_json(result, by_alias=True),
                      status_code=status, media_type="application/json")
    if sub is not None:
        answer.headers.raw.extend(sub.headers.raw)
    return answer


SessionDep = Annotated[Session, Depends(get_session, scope="function")]


def one_thread(endpoint: Callable[..., Any], route: APIRoute | None = None) -> Callable[..., Any]:
    """``endpoint`` (a sync route) committing the session it was given in its own thread, as it
    returns (rolled back if it raises); with ``route``, a result of the route's response model
    is also serialized there (FastAPI would validate it again in another thread). Async routes
    are returned unchanged."""
    if getattr(endpoint, "_one_thread", False) or inspect.iscoroutinefunction(endpoint):
        return endpoint

    @functools.wraps(endpoint)
    def locked(*args: Any, **kwargs: Any) -> Any:
        """The route and its commit (an answer built after the commit stays to be built)."""
        db = next((v for v in kwargs.values() if isinstance(v, Session)), None)
        if db is None:
            return endpoint(*args, **kwargs)
        # a SQLite writer takes its turn just before its BEGIN IMMEDIATE (db.session), and
        # waits there rather than polling in SQLite's busy handler
        at_begin = TURN_AT_BEGIN.set(_turn(db))
        try:
            _make_plan(endpoint, db, kwargs)
            result = endpoint(*args, **kwargs)
            db.commit()
        except BaseException:
            _end(db, db.rollback)
            raise
        finally:
            TURN_AT_BEGIN.reset(at_begin)
        _give_turn(db)
        return result

    def answer(result: Any, kwargs: dict[str, Any]) -> Any:
        if isinstance(result, Later):
            result = result.build()
        return result if route is None else _answer(result, route, kwargs)

    @functools.wraps(endpoint)
    def run(*args: Any, **kwargs: Any) -> Any:
        return answer(locked(*args, **kwargs), kwargs)

    served: Callable[..., Any] = run
    if getattr(endpoint, "_short", False):
        @functools.wraps(endpoint)
        async def served(*args: Any, **kwargs: Any) -> Any:
            db = next((v for v in kwargs.values() if isinstance(v, Session)), None)
            if db is not None and BATCH in db.info:  # a writer: its batch (db.batch)
                _make_plan(endpoint, db, kwargs)  # on the loop, before the lock
                batch, maker = db.info.pop(BATCH)
                job = functools.partial(_in_batch, endpoint, maker, db, args, kwargs)
                result = await batch.run(job, reads=kwargs.get("session_id"))
                if result is IN_A_THREAD:  # SQLite's lock is held outside the queue
                    return await run_in_threadpool(run, *args, **kwargs)
                return answer(result, kwargs)
            sqlite = db is not None and db.get_bind().dialect.name == "sqlite"
            turn = _turn(db) if sqlite else None  # type: ignore[arg-type]
            if sqlite and (turn is None or turn.held):
                return run(*args, **kwargs)  # a read, or a writer begun with its turn
            return await run_in_threadpool(run, *args, **kwargs)

        del served.__wrapped__  # FastAPI would unwrap it and take the sync route for the call

    # The endpoint's annotations, evaluated in its own module: FastAPI before 0.123 reads string
    # annotations (``from __future__ import annotations``) in the wrapper's globals, not the
    # wrapped function's, and would take a body model for a query parameter.
    served.__signature__ = inspect.signature(endpoint, eval_str=True)  # type: ignore[attr-defined]
    served._one_thread = True  # type: ignore[attr-defined]
    return served


def short(endpoint: Callable[..., Any] | None = None, *,
          plan: Callable[..., Any] | None = None) -> Any:
    """Mark a sync route whose work is a millisecond or two (a touch-up, the reads of a slot or
    a controller): :func:`one_thread` runs a short read on the event loop (SQLite), and a
    short writer in a batch of writers in one transaction (``db.batch``; a writer with an
    Idempotency-Key runs alone, its key claimed in its own transaction).

    A thread cost such a route more than its work: the hop, and with 2 workers a writer in a
    thread held SQLite's write lock 2–2.5 ms for about 1 ms of work, winning the GIL back from
    the event loop after each database call. A short writer reads its controller and session
    with ``db.rows`` and writes with ``db.touch_up``, which know the batch (``db.rows.Locked``).

    ``plan`` (a writer's): a function of the route's own arguments run before the writer's
    lock is taken, without the database, for work that can be done ahead (a touch-up's
    kinematics); what it returns is the route's :func:`plan_of`, for the route to check under
    the lock and use. SQLite has one write lock for every writer: the time a writer holds it
    bounds how many writes a second get through."""
    def mark(fn: Callable[..., Any]) -> Callable[..., Any]:
        fn._short = True  # type: ignore[attr-defined]
        fn._plan = plan  # type: ignore[attr-defined]
        return fn

    return mark if endpoint is None else mark(endpoint)


def plan_of(db: Session) -> Any:
    """What the route's ``plan`` returned (see :func:`short`), or None."""
    return db.info.pop(PLAN, None)


def _make_plan(endpoint: Callable[..., Any], db: Session, kwargs: dict[str, Any]) -> None:
    plan = getattr(endpoint, "_plan", None)
    if plan is not None and PLAN not in db.info:
        db.info[PLAN] = plan(**kwargs)


def _in_batch(endpoint: Callable[..., Any], maker: sessionmaker, db: Session, args: tuple,
              kwargs: dict[str, Any], conn: Connection) -> Any:
    """A :func:`short` writer in its batch (``db.batch``): the route on a session of the
    batch's connection, in the batch's transaction, which the batch
    commits (the session commits nothing of it, ``join_transaction_mode="rollback_only"``,
    and rolls nothing back: the batch does)."""
    joined = maker(bind=conn, join_transaction_mode="rollback_only")
    joined.info.update(db.info)  # db.info itself is kept for a run again (a batch undone)
    try:
        result = endpoint(*args, **{k: joined if v is db else v for k, v in kwargs.items()})
        joined.flush()
        return result
    finally:
        joined.close()


class Later:
    """A route's answer built after its commit, without the writers' lock (:func:`later`)."""

    def __init__(self, build: Callable[[], Any]) -> None:
        self.build = build


def later(build: Callable[[], Any]) -> Any:
    """Return this from a route to have its answer, ``build()``, built after the commit: a
    :func:`short` writer's batch holds SQLite's lock until its last writer committed.
    ``build`` must not use the database (it would begin a transaction of its own, after the
    commit and outside the writers' queue): it builds from what the route read."""
    return Later(build)


def install(app: FastAPI) -> None:
    """The writers' bulkhead of ``app`` and the row lock at BEGIN (see the module's docstring)."""
    app.state.writers = asyncio.Semaphore(writer_slots(app.state.engine.dialect.name))
    app.state.writer_queue = writer_queue(app.state.engine)
    app.state.controller_turns = weakref.WeakValueDictionary()  # PostgreSQL: see get_session
    app.state.batches = weakref.WeakKeyDictionary()  # event loop: {controller id or None: batch}
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
    :func:`one_thread` (its transaction in its one thread).

    Rather than ``app.include_router``: recent FastAPI (0.165 here) keeps an included router
    whole and matches a request through each included router in turn, a few tenths of a
    millisecond per request with fourteen routers (older FastAPI copied the routes, as this
    does). A router added here needs nothing else to get :func:`one_thread`.
    """
    for route in router.routes:
        if not isinstance(route, APIRoute):  # a websocket or a mount would skip the app's auth
            raise TypeError(f"add_routes serves HTTP routes only, got {route!r}")
        app.router.add_api_route(route.path, one_thread(route.endpoint, route),
                                 **{k: getattr(route, k) for k in ROUTE_FIELDS})
