"""Database engine, sessions and the declarative base.

The request (or the queue task) is the unit of work: services only flush, and the caller
commits through ``session_scope`` or the ``SessionDep`` dependency.
"""

from __future__ import annotations

import collections
import sqlite3
import time
from collections.abc import AsyncIterator, Iterable, Iterator
from contextlib import asynccontextmanager, contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any

import anyio
from anyio.lowlevel import RunVar
from fastapi import Depends, FastAPI, Request
from fastapi.responses import JSONResponse
from sqlalchemy import (
    CheckConstraint,
    DateTime,
    Dialect,
    Engine,
    ForeignKey,
    MetaData,
    TypeDecorator,
    create_engine,
    event,
)
from sqlalchemy.exc import OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from sqlalchemy.orm import (
    DeclarativeBase,
    Mapped,
    MappedColumn,
    Session,
    mapped_column,
    sessionmaker,
)
from starlette.types import ASGIApp, Receive, Scope, Send

from backend.config import get_settings
from backend.errors import Busy
from backend.sqlite_turns import REQUEST_DEADLINE, STARTED, TurnTakingConnection

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


def parent_key(target: str, **column: Any) -> MappedColumn[Any]:
    """A column keyed to the row ``target`` ("table.id") that this row belongs to: deleting
    that row deletes this one with it."""
    return mapped_column(ForeignKey(target, ondelete="CASCADE"), **column)


def one_of(column: str, values: Iterable[str]) -> CheckConstraint:
    """The check that ``column`` holds one of ``values``, named "<column>_valid"."""
    listed = ", ".join(repr(value) for value in values)
    return CheckConstraint(f"{column} IN ({listed})", name=f"{column}_valid")


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
    deadline = request.scope.get(STARTED, time.monotonic()) + wait_s
    slots = _request_slots()
    if not await slots.sessions.acquire(deadline - time.monotonic(),
                                        read=request.method in _READ_METHODS):
        raise DatabaseBusy(f"the server is busy: this request got no turn at the database "
                           f"within {wait_s:g} s; please try again")
    REQUEST_DEADLINE.set(deadline)
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
            scope[STARTED] = time.monotonic()
        await self.app(scope, receive, send)


def _is_locked(exc: OperationalError) -> bool:
    return isinstance(exc.orig, sqlite3.OperationalError) and "locked" in str(exc.orig)


# Function scope: the session ends (committed) before the response is sent.
SessionDep = Annotated[Session, Depends(get_session, scope="function")]
