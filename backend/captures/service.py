"""Capture rules: importing sequences, reading them back. Services flush, never commit."""

from __future__ import annotations

import hashlib
import logging
import mimetypes
import re
import secrets
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from pydantic import Field
from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from backend.captures.calibration import imported_model
from backend.captures.models import Camera, Frame, Hand, SceneObject, Sequence, Subject
from backend.captures.plans import SequencePlan
from backend.captures.schemas import ImportResultRead
from backend.errors import Conflict, NotFound
from backend.storage import Storage
from worker.formats import dexycb
from worker.geometry.cameras import CameraModel

UPLOAD_THREADS = 8
# Most missing file keys an error message lists.
LISTED_KEYS = 5

log = logging.getLogger(__name__)


class ImportResult(ImportResultRead):
    """What an import did, as the API reads it, and where its files are stored."""

    # Left out of every dump: the storage prefix is for the import's own clean-up only.
    storage_uid: str = Field("", exclude=True)


@dataclass(frozen=True)
class StoredFile:
    """One file an import writes: its storage key, and the capture file or bytes it holds."""

    key: str
    path: Path | None
    data: bytes | None = None


def new_storage_uid(subject: str, name: str) -> str:
    """A storage prefix of its own for one import attempt: the name's hash, then a random part.

    Two imports of the same sequence at once write under different prefixes, so the one that
    loses the race (its rows are refused by the unique name) removes only its own files.
    """
    digest = hashlib.sha256(f"{subject}/{name}".encode()).hexdigest()[:24]
    return f"{digest}-{secrets.token_hex(6)}"


def capture_prefix(uid: str) -> str:
    """Storage prefix of a sequence's frames, models and thumbnails."""
    return f"captures/{uid}"


def solve_prefix(uid: str) -> str:
    """Storage prefix of a sequence's solve results (backend.solve.results.result_key)."""
    return f"solves/{uid}"


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


def list_sequences(session: Session, limit: int | None = None, offset: int = 0
                   ) -> list[Sequence]:
    """Sequences in id order with their cameras, objects, hands and subject; a page of them
    when ``limit`` is given."""
    stmt = (select(Sequence).order_by(Sequence.id).offset(offset).limit(limit)
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
            f"delete it first to re-import (`dexlabel sequences delete {seq.id}` or "
            f"DELETE /api/sequences/{seq.id})"
        )
    return seq


def import_sequence(session: Session, storage: Storage, plan: SequencePlan) -> ImportResult:
    """Copy a planned sequence's files to storage and add its rows (flushed, not committed).

    A new sequence is written under a storage prefix of this attempt's own, and on any failure
    before the rows are flushed that prefix is removed again (the caller's rollback removes the
    rows). A sequence already imported from the same capture is checked instead: stored files
    that went missing are written again from the capture (``repaired``).
    """
    seq = existing_import(session, plan)
    if seq is not None:
        repaired = restore_missing_files(session, storage, plan, seq)
        return ImportResult(sequence_id=seq.id, subject=plan.subject, name=plan.name,
                            created=False, num_cameras=len(seq.cameras),
                            num_frames=seq.num_frames, repaired=repaired,
                            storage_uid=seq.storage_uid)
    uid = new_storage_uid(plan.subject, plan.name)
    try:
        seq = _add_rows(session, plan, uid)
        _write(storage, plan_files(plan, capture_prefix(uid)))
        session.flush()
    except BaseException:
        storage.delete_prefix(capture_prefix(uid))
        raise
    return ImportResult(sequence_id=seq.id, subject=plan.subject, name=plan.name, created=True,
                        num_cameras=len(plan.cameras), num_frames=plan.num_frames,
                        storage_uid=uid)


def restore_missing_files(
    session: Session, storage: Storage, plan: SequencePlan, seq: Sequence
) -> int:
    """Write again every stored file of ``seq`` that is missing, from the capture it was imported
    from (same fingerprint); how many were written.

    Raises:
        Conflict: a stored file the rows refer to is missing and the capture has nothing for
            that key; the detail lists the keys and how to delete the sequence.
    """
    files = {f.key: f for f in plan_files(plan, capture_prefix(seq.storage_uid))}
    keys = set(files)
    keys.update(k for row in _frame_rows(session, seq.id) for k in row if k)
    keys.update(obj.mesh_key for obj in seq.objects)
    with ThreadPoolExecutor(UPLOAD_THREADS) as pool:
        present = dict(zip(sorted(keys), pool.map(storage.exists, sorted(keys)), strict=True))
    missing = [k for k, there in present.items() if not there]
    lost = [k for k in missing if k not in files]
    if lost:
        listed = ", ".join(lost[:LISTED_KEYS]) + (" ..." if len(lost) > LISTED_KEYS else "")
        raise Conflict(
            f"sequence {seq.id} ({plan.subject}/{plan.name}): {len(lost)} stored file(s) are "
            f"missing and this capture has nothing to restore them from: {listed}; delete the "
            f"sequence (`dexlabel sequences delete {seq.id}` or DELETE /api/sequences/{seq.id}) "
            "and import it again")
    if missing:
        _write(storage, [files[k] for k in missing])
        log.warning("sequence %d (%s/%s): %d stored file(s) were missing and are written again "
                    "from the capture", seq.id, plan.subject, plan.name, len(missing))
    return len(missing)


def _frame_rows(session: Session, sequence_id: int) -> list[tuple[str, str | None]]:
    stmt = (select(Frame.color_key, Frame.depth_key).join(Camera)
            .where(Camera.sequence_id == sequence_id))
    return [(row[0], row[1]) for row in session.execute(stmt)]


def _get_or_create_subject(session: Session, name: str) -> Subject:
    subject = session.scalars(select(Subject).where(Subject.name == name)).one_or_none()
    if subject is None:
        subject = Subject(name=name)
        session.add(subject)
    return subject


def color_key(prefix: str, serial: str, index: int) -> str:
    return f"{prefix}/{serial}/{dexycb.color_file(index)}"


def depth_key(prefix: str, serial: str, index: int) -> str:
    return f"{prefix}/{serial}/{dexycb.depth_file(index)}"


def model_key(prefix: str, object_name: str, file_name: str) -> str:
    return f"{prefix}/{dexycb.model_dir(object_name)}/{file_name}"


def plan_files(plan: SequencePlan, prefix: str) -> list[StoredFile]:
    """Every file an import of ``plan`` under ``prefix`` writes: models, colour and depth."""
    files = [StoredFile(model_key(prefix, obj.name, path.name), path)
             for obj in plan.objects for path in obj.model_files]
    for cam in plan.cameras:
        if cam.video_path is None:
            for fr in cam.frames:
                files.append(StoredFile(color_key(prefix, cam.serial, fr.index), fr.color_path))
                if fr.depth_path is not None:
                    files.append(StoredFile(depth_key(prefix, cam.serial, fr.index),
                                            fr.depth_path))
        else:
            files.extend(StoredFile(color_key(prefix, cam.serial, index), None, data)
                         for index, data in enumerate(cam.video_frames))
    return files


def _add_rows(session: Session, plan: SequencePlan, uid: str) -> Sequence:
    seq = Sequence(
        subject=_get_or_create_subject(session, plan.subject), name=plan.name, storage_uid=uid,
        num_frames=plan.num_frames, master_serial=plan.master_serial,
        source_kind=plan.source_kind, fingerprint=plan.fingerprint,
    )
    prefix = capture_prefix(uid)
    for view, cam_plan in enumerate(plan.cameras):
        cam = Camera(
            serial=cam_plan.serial, view_index=view, width=cam_plan.width,
            height=cam_plan.height, fx=cam_plan.fx, fy=cam_plan.fy, ppx=cam_plan.ppx,
            ppy=cam_plan.ppy, distortion=cam_plan.distortion, extrinsics=cam_plan.extrinsics,
            has_depth=cam_plan.video_path is None,
        )
        if cam_plan.video_path is None:
            for fr in cam_plan.frames:
                cam.frames.append(Frame(
                    index=fr.index, color_key=color_key(prefix, cam.serial, fr.index),
                    depth_key=(depth_key(prefix, cam.serial, fr.index)
                               if fr.depth_path is not None else None),
                    color_bytes=fr.color_path.stat().st_size))
        else:
            for index, data in enumerate(cam_plan.video_frames):
                cam.frames.append(Frame(index=index, color_key=color_key(prefix, cam.serial, index),
                                        depth_key=None, color_bytes=len(data)))
        seq.cameras.append(cam)
    for obj in plan.objects:
        seq.objects.append(SceneObject(
            index=obj.index, ycb_id=obj.ycb_id, name=obj.name,
            mesh_key=model_key(prefix, obj.name, obj.mesh_path.name),
            num_vertices=obj.num_vertices, num_faces=obj.num_faces, grasped=obj.grasped,
            initial_pose=obj.initial_pose,
        ))
    for hand in plan.hands:
        seq.hands.append(Hand(index=hand.index, side=hand.side, calib_name=hand.calib_name,
                              betas=hand.betas))
    session.add(seq)
    return seq


def _write(storage: Storage, files: list[StoredFile]) -> None:
    with ThreadPoolExecutor(UPLOAD_THREADS) as pool:
        for _ in pool.map(lambda f: _put(storage, f), files):
            pass


def _put(storage: Storage, file: StoredFile) -> None:
    if file.data is not None:
        payload = file.data
    else:
        assert file.path is not None
        payload = file.path.read_bytes()
    storage.put_bytes(file.key, payload,
                      mimetypes.guess_type(file.key)[0] or "application/octet-stream")


def sequence_cameras(session: Session, sequence_id: int) -> list[Camera]:
    """A sequence's cameras in view order (the index every view refers to)."""
    return list(session.scalars(select(Camera).where(Camera.sequence_id == sequence_id)
                                .order_by(Camera.view_index, Camera.id)))


def camera_model(camera: Camera) -> CameraModel:
    """A camera row's imported calibration as the worker packages take it (pixels,
    camera-to-world metres); :func:`backend.captures.calibration.calibrated_models` gives the
    version in use."""
    return imported_model(camera)


_YCB_PREFIX = re.compile(r"^\d+_")


def object_label(name: str) -> str:
    """A YCB object name for people: "006_mustard_bottle" -> "mustard bottle"."""
    label = _YCB_PREFIX.sub("", name).replace("_", " ").strip()
    return label or name
