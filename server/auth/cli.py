"""``pendant users``, ``pendant tokens`` and ``pendant roles``: administer who may change a frame.

    pendant users add NAME --role ROLE [--db URL]     (Operator, Programmer, Expert,
    pendant users list [--db URL]                      Administrator or a site role)
    pendant users revoke NAME [--db URL]
    pendant users cert NAME FILE [--days 365] [--db URL]   (an OPC UA certificate login)
    pendant users rws-password NAME [--db URL]         (the RWS face's Digest secret, as HA1)
    pendant tokens create NAME [--days 90 | --no-expiry] [--label TEXT] [--db URL]
    pendant tokens list [NAME] [--db URL]              (ids, labels, expiry; never a secret)
    pendant tokens revoke ID [--db URL]
    pendant roles add NAME PERMISSION... [--description TEXT] [--db URL]
    pendant roles list [--db URL]

They work on the database directly (whoever can run them can read the DB file anyway); each
change is audited with source ``cli`` and the operating-system user.
"""

from __future__ import annotations

import getpass
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from sqlalchemy.orm import Session

from db.crud import StateConflict
from server.auth import audit, tokens
from server.auth.certificates import certificate_der
from server.auth.permissions import PERMISSIONS


@contextmanager
def cli_session(db_url: str | None, write: bool = True,
                operation: str = "cli") -> Iterator[Session]:
    """A migrated DB session committed at the end, audited as ``cli:<os user>``.

    A ``write`` session is the write every face runs (:func:`server.service.transaction.writing`,
    ``operation`` naming its audit record when no row hook recorded the change): a writer's
    from its first statement (SQLite: ``BEGIN IMMEDIATE``, waiting up to the busy timeout for
    the service's writers; PostgreSQL: row locks): a
    transaction that read first and then upgraded to a write would lose to the service's
    writers ("database is locked", at once, in WAL mode) or queue behind them for seconds,
    and a revocation is an emergency action (issue 21). The schema step runs only when the
    schema is not the code's (under the migration lock), so a command on a current database
    takes no other lock."""
    from db.session import make_engine, make_sessionmaker, upgrade
    from server.service import transaction
    from server.settings import Settings

    settings = Settings(db_url=db_url) if db_url else Settings()
    engine = make_engine(settings.db_url)
    token = audit.CONTEXT.set(audit.AuditContext(f"cli:{getpass.getuser()}", None, "cli"))
    try:
        upgrade(engine)
        audit.install()
        maker = make_sessionmaker(engine)
        with (transaction.writing(maker, operation=operation) if write else maker()) as db:
            tokens.ensure_default_roles(db)
            yield db
            if not write:
                db.commit()  # the default roles, on a database that had none
    finally:
        audit.CONTEXT.reset(token)
        engine.dispose()


def _fail(err: Exception) -> int:
    print(f"pendant: {err}", file=sys.stderr)
    return 2


def run_users(args: Any) -> int:
    password = None
    if args.action == "rws-password":  # asked before the write begins: the service's writers
        with cli_session(args.db, write=False) as db:  # do not wait while a person types
            try:
                tokens.get_user(db, args.name)  # an unknown user before the password prompt
            except LookupError as err:
                return _fail(err)
        try:
            password = _new_password()
        except ValueError as err:
            return _fail(err)
    with cli_session(args.db, write=args.action != "list", operation="users") as db:
        try:
            if args.action == "add":
                u = tokens.add_user(db, args.name, args.role)
                print(f"user {u.name} ({u.role}) added; give them a token: "
                      f"pendant tokens create {u.name}")
            elif args.action == "revoke":
                u = tokens.revoke_user(db, args.name)
                print(f"user {u.name} revoked with every token and login")
            elif args.action == "cert":
                der = certificate_der(args.file)
                tokens.create_token(db, tokens.get_user(db, args.name), args.days,
                                    "opcua certificate", secret=tokens.certificate_secret(der))
                print(f"certificate {args.file.name} logs {args.name} in over OPC UA "
                      f"(valid {args.days:g} days; pendant users revoke ends it)")
            elif args.action == "rws-password":
                from server.rws import digest, ops

                tokens.get_user(db, args.name)  # revoked or removed since the prompt
                ops.set_rws_ha1(db, args.name, digest.ha1(args.name, str(password)))
                print(f"{args.name} logs in to the RWS face with that password (stored as "
                      "its Digest HA1)")
            else:
                print(f"{'id':>4}  {'name':24s} {'role':16s} {'created (UTC)':20s} revoked")
                for u in tokens.list_users(db):
                    revoked = u.revoked_at.strftime("%Y-%m-%d %H:%M") if u.revoked_at else ""
                    print(f"{u.id:4d}  {u.name:24s} {u.role:16s} "
                          f"{u.created_at.strftime('%Y-%m-%d %H:%M'):20s} {revoked}")
        except (ValueError, StateConflict, OSError) as err:
            return _fail(err)
    return 0


def _new_password() -> str:
    """The new RWS password: asked twice on a terminal, else the first line of stdin."""
    if sys.stdin.isatty():
        first = getpass.getpass("RWS password: ")
        if first != getpass.getpass("again: "):
            raise ValueError("password: the two entries differ")
    else:
        first = sys.stdin.readline().rstrip("\r\n")
    if len(first) < 8:
        raise ValueError("password: at least 8 characters")
    return first


def run_tokens(args: Any) -> int:
    if args.action in ("list", "revoke"):
        return run_token_admin(args)
    with cli_session(args.db, operation="tokens") as db:
        try:
            days = None if args.no_expiry else args.days
            secret = tokens.create_token(db, tokens.get_user(db, args.name), days, args.label)
        except (ValueError, StateConflict) as err:
            return _fail(err)
    until = "no expiry" if days is None else f"valid {days:g} days"
    print(f"token for {args.name} ({until}; shown once, only its hash is stored):", file=sys.stderr)
    print(secret)
    return 0


def run_token_admin(args: Any) -> int:
    with cli_session(args.db, write=args.action == "revoke", operation="tokens") as db:
        if args.action == "revoke":
            t = tokens.revoke_token(db, args.token_id)
            print(f"token {t.id} revoked")
            return 0
        user = tokens.get_user(db, args.name) if args.name else None
        names = {u.id: u.name for u in tokens.list_users(db)}
        print(f"{'id':>4}  {'user':24s} {'label':16s} {'expires (UTC)':18s} revoked")
        for t in tokens.list_tokens(db, user):
            exp = t.expires_at.strftime("%Y-%m-%d %H:%M") if t.expires_at else "never"
            rev = t.revoked_at.strftime("%Y-%m-%d %H:%M") if t.revoked_at else ""
            print(f"{t.id:4d}  {names.get(t.user_id, '?'):24s} {t.label:16s} {exp:18s} {rev}")
    return 0


def run_roles(args: Any) -> int:
    with cli_session(args.db, write=args.action == "add", operation="roles") as db:
        try:
            if args.action == "add":
                r = tokens.add_role(db, args.name, args.permissions, args.description)
                print(f"role {r.name}: {', '.join(r.permissions)}")
            else:
                for r in tokens.list_roles(db):
                    print(f"{r.name:16s} {', '.join(r.permissions)}")
        except (ValueError, StateConflict) as err:
            return _fail(err)
    return 0


def add_auth_commands(subparsers: Any) -> None:
    """Register ``users``, ``tokens`` and ``roles`` on the ``pendant`` command's subparsers."""
    u = subparsers.add_parser("users", help="add, list or revoke users (docs/security.md)")
    us = u.add_subparsers(dest="action", required=True)
    a = us.add_parser("add", help="add a user with a role")
    a.add_argument("name")
    a.add_argument("--role", required=True,
                   help="Operator, Programmer, Expert, Administrator or a site role")
    us.add_parser("list", help="every user with role and revocation")
    r = us.add_parser("revoke", help="revoke a user with every token and login")
    r.add_argument("name")
    ce = us.add_parser("cert", help="let a user log in to the OPC UA face with a certificate")
    ce.add_argument("name")
    ce.add_argument("file", type=Path, help="the client's X.509 certificate (PEM or DER)")
    ce.add_argument("--days", type=float, default=365.0, help="how long it logs in (365)")
    rp = us.add_parser("rws-password", help="set a user's password for the RWS face (HTTP "
                       "Digest; read from stdin or asked twice; docs/rws.md)")
    rp.add_argument("name")
    for p in (a, us.choices["list"], r, ce, rp):
        p.add_argument("--db", help="database URL")
        p.set_defaults(func=run_users)

    t = subparsers.add_parser("tokens", help="create an API token for a user")
    ts = t.add_subparsers(dest="action", required=True)
    c = ts.add_parser("create", help="a new bearer token (printed once)")
    c.add_argument("name", help="the user")
    c.add_argument("--days", type=float, default=90.0, help="lifetime in days (90)")
    c.add_argument("--no-expiry", action="store_true", help="a token that does not expire")
    c.add_argument("--label", default="", help="what the token is for (cell PC, CI, ...)")
    tl = ts.add_parser("list", help="every token (id, user, label, expiry), never a secret")
    tl.add_argument("name", nargs="?", help="only this user's tokens")
    tr = ts.add_parser("revoke", help="revoke one token by its id (pendant tokens list)")
    tr.add_argument("token_id", type=int)
    for p in (c, tl, tr):
        p.add_argument("--db", help="database URL")
        p.set_defaults(func=run_tokens)

    ro = subparsers.add_parser("roles", help="list the roles or add a site role")
    rs = ro.add_subparsers(dest="action", required=True)
    ra = rs.add_parser("add", help="a site role: a name and its permissions")
    ra.add_argument("name")
    ra.add_argument("permissions", nargs="+", choices=PERMISSIONS, metavar="PERMISSION",
                    help=", ".join(PERMISSIONS))
    ra.add_argument("--description", default="")
    rl = rs.add_parser("list", help="every role with its permissions")
    for p in (ra, rl):
        p.add_argument("--db", help="database URL")
        p.set_defaults(func=run_roles)
