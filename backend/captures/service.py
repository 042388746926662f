"""Capture rules: importing sequences, reading them back. Services flush, never commit."""

from __future__ import annotations

import hashlib
import mimetypes
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from backend.captures.layout import CameraPlan, SequencePlan
from backend.captures.models import Camera, Frame, Hand, SceneObject, Sequence, Subject
from backend.errors import Conflict, NotFound
from backend.storage import Storage
from worker.geometry.cameras import CameraModel

UPLOAD_THREADS = 8


@dataclass
class ImportResult:
    sequence_id: int
    subject: str
    name: str
    created: bool
    num_cameras: int
    num_frames: int


def storage_uid(subject: str, name: str) -> str:
    return hashlib.sha256(f"{subject}/{name}".encode()).hexdigest()[:24]


def find_sequence(session: Session, subject: str, name: str) -> Sequence | None:
    stmt = (select(Sequence).join(Subject)
            .where(Subject.name == subject, Sequence.name == name))
    return session.scalars(stmt).one_or_none()


def get_sequence_or_raise(session: Session, sequence_id: int) -> Sequence:
    stmt = (select(Sequence).where(Sequence.id == sequence_id)
            .options(selectinload(Sequence.cameras), selectinload(Sequence.objects),
                     selectinload(Sequence.hands), selectinload(Sequence.subject)))
    seq = session.scalars(stmt).one_or_none()
    if seq is None:
        raise NotFound(f"sequence {sequence_id} does not exist")
    return seq


def list_sequences(session: Session) -> list[Sequence]:
    stmt = (select(Sequence).order_by(Sequence.id)
            .options(selectinload(Sequence.cameras), selectinload(Sequence.objects),
                     selectinload(Sequence.hands), selectinload(Sequence.subject)))
    return list(session.scalars(stmt))


def get_camera_or_raise(session: Session, sequence_id: int, serial: str) -> Camera:
    stmt = select(Camera).where(Camera.sequence_id == sequence_id, Camera.serial == serial)
    cam = session.scalars(stmt).one_or_none()
    if cam is None:
        raise NotFound(f"sequence {sequence_id} has no camera {serial!r}")
    return cam


def list_frames(session: Session, camera_id: int) -> list[Frame]:
    stmt = select(Frame).where(Frame.camera_id == camera_id).order_by(Frame.index)
    return list(session.scalars(stmt))


def get_frame_or_raise(session: Session, sequence_id: int, serial: str, index: int) -> Frame:
    camera = get_camera_or_raise(session, sequence_id, serial)
    stmt = select(Frame).where(Frame.camera_id == camera.id, Frame.index == index)
    frame = session.scalars(stmt).one_or_none()
    if frame is None:
        seq = session.get(Sequence, sequence_id)
        count = seq.num_frames if seq else 0
        raise NotFound(f"camera {serial!r} has no frame {index} (frames are 0..{count - 1})")
    return frame


def existing_import(session: Session, plan: SequencePlan) -> Sequence | None:
    """The already-imported copy of ``plan``; Conflict if a different capture has its name."""
    seq = find_sequence(session, plan.subject, plan.name)
    if seq is None:
        return None
    if seq.fingerprint != plan.fingerprint:
        raise Conflict(
            f"sequence {plan.subject}/{plan.name} is already imported with different content; "
            "delete it first to re-import"
        )
    return seq


def import_sequence(session: Session, storage: Storage, plan: SequencePlan) -> ImportResult:
    """Copy a planned sequence's files to storage and add its rows (flushed, not committed).

    On any failure the files written under the sequence's storage prefix are removed again;
    the caller's rollback removes the rows.
    """
    seq = existing_import(session, plan)
    if seq is not None:
        frames = seq.num_frames
        return ImportResult(seq.id, plan.subject, plan.name, False, len(seq.cameras), frames)
    uid = storage_uid(plan.subject, plan.name)
    prefix = f"captures/{uid}"
    try:
        seq = _add_rows(session, plan, uid)
        _upload(storage, plan, seq, prefix)
        session.flush()
    except BaseException:
        storage.delete_prefix(prefix)
        raise
    return ImportResult(seq.id, plan.subject, plan.name, True, len(plan.cameras), plan.num_frames)


def _get_or_create_subject(session: Session, name: str) -> Subject:
    subject = session.scalars(select(Subject).where(Subject.name == name)).one_or_none()
    if subject is None:
        subject = Subject(name=name)
        session.add(subject)
    return subject


def _add_rows(session: Session, plan: SequencePlan, uid: str) -> Sequence:
    seq = Sequence(
        subject=_get_or_create_subject(session, plan.subject), name=plan.name, storage_uid=uid,
        num_frames=plan.num_frames, master_serial=plan.master_serial,
        source_kind=plan.source_kind, fingerprint=plan.fingerprint,
    )
    prefix = f"captures/{uid}"
    for view, cam in enumerate(plan.cameras):
        seq.cameras.append(Camera(
            serial=cam.serial, view_index=view, width=cam.width, height=cam.height,
            fx=cam.fx, fy=cam.fy, ppx=cam.ppx, ppy=cam.ppy, distortion=cam.distortion,
            extrinsics=cam.extrinsics, has_depth=cam.video_path is None,
        ))
    for obj in plan.objects:
        seq.objects.append(SceneObject(
            index=obj.index, ycb_id=obj.ycb_id, name=obj.name,
            mesh_key=f"{prefix}/models/{obj.name}/{obj.mesh_path.name}",
            num_vertices=obj.num_vertices, num_faces=obj.num_faces, grasped=obj.grasped,
            initial_pose=obj.initial_pose,
        ))
    for hand in plan.hands:
        seq.hands.append(Hand(index=hand.index, side=hand.side, calib_name=hand.calib_name,
                              betas=hand.betas))
    session.add(seq)
    return seq


def _upload(storage: Storage, plan: SequencePlan, seq: Sequence, prefix: str) -> None:
    jobs: list[tuple[str, bytes | None, str]] = []  # (key, data or None to read path, path)
    jobs.extend((f"{prefix}/models/{obj.name}/{path.name}", None, str(path))
                for obj in plan.objects for path in obj.model_files)
    for cam_plan, cam in zip(plan.cameras, seq.cameras, strict=True):
        for index, color_key, depth_key, color_bytes in _frame_sources(cam_plan, prefix, jobs):
            cam.frames.append(Frame(index=index, color_key=color_key, depth_key=depth_key,
                                    color_bytes=color_bytes))
    with ThreadPoolExecutor(UPLOAD_THREADS) as pool:
        for _ in pool.map(lambda job: _put(storage, *job), jobs):
            pass


def _put(storage: Storage, key: str, data: bytes | None, path: str) -> None:
    payload = data if data is not None else open(path, "rb").read()  # noqa: SIM115
    storage.put_bytes(key, payload, mimetypes.guess_type(key)[0] or "application/octet-stream")


def _frame_sources(
    cam: CameraPlan, prefix: str, jobs: list[tuple[str, bytes | None, str]]
) -> Iterator[tuple[int, str, str | None, int]]:
    base = f"{prefix}/{cam.serial}"
    if cam.video_path is None:
        for fr in cam.frames:
            color_key = f"{base}/color_{fr.index:06d}.jpg"
            jobs.append((color_key, None, str(fr.color_path)))
            depth_key = None
            if fr.depth_path is not None:
                depth_key = f"{base}/aligned_depth_to_color_{fr.index:06d}.png"
                jobs.append((depth_key, None, str(fr.depth_path)))
            yield fr.index, color_key, depth_key, fr.color_path.stat().st_size
        return
    for index, data in enumerate(cam.video_frames):
        color_key = f"{base}/color_{index:06d}.jpg"
        jobs.append((color_key, data, ""))
        yield index, color_key, None, len(data)


def sequence_cameras(session: Session, sequence_id: int) -> list[Camera]:
    """A sequence's cameras in view order (the index every view refers to)."""
    return list(session.scalars(select(Camera).where(Camera.sequence_id == sequence_id)
                                .order_by(Camera.view_index, Camera.id)))


def camera_model(camera: Camera) -> CameraModel:
    """A camera row as the worker packages take it (pixels, camera-to-world metres)."""
    K = np.array([[camera.fx, 0.0, camera.ppx], [0.0, camera.fy, camera.ppy], [0.0, 0.0, 1.0]])
    dist = np.zeros(5)
    coeffs = np.asarray(camera.distortion or [], dtype=np.float64)[:5]
    dist[: len(coeffs)] = coeffs
    return CameraModel(K=K, dist=dist, T_cam_to_world=np.asarray(camera.extrinsics, float),
                       width=camera.width, height=camera.height)
