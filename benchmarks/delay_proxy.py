"""A TCP proxy that holds every chunk for a fixed time each way: PostgreSQL on another host,
as a benchmark sees it (``benchmarks/api.py --pg-delay-ms``). Linux's ``netem`` does this in
the kernel, but needs its module and root; this needs neither.

    python benchmarks/delay_proxy.py LISTEN_PORT HOST PORT DELAY_MS

Every chunk read from one side is written to the other ``DELAY_MS`` later (one way: a round
trip gains twice that), in order. It runs in its own process, so its CPU is not the
service's.
"""

from __future__ import annotations

import asyncio
import sys


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                delay_s: float) -> None:
    loop = asyncio.get_running_loop()
    try:
        while data := await reader.read(65536):
            loop.call_later(delay_s, writer.write, data)  # call_later keeps their order
    finally:
        await asyncio.sleep(2 * delay_s)  # what is still on its way
        writer.close()


def main() -> None:
    listen_port, host, port, delay_s = (int(sys.argv[1]), sys.argv[2], int(sys.argv[3]),
                                        float(sys.argv[4]) / 1e3)

    async def connection(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up_reader, up_writer = await asyncio.open_connection(host, port)
        await asyncio.gather(_pipe(reader, up_writer, delay_s),
                             _pipe(up_reader, writer, delay_s), return_exceptions=True)

    async def serve() -> None:
        server = await asyncio.start_server(connection, "127.0.0.1", listen_port)
        async with server:
            await server.serve_forever()

    try:
        import uvloop  # uvicorn[standard]'s event loop: less CPU per chunk

        factory = uvloop.new_event_loop
    except ImportError:
        factory = None
    with asyncio.Runner(loop_factory=factory) as runner:
        runner.run(serve())


if __name__ == "__main__":
    main()
