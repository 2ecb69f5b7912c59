"""The FastAPI application: routers per menu, error handlers, the DB, the pendant page.

``create_app(settings)`` migrates the DB (Alembic ``upgrade head``), creates the demo
controller "cell-1" (KUKA KR 6 R900 sixx) in an empty DB and serves ``web/`` at ``/``.
``uvicorn server.app:app`` uses the default settings (``PENDANT_DB_URL`` or the user data dir).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from db import crud
from db.session import make_engine, make_sessionmaker, run_migrations
from server import errors
from server.emulator import DEMO_ROBOT, home_joints
from server.events.dispatcher import Dispatcher, WebhookSink
from server.events.mqtt import MqttSink
from server.routers import (analysis, base, controllers, export, fixed_tool, robot, sessions, tool,
                            webhooks, workpiece)
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
    {"name": "Events", "description": "Webhooks for MES: frame committed, calibration computed, "
                                      "import applied, analysis finished (signed, retried)."},
]

PLACEHOLDER = """<!doctype html><html><head><meta charset="utf-8"><title>pendant</title></head>
<body><h1>pendant</h1><p>The pendant page (web/index.html) is not installed. The REST API is
at <a href="/docs">/docs</a>.</p></body></html>"""


def ensure_demo(app: FastAPI) -> None:
    """An empty DB gets the demo controller "cell-1" so the pendant page has something to show."""
    with app.state.sessionmaker() as db:
        if not crud.list_controllers(db):
            joints = home_joints(ROBOTS[DEMO_ROBOT])
            crud.create_controller(db, "cell-1", DEMO_ROBOT, None, 1, joints)
            db.commit()


def event_dispatcher(app: FastAPI) -> Dispatcher:
    """The webhook (and, when configured, MQTT) dispatcher of this process (docs/events.md)."""
    s: Settings = app.state.settings
    sinks: dict = {"webhook": WebhookSink()}
    if s.mqtt_url:
        sinks["mqtt"] = MqttSink(s.mqtt_url, s.uns_site, s.uns_area)
    return Dispatcher(app.state.sessionmaker, sinks, backoff_s=s.events_backoff_s)


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Deliver events while the service runs."""
    dispatcher = event_dispatcher(app) if app.state.settings.dispatch_events else None
    if dispatcher is not None:
        dispatcher.start()
    app.state.dispatcher = dispatcher
    try:
        yield
    finally:
        if dispatcher is not None:
            dispatcher.stop()


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
    app = FastAPI(title="pendant", version="0.1.0", openapi_tags=TAGS, lifespan=lifespan,
                  description="A controller-side teach-pendant emulator: tool, base, "
                              "fixed-tool and workpiece calibration menus as a REST service.")
    engine = make_engine(settings.db_url)
    run_migrations(engine)
    app.state.engine = engine
    app.state.sessionmaker = make_sessionmaker(engine)
    app.state.sessionmaker.configure(info={"mqtt_sink": bool(settings.mqtt_url)})  # db.outbox
    app.state.write_lock = asyncio.Lock()  # one writer at a time (SQLite); see deps.get_session
    app.state.settings = settings
    errors.install(app)
    for module in (controllers, robot, tool, base, fixed_tool, workpiece, sessions, export,
                   analysis, webhooks):
        app.include_router(module.router)
    if settings.demo_controller:
        ensure_demo(app)
    _mount_web(app, Path(settings.web_dir))
    return app


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
