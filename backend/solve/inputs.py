"""What a solve reads from the database and storage, as the arrays worker.solver takes.

Labels come only from approved assignments. Where several are approved for one task (one view
of one target), they are merged per frame: the median of their positions (pixels) and visible
where most of them say visible. Views run in the cameras' ``view_index`` order.

Hand labels are first checked against their own view's images (worker.assist.stretches):
an interpolated stretch the images say the hand left is dropped from the merge (it would pin
the solve to a straight line the hand did not take), and each view keeps, per frame and joint,
the best evidence any of its workers gave (keyed, confirmed by the images, unchecked) for the
hand's per-frame confidence (worker.solver.hand_confidence).
"""

from __future__ import annotations

import tempfile
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.accepted import count_accepted, labelled_work, sequence_tasks
from backend.annotation.models import Assignment
from backend.annotation.proposals import grey_frames
from backend.captures.calibration import (
    CalibrationVersion,
    calibrated_models,
    camera_entry,
    hand_betas,
    version_in_use,
)
from backend.captures.models import Camera, Frame, Sequence
from backend.captures.service import sequence_cameras
from backend.config import get_settings
from backend.solve.calibrated import depth_in_world_time, hand_in_world_time, objects_in_world_time
from backend.storage import Storage, get_storage
from worker.assist.stretches import (
    EVIDENCE_CONFIRMED,
    EVIDENCE_CONTRADICTED,
    EVIDENCE_KEYED,
    EVIDENCE_NONE,
    EVIDENCE_UNCHECKED,
    check_stretches,
)
from worker.geometry.mesh_io import Mesh, read_mesh
from worker.hand import HandModel, load_hand_model
from worker.hand.joints import NUM_JOINTS
from worker.hand.params import check_side
from worker.solver import HandTarget, Landmark, ObjectTarget, SolveInputs
from worker.tracks.interpolate import dense_points


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


def count_approved(session: Session, sequence_id: int) -> int:
    return count_accepted(session, sequence_id)


def load_mesh(storage: Storage, key: str) -> Mesh:
    """An object model (OBJ or PLY, metres) from storage."""
    with tempfile.NamedTemporaryFile(suffix=Path(key).suffix) as fh:
        fh.write(storage.get_bytes(key))
        fh.flush()
        return read_mesh(Path(fh.name))


def load_depth(storage: Storage, camera: Camera, frames: list[Frame]) -> np.ndarray | None:
    """(F, H, W) uint16 millimetres of one view, or None when the view has no depth.

    Raises ValueError naming the file when a stored depth map is not an H x W uint16 PNG.
    """
    keys = [f.depth_key for f in frames if f.depth_key is not None]
    if not camera.has_depth or not frames or len(keys) < len(frames):
        return None
    maps = []
    for key in keys:
        data = np.frombuffer(storage.get_bytes(key), np.uint8)
        depth = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        if depth is None or depth.dtype != np.uint16 or depth.shape != (camera.height,
                                                                        camera.width):
            raise ValueError(f"depth map {key} is not a {camera.width}x"
                             f"{camera.height} uint16 PNG")
        maps.append(depth)
    return np.stack(maps)


def hand_model_for(side: str) -> HandModel:
    """The MANO model of ``side``: official pickles from DEXLABEL_MANO_DIR, else built in."""
    return load_hand_model(check_side(side), get_settings().mano_dir)


@dataclass
class GatheredInputs:
    """The solver's inputs plus the names the API shows beside them."""

    inputs: SolveInputs
    serials: list[str]
    object_names: list[str]
    hand_side: str | None


def hand_target(seq: Sequence, cameras: list[Camera], labels: dict,
                hand_index: int = 0, evidence: dict | None = None,
                version: CalibrationVersion | None = None) -> HandTarget | None:
    """One hand's merged labels over all views (NaN in views nobody labelled), with each
    view's evidence codes where ``evidence`` has them (approved_labels), and its betas under
    the calibration ``version`` (None: the imported ones); the solver takes one hand,
    DexYCB's sequences have one."""
    hand = next((h for h in seq.hands if h.index == hand_index), None)
    if hand is None:
        return None
    key = f"hand:{hand.index}"
    keypoints = np.full((len(cameras), seq.num_frames, NUM_JOINTS, 2), np.nan)
    visible = np.zeros((len(cameras), seq.num_frames, NUM_JOINTS), dtype=bool)
    codes = None if evidence is None else np.full(visible.shape, EVIDENCE_NONE, np.int8)
    for view, camera in enumerate(cameras):
        if (camera.id, key) in labels:
            keypoints[view], visible[view] = labels[(camera.id, key)]
        if codes is not None and evidence is not None and (camera.id, key) in evidence:
            codes[view] = evidence[(camera.id, key)]
    shape = hand_betas(version, hand.index, hand.betas)
    betas = np.asarray(shape if shape is not None else [], dtype=np.float64)
    return HandTarget(side=hand.side, betas=betas, keypoints=keypoints, visible=visible,
                      evidence=codes)


def object_targets(seq: Sequence, cameras: list[Camera], labels: dict,
                   storage: Storage) -> list[ObjectTarget]:
    """Every object with its mesh, initial pose and the landmarks of its approved tasks."""
    out = []
    for obj in seq.objects:
        mesh = load_mesh(storage, obj.mesh_key)
        landmarks = []
        for view, camera in enumerate(cameras):
            merged = labels.get((camera.id, f"object:{obj.index}"))
            if merged is None:
                continue
            xy, visible = merged
            landmarks += [Landmark(view=view, xy=xy[:, p], visible=visible[:, p])
                          for p in range(xy.shape[1])]
        pose = None if obj.initial_pose is None else np.asarray(obj.initial_pose, float)
        out.append(ObjectTarget(name=obj.name, vertices=mesh.vertices, faces=mesh.faces,
                                initial_pose=pose, landmarks=landmarks))
    return out


def gather_inputs(session: Session, sequence_id: int, with_depth: bool = True) -> GatheredInputs:
    """Cameras, merged approved labels, meshes, initial poses and depth of one sequence,
    under the calibration version in use (labels and depth in world time)."""
    storage = get_storage()
    seq = session.get_one(Sequence, sequence_id)
    cameras = sequence_cameras(session, sequence_id)
    version = version_in_use(session, sequence_id)
    entries = [camera_entry(version, c) for c in cameras]
    evidence: dict[tuple[int, str], np.ndarray] = {}
    labels = approved_labels(session, sequence_id, seq.num_frames, evidence)
    hand = hand_in_world_time(hand_target(seq, cameras, labels, evidence=evidence,
                                          version=version), entries)
    depth: list[np.ndarray | None] = []
    for camera in cameras:
        frames = list(session.scalars(select(Frame).where(Frame.camera_id == camera.id)
                                      .order_by(Frame.index)))
        depth.append(load_depth(storage, camera, frames) if with_depth else None)
    inputs = SolveInputs(
        cameras=calibrated_models(session, cameras), num_frames=seq.num_frames, hand=hand,
        objects=objects_in_world_time(object_targets(seq, cameras, labels, storage), entries),
        depth=depth_in_world_time(depth, entries),
        hand_model=hand_model_for(hand.side) if hand is not None else None)
    return GatheredInputs(inputs=inputs, serials=[c.serial for c in cameras],
                          object_names=[o.name for o in seq.objects],
                          hand_side=hand.side if hand is not None else None)
