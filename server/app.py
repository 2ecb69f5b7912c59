"""The FastAPI application: routers per menu, error handlers, the DB, the pendant page.

``create_app(settings)`` checks the DB's schema: an old one is migrated (Alembic ``upgrade
head``) under a database-wide lock when ``settings.migrate`` (the default, so the README's
``pendant serve`` works on a fresh machine), else refused naming ``pendant db upgrade``. It
creates the demo controller "cell-1" (KUKA KR 6 R900 sixx) in an empty DB and serves ``web/``
at ``/``. ``uvicorn server.app:app`` uses the default settings (``PENDANT_DB_URL`` or the user
data dir); ``pendant serve --workers N`` starts N such processes on one database.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from db import crud
from db.session import (current_revision, make_engine, make_sessionmaker, migration_lock,
                        schema_status, upgrade, write_session)
from server import deps, errors, idempotency
from emulator import DEMO_ROBOT, home_joints
from server.routers import (analysis, base, controllers, export, fixed_tool, robot, sessions, tool,
                            workpiece)
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
    {"name": "Export", "description": "Controller files (KUKA, ABB, FANUC, UR) and JSON "
                                      "backup/restore."},
]

PLACEHOLDER = """<!doctype html><html><head><meta charset="utf-8"><title>pendant</title></head>
<body><h1>pendant</h1><p>The pendant page (web/index.html) is not installed. The REST API is
at <a href="/docs">/docs</a>.</p></body></html>"""


class SchemaOutOfDate(RuntimeError):
    """The DB's schema is not the code's and ``serve`` was told not to migrate."""


def ensure_demo(app: FastAPI) -> None:
    """An empty DB gets the demo controller "cell-1" so the pendant page has something to show
    (under the schema lock: N workers starting on a fresh DB create it once)."""
    with migration_lock(app.state.engine), write_session(app.state.sessionmaker) as db:
        if not crud.list_controllers(db):
            joints = home_joints(ROBOTS[DEMO_ROBOT])
            crud.create_controller(db, "cell-1", DEMO_ROBOT, None, 1, joints)
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


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    yield
    app.state.engine.dispose()  # close the pooled connections (a PostgreSQL server counts them)


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
    app = FastAPI(title="pendant", version="0.1.0", openapi_tags=TAGS, lifespan=_lifespan,
                  description="A controller-side teach-pendant emulator: tool, base, "
                              "fixed-tool and workpiece calibration menus as a REST service.")
    engine = make_engine(settings.db_url)
    check_schema(engine, settings.migrate)
    app.state.engine = engine
    app.state.sessionmaker = make_sessionmaker(engine)
    app.state.settings = settings
    deps.install(app)
    errors.install(app)
    idempotency.install(app)
    _install_health(app)
    for module in (controllers, robot, tool, base, fixed_tool, workpiece, sessions, export,
                   analysis):
        app.include_router(module.router)
    if settings.demo_controller:
        ensure_demo(app)
    _mount_web(app, Path(settings.web_dir))
    return app


def _install_health(app: FastAPI) -> None:
    @app.get("/healthz", tags=["Controllers"], summary="Liveness and readiness: the DB answers")
    def healthz() -> dict[str, str]:
        """``{"status": "ok", "schema": <revision>}`` when the database answers (load
        balancers and compose health checks poll this)."""
        return {"status": "ok", "schema": current_revision(app.state.engine) or ""}


def _mount_web(app: FastAPI, web: Path) -> None:
    index = web / "index.html"

    @app.get("/", include_in_schema=False, response_model=None)
    def pendant_page() -> FileResponse | HTMLResponse:
        return FileResponse(index) if index.is_file() else HTMLResponse(PLACEHOLDER)

    if web.is_dir():  # pendant.js, pendant.css next to index.html; API routes match first
        app.mount("/", StaticFiles(directory=web), name="web")


def __getattr__(name: str) -> FastAPI:
    """``server.app:app`` for ``uvicorn server.app:app``: built on first access."""
    if name == "app":
        global app
        app = create_app()
        return app
    raise AttributeError(name)
