"""Progress endpoints: where a sequence's tasks and solve stand; the admin's task routes,
which answer with each task's state derived from its work."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, Query
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.accounts.deps import CurrentAdmin
from backend.annotation import service as tasks
from backend.annotation.deps import WorkerClaims
from backend.annotation.models import Task
from backend.annotation.points import point_colours, point_names, skeleton
from backend.annotation.schemas import (
    AnnotateTaskRead,
    AssignmentRead,
    FramesLinks,
    HighlightUpdate,
    TaskRead,
    TaskState,
    TracksPayload,
)
from backend.annotation.tokens import READONLY_SCOPE, TASK_SCOPE, frame_token
from backend.captures.models import Sequence
from backend.captures.service import object_label
from backend.db import SessionDep
from backend.errors import NotFound
from backend.progress.frame_costs import frame_costs
from backend.progress.schemas import SequenceFrameCost, SequenceProgress
from backend.progress.service import sequence_progress, sequences_progress, task_states
from backend.storage import get_storage
from backend.validation import Id, Offset, QueryId

router = APIRouter(prefix="/api", tags=["progress"])


@router.get("/progress", response_model=list[SequenceProgress])
def list_progress(session: SessionDep, _: CurrentAdmin, limit: int = Query(50, ge=1, le=1000),
                  offset: Offset = 0) -> list[SequenceProgress]:
    """The progress of sequences in id order, ``limit`` (50, at most 1,000) from ``offset`` on:
    the same page as GET /api/sequences with the same ``limit`` and ``offset``."""
    ids = list(session.scalars(select(Sequence.id).order_by(Sequence.id)
                               .offset(offset).limit(limit)))
    return sequences_progress(session, ids)


@router.get("/sequences/{sequence_id}/progress", response_model=SequenceProgress)
def get_progress(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> SequenceProgress:
    """Every view x target task's state (open, published, submitted, in review, accepted)
    with its HIT and assignment counts, the totals, and the sequence's latest solve run."""
    return sequence_progress(session, sequence_id)


@router.get("/frame-costs", response_model=list[SequenceFrameCost])
def list_frame_costs(session: SessionDep, _: CurrentAdmin, limit: int = Query(50, ge=1, le=200),
                     offset: Offset = 0) -> list[SequenceFrameCost]:
    """Per sequence (in id order, ``limit`` from ``offset``) and target: human actions,
    working seconds and money spent (the crowd ledger's) per frame its current solve labelled
    and did not flag; totals per sequence."""
    ids = list(session.scalars(select(Sequence.id).order_by(Sequence.id)
                               .offset(offset).limit(limit)))
    return frame_costs(session, ids)


@router.get("/sequences/{sequence_id}/frame-costs", response_model=SequenceFrameCost)
def get_frame_costs(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> SequenceFrameCost:
    """One sequence's cost per labelled 3D frame, per target and in total."""
    found = frame_costs(session, [sequence_id])
    if not found:
        raise NotFound(f"sequence {sequence_id} does not exist")
    return found[0]


# ----- tasks, each with its state derived from its work ----------------------------------

# The annotation domain's task routes, answered with each task's state (under its tag).
tasks_router = APIRouter(prefix="/api", tags=["annotation"])

def _task_reads(session: Session, tasks: list[Task]) -> list[TaskRead]:
    """The tasks as the API shows them, each with its state derived from its work."""
    states = task_states(session, [t.id for t in tasks])
    return [_task_read(t, states[t.id].state) for t in tasks]


def _target(task: Task) -> str:
    """What the task labels, as a worker calls it: "right hand", "mustard bottle"."""
    if task.kind != "hand":
        obj = next((o for o in task.sequence.objects if o.id == task.object_id), None)
        return object_label(obj.name) if obj is not None else "object"
    side = next((h.side for h in task.sequence.hands if h.id == task.hand_id), None)
    return f"{side} hand" if side else "hand"


def _task_read(task: Task, status: TaskState) -> TaskRead:
    serials = [camera.serial for camera in task.sequence.cameras]
    return TaskRead(
        id=task.id, kind=task.kind, sequence_id=task.sequence_id, serial=task.camera.serial,
        view_number=serials.index(task.camera.serial) + 1, num_views=len(serials),
        view_serials=serials, target=_target(task),
        target_key=task.target_key, num_points=task.num_points,
        num_frames=task.sequence.num_frames, width=task.camera.width, height=task.camera.height,
        fps=task.sequence.fps, point_names=point_names(task.kind),
        point_colors=point_colours(task.kind), skeleton=skeleton(task.kind),
        highlight=task.highlight, status=status,
    )


@tasks_router.post("/sequences/{sequence_id}/tasks", response_model=list[TaskRead])
def create_tasks(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> list[TaskRead]:
    """One task per view and target; running it again creates only what is missing."""
    made = tasks.create_tasks(session, get_storage(), sequence_id)
    return _task_reads(session, [tasks.get_task_or_raise(session, t.id) for t in made])


@tasks_router.get("/tasks", response_model=list[TaskRead])
def list_tasks(session: SessionDep, _: CurrentAdmin, sequence_id: QueryId = None,
               limit: int = Query(500, ge=1, le=5000),
               offset: Offset = 0) -> list[TaskRead]:
    """Tasks in id order, ``limit`` (500, at most 5,000) from ``offset`` on."""
    return _task_reads(session, tasks.list_tasks(session, sequence_id, limit, offset))


@tasks_router.put("/tasks/{task_id}/highlight", response_model=TaskRead)
def set_highlight(task_id: Id, body: HighlightUpdate, session: SessionDep,
                  _: CurrentAdmin) -> TaskRead:
    """Draw the object's box by hand (when its projected initial pose is missing or wrong)."""
    task = tasks.set_highlight_box(session, tasks.get_task_or_raise(session, task_id), body.box)
    return _task_reads(session, [task])[0]


# ----- the annotation page's task: the task, where it stands, its frames, the assignment ----

page_router = APIRouter(prefix="/api", tags=["annotation"])


@page_router.get("/annotate/task", response_model=AnnotateTaskRead)
def read_task(claims: WorkerClaims, session: SessionDep) -> AnnotateTaskRead:
    task = tasks.get_task_or_raise(session, int(claims["task_id"]))
    # The frame links carry a read-only view token of their own, never the page's token.
    base = f"/api/sequences/{task.sequence_id}/views/{task.camera.serial}"
    token = frame_token(task)
    frames = FramesLinks(bundle_url=f"{base}/frames.bin?token={token}",
                         manifest_url=f"{base}/frames?token={token}")
    if claims["scope"] == TASK_SCOPE:
        return AnnotateTaskRead(mode="preview", task=_task_reads(session, [task])[0], frames=frames,
                                assignment=None)
    assignment = tasks.get_assignment_or_raise(session, int(claims["assignment_id"]))
    payload = tasks.tracks_payload(assignment)
    read = AssignmentRead(
        id=assignment.id, external_id=assignment.external_id, worker_id=assignment.worker_id,
        status=assignment.status, version=assignment.version, edit_count=assignment.edit_count,
        working_time_s=assignment.working_time_s,
        tracks=TracksPayload.model_validate(payload) if payload else None,
    )
    mode: Literal["edit", "submitted", "review"] = "review" if claims["scope"] == READONLY_SCOPE \
        else "edit" if assignment.status == "working" else "submitted"
    return AnnotateTaskRead(mode=mode, task=_task_reads(session, [task])[0], frames=frames,
                            assignment=read)
