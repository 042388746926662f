"""Throwaway PostgreSQL and Redis servers for outage tests and drills: each on a free local
port with its own data folder, stopped and started again at will. The machine's own servers
are never touched.

PostgreSQL's binaries come from /usr/lib/postgresql/*/bin (or the PATH); run as root, the
server runs as the ``postgres`` user, which initdb requires.
"""

from __future__ import annotations

import asyncio
import glob
import os
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")


class Unavailable(RuntimeError):
    """The server's binaries are not installed here."""


def run_async(main: Callable[[], Awaitable[T]]) -> T:
    """``asyncio.run(main())`` in a thread of its own: a test's thread may run an event loop
    already (Playwright's sync API keeps one running for the rest of a process that ran a
    browser test), where asyncio.run refuses."""

    async def _main() -> T:
        return await main()

    with ThreadPoolExecutor(1) as pool:
        return pool.submit(asyncio.run, _main()).result()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _listening(port: int) -> bool:
    with socket.socket() as sock:
        sock.settimeout(0.2)
        return sock.connect_ex(("127.0.0.1", port)) == 0


def wait_for(predicate: Callable[[], Any], what: str, timeout_s: float = 30.0,
             interval_s: float = 0.05) -> Any:
    """The first true value ``predicate()`` returns, polling every ``interval_s``; TimeoutError
    naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(interval_s)
    raise TimeoutError(f"timed out after {timeout_s:g} s waiting for {what}")


def _pg_bin(name: str) -> str:
    found = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"))
    path = found[-1] if found else shutil.which(name)
    if not path:
        raise Unavailable(f"PostgreSQL's {name} is not installed")
    return path


class ThrowawayPostgres:
    """``start()`` / ``stop()`` a PostgreSQL cluster of its own; ``url`` is its SQLAlchemy URL
    (trust authentication, user postgres, database postgres)."""

    def __init__(self) -> None:
        self.port = free_port()
        self._as_root = os.geteuid() == 0
        # Under /tmp (not a root-only pytest folder): the postgres user must reach it.
        self.root = Path(tempfile.mkdtemp(prefix="dexlabel-pg-"))
        self.data = self.root / "data"
        if self._as_root:
            shutil.chown(self.root, "postgres")
        self._run(_pg_bin("initdb"), "-D", str(self.data), "-A", "trust", "-U", "postgres",
                  "-E", "UTF8", "--no-sync")

    @property
    def url(self) -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/postgres"

    def _run(self, *argv: str) -> None:
        command = (["runuser", "-u", "postgres", "--"] if self._as_root else []) + list(argv)
        subprocess.run(command, check=True, capture_output=True, timeout=120)

    def start(self) -> ThrowawayPostgres:
        self._run(_pg_bin("pg_ctl"), "-D", str(self.data), "-l", str(self.root / "server.log"),
                  "-w", "-o", f"-p {self.port} -k {self.root} -c listen_addresses=127.0.0.1 "
                  "-c fsync=off -c full_page_writes=off", "start")
        return self

    def stop(self) -> None:
        """Stop at once, as a crash or a lost server would (no clean shutdown of clients)."""
        self._run(_pg_bin("pg_ctl"), "-D", str(self.data), "-m", "immediate", "-w", "stop")

    def running(self) -> bool:
        return _listening(self.port)

    def remove(self) -> None:
        if self.running():
            self.stop()
        shutil.rmtree(self.root, ignore_errors=True)


class ThrowawayRedis:
    """``start()`` / ``stop()`` a Redis without persistence: restarted, it is empty, as a Redis
    that lost its memory is."""

    def __init__(self) -> None:
        if not shutil.which("redis-server"):
            raise Unavailable("redis-server is not installed")
        self.port = free_port()
        self.root = Path(tempfile.mkdtemp(prefix="dexlabel-redis-"))
        self._proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> ThrowawayRedis:
        log = (self.root / "server.log").open("ab")
        self._proc = subprocess.Popen(
            ["redis-server", "--port", str(self.port), "--bind", "127.0.0.1", "--save", "",
             "--appendonly", "no", "--dir", str(self.root)], stdout=log, stderr=log)
        wait_for(lambda: _listening(self.port), f"Redis on port {self.port}")
        return self

    def stop(self) -> None:
        if self._proc is not None:
            self._proc.kill()
            self._proc.wait(timeout=10)
            self._proc = None
        wait_for(lambda: not _listening(self.port), "Redis to stop")

    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def remove(self) -> None:
        if self.running():
            self.stop()
        shutil.rmtree(self.root, ignore_errors=True)
