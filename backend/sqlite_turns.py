"""SQLite served one writer at a time, in turn: the embedded database's connections wait for
their turn to write (in the order they asked) instead of failing on a locked file.
"""

from __future__ import annotations

import collections
import re
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any, cast


class _WriterTurns:
    """The turn to write to one SQLite file in this process, served first come, first served.

    SQLite lets one connection write at a time. A writer that finds the file locked polls it,
    sleeping up to 100 ms between tries, and can lose to newcomers until its busy timeout
    runs out ("database is locked"). Writers waiting here instead get the turn in arrival
    order the moment the one before them commits or rolls back.
    """

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._waiting: collections.deque[object] = collections.deque()
        self._held = False

    def acquire(self, timeout_s: float) -> bool:
        with self._cond:
            if not self._held and not self._waiting:
                self._held = True
                return True
            ticket = object()
            self._waiting.append(ticket)
            deadline = time.monotonic() + timeout_s
            while self._held or self._waiting[0] is not ticket:
                left = deadline - time.monotonic()
                if left <= 0:
                    self._waiting.remove(ticket)
                    self._cond.notify_all()
                    return False
                self._cond.wait(left)
            self._waiting.popleft()
            self._held = True
            return True

    def release(self) -> None:
        with self._cond:
            self._held = False
            self._cond.notify_all()


_TURNS: dict[str, _WriterTurns] = {}
_TURNS_GUARD = threading.Lock()
# Statements that never write; any other statement (INSERT, UPDATE, DELETE, DDL, SAVEPOINT)
# takes the writer turn first.
_READS = frozenset({"SELECT", "PRAGMA", "EXPLAIN", "WITH"})
_FIRST_WORD = re.compile(r"\s*([A-Za-z]+)")


# When the request this thread works for stops waiting for the database (monotonic seconds).
REQUEST_DEADLINE: ContextVar[float | None] = ContextVar("dexlabel_request_deadline",
                                                        default=None)
# Where the scope records when the app started on a request.
STARTED = "dexlabel.started"


def _turns_of(database: str) -> _WriterTurns:
    key = database if database.startswith("file:") else str(Path(database).resolve())
    with _TURNS_GUARD:
        return _TURNS.setdefault(key, _WriterTurns())


def _writes(sql: str) -> bool:
    word = _FIRST_WORD.match(sql)
    return word is None or word.group(1).upper() not in _READS


class TurnTakingConnection(sqlite3.Connection):
    """A SQLite connection that takes its process's writer turn (:class:`_WriterTurns`)
    before the first write of a transaction and gives it back when the transaction ends.

    Python's sqlite3 begins a transaction at the first INSERT, UPDATE or DELETE, which is
    where SQLite takes its write lock, and the lock is held to the commit or rollback: the
    turn spans exactly that. Waiting longer than the connection's timeout (seconds) raises
    "database is locked", as SQLite's own busy timeout does.
    """

    def __init__(self, database: str, *args: Any, **kwargs: Any) -> None:
        super().__init__(database, *args, **kwargs)
        self.turns = _turns_of(str(database))
        self.wait_s = float(kwargs.get("timeout", 5.0))
        self.has_turn = False

    def cursor(self, factory: Any = None) -> Any:
        return super().cursor(factory or TurnTakingCursor)

    def commit(self) -> None:
        try:
            super().commit()
        finally:
            self.give_turn_back()

    def rollback(self) -> None:
        try:
            super().rollback()
        finally:
            self.give_turn_back()

    def close(self) -> None:
        try:
            super().close()
        finally:
            self.give_turn_back()

    @contextmanager
    def statement(self, sql: str) -> Iterator[None]:
        """Runs one statement: with the writer turn first if it writes and the transaction
        has none yet; a statement outside a transaction (DDL, a failed first write) gives
        the turn back when it ends."""
        if not self.has_turn and _writes(sql):
            # A request waits only until its own deadline (see get_session).
            deadline = REQUEST_DEADLINE.get()
            wait_s = self.wait_s if deadline is None else deadline - time.monotonic()
            if not self.turns.acquire(wait_s):
                raise sqlite3.OperationalError(
                    f"database is locked: no turn to write came within {self.wait_s:g} s")
            self.has_turn = True
        try:
            yield
        finally:
            if self.has_turn and not self.in_transaction:
                self.give_turn_back()

    def give_turn_back(self) -> None:
        if self.has_turn:
            self.has_turn = False
            self.turns.release()


class TurnTakingCursor(sqlite3.Cursor):
    """The cursor of a :class:`TurnTakingConnection`: each statement asks for the turn."""

    def _connection(self) -> TurnTakingConnection:
        return cast(TurnTakingConnection, self.connection)

    def execute(self, sql: str, parameters: Any = (), /) -> TurnTakingCursor:
        with self._connection().statement(sql):
            return super().execute(sql, parameters)

    def executemany(self, sql: str, seq_of_parameters: Any, /) -> TurnTakingCursor:
        with self._connection().statement(sql):
            return super().executemany(sql, seq_of_parameters)

    def executescript(self, sql_script: str, /) -> TurnTakingCursor:
        with self._connection().statement("SCRIPT"):
            return cast(TurnTakingCursor, super().executescript(sql_script))
