"""bench/qc.py's object scenarios judged after the product's own solve of the crowd's work.

The crowd's labels travel the way backend.pipeline moves them: each submission queues its
target's QC job; QC approves, rejects or leaves work for review; once every task of the
sequence has accepted work, the QC job queues the solve (default optimiser, the deployment's
settings) of those accepted labels; the finished solve queues the landmark QC of every object
target, which re-scores each object label against the solved objects. The queued jobs run
here, one after another, through the job table (backend.jobs.runner.run_queued), as an idle
queue worker would run them.

What a person does in the product is simulated as plainly as possible:
- the hand: one careful worker per view, submitted once and kept for every crowd (the object
  scenarios measure the landmark workers; the solve needs the hand's accepted labels);
- a rejected label's task gets another worker drawn from the same mixed crowd (the
  marketplace re-opens the task with one more assignment);
- work QC leaves undecided (review, or provisional) is decided by an admin who judges right:
  careful work (and a frozen track on an object that never moves) approved, the rest rejected.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from sqlalchemy import delete, select

# A crowd whose tasks are still not all accepted after this many rounds of re-opened tasks
# and admin decisions is reported unsolved (each round is a few QC jobs, no solve).
MAX_ROUNDS = 12
# Profiles an admin approves (a frozen track on a still object is right, and so is marking
# hidden all through an object the view never shows, and a swap of two landmarks the view
# hides all through it).
RIGHT = ("careful", "lazy-still", "unseen", "swap-unseen")


def drain() -> list[str]:
    """Run the queued jobs (QC, solve) here until none is left; the keys run, in order."""
    from backend.jobs.consumer import run_queued
    from worker.tasks import register_handlers

    register_handlers()
    return run_queued()


def request_qc_of(task_ids: list[int]) -> None:
    """Queue the QC job of each task's target, as a direct-link submission does."""
    from backend.annotation.models import Task
    from backend.db import session_scope
    from backend.quality.service import request_qc

    with session_scope() as session:
        for task_id in task_ids:
            request_qc(session, session.get_one(Task, task_id))


def clear_solves(sequence_id: int) -> None:
    """Forget the sequence's solve runs (the next crowd is a new project: nothing solved)."""
    from backend.db import session_scope
    from backend.solve.models import SolveRun

    with session_scope() as session:
        session.execute(delete(SolveRun).where(SolveRun.sequence_id == sequence_id))


def _admin_decides(assignment_id: int, approve: bool) -> None:
    """An admin's decision on direct-link work (no marketplace to pay): the assignment's
    status, the report's record of it, and the target's QC asked for again (as
    backend.pipeline does after an admin's approval or rejection)."""
    from backend.annotation.models import Assignment
    from backend.db import session_scope
    from backend.quality.service import record_decision, request_qc

    decision = "approved" if approve else "rejected"
    with session_scope() as session:
        assignment = session.get_one(Assignment, assignment_id)
        assignment.status = decision
        record_decision(session, assignment_id, decision)
        request_qc(session, assignment.task)


def _unaccepted(sequence_id: int) -> dict[int, tuple[int, str]]:
    """{task id: (id, status) of its newest assignment} of every task without accepted work."""
    from backend.annotation.models import Assignment, Task
    from backend.db import session_scope

    with session_scope() as session:
        rows = session.execute(select(Task.id, Assignment.id, Assignment.status)
                               .join(Assignment, Assignment.task_id == Task.id)
                               .where(Task.sequence_id == sequence_id)
                               .order_by(Assignment.id)).all()
    newest: dict[int, tuple[int, str]] = {}
    accepted = set()
    for task_id, assignment_id, status in rows:
        newest[task_id] = (assignment_id, status)
        if status == "approved":
            accepted.add(task_id)
    return {t: v for t, v in newest.items() if t not in accepted}


def statuses(profile_of: dict[int, str]) -> dict[str, dict[str, int]]:
    """{profile: {assignment status: count}} of the assignments in ``profile_of``."""
    from backend.annotation.models import Assignment
    from backend.db import session_scope

    out: dict[str, dict[str, int]] = {}
    with session_scope() as session:
        for assignment_id, status in session.execute(select(Assignment.id, Assignment.status)
                                                     .where(Assignment.id.in_(profile_of))):
            row = out.setdefault(profile_of[assignment_id], {})
            row[status] = row.get(status, 0) + 1
    return out


def solved_run(sequence_id: int) -> tuple[int, float] | None:
    """(id, solve seconds) of the sequence's newest finished solve run, None before one."""
    from backend.db import session_scope
    from backend.quality.inputs import latest_solve

    with session_scope() as session:
        run = latest_solve(session, sequence_id)
        return None if run is None else (run.id, float(run.timings.get("total_s", 0.0)))


def to_solve(sequence_id: int, task_ids: list[int], profile_of: dict[int, str],
             resubmit: Callable[[int], tuple[int, str]]) -> tuple[dict[str, int], str | None]:
    """Carry the submitted work of ``task_ids`` through QC, the decisions a person makes, the
    solve and the landmark QC after it (module docstring). profile_of: {assignment id:
    profile} of every simulated assignment, extended with the re-opened tasks' workers;
    resubmit(task id) submits another crowd worker's label to the task, returning its
    (assignment id, profile). Returns counts (rounds, reopened, admin_approved,
    admin_rejected, solved: 1 when the solve ran) and, when it did not, why."""
    counts = {"rounds": 0, "reopened": 0, "admin_approved": 0, "admin_rejected": 0,
              "solved": 0}
    request_qc_of(task_ids)
    for _ in range(MAX_ROUNDS):
        drain()
        counts["rounds"] += 1
        if solved_run(sequence_id) is not None:
            counts["solved"] = 1
            break
        asked = []
        for task_id, (assignment_id, status) in sorted(_unaccepted(sequence_id).items()):
            if status == "submitted":
                right = profile_of.get(assignment_id) in RIGHT
                _admin_decides(assignment_id, right)
                counts["admin_approved" if right else "admin_rejected"] += 1
                status = "approved" if right else "rejected"
            if status == "rejected":  # by QC or by the admin: the task is re-opened
                new_id, profile = resubmit(task_id)
                profile_of[new_id] = profile
                counts["reopened"] += 1
                asked.append(task_id)
        request_qc_of(asked)
    return counts, None if counts["solved"] else why_unsolved(sequence_id)


def why_unsolved(sequence_id: int) -> str:
    """What kept the sequence from a finished solve: a failed run's error, a solve job left
    waiting, or the tasks still without accepted work."""
    from backend.db import session_scope
    from backend.jobs.models import Job
    from backend.solve.models import SolveRun

    with session_scope() as session:
        run = session.scalar(select(SolveRun).where(SolveRun.sequence_id == sequence_id)
                             .order_by(SolveRun.id.desc()).limit(1))
        if run is not None:
            return f"solve run {run.id} {run.status}: {run.error}"
        waiting = session.scalar(select(Job).where(Job.kind == "solve",
                                                   Job.status == "waiting"))
        if waiting is not None:
            return f"solve waiting: {waiting.error}"
    left = _unaccepted(sequence_id)
    return f"{len(left)} tasks without accepted work after {MAX_ROUNDS} rounds: " + ", ".join(
        f"task {t} ({status})" for t, (_, status) in sorted(left.items()))


def object_add_mm(sequence_id: int, true_poses: np.ndarray) -> tuple[list[float], int]:
    """The newest solve's objects against the truth: per object the mean vertex distance
    (ADD, mm) over the frames the solve trusts, and how many (object, frame) poses it flags.
    true_poses (O, F, 3, 4) object-to-world, metres."""
    from backend.db import session_scope
    from backend.quality.inputs import solved_objects

    with session_scope() as session:
        found = solved_objects(session, sequence_id)
    if found is None:
        return [], 0
    scene, _ = found
    out = []
    for index, vertices in enumerate(scene.vertices):
        solved = np.einsum("fij,nj->fni", scene.poses[index, :, :, :3], vertices) \
            + scene.poses[index, :, None, :, 3]
        truth = np.einsum("fij,nj->fni", true_poses[index, :, :, :3], vertices) \
            + true_poses[index, :, None, :, 3]
        distance = np.linalg.norm(solved - truth, axis=-1).mean(axis=1)
        out.append(round(float(np.nanmean(distance)) * 1000.0, 2)
                   if np.isfinite(distance).any() else float("nan"))
    flagged = int((~np.isfinite(scene.poses).all(axis=(2, 3))).sum())
    return out, flagged
