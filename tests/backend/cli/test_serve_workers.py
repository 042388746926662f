"""`dexlabel serve --workers N`: several server processes on PostgreSQL; refused on SQLite; the
server processes end when their supervisor is killed."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.backend.cli.conftest import DEXLABEL, clean_env, free_port


def _wait_serving(proc: subprocess.Popen[str], base: str, seconds: float = 90) -> int:
    """The status of the first HTTP answer from ``base`` (the server is up)."""
    deadline = time.monotonic() + seconds
    while True:
        assert proc.poll() is None, proc.communicate()[0]
        try:
            with urllib.request.urlopen(f"{base}/api/sequences/1/views/x/frames",
                                        timeout=5) as resp:
                return int(resp.status)
        except urllib.error.HTTPError as exc:
            return exc.code
        except OSError:
            pass
        assert time.monotonic() < deadline, f"the server did not start in {seconds:.0f} s"
        time.sleep(0.3)


def _children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True, check=False)
    return [int(p) for p in out.stdout.split()]


def _running(pid: int) -> bool:
    """Whether ``pid`` is a live process (an exited one not yet reaped counts as gone)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _port_free(port: int) -> bool:
    """Whether a new server could listen on ``port`` (bound as uvicorn binds)."""
    with socket.socket() as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(("127.0.0.1", port))
        except OSError:
            return False
        return True


def test_several_processes_are_refused_on_sqlite(cli: CliRunner, instance: Path) -> None:
    from backend.cli import app

    result = cli.invoke(app, ["serve", "--workers", "2", "--port", str(free_port())])
    assert result.exit_code == 2, result.output
    assert "--workers 2 needs PostgreSQL (DEXLABEL_DATABASE_URL)" in result.output
    assert not (instance / "server.json").exists()


@pytest.mark.postgres
def test_several_processes_serve_one_port_on_postgresql(
    tmp_path: Path, postgres_server_url: str,
) -> None:
    from backend.migrate import upgrade

    upgrade(postgres_server_url)
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    env = clean_env(DEXLABEL_VAR_DIR=str(tmp_path / "var"), DEXLABEL_ENV="test",
                    DEXLABEL_DATABASE_URL=postgres_server_url,
                    DEXLABEL_INPROCESS_WORKER="false")
    proc = subprocess.Popen([*DEXLABEL, "serve", "--workers", "2", "--port", str(port)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        status = _wait_serving(proc, base)
        assert status == 401  # the API answers (no token), from a database-backed app
        assert (tmp_path / "var" / "server.json").exists()
        children = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True,
                                  text=True, check=False).stdout.split()
        assert len(children) >= 2, children
    finally:
        proc.send_signal(signal.SIGTERM)
        output = proc.communicate(timeout=60)[0]
    assert proc.returncode == 0, output
    assert not (tmp_path / "var" / "server.json").exists()


@pytest.mark.postgres
def test_server_processes_end_when_their_supervisor_is_killed(
    tmp_path: Path, postgres_server_url: str,
) -> None:
    from backend.migrate import upgrade

    upgrade(postgres_server_url)
    port = free_port()
    env = clean_env(DEXLABEL_VAR_DIR=str(tmp_path / "var"), DEXLABEL_ENV="test",
                    DEXLABEL_DATABASE_URL=postgres_server_url,
                    DEXLABEL_INPROCESS_WORKER="false")
    proc = subprocess.Popen([*DEXLABEL, "serve", "--workers", "2", "--port", str(port)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    children: list[int] = []
    try:
        assert _wait_serving(proc, f"http://127.0.0.1:{port}") == 401
        deadline = time.monotonic() + 60
        while len(children) < 2:  # both server processes (and any helper of the supervisor)
            assert time.monotonic() < deadline, "two server processes did not start in 60 s"
            time.sleep(0.2)
            children = _children(proc.pid)
        proc.kill()
        proc.wait(timeout=30)
        deadline = time.monotonic() + 10
        while any(map(_running, children)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [p for p in children if _running(p)], "server processes outlived the kill"
        assert _port_free(port), f"port {port} is still held after the server processes ended"
    finally:
        proc.kill()
        for pid in children:
            if _running(pid):
                os.kill(pid, signal.SIGKILL)
        proc.communicate(timeout=30)
