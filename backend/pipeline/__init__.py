"""The one place that moves work between stages: submitted -> confirmed -> QC -> solve, and
solve -> landmark QC (object landmarks checked against the solved objects), and, for a
sequence published under the adaptive policy, solve -> more views (backend.crowd.adaptive).

Each domain does its own step and knows nothing of the next one (annotation saves and
submits, crowd talks to the marketplace, quality scores and acts, solve fits poses); this
module calls them in order and queues the next stage's job. Nothing else triggers a stage, so
the domains import each other in one direction only, and every stage is reached through a job
row of the job table (a job asked for while it runs runs again afterwards, see
backend.jobs.service), so no submission is left without its quality check.

Functions that take a session work inside the caller's unit of work (an API request, a CLI
command); the job bodies (``confirm``, ``run_qc``) open their own.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session, aliased

from backend.annotation import service as annotation
from backend.annotation.models import Assignment, Task
from backend.annotation.schemas import TracksSave
from backend.crowd import confirm as crowd_confirm
from backend.crowd import decisions
from backend.crowd import flows as crowd_flows
from backend.crowd import sync as crowd_sync
from backend.crowd.adaptive import needed_views, plan_options, views_to_compare
from backend.crowd.provider import CrowdProvider
from backend.crowd.schemas import PaymentRead, SyncResult
from backend.db import session_scope
from backend.errors import DexlabelError
from backend.jobs.models import Job
from backend.jobs.runner import ACTIVE
from backend.jobs.service import enqueue_job, mark_waiting
from backend.labels import ACCEPTED, SCORED_STATUSES, accepted_digest
from backend.labels.suggestions import queue_fits
from backend.quality import flows as quality_flows
from backend.quality.models import QCReport
from backend.quality.service import qc_key, record_decision, request_landmark_qc, request_qc
from backend.rig.service import adopt
from backend.solve.models import SolveRun
from backend.solve.results import decode_result
from backend.solve.service import request_solve
from backend.solve.trust import target_trust
from backend.storage import get_storage

CONFIRM = "confirm"
PUBLISH_VIEWS = "publish_views"


def confirm_key(assignment_id: int) -> str:
    return f"{CONFIRM}:{assignment_id}"


# --- submitted ---------------------------------------------------------------------------


def submit(session: Session, assignment: Assignment, body: TracksSave) -> Assignment:
    """The worker's submit: save and check the work, then send it on. Work from a
    marketplace is confirmed with the requester API first (the confirm job); work from a
    direct link goes to the quality check at once."""
    assignment = annotation.submit(session, assignment, body)
    if assignment.hit_id:
        enqueue_job(session, CONFIRM, confirm_key(assignment.id),
                    {"assignment_id": assignment.id})
    else:
        request_qc(session, assignment.task)
    return assignment


# --- confirmed ---------------------------------------------------------------------------


def _confirmed(session: Session, assignment_ids: list[int]) -> None:
    """Submissions the requester API vouched for: each submitted one goes to QC."""
    for assignment_id in assignment_ids:
        assignment = session.get_one(Assignment, assignment_id)
        if assignment.status == "submitted":
            request_qc(session, assignment.task)


def _qc_covered(session: Session, assignment_id: int) -> bool:
    """Whether the assignment has a QC report, or its target's QC job is queued or running."""
    if session.scalar(select(QCReport.id).where(QCReport.assignment_id == assignment_id)):
        return True
    task = session.get_one(Assignment, assignment_id).task
    status = session.scalar(select(Job.status).where(
        Job.key == qc_key(task.sequence_id, task.target_key)))
    return status in ACTIVE


def sync(session: Session, crowd: CrowdProvider | None = None) -> SyncResult:
    """Collect the providers' submissions (``crowd sync``; ``crowd``: only that provider's)
    and queue QC for the new ones."""
    result = crowd_sync.sync(session, crowd)
    _confirmed(session, result.accepted_ids)
    return result


def confirm(assignment_id: int) -> dict[str, Any]:
    """The confirm job: ask the provider for one submission, then queue its QC."""
    record = crowd_confirm.submitted_record(assignment_id)
    if record == "already_accepted":
        state = record
        # Recorded by another path: crowd sync queued its QC, a provider's webhook (which sits
        # below QC) did not; queued here when it is neither scored nor waiting to be.
        with session_scope() as session:
            if not _qc_covered(session, assignment_id):
                _confirmed(session, [assignment_id])
    elif isinstance(record, str):
        state = record
    else:
        with session_scope() as session:
            state, ours = crowd_sync.accept_record(session, record)
            if state == "accepted" and ours is not None:
                _confirmed(session, [ours.id])
    return {"state": state, "message": f"assignment {assignment_id}: {state.replace('_', ' ')}"}


# --- decided (by an admin) ---------------------------------------------------------------


def _decided(session: Session, assignment_id: int, decision: str) -> None:
    """An admin's approval or rejection shows on the QC report at once, and the target's QC
    runs again (it acts on what is left and asks for the solve once all is accepted)."""
    record_decision(session, assignment_id, decision)
    request_qc(session, session.get_one(Assignment, assignment_id).task)


def approve(session: Session, crowd: CrowdProvider | None, assignment_id: int,
            feedback: str | None = None) -> PaymentRead:
    payment = decisions.approve(session, crowd, assignment_id, feedback)
    _decided(session, assignment_id, "approved")
    return payment


def reject(session: Session, crowd: CrowdProvider | None, assignment_id: int,
           feedback: str, category: str | None = None) -> PaymentRead:
    payment = decisions.reject(session, crowd, assignment_id, feedback, category)
    _decided(session, assignment_id, "rejected")
    return payment


# --- QC -> solve -------------------------------------------------------------------------


def run_qc(sequence_id: int, target_key: str) -> dict[str, Any]:
    """The QC job of one target: score and act (backend.quality.flows), then ask for the
    sequence's solve once every task has accepted work."""
    result = quality_flows.run_qc(sequence_id, target_key)
    with session_scope() as session:
        result["solve"] = solve_if_ready(session, sequence_id)
        # An adaptive sequence whose published views are too few for QC to decide: one more.
        if plan_options(session, sequence_id) is not None \
                and waiting_for_views(session, sequence_id, target_key)[0]:
            enqueue_job(session, PUBLISH_VIEWS, qc_views_key(sequence_id, target_key),
                        {"sequence_id": sequence_id, "target_key": target_key})
            result["publish_views"] = "queued"
        # Views whose suggestions are fitted from the work now accepted: prepared ahead.
        result["suggestions_preparing"] = queue_fits(session, get_storage(), sequence_id,
                                                     target_key)
    result["message"] = _qc_message(target_key, result)
    return result


def _qc_message(target_key: str, result: dict[str, Any]) -> str:
    """"hand:0 scored 6: 4 approve, 0 review, 2 reject; acted: 4 approved, 2 rejected;
    waiting: 3 of 12 tasks not accepted yet"."""
    scored = result.get("scored", {})
    total = sum(scored.get(k, 0) for k in ("approve", "review", "reject"))
    line = (f"{target_key} scored {total}: " + ", ".join(
        f"{scored.get(k, 0)} {k}" for k in ("approve", "review", "reject")))
    if scored.get("provisional"):
        line += f" ({scored['provisional']} provisional)"
    acted = result.get("actions") or {}
    if acted:
        line += "; acted: " + ", ".join(f"{n} {what}" for what, n in sorted(acted.items()))
    return f"{line}; {result['solve']}"


def judged_after_solve(session: Session, sequence_id: int) -> set[int]:
    """Object tasks of the sequence without accepted work whose submitted work QC left
    provisional (nothing could judge it before the object is solved: its landmarks hidden
    while the object moves, say): the landmark QC after a solve judges it
    (request_landmark_qc), so the solve does not wait for it."""
    other = aliased(Assignment)
    accepted = select(other.id).where(other.task_id == Task.id,
                                      other.status == ACCEPTED).exists()
    rows = session.execute(
        select(Task.id).join(Assignment, Assignment.task_id == Task.id)
        .join(QCReport, QCReport.assignment_id == Assignment.id)
        .where(Task.sequence_id == sequence_id, Task.kind == "object", ~accepted,
               Assignment.status == "submitted", QCReport.provisional.is_(True),
               QCReport.outcome != "reject")).scalars()
    return set(rows)


def waiting_for_views(session: Session, sequence_id: int, target_key: str
                      ) -> tuple[set[int], set[int]]:
    """(waiting, covered) for one target: the tasks without accepted work whose submitted
    work QC left provisional for want of views to compare it with (leaving out the work only
    a solve can judge: judged_after_solve), and the tasks with work QC kept (accepted, or
    scored and not rejected). Both empty while any submitted work has not been scored yet
    (its QC is still to run, and may decide)."""
    rows = session.execute(
        select(Task.id, Assignment.status, QCReport.provisional, QCReport.outcome)
        .join(Assignment, Assignment.task_id == Task.id)
        .outerjoin(QCReport, QCReport.assignment_id == Assignment.id)
        .where(Task.sequence_id == sequence_id, Task.target_key == target_key,
               Assignment.status.in_(SCORED_STATUSES))).all()
    if any(status == "submitted" and outcome is None for _, status, _, outcome in rows):
        return set(), set()
    accepted = {task for task, status, _, _ in rows if status == ACCEPTED}
    covered = accepted | {task for task, _, _, outcome in rows
                          if outcome not in (None, "reject")}
    waiting = {task for task, status, provisional, outcome in rows
               if status == "submitted" and provisional and outcome != "reject"} - accepted
    return waiting - judged_after_solve(session, sequence_id), covered


def solve_if_ready(session: Session, sequence_id: int) -> str:
    """Queue one solve per set of accepted labels once every task has accepted work, or
    work only a solve can judge (judged_after_solve); say why not otherwise (the QC job's
    result shows it)."""
    digest, missing = accepted_digest(session, sequence_id,
                                      judged_after_solve(session, sequence_id))
    if digest is None:
        total = len(list(session.scalars(select(Task.id).where(
            Task.sequence_id == sequence_id))))
        return f"waiting: {missing} of {total} tasks not accepted yet"
    existing = session.scalar(select(SolveRun).where(
        SolveRun.sequence_id == sequence_id, SolveRun.labels_digest == digest,
        SolveRun.status != "failed").order_by(SolveRun.id.desc()))
    if existing is not None:
        return f"solve run {existing.id} ({existing.status}) has these labels already"
    try:
        run = request_solve(session, sequence_id, labels_digest=digest)
    except DexlabelError as exc:
        mark_waiting(session, "solve", f"solve:{sequence_id}", {"sequence_id": sequence_id},
                     exc.detail)
        return f"solve not started: {exc.detail}"
    return f"solve run {run.id} queued"


# --- solve -> landmark QC ----------------------------------------------------------------


def run_solve(run_id: int) -> dict[str, Any]:
    """The solve job (backend.solve.flows), then, once the run is done, the QC of every
    object target with submitted work: its landmarks are checked against the solved objects."""
    # The solver (PyTorch) is loaded by the worker that runs this job, not by the API.
    from backend.solve.flows import run_solve as solve_run

    result = solve_run(run_id)
    if not result.get("error"):
        with session_scope() as session:
            sequence_id = session.get_one(SolveRun, run_id).sequence_id
            jobs = request_landmark_qc(session, sequence_id)
            if plan_options(session, sequence_id) is not None:
                enqueue_job(session, PUBLISH_VIEWS, f"{PUBLISH_VIEWS}:{run_id}",
                            {"run_id": run_id})
                result["publish_views"] = "queued"
        result["landmark_qc"] = len(jobs)
    return result


# --- solve -> more views (the adaptive publishing policy) ------------------------------


def publish_views(run_id: int) -> dict[str, Any]:
    """The job after a done solve of an adaptively published sequence: publish, per target
    whose frames the solve could not trust enough, one more view, saying why
    (backend.crowd.adaptive). A run whose labels are no longer the accepted ones publishes
    nothing: the newer run's job decides."""
    with session_scope() as session:
        run = session.get_one(SolveRun, run_id)
        sequence_id, finished_at, key = run.sequence_id, run.finished_at, run.result_key
        digest, _ = accepted_digest(session, sequence_id)
        stale = run.status != "done" or (run.labels_digest not in (None, digest))
    if stale or key is None:
        return {"published": 0, "message": f"solve run {run_id}: not the latest labels' run"}
    arrays = decode_result(get_storage().get_bytes(key))
    with session_scope() as session:
        reasons = needed_views(session, sequence_id,
                               target_trust(session, sequence_id, arrays), finished_at)
    if not reasons:
        return {"published": 0, "message": f"solve run {run_id}: no more views needed"}
    result = crowd_flows.publish_needed(None, sequence_id, reasons)
    return {"published": result.created + result.recovered, "reasons": reasons,
            "message": f"solve run {run_id}: {len(reasons)} more views published"}


def qc_views_key(sequence_id: int, target_key: str) -> str:
    return f"{PUBLISH_VIEWS}:qc:{sequence_id}:{target_key}"


def publish_views_to_compare(sequence_id: int, target_key: str) -> dict[str, Any]:
    """The job after a QC of an adaptively published target that left work provisional for
    want of views to compare it with: publish one more view of it, saying why
    (backend.crowd.adaptive.views_to_compare). Nothing once QC can decide, or while a
    published view's work is still to come."""
    with session_scope() as session:
        reasons = views_to_compare(session, sequence_id, target_key,
                                   *waiting_for_views(session, sequence_id, target_key))
    if not reasons:
        return {"published": 0, "message": f"{target_key}: no view needed for QC"}
    result = crowd_flows.publish_needed(None, sequence_id, reasons)
    return {"published": result.created + result.recovered, "reasons": reasons,
            "message": f"{target_key}: one more view published for QC to compare"}


# --- calibration -> solve ----------------------------------------------------------------


def adopt_calibration(session: Session, sequence_id: int, number: int, solve: bool = True
                      ) -> str:
    """Put calibration version ``number`` in use (0: the imported one) and, when asked and
    every task has accepted work, queue a solve under it; says what became of the solve."""
    adopt(session, sequence_id, number)
    if not solve:
        return "not requested"
    digest, missing = accepted_digest(session, sequence_id)
    if digest is None:
        return f"waiting: {missing} tasks not accepted yet"
    try:
        run = request_solve(session, sequence_id, labels_digest=digest)
    except DexlabelError as exc:
        return f"solve not started: {exc.detail}"
    return f"solve run {run.id} queued"
