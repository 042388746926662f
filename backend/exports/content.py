"""What an export of one sequence holds, read from the database and storage in one short unit
of work: cameras, objects, hands, the labelled work (accepted, or all submitted, with its QC
outcome) as raw keyframes and dense per-frame tracks, and the current solve's arrays.

Pixels x right, y down (as OpenCV projects); camera frames and world in metres; the world is the
capture's master frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.captures.assets import hand_model_for
from backend.captures.calibration import calibrated_models, hand_betas, version_in_use
from backend.captures.models import Frame, Sequence
from backend.captures.service import sequence_cameras
from backend.labels import INCLUDE_STATUSES, labelled_work, merge_labels, sequence_tasks
from backend.quality.models import QCReport
from backend.solve.results import decode_result, hand_trust, object_trust
from backend.solve.service import current_run
from backend.storage import get_storage
from worker.formats.provenance import ProvenanceState, frame_provenance, view_states
from worker.geometry import CameraModel
from worker.tracks.interpolate import dense_points


@dataclass
class ViewContent:
    """One camera: as the worker packages take it, its serial and its frames' storage keys."""

    serial: str
    camera: CameraModel
    color_keys: list[str]
    depth_keys: list[str | None]


@dataclass
class ObjectContent:
    index: int
    ycb_id: int
    name: str
    grasped: bool
    mesh_key: str


@dataclass
class HandContent:
    index: int
    side: str
    calib_name: str | None
    betas: list[float] | None


@dataclass
class WorkContent:
    """One assignment's labels of one task (one view of one target).

    keyframes: per point, the stored rows [frame, x, y, visible01] (px). xy: (F, P, 2) px, NaN
    where the point has no position; visible: (F, P) bool (worker.tracks.interpolate.dense_points).
    """

    assignment_id: int
    external_id: str
    worker_id: str
    status: str
    task_id: int
    view: int
    target_key: str
    kind: str
    keyframes: list[list[list[Any]]]
    xy: np.ndarray
    visible: np.ndarray
    working_time_s: float
    edit_count: int
    submitted_at: datetime | None
    qc: dict[str, Any] | None


@dataclass
class SolveContent:
    """The sequence's current solve run and its arrays (see backend.solve.results)."""

    run_id: int
    optimiser: str
    finished_at: datetime | None
    arrays: dict[str, np.ndarray]
    # The solved hand's vertices (F, N, 3) world metres (NaN rows where unlabelled), its faces
    # and its rest root joint (3,), for pose_m in camera frames; None without a hand.
    hand_vertices: np.ndarray | None = None
    hand_faces: np.ndarray | None = None
    root_joint: np.ndarray | None = None
    result_key: str | None = None
    # Trust of every solved value (see backend.solve.results): object_confidence (O, F) in
    # [0, 1] and object_flags (O, F) str; hand_confidence (F,) and hand_flags (F,) str; a flag
    # is the reason the value is not trusted, "" where it is. Filled by fetch_solve.
    object_confidence: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    object_flags: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=str))
    hand_confidence: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hand_flags: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=str))

    def hand_trusted(self, frame: int) -> bool:
        """True where the solve labelled the hand at ``frame`` and did not flag it."""
        joints = self.arrays["hand_joints"][frame]
        return bool(np.isfinite(joints).all()) and not self.hand_flags[frame]

    def object_flag(self, index: int, frame: int) -> dict[str, Any]:
        """{"valid", "confidence", "flag"} of object ``index``'s pose at ``frame``."""
        flag = str(self.object_flags[index, frame])
        return {"valid": not flag, "confidence": round(float(self.object_confidence[index, frame]),
                                                       3), "flag": flag or None}


@dataclass
class SequenceContent:
    sequence_id: int
    subject: str
    name: str
    num_frames: int
    fps: float
    master_serial: str | None
    views: list[ViewContent]
    objects: list[ObjectContent]
    hands: list[HandContent]
    work: list[WorkContent] = field(default_factory=list)
    solve: SolveContent | None = None
    _provenance: dict[str, list[list[ProvenanceState]]] = field(default_factory=dict)

    def merged_labels(self, view: int, target_key: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The accepted work of one view and target merged as the solve merges it: (F, P, 2) px
        and (F, P) bool; None when there is none."""
        chosen = [(w.xy, w.visible) for w in self.work
                  if w.view == view and w.target_key == target_key and w.status == "approved"]
        return merge_labels(chosen) if chosen else None

    def provenance_states(self, target_key: str) -> list[list[ProvenanceState]]:
        """Per view, per frame the provenance state of ``target_key``'s accepted labels
        (worker.formats.provenance; a view with several approved assignments takes the first)."""
        states: list[list[ProvenanceState]] = []
        for v in range(len(self.views)):
            work = next((w for w in self.work if w.view == v and w.target_key == target_key
                         and w.status == "approved"), None)
            states.append(view_states(work.keyframes, self.num_frames) if work is not None
                          else ["none"] * self.num_frames)
        return states

    def provenance(self, target_key: str, frame: int) -> dict[str, Any]:
        """One frame's provenance of a target: {"views_decided", "views": {serial: state}}."""
        if target_key not in self._provenance:
            self._provenance[target_key] = self.provenance_states(target_key)
        return frame_provenance(self._provenance[target_key], [v.serial for v in self.views],
                                frame)


def _qc(report: QCReport | None) -> dict[str, Any] | None:
    if report is None:
        return None
    return {"outcome": report.outcome, "action": report.action, "method": report.method,
            "provisional": report.provisional, "reasons": list(report.reasons or []),
            "metrics": report.metrics}


def _work(session: Session, sequence_id: int, views: dict[int, int], num_frames: int,
          include: str) -> list[WorkContent]:
    tasks = {t.id: t for t in sequence_tasks(session, sequence_id)}
    work = labelled_work(session, tasks, INCLUDE_STATUSES[include])
    reports = {r.assignment_id: r for r in session.scalars(
        select(QCReport).where(QCReport.assignment_id.in_([a.id for a in work])))}
    out = []
    for a in work:
        task = tasks[a.task_id]
        xy, visible = dense_points(((t.point_index, t.keyframes) for t in a.tracks), num_frames,
                                   task.num_points)
        keyframes: list[list[list[Any]]] = [[] for _ in range(task.num_points)]
        for track in a.tracks:
            if 0 <= track.point_index < task.num_points:
                keyframes[track.point_index] = [list(row) for row in track.keyframes]
        out.append(WorkContent(
            assignment_id=a.id, external_id=a.external_id, worker_id=a.worker_id,
            status=a.status, task_id=task.id, view=views[task.camera_id],
            target_key=task.target_key, kind=task.kind, keyframes=keyframes, xy=xy,
            visible=visible, working_time_s=float(a.working_time_s or 0.0),
            edit_count=int(a.edit_count or 0), submitted_at=a.submitted_at,
            qc=_qc(reports.get(a.id))))
    return out


def _solved_hand(solve: SolveContent) -> None:
    """The hand mesh at every labelled frame and the rest root joint, from pose_m and betas."""
    # Posing loads PyTorch: imported here, so that only exports with a solved hand pay for it.
    from worker.hand.layer import HandLayer
    from worker.hand.posing import posed_hand

    arrays = solve.arrays
    side = str(arrays["hand_side"])
    if not side or arrays["betas"].size == 0:
        return
    model = hand_model_for(side)
    layer = HandLayer(model)
    pose_m = np.asarray(arrays["hand_pose_m"], dtype=np.float64)
    finite: np.ndarray = np.asarray(np.isfinite(pose_m).all(axis=1))
    betas = np.asarray(arrays["betas"], dtype=np.float64)
    _, rest_joints = posed_hand(layer, np.zeros((1, pose_m.shape[1])), betas)
    solve.root_joint = rest_joints[0, 0]
    vertices, _ = posed_hand(layer, np.where(finite[:, None], pose_m, 0.0), betas)
    vertices[~finite] = np.nan
    solve.hand_vertices = vertices
    solve.hand_faces = np.asarray(model.faces, dtype=np.int64)


def load_sequence(session: Session, sequence_id: int, include: str = "accepted",
                  with_solve: bool = True) -> SequenceContent:
    """Everything an export writes of one sequence from the database; frames stay in storage
    and the solve's arrays are read by :func:`fetch_solve` once the unit of work is over."""
    seq = session.get_one(Sequence, sequence_id)
    cameras = sequence_cameras(session, sequence_id)
    version = version_in_use(session, sequence_id)
    views = []
    for camera, model in zip(cameras, calibrated_models(session, cameras), strict=True):
        frames = list(session.scalars(select(Frame).where(Frame.camera_id == camera.id)
                                      .order_by(Frame.index)))
        views.append(ViewContent(camera.serial, model,
                                 [f.color_key for f in frames], [f.depth_key for f in frames]))
    content = SequenceContent(
        sequence_id=seq.id, subject=seq.subject.name, name=seq.name,
        num_frames=seq.num_frames, fps=float(seq.fps), master_serial=seq.master_serial,
        views=views,
        objects=[ObjectContent(o.index, o.ycb_id, o.name, o.grasped, o.mesh_key)
                 for o in seq.objects],
        hands=[HandContent(h.index, h.side, h.calib_name,
                           hand_betas(version, h.index, list(h.betas) if h.betas else None))
               for h in seq.hands])
    content.work = _work(session, sequence_id, {c.id: i for i, c in enumerate(cameras)},
                         seq.num_frames, include)
    run = current_run(session, sequence_id) if with_solve else None
    if run is not None and run.result_key is not None:
        content.solve = SolveContent(run.id, run.optimiser, run.finished_at, {},
                                     result_key=run.result_key)
    return content


def fetch_solve(content: SequenceContent) -> None:
    """Read the solve's arrays from storage and pose its hand (outside any transaction)."""
    solve = content.solve
    if solve is None or solve.arrays or solve.result_key is None:
        return
    solve.arrays = decode_result(get_storage().get_bytes(solve.result_key))
    # Every solved value is kept; its trust travels beside it and each format writes the flag
    # in the form its readers understand (see the README's Export section).
    solve.object_confidence, solve.object_flags = object_trust(solve.arrays)
    solve.hand_confidence, solve.hand_flags = hand_trust(solve.arrays)
    _solved_hand(solve)
