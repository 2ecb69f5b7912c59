"""``pendant opcua``: the OPC UA server as a process of its own, on the service's database.

    pendant opcua [--host 127.0.0.1] [--port 4840] [--db URL]

``pendant serve --opcua-port 4840`` starts the same process beside the REST service.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import subprocess
import sys
from pathlib import Path


def add_opcua_commands(sub: argparse._SubParsersAction) -> None:
    o = sub.add_parser("opcua", help="serve the OPC UA face (Robotics companion specification) "
                                     "on the service's database")
    add_opcua_arguments(o)
    o.add_argument("--db", help="database URL (default: PENDANT_DB_URL, else the SQLite file in "
                                "the user data dir)")
    o.add_argument("--exit-with-parent", action="store_true", help=argparse.SUPPRESS)
    o.add_argument("--pki", type=Path, help="folder of the server's certificate and key (made on "
                                            "first start; default: opcua-pki in the user data "
                                            "dir)")
    o.set_defaults(func=run_opcua)


def add_opcua_arguments(o: argparse.ArgumentParser) -> None:
    o.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    o.add_argument("--port", type=int, default=4840, help="OPC UA port (default 4840)")


def run_opcua(args: argparse.Namespace) -> int:
    from server.app import create_app
    from server.opcua.service import run
    from server.settings import parent_pid
    from server.settings import Settings

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    app = create_app(Settings(db_url=args.db) if args.db else Settings())
    try:
        asyncio.run(run(app.state.sessionmaker, args.host, args.port, app.state.settings.auth,
                        args.pki or default_pki_dir(),
                        parent_pid() if args.exit_with_parent else None))
    except KeyboardInterrupt:
        pass
    return 0


def default_pki_dir() -> Path:
    import platformdirs

    return Path(platformdirs.user_data_dir("pendant")) / "opcua-pki"


def start_beside(host: str, port: int, db_url: str | None, auth: bool = True) -> subprocess.Popen:
    """``pendant serve --opcua-port``: the OPC UA face as a child process on the same DB (and,
    with ``serve --no-auth``, as open as the REST service)."""
    import os

    from server.settings import ENV_NO_AUTH, ENV_PARENT_PID

    cmd = [sys.executable, "-m", "server.cli", "opcua", "--host", host, "--port", str(port),
           "--exit-with-parent"]
    if db_url:
        cmd += ["--db", db_url]
    # a session of its own: a terminal's Ctrl-C reaches serve alone, which stops its children
    return subprocess.Popen(cmd, env={**os.environ, ENV_NO_AUTH: "0" if auth else "1",
                                      ENV_PARENT_PID: str(os.getpid())},
                            start_new_session=True)
