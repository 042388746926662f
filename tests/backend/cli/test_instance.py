"""One instance, found from anywhere: a command outside an instance says so and creates
nothing; serve records its address, which the requester client and `crowd sync` in another
process use; a marketplace that does not answer is named with its setting."""

from __future__ import annotations

import http.client
import json
import os
import sqlite3
import subprocess
import time
from pathlib import Path

import httpx
import pytest
from typer.testing import CliRunner

from backend.cli import app
from tests.backend.cli.conftest import DEXLABEL, clean_env, free_port


def _run(args: list[str], cwd: Path, **settings: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*DEXLABEL, *args], cwd=cwd, env=clean_env(**settings),
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args", [["qc", "reports", "1"], ["jobs", "list"], ["crowd", "sync"],
                                  ["tasks", "create", "1"], ["serve"]])
def test_a_command_outside_an_instance_names_the_setting_and_leaves_nothing(
    tmp_path: Path, args: list[str],
) -> None:
    done = _run(args, tmp_path)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.startswith("error: no migrated database at var/dexlabel.db")
    assert "DEXLABEL_VAR_DIR" in done.stderr and "dexlabel migrate" in done.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_folder_with_an_unmigrated_database_is_not_an_instance(tmp_path: Path) -> None:
    (tmp_path / "var").mkdir()
    (tmp_path / "var" / "dexlabel.db").touch()
    done = _run(["qc", "workers"], tmp_path)
    assert done.returncode == 2
    assert "no migrated database" in done.stderr


def test_help_needs_no_instance(tmp_path: Path) -> None:
    for args in (["qc", "reports", "--help"], ["qc"], ["--help"]):
        done = _run(args, tmp_path)
        # Help asked for is on stdout; a group named alone shows it on stderr (exit 2).
        assert "Usage" in (done.stdout if "--help" in args else done.stderr), (args, done)
        assert "no migrated database" not in done.stderr
    assert list(tmp_path.iterdir()) == []


def test_settings_point_at_the_instance_from_any_folder(tmp_path: Path, instance: Path) -> None:
    done = _run(["jobs", "list"], tmp_path, DEXLABEL_VAR_DIR=str(instance))
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "no jobs"


def test_the_recorded_server_is_the_requester_endpoint(instance: Path) -> None:
    from backend.config import get_settings
    from backend.crowd.client import make_client
    from backend.instance import forget_server, public_url, record_server

    settings = get_settings()
    assert make_client(settings).meta.endpoint_url == "http://127.0.0.1:8000/mturk"
    record_server(settings, "http://127.0.0.1:8101")
    assert json.loads((instance / "server.json").read_text())["pid"] == os.getpid()
    assert public_url(settings) == "http://127.0.0.1:8101"
    assert make_client(settings).meta.endpoint_url == "http://127.0.0.1:8101/mturk"
    forget_server(settings)
    assert not (instance / "server.json").exists()
    assert make_client(settings).meta.endpoint_url == "http://127.0.0.1:8000/mturk"


def test_a_record_left_by_a_dead_server_is_ignored(instance: Path) -> None:
    from backend.config import get_settings
    from backend.instance import SERVER_FILE, recorded_server

    record = {"url": "http://127.0.0.1:8101", "pid": 2**22 + 12345,
              "host": __import__("socket").gethostname()}
    (instance / SERVER_FILE).write_text(json.dumps(record))
    assert recorded_server(get_settings()) is None


def test_public_url_set_wins_over_the_record(instance: Path, monkeypatch: pytest.MonkeyPatch
                                              ) -> None:
    from backend.config import get_settings
    from backend.instance import public_url, record_server

    record_server(get_settings(), "http://127.0.0.1:8101")
    monkeypatch.setenv("DEXLABEL_PUBLIC_URL", "http://example.test:9000")
    get_settings.cache_clear()
    assert public_url(get_settings()) == "http://example.test:9000"


def _tasks(cli: CliRunner, capture: Path) -> None:
    assert cli.invoke(app, ["import", str(capture)]).exit_code == 0
    assert cli.invoke(app, ["tasks", "create", "1"]).exit_code == 0


def test_an_unreachable_marketplace_is_one_line_naming_url_and_setting(
    instance: Path, cli: CliRunner, monkeypatch: pytest.MonkeyPatch, small_capture: Path,
) -> None:
    from backend.config import get_settings

    _tasks(cli, small_capture)
    port = free_port()
    monkeypatch.setenv("DEXLABEL_PUBLIC_URL", f"http://127.0.0.1:{port}")
    get_settings.cache_clear()
    done = cli.invoke(app, ["publish", "--sequence", "1"])
    assert done.exit_code == 2, done.output
    error = done.output.splitlines()[-1]
    assert error == (f"error: the marketplace at http://127.0.0.1:{port}/mturk cannot be "
                     "reached (no connection); check DEXLABEL_PUBLIC_URL (the built-in "
                     "marketplace is served at its /mturk)")
    assert "Traceback" not in done.output


def test_an_unreachable_endpoint_setting_is_named(
    instance: Path, cli: CliRunner, monkeypatch: pytest.MonkeyPatch, small_capture: Path,
) -> None:
    from backend.config import get_settings

    _tasks(cli, small_capture)
    monkeypatch.setenv("DEXLABEL_MTURK_ENDPOINT_URL", f"https://127.0.0.1:{free_port()}")
    get_settings.cache_clear()
    done = cli.invoke(app, ["publish"])
    assert done.exit_code == 2
    assert done.output.splitlines()[-1].endswith(
        "cannot be reached (no connection); check DEXLABEL_MTURK_ENDPOINT_URL")


def _idle_connection_is_kept(port: int) -> None:
    """A client that pauses between calls (a worker's page, a requester's boto3 client) reuses
    its connection: the server must not have closed it a few seconds into the pause, or the
    next request is lost unanswered (uvicorn's own default closes it after 5 s)."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.request("GET", "/healthz")
        first = conn.getresponse()
        first.read()
        assert first.status == 200
        time.sleep(6.5)
        conn.request("GET", "/healthz")
        again = conn.getresponse()
        again.read()
        assert again.status == 200
    finally:
        conn.close()


@pytest.mark.slow
def test_commands_in_another_terminal_reach_the_server_on_its_port(
    tmp_path: Path, instance: Path, cli: CliRunner, small_capture: Path,
) -> None:
    _tasks(cli, small_capture)
    port = free_port()
    settings = {"DEXLABEL_VAR_DIR": str(instance), "DEXLABEL_INPROCESS_WORKER": "false"}
    server = subprocess.Popen([*DEXLABEL, "serve", "--port", str(port)], cwd=tmp_path,
                              env=clean_env(**settings), stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                assert server.poll() is None, server.stderr.read() if server.stderr else ""
                assert time.monotonic() < deadline, "the server did not start"
                time.sleep(0.2)
        record = json.loads((instance / "server.json").read_text())
        assert record["url"] == f"http://127.0.0.1:{port}"
        _idle_connection_is_kept(port)
        done = _run(["publish", "--sequence", "synth-subject-01/synth_000003",
                     "--min-approval-rate", "0"], tmp_path, **settings)
        assert done.returncode == 0, done.stderr
        assert "published: 9 created, 0 recovered, 0 already published" in done.stdout
        # The HITs open the annotation page on the server's own port.
        with sqlite3.connect(instance / "dexlabel.db") as db:
            questions = [q for (q,) in db.execute("SELECT question FROM market_hits")]
        assert len(questions) == 9
        assert all(f"http://127.0.0.1:{port}/annotate/" in q for q in questions)
        done = _run(["crowd", "sync"], tmp_path, **settings)
        assert done.returncode == 0, done.stderr
        assert done.stdout.startswith("9 HITs: 0 new submissions accepted")
    finally:
        server.terminate()
        server.wait(timeout=30)
    assert not (instance / "server.json").exists()
    done = _run(["crowd", "sync"], tmp_path, **settings)
    assert done.returncode == 2
    assert done.stderr.startswith("error: the marketplace at http://127.0.0.1:8000/mturk cannot")
    assert "no `dexlabel serve` or `dexlabel demo` of this instance is running" in done.stderr
