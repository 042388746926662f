"""Publishing views where the 3D needs them: the adaptive policy, beside DexYCB's every view.

Under ``every-view`` a publish sends every due (target, view) task at once. Under ``adaptive``
a publish sends, per target (a hand or an object of a sequence) none of whose views is
published yet, the ``initial_views`` views that pin its 3D best (worker.geometry.view_choice:
the widest baselines among the views that see it, seen from where the target is: an object's
initial pose, a hand at its grasped object, else the point the rig looks at). The other views
are *held*: they wait, and the sequence's solve waits for the published ones only. After each
solve, :func:`needed_views` names, per target whose frames are confident (solve confidence at
least ``confidence``, no flag) on fewer than ``confident_share`` of its frames, the one held
view that best covers the weak frames; it is published with the reason, and the next solve
judges again, until the target is confident or every view is published.

QC compares each label with the other views' (at least worker.quality.support.MIN_VIEWS in
all): with fewer views in, it leaves the work provisional and nothing is accepted, so no solve
runs. When every published view of a target has submitted work and some of it waits for
views to compare with, :func:`views_to_compare` names one held view to publish (the one that
best widens the baselines at the target), until QC can decide.

Occlusion is judged by whether the target lies in front of a camera and inside its image (the
object's initial pose, the hand's grasped object). A hand's initial views start from the view
its first worker labels best from nothing (worker.geometry.view_choice.start_views: the moving
hand whole in the image and far from the camera, read from START_SAMPLES of each view's depth
maps), then widen the baselines from it, among the views that keep the hand whole before the
others: QC accepts nothing before it can compare 3 views, so every initial view is worked with
no other view's work to suggest from. The start view is published first, so it heads the
crowd's list. Without depth (or with no view that qualifies) the widest pair leads as before.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np
from sqlalchemy import ColumnElement, and_, select
from sqlalchemy.orm import Session

from backend.annotation.models import Task
from backend.captures.assets import load_depth
from backend.captures.calibration import calibrated_models
from backend.captures.models import Camera, Frame, SceneObject
from backend.config import get_settings
from backend.crowd.models import CrowdHit, PublishPlan
from backend.crowd.schemas import PublishOptions
from backend.errors import NotFound, StorageError
from backend.storage import get_storage
from worker.geometry.cameras import CameraModel
from worker.geometry.view_choice import (
    HandInView,
    hand_in_view,
    initial_views,
    next_view,
    rig_centre,
    seen,
    start_views,
)
from worker.quality.support import MIN_VIEWS as QC_MIN_VIEWS
from worker.tracks.spans import format_spans, frame_spans

EVERY_VIEW, ADAPTIVE = "every-view", "adaptive"
INITIAL_REASON = "initial: widest baselines"
START_REASON = "initial: worked first, the hand whole in view"
# Depth maps read per view to choose a hand's start view (the clip's first frame among them).
START_SAMPLES = 18
# Frame ranges named in a reason before the rest is summed up (the column holds 300 chars).
REASON_RANGES = 6
REASON_CHARS = 300


@dataclass(frozen=True)
class Policy:
    """A publish's policy and its numbers (see the module)."""

    name: str
    initial_views: int
    confidence: float
    confident_share: float


@dataclass(frozen=True)
class TargetTrust:
    """What a solve says of one target: confidence (F,) in [0, 1], flags (F,) str ("" =
    trusted) and points (F, N, 3) world metres (NaN where unknown) where the target was
    solved."""

    confidence: np.ndarray
    flags: np.ndarray
    points: np.ndarray


def policy_of(options: PublishOptions) -> Policy:
    """The options' policy, each number the setting's where the options leave it unset."""
    s = get_settings()
    return Policy(options.policy or s.publish_policy,
                  options.initial_views or s.publish_initial_views,
                  options.confidence or s.publish_confidence,
                  options.confident_share or s.publish_confident_share)


def plan_of(session: Session, sequence_id: int) -> PublishPlan | None:
    return session.scalar(select(PublishPlan).where(PublishPlan.sequence_id == sequence_id))


def record_plan(session: Session, sequence_id: int, policy: Policy,
                options: PublishOptions) -> PublishPlan:
    """Keep the sequence's policy and the options of its publish (the publishes after each
    solve use them again); the last publish's win."""
    plan = plan_of(session, sequence_id)
    if plan is None:
        plan = PublishPlan(sequence_id=sequence_id)
        session.add(plan)
    plan.policy, plan.initial_views = policy.name, policy.initial_views
    plan.confidence, plan.confident_share = policy.confidence, policy.confident_share
    plan.options = options.model_dump(mode="json")
    return plan


def plan_policy(plan: PublishPlan) -> Policy:
    return Policy(plan.policy, plan.initial_views, plan.confidence, plan.confident_share)


def held() -> ColumnElement[bool]:
    """Whether a task (a row of ``tasks`` in the statement) is held back by the adaptive
    policy: of a sequence published under it, with no unit in any round. A clause, so that the
    readers that list tasks learn it in the statement they make anyway."""
    adaptive = select(PublishPlan.sequence_id).where(PublishPlan.policy == ADAPTIVE)
    unit = select(CrowdHit.id).where(CrowdHit.task_id == Task.id)
    return and_(Task.sequence_id.in_(adaptive), ~unit.exists())


def held_task_ids(session: Session, sequence_ids: list[int]) -> set[int]:
    """Tasks of ``sequence_ids`` that the adaptive policy holds back (see :func:`held`)."""
    return set(session.scalars(select(Task.id).where(
        Task.sequence_id.in_(sequence_ids), held())))


def _published_ids(session: Session, task_ids: list[int]) -> set[int]:
    return set(session.scalars(select(CrowdHit.task_id).where(CrowdHit.task_id.in_(task_ids))))


def _target_tasks(session: Session, sequence_id: int) -> dict[str, list[Task]]:
    """The sequence's tasks per target key, each list in view order."""
    rows = session.scalars(select(Task).join(Camera, Camera.id == Task.camera_id)
                           .where(Task.sequence_id == sequence_id)
                           .order_by(Task.target_key, Camera.view_index))
    out: dict[str, list[Task]] = defaultdict(list)
    for task in rows:
        out[task.target_key].append(task)
    return dict(out)


def _anchor(session: Session, tasks: list[Task], models: list[CameraModel]) -> np.ndarray:
    """(3,) world metres: where the target is before anything is solved (see the module)."""
    task = tasks[0]
    if task.object_id is not None:
        obj = session.get_one(SceneObject, task.object_id)
        objects = [obj]
    else:
        objects = list(session.scalars(select(SceneObject).where(
            SceneObject.sequence_id == task.sequence_id, SceneObject.grasped.is_(True))
            .order_by(SceneObject.index)))
    for obj in objects:
        if obj.initial_pose is not None:
            return np.asarray(obj.initial_pose, np.float64)[:3, 3]
    return rig_centre(models)


def _views(tasks: list[Task]) -> str:
    """The tasks' views by camera serial, as the admin page names them."""
    return ", ".join(task.camera.serial for task in tasks)


def initial_choice(session: Session, tasks: list[Task], count: int) -> dict[int, str]:
    """The initial tasks of one target (its tasks in view order) and their reason, in the
    order they are published: a hand's start view first, the other initial views taken from
    the views that keep the hand whole before the rest (see the module), in view order."""
    whole = start_views(_hands_in_view(session, tasks)) if tasks[0].kind == "hand" else []
    first = whole[0] if whole else None
    if len(tasks) <= count:
        chosen, reason = list(range(len(tasks))), f"{INITIAL_REASON} (all {len(tasks)} views)"
    else:
        models = calibrated_models(session, [task.camera for task in tasks])
        chosen = initial_views(models, _anchor(session, tasks, models), count, first, whole)
        reason = f"{INITIAL_REASON} ({count} of {len(tasks)} views)"
    order = sorted(chosen) if first is None else [first, *sorted(set(chosen) - {first})]
    out = {tasks[i].id: reason for i in order}
    if first is not None:
        out[tasks[first].id] = reason.replace(INITIAL_REASON, START_REASON)
    return out


def _hands_in_view(session: Session, tasks: list[Task]) -> list[HandInView | None]:
    """Per task, what START_SAMPLES of its view's depth maps say of the moving hand (None: the
    view has no depth, or a map could not be read; the view is then not a start view)."""
    storage = get_storage()
    out: list[HandInView | None] = []
    for task in tasks:
        frames = list(session.scalars(select(Frame).where(Frame.camera_id == task.camera_id)
                                      .order_by(Frame.index)))
        sampled = frames[::max(1, -(-len(frames) // START_SAMPLES))]
        try:
            depth = load_depth(storage, task.camera, sampled) if len(sampled) >= 2 else None
        except (ValueError, NotFound, StorageError):
            # Publishing goes on without this view's depth: it is not a start view.
            depth = None
        out.append(None if depth is None else hand_in_view(depth))
    return out


def select_due(session: Session, task_ids: list[int], policy: Policy) -> dict[int, str | None]:
    """Which of the due ``task_ids`` a publish under ``policy`` sends, with each one's reason
    (None: every view at once, or a task already published in an earlier round)."""
    if policy.name == EVERY_VIEW or not task_ids:
        return dict.fromkeys(task_ids)
    due = set(task_ids)
    out: dict[int, str | None] = {}
    for sequence_id in sorted(set(session.scalars(
            select(Task.sequence_id).where(Task.id.in_(task_ids))))):
        by_target = _target_tasks(session, sequence_id)
        published = _published_ids(session, [t.id for g in by_target.values() for t in g])
        for tasks in by_target.values():
            if due.isdisjoint(t.id for t in tasks):
                continue
            # The initial views (again, where a publish stopped half way), and, in later
            # rounds, the views published before; the views the solves add follow them.
            for t in tasks:
                if t.id in due and t.id in published:
                    out[t.id] = None
            if not any(t.id in due and t.id not in published for t in tasks):
                continue
            chosen = initial_choice(session, tasks, policy.initial_views)
            out.update({task_id: reason for task_id, reason in chosen.items()
                        if task_id in due and task_id not in published})
    # Each target's initial views in the order initial_choice gives (its start view first),
    # the rest in the order asked.
    ordered = [task_id for task_id in out if out[task_id] is not None]
    return {task_id: out[task_id] for task_id in
            [*ordered, *(t for t in task_ids if t in out and out[t] is None)]}


def frame_ranges(flags: np.ndarray) -> str:
    """"frames 12-30, 40" where ``flags`` (F,) is true (the first REASON_RANGES spans, then a
    count), named as every message names frames (worker.tracks.spans)."""
    spans = frame_spans(flags)
    text = format_spans(spans[:REASON_RANGES])
    if len(spans) > REASON_RANGES:
        text += f" and {len(spans) - REASON_RANGES} more stretches"
    return text


def weak_frames(trust: TargetTrust, policy: Policy) -> np.ndarray:
    """(F,) bool: frames below the confidence or flagged."""
    return np.asarray((np.asarray(trust.confidence) < policy.confidence)
                      | (np.asarray(trust.flags) != ""))


def needed_views(session: Session, sequence_id: int, trust: dict[str, TargetTrust],
                 solved_at: datetime | None = None) -> dict[int, str]:
    """After a solve: per target of an adaptive sequence whose confident frames fall short of
    the plan's share and that has held views, the held task that best covers its weak frames,
    with the reason. Empty under every view, or when every target is confident or complete.
    A target given a view since ``solved_at`` (the solve's end: a publish run again) waits
    for the next solve."""
    plan = plan_of(session, sequence_id)
    if plan is None or plan.policy != ADAPTIVE:
        return {}
    policy = plan_policy(plan)
    out: dict[int, str] = {}
    for target, tasks in sorted(_target_tasks(session, sequence_id).items()):
        if target not in trust or _added_since(session, tasks, solved_at):
            continue
        published = _published_ids(session, [t.id for t in tasks])
        held = [i for i, t in enumerate(tasks) if t.id not in published]
        done = [i for i, t in enumerate(tasks) if t.id in published]
        weak = weak_frames(trust[target], policy)
        if not held or not weak.size or 1.0 - weak.mean() >= policy.confident_share:
            continue
        models = calibrated_models(session, [task.camera for task in tasks])
        points = np.asarray(trust[target].points, np.float64)[weak]
        if not np.isfinite(points).all(axis=-1).any() or not seen(models, points).any():
            points = _anchor(session, tasks, models).reshape(1, 1, 3)
        view, _score = next_view(models, done, held, points)
        out[tasks[view].id] = (
            f"{frame_ranges(weak)} below confidence "
            f"{policy.confidence:g} or flagged after views "
            f"{_views([tasks[i] for i in done])}")[:REASON_CHARS]
    return out


def views_to_compare(session: Session, sequence_id: int, target_key: str,
                     waiting: set[int], covered: set[int]) -> dict[int, str]:
    """For a target of an adaptive sequence whose tasks ``waiting`` hold work that QC left
    provisional (too few views to compare it with), the held task to publish next, with the
    reason. Empty when nothing waits, when no view is held, or while a published view of the
    target is not in ``covered`` (tasks with work QC kept): its work is still to come (being
    done, or re-opened after a rejection) and may let QC decide."""
    plan = plan_of(session, sequence_id)
    if plan is None or plan.policy != ADAPTIVE or not waiting:
        return {}
    tasks = _target_tasks(session, sequence_id).get(target_key, [])
    published = _published_ids(session, [t.id for t in tasks])
    held = [i for i, t in enumerate(tasks) if t.id not in published]
    done = [i for i, t in enumerate(tasks) if t.id in published]
    if not held or not done or not published <= covered:
        return {}
    models = calibrated_models(session, [task.camera for task in tasks])
    view, _score = next_view(models, done, held,
                             _anchor(session, tasks, models).reshape(1, 1, 3))
    named = [t for t in tasks if t.id in waiting]
    return {tasks[view].id: (
        f"QC compares each label with at least {QC_MIN_VIEWS} views: the work in "
        f"{_views(named)} waits for another view")[:REASON_CHARS]}


def _added_since(session: Session, tasks: list[Task], since: datetime | None) -> bool:
    if since is None:
        return False
    return session.scalar(select(CrowdHit.id).where(
        CrowdHit.task_id.in_([t.id for t in tasks]), CrowdHit.created_at > since).limit(1)) \
        is not None


def plan_options(session: Session, sequence_id: int) -> PublishOptions | None:
    """The publish options the sequence's adaptive plan keeps (None: no adaptive plan)."""
    plan = plan_of(session, sequence_id)
    if plan is None or plan.policy != ADAPTIVE:
        return None
    options: dict[str, Any] = dict(plan.options)
    return PublishOptions.model_validate(options)
