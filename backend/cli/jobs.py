"""CLI of the job table: `dexlabel jobs list`, `dexlabel jobs retry`."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

import typer

from backend.cli.console import refusing_bad_input
from backend.db import session_scope

jobs_app = typer.Typer(help="Queue jobs: status, attempts, results and errors.",
                       no_args_is_help=True, rich_markup_mode=None)


class JobStatus(StrEnum):
    """The job table's statuses as choices (a test keeps them equal to JOB_STATUSES)."""

    queued = "queued"
    running = "running"
    retrying = "retrying"
    waiting = "waiting"
    done = "done"
    failed = "failed"


@jobs_app.command("list")
def jobs_list(
    status: Annotated[JobStatus | None, typer.Option(help="only jobs in this status")] = None,
    kind: Annotated[str | None, typer.Option(help="only jobs of this kind (qc, solve, ...)")]
    = None,
) -> None:
    """The newest jobs, one line each: status, result or error.

    Each line gives the job's status, attempts, and its result or error."""
    from backend.jobs.service import describe, list_jobs

    with session_scope() as session:
        jobs = list_jobs(session, status.value if status else None, kind)
        if not jobs:
            typer.echo("no jobs" + (f" {status.value}" if status else "")
                       + (f" of kind {kind}" if kind else ""))
        for job in jobs:
            typer.echo(f"{job.id:5d} {job.key:28s} {job.status:8s} "
                       f"{job.attempts}/{job.max_attempts}  {describe(job)[:160]}")


@jobs_app.command("retry")
def jobs_retry(job_id: Annotated[int, typer.Argument()]) -> None:
    """Queue a failed or waiting job again."""
    from backend.jobs.service import retry_job

    with refusing_bad_input(), session_scope() as session:
        job = retry_job(session, job_id)
        typer.echo(f"{job.key}: queued")
