"""The CLI behaves the same everywhere: bad input is one `error:` line and exit 2, sequences by
id or SUBJECT/NAME, an unknown sequence is an error, `qc run` runs the check here and prints
its real outcome, a bonus is checked before its ledger row, `jobs list --status` takes only
the job table's statuses, and long work ends with its timing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import func, select
from typer.testing import CliRunner

from backend.cli import app

SEQUENCE = "synth-subject-01/synth_000003"  # the small capture's (seed 3)


@pytest.fixture
def imported(instance: Path, cli: CliRunner, small_capture: Path) -> int:
    done = cli.invoke(app, ["import", str(small_capture)])
    assert done.exit_code == 0, done.output
    assert f"imported {SEQUENCE} (id 1)" in done.output
    assert "importing" in done.output and "done in" in done.output
    return 1


@pytest.mark.parametrize("args", [
    ["qc", "reports", "999"], ["qc", "reports", "nobody/nothing"], ["qc", "run", "999"],
    ["solve", "999"], ["calibrate-hand", "999"], ["tasks", "create", "999"],
    ["publish", "--sequence", "999", "--dry-run"], ["qc", "reports", "no-slash"],
])
def test_an_unknown_sequence_is_an_error_not_an_empty_listing(
    imported: int, cli: CliRunner, args: list[str],
) -> None:
    done = cli.invoke(app, args)
    assert done.exit_code == 2, done.output
    assert done.output.startswith("error: no sequence "), done.output
    assert done.output.count("\n") == 1


@pytest.mark.parametrize("ref", ["1", SEQUENCE])
def test_a_sequence_is_named_by_id_or_subject_and_name(imported: int, cli: CliRunner,
                                                       ref: str) -> None:
    done = cli.invoke(app, ["tasks", "create", ref])
    assert done.exit_code == 0, done.output
    assert done.output.startswith("9 tasks: 3 hand, 6 object")
    done = cli.invoke(app, ["qc", "reports", ref])
    assert (done.exit_code, done.output) == (0, "sequence 1 has no QC reports yet\n")


def test_solve_refusals_exit_2_like_every_command(imported: int, cli: CliRunner) -> None:
    cli.invoke(app, ["tasks", "create", "1"])
    done = cli.invoke(app, ["solve", SEQUENCE])
    assert done.exit_code == 2, done.output
    assert done.output.startswith("error: ")


def _submit_careful_work(sequence_id: int, capture: Path) -> None:
    """Every view of the hand labelled by a careful worker through a direct link."""
    from backend.annotation.models import Task
    from backend.annotation.schemas import TracksSave
    from backend.annotation.service import create_assignment, create_tasks
    from backend.captures.truth import CaptureTruth
    from backend.db import session_scope
    from backend.pipeline import submit
    from backend.storage import get_storage
    from worker.synth.annotators import annotate

    rng = np.random.default_rng(0)
    truth = CaptureTruth(capture)
    with session_scope() as session:
        create_tasks(session, get_storage(), sequence_id)
        hands = list(session.scalars(select(Task).where(Task.kind == "hand")))
        for task in hands:
            view = {"kind": "hand", "serial": task.camera.serial,
                    "num_frames": task.sequence.num_frames, "target_key": task.target_key}
            xy, visible = truth.points(view, rng)
            work = annotate(xy, visible, (task.camera.width, task.camera.height), "careful",
                            rng)
            assignment = create_assignment(session, task, f"W{task.id}")
            submit(session, assignment, TracksSave(
                version=assignment.version, edit_count=20, working_time_s=120.0,
                tracks=[{"point": p, "keyframes": rows} for p, rows in enumerate(work.tracks)]))


def test_qc_run_runs_the_check_here_and_prints_its_outcome(
    imported: int, cli: CliRunner, small_capture: Path,
) -> None:
    _submit_careful_work(imported, small_capture)
    done = cli.invoke(app, ["qc", "run", SEQUENCE, "--target", "hand:0"])
    assert done.exit_code == 0, done.output
    first = done.output.splitlines()[0]
    assert first.startswith("qc:1:hand:0: qc: hand:0 scored 3: "), first
    assert "no handler" not in done.output
    assert done.output.count("assignment ") == 3
    done = cli.invoke(app, ["jobs", "list", "--status", "done", "--kind", "qc"])
    assert done.exit_code == 0
    assert "qc:1:hand:0" in done.output and "hand:0 scored 3" in done.output


def test_qc_run_of_a_sequence_without_work_is_refused(imported: int, cli: CliRunner) -> None:
    done = cli.invoke(app, ["qc", "run", "1"])
    assert done.exit_code == 2
    assert done.output == "error: sequence 1 has no submitted work to check\n"


@pytest.mark.parametrize("amount", ["0", "0.00", "-1", "abc", "1.001"])
def test_a_bonus_amount_is_checked_before_any_ledger_row(instance: Path, cli: CliRunner,
                                                        amount: str) -> None:
    from backend.crowd.models import CrowdPayment
    from backend.db import session_scope

    done = cli.invoke(app, ["crowd", "bonus", "--reason", "thanks", "--", "1", amount])
    assert done.exit_code == 2, done.output
    assert done.output.startswith("error: ")
    with session_scope() as session:
        assert session.scalar(select(func.count()).select_from(CrowdPayment)) == 0


def test_jobs_list_status_takes_only_the_job_tables_statuses(instance: Path,
                                                             cli: CliRunner) -> None:
    from backend.cli.jobs import JobStatus
    from backend.jobs.models import JOB_STATUSES

    assert tuple(s.value for s in JobStatus) == JOB_STATUSES
    done = cli.invoke(app, ["jobs", "list", "--status", "finished"])
    assert done.exit_code == 2
    assert "'finished' is not one of" in done.output
    for status in JOB_STATUSES:
        done = cli.invoke(app, ["jobs", "list", "--status", status])
        assert (done.exit_code, done.output) == (0, f"no jobs {status}\n")


def test_jobs_list_shows_each_jobs_result_or_error(imported: int, cli: CliRunner) -> None:
    from backend.db import session_scope
    from backend.jobs.models import Job

    with session_scope() as session:
        session.add(Job(kind="solve", key="solve:1", status="failed", attempts=5,
                        max_attempts=5, error="Traceback...\nValueError: no accepted labels"))
    done = cli.invoke(app, ["jobs", "list"])
    assert done.exit_code == 0
    lines = {line.split()[1]: line for line in done.output.splitlines()}
    assert lines["solve:1"].endswith("solve: failed: ValueError: no accepted labels")
    assert "frame_stats:1" in lines


def test_progress_prints_a_plain_line_per_step_off_a_terminal(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from backend.cli.console import progress

    with progress("publishing 2 HITs", total=2) as step:
        step("task 1")
        step("task 2")
    lines = capsys.readouterr().out.splitlines()
    assert lines[:3] == ["publishing 2 HITs ...", "publishing 2 HITs: task 1 (1/2)",
                         "publishing 2 HITs: task 2 (2/2)"]
    assert lines[3].startswith("publishing 2 HITs: done in ") and lines[3].endswith(" s")
