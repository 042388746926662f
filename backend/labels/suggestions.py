"""Pre-fill suggestions for the annotation page: where the target's accepted work in other views
places each point in this view, and the epipolar lines of those labels.

Once a target (a hand or an object of a sequence) has accepted work (backend.labels)
in at least MIN_ACCEPTED_VIEWS views other than this one, each point is triangulated per frame
from them and projected into this view (worker.assist.prefill). A hand with accepted work in
only one or two other views gets the hand model fitted to those views' labels and depth maps
instead (worker.solver.suggest), its joints projected into this view; an object, its mesh's
poses fitted to their landmarks and depth, the first accepted worker's landmarks carried by
them into this view. The fit takes CPU seconds and PyTorch, so it never runs in a request:
the request queues a FITTED_KIND job (compute_fitted, once per view, frames and accepted
work) and answers ``preparing`` until the job has stored its result in storage under a
digest of what it rests on. Either way the visibility is suggested from this view's depth
maps, and the result is kept in memory (CACHE_SIZE views) until the accepted work or the
calibration changes. The assignment's check cells (worker.assist.checks) are planted into
the suggested positions, as into every suggestion the page shows; the epipolar data is left
as it is. Nothing the worker sees is written: a suggestion the worker accepts is saved as a
keyframe with source "prefilled".

Positions are image px (x right, y down) of the clip's frames first_frame..last_frame.
"""

from __future__ import annotations

import hashlib
import io
import json
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, Literal

import cv2
import numpy as np
from pydantic import BaseModel, Field
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation import service
from backend.annotation.models import Assignment, Task
from backend.annotation.tokens import TASK_SCOPE
from backend.captures.assets import hand_model_for, load_mesh
from backend.captures.calibration import hand_betas, version_in_use
from backend.captures.models import Camera, Frame, Hand, SceneObject
from backend.captures.service import camera_model, sequence_cameras
from backend.config import get_settings
from backend.db import session_scope
from backend.errors import DexlabelError, StorageError, Unauthorized
from backend.jobs.models import Job
from backend.jobs.runner import ACTIVE
from backend.jobs.service import enqueue_job, last_error_line
from backend.labels import labelled_work, sequence_tasks, work_query
from backend.storage import Storage, get_storage
from worker.assist.checks import check_key, plant
from worker.assist.prefill import (
    MIN_ACCEPTED_VIEWS,
    DepthReader,
    Prefill,
    ViewWork,
    distinct_views,
    epipolar_guide,
    prefill,
    view_work,
)
from worker.assist.prefill import EpipolarView as EpipolarGuide

# Other views with accepted work before a view is offered suggestions: one (the hand's model,
# or the object's mesh, is fitted to its labels and depth).
MIN_VIEWS = 1
# The job that fits a target's model to the accepted work of one or two views (compute_fitted).
FITTED_KIND = "fitted_suggestions"
# Views whose suggestions are kept in memory (about 0.3 MB each for 21 points x 72 frames and 7
# labelled views): every page load of a task reads them, and decoding the view's depth maps
# is most of their cost (72 PNG frames at 640x480, 4-6 ms of CPU each).
CACHE_SIZE = 32
_CACHE: OrderedDict[Hashable, tuple[Prefill, list[EpipolarGuide]]] = OrderedDict()
_CACHE_LOCK = threading.Lock()


class InvalidSuggestionRequest(DexlabelError, status_code=422, code="invalid_suggestion_request"):
    pass


class PointSuggestions(BaseModel):
    """One point over the frame range: per frame a suggested position [x, y] (image px) or
    null, and a suggested visibility: true, false (occluded: behind a surface or outside the
    image), or null (the depth map cannot tell, or nothing is suggested)."""

    point: int
    xy: list[list[float] | None]
    visible: list[bool | None]


class EpipolarView(BaseModel):
    """One labelled view's guide. ``F`` (3 x 3, rows) maps a pixel [x, y, 1] of ``xy`` to the
    line (a, b, c), a x + b y + c = 0, in this view; divide it by hypot(a, b) for distances
    in px. ``xy``: per point, per frame, the view's accepted decided visible label (the mean
    of its accepted assignments) or null. Both sides are undistorted pinhole pixels: ``xy``
    has its own lens distortion removed already; this view's distortion bends the true curve
    off the line by up to a few px near the image's edges (about 2.5 px at 640x480 on the
    synthetic captures), well under a px near the centre."""

    serial: str
    F: list[list[float]] = Field(min_length=3, max_length=3)
    xy: list[list[list[float] | None]]


Method = Literal["triangulated", "fitted"]


class SuggestionsRead(BaseModel):
    """Pre-fill suggestions for the assignment's view. ``available`` is false (with the
    ``reason``, and empty lists) until the target has accepted work in ``min_views`` other
    views; ``views`` are the serials of the views with accepted work. ``method``: how the
    positions were found: "triangulated" from 3 or more views, or "fitted" (the hand's model
    or the object's mesh fitted to the labels and depth of 1 or 2 views; rougher, a person
    checks every one). ``preparing``: the fit runs on the worker queue and its result is not
    stored yet; ask again in a few seconds."""

    available: bool
    reason: str | None
    views: list[str]
    min_views: int
    method: Method | None = None
    preparing: bool = False
    first_frame: int
    last_frame: int
    points: list[PointSuggestions]
    epipolar: list[EpipolarView]


def assignment_of(session: Session, claims: dict[str, Any]) -> Assignment:
    """The assignment an assignment or review token opens (suggestions write nothing, so a
    read-only review link may read them); a preview link has none (401)."""
    if claims["scope"] == TASK_SCOPE:
        raise Unauthorized("suggestions belong to an assignment: a preview link has none; "
                           "accept the HIT first")
    return service.get_assignment_or_raise(session, int(claims["assignment_id"]))


def frame_range(first: int | None, last: int | None, num_frames: int) -> tuple[int, int]:
    """first..last (inclusive), default the whole clip; 422 naming a frame outside it."""
    first = 0 if first is None else first
    last = num_frames - 1 if last is None else last
    problems = [f"{name} {value} is out of range 0-{num_frames - 1}"
                for name, value in (("first_frame", first), ("last_frame", last))
                if not 0 <= value < num_frames]
    if not problems and first > last:
        problems.append(f"first_frame {first} is after last_frame {last}")
    if problems:
        raise InvalidSuggestionRequest("; ".join(problems))
    return first, last


def _target_name(task: Task) -> str:
    return "hand" if task.kind == "hand" else "object"


def _unavailable_reason(task: Task, serials: list[str]) -> str:
    have = ("there is none" if not serials else
            f"there is 1 (view {serials[0]})" if len(serials) == 1 else
            f"there are {len(serials)} (views {', '.join(serials)})")
    return (f"suggestions need accepted work in {MIN_VIEWS} other view of this "
            f"{_target_name(task)}; {have}")


def depth_reader(session: Session, storage: Storage, camera: Camera, first: int, last: int
                  ) -> DepthReader | None:
    """A reader ``frame -> (H, W) uint16 mm`` of the camera's depth maps, frame counted from
    ``first``; None when the view has no depth for every frame of the range."""
    if not camera.has_depth:
        return None
    stored = list(session.scalars(select(Frame.depth_key).where(
        Frame.camera_id == camera.id, Frame.index >= first, Frame.index <= last)
        .order_by(Frame.index)))
    keys = [key for key in stored if key]
    if len(keys) != last - first + 1:
        return None

    def read(frame: int) -> np.ndarray:
        key = keys[frame]
        depth = cv2.imdecode(np.frombuffer(storage.get_bytes(key), np.uint8),
                             cv2.IMREAD_UNCHANGED)
        if depth is None or depth.dtype != np.uint16 or depth.shape != (camera.height,
                                                                         camera.width):
            raise StorageError(f"{key}: not a {camera.width}x{camera.height} 16-bit depth map")
        return depth

    return read


def _xy_lists(xy: np.ndarray) -> list[list[float] | None]:
    """(R, 2) px -> per frame [x, y] rounded to 1/1000 px, or None."""
    finite = np.isfinite(xy).all(axis=-1).tolist()
    return [v if ok else None
            for v, ok in zip(np.round(xy, 3).tolist(), finite, strict=True)]


def _dense_work(accepted: list[Assignment], others: dict[int, Task], view_of: dict[int, int],
                task: Task, first: int, last: int) -> list[ViewWork]:
    """The accepted assignments (tracks loaded) as ViewWork of frames first..last."""
    work = []
    for assignment in accepted:
        other = others[assignment.task_id]
        dense = view_work(view_of[other.camera_id],
                          ((t.point_index, t.keyframes) for t in assignment.tracks),
                          task.sequence.num_frames, task.num_points)
        work.append(ViewWork(dense.view, dense.xy[first:last + 1],
                             dense.visible[first:last + 1], dense.decided[first:last + 1]))
    return work


def _cache_key(task: Task, first: int, last: int, accepted: list[Assignment],
               cameras: list[Camera]) -> Hashable:
    """What a view's suggestions depend on: the frames, the accepted work (an assignment's
    tracks change only with its version; creation times tell apart rows whose id a deleted
    one had) and the calibration."""
    calibration = tuple((c.id, c.fx, c.fy, c.ppx, c.ppy, json.dumps(c.distortion),
                         json.dumps(c.extrinsics)) for c in cameras)
    work = tuple((a.id, a.version, a.created_at, a.saved_at, a.submitted_at) for a in accepted)
    return (task.id, task.created_at, first, last, work, calibration)


def _key_digest(key: Hashable) -> str:
    """A stable name for a cache key's content (its repr: ids, versions, times, numbers)."""
    return hashlib.sha256(repr(key).encode()).hexdigest()[:32]


def fitted_storage_key(task_id: int, digest: str) -> str:
    """Where the fit job stores a view's fitted suggestions for the work named by ``digest``."""
    return f"suggestions/fitted/{task_id}/{digest}.npz"


def fitted_job_key(task_id: int, first: int, last: int, digest: str) -> str:
    """The fit job's key: one job per view, frames and accepted work."""
    return f"{FITTED_KIND}:{task_id}:{first}:{last}:{digest}"


def _save_prefill(storage: Storage, key: str, found: Prefill) -> None:
    buffer = io.BytesIO()
    np.savez_compressed(buffer, xy=found.xy, visible=found.visible, known=found.known,
                        views=found.views, points=found.points)
    storage.put_bytes(key, buffer.getvalue(), "application/octet-stream")


def _load_prefill(storage: Storage, key: str) -> Prefill | None:
    """The stored fitted suggestions, None when there are none (yet)."""
    if not storage.exists(key):
        return None
    with np.load(io.BytesIO(storage.get_bytes(key)), allow_pickle=False) as data:
        return Prefill(xy=data["xy"], visible=data["visible"], known=data["known"],
                       views=data["views"], points=data["points"])


def _computed(session: Session, storage: Storage, task: Task, cameras: list[Camera],
              others: dict[int, Task], accepted: list[Assignment], first: int, last: int
              ) -> tuple[Prefill, list[EpipolarGuide]] | str:
    """The view's suggestions and epipolar guide from the accepted work, from the cache when
    nothing they depend on changed. Fitted suggestions (fewer than MIN_ACCEPTED_VIEWS views)
    are read from what the fit job stored; when it has stored none for this work, the
    digest of the work it has to be run for."""
    key = _cache_key(task, first, last, accepted, cameras)
    with _CACHE_LOCK:
        if key in _CACHE:
            _CACHE.move_to_end(key)
            return _CACHE[key]
    # The tracks, read only now; the work read with them is what the result is stored under.
    accepted = labelled_work(session, others)
    key = _cache_key(task, first, last, accepted, cameras)
    view_of = {c.id: i for i, c in enumerate(cameras)}
    work = _dense_work(accepted, others, view_of, task, first, last)
    models, target = [camera_model(c) for c in cameras], view_of[task.camera_id]
    if len(distinct_views(work)) >= MIN_ACCEPTED_VIEWS:
        found = prefill(models, work, target,
                        depth_reader(session, storage, task.camera, first, last))
    else:
        digest = _key_digest(key)
        stored = _load_prefill(storage, fitted_storage_key(task.id, digest))
        if stored is None:
            return digest
        found = stored
    result = (found, epipolar_guide(models, work, target))
    with _CACHE_LOCK:
        _CACHE[key] = result
        while len(_CACHE) > CACHE_SIZE:
            _CACHE.popitem(last=False)
    return result


def _fit(session: Session, storage: Storage, task: Task, cameras: list[Camera],
         work: list[ViewWork], first: int, last: int) -> Callable[[], Prefill]:
    """Reads what fitting the hand model (or the object's poses) to the work of one or two
    views needs (their labels and depth maps) and returns the fit, projected into the task's
    view (worker.solver.suggest): it takes CPU seconds (about 16 s for 24 frames,
    BENCHMARKS.md), so the fit job runs it with the session closed."""
    models = [camera_model(c) for c in cameras]
    target = [c.id for c in cameras].index(task.camera_id)
    reader = depth_reader(session, storage, task.camera, first, last)
    depth = {}
    for view in distinct_views(work):
        read = depth_reader(session, storage, cameras[view], first, last)
        if read is not None:
            depth[view] = np.stack([read(f) for f in range(last - first + 1)])
    if task.kind == "hand":
        hand = session.get_one(Hand, task.hand_id)
        side = hand.side
        betas = hand_betas(version_in_use(session, task.sequence_id), hand.index, hand.betas)
        shape = np.zeros(10) if betas is None else np.asarray(betas, float)

        def fit_hand() -> Prefill:
            # PyTorch loads here, in the job's process, never with the API.
            from worker.solver.suggest import fit_hand_joints, fitted_prefill

            points = fit_hand_joints(models, work, depth, side, shape, hand_model_for(side))
            return fitted_prefill(models, work, target, points, reader)

        return fit_hand
    obj = session.get_one(SceneObject, task.object_id)
    mesh = load_mesh(storage, obj.mesh_key)
    # The given pose is of frame 0: it starts a range that starts there.
    pose = None if obj.initial_pose is None or first else np.asarray(obj.initial_pose)
    num_points = task.num_points

    def fit_object() -> Prefill:
        from worker.solver.suggest import fit_object_points, fitted_prefill

        try:
            points, _ = fit_object_points(models, work, depth, mesh.vertices, mesh.faces, pose)
        except ValueError:  # no pose at the range's first frame could be fitted
            points = np.full((last - first + 1, num_points, 3), np.nan)
        return fitted_prefill(models, work, target, points, reader)

    return fit_object


def _view_inputs(session: Session, task: Task) -> tuple[list[Camera], dict[int, Task]]:
    """The sequence's cameras and the target's tasks of the other views."""
    cameras = sequence_cameras(session, task.sequence_id)
    others = {t.id: t for t in sequence_tasks(session, task.sequence_id, task.target_key)
              if t.camera_id != task.camera_id}
    return cameras, others


def compute_fitted(task_id: int, first: int, last: int, storage: Storage | None = None
                   ) -> dict[str, Any]:
    """The fit job (FITTED_KIND): fit the target's model to the accepted work of one or two
    other views and store the view's suggestions under the digest of that work (idempotent:
    work already fitted is left as stored, a second run writes the same file)."""
    storage = storage or get_storage()
    with session_scope() as session:
        task = service.get_task_or_raise(session, task_id)
        cameras, others = _view_inputs(session, task)
        accepted = labelled_work(session, others)
        digest = _key_digest(_cache_key(task, first, last, accepted, cameras))
        key = fitted_storage_key(task_id, digest)
        view_of = {c.id: i for i, c in enumerate(cameras)}
        work = _dense_work(accepted, others, view_of, task, first, last)
        views = len(distinct_views(work))
        if storage.exists(key) or views >= MIN_ACCEPTED_VIEWS:
            return {"key": key, "message": f"task {task_id} frames {first}-{last}: nothing "
                                           f"to fit ({views} views, stored: "
                                           f"{storage.exists(key)})"}
        fit = _fit(session, storage, task, cameras, work, first, last)
    _save_prefill(storage, key, fit())
    return {"key": key, "message": f"task {task_id} frames {first}-{last}: fitted to "
                                   f"{views} view{'s' if views > 1 else ''}"}


def _fit_queued(session: Session, task: Task, first: int, last: int, digest: str
                ) -> tuple[str, bool]:
    """Queue the fit job for this work unless it is queued, running or done already; the
    reason to show, and whether the suggestions are on their way."""
    model = "the hand model" if task.kind == "hand" else "the object's mesh"
    key = fitted_job_key(task.id, first, last, digest)
    job = session.scalars(select(Job).where(Job.key == key)).one_or_none()
    if job is not None and job.status == "failed":
        return (f"suggestions from {model} could not be prepared: {last_error_line(job)}",
                False)
    if job is None or job.status not in ACTIVE:
        enqueue_job(session, FITTED_KIND, key,
                    {"task_id": task.id, "first_frame": first, "last_frame": last})
    return (f"suggestions from {model} are being prepared; they will appear shortly",
            True)


def queue_fits(session: Session, storage: Storage, sequence_id: int, target_key: str) -> int:
    """Queue the fit job (whole clip) of every view of the target that no worker holds, has
    submitted or has done and whose suggestions are fitted from the accepted work and not
    stored yet, so that they are usually ready before its next worker asks (QC calls this once
    it has decided); how many views are being prepared."""
    preparing = 0
    tasks = sequence_tasks(session, sequence_id, target_key)
    # Views someone holds, has submitted or has done are not prepared ahead (a worker who opens
    # one asks, and the request queues the fit): the CPU goes to views still waiting for one.
    held = set(session.scalars(select(Assignment.task_id).where(
        Assignment.task_id.in_([t.id for t in tasks]),
        Assignment.status.in_(("working", "submitted", "approved")))))
    for task in tasks:
        if task.id in held:
            continue
        cameras, others = _view_inputs(session, task)
        view_of = {c.id: i for i, c in enumerate(cameras)}
        accepted = list(session.scalars(work_query(others, with_tracks=False)))
        if not accepted:
            continue
        last = task.sequence.num_frames - 1
        accepted = labelled_work(session, others)
        work = _dense_work(accepted, others, view_of, task, 0, last)
        if len(distinct_views(work)) >= MIN_ACCEPTED_VIEWS:
            continue
        digest = _key_digest(_cache_key(task, 0, last, accepted, cameras))
        if storage.exists(fitted_storage_key(task.id, digest)):
            continue
        preparing += _fit_queued(session, task, 0, last, digest)[1]
    return preparing


def clear_cache() -> None:
    """Forget every kept result (the next request of each view computes it again)."""
    with _CACHE_LOCK:
        _CACHE.clear()


def suggestions(session: Session, storage: Storage, assignment: Assignment,
                first_frame: int | None = None, last_frame: int | None = None
                ) -> SuggestionsRead:
    """Pre-fill suggestions and epipolar data for the assignment's view, frames
    ``first_frame``..``last_frame`` (default the whole clip); 422 for frames outside it."""
    task = service.get_task_or_raise(session, assignment.task_id)
    num_frames, num_points = task.sequence.num_frames, task.num_points
    first, last = frame_range(first_frame, last_frame, num_frames)
    camera_rows, others = _view_inputs(session, task)
    view_of = {c.id: i for i, c in enumerate(camera_rows)}
    accepted = list(session.scalars(work_query(others, with_tracks=False)))
    views = sorted({view_of[others[a.task_id].camera_id] for a in accepted})
    serials = [camera_rows[v].serial for v in views]

    def unavailable(reason: str, preparing: bool = False) -> SuggestionsRead:
        return SuggestionsRead(available=False, reason=reason, views=serials,
                               min_views=MIN_VIEWS, preparing=preparing, first_frame=first,
                               last_frame=last, points=[], epipolar=[])

    if len(views) < MIN_VIEWS:
        return unavailable(_unavailable_reason(task, serials))
    computed = _computed(session, storage, task, camera_rows, others, accepted, first, last)
    if isinstance(computed, str):
        return unavailable(*_fit_queued(session, task, first, last, computed))
    found, guide = computed
    # Check cells go wherever the page shows a suggestion as visible (unknown included).
    shown = np.isfinite(found.xy).all(axis=-1) & ~(found.known & ~found.visible)
    xy = plant(check_key(get_settings().signing_key), assignment.id,
               np.swapaxes(found.xy, 0, 1), shown.T, first, num_frames, num_points,
               task.camera.width, task.camera.height)
    flags = found.visible.astype(object)
    flags[~found.known] = None
    visible = flags.T.tolist()
    points = [PointSuggestions(point=p, xy=_xy_lists(xy[p]), visible=visible[p])
              for p in range(num_points)]
    epipolar = [EpipolarView(
        serial=camera_rows[g.view].serial, F=g.fundamental.tolist(),
        xy=[_xy_lists(g.xy[:, p]) for p in range(num_points)]) for g in guide]
    method: Method = "triangulated" if len(views) >= MIN_ACCEPTED_VIEWS else "fitted"
    return SuggestionsRead(available=True, reason=None, views=serials,
                           min_views=MIN_VIEWS, method=method,
                           first_frame=first, last_frame=last, points=points,
                           epipolar=epipolar)
