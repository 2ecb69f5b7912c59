"""Review findings on db/writers.py (deterministic demonstrations; each FAILS on HEAD)."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
import threading
import time

import pytest

from db.writers import WriterQueue

LOCK_PROBE = ("import fcntl, os, sys\n"
              "fd = os.open(sys.argv[1], os.O_RDWR)\n"
              "fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)\n")


def other_process_can_lock(path: str) -> bool:
    return subprocess.run([sys.executable, "-c", LOCK_PROBE, path],
                          capture_output=True).returncode == 0


@pytest.fixture()
def queue(tmp_path) -> WriterQueue:  # noqa: ANN001
    return WriterQueue(str(tmp_path / "pendant.db.writer.lock"))


def test_F1_a_job_raising_a_base_exception_is_answered_too(queue):
    """WriterBatch._lead: the job that raised a BaseException was popped from ``jobs`` before
    it ran, so neither the finally (extendleft) nor the except (fail self._jobs) sees its
    future: its request awaits forever."""

    class Boom(BaseException):
        pass

    def boom() -> None:
        raise Boom()

    async def main() -> tuple[bool, bool]:
        batch = queue.batch()
        first = asyncio.ensure_future(batch.run(boom))
        second = asyncio.ensure_future(batch.run(lambda: "x"))
        await asyncio.wait([first, second], timeout=1)
        return first.done(), second.done()

    first_done, second_done = asyncio.run(main())
    assert second_done  # the writer it left is failed (RuntimeError), as c7ecf27 says
    assert first_done, "the writer whose job raised the BaseException is never answered"


def test_F2_an_interrupted_thread_waiter_does_not_swallow_the_next_turn(queue):
    """WriterQueue.acquire: a thread interrupted while it waits (a signal handler raising in
    the main thread: Ctrl-C in a CLI or a script) leaves its waiter lock queued; the holder
    then hands the turn to that dead waiter and it is lost for good. (The old
    threading.Lock-based queue just did not acquire.)"""
    assert threading.current_thread() is threading.main_thread()

    class Interrupted(Exception):
        pass

    def handler(*_):  # noqa: ANN002, ANN202
        raise Interrupted()

    old = signal.signal(signal.SIGUSR1, handler)
    try:
        queue.acquire()  # a holder
        main = threading.main_thread().ident
        threading.Timer(0.2, signal.pthread_kill, (main, signal.SIGUSR1)).start()
        with pytest.raises(Interrupted):
            queue.acquire()  # waits; interrupted
    finally:
        signal.signal(signal.SIGUSR1, old)
    queue.release()  # the holder is done
    assert queue.try_acquire(), "the turn went to the interrupted waiter and is lost"
    queue.release()


def test_F3_a_cancelled_flock_wait_leaves_no_flock_behind(queue):
    """WriterQueue.acquire_async: natively cancelled (asyncio.run's shutdown cancelling the
    batch leader, or a request cancelled in WriterTurn.take_async) while its thread waits for
    another process's flock, it gives the turn back; the abandoned thread then takes the
    flock and sets _flocked with no turn held: the other processes are locked out until
    this process's next turn ends."""
    open(queue.path, "w").close()
    holder = subprocess.Popen([sys.executable, "-c",
                               LOCK_PROBE + "print('held', flush=True)\nsys.stdin.read()\n",
                               queue.path], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True)
    assert holder.stdout.readline().strip() == "held"

    async def main() -> None:
        waiter = asyncio.ensure_future(queue.acquire_async())
        await asyncio.sleep(0.3)  # in its thread, in flock()
        waiter.cancel()
        with pytest.raises(asyncio.CancelledError):
            await waiter
        holder.communicate("", timeout=10)  # the other process lets go
        await asyncio.sleep(0.5)  # the abandoned thread takes the flock meanwhile

    try:
        asyncio.run(main())
    finally:
        if holder.poll() is None:
            holder.kill()
    assert not queue._held  # no turn in this process
    assert other_process_can_lock(queue.path), (
        f"flock leaked with no turn held (_flocked={queue._flocked})")
