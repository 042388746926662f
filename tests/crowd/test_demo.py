"""`dexlabel demo --no-serve` in a subprocess: a small capture is imported, its tasks published
on the built-in marketplace, a simulated crowd submits work through the served app, and a
re-run adds nothing."""

from __future__ import annotations

import os
import socket
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

# 3 views x (1 hand + 1 object) = 6 tasks; 2 assignments per HIT; 2 workers per hand task.
DEMO_ARGS = ["--no-serve", "--frames", "6", "--views", "3", "--objects", "1",
             "--assignments", "2"]


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _run_demo(var_dir: Path, port: int, *extra: str) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEXLABEL_")}
    env.update({"DEXLABEL_VAR_DIR": str(var_dir), "DEXLABEL_INPROCESS_WORKER": "false"})
    proc = subprocess.run(
        [sys.executable, "-m", "backend.cli", "demo", "--port", str(port), *DEMO_ARGS, *extra],
        env=env, cwd=var_dir.parent, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def _counts(var_dir: Path) -> dict[str, object]:
    with sqlite3.connect(var_dir / "dexlabel.db") as db:
        return {
            "tasks": db.execute("SELECT kind, count(*) FROM tasks GROUP BY kind ORDER BY kind"
                                ).fetchall(),
            "hits": db.execute("SELECT count(*), sum(max_assignments) FROM crowd_hits"
                               ).fetchone(),
            "market_hits": db.execute("SELECT count(*) FROM market_hits").fetchone()[0],
            "submitted": db.execute(
                "SELECT t.kind, count(*) FROM assignments a JOIN tasks t ON t.id = a.task_id "
                "WHERE a.status = 'submitted' GROUP BY t.kind ORDER BY t.kind").fetchall(),
            "verified": db.execute("SELECT count(*) FROM crowd_submissions").fetchone()[0],
            "workers": db.execute("SELECT count(DISTINCT worker_id) FROM crowd_submissions"
                                  ).fetchone()[0],
        }


@pytest.mark.slow
def test_demo_publishes_and_fills_itself_with_simulated_submissions_once(
    tmp_path: Path,
) -> None:
    var_dir = tmp_path / "var"
    out = _run_demo(var_dir, _free_port())
    assert "hand tasks: 3 HITs created, 0 recovered, 3 published in all" in out
    assert "6 of 6 simulated workers submitted; 6 submissions synced" in out
    first = _counts(var_dir)
    assert first["tasks"] == [("hand", 3), ("object", 3)]
    assert first["hits"] == (6, 12) and first["market_hits"] == 6
    # Hand HITs are offered first: the six workers fill the three hand tasks twice.
    assert first["submitted"] == [("hand", 6)]
    assert (first["verified"], first["workers"]) == (6, 6)

    again = _run_demo(var_dir, _free_port())
    assert "hand tasks: 0 HITs created, 0 recovered, 3 published in all" in again
    assert "simulated crowd skipped: 6 submissions already in the demo" in again
    assert _counts(var_dir) == first
