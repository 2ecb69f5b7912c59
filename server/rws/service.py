"""Run a face (an ASGI app or an asyncio server) in a thread of its own, beside REST."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from typing import Any


class Running:
    """A face serving in its own thread and event loop until :meth:`stop`."""

    def __init__(self, name: str, start: Callable[[], Any], stop: Callable[[], Any]):
        self.loop = asyncio.new_event_loop()
        self._stop = stop
        self._started = threading.Event()
        self._error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, args=(start,), name=name, daemon=True)
        self.thread.start()

    def _run(self, start: Callable[[], Any]) -> None:
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_until_complete(start())
        except BaseException as err:  # noqa: BLE001 - reported by wait_started
            self._error = err
            self._started.set()
            return
        self._started.set()
        try:
            self.loop.run_forever()
        finally:
            self.loop.run_until_complete(self.loop.shutdown_asyncgens())
            self.loop.run_until_complete(self.loop.shutdown_default_executor())
            self.loop.close()

    def wait_started(self, timeout_s: float = 30.0) -> None:
        if not self._started.wait(timeout_s):
            raise TimeoutError(f"{self.thread.name} did not start within {timeout_s} s")
        if self._error is not None:
            raise self._error

    def stop(self, timeout_s: float = 10.0) -> None:
        async def stopping() -> None:
            try:
                await self._stop()
            finally:  # every connection's task ends here, in its loop, before the loop stops
                others = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
                for t in others:
                    t.cancel()
                await asyncio.gather(*others, return_exceptions=True)
                self.loop.stop()

        self.loop.call_soon_threadsafe(lambda: self.loop.create_task(stopping()))
        self.thread.join(timeout_s)


def serve_asgi(app: Any, host: str, port: int, name: str) -> Running:
    """uvicorn on ``app`` at ``host:port`` in a thread (no signal handlers of its own)."""
    import uvicorn

    server = uvicorn.Server(uvicorn.Config(app, host=host, port=port, log_level="warning",
                                           lifespan="off", ws="websockets"))
    task: dict[str, asyncio.Task] = {}

    async def start() -> None:  # uvicorn installs no signal handlers outside the main thread
        t = task["serve"] = asyncio.get_running_loop().create_task(server.serve())
        while not server.started:
            if t.done():
                t.result()
                raise OSError(f"{name}: cannot listen on {host}:{port}")
            await asyncio.sleep(0.02)

    async def stop() -> None:
        server.should_exit = True
        await task["serve"]

    running = Running(name, start, stop)
    running.wait_started()
    return running
