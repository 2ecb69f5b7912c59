"""The SQLite writers' queue (db.writers): turns handed on in order, to threads and to event-loop
tasks alike, never lost to a cancelled waiter, and batches of the loop's writers run together
under one turn, in one transaction (db.batch.SQLiteBatch)."""

from __future__ import annotations

import asyncio
import signal
import subprocess
import sys
import threading

import pytest

from db.batch import SQLiteBatch
from db.session import make_engine, write_engine
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


@pytest.fixture()
def batch(queue, tmp_path) -> SQLiteBatch:  # noqa: ANN001
    """The loop's batch of writers on ``queue``, in one transaction of a SQLite file."""
    engine = make_engine(f"sqlite:///{tmp_path / 'pendant.db'}")
    yield SQLiteBatch(queue, write_engine(engine))
    engine.dispose()


def test_a_loop_writer_waits_behind_a_thread_and_gets_the_turn_with_the_flock(queue):
    order: list[str] = []

    async def main() -> None:
        queue.acquire()  # a thread's turn (this one)
        waiter = asyncio.create_task(queue.acquire_async())
        await asyncio.sleep(0.05)
        assert not waiter.done()  # waits its turn
        order.append("thread done")
        queue.release()
        await asyncio.wait_for(waiter, 5)
        order.append("loop writer")
        assert not other_process_can_lock(queue.path)  # its turn holds the host's flock
        queue.release()

    asyncio.run(main())
    assert order == ["thread done", "loop writer"]
    assert other_process_can_lock(queue.path)  # let go with the last turn


def test_turns_go_first_come_first_served_to_threads_and_tasks(queue):
    order: list[str] = []

    def thread_writer(name: str, queued: threading.Event) -> None:
        queued.set()
        queue.acquire()
        order.append(name)
        queue.release()

    async def task_writer(name: str) -> None:
        await queue.acquire_async()
        order.append(name)
        queue.release()

    async def main() -> None:
        queue.acquire()
        tasks, threads = [], []
        for k in range(3):
            tasks.append(asyncio.create_task(task_writer(f"task{k}")))
            await asyncio.sleep(0.02)
            queued = threading.Event()
            t = threading.Thread(target=thread_writer, args=(f"thread{k}", queued))
            t.start()
            threads.append(t)
            queued.wait(5)
            await asyncio.sleep(0.05)  # the thread is queued by now
        queue.release()
        await asyncio.wait_for(asyncio.gather(*tasks), 10)
        for t in threads:
            await asyncio.to_thread(t.join, 10)

    asyncio.run(main())
    assert order == ["task0", "thread0", "task1", "thread1", "task2", "thread2"]


def test_a_cancelled_waiter_does_not_keep_or_lose_the_turn(queue):
    async def main() -> None:
        queue.acquire()
        gone = asyncio.create_task(queue.acquire_async())
        await asyncio.sleep(0.02)
        gone.cancel()  # a client that left while waiting
        with pytest.raises(asyncio.CancelledError):
            await gone
        queue.release()
        await asyncio.wait_for(queue.acquire_async(), 5)  # the turn is free again
        queue.release()

        # handed the turn just as it is cancelled: it passes the turn on
        queue.acquire()
        late = asyncio.create_task(queue.acquire_async())
        nxt = asyncio.create_task(queue.acquire_async())
        await asyncio.sleep(0.02)
        queue.release()  # hands the turn to `late` (its wake-up is scheduled, not run)
        late.cancel()
        with pytest.raises(asyncio.CancelledError):
            await late
        await asyncio.wait_for(nxt, 5)  # so the next one got it
        queue.release()

    asyncio.run(main())
    assert other_process_can_lock(queue.path)


def test_the_loops_writers_that_wait_run_as_one_batch_in_order(queue, batch):
    ran: list[str] = []
    connections: set[int] = set()

    def job(name: str, fail: bool = False):  # noqa: ANN202
        def run(conn) -> str:  # noqa: ANN001
            assert not other_process_can_lock(queue.path)  # under the turn and its flock
            assert conn.in_transaction()
            connections.add(id(conn))
            ran.append(name)
            if fail:
                raise ValueError(f"{name} refused")
            return name.upper()
        return run

    async def main() -> list:
        queue.acquire()  # a thread holds the turn: the writers gather meanwhile
        futures = [asyncio.ensure_future(batch.run(job(n, fail=n == "b")))
                   for n in ("a", "b", "c")]
        await asyncio.sleep(0.05)
        assert ran == []
        queue.release()
        return await asyncio.wait_for(asyncio.gather(*futures, return_exceptions=True), 5)

    results = asyncio.run(main())
    assert ran == ["a", "b", "c"]
    assert results[0] == "A" and results[2] == "C"  # one writer's refusal is its own
    assert isinstance(results[1], ValueError) and "b refused" in str(results[1])
    assert len(connections) == 1  # one transaction for the batch
    assert other_process_can_lock(queue.path)


def test_a_writer_whose_client_left_before_its_batch_ran_is_skipped(queue, batch):
    ran: list[str] = []

    async def main() -> None:
        queue.acquire()
        gone = asyncio.ensure_future(batch.run(lambda _conn: ran.append("gone")))
        stays = asyncio.ensure_future(batch.run(lambda _conn: ran.append("stays")))
        await asyncio.sleep(0.02)
        gone.cancel()
        queue.release()
        await asyncio.wait_for(stays, 5)

    asyncio.run(main())
    assert ran == ["stays"]


def test_a_batched_writer_runs_in_its_own_requests_context(queue, batch):
    """Each writer of a batch sees its own request's context variables (the actor the audit
    records, the request id), not those of whoever started the batch."""
    import contextvars

    who: contextvars.ContextVar[str] = contextvars.ContextVar("who", default="nobody")

    async def request(name: str) -> str:
        who.set(name)
        return await batch.run(lambda _conn: who.get())

    async def main() -> list:
        queue.acquire()
        tasks = [asyncio.ensure_future(request(n)) for n in ("alice", "bob")]
        await asyncio.sleep(0.05)
        queue.release()
        return await asyncio.wait_for(asyncio.gather(*tasks), 5)

    assert asyncio.run(main()) == ["alice", "bob"]


def test_a_batched_writer_whose_job_raises_a_base_exception_is_answered_too(batch):
    """A job raising a BaseException (not a request's own error) ends the batch: its writer
    and the writers after it are answered with an error, none waits forever."""

    class Boom(BaseException):
        pass

    def boom(_conn) -> None:  # noqa: ANN001
        raise Boom()

    async def main() -> tuple[bool, bool]:
        first = asyncio.ensure_future(batch.run(boom))
        second = asyncio.ensure_future(batch.run(lambda _conn: "x"))
        await asyncio.wait([first, second], timeout=1)
        return first.done(), second.done()

    first_done, second_done = asyncio.run(main())
    assert second_done  # the writer it left is failed (RuntimeError), as c7ecf27 says
    assert first_done, "the writer whose job raised the BaseException is never answered"


def test_an_interrupted_thread_waiter_does_not_swallow_the_next_turn(queue):
    """A thread interrupted while it waits (a signal handler raising in the main thread:
    Ctrl-C in a CLI or a script) leaves the queue; the turn is not handed to it and lost."""
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
    got = threading.Event()
    t = threading.Thread(target=lambda: (queue.acquire(), got.set(), queue.release()))
    t.start()
    assert got.wait(5), "the turn went to the interrupted waiter and is lost"
    t.join(5)


def test_a_cancelled_wait_for_another_processs_flock_leaves_no_flock_behind(queue):
    """A loop writer cancelled (the batch leader at the loop's shutdown) while its thread
    waits for another process's flock: once the thread has the flock, it is let go with the
    turn; the other processes are not locked out."""
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
