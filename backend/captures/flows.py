"""Import as a whole unit of work: plan, copy, commit, then enqueue the frame-statistics job;
and deleting a sequence with its files.

Every sequence is its own transaction, and every import attempt writes its files under a
storage prefix of its own, so no partial sequence survives and an import never removes files it
did not write. If anything fails before the commit (a bad file, storage, the commit), the
sequence's rows are rolled back and that attempt's files removed. Two imports of the same new
sequence at once both write their files; the unique sequence name lets only one commit, and the
other, refused, removes its own files and finds the committed sequence when it asks again.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from backend.captures import layout, service
from backend.captures.models import Sequence
from backend.db import session_scope
from backend.errors import StorageError
from backend.jobs.service import enqueue_job
from backend.storage import Storage, get_storage

# The job kind of a sequence's frame statistics and thumbnails (worker.tasks runs it).
FRAME_STATS = "frame_stats"
# A lost race (another import committed the same sequence or subject first) is retried this
# many times; the next attempt sees the winner's rows.
IMPORT_ATTEMPTS = 3

log = logging.getLogger(__name__)


def import_path(path: str | Path, storage: Storage | None = None) -> list[service.ImportResult]:
    """Import every sequence under ``path`` (a capture root or one sequence folder).

    All sequences are parsed and checked before the first one is written. A sequence already
    imported from the same capture is unchanged, except that stored files that went missing are
    written again (``repaired``).
    """
    storage = storage or get_storage()
    plans = [layout.read_sequence(d) for d in layout.find_sequence_dirs(Path(path))]
    return [_import_plan(storage, plan) for plan in plans]


def _import_plan(storage: Storage, plan: layout.SequencePlan) -> service.ImportResult:
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


def _import_once(storage: Storage, plan: layout.SequencePlan) -> service.ImportResult:
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


@dataclass
class DeleteResult:
    sequence: service.DeletedSequence
    files: int


def delete_sequence(sequence_id: int, force: bool = False,
                    storage: Storage | None = None) -> DeleteResult:
    """Delete a sequence: its rows (and the work on it, with ``force``), then its stored frames,
    models, thumbnails and solve results.

    The rows go first, in their own committed transaction, so nothing ever refers to a removed
    file; files that cannot be removed then are reported as a StorageError naming the prefix.
    """
    storage = storage or get_storage()
    with session_scope() as session:
        deleted = service.delete_sequence(session, sequence_id, force)
    prefixes = (service.capture_prefix(deleted.storage_uid),
                service.solve_prefix(deleted.storage_uid))
    try:
        files = sum(storage.delete_prefix(prefix) for prefix in prefixes)
    except (OSError, StorageError) as exc:
        detail = exc.detail if isinstance(exc, StorageError) else str(exc)
        raise StorageError(
            f"sequence {sequence_id} is deleted but its files under {' and '.join(prefixes)} "
            f"could not all be removed: {detail}") from exc
    return DeleteResult(deleted, files)
