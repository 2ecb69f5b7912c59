"""A batch of touch-ups in one transaction under the controller's row lock (db.batch: what
PostgreSQL's short writers run in): each writer's rows as if it had run alone, a failed
writer's rows never committed, and each answer showing its own change.

``in_one_transaction`` is plain SQLAlchemy, so these run on both backends; the HTTP walk at
the end goes through the batches of whichever backend the suite runs on."""

from __future__ import annotations

import threading

import emulator
from api_helpers import *  # noqa: F403
from api_helpers import C, make_client, ok, open_session
from db import rows
from db import touch_up as touch
from db.batch import in_one_transaction
from db.models import CalibSession, Controller
from server.routers.common import state_of
from solvers.errors import CalibrationError

POSE = (400.0, 10.0, 300.0, 0.0, 90.0, 0.0)


def _teach(session_id: int, step: int, fail: str | None = None):  # noqa: ANN202
    """A touch-up of ``step`` as the route does it, as a job of the batch; ``fail`` = "before"
    (refused before it writes, like a wrong step) or "after" (fails after its writes)."""
    def job(conn):  # noqa: ANN001, ANN202
        c = rows.controller(conn, 1, lock=True)
        s = rows.session(conn, 1, session_id)
        if fail == "before":
            raise CalibrationError(("step",), "refused before writing")
        touch.put_point(conn, s, step, "joints", POSE, [0.0] * 6, t_s=float(c.clock_s))
        touch.store_state(conn, c, emulator.touched_up(state_of(c)))
        if fail == "after":
            raise RuntimeError("failed after writing")
        clock = c.clock_s
        return lambda: (s.version, [p.step for p in s.points], clock)  # built after the commit
    return job


def _session_id(client) -> int:  # noqa: ANN001
    return int(open_session(client, "tool.xyz_4point", 1).rsplit("/", 1)[1])


def _state(client, sid: int) -> tuple:  # noqa: ANN001
    with client.app.state.sessionmaker() as db:
        s, c = db.get(CalibSession, sid), db.get(Controller, 1)
        return s.version, sorted(p.step for p in s.points), c.clock_s, c.version


def test_a_batch_commits_its_writers_and_drops_a_failed_one(client):
    a, b = _session_id(client), _session_id(client)
    va, _, clock0, cv0 = _state(client, a)
    vb = _state(client, b)[0]
    outcomes = in_one_transaction(client.app.state.engine, 1, [
        _teach(a, 0), _teach(b, 0, fail="before"), _teach(a, 1), _teach(b, 1, fail="after"),
        _teach(b, 2)])
    assert [ok_ for ok_, _ in outcomes] == [True, False, True, False, True]
    assert isinstance(outcomes[1][1], CalibrationError)
    assert str(outcomes[3][1]) == "failed after writing"
    tick = emulator.TOUCH_UP_S
    # each answer (built after the commit, as deps.later) is its own writer's: session a at
    # +1 then +2, the clock one tick each
    assert outcomes[0][1]() == (va + 1, [0], clock0 + tick)
    assert outcomes[2][1]() == (va + 2, [0, 1], clock0 + 2 * tick)
    assert outcomes[4][1]() == (vb + 1, [2], clock0 + 3 * tick)
    # in the database: the three that succeeded, not the one that failed after writing
    assert _state(client, a)[:2] == (va + 2, [0, 1])
    assert _state(client, b)[:2] == (vb + 1, [2])
    _, _, clock, cv = _state(client, a)
    assert abs(clock - (clock0 + 3 * tick)) < 1e-9 and cv == cv0 + 3


def test_a_batch_of_an_unknown_controller_answers_each_writer(client):
    outcomes = in_one_transaction(client.app.state.engine, 999, [_teach(1, 0), _teach(1, 1)])
    assert [ok_ for ok_, _ in outcomes] == [False, False]
    assert all("controller" in str(exc) for _, exc in outcomes)


def test_concurrent_touch_ups_each_answer_their_own_change(client):
    """Touch-ups of 8 sessions from 8 threads at once (they meet in batches), with a wrong
    step among them: every answer's ETag is its session's version and its body that version's
    steps; no clock tick is lost and no refused touch-up wrote."""
    urls = [open_session(client, "tool.xyz_4point", 1) for _ in range(8)]
    clock0 = ok(client.get(f"{C}/cell/clock"))["clock_s"]
    answers: dict[int, list] = {k: [] for k in range(len(urls))}

    def teach(k: int) -> None:
        for step in (0, 1, 99, 2, 0):
            answers[k].append(client.post(f"{urls[k]}/touch-up", json={"step": step}))

    threads = [threading.Thread(target=teach, args=(k,)) for k in range(len(urls))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    for k, url in enumerate(urls):
        codes = [r.status_code for r in answers[k]]
        assert codes == [200, 200, 422, 200, 200], codes
        versions = [int(r.headers["ETag"].strip('"')) for r in answers[k] if r.status_code == 200]
        assert versions == list(range(versions[0], versions[0] + 4))
        filled = [[s["filled"] for s in r.json()["steps"]] for r in answers[k]
                  if r.status_code == 200]
        assert filled[:3] == [[True, False, False, False], [True, True, False, False],
                              [True, True, True, False]]
        final = client.get(url)
        assert final.headers["ETag"] == answers[k][-1].headers["ETag"]
    clock = ok(client.get(f"{C}/cell/clock"))["clock_s"]
    assert abs(clock - (clock0 + 4 * len(urls) * emulator.TOUCH_UP_S)) < 1e-6


def test_a_route_run_again_after_an_undone_batch_gets_a_fresh_session(client):
    """The routes of a batch (``deps._in_batch``): when a later writer fails after writing,
    the batch runs again without it, and the earlier writer's route runs again on a session of
    the new transaction (not the closed one of the undone pass); its write is committed once."""
    from functools import partial

    from sqlalchemy import text

    from server.deps import _in_batch

    maker, engine = client.app.state.sessionmaker, client.app.state.engine
    calls: list[str] = []

    def rename(db) -> str:  # noqa: ANN001
        calls.append("rename")
        db.execute(text("UPDATE controller SET name = name || '+' WHERE id = 1"))
        return "renamed"

    def fails_after_writing(db) -> None:  # noqa: ANN001
        db.execute(text("UPDATE controller SET name = 'lost' WHERE id = 1"))
        raise RuntimeError("failed after writing")

    name0 = ok(client.get(C))["name"]
    request_db = maker()
    jobs = [partial(_in_batch, rename, maker, request_db, (), {"db": request_db}),
            partial(_in_batch, fails_after_writing, maker, request_db, (), {"db": request_db})]
    outcomes = in_one_transaction(engine, None, jobs)
    request_db.close()
    assert outcomes[0] == (True, "renamed") and outcomes[1][0] is False
    assert calls == ["rename", "rename"]  # run again in the second pass
    assert ok(client.get(C))["name"] == name0 + "+"


def test_a_batch_reads_its_writers_sessions_in_one_query(client, monkeypatch):
    """With the writers' sessions named (``reads``: what ``deps`` passes, the path's
    session_id), the batch reads the controller and all the sessions in two queries, however
    many writers it has (PostgreSQL: in one round trip, ``db.pipeline``); a writer naming a
    session that is not its controller's is refused."""
    from sqlalchemy import event

    from db import pipeline

    engine = client.app.state.engine
    sids = [_session_id(client) for _ in range(4)]
    selects: list[str] = []
    piped: list[int] = []  # selects sent together through db.pipeline (one round trip)
    read = pipeline.read
    monkeypatch.setattr(pipeline, "read", lambda conn, sent: piped.append(len(sent)) or
                        read(conn, sent))

    def seen(_conn, _cursor, statement, *_):  # noqa: ANN001, ANN202
        if statement.lstrip().upper().startswith("SELECT"):
            selects.append(statement)

    event.listen(engine, "before_cursor_execute", seen)
    try:
        outcomes = in_one_transaction(engine, 1, [_teach(sid, 0) for sid in sids] +
                                      [_teach(10**6, 0)], reads=[*sids, 10**6])
    finally:
        event.remove(engine, "before_cursor_execute", seen)
    assert [ok_ for ok_, _ in outcomes] == [True] * 4 + [False]
    assert "no session" in str(outcomes[4][1])
    # the controller, the four sessions (together on PostgreSQL), the unknown one's own try
    if engine.dialect.name == "postgresql":
        assert piped == [2] and len(selects) == 1
    else:
        assert piped == [] and len(selects) == 3
    assert [_state(client, sid)[:2] for sid in sids] == [(outcomes[k][1]()[0], [0])
                                                         for k in range(4)]



def _batch_steps(engine, session_id: int, step: int) -> list[int]:  # noqa: ANN001
    """Teach ``step`` of ``session_id`` in a batch of ``engine`` (its process's session cache):
    the steps the writer saw filled after its touch-up."""
    ((ok_, result),) = in_one_transaction(engine, 1, [_teach(session_id, step)],
                                          reads=[session_id])
    assert ok_, result
    return result()[1]


def _cached_version(engine, session_id: int) -> int | None:  # noqa: ANN001
    with engine.connect() as conn:
        return rows.session_cache(conn).version_of(session_id)


def test_a_session_changed_by_another_process_is_read_again(client, db_url):
    """A batch keeps the sessions it committed (``db.rows.SessionCache``, one per database
    pool) and does not read their points again while their version is the one it left; a
    change by another process (here another app's engine and pool on the same database)
    bumps the version, and the next batch here reads the session again."""
    here = client.app.state.engine
    sid = _session_id(client)
    assert _batch_steps(here, sid, 0) == [0]
    cached = _cached_version(here, sid)
    assert cached == _state(client, sid)[0]  # kept as committed
    with make_client(db_url) as other:  # another worker
        assert _batch_steps(other.app.state.engine, sid, 1) == [0, 1]
        ok(other.post(f"{C}/sessions/{sid}/touch-up", json={"step": 2}))
    assert _batch_steps(here, sid, 3) == [0, 1, 2, 3]  # not the [0, 3] of a stale copy
    assert _batch_steps(here, sid, 0) == [0, 1, 2, 3]  # a hit: its own change, kept
    assert _state(client, sid)[:2] == (cached + 4, [0, 1, 2, 3])


def test_a_new_session_with_an_old_sessions_id_and_version_is_not_taken_for_it(client,
                                                                                db_url):
    """SQLite gives the id of a deleted last row again: a session made then, by another
    process, can reach the version this process's cache holds for the old one. Its
    ``created_at`` tells them apart, and its own points are read."""
    from sqlalchemy import text

    engine = client.app.state.engine
    if engine.dialect.name != "sqlite":
        return  # PostgreSQL's sequences never give an id again
    sid = _session_id(client)
    assert _batch_steps(engine, sid, 0) == [0]
    old = _cached_version(engine, sid)
    with engine.begin() as conn:  # deleted behind the service's back (a restore, an admin)
        conn.execute(text("DELETE FROM taught_point WHERE session_id = :s"), {"s": sid})
        conn.execute(text("DELETE FROM calib_session WHERE id = :s"), {"s": sid})
    with make_client(db_url) as other:  # another worker makes and teaches a new one
        assert _session_id(other) == sid  # the same id again
        ok(other.post(f"{C}/sessions/{sid}/touch-up", json={"step": 1}))
    assert _state(client, sid)[0] == old == _cached_version(engine, sid)  # same id, version
    assert _batch_steps(engine, sid, 2) == [1, 2]  # not the old session's [0, 2]


def test_re_teaches_of_a_batch_are_written_as_the_one_row_statements_write_them(client,
                                                                                monkeypatch):
    """Re-teaches of several sessions in one batch, one session twice (their writes set
    aside and sent together: one round trip on PostgreSQL, ``db.pipeline``): each point
    holds its own joints, pose and time, each session's version went up once per touch-up."""
    from db import pipeline
    from db.models import TaughtPoint

    engine = client.app.state.engine
    sids = [_session_id(client) for _ in range(3)]
    in_one_transaction(engine, 1, [_teach(sid, 0) for sid in sids], reads=sids)
    before = {sid: _state(client, sid)[0] for sid in sids}
    sent: list[tuple] = []
    write = pipeline.write
    monkeypatch.setattr(pipeline, "write", lambda conn, runs: sent.append(tuple(
        (stmt, len(params)) for stmt, params in runs)) or write(conn, runs))

    def reteach(sid: int, q0: float):  # noqa: ANN202
        def job(conn):  # noqa: ANN001, ANN202
            c = rows.controller(conn, 1, lock=True)
            s = rows.session(conn, 1, sid)
            touch.put_point(conn, s, 0, "joints", (q0, 1.0, 2.0, 3.0, 4.0, 5.0),
                            [q0, 0.0, 0.0, 0.0, 0.0, 0.0], t_s=q0)
            touch.store_state(conn, c, emulator.touched_up(state_of(c)))
        return job

    jobs = [reteach(sids[0], 10.0), reteach(sids[1], 11.0), reteach(sids[2], 12.0),
            reteach(sids[0], 13.0)]
    assert all(ok_ for ok_, _ in in_one_transaction(engine, 1, jobs, reads=[*sids, sids[0]]))
    with client.app.state.sessionmaker() as db:
        got = {sid: db.query(TaughtPoint).filter_by(session_id=sid, step=0).one()
               for sid in sids}
        for sid, q0 in zip(sids, (13.0, 11.0, 12.0)):
            p = got[sid]
            assert (p.joints_deg, p.x_mm, p.c_deg, p.t_s, p.motion_sign) == \
                ([q0, 0.0, 0.0, 0.0, 0.0, 0.0], q0, 5.0, q0, None)
    assert [_state(client, sid)[0] - before[sid] for sid in sids] == [2, 1, 1]
    if engine.dialect.name == "postgresql":  # the points, the sessions, the controller
        assert sent == [((touch.UPDATE_POINT, 4), (touch.BUMP_SESSION, 4),
                         (touch.STORE_STATE, 1))]
    else:
        assert sent == []


def test_a_restored_session_is_not_taken_for_the_one_restored_before_it(client):
    """A restore makes a controller's sessions again, at version 1 with their old
    ``created_at`` (and on SQLite at the ids they had): restoring an older backup after a
    batch kept a session of a newer one must not hand the batch the newer one's points."""
    from db import crud

    engine = client.app.state.engine
    sid = _session_id(client)
    ok(client.post(f"{C}/sessions/{sid}/touch-up", json={"step": 0, "joints_deg": [1.0] * 6}))
    with client.app.state.sessionmaker() as db:
        older = crud.backup(db, db.get(Controller, 1))
    ok(client.post(f"{C}/sessions/{sid}/touch-up", json={"step": 0, "joints_deg": [2.0] * 6}))
    with client.app.state.sessionmaker() as db:
        newer = crud.backup(db, db.get(Controller, 1))

    def restore(doc: dict) -> int:
        with client.app.state.sessionmaker() as db:
            crud.restore_backup(db, db.get(Controller, 1), doc)
            db.commit()
            (s,) = crud.list_sessions(db, 1)
            return s.id

    def joints_of_step_0(session_id: int):  # noqa: ANN202
        def job(conn):  # noqa: ANN001, ANN202
            return rows.session(conn, 1, session_id).points[0].joints_deg
        return job

    new_id = restore(newer)
    ((_, seen),) = in_one_transaction(engine, 1, [joints_of_step_0(new_id)], reads=[new_id])
    assert seen == [2.0] * 6  # and the batch keeps this session
    old_id = restore(older)
    ((_, seen),) = in_one_transaction(engine, 1, [joints_of_step_0(old_id)], reads=[old_id])
    assert seen == [1.0] * 6


def test_a_pipelined_statement_that_fails_raises_sqlalchemys_error(client):
    """PostgreSQL (``db.pipeline``): a statement the server refuses raises as
    ``Connection.execute`` would (SQLAlchemy's ``DBAPIError``, naming the server's reason),
    and the connection rolls back and goes on."""
    import pytest
    from sqlalchemy import literal_column, select
    from sqlalchemy.exc import DBAPIError

    from db import pipeline

    engine = client.app.state.engine
    with engine.connect() as conn:
        if not pipeline.supported(conn):
            return  # SQLite: SQLAlchemy sends each statement itself
        with pytest.raises(DBAPIError, match="division by zero"), conn.begin():  # a batch's
            pipeline.read(conn, [(select(literal_column("1") / literal_column("0")), {})])
        with conn.begin():
            assert pipeline.read(conn, [(rows.CONTROLLER, {"b_id": 1})])[0][0][0] == 1
