"""``pendant opcua``: the OPC UA server as a process of its own, on the service's database.

    pendant opcua [--host 127.0.0.1] [--port 4840] [--db URL] [--pki DIR] [--none-endpoint]
    pendant opcua trust CERT [--db URL | --pki DIR]

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
                                     "on the service's database; `pendant opcua trust CERT` "
                                     "adds a client certificate to its trust list")
    add_opcua_arguments(o)
    o.add_argument("--db", help="database URL (default: PENDANT_DB_URL, else the SQLite file in "
                                "the user data dir)")
    o.add_argument("--exit-with-parent", action="store_true", help=argparse.SUPPRESS)
    _pki_argument(o)
    o.add_argument("--none-endpoint", action="store_true",
                   help="also serve a SecurityPolicy None endpoint (Anonymous only: with a "
                        "login required it can only discover; for the --no-auth demo)")
    o.set_defaults(func=run_opcua)
    osub = o.add_subparsers(dest="opcua_command")
    t = osub.add_parser("trust", help="trust a client application certificate (DER or PEM; a "
                                      "refused one is kept in PKI/rejected)")
    t.add_argument("cert", type=Path, metavar="CERT")
    t.add_argument("--db", help="the database whose face it is (picks the default PKI folder)")
    _pki_argument(t)
    t.set_defaults(func=trust_certificate)


def _pki_argument(o: argparse.ArgumentParser) -> None:
    o.add_argument("--pki", type=Path, help="the face's PKI folder: its certificate and key, "
                                            "trusted/ and rejected/ client certificates "
                                            "(default: <db file>-opcua-pki beside a SQLite "
                                            "file, else one per database in the user data dir)")


def add_opcua_arguments(o: argparse.ArgumentParser) -> None:
    o.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    o.add_argument("--port", type=int, default=4840, help="OPC UA port (default 4840)")


def _pki_dir(args: argparse.Namespace) -> Path:
    from server.opcua.pki import default_pki_dir
    from server.settings import Settings

    if args.pki is not None:
        return args.pki
    return default_pki_dir((Settings(db_url=args.db) if args.db else Settings()).db_url)


def trust_certificate(args: argparse.Namespace) -> int:
    from server.opcua.pki import PkiError, trust

    pki = _pki_dir(args)
    try:
        path = trust(pki, args.cert)
    except PkiError as err:
        print(f"pendant: opcua trust: CERT: {err}", file=sys.stderr)
        return 2
    print(f"trusted: {path}")
    return 0


def run_opcua(args: argparse.Namespace) -> int:
    from server.api.app import create_app
    from server.opcua.service import run
    from server.settings import ENV_NO_AUTH, LOOPBACK_HOSTS, Settings, parent_pid

    settings = Settings(db_url=args.db) if args.db else Settings()
    if not settings.auth and args.host not in LOOPBACK_HOSTS:
        print(f"pendant: --host: no-auth ({ENV_NO_AUTH}=1) serves loopback only "
              f"(127.0.0.1, localhost, ::1), not {args.host}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    app = create_app(settings)
    try:
        asyncio.run(run(app.state.sessionmaker, args.host, args.port, app.state.settings.auth,
                        _pki_dir(args), parent_pid() if args.exit_with_parent else None,
                        none_endpoint=args.none_endpoint))
    except KeyboardInterrupt:
        pass
    return 0


def start_beside(host: str, port: int, db_url: str | None, auth: bool = True,
                 pki: Path | None = None) -> subprocess.Popen:
    """``pendant serve --opcua-port [--opcua-pki DIR]``: the OPC UA face as a child process on
    the same DB (and, with ``serve --no-auth``, as open as the REST service)."""

    from server.settings import ENV_NO_AUTH, ENV_PARENT_PID

    cmd = [sys.executable, "-m", "server.cli", "opcua", "--host", host, "--port", str(port),
           "--exit-with-parent"]
    if db_url:
        cmd += ["--db", db_url]
    if pki is not None:
        cmd += ["--pki", str(pki)]
    # a session of its own: a terminal's Ctrl-C reaches serve alone, which stops its children
    return subprocess.Popen(cmd, env={**os.environ, ENV_NO_AUTH: "0" if auth else "1",
                                      ENV_PARENT_PID: str(os.getpid())},
                            start_new_session=True)
