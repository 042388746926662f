"""What a solve reads from the database and storage, as the arrays worker.solver takes.

Labels come only from approved assignments, merged per view (backend.labels.approved_labels);
views run in the cameras' ``view_index`` order. Hand labels are first checked against their own
view's images: an interpolated stretch the images say the hand left would pin the solve to a
straight line the hand did not take, and each view's best evidence per frame and joint feeds
the hand's per-frame confidence (worker.solver.hand_confidence).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.captures.assets import hand_model_for, load_depth, load_mesh
from backend.captures.calibration import (
    CalibrationVersion,
    calibrated_models,
    camera_entry,
    hand_betas,
    version_in_use,
)
from backend.captures.models import Camera, Frame, Sequence
from backend.captures.service import sequence_cameras
from backend.labels import approved_labels
from backend.solve.calibrated import depth_in_world_time, hand_in_world_time, objects_in_world_time
from backend.storage import Storage, get_storage
from worker.assist.stretches import EVIDENCE_NONE
from worker.hand.joints import NUM_JOINTS
from worker.solver import HandTarget, Landmark, ObjectTarget, SolveInputs


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
