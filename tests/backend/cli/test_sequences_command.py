"""`dexlabel sequences delete SEQUENCE [--force]`: by id or SUBJECT/NAME, refused (exit 2)
while the sequence has submitted work unless forced, an unknown sequence is an error."""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import func, select
from typer.testing import CliRunner

from backend.annotation.models import Assignment
from backend.annotation.service import create_tasks
from backend.captures.models import Sequence
from backend.cli import app
from backend.db import session_scope
from backend.storage import get_storage

SEQUENCE = "synth-subject-01/synth_000003"  # the small capture's (seed 3)


def _sequences() -> int:
    with session_scope() as s:
        return int(s.scalar(select(func.count()).select_from(Sequence)) or 0)


def test_sequences_delete_refuses_submitted_work_unless_forced(
    instance: Path, cli: CliRunner, small_capture: Path
) -> None:
    done = cli.invoke(app, ["import", str(small_capture)])
    assert done.exit_code == 0, done.output
    with session_scope() as s:
        task = create_tasks(s, get_storage(), 1)[0]
        s.add(Assignment(task_id=task.id, worker_id="W1", external_id="A1", status="submitted"))

    done = cli.invoke(app, ["sequences", "delete", SEQUENCE])
    assert done.exit_code == 2, done.output
    assert done.output.startswith("error: sequence 1 ") and "--force" in done.output
    assert _sequences() == 1

    done = cli.invoke(app, ["sequences", "delete", SEQUENCE, "--force"])
    assert done.exit_code == 0, done.output
    assert done.output.startswith(f"deleted sequence 1 {SEQUENCE}: 9 tasks, 1 assignments")
    assert _sequences() == 0
    assert not any(p.is_file() for p in (instance / "storage").rglob("*"))

    done = cli.invoke(app, ["sequences", "delete", "1"])
    assert done.exit_code == 2 and done.output.startswith("error: no sequence 1")
