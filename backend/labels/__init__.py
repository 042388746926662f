"""The accepted-labels read model: which assignments' tracks count, for QC, the solve, the
export and pre-fill, and those tracks as the arrays they take.

- accepted labels: assignments whose status is ACCEPTED (approved by QC or by an admin); the
  solve fits them, the export's default ``include="accepted"`` writes them;
- scored labels: submitted or accepted work the marketplace has vouched for (QC's consensus);
- submitted work: every assignment that was submitted, whatever became of it (the export's
  ``include="submitted"``, each with its QC outcome).

A view's labels are dense (F, P, 2) image px (NaN = no position) and (F, P) visibility; where
several are approved for one task (one view of one target) they are merged per frame: the
median of their positions and visible where most of them say visible. Hand labels can first be
checked against their own view's images (worker.assist.stretches): an interpolated stretch
the images say the hand left is dropped from the merge, and each view keeps, per frame and
joint, the best evidence any of its workers gave (keyed, confirmed by the images, unchecked).
"""

from __future__ import annotations

import hashlib
from collections import defaultdict
from collections.abc import Iterable, Sequence
from typing import Any, Literal

import numpy as np
from sqlalchemy import ColumnElement, Select, exists, func, or_, select
from sqlalchemy.orm import Session, selectinload

from backend.annotation.models import Assignment, Task
from backend.annotation.proposals import grey_frames
from backend.crowd.adaptive import held
from backend.crowd.models import CrowdSubmission
from backend.storage import get_storage
from worker.assist.stretches import (
    EVIDENCE_CONFIRMED,
    EVIDENCE_CONTRADICTED,
    EVIDENCE_KEYED,
    EVIDENCE_NONE,
    EVIDENCE_UNCHECKED,
    check_stretches,
)
from worker.tracks.interpolate import dense_points

ACCEPTED = "approved"
ACCEPTED_STATUSES: tuple[str, ...] = (ACCEPTED,)
# Assignments whose labels take part in scoring; rejected work is left out of the consensus.
SCORED_STATUSES: tuple[str, ...] = ("submitted", ACCEPTED)
SUBMITTED_STATUSES: tuple[str, ...] = ("submitted", ACCEPTED, "rejected")
Include = Literal["accepted", "submitted"]
INCLUDE_STATUSES: dict[str, tuple[str, ...]] = {"accepted": ACCEPTED_STATUSES,
                                                "submitted": SUBMITTED_STATUSES}

# Marketplace work takes part once the requester API has vouched for it (its confirmation
# recorded a CrowdSubmission: the marketplace's record names its HIT and worker), so work on
# an assignment id the marketplace does not know never enters the consensus. Work from an
# admin's direct link has no HIT. (Correlated: each candidate assignment is looked up by the
# unique index on crowd_submissions.assignment_id, not the whole table read into a hash.)
VOUCHED_FOR: ColumnElement[bool] = or_(
    Assignment.hit_id.is_(None), exists().where(CrowdSubmission.assignment_id == Assignment.id))


def sequence_tasks(session: Session, sequence_id: int, target_key: str | None = None
                   ) -> list[Task]:
    """A sequence's tasks (of one target, if given) in id order."""
    stmt = select(Task).where(Task.sequence_id == sequence_id).order_by(Task.id)
    if target_key is not None:
        stmt = stmt.where(Task.target_key == target_key)
    return list(session.scalars(stmt))


def work_query(task_ids: Iterable[int], statuses: Sequence[str] = ACCEPTED_STATUSES,
               vouched: bool = False, with_tracks: bool = True) -> Select[Assignment]:
    """The assignments of ``task_ids`` in ``statuses`` (only vouched-for ones if ``vouched``),
    in id order, their tracks loaded in one more query."""
    stmt = select(Assignment).where(Assignment.task_id.in_(list(task_ids)),
                                    Assignment.status.in_(statuses))
    if vouched:
        stmt = stmt.where(VOUCHED_FOR)
    if with_tracks:
        stmt = stmt.options(selectinload(Assignment.tracks))
    return stmt.order_by(Assignment.id)


def labelled_work(session: Session, task_ids: Iterable[int],
                  statuses: Sequence[str] = ACCEPTED_STATUSES, vouched: bool = False
                  ) -> list[Assignment]:
    """The assignments of :func:`work_query`, with their tracks."""
    return list(session.scalars(work_query(task_ids, statuses, vouched)))


def count_accepted(session: Session, sequence_id: int) -> int:
    """How many accepted assignments the sequence has."""
    tasks = list(session.scalars(select(Task.id).where(Task.sequence_id == sequence_id)))
    stmt = select(func.count(Assignment.id)).where(Assignment.task_id.in_(tasks),
                                                   Assignment.status.in_(ACCEPTED_STATUSES))
    return int(session.scalar(stmt) or 0)


def accepted_ids_by_task(session: Session, task_ids: Iterable[int]) -> list[tuple[int, int]]:
    """(task id, assignment id) of every accepted assignment of ``task_ids``, by assignment."""
    rows = session.execute(
        select(Assignment.task_id, Assignment.id)
        .where(Assignment.task_id.in_(list(task_ids)), Assignment.status.in_(ACCEPTED_STATUSES))
        .order_by(Assignment.id)).all()
    return [(int(task_id), int(assignment_id)) for task_id, assignment_id in rows]


def accepted_digest(session: Session, sequence_id: int, excused: Iterable[int] = ()
                    ) -> tuple[str | None, int]:
    """(digest of the accepted assignments, tasks still without one); the digest is None
    while any task of the sequence lacks accepted work. Tasks the adaptive publishing policy
    holds back (backend.crowd.adaptive) are not waited for, nor the ``excused`` task ids."""
    return accepted_digests(session, [sequence_id], excused)[sequence_id]


def accepted_digests(session: Session, sequence_ids: list[int], excused: Iterable[int] = ()
                     ) -> dict[int, tuple[str | None, int]]:
    """:func:`accepted_digest` of each sequence, in two statements whatever their number."""
    skip = set(excused)
    task_sequence = {task_id: seq_id for task_id, seq_id in session.execute(
        select(Task.id, Task.sequence_id).where(Task.sequence_id.in_(sequence_ids), ~held()))
        if task_id not in skip}
    tasks: dict[int, set[int]] = {i: set() for i in sequence_ids}
    for task_id, seq_id in task_sequence.items():
        tasks[seq_id].add(task_id)
    accepted: dict[int, list[tuple[int, int]]] = {i: [] for i in sequence_ids}
    for task_id, assignment_id in accepted_ids_by_task(session, task_sequence):
        accepted[task_sequence[task_id]].append((task_id, assignment_id))
    out: dict[int, tuple[str | None, int]] = {}
    for seq_id in sequence_ids:
        missing = len(tasks[seq_id] - {task_id for task_id, _ in accepted[seq_id]})
        if not tasks[seq_id] or missing:
            out[seq_id] = (None, missing)
            continue
        ids = ",".join(str(assignment_id) for _, assignment_id in accepted[seq_id])
        out[seq_id] = (hashlib.sha256(ids.encode()).hexdigest(), 0)
    return out


def dense_labels(assignment: Assignment, num_frames: int,
                 num_points: int) -> tuple[np.ndarray, np.ndarray]:
    """One assignment's tracks as (F, P, 2) px (NaN = no position) and (F, P) visibility."""
    return dense_points(((t.point_index, t.keyframes) for t in assignment.tracks), num_frames,
                        num_points)


def merge_labels(labels: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Several workers' labels of one view: per-frame median position, majority visibility.

    labels: A pairs of (F, P, 2) px and (F, P) bool. Returns (F, P, 2) px (NaN where nobody
    placed the point) and (F, P) bool, visible where more than half of the A workers say so.
    """
    xy = np.stack([x for x, _ in labels])
    votes = np.stack([v for _, v in labels]).sum(axis=0)
    placed = np.isfinite(xy).all(axis=-1).any(axis=0)
    merged = np.full(xy.shape[1:], np.nan)
    if placed.any():
        merged[placed] = np.nanmedian(xy[:, placed], axis=0)
    return merged, 2 * votes > len(labels)


def merge_evidence(codes: list[np.ndarray]) -> np.ndarray:
    """(F, P) int8: per frame and point the best EVIDENCE_* code among a view's workers
    (keyed before confirmed before unchecked; no label and contradicted count last)."""
    rank = np.array([9, 0, 1, 2, 8], dtype=np.int8)  # indexed by code
    ranked = np.stack([rank[c] for c in codes]).min(axis=0)
    back = np.full(10, EVIDENCE_NONE, dtype=np.int8)
    back[[0, 1, 2, 8]] = [EVIDENCE_KEYED, EVIDENCE_CONFIRMED, EVIDENCE_UNCHECKED,
                          EVIDENCE_CONTRADICTED]
    return back[ranked]


def approved_labels(session: Session, sequence_id: int, num_frames: int,
                    evidence: dict[tuple[int, str], np.ndarray] | None = None
                    ) -> dict[tuple[int, str], tuple[np.ndarray, np.ndarray]]:
    """Merged approved labels keyed by (camera id, target key) of every task that has any.

    With ``evidence`` (a dict to fill), hand labels are first checked against their view's
    images (see the module) and it receives each hand view's merged (F, P) EVIDENCE_* codes
    under the same key; without it, the labels are merged as stored (database reads only)."""
    # The sequence's tasks, then their approved work by task (each read by its index).
    tasks = {task.id: task for task in sequence_tasks(session, sequence_id)}
    grouped: dict[tuple[int, str], list] = defaultdict(list)
    codes: dict[tuple[int, str], list[np.ndarray]] = defaultdict(list)
    grey: dict[int, np.ndarray] = {}
    for assignment in labelled_work(session, tasks):
        task = tasks[assignment.task_id]
        key = (task.camera_id, task.target_key)
        xy, visible = dense_labels(assignment, num_frames, task.num_points)
        if task.kind == "hand" and evidence is not None:
            if task.camera_id not in grey:
                grey[task.camera_id] = grey_frames(
                    session, get_storage(), task.camera_id, 0, num_frames - 1,
                    (task.camera.width, task.camera.height))
            check = check_stretches(grey[task.camera_id],
                                    track_rows(assignment, task.num_points))
            xy[check.contradicted], visible[check.contradicted] = np.nan, False
            codes[key].append(check.evidence)
        grouped[key].append((xy, visible))
    if evidence is not None:
        evidence.update({key: merge_evidence(found) for key, found in codes.items()})
    return {key: merge_labels(labels) for key, labels in grouped.items()}


def track_rows(assignment: Assignment, num_points: int) -> list[list[list[Any]]]:
    """The assignment's stored keyframe rows, one list per point (empty where none)."""
    rows: list[list[list[Any]]] = [[] for _ in range(num_points)]
    for track in assignment.tracks:
        if 0 <= track.point_index < num_points:
            rows[track.point_index] = list(track.keyframes)
    return rows
