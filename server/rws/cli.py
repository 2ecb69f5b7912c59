"""``pendant serve``'s controller faces: ``--rws-port`` (docs/rws.md), ``--kvp-port`` (docs/kvp.md).

Each runs in a thread of the serve process, on the service's own database and operations.
"""

from __future__ import annotations

import argparse
import ipaddress
from typing import Any

from solvers.errors import CalibrationError


def add_face_arguments(s: argparse.ArgumentParser) -> None:
    s.add_argument("--rws-port", type=int, metavar="PORT",
                   help="also serve ABB Robot Web Services for one ABB controller (HTTP "
                        "Digest; pendant users rws-password NAME; docs/rws.md)")
    s.add_argument("--rws-controller", metavar="NAME",
                   help="the controller RWS serves (default: the first ABB controller)")
    s.add_argument("--kvp-port", type=int, metavar="PORT",
                   help="also serve KUKAVARPROXY's protocol for one KUKA controller (no login: "
                        "acts as --kvp-user; docs/kvp.md)")
    s.add_argument("--kvp-user", metavar="NAME",
                   help="the pendant user the KVP face acts as (its role decides writes)")
    s.add_argument("--kvp-controller", metavar="NAME",
                   help="the controller KVP serves (default: the first KUKA controller)")
    s.add_argument("--kvp-host", default="127.0.0.1", metavar="ADDR",
                   help="address the KVP face listens on (default 127.0.0.1)")
    s.add_argument("--kvp-allow", action="append", default=[], metavar="ADDR",
                   help="a client address KVP serves besides loopback (repeat)")


def start_faces(args: argparse.Namespace, maker: Any, auth: bool,
                allowed_hosts: tuple[str, ...] = ("*",)) -> list[Any]:
    """Start the faces asked for; each a :class:`server.rws.service.Running`. RWS answers
    the ``Host`` names REST answers (``allowed_hosts``)."""
    started: list[Any] = []
    try:
        if args.rws_port:
            from server.rws.app import RwsFace, create_rws_app
            from server.rws.service import serve_asgi

            started.append(serve_asgi(create_rws_app(RwsFace(maker, args.rws_controller, auth),
                                                     allowed_hosts),
                                      args.host, args.rws_port, "rws"))
        if args.kvp_port:
            from server.kvp.server import KvpFace, serve_in_thread

            if auth and not args.kvp_user:
                raise CalibrationError(("--kvp-user",), "the KVP protocol has no login: name "
                                       "the pendant user it acts as")
            for a in args.kvp_allow:
                try:
                    ipaddress.ip_address(a)
                except ValueError:
                    raise CalibrationError(("--kvp-allow",), f"{a!r} is not an IP address") \
                        from None
            loopback = args.kvp_host in ("127.0.0.1", "::1", "localhost")
            if not loopback and not args.kvp_allow:
                raise CalibrationError(("--kvp-host",), f"{args.kvp_host} is not loopback: "
                                       "name the clients it serves with --kvp-allow ADDR")
            face = KvpFace(maker, args.kvp_user, args.kvp_controller, auth,
                           tuple(args.kvp_allow))
            started.append(serve_in_thread(face, args.kvp_host, args.kvp_port))
    except BaseException:
        for running in started:
            running.stop()
        raise
    return started
