"""PostgreSQL: a batch's statements in three round trips under the row lock, not six
(psycopg's pipeline mode).

SQLAlchemy sends a statement and waits for its answer before the next. A batch of short
writers (:mod:`db.batch`) on PostgreSQL sent eight that way: the pool's ping, ``BEGIN``, the
controller's row lock, its sessions, two runs of writes, the controller, ``COMMIT``; six of
them with the row lock held, each a wait in which the batch's thread gave the GIL up and
then had to win it back from the event loop. psycopg's pipeline mode sends several
statements and waits once (`libpq pipeline mode
<https://www.postgresql.org/docs/current/libpq-pipeline-mode.html>`_, PostgreSQL 14's libpq,
which psycopg's binary wheel carries). A batch uses it twice, then commits:

- :func:`read`: ``SELECT ... FOR UPDATE`` of the controller and the sessions' select in one
  round trip (the server runs them in order, so the sessions are read under the lock;
  psycopg's ``BEGIN`` goes before, on its own, before the lock);
- :func:`write`: the writes, each run of one statement as one ``executemany``, in one
  round trip; their rowcounts are checked before the ``COMMIT`` (SQLAlchemy's). (A step
  taught for the first time is inserted at once, for its id: a round trip of its own.)

The statements are the Core statements of :mod:`db.rows` and :mod:`db.touch_up`, compiled by
SQLAlchemy for the connection's dialect, with SQLAlchemy's own bind and result processors
(``TypeEngine.bind_processor`` / ``result_processor``); only the sending is psycopg's. The
connection and its transaction are SQLAlchemy's: the pipeline runs on the DBAPI connection
under them, and a failure raises (as SQLAlchemy's exception) through the batch's ``with
conn.begin()``, which rolls back. These statements pass no ``before_cursor_execute``
listener and no ``echo``.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from sqlalchemy import Connection
from sqlalchemy.exc import DBAPIError

Statement = tuple[Any, dict[str, Any]]  # a Core statement and its parameters


def supported(conn: Connection) -> bool:
    """Whether ``conn`` is psycopg 3 on PostgreSQL with pipeline mode (else the batch sends
    its statements through SQLAlchemy, one round trip each)."""
    if conn.dialect.name != "postgresql" or conn.dialect.driver != "psycopg" \
            or conn.dialect.is_async:
        return False
    from psycopg import Pipeline

    return Pipeline.is_supported()


_COMPILED: weakref.WeakKeyDictionary[Any, dict[Any, tuple[Any, dict[str, Any],
                                                          dict[str, Any]]]] = \
    weakref.WeakKeyDictionary()  # per dialect (an engine's), then per statement


def _compiled(stmt: Any, dialect: Any) -> tuple[Any, dict[str, Any], dict[str, Any]]:
    """``stmt`` compiled for ``dialect``, the bind processors of its parameters, and the
    values it carries itself (``.values(state="open")``)."""
    known = _COMPILED.setdefault(dialect, {})
    found = known.get(stmt)
    if found is None:
        compiled = stmt.compile(dialect=dialect)
        procs = {name: p for name, b in compiled.binds.items()
                 if (p := b.type.dialect_impl(dialect).bind_processor(dialect))}
        rendered = set(compiled.bind_names.values())
        own = {name: b.effective_value for name, b in compiled.binds.items()
               if name in rendered and not b.required}
        found = known[stmt] = compiled, procs, own
    return found


def _sql(stmt: Any, params: dict[str, Any], dialect: Any) -> tuple[str, dict[str, Any]]:
    """The SQL text (expanding ``IN`` parameters expanded) and the parameters as the driver
    takes them (SQLAlchemy's bind processors applied: JSON, time stamps)."""
    compiled, procs, own = _compiled(stmt, dialect)
    if compiled.post_compile_params:  # IN (...): the statement depends on the parameters
        state = compiled.construct_expanded_state(params)
        sql, params, procs = state.statement, state.parameters, {**procs, **state.processors}
    else:  # as construct_params, without its checks, once per row of an executemany
        sql, params = compiled.string, {**own, **params}
    return sql, {k: (procs[k](v) if k in procs else v) for k, v in params.items()}


_RESULT_PROCESSORS: weakref.WeakKeyDictionary[Any, dict[Any, list[tuple[int, Any]]]] = \
    weakref.WeakKeyDictionary()  # per dialect, then per (statement, column types)


def _result_processors(stmt: Any, description: Any, dialect: Any) -> list[tuple[int, Any]]:
    """SQLAlchemy's result processors of ``stmt``'s columns, by the types the server sent
    (``cursor.description``): (column index, processor) where there is one."""
    known = _RESULT_PROCESSORS.setdefault(dialect, {})
    key = (stmt, tuple(d.type_code for d in description))
    found = known.get(key)
    if found is None:
        found = known[key] = [
            (i, p) for i, (col, d) in enumerate(zip(stmt.selected_columns, description))
            if (p := col.type.dialect_impl(dialect).result_processor(dialect, d.type_code))]
    return found


def _rows(cursor: Any, stmt: Any, dialect: Any) -> list[tuple]:
    """The cursor's rows with SQLAlchemy's result processors for ``stmt``'s columns."""
    rows = cursor.fetchall()
    procs = _result_processors(stmt, cursor.description, dialect)
    if not procs:
        return rows
    out = []
    for row in rows:
        values = list(row)
        for i, p in procs:
            values[i] = p(values[i])
        out.append(tuple(values))
    return out


@contextmanager
def _as_sqlalchemy_errors(conn: Connection, what: str) -> Iterator[None]:
    """The driver's errors as SQLAlchemy's (``sqlalchemy.exc.OperationalError`` and so on),
    as ``Connection.execute`` raises them. A connection lost here is not marked invalid at
    once: the pool's ping finds it at its next checkout."""
    try:
        yield
    except conn.dialect.loaded_dbapi.Error as exc:
        raise DBAPIError.instance(what, None, exc, conn.dialect.loaded_dbapi.Error,
                                  dialect=conn.dialect) from exc


def read(conn: Connection, statements: Sequence[Statement]) -> list[list[tuple]]:
    """Run the selects ``statements`` in ``conn``'s transaction in one round trip (psycopg
    sends the ``BEGIN`` of a transaction on its own first): each one's rows, in the order of
    its columns. Rows come in binary (fewer bytes to parse than text)."""
    raw, dialect = conn.connection.driver_connection, conn.dialect
    with _as_sqlalchemy_errors(conn, "a batch's reads"):
        with raw.pipeline():  # its end sends one Sync and takes every result
            cursors = []
            for stmt, params in statements:
                cursor = raw.cursor(binary=True)
                cursor.execute(*_sql(stmt, params, dialect))
                cursors.append(cursor)
        return [_rows(c, stmt, dialect) for c, (stmt, _) in zip(cursors, statements)]


def write(conn: Connection, runs: Sequence[tuple[Any, list[dict[str, Any]]]]) -> list[int]:
    """Send ``runs`` (a statement and its parameter sets each: one ``executemany``) in
    ``conn``'s transaction, in one round trip: how many rows each run changed."""
    raw, dialect = conn.connection.driver_connection, conn.dialect
    with _as_sqlalchemy_errors(conn, "a batch's writes"):
        with raw.pipeline():  # its end sends one Sync and takes every result
            cursors = []
            for stmt, params in runs:
                sent = [_sql(stmt, p, dialect) for p in params]
                cursor = raw.cursor()
                cursor.executemany(sent[0][0], [p for _, p in sent])
                cursors.append(cursor)
    return [c.rowcount for c in cursors]
