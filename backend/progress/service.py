"""Task and sequence states, derived on read from the rows the stages write.

A task's state is the furthest any of its work has got:

- ``accepted``: an assignment of it is approved;
- ``in review``: a submitted assignment has its QC report and waits for a decision;
- ``submitted``: a submitted assignment waits for its confirmation or quality check;
- ``published``: a HIT of it is open on the marketplace, or someone is working on it;
- ``open``: none of these (never published, or every HIT expired and all work rejected).

Nothing stores these states, so they cannot disagree with the work they describe.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable

from sqlalchemy import func, select
from sqlalchemy.orm import Session, selectinload

from backend.annotation.models import Assignment, Task
from backend.annotation.schemas import TASK_STATES, TaskState
from backend.captures.models import Camera, Sequence
from backend.crowd.adaptive import EVERY_VIEW, held
from backend.crowd.models import CrowdHit, PublishPlan
from backend.errors import NotFound
from backend.labels import ACCEPTED, accepted_digests
from backend.progress.schemas import (
    AssignmentCounts,
    SequenceProgress,
    SequenceState,
    SolveProgress,
    TaskProgress,
)
from backend.quality.models import QCReport
from backend.solve.models import SolveRun


def _state(assignments: dict[str, int], reviewed: int, hits_live: int) -> TaskState:
    if assignments.get(ACCEPTED):
        return "accepted"
    if reviewed:
        return "in review"
    if assignments.get("submitted"):
        return "submitted"
    if hits_live or assignments.get("working"):
        return "published"
    return "open"


def task_states(session: Session, task_ids: Iterable[int]) -> dict[int, TaskProgress]:
    """The progress of each task in ``task_ids`` (a few grouped queries, whatever their number)."""
    ids = list(task_ids)
    if not ids:
        return {}
    counts: dict[int, dict[str, int]] = defaultdict(dict)
    for task_id, status, n in session.execute(
            select(Assignment.task_id, Assignment.status, func.count())
            .where(Assignment.task_id.in_(ids)).group_by(Assignment.task_id, Assignment.status)):
        counts[task_id][status] = n
    reviewed: Counter[int] = Counter()
    for task_id, n in session.execute(
            select(Assignment.task_id, func.count())
            .join(QCReport, QCReport.assignment_id == Assignment.id)
            .where(Assignment.task_id.in_(ids), Assignment.status == "submitted")
            .group_by(Assignment.task_id)):
        reviewed[task_id] = n
    hits: Counter[int] = Counter()
    live: Counter[int] = Counter()
    slots: Counter[int] = Counter()
    reasons: dict[int, str] = {}
    for task_id, expired_at, max_assignments, reason in session.execute(
            select(CrowdHit.task_id, CrowdHit.expired_at, CrowdHit.max_assignments,
                   CrowdHit.reason)
            .where(CrowdHit.task_id.in_(ids), CrowdHit.hit_id.is_not(None))
            .order_by(CrowdHit.round)):
        hits[task_id] += 1
        live[task_id] += expired_at is None
        slots[task_id] += max_assignments
        if reason and task_id not in reasons:
            reasons[task_id] = reason
    _count_confirmable_work(session, ids, counts, slots)
    rows = session.execute(
        select(Task.id, Task.kind, Task.target_key, Camera.serial, held())
        .join(Camera, Camera.id == Task.camera_id).where(Task.id.in_(ids))).all()
    return {
        task_id: TaskProgress(
            task_id=task_id, serial=serial, target_key=target_key, kind=kind,
            state=_state(counts[task_id], reviewed[task_id], live[task_id]),
            hits=hits[task_id], hits_live=live[task_id],
            assignments=AssignmentCounts(**counts[task_id]),
            publish_reason=reasons.get(task_id), held=bool(is_held))
        for task_id, kind, target_key, serial, is_held in rows}


def _count_confirmable_work(session: Session, ids: list[int],
                            counts: dict[int, dict[str, int]], slots: Counter[int]) -> None:
    """Marketplace work being done counts up to the assignments the task's HITs offer: work
    the marketplace has not confirmed yet (opened with a HIT's task token, which previewers
    hold too) counts no further than workers can hold. Work on a direct link (no HIT) is an
    admin's and always counts."""
    for task_id, n in session.execute(
            select(Assignment.task_id, func.count())
            .where(Assignment.task_id.in_(ids), Assignment.status == "working",
                   Assignment.hit_id.is_not(None))
            .group_by(Assignment.task_id)):
        direct = counts[task_id].get("working", 0) - n
        counts[task_id]["working"] = direct + min(n, slots[task_id])


def _target_order(key: str) -> tuple[int, int, str]:
    kind, _, index = key.partition(":")
    return (0 if kind == "hand" else 1, int(index) if index.isdigit() else 0, key)


def _solve(run: SolveRun, digest: str | None) -> SolveProgress:
    """A sequence's newest run, and whether the accepted labels (``digest``) changed since."""
    if run.labels_digest is None:
        labels = "by hand"
    else:
        labels = "current" if digest == run.labels_digest else "outdated"
    return SolveProgress(run_id=run.id, status=run.status, labels=labels,
                         finished_at=run.finished_at, error=run.error)


def sequence_progress(session: Session, sequence_id: int) -> SequenceProgress:
    """The view x target grid of one sequence, its counts and its current solve.

    Raises:
        NotFound: no such sequence.
    """
    found = sequences_progress(session, [sequence_id])
    if not found:
        raise NotFound(f"sequence {sequence_id} does not exist")
    return found[0]


def sequences_progress(session: Session, sequence_ids: list[int]) -> list[SequenceProgress]:
    """The progress of each existing sequence of ``sequence_ids``, in that order, in the same
    few grouped statements whatever their number."""
    seqs: dict[int, Sequence] = {}
    policies: dict[int, str] = {}
    for seq, policy in session.execute(
            select(Sequence, PublishPlan.policy)
            .outerjoin(PublishPlan, PublishPlan.sequence_id == Sequence.id)
            .where(Sequence.id.in_(sequence_ids))
            .options(selectinload(Sequence.subject), selectinload(Sequence.cameras))):
        seqs[seq.id] = seq
        policies[seq.id] = policy or EVERY_VIEW
    ids = [i for i in sequence_ids if i in seqs]
    by_sequence: dict[int, list[int]] = defaultdict(list)
    for task_id, seq_id in session.execute(
            select(Task.id, Task.sequence_id).where(Task.sequence_id.in_(ids))):
        by_sequence[seq_id].append(task_id)
    states = task_states(session, [t for tasks in by_sequence.values() for t in tasks])
    solves = _solves(session, ids)
    return [_progress(seqs[i], [states[t] for t in by_sequence[i]], solves.get(i),
                      policies[i]) for i in ids]


def _solves(session: Session, sequence_ids: list[int]) -> dict[int, SolveProgress]:
    newest = (select(func.max(SolveRun.id)).where(SolveRun.sequence_id.in_(sequence_ids))
              .group_by(SolveRun.sequence_id))
    runs = list(session.scalars(select(SolveRun).where(SolveRun.id.in_(newest))))
    digests = accepted_digests(session, [r.sequence_id for r in runs if r.labels_digest])
    return {run.sequence_id: _solve(run, digests.get(run.sequence_id, (None, 0))[0])
            for run in runs}


def _progress(seq: Sequence, tasks: list[TaskProgress], solve: SolveProgress | None,
              policy: str = EVERY_VIEW) -> SequenceProgress:
    cells = sorted(tasks, key=lambda t: (t.serial, _target_order(t.target_key)))
    counts = dict.fromkeys(TASK_STATES, 0)
    totals: Counter[str] = Counter()
    for cell in cells:
        counts[cell.state] += 1
        totals.update(cell.assignments.model_dump())
    held = sum(cell.held for cell in cells)
    state: SequenceState
    if not cells:
        state = "no tasks"
    elif counts["accepted"] == len(cells) - held and counts["accepted"]:
        state = "solved" if solve and solve.status == "done" and solve.labels == "current" \
            else "accepted"
    elif counts["open"] == len(cells):
        state = "open"
    else:
        state = "in progress"
    return SequenceProgress(
        sequence_id=seq.id, subject=seq.subject.name, name=seq.name, state=state,
        views=sorted({c.serial for c in cells} or {c.serial for c in seq.cameras}),
        targets=sorted({c.target_key for c in cells}, key=_target_order),
        counts=counts, hits=sum(c.hits for c in cells),
        hits_live=sum(c.hits_live for c in cells), assignments=AssignmentCounts(**totals),
        tasks=cells, publish_policy=policy, held=held, solve=solve)
