"""Request dependencies: one database session and one transaction per request.

A request that writes is one transaction, committed before the answer is sent (a client that
got a 2xx finds its change in the database), and atomic whichever process or host serves it.
It is a write as every face runs one (:mod:`server.service.transaction`): a writer's session
(SQLite ``BEGIN IMMEDIATE``; on PostgreSQL the controller of the path locked at ``BEGIN``), this
process's turn on SQLite, and the operation's audit record (the route's name) at the commit.

The transaction runs in the route's worker thread, never on the event loop: a sync route
taking a session (``SessionDep``) is wrapped by :func:`one_thread`, which takes the turn and
commits (or rolls back) in that thread as the route returns, so the write lock is held only
while the route works. An async route, or an Idempotency-Key claimed before the route, commits
in :func:`get_session` (in the threadpool too).

The load this serves: a plant of a few hundred cells, a person touching up every few seconds,
~100 writes/s at worst plus MES reads (``benchmarks/plant.py``, README "Measured").
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import AsyncIterator, Callable
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Request
from fastapi.routing import APIRoute
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from server.api import idempotency
from server.service import transaction

READ_METHODS = ("GET", "HEAD", "OPTIONS")


def _controller_id(request: Request) -> int | None:
    cid = request.path_params.get("controller_id")
    try:
        return None if cid is None else int(cid)
    except ValueError:
        return None  # not an int: the route's own validation answers 422


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
    db = transaction.writer(maker, _controller_id(request)) if writes else maker()
    try:
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
    """The write's commit (:func:`server.service.transaction.commit`), its audit record naming
    the path's controller and session."""
    ids = {k: int(v) for k in AUDIT_KEYS
           if (v := params.get(k)) is not None and str(v).isdigit()}
    transaction.commit(db, operation, **ids)


def one_thread(endpoint: Callable[..., Any]) -> Callable[..., Any]:
    """``endpoint`` (a sync route) committing the session it was given in its own worker
    thread as it returns (rolled back if it raises). Async routes are returned unchanged.
    A writing route on SQLite runs in its process's turn
    (:func:`server.service.transaction.sqlite_turn`)."""
    if inspect.iscoroutinefunction(endpoint) or getattr(endpoint, "_one_thread", False):
        return endpoint

    @functools.wraps(endpoint)
    def run(*args: Any, **kwargs: Any) -> Any:
        db = next((v for v in kwargs.values() if isinstance(v, Session)), None)
        if db is None:
            return endpoint(*args, **kwargs)
        with transaction.sqlite_turn(db):
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
        app.router.add_api_route(route.path, one_thread(route.endpoint),
                                 **{k: getattr(route, k) for k in ROUTE_FIELDS})
