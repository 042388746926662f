"""Deleting a sequence: one flow across every domain that holds something of it (its HITs
on the marketplace, its rows and the work on them, its payment ledger kept as a cost, its
stored files)."""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session

from backend.annotation.models import Assignment, Task
from backend.captures.models import Sequence
from backend.captures.service import capture_prefix, get_sequence_or_raise, solve_prefix
from backend.crowd.costs import keep_deleted
from backend.crowd.flows import expire_sequence_hits
from backend.db import session_scope
from backend.errors import Conflict, StorageError
from backend.storage import Storage, get_storage

# Assignment states that hold a worker's finished work: deleting their sequence needs force.
FINISHED_WORK = ("submitted", "approved")


@dataclass
class DeletedSequence:
    sequence_id: int
    subject: str
    name: str
    storage_uid: str
    tasks: int
    assignments: int
    finished_assignments: int


def delete_sequence_rows(session: Session, sequence_id: int, force: bool = False,
                         check_only: bool = False) -> DeletedSequence:
    """Delete a sequence's rows and everything that hangs off them (cameras, frames, objects,
    hands, tasks, assignments, HIT and QC records, solve runs: the foreign keys cascade); its
    payment ledger is first summed into crowd_deleted_costs. Its stored files are the
    caller's to remove, once this is committed. ``check_only``: raise as a delete would,
    delete nothing.

    Raises:
        NotFound: no such sequence.
        Conflict: it has submitted or approved work and ``force`` is not given.
    """
    seq = get_sequence_or_raise(session, sequence_id)
    tasks = session.scalar(select(func.count()).select_from(Task)
                           .where(Task.sequence_id == sequence_id)) or 0
    rows = session.execute(select(Assignment.status, func.count()).join(Task)
                           .where(Task.sequence_id == sequence_id)
                           .group_by(Assignment.status)).all()
    by_status: dict[str, int] = dict(rows)
    finished = sum(by_status.get(status, 0) for status in FINISHED_WORK)
    if finished and not force:
        raise Conflict(
            f"sequence {sequence_id} ({seq.subject.name}/{seq.name}) has {finished} submitted "
            f"or approved assignment(s); deleting it deletes that work too: ask again with "
            f"force (`--force`, `?force=true`) to delete it anyway")
    deleted = DeletedSequence(sequence_id, seq.subject.name, seq.name, seq.storage_uid,
                              tasks, sum(by_status.values()), finished)
    if check_only:
        return deleted
    # The payment rows go with the assignments; the money they record stays in the cost report.
    keep_deleted(session, sequence_id, f"{seq.subject.name}/{seq.name}")
    session.execute(delete(Sequence).where(Sequence.id == sequence_id)
                    .execution_options(synchronize_session=False))
    session.expunge_all()
    return deleted


@dataclass
class DeleteResult:
    sequence: DeletedSequence
    files: int


def delete_sequence(sequence_id: int, force: bool = False,
                    storage: Storage | None = None) -> DeleteResult:
    """Delete a sequence: its rows (and the work on it, with ``force``), then its stored frames,
    models, thumbnails and solve results.

    Its open HITs are expired on the marketplace first (a worker could otherwise still take
    work that has nowhere to go); a marketplace that refuses or cannot be reached stops the
    delete with its error, nothing deleted. The rows go next, in their own committed
    transaction, so nothing ever refers to a removed file; files that cannot be removed then
    are reported as a StorageError naming the prefix.
    """
    storage = storage or get_storage()
    with session_scope() as session:  # not found, or work and no force: refused before any HIT
        delete_sequence_rows(session, sequence_id, force, check_only=True)
    expire_sequence_hits(sequence_id)
    with session_scope() as session:
        deleted = delete_sequence_rows(session, sequence_id, force)
    prefixes = (capture_prefix(deleted.storage_uid),
                solve_prefix(deleted.storage_uid))
    try:
        files = sum(storage.delete_prefix(prefix) for prefix in prefixes)
    except (OSError, StorageError) as exc:
        detail = exc.detail if isinstance(exc, StorageError) else str(exc)
        raise StorageError(
            f"sequence {sequence_id} is deleted but its files under {' and '.join(prefixes)} "
            f"could not all be removed: {detail}") from exc
    return DeleteResult(deleted, files)
