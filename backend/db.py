"""Database engine, sessions and the declarative base.

The request (or the queue task) is the unit of work: services only flush, and the caller
commits through ``session_scope`` or the ``SessionDep`` dependency.
"""

from __future__ import annotations

import collections
import re
import sqlite3
import threading
import time
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager, contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any, cast

import anyio
from anyio.lowlevel import RunVar
from fastapi import Depends, FastAPI, Request
from fastapi.responses import JSONResponse
from sqlalchemy import DateTime, Dialect, Engine, MetaData, TypeDecorator, create_engine, event
from sqlalchemy.exc import OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column, sessionmaker
from starlette.types import ASGIApp, Receive, Scope, Send

from backend.config import get_settings
from backend.errors import Busy

# Stable constraint names so Alembic migrations can drop and alter them on every backend.
NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utcnow() -> datetime:
    return datetime.now(UTC)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)


class UTCDateTime(TypeDecorator[datetime]):
    """A timezone-aware UTC datetime on every backend: SQLite stores the UTC wall time and
    hands back naive values, which get their UTC zone back on load. Every DateTime column of
    the models is of this type, so every date the API or the CLI shows carries its offset."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        # A naive value is taken as UTC (what utcnow() and SQLite give).
        value = value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)
        return value.replace(tzinfo=None) if dialect.name == "sqlite" else value

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


class TimestampMixin:
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)


# ----- SQLite: one writer at a time, served in turn --------------------------------------

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
_REQUEST_DEADLINE: ContextVar[float | None] = ContextVar("dexlabel_request_deadline",
                                                        default=None)
# Where the scope records when the app started on a request.
_STARTED = "dexlabel.started"


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

    def before_statement(self, sql: str) -> None:
        if not self.has_turn and _writes(sql):
            # A request waits only until its own deadline (see get_session).
            deadline = _REQUEST_DEADLINE.get()
            wait_s = self.wait_s if deadline is None else deadline - time.monotonic()
            if not self.turns.acquire(wait_s):
                raise sqlite3.OperationalError(
                    f"database is locked: no turn to write came within {self.wait_s:g} s")
            self.has_turn = True

    def after_statement(self) -> None:
        # A statement outside a transaction (DDL, a failed first write) ends its own.
        if self.has_turn and not self.in_transaction:
            self.give_turn_back()

    def give_turn_back(self) -> None:
        if self.has_turn:
            self.has_turn = False
            self.turns.release()


class TurnTakingCursor(sqlite3.Cursor):
    """The cursor of a :class:`TurnTakingConnection`: each statement asks for the turn."""

    def execute(self, sql: str, parameters: Any = (), /) -> TurnTakingCursor:
        conn = cast(TurnTakingConnection, self.connection)
        conn.before_statement(sql)
        try:
            return super().execute(sql, parameters)
        finally:
            conn.after_statement()

    def executemany(self, sql: str, seq_of_parameters: Any, /) -> TurnTakingCursor:
        conn = cast(TurnTakingConnection, self.connection)
        conn.before_statement(sql)
        try:
            return super().executemany(sql, seq_of_parameters)
        finally:
            conn.after_statement()

    def executescript(self, sql_script: str, /) -> TurnTakingCursor:
        conn = cast(TurnTakingConnection, self.connection)
        conn.before_statement("SCRIPT")
        try:
            return cast(TurnTakingCursor, super().executescript(sql_script))
        finally:
            conn.after_statement()


# ----- engines --------------------------------------------------------------------------

def make_engine(url: str, *, pool_size: int = 10, max_overflow: int = 10,
                wait_s: float = 5.0) -> Engine:
    """An engine for ``url``; SQLite gets foreign keys, WAL, a created parent folder and
    writers served in turn (:class:`TurnTakingConnection`).

    ``pool_size`` connections are kept open and ``max_overflow`` more are opened under load;
    asking for one waits at most ``wait_s`` seconds (then ``sqlalchemy.exc.TimeoutError``),
    as does a SQLite writer for its turn and for the file's lock ("database is locked").
    """
    pool: dict[str, Any] = {"pool_size": pool_size, "max_overflow": max_overflow,
                            "pool_timeout": wait_s}
    if url.startswith("sqlite"):
        path = url.split("///", 1)[-1]
        memory = not path or path.startswith(":memory:") or "mode=memory" in path
        if not memory:
            Path(path.split("?", 1)[0]).parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url, connect_args={
            "check_same_thread": False, "timeout": wait_s, "factory": TurnTakingConnection},
            **({} if memory else pool))

        @event.listens_for(engine, "connect")
        def _sqlite_pragmas(dbapi_conn, _record) -> None:  # type: ignore[no-untyped-def]
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA journal_mode=WAL")
            cur.close()

        return engine
    return create_engine(url, pool_pre_ping=True, **pool)


@lru_cache
def get_engine() -> Engine:
    settings = get_settings()
    return make_engine(settings.database_url, pool_size=settings.db_pool_size,
                       max_overflow=settings.db_max_overflow, wait_s=settings.db_wait_s)


@lru_cache
def get_sessionmaker() -> sessionmaker[Session]:
    return sessionmaker(bind=get_engine(), expire_on_commit=False)


@contextmanager
def session_scope() -> Iterator[Session]:
    """One unit of work: commit on success, roll back on any error."""
    session = get_sessionmaker()()
    try:
        yield session
        session.commit()
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()


# ----- the request's session --------------------------------------------------------------

class DatabaseBusy(Busy):
    """No turn at the database came within DEXLABEL_DB_WAIT_S; the same request later works."""

    def __init__(self, detail: str, retry_after_s: int = 1) -> None:
        super().__init__(detail)
        self.headers = {"Retry-After": str(retry_after_s)}


class _SessionSlots:
    """The session slots of one event loop, handed over in arrival order, except that reads
    (GET, HEAD: a page opening, a listing) go before waiting writes (an autosave, which the
    page keeps and sends again when refused)."""

    def __init__(self, size: int) -> None:
        self.free = size
        self.reads: collections.deque[anyio.Event] = collections.deque()
        self.writes: collections.deque[anyio.Event] = collections.deque()

    async def acquire(self, timeout_s: float, *, read: bool) -> bool:
        """Wait at most ``timeout_s`` for a slot; whether one was got."""
        if self.free > 0:
            self.free -= 1
            return True
        handed = anyio.Event()
        queue = self.reads if read else self.writes
        queue.append(handed)
        try:
            with anyio.move_on_after(timeout_s):
                await handed.wait()
        except BaseException:
            self._forget(handed, queue)
            raise
        if handed.is_set():  # handed over, even if the time ran out at that moment
            return True
        queue.remove(handed)
        return False

    def _forget(self, handed: anyio.Event, queue: collections.deque[anyio.Event]) -> None:
        if handed.is_set():
            self.release()
        else:
            queue.remove(handed)

    def release(self) -> None:
        for queue in (self.reads, self.writes):
            if queue:
                queue.popleft().set()  # the slot passes straight to the next in line
                return
        self.free += 1


@dataclass(frozen=True)
class _RequestSlots:
    """One event loop's database slots: requests holding a session, and the threads their
    commits run on (never queued behind other work: a commit releases a connection)."""

    sessions: _SessionSlots
    finishers: anyio.CapacityLimiter


_SLOTS: RunVar[_RequestSlots] = RunVar("dexlabel_request_slots")
_READ_METHODS = frozenset({"GET", "HEAD"})


def _request_slots() -> _RequestSlots:
    try:
        return _SLOTS.get()
    except LookupError:
        size = get_settings().db_pool_size
        slots = _RequestSlots(_SessionSlots(size), anyio.CapacityLimiter(size))
        _SLOTS.set(slots)
        return slots


def _finish(session: Session, commit: bool) -> None:
    try:
        if commit:
            session.commit()
    finally:
        session.close()


async def get_session(request: Request) -> AsyncIterator[Session]:
    """The request's unit of work: committed before the response is sent (so a failed
    commit is the reply), rolled back on any error.

    At most DEXLABEL_DB_POOL_SIZE requests of a process hold a session at once, which is the
    number of pooled connections, so every one of them gets a connection without waiting and
    a burst queues here rather than on the pool (reads first, :class:`_SessionSlots`). A
    request waits for its turn (a session, and
    on SQLite the writer's turn) until DEXLABEL_DB_WAIT_S after the app started on it; then
    it is answered 503 with Retry-After, so an overloaded server refuses work in seconds
    instead of finishing it after the page gave up. A session holds its connection across
    the request's thread hops (dependencies, endpoint, response validation), so a request
    thread never waits on a connection that only a queued request could give back.
    """
    wait_s = get_settings().db_wait_s
    deadline = request.scope.get(_STARTED, time.monotonic()) + wait_s
    slots = _request_slots()
    if not await slots.sessions.acquire(deadline - time.monotonic(),
                                        read=request.method in _READ_METHODS):
        raise DatabaseBusy(f"the server is busy: this request got no turn at the database "
                           f"within {wait_s:g} s; please try again")
    _REQUEST_DEADLINE.set(deadline)
    try:
        session = get_sessionmaker()()
        try:
            yield session
        except BaseException:
            with anyio.CancelScope(shield=True):
                await _end(session, slots, commit=False)
            raise
        with anyio.CancelScope(shield=True):
            await _end(session, slots, commit=True)
    finally:
        slots.sessions.release()


async def _end(session: Session, slots: _RequestSlots, *, commit: bool) -> None:
    if not session.in_transaction() and not (session.new or session.dirty or session.deleted):
        session.close()  # never touched the database: nothing to send
        return
    await anyio.to_thread.run_sync(_finish, session, commit, limiter=slots.finishers)


def _busy_answer(retry_after_s: int = 1) -> JSONResponse:
    return JSONResponse({"error": Busy.code, "detail": "the database is busy; please try again"},
                        status_code=Busy.status_code,
                        headers={"Retry-After": str(retry_after_s)})


def install_request_limits(app: FastAPI) -> None:
    """Size the app's request threads from the settings (DEXLABEL_HTTP_THREADS, checked to be
    above DEXLABEL_DB_POOL_SIZE) when it starts, and answer a request that found no turn at
    the database in time 503 with Retry-After: a full pool (``sqlalchemy.exc.TimeoutError``),
    a SQLite file locked past its busy timeout, or no session slot (:class:`DatabaseBusy`)."""
    inner = app.router.lifespan_context

    @asynccontextmanager
    async def lifespan(app_: Any) -> AsyncIterator[Any]:
        limiter = anyio.to_thread.current_default_thread_limiter()
        limiter.total_tokens = get_settings().http_threads
        async with inner(app_) as state:
            yield state

    app.router.lifespan_context = lifespan
    app.add_middleware(_StartTime)

    async def _busy(_: Request, exc: Exception) -> JSONResponse:
        if isinstance(exc, DatabaseBusy):
            return JSONResponse({"error": exc.code, "detail": exc.detail},
                                status_code=exc.status_code, headers=exc.headers)
        if isinstance(exc, OperationalError) and not _is_locked(exc):
            raise exc  # any other database failure stays a server error
        return _busy_answer()

    for kind in (DatabaseBusy, PoolTimeout, OperationalError):
        app.add_exception_handler(kind, _busy)


class _StartTime:
    """Records in the scope when the app started on a request (its database deadline counts
    from there)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            scope[_STARTED] = time.monotonic()
        await self.app(scope, receive, send)


def _is_locked(exc: OperationalError) -> bool:
    return isinstance(exc.orig, sqlite3.OperationalError) and "locked" in str(exc.orig)


# Function scope: the session ends (committed) before the response is sent.
SessionDep = Annotated[Session, Depends(get_session, scope="function")]
