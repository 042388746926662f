"""`dexlabel demo --no-serve` under the adaptive publishing policy: per target only the views
of widest baseline are published, the simulated crowd works them, the solve runs on them and,
confident, asks for no more; the held views stay unpublished and `dexlabel status` names them.
Asked for more confidence than the initial views give, the solve publishes another view with
its reason and the demo's crowd comes back for it.
"""

from __future__ import annotations

import json
import re
import sqlite3
import subprocess
from pathlib import Path

import pytest

from tests.backend.cli.conftest import DEXLABEL, clean_env, free_port

ARGS = ["--no-serve", "--frames", "12", "--views", "4", "--objects", "1"]


@pytest.mark.slow
def test_an_adaptive_demo_is_solved_from_fewer_views(tmp_path: Path) -> None:
    var_dir = tmp_path / "var"
    env = clean_env(DEXLABEL_VAR_DIR=str(var_dir), DEXLABEL_PUBLISH_POLICY="adaptive")
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
        last_publish = json.loads(db.execute(
            "SELECT result FROM jobs WHERE kind = 'publish_views' ORDER BY id DESC LIMIT 1"
        ).fetchone()[0])
    # The solve was confident on the initial views: nothing more was published.
    assert tasks == 8 and len(reasons) == 6, reasons
    assert all(r == "initial: widest baselines (3 of 4 views)" for r in reasons), reasons
    assert unaccepted == 0
    assert last_publish["published"] == 0, last_publish
    status = subprocess.run([*DEXLABEL, "status", "1"], env=env, cwd=tmp_path,
                            capture_output=True, text=True, timeout=120)
    assert status.returncode == 0, status.stderr
    head = status.stdout.splitlines()[0]
    assert "solved: 8 tasks (6 accepted, 2 held back)" in head, head


@pytest.mark.slow
def test_the_demo_crowd_comes_back_for_the_views_a_solve_publishes(tmp_path: Path) -> None:
    var_dir = tmp_path / "var"
    # Confidence 1 on every frame: more than the initial views give a target.
    env = clean_env(DEXLABEL_VAR_DIR=str(var_dir), DEXLABEL_PUBLISH_POLICY="adaptive",
                    DEXLABEL_PUBLISH_CONFIDENCE="1", DEXLABEL_PUBLISH_CONFIDENT_SHARE="1")
    done = subprocess.run([*DEXLABEL, "demo", "--port", str(free_port()), *ARGS], env=env,
                          cwd=tmp_path, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout + done.stderr
    with sqlite3.connect(var_dir / "dexlabel.db") as db:
        reasons = [r for (r,) in db.execute("SELECT reason FROM crowd_hits ORDER BY id")]
        unaccepted = db.execute(
            "SELECT count(*) FROM tasks t WHERE EXISTS (SELECT 1 FROM crowd_hits h WHERE "
            "h.task_id = t.id) AND NOT EXISTS (SELECT 1 FROM assignments a WHERE "
            "a.task_id = t.id AND a.status = 'approved')").fetchone()[0]
    later = [r for r in reasons if not r.startswith("initial:")]
    assert len(reasons) > 6 and later, (reasons, done.stdout)
    assert all("below confidence 1" in r for r in later), later
    # Every view published, the later ones too, has accepted work.
    assert unaccepted == 0
