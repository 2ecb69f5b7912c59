"""The FastAPI application: routers per menu, error handlers, the DB, the pendant page.

``create_app(settings)`` checks the DB's schema: an old one is migrated (Alembic ``upgrade
head``) under a database-wide lock when ``settings.migrate`` (the default, so the README's
``pendant serve`` works on a fresh machine), else refused naming ``pendant db upgrade``. It
creates the demo controller "cell-1" (KUKA KR 6 R900 sixx) in an empty DB and serves ``web/``
at ``/``. ``uvicorn server.api.app:app`` uses the default settings (``PENDANT_DB_URL`` or the user
data dir); ``pendant serve --workers N`` starts N such processes on one database.
"""

from __future__ import annotations

import gc
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import Depends, FastAPI
from fastapi.responses import FileResponse, HTMLResponse
from fastapi_offline import FastAPIOffline
from starlette.exceptions import HTTPException as StarletteHTTPException

from db import crud
from db.session import (current_revision, make_engine, make_sessionmaker, migration_lock,
                        open_pool, schema_status, upgrade, write_session)
from emulator import DEMO_ROBOT, home_joints
from server import __version__
from server.api import deps
from server.api import errors
from server.service import external
from server.api import idempotency
from server.auth import audit, guard, openapi, tokens
from server.auth import routes as auth_routes
from server.auth.web import SiteGuard
from server.events.dispatcher import Dispatcher, WebhookSink
from server.events.mqtt import MqttSink
from server.api.limits import BodyLimits
from server.api.routers import (analysis, base, controllers, export, fixed_tool, jobs, robot, sessions,
                            tool, webhooks, workpiece)
from server.api.routers import external as external_router
from server.api.routers import plan as plan_router
from server.settings import Settings
from solvers.robots import ROBOTS

TAGS = [
    {"name": "Controllers", "description": "The emulated controllers (cells)."},
    {"name": "Robot", "description": "Joints, jogging, active tool/base, approach (careful "
                                     "jogging done for you)."},
    {"name": "Tool", "description": "The 16 tool slots (TOOL_DATA): robot-held tools and "
                                    "workpieces."},
    {"name": "Base", "description": "The 32 base slots (BASE_DATA): bases and fixed tools."},
    {"name": "Fixed tool", "description": "External TCPs (base slots of type fixed_tool)."},
    {"name": "Workpiece", "description": "Robot-held workpieces (tool slots of type workpiece)."},
    {"name": "Sessions", "description": "Calibration menus: open, touch up, compute, save, "
                                        "discard."},
    {"name": "External kinematics", "description": "Turntables, positioners and rails "
                                                   "(EX_KIN 1..6): machine data, history, "
                                                   "the emulated external axes."},
    {"name": "Export", "description": "Controller files (KUKA, ABB, FANUC, UR) and JSON "
                                      "backup/restore."},
    {"name": "Jobs", "description": "Analyses and restores run by the worker processes: state, "
                                    "progress, cancel, result."},
    {"name": "Auth", "description": "Log in, users, API tokens, roles and the audit trail "
                                    "(docs/security.md)."},
    {"name": "Events", "description": "Webhooks for MES: frame committed, calibration computed, "
                                      "import applied, analysis finished (signed, retried)."},
]

WEB_SUFFIXES = (".html", ".js", ".css", ".json", ".png", ".svg")  # what web/ serves

PLACEHOLDER = """<!doctype html><html><head><meta charset="utf-8"><title>pendant</title></head>
<body><h1>pendant</h1><p>The pendant page (web/index.html) is not installed. The REST API is
at <a href="/docs">/docs</a>.</p></body></html>"""


def freeze_garbage() -> None:
    """Move every object made so far into the garbage collector's permanent generation.

    A full collection of Python's cyclic garbage collector walks every object of the process:
    the app, SQLAlchemy, pydantic, NumPy and SciPy make that 80-170 ms, during which the worker
    answers nothing (it was the p99 of touch-ups: ``benchmarks/README.md``). Frozen
    (``gc.freeze``), a collection walks only what was made since. For a service process once
    it has started (``app.state.service_process``), not for the many apps of a test run: what they
    leave behind would never be collected."""
    gc.collect()
    gc.freeze()


class SchemaOutOfDate(RuntimeError):
    """The DB's schema is not the code's and ``serve`` was told not to migrate."""


def ensure_demo(app: FastAPI) -> None:
    """An empty DB gets the demo controller "cell-1" so the pendant page has something to show
    (under the schema lock: N workers starting on a fresh DB create it once)."""
    with migration_lock(app.state.engine), write_session(app.state.sessionmaker) as db:
        if not crud.list_controllers(db):
            joints = home_joints(ROBOTS[DEMO_ROBOT])
            c = crud.create_controller(db, "cell-1", DEMO_ROBOT, None, 1, joints)
            external.enable(db, c, ROBOTS[DEMO_ROBOT].reach_mm)  # E1..E4 (docs/emulator.md)
        db.commit()


def check_schema(engine, migrate: bool) -> None:  # noqa: ANN001
    """Migrate an old schema under the lock, or refuse naming the command (``migrate=False``)."""
    if migrate:
        upgrade(engine)
        return
    current, head = schema_status(engine)
    if current != head:
        raise SchemaOutOfDate(f"the database is at schema {current or 'empty'}, this pendant "
                              f"needs {head}: run `pendant db upgrade` first")


def bootstrap(app: FastAPI) -> None:
    """First start: an Administrator and its token (``app.state.first_token`` if one was made);
    under the schema lock, so N workers starting on a fresh DB make one Administrator."""
    with migration_lock(app.state.engine), write_session(app.state.sessionmaker) as db:
        made = tokens.bootstrap_admin(db, app.state.settings.bootstrap_token)
        db.commit()
    app.state.first_token = made if made and not app.state.settings.bootstrap_token else None


def event_dispatcher(app: FastAPI) -> Dispatcher:
    """The webhook (and, when configured, MQTT) dispatcher of this process (docs/events.md)."""
    s: Settings = app.state.settings
    sinks: dict = {"webhook": WebhookSink()}
    if s.mqtt_url:
        sinks["mqtt"] = MqttSink(s.mqtt_url, s.uns_site, s.uns_area)
    return Dispatcher(app.state.sessionmaker, sinks, backoff_s=s.events_backoff_s)


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Deliver events while the service runs; close the DB pool at the end. A service process
    (``app.state.service_process``) starts with its database connections open
    (:func:`db.session.open_pool`) and :func:`freeze_garbage`."""
    if getattr(app.state, "service_process", False):
        open_pool(app.state.engine)
        freeze_garbage()
    dispatcher = event_dispatcher(app) if app.state.settings.dispatch_events else None
    if dispatcher is not None:
        dispatcher.start()
    app.state.dispatcher = dispatcher
    try:
        yield
    finally:
        if dispatcher is not None:
            dispatcher.stop()
        app.state.engine.dispose()  # close the pooled connections (a PostgreSQL server counts them)


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
    # FastAPIOffline: FastAPI whose /docs and /redoc load Swagger UI and ReDoc from the
    # fastapi-offline package, not a CDN (robot cells are often offline)
    app = FastAPIOffline(title="pendant", version=__version__, openapi_tags=TAGS,
                         lifespan=lifespan,
                         dependencies=[Depends(guard.authorize)],
                         description="A controller-side teach-pendant emulator: tool, base, "
                                     "fixed-tool and workpiece calibration menus as a REST "
                                     "service.")
    audit.install()
    tokens.install_cache_hook()  # a revocation flushed here empties the token cache
    engine = make_engine(settings.db_url)
    check_schema(engine, settings.migrate)
    app.state.engine = engine
    app.state.sessionmaker = make_sessionmaker(engine)
    app.state.sessionmaker.configure(info={"mqtt_sink": bool(settings.mqtt_url)})  # db.outbox
    app.state.settings = settings
    deps.install(app)
    errors.install(app)
    idempotency.install(app)
    _install_health(app)
    app.add_middleware(BodyLimits)
    for module in (controllers, robot, tool, base, fixed_tool, workpiece, sessions, export,
                   analysis, jobs, auth_routes, webhooks, plan_router, external_router):
        deps.add_routes(app, module.router)  # flat, each transaction in its route's thread
    bootstrap(app)
    if settings.cors_origins:
        from starlette.middleware.cors import CORSMiddleware

        app.add_middleware(CORSMiddleware, allow_origins=list(settings.cors_origins),
                           allow_methods=["*"], allow_headers=["authorization", "content-type",
                                                               "x-csrf-token", "if-match",
                                                               "idempotency-key"])
    app.add_middleware(SiteGuard, allowed_hosts=settings.allowed_hosts,
                       cors_origins=settings.cors_origins)
    if settings.demo_controller:
        ensure_demo(app)
    _mount_web(app, Path(settings.web_dir))
    openapi.install(app)  # bearer and cookie + CSRF in /docs (server.auth.openapi)
    return app


def _install_health(app: FastAPI) -> None:
    @app.get("/healthz", tags=["Controllers"], summary="Liveness and readiness: the DB answers")
    def healthz() -> dict[str, str]:
        """``{"status": "ok", "schema": <revision>}`` when the database answers (load
        balancers and compose health checks poll this)."""
        return {"status": "ok", "schema": current_revision(app.state.engine) or ""}


def _mount_web(app: FastAPI, web: Path) -> None:
    """``/`` is the pendant page, ``/{file}`` the page's files (GET and HEAD only).

    Files are routes rather than a mount at ``/``: a mount would answer every path and
    method, so a wrong method on an API path would get the mount's 405 (without ``Allow``)
    instead of the API route's.
    """
    index = web / "index.html"
    root = web.resolve()
    revalidate = {"Cache-Control": "no-cache"}  # no user data; else SiteGuard says no-store

    @app.get("/", include_in_schema=False, response_model=None)
    def pendant_page() -> FileResponse | HTMLResponse:
        return (FileResponse(index, headers=revalidate) if index.is_file()
                else HTMLResponse(PLACEHOLDER, headers=revalidate))

    @app.api_route("/{name}", methods=["GET", "HEAD"], include_in_schema=False)
    def web_file(name: str) -> FileResponse:
        if "\0" in name or not name.isprintable():  # "/index.html%00.js": no such file
            raise StarletteHTTPException(status_code=404)
        path = (root / name).resolve()
        if path.parent != root or path.suffix not in WEB_SUFFIXES or not path.is_file():
            raise StarletteHTTPException(status_code=404)
        return FileResponse(path, headers=revalidate)


def __getattr__(name: str) -> FastAPI:
    """``server.api.app:app`` for ``uvicorn server.api.app:app``: built on first access."""
    if name == "app":
        global app
        app = create_app()
        app.state.service_process = True  # a service process (uvicorn's worker)
        return app
    raise AttributeError(name)
