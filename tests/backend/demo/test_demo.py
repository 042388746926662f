"""`dexlabel demo --no-serve` as a new user runs it: a small capture is imported, every task
(object tasks too) published and worked by the simulated crowd until it has accepted work, QC
and the solve finish, and the links print with ready logins kept in the instance; a re-run adds
nothing and prints the same logins."""

from __future__ import annotations

import json
import re
import sqlite3
import stat
import subprocess
from pathlib import Path

import pytest

from tests.backend.cli.conftest import DEXLABEL, clean_env, free_port

DEMO_ARGS = ["--no-serve", "--frames", "12", "--views", "3", "--objects", "1"]
LOGIN = re.compile(r"^(worker portal|admin page): +(http://\S+) +email (\S+) +password (\S+)$",
                   re.MULTILINE)


def run_demo(var_dir: Path, *extra: str) -> str:
    """The demo in a subprocess with only DEXLABEL_VAR_DIR set; its output (exit 0)."""
    done = subprocess.run(
        [*DEXLABEL, "demo", "--port", str(free_port()), *DEMO_ARGS, *extra],
        env=clean_env(DEXLABEL_VAR_DIR=str(var_dir)), cwd=var_dir.parent,
        capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def logins(out: str) -> dict[str, tuple[str, str, str]]:
    """{"worker portal" | "admin page": (url, email, password)} as the demo printed them."""
    return {m[1]: (m[2], m[3], m[4]) for m in LOGIN.finditer(out)}


@pytest.mark.slow
def test_the_demo_reaches_a_finished_solve_and_prints_links_and_logins(tmp_path: Path) -> None:
    var_dir = tmp_path / "var"
    out = run_demo(var_dir)
    assert re.search(r"^annotate: +http://127\.0\.0\.1:\d+/annotate/\?\S+#token=\S+$", out,
                     re.MULTILINE)
    first = logins(out)
    assert first["worker portal"][0].endswith("/market/")
    assert first["admin page"][0].endswith("/admin/")
    assert "/frames?token=" not in out  # no raw JSON link
    summary = re.search(r"^(\d+) submitted, (\d+) scored: (\d+) approved, (\d+) rejected.*; "
                        r"solve (\d+) done in \d+ s", out, re.MULTILINE)
    assert summary, out
    assert int(summary[1]) == int(summary[2])  # every submission has its QC report
    assert "--no-serve: nothing is being served" in out
    # A hand HIT stays open for the demo worker in the portal (tests/backend/demo/
    # test_portal_hit.py checks the portal's list).
    assert re.search(r"^hand HIT \S+ is open in the worker portal for the demo worker$", out,
                     re.MULTILINE), out
    saved = var_dir / "demo-logins.json"
    assert stat.S_IMODE(saved.stat().st_mode) == 0o600
    assert json.loads(saved.read_text())["worker"]["password"] == first["worker portal"][2]
    assert not (var_dir / "server.json").exists()
    with sqlite3.connect(var_dir / "dexlabel.db") as db:
        kinds = dict(db.execute("SELECT kind, count(*) FROM tasks GROUP BY kind"))
        unaccepted = db.execute(
            "SELECT count(*) FROM tasks t WHERE NOT EXISTS (SELECT 1 FROM assignments a "
            "WHERE a.task_id = t.id AND a.status = 'approved')").fetchone()[0]
        unscored = db.execute(
            "SELECT count(*) FROM assignments a WHERE a.status != 'working' AND NOT EXISTS "
            "(SELECT 1 FROM qc_reports r WHERE r.assignment_id = a.id)").fetchone()[0]
        busy = db.execute("SELECT count(*) FROM jobs WHERE status IN "
                          "('queued', 'running', 'retrying')").fetchone()[0]
        submitted = db.execute("SELECT count(*) FROM assignments WHERE status != 'working'"
                               ).fetchone()[0]
    assert kinds == {"hand": 3, "object": 3}
    assert (unaccepted, unscored, busy) == (0, 0, 0)

    # `dexlabel status 1` in the same instance: every view x target accepted, the solve done.
    status = subprocess.run([*DEXLABEL, "status", "1"], env=clean_env(DEXLABEL_VAR_DIR=str(
        var_dir)), cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert status.returncode == 0, status.stderr
    head, *rest = status.stdout.splitlines()
    assert "solved: 6 tasks (6 accepted)" in head and f"run {summary[5]} done" in head, head
    start = rest.index("") + 1
    grid, costs = rest[start:rest.index("", start)], rest[rest.index("", start) + 2:]
    assert grid[0].split() == ["view", "hand:0", "object:0"]
    assert len(grid) == 4 and all(r.split()[1:] == ["accepted", "accepted"] for r in grid[1:])
    # The cost per labelled 3D frame: the solved frames of each target, paid from the ledger.
    assert [r.split()[0] for r in costs[1:]] == ["hand:0", "object:0", "total"]
    assert all(int(r.split()[1]) > 0 and float(r.split()[4]) > 0 for r in costs[1:]), costs

    again = run_demo(var_dir)
    # The same emails and passwords (the port differs from run to run).
    assert {k: v[1:] for k, v in logins(again).items()} == {k: v[1:] for k, v in first.items()}
    assert "round 1" not in again  # every task already has accepted work
    with sqlite3.connect(var_dir / "dexlabel.db") as db:
        assert db.execute("SELECT count(*) FROM assignments WHERE status != 'working'"
                          ).fetchone()[0] == submitted
