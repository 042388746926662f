"""What the benchmarks share: running `dexlabel serve` on a free local port for a measurement,
and timing a call."""

from __future__ import annotations

import atexit
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

START_S = 180


def isolated_workdir(name: str, **settings: str) -> Path:
    """A new temp folder holding this run's embedded database, queue and storage.

    Points this process's DEXLABEL_* environment at it (dropping any database, Redis or storage
    URL set outside), so the benchmark and the server it starts measure a fresh embedded setup.
    """
    work = Path(tempfile.mkdtemp(prefix=f"dexlabel-bench-{name}-"))
    # Removed when the benchmark exits (pass DEXLABEL_BENCH_KEEP=1 to inspect it afterwards).
    if not os.environ.get("DEXLABEL_BENCH_KEEP"):
        atexit.register(shutil.rmtree, work, ignore_errors=True)
    os.environ.update({"DEXLABEL_VAR_DIR": str(work / "var"), "DEXLABEL_ENV": "test",
                       "DEXLABEL_INPROCESS_WORKER": "false", **settings})
    for key in ("DEXLABEL_DATABASE_URL", "DEXLABEL_REDIS_URL", "DEXLABEL_STORAGE_URL"):
        os.environ.pop(key, None)
    return work


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_up(base: str, proc: subprocess.Popen) -> None:
    """Block until ``base``/healthz answers; fail if the server exits or takes over
    START_S seconds (a busy 2-core machine can take a minute to import and start it)."""
    deadline = time.monotonic() + START_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError("server exited during start-up")
        try:
            urllib.request.urlopen(f"{base}/healthz")
            return
        except OSError:
            time.sleep(0.2)
    raise RuntimeError(f"server did not start in {START_S} s")


def start_server(env: dict[str, str], port: int | None = None) -> tuple[subprocess.Popen, str]:
    """`dexlabel serve` in a child process with ``env``; returns it and its base URL once up."""
    port = port or free_port()
    base = f"http://127.0.0.1:{port}"
    proc = subprocess.Popen([sys.executable, "-m", "backend.cli", "serve", "--port", str(port)],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wait_up(base, proc)
    return proc, base


def median_ms(fn: Callable[[], Any], runs: int) -> float:
    """The median wall time of ``runs`` calls of ``fn``, ms (0.1 ms)."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1000)
    return round(statistics.median(times), 1)
