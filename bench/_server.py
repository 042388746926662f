"""What the benchmarks share: running `dexlabel serve` on a free local port for a measurement."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
import urllib.request


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_up(base: str, proc: subprocess.Popen) -> None:
    """Block until ``base``/healthz answers; fail if the server exits or takes over 60 s."""
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError("server exited during start-up")
        try:
            urllib.request.urlopen(f"{base}/healthz")  # noqa: S310 - local server
            return
        except OSError:
            time.sleep(0.2)
    raise RuntimeError("server did not start in 60 s")


def start_server(env: dict[str, str], port: int | None = None) -> tuple[subprocess.Popen, str]:
    """`dexlabel serve` in a child process with ``env``; returns it and its base URL once up."""
    port = port or free_port()
    base = f"http://127.0.0.1:{port}"
    proc = subprocess.Popen([sys.executable, "-m", "backend.cli", "serve", "--port", str(port)],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wait_up(base, proc)
    return proc, base
