"""Benchmark: hundreds of annotators autosaving at once, and bursts of page loads, on loopback.

Starts its own `dexlabel serve` on a free local port in a new instance (a temp folder; on
PostgreSQL also a new database on the local server, dropped at the end), imports a synthetic
capture (``--capture DIR`` reuses one written by `dexlabel synth`), creates the hand tasks and
``--annotators`` direct assignment links through the admin API, then runs that many simulated
annotators (asyncio streams, one kept-alive connection each, requests encoded once as bytes
and answers read by their length: a client lean enough not to eat the cores the server
needs) for ``--seconds``: each autosaves
its full hand task (21 points keyed on every frame, PUT /api/annotate/tracks with the version
it holds) every 2 s, one save in flight at a time, giving up on a save after 15 s as the page
does.
``--bursts`` times during the run, ``--burst`` page loads start at the same moment (GET
/api/annotate/task, then the view's frame bundle). Everything is bounded: the run stops by
itself after ``--seconds`` plus the last saves' timeout, and the server is stopped at the end.

Afterwards it checks that every acknowledged save is stored (each assignment's stored version
equals the last version the server acknowledged to its annotator) and how soon the server
answers a page's read once the load stops.

Prints a JSON summary on its last line:
    saves, saves_per_s          acknowledged autosaves, and per second of the run
    save_ms                     p50, p99, max latency of acknowledged autosaves
    save_errors                 failed autosaves by kind (timeout, http_503, http_500, ...)
    page_loads, page_load_ms    page loads of the bursts that completed (task + bundle), and
                                their p50, p99, max latency; page_load_errors by kind
    lost                        assignments whose stored version is below the last acknowledged
                                one (an acknowledged save that is not in the database)
    committed_unacknowledged    assignments whose stored version is above it (a save committed
                                while its annotator had given up on the answer)
    after_burst_ms              a page read right after each burst of page loads (null: no
                                answer within 5 s)
    after_load_ms               the first page read once the load stopped (5 s at most, else
                                null and after_load_error says why)
    server_cpu_s, cpu_s_per_save
                                CPU seconds of the server process(es) during the run (autosaves
                                and page loads together), and per acknowledged save
    bench_cpu_s, bench_cpu_ms_per_save
                                CPU seconds of the client (this process and the one that
                                runs the page-load bursts) during the run, and ms per
                                acknowledged save
    bench_loop_lag_ms           how late the annotators' event loop wakes from 100 ms sleeps
                                (p50, p99, max): latencies include the client's own delay
    server_log                  counts of tracebacks and "database is locked" in its log
    stop_s                      seconds the server took to exit on SIGTERM
    load_before, load_after     the machine's 1-minute load average
    alone_cpu_ms_per_save, alone_ms_per_save
                                before the crowd starts, ``--alone`` saves of one annotator
                                back to back: the server's CPU ms per save with nothing else
                                to do (what a save costs, little moved by other load on the
                                machine), and the wall time per save;
                                alone_bench_cpu_ms_per_save: the client's own CPU per save
Usage: python bench/load.py [--db sqlite|postgres] [--annotators 200] [--seconds 60]
       [--workers 1] [--burst 100] [--bursts 2] [--seed 7] [--views 2] [--capture DIR]
       [--alone 300]
The PostgreSQL server is DEXLABEL_BENCH_POSTGRES_URL (default the local one as user postgres).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import multiprocessing
import os
import random
import signal
import subprocess
import sys
import time
import uuid
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from _server import free_port, isolated_workdir, wait_up

ADMIN = ("load@example.org", "load-bench-password-1")
SAVE_PERIOD_S = 2.0
# The annotation page gives up on a request after 15 s (frontend/annotate/api.js).
REQUEST_TIMEOUT_S = 15.0
AFTER_LOAD_LIMIT_S = 5.0
POSTGRES_URL = os.environ.get("DEXLABEL_BENCH_POSTGRES_URL",
                              "postgresql+psycopg://postgres@127.0.0.1:5432/postgres")


# ----- the instance -----------------------------------------------------------------------

def _create_database() -> tuple[str, str]:
    """A new empty database on the PostgreSQL server; returns (its URL, its name)."""
    from sqlalchemy import create_engine, text
    from sqlalchemy.engine import make_url

    admin_url = make_url(POSTGRES_URL)
    name = f"dexlabel_load_{uuid.uuid4().hex[:10]}"
    engine = create_engine(admin_url, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    engine.dispose()
    return admin_url.set(database=name).render_as_string(hide_password=False), name


def _drop_database(name: str) -> None:
    from sqlalchemy import create_engine, text

    engine = create_engine(POSTGRES_URL, isolation_level="AUTOCOMMIT")
    with engine.connect() as conn:
        conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
    engine.dispose()


def _prepare(work: Path, capture: Path | None, views: int, seed: int) -> int:
    """Synthesise (unless given) and import the capture, create the admin; the sequence id."""
    from backend.accounts.service import create_admin
    from backend.captures.flows import import_path
    from backend.config import get_settings
    from backend.db import get_engine, session_scope
    from backend.migrate import upgrade
    from worker.synth import generate_capture

    if capture is None:
        capture = work / "capture"
        generate_capture(capture, seed=seed, frames=72, views=views, objects=1)
    upgrade(get_settings().database_url)
    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as s:
        create_admin(s, *ADMIN)
    get_engine().dispose()
    return sequence_id


def _start_server(port: int, workers: int, log: Path) -> subprocess.Popen[bytes]:
    cmd = [sys.executable, "-m", "backend.cli", "serve", "--port", str(port)]
    if workers > 1:
        cmd += ["--workers", str(workers)]
    with log.open("wb") as out:
        proc = subprocess.Popen(cmd, env=os.environ.copy(), stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
    wait_up(f"http://127.0.0.1:{port}", proc)
    return proc


def _stop_server(proc: subprocess.Popen[bytes]) -> float | None:
    """SIGTERM, then the seconds until it exited (None: killed after 60 s)."""
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=60)
        return round(time.monotonic() - t0, 2)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        return None


def _tree_cpu_s(root: int) -> float:
    """CPU seconds (user + system) of ``root`` and every process below it, from /proc."""
    parents: dict[int, int] = {}
    times: dict[int, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        parents[int(entry.name)] = int(fields[1])
        times[int(entry.name)] = (int(fields[11]) + int(fields[12])) / tick
    total, todo = 0.0, [root]
    while todo:
        pid = todo.pop()
        total += times.get(pid, 0.0)
        todo.extend(p for p, parent in parents.items() if parent == pid)
    return total


def _stored_versions(database_url: str, ids: list[int]) -> dict[int, int]:
    from sqlalchemy import create_engine, text
    from sqlalchemy.pool import NullPool

    engine = create_engine(database_url, poolclass=NullPool)
    with engine.connect() as conn:
        rows = conn.execute(text("SELECT id, version FROM assignments")).all()
    engine.dispose()
    wanted = set(ids)
    return {int(r[0]): int(r[1]) for r in rows if r[0] in wanted}


def _log_counts(log: Path) -> dict[str, int]:
    text = log.read_text(errors="replace") if log.exists() else ""
    return {"tracebacks": text.count("Traceback (most recent call last)"),
            "database_is_locked": text.count("database is locked"),
            "pool_timeouts": text.count("QueuePool limit")}


# ----- the simulated crowd ----------------------------------------------------------------

@dataclass
class Annotator:
    assignment_id: int
    token: str
    bodies: tuple[bytes, bytes]  # the same tracks, alternately shifted by 0.01 px
    acked: int = 0
    version: int = 0


@dataclass
class Stats:
    save_ms: list[float] = field(default_factory=list)
    save_errors: Counter[str] = field(default_factory=Counter)
    load_ms: list[float] = field(default_factory=list)
    load_errors: Counter[str] = field(default_factory=Counter)
    after_bursts: list[dict[str, Any]] = field(default_factory=list)


def _tracks_json(rng: random.Random, frames: int, width: int, height: int, shift: float) -> str:
    tracks = []
    for point in range(21):
        x0, y0 = rng.uniform(80, width - 80), rng.uniform(80, height - 80)
        rows = [[f, round(x0 + 30 * ((f * 7 + point) % 11) / 11 + shift, 2),
                 round(y0 + 20 * ((f * 5 + point) % 7) / 7, 2), 1] for f in range(frames)]
        tracks.append({"point": point, "keyframes": rows})
    return json.dumps(tracks, separators=(",", ":"))


def _body(annotator: Annotator, edits: int) -> bytes:
    tracks = annotator.bodies[annotator.version % 2]
    head = (f'{{"version":{annotator.version},"edit_count":{edits},'
            f'"working_time_s":{2.0 * edits},"tracks":')
    return head.encode() + tracks + b"}"


def _error_kind(exc: Exception) -> str:
    import httpx

    if isinstance(exc, httpx.TimeoutException | TimeoutError):
        return "timeout"
    return type(exc).__name__


class Connection:
    """One kept-alive HTTP/1.1 connection of an annotator's page, as lean as a client gets:
    each request goes out as bytes encoded here in one write, and the answer is read by its
    Content-Length (or its chunks). A crowd's browsers run on their own machines; on this
    one the load generator shares the cores with the server, so its own cost per save is kept
    to a fraction of the server's (``bench_cpu_ms_per_save``)."""

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port
        self.reader: asyncio.StreamReader | None = None
        self.writer: asyncio.StreamWriter | None = None
        self.received = 0

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
        self.reader = self.writer = None

    def encode(self, method: str, path: str, headers: dict[str, str], body: bytes = b"") -> bytes:
        lines = [f"{method} {path} HTTP/1.1", f"Host: {self.host}:{self.port}",
                 *(f"{k}: {v}" for k, v in headers.items()), f"Content-Length: {len(body)}"]
        return ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + body

    async def request(self, raw: bytes, *, discard: bool = False) -> tuple[int, bytes]:
        """Send one encoded request; (status, body). Sent again once when a kept-alive
        connection broke before any answer came (the server had just closed it), as browsers
        do; the connection is dropped when the request fails or times out half-way. With
        ``discard`` the body is read in pieces, counted (``received``) and not kept."""
        for attempt in (0, 1):
            if self.writer is None:
                self.reader, self.writer = await asyncio.open_connection(self.host, self.port)
            try:
                self.writer.write(raw)
                await self.writer.drain()
                assert self.reader is not None
                status_line = await self.reader.readline()
                if not status_line:
                    raise ConnectionResetError("closed before an answer")
            except (ConnectionError, asyncio.IncompleteReadError):
                self.close()
                if attempt:
                    raise
                continue
            try:
                return await self._answer(status_line, discard)
            except BaseException:
                self.close()
                raise
        raise AssertionError("unreachable")

    async def _answer(self, status_line: bytes, discard: bool = False) -> tuple[int, bytes]:
        assert self.reader is not None
        status = int(status_line.split(b" ", 2)[1])
        length, chunked, close = 0, False, False
        while (line := await self.reader.readline()) not in (b"\r\n", b""):
            name, _, value = line.partition(b":")
            name = name.strip().lower()
            if name == b"content-length":
                length = int(value)
            elif name == b"transfer-encoding":
                chunked = b"chunked" in value.lower()
            elif name == b"connection":
                close = b"close" in value.lower()
        if chunked:
            parts = []
            while size := int((await self.reader.readline()).split(b";")[0], 16):
                parts.append(await self.reader.readexactly(size + 2))
            await self.reader.readline()
            body = b"".join(p[:-2] for p in parts)
            self.received = len(body)
        elif discard:
            self.received, left = length, length
            while left:
                left -= len(await self.reader.readexactly(min(left, 1 << 20)))
            body = b""
        else:
            body = await self.reader.readexactly(length)
        if close:
            self.close()
        return status, body


async def _annotate(port: int, who: Annotator, start_in: float, stop: asyncio.Event,
                    stats: Stats) -> None:
    """One annotator's page: its own connection (kept alive), one save at a time."""
    conn = Connection("127.0.0.1", port)
    try:
        await _autosave(conn, who, start_in, stop, stats)
    finally:
        conn.close()


async def _save(conn: Connection, who: Annotator, edits: int) -> tuple[int, dict[str, Any]]:
    """One autosave of the annotator's tracks from the version it holds; (status, answer).
    The page gives up after REQUEST_TIMEOUT_S in all (frontend/annotate/api.js)."""
    raw = conn.encode("PUT", "/api/annotate/tracks", {
        "Authorization": f"Bearer {who.token}", "Content-Type": "application/json"},
        _body(who, edits))
    try:
        async with asyncio.timeout(REQUEST_TIMEOUT_S):
            status, body = await conn.request(raw)
    except TimeoutError:
        conn.close()  # its answer may still come: this connection is spent
        raise
    return status, json.loads(body) if body else {}


async def _autosave(conn: Connection, who: Annotator, start_in: float, stop: asyncio.Event,
                    stats: Stats) -> None:
    loop = asyncio.get_running_loop()
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(stop.wait(), start_in)
        return
    edits = 0
    while not stop.is_set():
        edits += 1
        started = loop.time()
        try:
            status, answer = await _save(conn, who, edits)
        except Exception as exc:  # every failure of the request counts, by kind
            stats.save_errors[_error_kind(exc)] += 1
        else:
            if status == 200:
                who.version = who.acked = answer["version"]
                stats.save_ms.append((loop.time() - started) * 1000)
            else:
                stats.save_errors[f"http_{status}"] += 1
                if status == 409:  # a save that timed out was stored after all
                    who.version = answer.get("current_version", who.version)
        wait = started + SAVE_PERIOD_S - loop.time()
        if wait > 0:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), wait)


async def _page_load(port: int, token: str) -> tuple[float | None, str | None]:
    """A page opening: its own connection (a new browser), the task, then the frame bundle
    (counted, not kept), with the annotators' lean client, so that starting 100 pages costs
    this machine's cores what the server needs for them and little more. Its milliseconds,
    or the kind of its failure."""
    loop = asyncio.get_running_loop()
    started = loop.time()
    conn = Connection("127.0.0.1", port)
    try:
        async with asyncio.timeout(60.0):
            status, body = await conn.request(conn.encode(
                "GET", "/api/annotate/task", {"Authorization": f"Bearer {token}"}))
            if status != 200:
                return None, f"task_http_{status}"
            url = json.loads(body)["frames"]["bundle_url"]
            status, _ = await conn.request(conn.encode("GET", url, {}), discard=True)
            if status != 200:
                return None, f"bundle_http_{status}"
            if conn.received == 0:
                return None, "bundle_empty"
    except Exception as exc:  # every failure of the request counts, by kind
        return None, _error_kind(exc)
    finally:
        conn.close()
    return (loop.time() - started) * 1000, None


def _burst(base: str, tokens: list[str]) -> list[tuple[float | None, str | None]]:
    """Page loads of ``tokens`` started at the same moment, then a page read: run in a
    process of its own, so receiving the bundles does not slow the annotators' event loop."""

    async def run() -> list[tuple[float | None, str | None]]:
        loads = await asyncio.gather(*(_page_load(int(base.rsplit(':', 1)[1]), t)
                                       for t in tokens))
        after = await _after_load(base, tokens[0])
        return [*loads, (after.get("after_load_ms"), after.get("after_load_error"))]

    return asyncio.run(run())


async def _loop_lag(stop: asyncio.Event, lags: list[float]) -> None:
    """How late this event loop wakes from 100 ms sleeps (ms): when it is late, latencies
    measured here include the client's own delay."""
    loop = asyncio.get_running_loop()
    while not stop.is_set():
        t0 = loop.time()
        await asyncio.sleep(0.1)
        lags.append((loop.time() - t0 - 0.1) * 1000)


async def _admin(client: Any, sequence_id: int, count: int, seed: int) -> list[Annotator]:
    resp = await client.post("/api/auth/token", json={"email": ADMIN[0], "password": ADMIN[1]})
    resp.raise_for_status()
    headers = {"Authorization": f"Bearer {resp.json()['access_token']}"}
    resp = await client.post(f"/api/sequences/{sequence_id}/tasks", json={}, headers=headers)
    resp.raise_for_status()
    hand = [t for t in resp.json() if t["kind"] == "hand"]
    rng = random.Random(seed)
    bodies = {}
    for t in hand:
        state = rng.getstate()
        pair = []
        for shift in (0.0, 0.01):
            rng.setstate(state)
            pair.append(_tracks_json(rng, t["num_frames"], t["width"], t["height"], shift).encode())
        bodies[t["id"]] = (pair[0], pair[1])
    annotators = []
    for i in range(count):
        task = hand[i % len(hand)]
        resp = await client.post(f"/api/tasks/{task['id']}/assignments",
                                 json={"worker_id": f"LOAD{i:05d}"}, headers=headers)
        resp.raise_for_status()
        link = resp.json()
        annotators.append(Annotator(link["assignment_id"], link["token"], bodies[task["id"]]))
    return annotators


def _pct(values: list[float], q: float) -> float | None:
    if not values:
        return None
    ordered = sorted(values)
    return round(ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))], 1)


async def _after_load(base: str, token: str) -> dict[str, Any]:
    """The first page read once the load stopped (a new connection): its latency, or why it
    failed."""
    import httpx

    t0 = time.perf_counter()
    try:
        async with httpx.AsyncClient(base_url=base, timeout=AFTER_LOAD_LIMIT_S) as client:
            resp = await client.get("/api/annotate/task",
                                    headers={"Authorization": f"Bearer {token}"})
    except Exception as exc:  # a timeout or a refused connection is the finding
        return {"after_load_ms": None, "after_load_error": _error_kind(exc)}
    ms = round((time.perf_counter() - t0) * 1000, 1)
    if resp.status_code != 200:
        return {"after_load_ms": None, "after_load_error": f"http_{resp.status_code}"}
    return {"after_load_ms": ms}


async def _saves_alone(port: int, server_pid: int, who: Annotator, count: int
                       ) -> dict[str, Any]:
    """``count`` saves of one annotator back to back before the crowd starts: the server's CPU
    milliseconds per save with nothing else to do (a figure that the machine's other load
    hardly moves, unlike latencies), the wall time per save, and this client's CPU per save."""
    if count == 0:
        return {}
    conn = Connection("127.0.0.1", port)

    async def save(edits: int) -> None:
        status, answer = await _save(conn, who, edits)
        if status != 200:
            raise RuntimeError(f"a save alone was answered {status}: {answer}")
        who.version = who.acked = answer["version"]

    try:
        for i in range(min(count, 20)):  # warm-up
            await save(i)
        cpu0, t0, own0 = _tree_cpu_s(server_pid), time.perf_counter(), time.process_time()
        for i in range(count):
            await save(i)
        own = time.process_time() - own0
    finally:
        conn.close()
    return {"alone_saves": count,
            "alone_cpu_ms_per_save": round((_tree_cpu_s(server_pid) - cpu0) / count * 1000, 2),
            "alone_ms_per_save": round((time.perf_counter() - t0) / count * 1000, 2),
            "alone_bench_cpu_ms_per_save": round(own / count * 1000, 2)}


async def _drive(port: int, server_pid: int, sequence_id: int, args: argparse.Namespace,
                 database_url: str) -> dict[str, Any]:
    import httpx

    base = f"http://127.0.0.1:{port}"
    async with httpx.AsyncClient(base_url=base, timeout=60.0) as client:
        annotators = await _admin(client, sequence_id, args.annotators, args.seed)
    alone = await _saves_alone(port, server_pid, annotators[0], args.alone)
    rng = random.Random(args.seed)
    stats, stop = Stats(), asyncio.Event()
    loop = asyncio.get_running_loop()
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=spawn) as helper:
        helper_pid = await loop.run_in_executor(helper, os.getpid)  # started before the run
        cpu0 = _tree_cpu_s(server_pid)
        bench0, helper0 = time.process_time(), _tree_cpu_s(helper_pid)
        t0 = time.monotonic()
        lags: list[float] = []
        lag = asyncio.create_task(_loop_lag(stop, lags))
        crowd = [asyncio.create_task(_annotate(port, a, rng.uniform(0, SAVE_PERIOD_S),
                                               stop, stats)) for a in annotators]
        for i in range(args.bursts):
            at = t0 + args.seconds * (i + 1) / (args.bursts + 1)
            await asyncio.sleep(max(0.0, at - time.monotonic()))
            picks = [annotators[(i * args.burst + k) % len(annotators)].token
                     for k in range(args.burst)]
            *loads, after_burst = await loop.run_in_executor(helper, _burst, base, picks)
            for ms, error in loads:
                if error is None and ms is not None:
                    stats.load_ms.append(ms)
                else:
                    stats.load_errors[error or "unknown"] += 1
            stats.after_bursts.append({"after_load_ms": after_burst[0]})
        await asyncio.sleep(max(0.0, t0 + args.seconds - time.monotonic()))
        stop.set()
        await asyncio.gather(*crowd, lag)
        elapsed = time.monotonic() - t0
        cpu = _tree_cpu_s(server_pid) - cpu0
        bench_cpu = time.process_time() - bench0 + _tree_cpu_s(helper_pid) - helper0
    after = await _after_load(base, annotators[0].token)
    stored = _stored_versions(database_url, [a.assignment_id for a in annotators])
    lost = sum(1 for a in annotators if stored.get(a.assignment_id, 0) < a.acked)
    unacked = sum(1 for a in annotators if stored.get(a.assignment_id, 0) > a.acked)
    saves = len(stats.save_ms)
    return {
        "saves": saves, "saves_per_s": round(saves / elapsed, 1),
        "save_ms": {"p50": _pct(stats.save_ms, 0.5), "p99": _pct(stats.save_ms, 0.99),
                    "max": _pct(stats.save_ms, 1.0)},
        "save_errors": dict(stats.save_errors),
        "page_loads": len(stats.load_ms),
        "page_load_ms": {"p50": _pct(stats.load_ms, 0.5), "p99": _pct(stats.load_ms, 0.99),
                         "max": _pct(stats.load_ms, 1.0)},
        "page_load_errors": dict(stats.load_errors),
        "after_burst_ms": [a.get("after_load_ms") for a in stats.after_bursts],
        "lost": lost, "committed_unacknowledged": unacked, **after,
        "server_cpu_s": round(cpu, 1),
        "cpu_s_per_save": round(cpu / saves, 4) if saves else None,
        "bench_cpu_s": round(bench_cpu, 1),
        "bench_cpu_ms_per_save": round(bench_cpu / saves * 1000, 2) if saves else None,
        "bench_loop_lag_ms": {"p50": _pct(lags, 0.5), "p99": _pct(lags, 0.99),
                              "max": _pct(lags, 1.0)},
        "run_s": round(elapsed, 1), **alone,
    }


EPILOG = ("Default run here (2 shared cores): about 2-3 minutes (a 2 x 72 capture made, 300"
          " saves alone, 60 s of load). Short: --capture DIR (reuse a capture), --seconds 3"
          " --annotators 4 --bursts 1 --burst 2 --alone 20.")


def main() -> None:
    parser = argparse.ArgumentParser(epilog=EPILOG)
    parser.add_argument("--db", choices=("sqlite", "postgres"), default="sqlite")
    parser.add_argument("--annotators", type=int, default=200)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--workers", type=int, default=1, help="server processes")
    parser.add_argument("--burst", type=int, default=100, help="page loads per burst")
    parser.add_argument("--bursts", type=int, default=2)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--views", type=int, default=2, help="views of a new capture")
    parser.add_argument("--capture", type=Path, help="reuse this synthetic capture")
    parser.add_argument("--alone", type=int, default=300,
                        help="back-to-back saves of one annotator before the crowd (0: none)")
    args = parser.parse_args()
    if not (1 <= args.annotators <= 2000 and 1 <= args.seconds <= 1800 and 0 <= args.bursts <= 20
            and 1 <= args.burst <= 1000 and 1 <= args.workers <= 32
            and 0 <= args.alone <= 100_000):
        parser.error("out of range: --annotators 1-2000, --seconds 1-1800, --bursts 0-20, "
                     "--burst 1-1000, --workers 1-32, --alone 0-100000")

    port = free_port()
    base = f"http://127.0.0.1:{port}"
    work = isolated_workdir("load", DEXLABEL_PUBLIC_URL=base)
    database = None
    if args.db == "postgres":
        url, database = _create_database()
        os.environ["DEXLABEL_DATABASE_URL"] = url
    try:
        from backend.config import get_settings

        database_url = get_settings().database_url
        t0 = time.perf_counter()
        sequence_id = _prepare(work, args.capture, args.views, args.seed)
        prepare_s = time.perf_counter() - t0
        log = work / "server.log"
        load_before = os.getloadavg()[0]
        server = _start_server(port, args.workers, log)
        try:
            results = asyncio.run(_drive(port, server.pid, sequence_id, args, database_url))
        finally:
            stop_s = _stop_server(server)
    finally:
        if database is not None:
            _drop_database(database)
    print(json.dumps({"benchmark": "load", "db": args.db, "workers": args.workers,
                      "annotators": args.annotators, "seconds": args.seconds,
                      "burst": args.burst, "bursts": args.bursts,
                      "prepare_s": round(prepare_s, 1), **results, "stop_s": stop_s,
                      "server_log": _log_counts(log),
                      "load_before": round(load_before, 2),
                      "load_after": round(os.getloadavg()[0], 2)}))


if __name__ == "__main__":
    main()
