"""benchmarks/delay_proxy.py, which the PostgreSQL benchmark puts before the database to stand
for another host: bytes arrive whole, in order, both ways, each way a fixed time late."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

PROXY = Path(__file__).resolve().parent.parent / "benchmarks" / "delay_proxy.py"


def _echo_server() -> tuple[socket.socket, int]:
    server = socket.create_server(("127.0.0.1", 0))

    def serve() -> None:
        conn, _ = server.accept()
        with conn:
            while data := conn.recv(65536):
                conn.sendall(data)

    threading.Thread(target=serve, daemon=True).start()
    return server, server.getsockname()[1]


def _round_trip(sock: socket.socket, payload: bytes) -> tuple[bytes, float]:
    t0 = time.perf_counter()
    sock.sendall(payload)
    got = b""
    while len(got) < len(payload):
        got += sock.recv(65536)
    return got, time.perf_counter() - t0


def test_the_proxy_forwards_every_byte_in_order_each_way_late():
    server, port = _echo_server()
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        listen = probe.getsockname()[1]
    proxy = subprocess.Popen([sys.executable, str(PROXY), str(listen), "127.0.0.1", str(port),
                              "40"])
    try:
        for _ in range(200):
            try:
                sock = socket.create_connection(("127.0.0.1", listen), timeout=5)
                break
            except OSError:
                time.sleep(0.05)
        with sock:
            payload = bytes(range(256)) * 4096  # 1 MiB: many chunks, kept in order
            got, took = _round_trip(sock, payload)
            assert got == payload
            _, took = _round_trip(sock, b"ping")
            assert 0.08 <= took < 1.0  # 40 ms each way
    finally:
        proxy.kill()
        proxy.wait()
        server.close()
