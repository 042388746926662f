"""One server per instance: a second `serve` or `demo` on an instance that is served refuses
with a line naming the running one, and leaves its record alone; a record whose process is
gone is replaced."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from tests.backend.cli.conftest import DEXLABEL, clean_env, free_port


def _other_live_process() -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])


def _write_record(instance: Path, pid: int, url: str = "http://127.0.0.1:8101") -> dict:
    record = {"url": url, "pid": pid, "host": socket.gethostname(),
              "started_at": "2026-01-01T00:00:00+00:00"}
    (instance / "server.json").write_text(json.dumps(record))
    return record


def test_a_live_servers_record_is_neither_overwritten_nor_removed(instance: Path) -> None:
    from backend.config import get_settings
    from backend.errors import DexlabelError
    from backend.instance import forget_server, record_server

    other = _other_live_process()
    try:
        record = _write_record(instance, other.pid)
        with pytest.raises(DexlabelError) as refused:
            record_server(get_settings(), "http://127.0.0.1:8102")
        assert refused.value.code == "already_serving"
        assert (f"already served at http://127.0.0.1:8101 (pid {other.pid}"
                in refused.value.detail)
        forget_server(get_settings())
        assert json.loads((instance / "server.json").read_text()) == record
    finally:
        other.kill()
        other.wait()
    # Its process is gone: the record is stale and the next server replaces it.
    record_server(get_settings(), "http://127.0.0.1:8102")
    replaced = json.loads((instance / "server.json").read_text())
    assert (replaced["url"], replaced["pid"]) == ("http://127.0.0.1:8102", os.getpid())


def _wait_healthy(port: int, server: subprocess.Popen[str]) -> None:
    deadline = time.monotonic() + 90
    while True:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        assert server.poll() is None, server.stderr.read() if server.stderr else ""
        assert time.monotonic() < deadline, "the server did not start"
        time.sleep(0.2)


@pytest.mark.slow
def test_a_second_serve_or_demo_on_a_served_instance_refuses_naming_the_first(
    tmp_path: Path, instance: Path,
) -> None:
    env = clean_env(DEXLABEL_VAR_DIR=str(instance), DEXLABEL_INPROCESS_WORKER="false")
    port = free_port()
    first = subprocess.Popen([*DEXLABEL, "serve", "--port", str(port)], cwd=tmp_path, env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        _wait_healthy(port, first)
        for args in (["serve", "--port", str(free_port())],
                     ["demo", "--port", str(free_port()), "--no-serve", "--frames", "2",
                      "--views", "1", "--objects", "1"]):
            done = subprocess.run([*DEXLABEL, *args], cwd=tmp_path, env=env,
                                  capture_output=True, text=True, timeout=120)
            assert done.returncode == 2, (args, done.stdout, done.stderr)
            assert done.stderr.splitlines()[-1].startswith(
                f"error: this instance is already served at http://127.0.0.1:{port} "
                f"(pid {first.pid}"), done.stderr
            assert "Traceback" not in done.stderr
            record = json.loads((instance / "server.json").read_text())
            assert (record["url"], record["pid"]) == (f"http://127.0.0.1:{port}", first.pid)
            assert httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=5).status_code == 200
        assert not (instance / "demo-capture").exists()  # the demo refused before its work
    finally:
        first.terminate()
        first.wait(timeout=30)
    assert not (instance / "server.json").exists()
