"""A burst of requests against a server with a small database pool and few request threads.

Every request is answered, never with a 500 and never after a long hang: sessions queue for
their turn at the database instead of holding connections (or SQLite's write lock) while they
wait for a thread. A request that gets no turn within DEXLABEL_DB_WAIT_S is answered 503 with
Retry-After. The server is uvicorn in a thread of this process, on a free port.
"""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from tests.conftest import reset_caches
from tests.servers import run_async

BURST = 60


@dataclass
class Served:
    url: str
    tokens: list[str]  # one assignment of a hand task each
    assignment_ids: list[int]
    num_frames: int


def _prepare(capture: Path, count: int) -> tuple[list[str], list[int], int]:
    from backend.annotation import service
    from backend.annotation.tokens import assignment_token
    from backend.captures.flows import import_path
    from backend.db import session_scope
    from backend.storage import get_storage

    sequence_id = import_path(capture)[0].sequence_id
    tokens, ids = [], []
    with session_scope() as session:
        hands = [t for t in service.create_tasks(session, get_storage(), sequence_id)
                 if t.kind == "hand"]
        for i in range(count):
            task = service.get_task_or_raise(session, hands[i % len(hands)].id)
            assignment = service.create_assignment(session, task, f"LOAD{i}")
            tokens.append(assignment_token(task, assignment))
            ids.append(assignment.id)
        frames = hands[0].sequence.num_frames
    return tokens, ids, frames


@pytest.fixture
def serve(app_env: dict, small_capture: Path,
          monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[..., Served]]:
    """``serve(**settings)``: the app with these DEXLABEL_ settings, served in a thread."""
    import uvicorn

    started: list[tuple[uvicorn.Server, threading.Thread, socket.socket]] = []

    def start(**settings: str) -> Served:
        for name, value in settings.items():
            monkeypatch.setenv(f"DEXLABEL_{name.upper()}", value)
        reset_caches()
        tokens, ids, frames = _prepare(small_capture, BURST)
        from backend.app import create_app

        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        server = uvicorn.Server(uvicorn.Config(create_app(), log_level="warning"))
        thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
        thread.start()
        started.append((server, thread, sock))
        deadline = time.monotonic() + 15
        while not server.started:
            assert thread.is_alive() and time.monotonic() < deadline, "uvicorn did not start"
            time.sleep(0.01)
        return Served(f"http://127.0.0.1:{sock.getsockname()[1]}", tokens, ids, frames)

    yield start
    for server, thread, sock in started:
        server.should_exit = True
        thread.join(timeout=15)
        sock.close()


def _save_body(num_frames: int) -> dict:
    return {"version": 0, "edit_count": 1, "working_time_s": 2.0,
            "tracks": [{"point": p, "keyframes": [[f, 10.0 + p, 20.0 + f, 1]
                                                  for f in range(num_frames)]}
                       for p in range(21)]}


async def _burst(served: Served, timeout_s: float) -> list[httpx.Response | Exception]:
    """Every assignment saved at the same moment, with a page read beside each save."""
    body = _save_body(served.num_frames)
    limits = httpx.Limits(max_connections=2 * BURST)
    async with httpx.AsyncClient(base_url=served.url, timeout=timeout_s, limits=limits) as client:
        calls = []
        for token in served.tokens:
            headers = {"Authorization": f"Bearer {token}"}
            calls.append(client.put("/api/annotate/tracks", json=body, headers=headers))
            calls.append(client.get("/api/annotate/task", headers=headers))
        return await asyncio.gather(*calls, return_exceptions=True)


def _stored_versions(ids: list[int]) -> dict[int, int]:
    from sqlalchemy import select

    from backend.annotation.models import Assignment
    from backend.db import session_scope

    with session_scope() as session:
        rows = session.execute(select(Assignment.id, Assignment.version)
                               .where(Assignment.id.in_(ids))).all()
    return {row[0]: row[1] for row in rows}


def test_a_burst_on_a_small_pool_is_answered_in_full(serve: Callable[..., Served]) -> None:
    # Two request slots and three threads for 120 simultaneous requests: before, sessions
    # waiting for a thread kept their connections (and SQLite's write lock) while every
    # thread waited for a connection, until a 30 s timeout answered 500.
    served = serve(db_pool_size="2", db_max_overflow="0", http_threads="3", db_wait_s="20")
    t0 = time.monotonic()
    answers = run_async(lambda: _burst(served, timeout_s=25))
    took = time.monotonic() - t0
    failures = [a if isinstance(a, Exception) else f"{a.status_code} {a.text[:200]}"
                for a in answers if isinstance(a, Exception) or a.status_code != 200]
    assert not failures, failures[:5]
    assert took < 20, f"the burst took {took:.1f} s"
    # Every acknowledged save is stored.
    assert set(_stored_versions(served.assignment_ids).values()) == {1}
    # And the server answers at once afterwards.
    t0 = time.monotonic()
    page = httpx.get(f"{served.url}/api/annotate/task", timeout=5,
                     headers={"Authorization": f"Bearer {served.tokens[0]}"})
    assert page.status_code == 200 and time.monotonic() - t0 < 5


def test_a_request_that_gets_no_connection_in_time_is_answered_503_with_retry_after(
    serve: Callable[..., Served],
) -> None:
    served = serve(db_pool_size="1", db_max_overflow="0", http_threads="4", db_wait_s="0.5")
    from backend.db import get_engine

    # Hold the pool's only connection: the first request gets the one request slot and waits
    # for a connection, the second waits for the slot; both give up after 0.5 s.
    held = get_engine().connect()
    try:
        t0 = time.monotonic()

        async def two() -> list[httpx.Response]:
            async with httpx.AsyncClient(base_url=served.url, timeout=10) as client:
                headers = {"Authorization": f"Bearer {served.tokens[0]}"}
                return list(await asyncio.gather(
                    client.get("/api/annotate/task", headers=headers),
                    client.put("/api/annotate/tracks", json=_save_body(served.num_frames),
                               headers=headers)))

        answers = run_async(two)
        took = time.monotonic() - t0
    finally:
        held.close()
    for answer in answers:
        assert answer.status_code == 503, answer.text
        assert answer.json()["error"] == "busy"
        assert int(answer.headers["Retry-After"]) >= 1
    assert took < 5
    # Nothing of the refused save was written; with the connection back, it goes through.
    assert _stored_versions(served.assignment_ids[:1]) == {served.assignment_ids[0]: 0}
    saved = httpx.put(f"{served.url}/api/annotate/tracks", json=_save_body(served.num_frames),
                      headers={"Authorization": f"Bearer {served.tokens[0]}"}, timeout=10)
    assert saved.status_code == 200 and saved.json()["version"] == 1


@pytest.mark.parametrize("database_url", ["sqlite"], indirect=True)
def test_sqlite_writers_wait_their_turn_and_give_up_with_503(
    serve: Callable[..., Served],
) -> None:
    served = serve(db_wait_s="0.5")
    from sqlalchemy import text

    from backend.db import get_engine

    # Another writer of this process holds the turn (an open write transaction).
    with get_engine().connect() as conn:
        conn.execute(text("UPDATE assignments SET edit_count = 7 WHERE id = :id"),
                      {"id": served.assignment_ids[1]})
        t0 = time.monotonic()
        refused = httpx.put(f"{served.url}/api/annotate/tracks",
                            json=_save_body(served.num_frames), timeout=10,
                            headers={"Authorization": f"Bearer {served.tokens[0]}"})
        took = time.monotonic() - t0
        # Reads do not wait for writers.
        page = httpx.get(f"{served.url}/api/annotate/task", timeout=10,
                         headers={"Authorization": f"Bearer {served.tokens[0]}"})
        conn.rollback()
    assert refused.status_code == 503, refused.text
    assert refused.json()["error"] == "busy" and "Retry-After" in refused.headers
    assert 0.4 < took < 5
    assert page.status_code == 200
    saved = httpx.put(f"{served.url}/api/annotate/tracks", json=_save_body(served.num_frames),
                      headers={"Authorization": f"Bearer {served.tokens[0]}"}, timeout=10)
    assert saved.status_code == 200 and saved.json()["version"] == 1


def test_reads_get_a_free_session_slot_before_waiting_writes() -> None:
    import anyio

    from backend.db import _SessionSlots

    order: list[str] = []

    async def main() -> None:
        slots = _SessionSlots(1)
        assert await slots.acquire(0, read=False)  # the one slot is taken

        async def wait(name: str, read: bool) -> None:
            if await slots.acquire(5, read=read):
                order.append(name)
                slots.release()

        async with anyio.create_task_group() as tg:
            tg.start_soon(wait, "write", False)
            await anyio.sleep(0.05)
            tg.start_soon(wait, "read", True)
            await anyio.sleep(0.05)
            slots.release()
        # Nobody waits: a slot is free again, and a wait that runs out gets none.
        assert await slots.acquire(0, read=False)
        assert not await slots.acquire(0.05, read=True)

    run_async(main)
    assert order == ["read", "write"]
