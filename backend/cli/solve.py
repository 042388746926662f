"""Command-line functions of the solve, registered on the main app by backend/cli/__init__.py:

    dexlabel solve SEQUENCE [--optimiser paper|default] [--wait] [--json]
    dexlabel calibrate-hand SEQUENCE [--force]

SEQUENCE is a sequence id or SUBJECT/NAME.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Annotated, Any, Literal

import typer

from backend.cli.console import (
    EXIT_FAILED,
    SequenceArg,
    on_terminal,
    progress,
    refusing_bad_input,
    resolve_sequence,
)
from backend.db import session_scope

# How often --wait looks at a run another process is solving, seconds.
POLL_S = 2.0
# How often --wait off a terminal prints that the solve is still running, seconds.
TICK_S = 10.0


def solve_command(
    sequence: SequenceArg,
    optimiser: Annotated[Literal["paper", "default"] | None, typer.Option(
        "--optimiser", help="default: batched LM from triangulation; paper: DexYCB's Adam "
                            "(DEXLABEL_SOLVE_OPTIMISER when not given)")] = None,
    wait: Annotated[bool, typer.Option(
        "--wait", help="run the solve in this process and print its result")] = False,
    as_json: Annotated[bool, typer.Option(
        "--json", help="print the run (with --wait: its whole summary) as JSON on stdout, "
                       "and everything else on stderr")] = False,
) -> None:
    """Solve a sequence's accepted labels (queued, or --wait).

    Without --wait the solve is queued for a worker. With --wait it runs in this process (or
    waits for the worker that took it), shows its progress, and prints the result in a few
    lines: frames labelled, keypoint and depth errors, poses left unlabelled."""
    from backend.solve.service import request_solve

    with refusing_bad_input(), session_scope() as session:
        run = request_solve(session, resolve_sequence(session, sequence), optimiser)
        run_id, chosen = run.id, run.optimiser
    typer.echo(f"solve run {run_id} queued ({chosen} optimiser)", err=as_json)
    if not wait:
        if as_json:
            typer.echo(json.dumps({"run_id": run_id, "status": "queued", "optimiser": chosen}))
        return
    status, summary, error, timings = _run_and_wait(run_id, as_json)
    if status != "done":
        typer.echo(f"solve run {run_id} is {status}: {error or 'see dexlabel jobs list'}",
                   err=True)
        raise typer.Exit(EXIT_FAILED)
    seconds = float(timings.get("total_s", 0.0))
    if as_json:
        typer.echo(json.dumps({"run_id": run_id, "status": status, "optimiser": chosen,
                               "seconds": round(seconds, 3), "summary": summary},
                              sort_keys=True))
        return
    for line in summary_lines(run_id, chosen, summary or {}, seconds):
        typer.echo(line)


def _run_and_wait(run_id: int, quiet_stdout: bool) -> tuple[str, Any, str | None, dict]:
    """Run the solve's job here (a no-op when a queue consumer claimed it first) and wait
    until the run is done or failed: (status, summary, error, timings)."""
    from backend.jobs.runner import execute
    from backend.solve.service import job_key
    from worker.tasks import register_handlers

    register_handlers()
    with progress(f"solve run {run_id}", err=quiet_stdout) as step, \
            _ticking(run_id, quiet_stdout):
        execute(job_key(run_id))
        while (found := _read_run(run_id))[0] not in ("done", "failed"):
            time.sleep(POLL_S)
        step(found[0])
    return found


def _read_run(run_id: int) -> tuple[str, Any, str | None, dict]:
    from backend.solve.models import SolveRun

    with session_scope() as session:
        run = session.get_one(SolveRun, run_id)
        return run.status, run.summary, run.error, dict(run.timings or {})


@contextmanager
def _ticking(run_id: int, to_stderr: bool) -> Iterator[None]:
    """Off a terminal (a log, a pipe), a line every TICK_S while the body runs: the run's
    status and the time so far, so a long solve shows it is alive. On a terminal the
    progress bar's clock does that."""
    if on_terminal():
        yield
        return
    stop = threading.Event()
    started = time.perf_counter()

    def tick() -> None:
        while not stop.wait(TICK_S):
            try:
                status = _read_run(run_id)[0]
            except Exception:  # the database is busy or away: the clock alone, next time again
                status = "status unknown"
            typer.echo(f"solve run {run_id}: {status}, {time.perf_counter() - started:.0f} s",
                       err=to_stderr)

    ticker = threading.Thread(target=tick, name=f"solve-{run_id}-progress", daemon=True)
    ticker.start()
    try:
        yield
    finally:
        stop.set()
        ticker.join()


def _number(value: Any, unit: str) -> str:
    return "-" if value is None else f"{float(value):.2f} {unit}"


def summary_lines(run_id: int, optimiser: str, summary: dict[str, Any],
                  seconds: float) -> list[str]:
    """A finished run's summary as a few lines a person reads (the JSON has everything)."""
    lines = [f"solve run {run_id} done in {seconds:.1f} s ({optimiser} optimiser)"]
    frames, labelled = summary.get("frames"), summary.get("labelled_frames")
    if frames is not None:
        lines.append(f"  frames labelled: {labelled} of {frames}")
    unlabelled = (summary.get("solver") or {}).get("unlabelled") or {}
    if unlabelled:
        first = next(iter(unlabelled.items()))
        lines.append(f"  left unlabelled: {len(unlabelled)} frames (frame {first[0]}: "
                     f"{first[1]}{'; ...' if len(unlabelled) > 1 else ''})")
    lines.append(f"  keypoint error: median {_number(summary.get('kpt_px_median'), 'px')}, "
                 f"mean {_number(summary.get('kpt_px_mean'), 'px')}")
    tips = summary.get("fingertip_px") or {}
    if tips:
        lines.append("  fingertips: " + ", ".join(
            f"{finger} {'-' if px is None else f'{px:.1f}'}" for finger, px in tips.items())
            + " px")
    lines.append(f"  depth error: {_number(summary.get('depth_rms_mm'), 'mm')} RMS")
    flags = summary.get("object_flags") or []
    if flags:
        lines.append(f"  object poses not pinned down: {len(flags)} (exported as "
                     f"unlabelled; first: {flags[0]})")
    lines.append(f"  everything: --json, or GET /api/solve-runs/{run_id}")
    return lines


def calibrate_hand_command(
    sequence: SequenceArg,
    force: Annotated[bool, typer.Option(
        "--force", help="replace betas that are already there (e.g. from mano.yml)")] = False,
) -> None:
    """Fit the subject's hand shape (MANO betas) to its labels.

    The betas are fitted to the accepted hand tracks and stored on the hand."""
    from backend.solve.calibration import calibrate_hand

    with refusing_bad_input(), session_scope() as session:
        result = calibrate_hand(session, resolve_sequence(session, sequence), force=force)
    typer.echo(f"hand {result.hand_index} ({result.side}): betas from {result.frames_used} "
               f"frames, bone lengths within {result.max_residual_mm:.2f} mm")
    typer.echo(" ".join(f"{b:.4f}" for b in result.betas))
