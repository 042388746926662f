"""`dexlabel serve --workers N`: several server processes on PostgreSQL; refused on SQLite."""

from __future__ import annotations

import signal
import subprocess
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.backend.cli.conftest import DEXLABEL, clean_env, free_port


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
        deadline = time.monotonic() + 90
        while True:
            assert proc.poll() is None, proc.communicate()[0]
            try:
                with urllib.request.urlopen(f"{base}/api/sequences/1/views/x/frames",
                                            timeout=5) as resp:
                    status = resp.status
            except urllib.error.HTTPError as exc:
                status = exc.code
            except OSError:
                status = 0
            if status:
                break
            assert time.monotonic() < deadline, "the server did not start in 90 s"
            time.sleep(0.3)
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
