"""Command-line functions of the solve, registered on the main app by backend/cli/__init__.py:

    dexlabel solve SEQUENCE [--optimiser paper|default] [--wait]
    dexlabel calibrate-hand SEQUENCE [--force]

SEQUENCE is a sequence id or SUBJECT/NAME.
"""

from __future__ import annotations

import json
import time
from typing import Annotated, Literal

import typer

from backend.cli.console import (
    EXIT_FAILED,
    SequenceArg,
    progress,
    refusing_bad_input,
    resolve_sequence,
)
from backend.db import session_scope

# How often --wait looks at a run another process is solving, seconds.
POLL_S = 2.0


def solve_command(
    sequence: SequenceArg,
    optimiser: Annotated[Literal["paper", "default"] | None, typer.Option(
        "--optimiser", help="default: batched LM from triangulation; paper: DexYCB's Adam "
                            "(DEXLABEL_SOLVE_OPTIMISER when not given)")] = None,
    wait: Annotated[bool, typer.Option(
        "--wait", help="run the solve in this process and print its summary")] = False,
) -> None:
    """Queue a solve of the sequence's accepted labels (or run it here with --wait)."""
    from backend.jobs.runner import execute
    from backend.solve.models import SolveRun
    from backend.solve.service import job_key, request_solve

    with refusing_bad_input(), session_scope() as session:
        run = request_solve(session, resolve_sequence(session, sequence), optimiser)
        run_id, chosen = run.id, run.optimiser
    typer.echo(f"solve run {run_id} queued ({chosen} optimiser)")
    if not wait:
        return
    from worker.tasks import register_handlers

    register_handlers()
    with progress(f"solve run {run_id}") as step:
        execute(job_key(run_id))  # a no-op when a queue consumer claimed the job first
        while True:
            with session_scope() as session:
                run = session.get_one(SolveRun, run_id)
                status, summary, error, timings = run.status, run.summary, run.error, run.timings
            if status in ("done", "failed"):
                break
            time.sleep(POLL_S)
        step(status)
    if status != "done":
        typer.echo(f"solve run {run_id} is {status}: {error or 'see dexlabel jobs list'}",
                   err=True)
        raise typer.Exit(EXIT_FAILED)
    typer.echo(f"solve run {run_id} done in {timings.get('total_s', 0.0):.1f} s")
    typer.echo(json.dumps(summary, indent=2, sort_keys=True))


def calibrate_hand_command(
    sequence: SequenceArg,
    force: Annotated[bool, typer.Option(
        "--force", help="replace betas that are already there (e.g. from mano.yml)")] = False,
) -> None:
    """Fit the subject's MANO betas to the accepted hand tracks and store them on the hand."""
    from backend.solve.calibration import calibrate_hand

    with refusing_bad_input(), session_scope() as session:
        result = calibrate_hand(session, resolve_sequence(session, sequence), force=force)
    typer.echo(f"hand {result.hand_index} ({result.side}): betas from {result.frames_used} "
               f"frames, bone lengths within {result.max_residual_mm:.2f} mm")
    typer.echo(" ".join(f"{b:.4f}" for b in result.betas))
