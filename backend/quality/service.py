"""Quality control of a target (a hand, or one object) of a sequence: score, decide, act.

A QC job scores every submitted assignment of every view of one target together (the views
check each other), writes one report per assignment, then acts on the reports not acted on
yet, each action in its own unit of work after its marketplace call:

- approve on a clear pass; reject on a clear fail (feedback = the evidence) and re-open the
  task with one more assignment; leave borderline work to an admin;
- a provisional report (fewer than ``qc_min_views`` views in) never acts: the next submission
  to the target scores it again;
- a worker whose rejections reach ``qc_block_after_failures`` is blocked.

Re-running the job (a retry, a crashed worker, another submission) re-scores but never
repeats an action: each report's ``action`` is set in the same commit as the ledger row of
the payment it stands for.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task, TrainingClip
from backend.annotation.points import point_names
from backend.config import get_settings
from backend.crowd.models import CrowdHit, CrowdSubmission, CrowdWorkerAction
from backend.errors import NotFound
from backend.jobs.models import Job
from backend.jobs.service import enqueue_job
from backend.labels import SCORED_STATUSES
from backend.quality import gold
from backend.quality.camera_offsets import (
    camera_notes,
    lagged,
    landmark_lags,
    landmark_offsets,
    rescored,
    view_tracks,
)
from backend.quality.inputs import (
    TargetInputs,
    depth_maps,
    highlight_mask,
    import_posed_objects,
    solved_objects,
    stretch_checks,
    target_inputs,
)
from backend.quality.models import ADMIN_DECIDED, QCReport
from worker.tracks.sources import own_keyframes

if TYPE_CHECKING:
    from worker.quality.decide import QCThresholds

log = logging.getLogger(__name__)


def qc_key(sequence_id: int, target_key: str) -> str:
    return f"qc:{sequence_id}:{target_key}"


def request_qc(session: Session, task: Task) -> Job:
    """Queue the QC job of the task's target (after this unit of work commits)."""
    return enqueue_job(session, "qc", qc_key(task.sequence_id, task.target_key),
                       {"sequence_id": task.sequence_id, "target_key": task.target_key})


def request_qc_for(session: Session, sequence_id: int, target_key: str | None) -> list[Job]:
    """Queue QC for one target, or for every target of the sequence with submitted work."""
    stmt = (select(Task).join(Assignment, Assignment.task_id == Task.id)
            .where(Task.sequence_id == sequence_id, Assignment.status.in_(SCORED_STATUSES))
            .order_by(Task.id))
    if target_key:
        stmt = stmt.where(Task.target_key == target_key)
    firsts: dict[str, Task] = {}
    for task in session.scalars(stmt):
        firsts.setdefault(task.target_key, task)
    if not firsts:
        what = f"target {target_key!r} of " if target_key else ""
        raise NotFound(f"{what}sequence {sequence_id} has no submitted work to check")
    return [request_qc(session, task) for task in firsts.values()]


def request_landmark_qc(session: Session, sequence_id: int) -> list[Job]:
    """Queue QC for every object target of the sequence with submitted work (after a solve:
    its landmarks are then checked against the solved objects)."""
    stmt = (select(Task).join(Assignment, Assignment.task_id == Task.id)
            .where(Task.sequence_id == sequence_id, Task.kind == "object",
                   Assignment.status.in_(SCORED_STATUSES))
            .order_by(Task.id))
    firsts: dict[str, Task] = {}
    for task in session.scalars(stmt):
        firsts.setdefault(task.target_key, task)
    return [request_qc(session, task) for task in firsts.values()]


def thresholds_bounds(kind: str = "hand") -> QCThresholds:
    """The settings' QC threshold factors with the metric bounds of the target ``kind``
    (worker.quality.bounds.kind_bounds)."""
    from worker.quality.bounds import kind_bounds
    from worker.quality.decide import QCThresholds

    return QCThresholds(**{"bounds": kind_bounds(kind), **get_settings().qc_thresholds})


def px_lists(values: np.ndarray) -> list[Any]:
    """Pixels rounded to 0.1 px as nested lists, None where not finite."""
    out = np.round(np.asarray(values, np.float64), 1).astype(object)
    out[~np.isfinite(np.asarray(values, np.float64))] = None
    return list(out.tolist())


def replay_record(source: str, reference: np.ndarray | None, errors: np.ndarray | None,
                  issues: list[dict], shown: np.ndarray | None = None) -> dict[str, Any]:
    """What a report's replay draws, as stored: ``source`` "consensus" (the other views'
    leave-one-out reference) or "anchored" (the solved object's landmark) or "none";
    reference (F, P, 2) px and errors (F, P) px, 0.1 px, None where absent; shown (F, P)
    whether the solve sees an anchored landmark."""
    record: dict[str, Any] = {
        "source": source, "issues": issues,
        "reference": None if reference is None else px_lists(reference),
        "errors": None if errors is None else px_lists(errors)}
    if shown is not None:
        record["shown"] = np.asarray(shown, bool).astype(int).tolist()
    return record


def _replays(results: dict[str, Any], hand: dict[str, dict[str, np.ndarray]]
             ) -> dict[str, dict[str, Any]]:
    """Each result's replay record: the consensus' for hands, the anchored landmarks' for
    objects after a solve, the issues alone otherwise."""
    from worker.quality.anchored import AnchoredQC

    out = {}
    for key, qc in results.items():
        if key in hand:
            out[key] = replay_record("consensus", hand[key]["reference"], hand[key]["errors"],
                                     qc.issues)
        elif isinstance(qc, AnchoredQC) and qc.reprojection.size:
            out[key] = replay_record("anchored", qc.reprojection, qc.errors, qc.issues,
                                     qc.shown)
        else:
            out[key] = replay_record("none", None, None, list(getattr(qc, "issues", [])))
    return out


def _score(session: Session, inputs: TargetInputs, timings: dict[str, float]
           ) -> tuple[dict[str, Any], dict[str, str], bool, dict[str, dict[str, Any]]]:
    """Per-assignment QC results and scoring method ("consensus" against the other views,
    "gold" for training clips) keyed by assignment id (str), whether provisional, and each
    result's replay record."""
    from worker.quality.consensus import score_hand
    from worker.quality.stretch_qc import (
        add_stretch_results,
        discredited,
        without_contradicted,
    )

    training = set(session.scalars(select(TrainingClip.task_id).where(
        TrainingClip.task_id.in_(inputs.tasks))))
    crowd = [lab for lab in inputs.labels if inputs.who[lab.key].task_id not in training]
    results: dict[str, Any] = {}
    hand_replay: dict[str, dict[str, np.ndarray]] = {}
    provisional = False
    if inputs.kind == "hand" and crowd:
        started = time.perf_counter()
        depth = depth_maps(session, inputs.camera_rows, {lab.view for lab in crowd})
        timings["read_depth_s"] = round(time.perf_counter() - started, 3)
        started = time.perf_counter()
        checks = stretch_checks(session, inputs, crowd)
        sent = {lab.key: lab for lab in crowd}
        crowd = [without_contradicted(lab, checks[lab.key]) for lab in crowd]
        timings["stretches_s"] = round(time.perf_counter() - started, 3)
        started = time.perf_counter()
        report = score_hand(inputs.cameras, crowd, depth=depth,
                            unreferenced=discredited(crowd, checks, inputs.keyframes))
        timings["score_s"] = round(time.perf_counter() - started, 3)
        results.update(report.assignments)
        add_stretch_results(report.assignments, checks, inputs.keyframes, sent)
        hand_replay = report.replay
        provisional = bool(report.provisional)
    elif crowd:
        results.update(_score_landmarks(session, inputs, crowd, timings))
    methods = dict.fromkeys(results, "consensus")
    for lab in inputs.labels:
        if lab.key not in results:
            task_id = inputs.who[lab.key].task_id
            results[lab.key] = gold.score_training(session, task_id, lab, inputs.num_frames)
            methods[lab.key] = "gold"
    return results, methods, provisional, _replays(results, hand_replay)


def _score_landmarks(session: Session, inputs: TargetInputs, crowd: list,
                     timings: dict[str, float]) -> dict[str, Any]:
    """Object landmarks: each label on its own and against the object's motion as the other
    labels show it (worker.quality.landmarks); once the sequence is solved, or before that
    for an object nobody grasps (at its import pose), also against the known object
    (worker.quality.anchored): each landmark anchored to the object's surface and its track
    reprojected, visibility judged against the known meshes and depth, the landmarks distinct
    points in plain view (worker.quality.landmark_points)."""
    from worker.quality.anchored import merge_anchored, score_anchored
    from worker.quality.landmarks import score_object

    masks = {}
    for task in inputs.tasks.values():
        view = inputs.view_of_task[task.id]
        camera = inputs.cameras[view]
        mask = highlight_mask(task, camera.width, camera.height)
        if mask is not None:
            masks[view] = {0: mask}
    results = score_object(inputs.cameras, crowd, masks)
    started = time.perf_counter()
    target = int(inputs.target_key.split(":", 1)[1])
    # Before any solve, an object that stays where it was put is known all through: its
    # landmarks are judged against their projected anchors, not against its lack of motion.
    solved: tuple[Any, int | None] | None = solved_objects(session, inputs.sequence_id)
    if solved is None:
        posed = import_posed_objects(session, inputs.sequence_id, target)
        solved = None if posed is None else (posed, None)
    if solved is None:
        return results
    scene, run_id = solved
    depth = depth_maps(session, inputs.camera_rows, {lab.view for lab in crowd})
    anchored = {lab.key: score_anchored(inputs.cameras[lab.view], lab, scene, target,
                                        depth.get(lab.view)) for lab in crowd}
    # A camera's own lag and offset are taken out of its view before its labels are judged.
    tracks = view_tracks(session, inputs, scene, anchored)
    lags = landmark_lags(tracks)
    offsets = landmark_offsets(inputs, tracks, lags)
    for lab in crowd:
        offset, lag = offsets.get(lab.view), lags.get(lab.view, 0)
        shown = lagged(scene, lag) if lag else scene
        if offset is not None and offset.applied:
            anchored[lab.key] = rescored(inputs, lab, offset, shown, target,
                                         depth.get(lab.view))
        elif lag:
            anchored[lab.key] = score_anchored(inputs.cameras[lab.view], lab, shown, target,
                                               depth.get(lab.view))
        if lag:
            anchored[lab.key].metrics["camera_lag_frames"] = float(lag)
        results[lab.key] = merge_anchored(results[lab.key], anchored[lab.key], run_id)
    timings["anchored_s"] = round(time.perf_counter() - started, 3)
    return results


# Reports the thresholds are learned from: the project's newest consensus-scored ones of the
# target's kind. Medians and MADs of this many are stable to a few percent, and a QC job of a
# project with tens of thousands of reports reads these instead of every one.
POPULATION_LIMIT = 2000


def _population(session: Session, kind: str, fresh: dict[str, dict]) -> list[dict]:
    """Metrics of the project's newest consensus-scored assignments (at most
    ``POPULATION_LIMIT``) for this kind of target, with this run's fresh ones on top."""
    stmt = (select(QCReport.assignment_id, QCReport.metrics)
            .where(QCReport.method == "consensus", QCReport.target_key.like(f"{kind}:%"))
            .order_by(QCReport.id.desc()).limit(POPULATION_LIMIT))
    rows = {str(aid): metrics for aid, metrics in session.execute(stmt)}
    rows.update(fresh)
    return list(rows.values())


def score_target(session: Session, sequence_id: int, target_key: str,
                 timings: dict[str, float] | None = None) -> dict[str, int]:
    """Score the target's assignments and write (overwrite) their reports; counts by outcome.
    ``timings`` (if given) receives the seconds spent reading inputs and scoring."""
    from worker.quality.decide import decide, learn_thresholds

    timings = {} if timings is None else timings
    started = time.perf_counter()
    inputs = target_inputs(session, sequence_id, target_key)
    timings["read_tracks_s"] = round(time.perf_counter() - started, 3)
    results, methods, provisional, replays = _score(session, inputs, timings)
    for key, qc in results.items():  # check suggestions kept or corrected (decide.py)
        qc.metrics["checks_accepted"], qc.metrics["checks_corrected"] = inputs.who[key].checks
        # Whether the worker decided anything at all, hidden frames included (decide.py).
        qc.metrics["own_keyframes"] = own_keyframes(inputs.keyframes[key])
        qc.kept_checks = [list(cell) for cell in inputs.who[key].kept]
    fresh = {k: qc.metrics for k, qc in results.items() if methods[k] == "consensus"}
    thresholds = learn_thresholds(_population(session, inputs.kind, fresh),
                                  thresholds_bounds(inputs.kind))
    names = point_names(inputs.kind)
    views = len({lab.view for lab in inputs.labels})
    counts = {"approve": 0, "review": 0, "reject": 0, "provisional": 0}
    # The reports being overwritten, in one query.
    existing = {row.assignment_id: row for row in session.scalars(select(QCReport).where(
        QCReport.assignment_id.in_([inputs.who[key].assignment_id for key in results])))}
    for key, qc in results.items():
        method = methods[key]
        is_provisional = provisional and method == "consensus"
        decision = decide(qc, thresholds, names)
        who = inputs.who[key]
        row = existing.get(who.assignment_id)
        if row is None:
            row = QCReport(assignment_id=who.assignment_id)
            session.add(row)
        data = qc.to_dict()
        row.task_id, row.sequence_id, row.target_key = who.task_id, sequence_id, target_key
        row.worker_id, row.method = who.worker_id, method
        row.metrics, row.per_joint = data.get("metrics", {}), data.get("per_joint", [])
        row.per_frame, row.swaps = data.get("per_frame", []), data.get("swaps", [])
        row.replay = replays[key]
        row.thresholds, row.outcome = thresholds, decision.outcome
        row.reasons, row.feedback = list(decision.reasons), decision.feedback
        row.reasons += camera_notes(inputs, data.get("metrics", {}), qc.view)
        row.provisional = is_provisional or bool(decision.provisional)
        row.views = views
        counts[decision.outcome] += 1
        counts["provisional"] += int(row.provisional)
    session.flush()
    return counts


def record_decision(session: Session, assignment_id: int, decision: str) -> None:
    """An approval or rejection made outside the QC job (by an admin) on the assignment's
    report, if it has one not acted on yet."""
    row = session.scalar(select(QCReport).where(QCReport.assignment_id == assignment_id))
    if row is not None and row.action is None:
        row.action, row.action_detail = decision, ADMIN_DECIDED


def get_report_or_raise(session: Session, assignment_id: int) -> QCReport:
    row = session.scalar(select(QCReport).where(QCReport.assignment_id == assignment_id))
    if row is None:
        raise NotFound(f"assignment {assignment_id} has no QC report yet")
    return row


def list_reports(session: Session, sequence_id: int | None = None, outcome: str | None = None,
                 worker_id: str | None = None, limit: int = 500) -> list[QCReport]:
    stmt = select(QCReport).order_by(QCReport.id).limit(limit)
    if sequence_id is not None:
        stmt = stmt.where(QCReport.sequence_id == sequence_id)
    if outcome:
        stmt = stmt.where(QCReport.outcome == outcome)
    if worker_id:
        stmt = stmt.where(QCReport.worker_id == worker_id)
    return list(session.scalars(stmt))


def qc_score(outcomes: Mapping[str, int]) -> float | None:
    """A worker's running QC score from their final reports counted by outcome: approvals
    and half the reviews over every report (None without a final report)."""
    total = sum(outcomes.values())
    if not total:
        return None
    return round((outcomes.get("approve", 0) + 0.5 * outcomes.get("review", 0)) / total, 4)


def worker_quality(session: Session, worker_id: str | None = None, limit: int | None = None,
                   offset: int = 0) -> list[dict[str, Any]]:
    """Each worker's running quality: share of final (non-provisional) reports that passed;
    ``limit`` workers by id from ``offset`` on when a limit is given."""
    stmt = (select(QCReport.worker_id, QCReport.outcome, func.count())
            .where(QCReport.provisional.is_(False))
            .group_by(QCReport.worker_id, QCReport.outcome))
    if worker_id:
        stmt = stmt.where(QCReport.worker_id == worker_id)
    tally: dict[str, dict[str, int]] = {}
    for wid, outcome, count in session.execute(stmt):
        tally.setdefault(wid, {"approve": 0, "review": 0, "reject": 0})[outcome] = int(count)
    blocked = set(session.scalars(select(CrowdWorkerAction.worker_id).where(
        CrowdWorkerAction.kind == "block")))
    out = []
    page = sorted(tally.items())[offset:None if limit is None else offset + limit]
    for wid, t in page:
        total = sum(t.values())
        out.append({"worker_id": wid, "scored": total, "approved": t["approve"],
                    "review": t["review"], "rejected": t["reject"],
                    "score": qc_score(t),
                    "blocked": wid in blocked})
    return out


def hit_of(session: Session, assignment: Assignment) -> CrowdHit | None:
    submission = session.scalar(select(CrowdSubmission).where(
        CrowdSubmission.assignment_id == assignment.id))
    if submission is None:
        return None
    return session.scalar(select(CrowdHit).where(CrowdHit.hit_id == submission.hit_id))
