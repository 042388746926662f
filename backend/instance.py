"""The instance a command works on: its folder (``DEXLABEL_VAR_DIR``), its migrated database,
and the address its server is serving at.

A command that needs the database first checks that a migrated one is there, before any
engine is made (making a SQLite engine creates the file's folder), so a command run in the
wrong folder says so and leaves nothing behind. ``dexlabel serve`` and ``dexlabel demo``
record the address they serve at in ``{var_dir}/server.json`` and remove it when they stop;
one server per instance: a second one refuses while the recorded one is alive, and a record
whose process is gone is replaced;
commands in another terminal (``crowd sync``, ``crowd bonus``, ``publish``) reach the built-in
marketplace there unless ``DEXLABEL_PUBLIC_URL`` or ``DEXLABEL_MTURK_ENDPOINT_URL`` says
otherwise.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

from backend.config import Settings
from backend.errors import DexlabelError

SERVER_FILE = "server.json"
MIGRATIONS_TABLE = "alembic_version"


class NoInstance(DexlabelError, status_code=400, code="no_instance"):
    """No migrated database where the settings point."""


class AlreadyServing(DexlabelError, status_code=409, code="already_serving"):
    """A live server of this instance recorded its address: one server per instance."""


def _safe_url(url: str) -> str:
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)


def sqlite_path(database_url: str) -> Path | None:
    """The file of a SQLite URL (None for other databases and for in-memory SQLite)."""
    if not database_url.startswith("sqlite"):
        return None
    path = database_url.split("///", 1)[-1] if "///" in database_url else ""
    path = path.split("?", 1)[0]
    return Path(path) if path and path != ":memory:" else None


def _sqlite_migrated(path: Path) -> bool:
    if not path.is_file():
        return False
    # mode=rw opens the existing file only: a missing one is an error, never created.
    try:
        with sqlite3.connect(f"file:{path.as_posix()}?mode=rw", uri=True) as db:
            return db.execute(f"SELECT 1 FROM {MIGRATIONS_TABLE} LIMIT 1").fetchone() is not None
    except sqlite3.Error:
        return False


def _server_migrated(database_url: str) -> bool:
    from sqlalchemy import create_engine, inspect, text
    from sqlalchemy.pool import NullPool

    engine = create_engine(database_url, poolclass=NullPool)
    try:
        with engine.connect() as conn:
            if not inspect(conn).has_table(MIGRATIONS_TABLE):
                return False
            return conn.execute(text(f"SELECT 1 FROM {MIGRATIONS_TABLE}")).first() is not None
    except Exception as exc:  # any driver's failure to connect reads the same
        raise NoInstance(f"cannot reach the database at {_safe_url(database_url)} "
                         f"(DEXLABEL_DATABASE_URL): {str(exc).splitlines()[0]}") from exc
    finally:
        engine.dispose()


def database_ready(settings: Settings) -> bool:
    """Whether the settings' database exists and carries Alembic's version table."""
    path = sqlite_path(settings.database_url)
    if path is not None:
        return _sqlite_migrated(path)
    if settings.is_sqlite:
        return False  # in-memory SQLite: nothing survives between commands
    return _server_migrated(settings.database_url)


def require_database(settings: Settings) -> None:
    """Refuse to go on without a migrated database, naming where it was looked for.

    Raises:
        NoInstance: with the instance folder, the setting that moves it and the command that
            creates a database there.
    """
    if database_ready(settings):
        return
    path = sqlite_path(settings.database_url)
    where = (f"no migrated database at {path}" if path is not None
             else f"the database at {_safe_url(settings.database_url)} is not migrated")
    folder = settings.var_dir if settings.var_dir.is_absolute() else Path.cwd() / settings.var_dir
    raise NoInstance(
        f"{where}: this is not a dexlabel instance (instance folder {folder}). "
        "Set DEXLABEL_VAR_DIR to the instance's folder, or run `dexlabel migrate` to create "
        "one here")


# --- the server's address ---------------------------------------------------------------


def server_file(settings: Settings) -> Path:
    return settings.var_dir / SERVER_FILE


def client_url(host: str, port: int) -> str:
    """The address a client on this machine uses for a server bound to ``host:port``."""
    if host in ("0.0.0.0", ""):
        host = "127.0.0.1"
    elif host == "::":
        host = "::1"
    if ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{port}"


def record_server(settings: Settings, url: str) -> Path:
    """Write where this process serves; :func:`forget_server` removes it on the way out.

    Raises:
        AlreadyServing: another live server of this instance recorded its address (its
            record is left as it is).
    """
    path = server_file(settings)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _locked(path.parent):
        _refuse_live_record(path)
        record = {"url": url, "pid": os.getpid(), "host": socket.gethostname(),
                  "started_at": datetime.now(UTC).isoformat(timespec="seconds")}
        partial = path.with_name(path.name + ".partial")
        partial.write_text(json.dumps(record, indent=2) + "\n")
        partial.replace(path)
    return path


def refuse_second_server(settings: Settings) -> None:
    """Refuse to start a server while another live one serves this instance (the check a
    command makes before its slow preparations; :func:`record_server` makes it again).

    Raises:
        AlreadyServing: naming the running server's address and process id.
    """
    path = server_file(settings)
    if path.parent.is_dir():
        with _locked(path.parent):
            _refuse_live_record(path)


def forget_server(settings: Settings) -> None:
    """Remove this process's record (a record another server wrote since is left alone)."""
    path = server_file(settings)
    if not path.parent.is_dir():
        return
    with _locked(path.parent):
        record = _read_record(path)
        if record is not None and record.get("pid") == os.getpid():
            path.unlink(missing_ok=True)


@contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on the instance folder: two servers starting at once read and
    write the record one after the other."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing the descriptor releases the lock


def _refuse_live_record(path: Path) -> None:
    """Raise AlreadyServing when the record names a live process of this machine other than
    this one. A record of a process that is gone, or of this process, is stale; so is one
    written on another machine, since an instance folder belongs to one host (a container
    started again on the same folder gets a new host name)."""
    record = _read_record(path)
    if record is None or record.get("pid") == os.getpid():
        return
    if record.get("host") != socket.gethostname() or not _alive(record.get("pid")):
        return
    since = f", since {record['started_at']}" if isinstance(record.get("started_at"), str) else ""
    raise AlreadyServing(
        f"this instance is already served at {str(record['url']).rstrip('/')} (pid "
        f"{record.get('pid')}{since}; recorded in {path.name}): one server per instance. "
        "Stop that one first, or set DEXLABEL_VAR_DIR to another instance folder",
        url=record["url"], pid=record.get("pid"))


def _read_record(path: Path) -> dict | None:
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and isinstance(record.get("url"), str) else None


def _alive(pid: object) -> bool:
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process, alive
    return True


def recorded_server(settings: Settings) -> str | None:
    """The URL a running ``serve``/``demo`` of this instance recorded (None when no server is
    recorded, or its process on this machine is gone)."""
    record = _read_record(server_file(settings))
    if record is None:
        return None
    if record.get("host") == socket.gethostname() and not _alive(record.get("pid")):
        return None
    return str(record["url"]).rstrip("/")


def public_url(settings: Settings) -> str:
    """The app's public address: ``DEXLABEL_PUBLIC_URL`` when set, else the address this
    instance's running server recorded, else the default."""
    if "public_url" in settings.model_fields_set:
        return settings.public_url
    return recorded_server(settings) or settings.public_url


def serve_at(host: str, port: int) -> Settings:
    """The settings of a process that serves at ``host:port``: PUBLIC_URL is that address
    unless one was configured (the HITs' page links and the requester client must reach
    it)."""
    from backend.config import get_settings

    if "public_url" not in get_settings().model_fields_set:
        os.environ["DEXLABEL_PUBLIC_URL"] = client_url(host, port)
        get_settings.cache_clear()
    return get_settings()


def adopt_recorded_server() -> None:
    """For a command run beside a server (``publish``, ``crowd sync``): unless PUBLIC_URL is
    configured, this process's PUBLIC_URL becomes the address the running server recorded."""
    from backend.config import get_settings

    settings = get_settings()
    if "public_url" in settings.model_fields_set:
        return
    url = recorded_server(settings)
    if url:
        os.environ["DEXLABEL_PUBLIC_URL"] = url
        get_settings.cache_clear()
