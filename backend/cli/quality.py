"""CLI of quality control: `dexlabel qc ...`, `dexlabel training ...`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from sqlalchemy import select

from backend.cli.console import EXIT_FAILED, SequenceArg, refusing_bad_input, resolve_sequence
from backend.db import session_scope

qc_app = typer.Typer(help="Quality control of submitted work.", no_args_is_help=True,
                     rich_markup_mode=None)
training_app = typer.Typer(help="Training clips (gold) for the qualification.",
                           no_args_is_help=True, rich_markup_mode=None)


@qc_app.command("run")
def qc_run(
    sequence: SequenceArg,
    target: Annotated[str | None, typer.Option(help="hand:0, object:1, ... (default: all)")] = None,
    now: Annotated[bool, typer.Option("--now/--queue",
                                      help="run here and wait, or queue for a worker")] = True,
) -> None:
    """Score a sequence's submitted work and act on the decisions."""
    from backend.jobs.models import Job
    from backend.jobs.runner import execute
    from backend.jobs.service import describe
    from backend.quality.service import request_qc_for
    from worker.tasks import register_handlers

    with refusing_bad_input(), session_scope() as session:
        sequence_id = resolve_sequence(session, sequence)
        keys = [job.key for job in request_qc_for(session, sequence_id, target)]
    if now:
        register_handlers()
    failed = False
    for key in keys:
        if now:
            execute(key)  # a no-op when a queue consumer holds the job (it runs again after)
        with session_scope() as session:
            job = session.scalars(select(Job).where(Job.key == key)).one()
            failed |= job.status in ("failed", "retrying")
            typer.echo(f"{key}: {describe(job)}")
    if now:
        _print_reports(sequence_id)
    if failed:
        raise typer.Exit(EXIT_FAILED)


@qc_app.command("reports")
def qc_reports(sequence: SequenceArg) -> None:
    """One line per scored assignment, with the worker's feedback.

    Its outcome, errors, the action taken, and what the worker was told."""
    with refusing_bad_input(), session_scope() as session:
        sequence_id = resolve_sequence(session, sequence)
    _print_reports(sequence_id)


def _print_reports(sequence_id: int) -> None:
    from backend.quality.service import list_reports

    with session_scope() as session:
        rows = list_reports(session, sequence_id)
        if not rows:
            typer.echo(f"sequence {sequence_id} has no QC reports yet")
        for r in rows:
            m = r.metrics or {}
            med = m.get("median_error_px")
            typer.echo(f"assignment {r.assignment_id:5d} {r.target_key:9s} {r.worker_id:24s} "
                       f"{r.outcome:7s}{' (provisional)' if r.provisional else ''} "
                       f"median {med if med is None else round(med, 1)} px "
                       f"action {r.action or '-'}")
            if r.outcome != "approve" and r.feedback:
                typer.echo(f"    {r.feedback}")


@qc_app.command("workers")
def qc_workers() -> None:
    """Each worker's running quality score."""
    from backend.quality.service import worker_quality

    with session_scope() as session:
        for row in worker_quality(session):
            typer.echo(f"{row['worker_id']:24s} score {row['score']:.2f} scored {row['scored']} "
                       f"rejected {row['rejected']}{' BLOCKED' if row['blocked'] else ''}")


@training_app.command("create")
def training_create(
    task_id: Annotated[int, typer.Argument()],
    from_assignment: Annotated[int | None, typer.Option(help="an approved assignment")] = None,
    from_truth: Annotated[Path | None, typer.Option(
        help="a synthetic capture whose ground truth is the gold")] = None,
) -> None:
    """Make a task a training clip whose known labels score new workers."""
    from backend.quality.gold import create_clip, truth_tracks
    from backend.quality.schemas import TrainingClipCreate

    with refusing_bad_input(), session_scope() as session:
        tracks = truth_tracks(session, task_id, from_truth) if from_truth else None
        clip = create_clip(session, TrainingClipCreate(
            task_id=task_id, from_assignment_id=from_assignment, tracks=tracks))
        typer.echo(f"task {clip.task_id} is a training clip ({clip.source})")
