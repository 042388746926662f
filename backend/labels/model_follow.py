"""The hand model followed through a view's depth, for the annotation page: proposals for a hand
view that no other view's accepted work can suggest yet (the first views of a target).

The page sends the worker's keyframes (the anchors, as saved). Once one frame has
FOLLOW_START_JOINTS visible keyed joints, the hand model is fitted to them on this view's
depth and carried frame by frame through the clip (worker.solver.follow). That takes CPU
seconds per frame and PyTorch, so it never runs in a request: the request queues a
MODEL_FOLLOW_KIND job (compute_model_follow) and answers ``preparing`` until the job has
stored the result in storage under a digest of what it rests on (the keyframes, the view's
calibration, the hand's shape). One such job per task runs at a time: a worker who asks again
with other keyframes while one runs is told to wait for it.

The answer is, per point and frame of the clip, the followed position (image px) and whether
it is a proposal (ok): only where the point's keyframes have it visible (keyed visible or
between two visible keyframes) and not at a keyframe of the point. The assignment's check
cells (worker.assist.checks) are planted into the proposals, as into every suggestion the
page shows. Nothing the worker sees is written: a proposal the worker accepts is saved as a
"tracked" keyframe, as an accepted tracking proposal is.
"""

from __future__ import annotations

import hashlib
import io
import json
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation import service
from backend.annotation.models import Assignment, Task
from backend.annotation.schemas import MAX_POINTS, TrackIn, TracksSave
from backend.captures.assets import hand_model_for
from backend.captures.calibration import hand_betas, version_in_use
from backend.captures.models import Hand
from backend.captures.service import camera_model
from backend.config import get_settings
from backend.db import session_scope
from backend.errors import DexlabelError, StorageError
from backend.jobs.models import Job
from backend.jobs.runner import ACTIVE
from backend.jobs.service import enqueue_job, last_error_line
from backend.labels.suggestions import depth_reader
from backend.storage import Storage, get_storage
from backend.validation import MAX_INT32
from worker.assist.checks import check_key, plant
from worker.hand.joints import NUM_JOINTS
from worker.solver.types import FOLLOW_START_JOINTS
from worker.tracks.interpolate import dense_track
from worker.tracks.keyframes import as_keyframes

MODEL_FOLLOW_KIND = "model_follow"
# Clips longer than this are not followed (about a second of CPU a frame: a longer follow
# would hold the queue for minutes).
MAX_MODEL_FRAMES = 300
# The follow's stop reasons (worker.solver.follow.STOP_*), here without PyTorch.
Stopped = Literal["end", "depth", "keyframes"]
_START_REFUSED = {
    "depth": "the hand you keyed there does not lie on this view's depth (are the joints on "
             "the hand?)",
    "keyframes": "the hand model cannot take the pose you keyed there (is every joint the "
                 "one its number names?)",
}


class InvalidModelFollow(DexlabelError, status_code=422, code="invalid_model_follow"):
    pass


class ModelFollowRequest(BaseModel):
    """The worker's keyframes (as saved: per point ``[frame, x, y, visible01]`` rows; every
    keyframe, accepted proposals too: all the worker has checked) and, optionally, the frame
    to propose forward from (``begin``: the first frame at or after it with enough keyed
    joints; the page sends the frame it is on once an earlier frame has them, a correction,
    and the follow is carried there through the keyframes before it); without it the follow
    starts at the first such frame and runs both ways."""

    model_config = ConfigDict(extra="forbid")

    tracks: list[TrackIn] = Field(max_length=MAX_POINTS)
    begin: int | None = Field(default=None, ge=0, le=MAX_INT32)


class ModelStop(BaseModel):
    """Where the follow ended in one direction: the last frame it reached (``reached``; the
    start frame when it reached none) and why: ``end`` (the clip's end), ``depth`` (the
    view's depth no longer fits the hand there)."""

    direction: Literal["forward", "backward"]
    reached: int
    stopped: Stopped


class ModelPoint(BaseModel):
    """One point over the clip: per frame the followed position [x, y] (image px) or null,
    and whether it is a proposal (ok)."""

    point: int
    xy: list[list[float] | None]
    ok: list[bool]


class ModelFollowRead(BaseModel):
    """``available`` is false (with the ``reason``) where nothing is proposed: the view has no
    depth, no frame has enough keyed joints, the model could not start, or the follow is
    ``preparing`` on the worker queue (ask again in a few seconds with the same keyframes).
    ``start_frame``: the keyed frame the proposals start from: the first with enough keyed
    joints, at or after ``begin`` where one is given (a correction: the follow is carried
    there from the first keyed frame through the keyframes before it, or started there where
    that does not hold, worker.solver.follow.follow_hand)."""

    available: bool
    preparing: bool = False
    reason: str | None = None
    min_joints: int = FOLLOW_START_JOINTS
    start_frame: int | None = None
    first_frame: int
    last_frame: int
    points: list[ModelPoint] = Field(default_factory=list)
    stops: list[ModelStop] = Field(default_factory=list)


def _keyed(rows: list[list[list[Any]]], frames: int) -> tuple[np.ndarray, np.ndarray]:
    """(F, 21, 2) px of the keyed visible joints (NaN elsewhere) and (F, 21) where keyed."""
    keypoints = np.full((frames, NUM_JOINTS, 2), np.nan)
    for p, track in enumerate(rows[:NUM_JOINTS]):
        for k in as_keyframes(track):
            if k.visible and k.has_position:
                keypoints[k.frame, p] = (k.x, k.y)
    return keypoints, np.isfinite(keypoints).all(axis=-1)


def _start_frame(visible: np.ndarray, begin: int | None) -> int | None:
    """The frame the proposals start from: the first (at or after ``begin``) with enough keyed
    joints; None when there is none."""
    keyed = np.flatnonzero(visible.sum(axis=1) >= FOLLOW_START_JOINTS)
    if begin is not None:
        keyed = keyed[keyed >= begin]
    return int(keyed[0]) if len(keyed) else None


def _plain(row: list[Any]) -> list[Any]:
    """A keyframe row as [frame, x, y, visible01], the same after a trip through JSON."""
    x, y = (None if v is None else float(v) for v in row[1:3])
    return [int(row[0]), x, y, int(bool(row[3]))]


def _digest(task: Task, side: str, betas: list[float] | None, rows: list[list[list[Any]]],
            begin: int | None) -> str:
    """A stable name for what a follow rests on: the task, its view's calibration, the
    hand's shape, the keyframes and where it begins."""
    camera = task.camera
    content = json.dumps([task.id, str(task.created_at), task.sequence.num_frames,
                          [camera.fx, camera.fy, camera.ppx, camera.ppy, camera.distortion,
                           camera.extrinsics], side, betas,
                          [[_plain(r) for r in track] for track in rows], begin],
                         default=str)
    return hashlib.sha256(content.encode()).hexdigest()[:32]


def storage_key(task_id: int, digest: str) -> str:
    """Where the follow job stores a view's follow of the keyframes named by ``digest``."""
    return f"proposals/model/{task_id}/{digest}.npz"


def job_key(task_id: int, digest: str) -> str:
    return f"{MODEL_FOLLOW_KIND}:{task_id}:{digest}"


def _hand(session: Session, task: Task) -> tuple[str, list[float] | None]:
    hand = session.get_one(Hand, task.hand_id)
    return hand.side, hand_betas(version_in_use(session, task.sequence_id), hand.index,
                                 hand.betas)


def _save(storage: Storage, key: str, xy: np.ndarray, ok: np.ndarray, start: int,
          stops: dict[str, tuple[int, str]]) -> None:
    buffer = io.BytesIO()
    names = sorted(stops)
    np.savez_compressed(buffer, xy=xy, ok=ok, start=np.array(start),
                        stop_names=np.array(names, dtype=str),
                        stop_frames=np.array([stops[n][0] for n in names], dtype=np.int64),
                        stop_reasons=np.array([stops[n][1] for n in names], dtype=str))
    storage.put_bytes(key, buffer.getvalue(), "application/octet-stream")


def _load(storage: Storage, key: str
          ) -> tuple[np.ndarray, np.ndarray, int, dict[str, tuple[int, str]]] | None:
    if not storage.exists(key):
        return None
    with np.load(io.BytesIO(storage.get_bytes(key)), allow_pickle=False) as data:
        stops = {str(n): (int(f), str(r)) for n, f, r in zip(
            data["stop_names"], data["stop_frames"], data["stop_reasons"], strict=True)}
        return data["xy"], data["ok"], int(data["start"]), stops


def compute_model_follow(task_id: int, tracks: list[list[list[Any]]], begin: int | None,
                         storage: Storage | None = None) -> dict[str, Any]:
    """The follow job (MODEL_FOLLOW_KIND): follow the hand model from the keyframes ``tracks``
    (per point rows) through the task's view and store the result under their digest
    (idempotent: a follow already stored is left as it is)."""
    storage = storage or get_storage()
    with session_scope() as session:
        task = service.get_task_or_raise(session, task_id)
        side, betas = _hand(session, task)
        key = storage_key(task_id, _digest(task, side, betas, tracks, begin))
        if storage.exists(key):
            return {"key": key, "message": f"task {task_id}: already followed"}
        frames = task.sequence.num_frames
        read = depth_reader(session, storage, task.camera, 0, frames - 1)
        if read is None:
            raise StorageError(f"task {task_id}: the view has no depth map for every frame")
        depth = np.stack([read(f) for f in range(frames)])
        camera = camera_model(task.camera)
    keypoints, visible = _keyed(tracks, frames)
    shape = np.zeros(10) if betas is None else np.asarray(betas, float)
    # PyTorch loads here, in the job's process, never with the API.
    from worker.solver.follow import follow_hand

    found = follow_hand(camera, depth, keypoints, visible, side, shape, hand_model_for(side),
                        begin=begin)
    _save(storage, key, found.xy, found.ok, found.start, found.stops)
    held = np.flatnonzero(found.ok.any(axis=1))
    span = f"frames {held[0]}-{held[-1]}" if len(held) else "no frame"
    return {"key": key, "message": f"task {task_id}: the hand model followed {span} "
                                   f"from frame {found.start}"}


def _queued(session: Session, task: Task, digest: str, tracks: list[list[list[Any]]],
            begin: int | None) -> tuple[str, bool]:
    """Queue the follow job for these keyframes unless it is queued, running or failed, or
    another follow of this task is under way; the reason to show and whether it is on its
    way."""
    key = job_key(task.id, digest)
    job = session.scalars(select(Job).where(Job.key == key)).one_or_none()
    if job is not None and job.status == "failed":
        return f"the hand model could not follow this view: {last_error_line(job)}", False
    if job is None or job.status not in ACTIVE:
        other = session.scalars(select(Job.key).where(
            Job.kind == MODEL_FOLLOW_KIND, Job.key.like(f"{MODEL_FOLLOW_KIND}:{task.id}:%"),
            Job.key != key, Job.status.in_(ACTIVE)).limit(1)).first()
        if other is not None:
            wait = ("the hand model is still following your earlier keyframes; this follow "
                    "starts when that one is done")
            return wait, True
        enqueue_job(session, MODEL_FOLLOW_KIND, key,
                    {"task_id": task.id, "tracks": tracks, "begin": begin})
    return "the hand model is following the hand through this view's depth", True


def _stops(stops: dict[str, tuple[int, str]], frames: int) -> list[ModelStop]:
    out = []
    for name, step, edge in (("forward", 1, frames - 1), ("backward", -1, 0)):
        if name not in stops:
            continue
        frame, why = stops[name]
        # The frame given is the first the follow did not reach (-1: it reached the edge).
        reached = edge if frame < 0 else frame - step
        out.append(ModelStop(direction=name, reached=reached,
                             stopped=why if why in ("end", "depth", "keyframes") else "depth"))
    return out


def model_follow(session: Session, storage: Storage, assignment: Assignment,
                 body: ModelFollowRequest) -> ModelFollowRead:
    """The hand model's follow of the assignment's view from the keyframes in ``body``.

    Raises InvalidTracks (422) for keyframes the page could not save and InvalidModelFollow
    (422) for an object task or a ``begin`` outside the clip.
    """
    task = service.get_task_or_raise(session, assignment.task_id)
    frames, size = task.sequence.num_frames, (task.camera.width, task.camera.height)
    if task.kind != "hand":
        raise InvalidModelFollow("the hand model follows hand tasks only; this is an object "
                                 "task (track its landmarks with T)")
    if body.begin is not None and body.begin >= frames:
        raise InvalidModelFollow(f"begin {body.begin} is out of range 0-{frames - 1}")
    rows = service.check_tracks(service.clip_of(session, task.id),
                                TracksSave(version=0, tracks=body.tracks))

    def unavailable(reason: str, preparing: bool = False) -> ModelFollowRead:
        return ModelFollowRead(available=False, preparing=preparing, reason=reason,
                               first_frame=0, last_frame=frames - 1)

    if frames > MAX_MODEL_FRAMES:
        return unavailable(f"the hand model follows clips of at most {MAX_MODEL_FRAMES} "
                           f"frames; this one has {frames}")
    if not task.camera.has_depth:
        return unavailable("this view has no depth maps: the hand model cannot follow it")
    start = _start_frame(_keyed(rows, frames)[1], body.begin)
    if start is None:
        after = "" if body.begin is None else f" at or after frame {body.begin}"
        return unavailable(f"place at least {FOLLOW_START_JOINTS} visible joints on one "
                           f"frame{after} first: the hand model starts from that frame")
    side, betas = _hand(session, task)
    digest = _digest(task, side, betas, rows, body.begin)
    stored = _load(storage, storage_key(task.id, digest))
    if stored is None:
        return unavailable(*_queued(session, task, digest, rows, body.begin))
    xy, ok, started, stops = stored
    if not ok.any():
        why = next((r for _, r in stops.values() if r in _START_REFUSED), "depth")
        return unavailable(f"the hand model could not start from frame {started}: "
                           f"{_START_REFUSED[why]}")
    # Proposals only where the worker's keyframes have the point visible, never at its own
    # keyframes.
    for p, track in enumerate(rows[:NUM_JOINTS]):
        ok[:, p] &= dense_track(track, frames).visible.astype(bool)
        ok[[k.frame for k in as_keyframes(track)], p] = False
    xy = np.where(ok[..., None], xy, np.nan)
    xy = np.swapaxes(plant(check_key(get_settings().signing_key), assignment.id,
                           np.swapaxes(xy, 0, 1), ok.T, 0, frames, task.num_points, *size),
                     0, 1)
    points = [ModelPoint(
        point=p,
        xy=[[round(float(v[0]), 3), round(float(v[1]), 3)] if ok[f, p] else None
            for f, v in enumerate(xy[:, p])],
        ok=ok[:, p].tolist()) for p in range(task.num_points)]
    return ModelFollowRead(available=True, start_frame=start, first_frame=0,
                           last_frame=frames - 1, points=points,
                           stops=_stops(stops, frames))
