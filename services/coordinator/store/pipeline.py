"""PostgreSQL: statements of one transaction sent together, in one round trip.

psycopg's pipeline mode sends several statements and waits once for all their results. The
server still runs them one after the other, each as a statement of its own (in READ COMMITTED
each takes its own snapshot), in the caller's transaction: only the waiting between them goes.
Ingest uses it for the statements of a batch whose parameters are known before the previous
one's answer (store/ingest.py): on a loaded machine each round trip is a wait for the
database's process to be scheduled, and those under the exploration's row lock hold it.

The statements are SQLAlchemy Core statements compiled once for psycopg (`Piped`); they run
on the session's own connection, outside SQLAlchemy's execution, so a driver error is turned
into SQLAlchemy's exception here (a dropped connection: invalidated, `connection_invalidated`,
as SQLAlchemy does it, which the dispatcher answers `unavailable`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from enum import Enum
from typing import Any

import psycopg
from sqlalchemy import Connection
from sqlalchemy.dialects.postgresql.psycopg import PGDialect_psycopg
from sqlalchemy.exc import DBAPIError
from sqlalchemy.sql import Executable

_DIALECT = PGDialect_psycopg()

Step = tuple[str, Mapping[str, Any]]


class Piped:
    """A statement's psycopg text and its fixed parameters, compiled once.

    `sample`: a value for each bind parameter the caller supplies (an expanding one as a
    one-element list: its parameter is then named `<name>_1`)."""

    def __init__(self, statement: Executable, sample: Mapping[str, Any]) -> None:
        expanded = statement.compile(dialect=_DIALECT).construct_expanded_state(dict(sample))
        self.sql: str = expanded.statement
        supplied = {f"{k}_1" if isinstance(v, list) else k for k, v in sample.items()}
        # Enum members as their values: what SQLAlchemy's own execution binds.
        self._fixed = {k: v.value if isinstance(v, Enum) else v
                       for k, v in expanded.parameters.items() if k not in supplied}
        self._supplied = frozenset(supplied)

    def step(self, **values: Any) -> Step:
        if values.keys() != self._supplied:
            raise TypeError(f"parameters {sorted(values)}, expected {sorted(self._supplied)}")
        return self.sql, {**self._fixed, **values}


def run(connection: Connection, steps: Sequence[Step], *, commit: bool = False
        ) -> list[psycopg.Cursor[Any]]:
    """Run the steps in order in the connection's transaction, in one round trip; one cursor
    each, its rows and rowcount read after. With `commit`, the transaction's COMMIT goes in
    the same round trip (the caller's own commit then finds nothing to commit). Any failure
    raises SQLAlchemy's DBAPIError (the transaction is then aborted, as after any failed
    statement, and nothing of it is committed)."""
    raw = connection.connection.driver_connection
    assert isinstance(raw, psycopg.Connection), raw
    cursors: list[psycopg.Cursor[Any]] = []
    sql, params = steps[0]
    try:
        with raw.pipeline():
            for sql, params in steps:
                cursor = raw.cursor()
                cursor.execute(sql, params)
                cursors.append(cursor)
            if commit:
                sql, params = "COMMIT", {}
                raw.commit()
    except psycopg.Error as exc:
        invalidated = raw.broken or raw.closed
        if invalidated:
            connection.invalidate(exc)
        raise DBAPIError.instance(sql, params, exc, psycopg.Error, hide_parameters=True,
                                  connection_invalidated=invalidated,
                                  dialect=connection.dialect) from exc
    return cursors
