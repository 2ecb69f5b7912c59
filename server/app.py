"""The FastAPI application: routers per menu, error handlers, the DB, the pendant page.

``create_app(settings)`` migrates the DB (Alembic ``upgrade head``), creates the demo
controller "cell-1" (KUKA KR 6 R900 sixx) in an empty DB and serves ``web/`` at ``/``.
``uvicorn server.app:app`` uses the default settings (``PENDANT_DB_URL`` or the user data dir).
"""

from __future__ import annotations

import asyncio
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse, HTMLResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from db import crud
from db.session import make_engine, make_sessionmaker, run_migrations
from server import errors
from server.emulator import DEMO_ROBOT, home_joints
from server.limits import BodyLimits
from server.routers import (analysis, base, controllers, export, fixed_tool, jobs, robot, sessions,
                            tool, workpiece)
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
    {"name": "Jobs", "description": "Analyses and restores run by the worker processes: state, "
                                    "progress, cancel, result."},
]

WEB_SUFFIXES = (".html", ".js", ".css", ".json", ".png", ".svg")  # what web/ serves

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


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
    app = FastAPI(title="pendant", version="0.1.0", openapi_tags=TAGS,
                  description="A controller-side teach-pendant emulator: tool, base, "
                              "fixed-tool and workpiece calibration menus as a REST service.")
    engine = make_engine(settings.db_url)
    run_migrations(engine)
    app.state.engine = engine
    app.state.sessionmaker = make_sessionmaker(engine)
    app.state.write_lock = asyncio.Lock()  # one writer at a time (SQLite); see deps.get_session
    app.state.settings = settings
    errors.install(app)
    app.add_middleware(BodyLimits)
    for module in (controllers, robot, tool, base, fixed_tool, workpiece, sessions, export,
                   analysis, jobs):
        app.include_router(module.router)
    if settings.demo_controller:
        ensure_demo(app)
    _mount_web(app, Path(settings.web_dir))
    return app


def _mount_web(app: FastAPI, web: Path) -> None:
    """``/`` is the pendant page, ``/{file}`` the page's files (GET and HEAD only).

    Files are routes rather than a mount at ``/``: a mount would answer every path and
    method, so a wrong method on an API path would get the mount's 405 (without ``Allow``)
    instead of the API route's.
    """
    index = web / "index.html"
    root = web.resolve()

    @app.get("/", include_in_schema=False, response_model=None)
    def pendant_page() -> FileResponse | HTMLResponse:
        return FileResponse(index) if index.is_file() else HTMLResponse(PLACEHOLDER)

    @app.api_route("/{name}", methods=["GET", "HEAD"], include_in_schema=False)
    def web_file(name: str) -> FileResponse:
        path = (root / name).resolve()
        if path.parent != root or path.suffix not in WEB_SUFFIXES or not path.is_file():
            raise StarletteHTTPException(status_code=404)
        return FileResponse(path)


def __getattr__(name: str) -> FastAPI:
    """``server.app:app`` for ``uvicorn server.app:app``: built on first access."""
    if name == "app":
        global app
        app = create_app()
        return app
    raise AttributeError(name)
