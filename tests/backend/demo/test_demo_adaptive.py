"""`dexlabel demo --no-serve` under the adaptive publishing policy: per target first only the
views of widest baseline are published and the simulated crowd works them; asked for more
confidence than they give, a solve publishes another view with its reason and the demo's
crowd comes back for it; the views still held stay unpublished and `dexlabel status` names
them. (A confident solve asks for no more: tests/backend/crowd/test_adaptive_publish.py.)
"""

from __future__ import annotations

import re
import sqlite3
import subprocess
from pathlib import Path

import pytest

from tests.backend.cli.conftest import DEXLABEL, clean_env, free_port

ARGS = ["--no-serve", "--frames", "12", "--views", "4", "--objects", "1"]


@pytest.mark.slow
def test_an_adaptive_demo_publishes_views_where_the_solve_needs_them(tmp_path: Path) -> None:
    var_dir = tmp_path / "var"
    # Confidence 1 on every frame: more than the initial views give a target.
    env = clean_env(DEXLABEL_VAR_DIR=str(var_dir), DEXLABEL_PUBLISH_POLICY="adaptive",
                    DEXLABEL_PUBLISH_CONFIDENCE="1", DEXLABEL_PUBLISH_CONFIDENT_SHARE="1")
    done = subprocess.run([*DEXLABEL, "demo", "--port", str(free_port()), *ARGS], env=env,
                          cwd=tmp_path, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    assert "hand tasks: 3 HITs created" in out and "object tasks: 3 HITs created" in out, out
    assert re.search(r"; solve \d+ done in \d+ s", out), out
    with sqlite3.connect(var_dir / "dexlabel.db") as db:
        tasks = db.execute("SELECT count(*) FROM tasks").fetchone()[0]
        reasons = [r for (r,) in db.execute("SELECT reason FROM crowd_hits ORDER BY id")]
        unaccepted = db.execute(
            "SELECT count(*) FROM tasks t WHERE EXISTS (SELECT 1 FROM crowd_hits h WHERE "
            "h.task_id = t.id) AND NOT EXISTS (SELECT 1 FROM assignments a WHERE "
            "a.task_id = t.id AND a.status = 'approved')").fetchone()[0]
    assert tasks == 8
    # Each target's initial views; a hand's may start from the view its depth shows whole.
    widest = "initial: widest baselines (3 of 4 views)"
    start = "initial: worked first, the hand whole in view (3 of 4 views)"
    assert set(reasons[:6]) <= {widest, start} and reasons[:6].count(start) <= 1, reasons
    later = reasons[6:]
    assert later and all("below confidence 1" in r for r in later), (reasons, out)
    # Every view published, the later ones too, has accepted work.
    assert unaccepted == 0
    status = subprocess.run([*DEXLABEL, "status", "1"], env=env, cwd=tmp_path,
                            capture_output=True, text=True, timeout=120)
    assert status.returncode == 0, status.stderr
    head = status.stdout.splitlines()[0]
    held = 8 - len(reasons)
    shown = f"solved: 8 tasks ({len(reasons)} accepted, {held} held back)" if held \
        else "solved: 8 tasks"
    assert shown in head, head
