"""What the demo prints when it is ready: the state of its sequence in one line, and the
links and logins for a first look."""

from __future__ import annotations

import typer
from sqlalchemy import func, select

from backend.db import session_scope
from backend.demo import Login, unaccepted


def demo_summary(sequence_id: int) -> str:
    """"16 submitted, 16 scored: 9 approved, 7 rejected; solve 1 done in 41 s"."""
    from backend.annotation.models import Assignment, Task
    from backend.quality.models import QCReport
    from backend.solve.models import SolveRun

    with session_scope() as session:
        statuses = dict(session.execute(
            select(Assignment.status, func.count()).join(Task, Task.id == Assignment.task_id)
            .where(Task.sequence_id == sequence_id).group_by(Assignment.status)).all())
        scored = session.scalar(select(func.count(func.distinct(QCReport.assignment_id)))
                                .where(QCReport.sequence_id == sequence_id)) or 0
        run = session.scalar(select(SolveRun).where(SolveRun.sequence_id == sequence_id)
                             .order_by(SolveRun.id.desc()))
        solve = _solve_words(run)
    approved, rejected = statuses.get("approved", 0), statuses.get("rejected", 0)
    pending = statuses.get("submitted", 0)
    line = (f"{approved + rejected + pending} submitted, {scored} scored: {approved} approved, "
            f"{rejected} rejected")
    if pending:
        line += f", {pending} awaiting a decision"
    if run is None:
        missing, total = unaccepted(sequence_id)
        solve = f"no solve yet: {missing} of {total} tasks without accepted work"
    return f"{line}; {solve}"


def _solve_words(run) -> str:  # type: ignore[no-untyped-def]
    if run is None:
        return ""
    if run.status == "done":
        return f"solve {run.id} done in {float((run.timings or {}).get('total_s', 0.0)):.0f} s"
    if run.status == "failed":
        last = (run.error or "").strip().splitlines()
        return f"solve {run.id} failed: {last[-1] if last else 'see dexlabel jobs list'}"
    return f"solve {run.id} {run.status}"


def demo_print(seq, base: str, logins: dict[str, Login],  # type: ignore[no-untyped-def]
               annotate: str) -> None:
    base = base.rstrip("/")
    admin, worker = logins["admin"], logins["worker"]
    typer.echo(f"\nsequence {seq.subject}/{seq.name} (id {seq.sequence_id}): "
               f"{seq.num_cameras} cameras x {seq.num_frames} frames")
    typer.echo(f"annotate:      {annotate}")
    typer.echo(f"worker portal: {base}/market/  email {worker.email}  password {worker.password}")
    typer.echo(f"admin page:    {base}/admin/  email {admin.email}  password {admin.password}")
