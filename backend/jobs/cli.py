"""CLI of the job table: `dexlabel jobs list`, `dexlabel jobs retry`."""

from __future__ import annotations

from typing import Annotated

import typer

from backend.db import session_scope
from backend.errors import DexlabelError

jobs_app = typer.Typer(help="Queue jobs: status, attempts, results and errors.",
                       no_args_is_help=True)


def _fail(exc: DexlabelError) -> None:
    typer.secho(f"error: {exc.detail}", fg=typer.colors.RED, err=True)
    raise typer.Exit(code=2)


@jobs_app.command("list")
def jobs_list(
    status: Annotated[str | None, typer.Option(help="queued, running, retrying, waiting, "
                                                    "done or failed")] = None,
    kind: Annotated[str | None, typer.Option()] = None,
) -> None:
    """The newest jobs with their status, attempts and last error."""
    from backend.jobs.service import list_jobs

    with session_scope() as session:
        for job in list_jobs(session, status, kind):
            error = f"  {job.error.splitlines()[-1][:120]}" if job.error else ""
            typer.echo(f"{job.id:5d} {job.key:32s} {job.status:8s} "
                       f"attempts {job.attempts}/{job.max_attempts}{error}")


@jobs_app.command("retry")
def jobs_retry(job_id: Annotated[int, typer.Argument()]) -> None:
    """Queue a failed or waiting job again."""
    from backend.jobs.service import retry_job

    try:
        with session_scope() as session:
            job = retry_job(session, job_id)
            typer.echo(f"{job.key}: queued")
    except DexlabelError as exc:
        _fail(exc)
