"""When a solve starts: once every task has accepted work, or work that only a solve can judge
(an object label QC left provisional), on a real database."""

from __future__ import annotations

import uuid

from sqlalchemy import select

from backend.db import session_scope
from tests.backend.crowd.test_adaptive_publish import make_rig_sequence


def _work(sequence_id: int, waiting: str | None) -> int:
    """An assignment per task, approved, except one object task's: submitted, with a QC
    report whose verdict is ``waiting`` ("provisional" or "review"); that task's id."""
    from backend.annotation.models import Assignment, Task
    from backend.captures.models import Hand
    from backend.quality.models import QCReport

    with session_scope() as session:
        for hand in session.scalars(select(Hand).where(Hand.sequence_id == sequence_id)):
            hand.betas = [0.0] * 10
        tasks = list(session.scalars(select(Task).where(Task.sequence_id == sequence_id)
                                     .order_by(Task.id)))
        held = next(t for t in tasks if t.kind == "object")
        for task in tasks:
            status = "submitted" if task is held and waiting else "approved"
            assignment = Assignment(task_id=task.id, worker_id=f"W{task.id}", status=status,
                                    external_id=uuid.uuid4().hex)
            session.add(assignment)
            session.flush()
            if task is held and waiting:
                session.add(QCReport(assignment_id=assignment.id, task_id=task.id,
                                     sequence_id=sequence_id, target_key=task.target_key,
                                     worker_id=assignment.worker_id, metrics={},
                                     outcome="approve" if waiting == "provisional" else "review",
                                     provisional=waiting == "provisional"))
        return held.id


def test_a_solve_does_not_wait_for_object_work_only_a_solve_can_judge(crowd_url: str) -> None:
    from backend.pipeline import judged_after_solve, solve_if_ready

    sequence_id = make_rig_sequence()
    held = _work(sequence_id, "provisional")
    with session_scope() as session:
        assert judged_after_solve(session, sequence_id) == {held}
        assert solve_if_ready(session, sequence_id).endswith("queued")


def test_a_solve_waits_for_work_left_for_an_admin(crowd_url: str) -> None:
    from backend.pipeline import judged_after_solve, solve_if_ready

    sequence_id = make_rig_sequence()
    _work(sequence_id, "review")
    with session_scope() as session:
        assert judged_after_solve(session, sequence_id) == set()
        assert solve_if_ready(session, sequence_id) == "waiting: 1 of 8 tasks not accepted yet"
