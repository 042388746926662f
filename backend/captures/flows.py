"""Import as a whole unit of work: plan, copy, commit, then enqueue the frame-statistics job;
and that job's work, each frame's statistics and thumbnail.

Every sequence is its own transaction, and every import attempt writes its files under a
storage prefix of its own, so no partial sequence survives and an import never removes files it
did not write. If anything fails before the commit (a bad file, storage, the commit), the
sequence's rows are rolled back and that attempt's files removed. Two imports of the same new
sequence at once both write their files; the unique sequence name lets only one commit, and the
other, refused, removes its own files and finds the committed sequence when it asks again.
"""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np
from sqlalchemy import select, update
from sqlalchemy.exc import IntegrityError

from backend.captures import layout, service
from backend.captures.models import Camera, Frame, Sequence
from backend.captures.plans import SequencePlan
from backend.captures.reader import CaptureRoots
from backend.config import Settings
from backend.db import session_scope
from backend.errors import InvalidCapture
from backend.jobs.service import enqueue_job
from backend.storage import Storage, get_storage

# The job kind of a sequence's frame statistics and thumbnails (compute_frame_stats).
FRAME_STATS = "frame_stats"
# A lost race (another import committed the same sequence or subject first) is retried this
# many times; the next attempt sees the winner's rows.
IMPORT_ATTEMPTS = 3

log = logging.getLogger(__name__)


def import_path(path: str | Path, storage: Storage | None = None,
                roots: CaptureRoots | None = None) -> list[service.ImportResult]:
    """Import every sequence under ``path`` (a capture root or one sequence folder).

    All sequences are parsed and checked before the first one is written. A sequence already
    imported from the same capture is unchanged, except that stored files that went missing are
    written again (``repaired``). With ``roots`` (the HTTP import), the path, the root of every
    capture found and every file and folder read must lie inside one of those folders,
    symbolic links followed.

    Raises:
        InvalidCapture: a path with a NUL character, longer than MAX_PATH_CHARS, unreadable, or
            a capture with a missing or malformed file.
        Forbidden: outside ``roots``, named relative to the capture (roots relative to the
            instance folder).
    """
    storage = storage or get_storage()
    folder = _checked_path(path, roots)
    try:
        seq_dirs = layout.find_sequence_dirs(folder)
    except OSError as exc:  # a name too long for the file system, a folder it may not read
        raise InvalidCapture(_shown(str(path)), f"cannot be read ({exc.strerror or exc})") from exc
    if roots is not None:
        for capture_root in sorted({layout.capture_root_of(d) for d in seq_dirs}):
            if not roots.holds(capture_root):
                raise roots.refuse(f"the capture root of {_shown(str(path))} (the folder "
                                   "above its subject folders, where its calibration and "
                                   "models are read)")
    plans = [layout.read_sequence(d, roots) for d in seq_dirs]
    return [_import_plan(storage, plan) for plan in plans]


def allowed_capture_roots(settings: Settings) -> CaptureRoots:
    """The folders an HTTP import may read from (DEXLABEL_CAPTURE_ROOTS); by default the
    instance folder's captures/ and the instance folder itself."""
    roots = settings.capture_roots or [settings.var_dir / "captures", settings.var_dir]
    return CaptureRoots(roots, settings.var_dir)


def _shown(path: str) -> str:
    """A path as an error message shows it: at most 200 characters."""
    return path if len(path) <= 200 else f"{path[:200]}... ({len(path)} characters)"


def _checked_path(path: str | Path, roots: CaptureRoots | None) -> Path:
    text = str(path)
    if "\x00" in text:
        raise InvalidCapture(_shown(text.replace("\x00", "\\0")),
                             "a path must not contain a NUL character")
    if len(text) > layout.MAX_PATH_CHARS:
        raise InvalidCapture(_shown(text), f"a path has at most {layout.MAX_PATH_CHARS} "
                                           f"characters, this one has {len(text)}")
    try:
        resolved = Path(text).resolve()
    except (OSError, RuntimeError) as exc:  # RuntimeError: a symbolic link loop
        raise InvalidCapture(_shown(text), f"cannot be read ({exc})") from exc
    if roots is not None and not roots.holds(resolved):
        # The path as given, never where it leads: the server's folders stay unnamed.
        raise roots.refuse(_shown(text) if resolved == Path(text) else
                           f"{_shown(text)} (a symbolic link leads outside)")
    try:
        there = resolved.exists()
    except OSError as exc:
        raise InvalidCapture(_shown(text), f"cannot be read ({exc.strerror or exc})") from exc
    if not there:
        raise InvalidCapture(_shown(text), "path does not exist")
    return resolved


def _import_plan(storage: Storage, plan: SequencePlan) -> service.ImportResult:
    for attempt in range(1, IMPORT_ATTEMPTS + 1):
        try:
            return _import_once(storage, plan)
        except IntegrityError:
            # Another import committed this sequence (or its new subject) first; this attempt's
            # rows are rolled back and its own files removed. Asking again finds the winner.
            if attempt == IMPORT_ATTEMPTS:
                raise
            log.info("import of %s/%s lost a race to a concurrent import; looking again",
                     plan.subject, plan.name)
    raise AssertionError("unreachable")


def _import_once(storage: Storage, plan: SequencePlan) -> service.ImportResult:
    result: service.ImportResult | None = None
    try:
        with session_scope() as session:
            result = service.import_sequence(session, storage, plan)
            if result.created or result.repaired:
                enqueue_job(session, FRAME_STATS, f"{FRAME_STATS}:{result.sequence_id}",
                            {"sequence_id": result.sequence_id})
    except BaseException:
        if result is not None and result.created:
            _remove_uncommitted_files(storage, result.storage_uid)
        raise
    return result


def _remove_uncommitted_files(storage: Storage, uid: str) -> None:
    """Remove an attempt's files when its commit failed, unless its rows are there after all (a
    commit whose answer was lost); when that cannot be told, the files are kept."""
    try:
        with session_scope() as session:
            committed = session.scalar(select(Sequence.id).where(Sequence.storage_uid == uid))
    except Exception:  # the database is unreachable: keep the files
        log.warning("import under captures/%s failed and its commit cannot be checked; its "
                    "files are kept", uid)
        return
    if committed is None:
        storage.delete_prefix(service.capture_prefix(uid))


def compute_frame_stats(sequence_id: int, storage: Storage | None = None) -> dict[str, object]:
    """Statistics and a thumbnail for every frame of a sequence (the FRAME_STATS job).

    The frames' keys are read in one short unit of work, every file is read, measured and its
    thumbnail written with no transaction open, and the results are stored in a second one
    (idempotent: a retry computes and writes the same again).
    """
    from worker.quality.frame_stats import frame_statistics, thumbnail_jpeg

    storage = storage or get_storage()
    with session_scope() as session:
        frames = session.execute(
            select(Frame.id, Frame.index, Frame.color_key, Frame.depth_key).join(Camera)
            .where(Camera.sequence_id == sequence_id)
            .order_by(Camera.view_index, Frame.index)).all()
    results = []
    for frame_id, index, color_key, depth_key in frames:
        color = cv2.imdecode(np.frombuffer(storage.get_bytes(color_key), np.uint8),
                             cv2.IMREAD_COLOR)
        if color is None:
            raise ValueError(f"{color_key}: not a decodable colour image")
        depth = None
        if depth_key:
            depth = cv2.imdecode(np.frombuffer(storage.get_bytes(depth_key), np.uint8),
                                 cv2.IMREAD_UNCHANGED)
        thumb_key = color_key.rsplit("/", 1)[0] + f"/thumb_{index:06d}.jpg"
        storage.put_bytes(thumb_key, thumbnail_jpeg(color), "image/jpeg")
        results.append({"id": frame_id, "stats": frame_statistics(color, depth),
                        "thumb_key": thumb_key})
    with session_scope() as session:
        for row in results:
            session.execute(update(Frame).where(Frame.id == row["id"])
                            .values(stats=row["stats"], thumb_key=row["thumb_key"])
                            .execution_options(synchronize_session=False))
    log.info("frame statistics for sequence %d: %d frames", sequence_id, len(results))
    return {"frames": len(results),
            "message": f"{len(results)} frames of sequence {sequence_id}: statistics and "
                       "thumbnails"}
