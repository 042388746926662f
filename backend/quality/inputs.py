"""What a QC job reads: the target's cameras, every scored assignment's dense tracks, depth.

Arrays only leave this module; the scoring itself is pure (worker.quality).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task
from backend.annotation.proposals import grey_frames
from backend.captures.assets import load_mesh
from backend.captures.calibration import calibrated_models
from backend.captures.models import Camera, Frame, Sequence
from backend.captures.service import sequence_cameras
from backend.config import get_settings
from backend.labels import SCORED_STATUSES, labelled_work, sequence_tasks
from backend.solve.models import SolveRun
from backend.solve.results import decode_result, object_trust
from backend.storage import get_storage
from worker.assist.checks import accepted_checks, check_key, kept_checks
from worker.assist.stretches import StretchCheck, check_stretches
from worker.geometry import CameraModel
from worker.tracks.interpolate import dense_points
from worker.tracks.sources import SOURCE_PREFILLED, keyframe_sources

if TYPE_CHECKING:
    from worker.quality.solved_scene import SolvedObjects
    from worker.quality.view_labels import ViewLabels

# Depth maps decoded at once when the visibility check reads a view.
DECODE_THREADS = 4


@dataclass
class ScoredAssignment:
    """Who and what one label set is, beside its arrays; checks: (accepted, corrected) check
    suggestions of the assignment (worker.assist.checks.accepted_checks); kept: the (point,
    frame) check cells accepted unchanged."""

    assignment_id: int
    task_id: int
    worker_id: str
    checks: tuple[int, int] = (0, 0)
    kept: tuple[tuple[int, int], ...] = ()


@dataclass
class TargetInputs:
    sequence_id: int
    target_key: str
    kind: str
    num_frames: int
    # One per view, in view order: as the worker packages take them, and the rows.
    cameras: list[CameraModel]
    camera_rows: list[Camera]
    labels: list[ViewLabels] = field(default_factory=list)
    who: dict[str, ScoredAssignment] = field(default_factory=dict)
    tasks: dict[int, Task] = field(default_factory=dict)
    view_of_task: dict[int, int] = field(default_factory=dict)
    # Each label's stored keyframe rows, one list per point, keyed like ``labels``.
    keyframes: dict[str, list[list[list[Any]]]] = field(default_factory=dict)


def view_labels(assignment: Assignment, view: int, num_frames: int, num_points: int
                ) -> ViewLabels:
    """An assignment's tracks as dense (F, P, 2) px (NaN = no position), (F, P) visibility
    and (F, P) decided, as a worker.quality.view_labels.ViewLabels.

    decided is False only where the value comes from pre-filled suggestions the worker kept
    unchanged (worker.tracks.sources.keyframe_sources); a frame the worker left unplaced is theirs
    as before, so work without pre-fill is judged exactly as it was."""
    from worker.quality.view_labels import ViewLabels

    xy, visible = dense_points(((t.point_index, t.keyframes) for t in assignment.tracks),
                               num_frames, num_points)
    decided = np.ones((num_frames, num_points), bool)
    for track in assignment.tracks:
        if 0 <= track.point_index < num_points:
            decided[:, track.point_index] = \
                keyframe_sources(track.keyframes, num_frames) != SOURCE_PREFILLED
    return ViewLabels(key=str(assignment.id), view=view, xy=xy, visible=visible,
                      working_time_s=assignment.working_time_s, decided=decided)


def stored_rows(assignment: Assignment, num_points: int) -> list[list[list[Any]]]:
    """The assignment's stored keyframe rows, one list per point (empty where none)."""
    tracks: list[list[list[Any]]] = [[] for _ in range(num_points)]
    for track in assignment.tracks:
        if 0 <= track.point_index < num_points:
            tracks[track.point_index] = track.keyframes
    return tracks


def check_counts(key: bytes, assignment: Assignment, num_frames: int, num_points: int
                 ) -> tuple[int, int]:
    """(accepted, corrected) check suggestions of a saved assignment (its stored rows)."""
    return accepted_checks(key, assignment.id, stored_rows(assignment, num_points),
                           num_points, num_frames)


def target_inputs(session: Session, sequence_id: int, target_key: str) -> TargetInputs:
    """Cameras of the sequence and the scored assignments of every task of one target."""
    sequence = session.get_one(Sequence, sequence_id)
    cameras = sequence_cameras(session, sequence_id)
    view_of = {camera.id: i for i, camera in enumerate(cameras)}
    tasks = sequence_tasks(session, sequence_id, target_key)
    if not tasks:
        raise ValueError(f"sequence {sequence_id} has no tasks for target {target_key!r}")
    out = TargetInputs(sequence_id=sequence_id, target_key=target_key, kind=tasks[0].kind,
                       num_frames=sequence.num_frames, camera_rows=cameras,
                       cameras=calibrated_models(session, cameras),
                       tasks={t.id: t for t in tasks},
                       view_of_task={t.id: view_of[t.camera_id] for t in tasks})
    key = check_key(get_settings().signing_key)
    # Every assignment's tracks in one more query, not one per assignment.
    for assignment in labelled_work(session, out.tasks, SCORED_STATUSES, vouched=True):
        task = out.tasks[assignment.task_id]
        view = view_of[task.camera_id]
        out.labels.append(view_labels(assignment, view, out.num_frames, task.num_points))
        out.keyframes[str(assignment.id)] = stored_rows(assignment, task.num_points)
        rows = out.keyframes[str(assignment.id)]
        out.who[str(assignment.id)] = ScoredAssignment(
            assignment.id, task.id, assignment.worker_id,
            check_counts(key, assignment, out.num_frames, task.num_points),
            tuple(kept_checks(key, assignment.id, rows, task.num_points, out.num_frames)))
    return out


def stretch_checks(session: Session, inputs: TargetInputs, labels: list[ViewLabels]
                   ) -> dict[str, StretchCheck]:
    """Each hand label's stretches checked against its own view's images
    (worker.assist.stretches), keyed by the label's key; each view's frames read once."""
    grey: dict[int, np.ndarray] = {}
    out: dict[str, StretchCheck] = {}
    for lab in labels:
        camera = inputs.camera_rows[lab.view]
        if lab.view not in grey:
            grey[lab.view] = grey_frames(session, get_storage(), camera.id, 0,
                                         inputs.num_frames - 1, (camera.width, camera.height))
        out[lab.key] = check_stretches(grey[lab.view], inputs.keyframes[lab.key])
    return out


class DepthStack:
    """The (F, H, W) uint16 depth maps (millimetres) of one view, read when indexed.

    Supports what the visibility check does with a depth array: ``shape`` and fancy indexing
    with (frames, rows, cols) integer arrays. Only the frames asked for are decoded, in
    parallel (cv2 releases the GIL), and none is kept afterwards: one view's maps are in
    memory at a time instead of every view's (8 x 72 maps are 350 MB).
    """

    ndim = 3

    def __init__(self, keys: list[str], height: int, width: int) -> None:
        self.keys = keys
        self.shape = (len(keys), height, width)

    def _load(self, frame: int) -> np.ndarray:
        data = get_storage().get_bytes(self.keys[frame])
        depth = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if depth is None or depth.dtype != np.uint16 or depth.shape != self.shape[1:]:
            raise ValueError(f"{self.keys[frame]}: not a {self.shape[2]}x{self.shape[1]} "
                             "16-bit depth map")
        return depth

    def __getitem__(self, index: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        frames, rows, cols = (np.asarray(i, dtype=np.int64) for i in index)
        out = np.zeros(frames.shape, dtype=np.uint16)
        needed = [int(f) for f in np.unique(frames)]
        with ThreadPoolExecutor(max_workers=DECODE_THREADS) as pool:
            for frame, depth in zip(needed, pool.map(self._load, needed), strict=True):
                at = frames == frame
                out[at] = depth[rows[at], cols[at]]
        return out


def depth_maps(session: Session, cameras: list[Camera], views: set[int]
               ) -> dict[int, DepthStack]:
    """The depth maps of each listed view (index into ``cameras``) that has depth, as lazily
    read stacks."""
    out: dict[int, DepthStack] = {}
    for view, camera in enumerate(cameras):
        if view not in views or not camera.has_depth:
            continue
        keys = list(session.scalars(select(Frame.depth_key).where(Frame.camera_id == camera.id)
                                    .order_by(Frame.index)))
        present = [key for key in keys if key]
        if keys and len(present) == len(keys):
            out[view] = DepthStack(present, camera.height, camera.width)
    return out


def highlight_mask(task: Task, width: int, height: int) -> np.ndarray | None:
    """The object's outline at its initial pose (the task's highlight polygon) as a mask."""
    polygon = (task.highlight or {}).get("polygon")
    if not polygon:
        return None
    mask = np.zeros((height, width), dtype=np.uint8)
    cv2.fillPoly(mask, [np.round(np.asarray(polygon, dtype=np.float64)).astype(np.int32)], 1)
    return mask.astype(bool)


def latest_solve(session: Session, sequence_id: int) -> SolveRun | None:
    """The sequence's newest finished solve run with stored results, if any."""
    return session.scalar(select(SolveRun).where(
        SolveRun.sequence_id == sequence_id, SolveRun.status == "done",
        SolveRun.result_key.is_not(None)).order_by(SolveRun.id.desc()).limit(1))


def solved_objects(session: Session, sequence_id: int) -> tuple[SolvedObjects, int] | None:
    """The sequence's objects as its newest solve left them (meshes in their own frames, poses
    (O, F, 3, 4) object-to-world in SceneObject.index order, NaN where the solve flags the
    pose) and the run's id; None before any solve. The result is read through
    backend.solve.results only."""
    from worker.quality.solved_scene import SolvedObjects

    run = latest_solve(session, sequence_id)
    if run is None or run.result_key is None:
        return None
    arrays = decode_result(get_storage().get_bytes(run.result_key))
    sequence = session.get_one(Sequence, sequence_id)
    names = [str(n) for n in arrays["object_names"]]
    poses = np.asarray(arrays["object_poses"], dtype=np.float64)
    if names != [o.name for o in sequence.objects] or poses.shape[:2] != (
            len(names), sequence.num_frames):
        raise ValueError(f"solve run {run.id} holds objects {names} over {poses.shape[1]} "
                         f"frames; the sequence has {[o.name for o in sequence.objects]} over "
                         f"{sequence.num_frames}")
    # A pose the solve flags as not pinned down by its evidence judges nobody.
    _, flags = object_trust(arrays)
    poses = np.where((flags == "")[..., None, None], poses, np.nan)
    storage = get_storage()
    meshes = [load_mesh(storage, o.mesh_key) for o in sequence.objects]
    return SolvedObjects(vertices=[np.asarray(m.vertices, np.float64) for m in meshes],
                         faces=[np.asarray(m.faces, np.int64) for m in meshes],
                         poses=poses), run.id


def import_posed_objects(session: Session, sequence_id: int, target: int
                         ) -> SolvedObjects | None:
    """The sequence's objects at the poses given at import (SceneObject.initial_pose,
    object-to-world at frame 0), when object ``target`` (its SceneObject.index) is one that
    stays where it was put: an object nobody grasps keeps its import pose in every frame, the
    grasped one only at frame 0 (NaN after it). None when the target is the grasped object or
    has no import pose: then only a solve says where it is."""
    from worker.quality.solved_scene import SolvedObjects

    sequence = session.get_one(Sequence, sequence_id)
    objects = sorted(sequence.objects, key=lambda o: o.index)
    if not 0 <= target < len(objects) or objects[target].grasped \
            or objects[target].initial_pose is None:
        return None
    poses = np.full((len(objects), sequence.num_frames, 3, 4), np.nan)
    for i, obj in enumerate(objects):
        if obj.initial_pose is not None:
            poses[i, :None if not obj.grasped else 1] = np.asarray(obj.initial_pose, np.float64)
    storage = get_storage()
    meshes = [load_mesh(storage, o.mesh_key) for o in objects]
    return SolvedObjects(vertices=[np.asarray(m.vertices, np.float64) for m in meshes],
                         faces=[np.asarray(m.faces, np.int64) for m in meshes], poses=poses)
