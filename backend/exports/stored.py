"""Export archives in the instance's storage (a local folder, or S3 on a scale-out), never on
one host's disk: the export job writes its archive to a scratch file on the host that runs it
and stores it under ``exports/export-<id>.<zip|tar>``; any API host streams it from there.

An archive is kept DEXLABEL_EXPORT_RETENTION_DAYS after its export finished; the clean-up job
(queued every hour by the queue consumers) deletes older ones, marking their exports
``deleted_at`` (a download then answers 410), and archives no export row names any more (its
row deleted, or an attempt that lost its job). Deleting an export deletes its row, and its
archive once that commits.
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.config import get_settings
from backend.db import session_scope
from backend.errors import Conflict, DexlabelError, NotFound
from backend.exports.service import JOB_KIND, get_export_or_raise
from backend.jobs.models import Job
from backend.jobs.runner import ACTIVE
from backend.queue import enqueue_after_commit
from backend.storage import get_storage

log = logging.getLogger(__name__)

PREFIX = "exports"
CLEANUP_KIND = "export_cleanup"
MEDIA_TYPES = {"zip": "application/zip", "tar": "application/x-tar"}


class ArchiveGone(DexlabelError, status_code=410, code="archive_gone"):
    """The export finished, but its archive has since been deleted."""


@dataclass(frozen=True)
class StoredArchive:
    """A finished export's archive: its storage key, the file name a download gets, its type."""

    key: str
    filename: str
    media_type: str


def archive_name(export_id: int, archive: str) -> str:
    return f"export-{export_id:06d}.{archive}"


def archive_key(export_id: int, archive: str) -> str:
    return f"{PREFIX}/{archive_name(export_id, archive)}"


@contextmanager
def scratch_file(export_id: int, archive: str) -> Iterator[Path]:
    """A path in a scratch folder of this host to write the archive to; the folder and what
    is in it are removed on the way out, stored or not."""
    with tempfile.TemporaryDirectory(prefix="dexlabel-export-") as folder:
        yield Path(folder) / archive_name(export_id, archive)


def store_archive(export_id: int, archive: str, path: Path) -> str:
    """Put the written archive into storage; its key."""
    key = archive_key(export_id, archive)
    get_storage().put_file(key, path, MEDIA_TYPES[archive])
    return key


def finished_archive(session: Session, export_id: int) -> StoredArchive:
    """The stored archive of a finished export; 409 while it runs or when it failed, 410 once
    its archive was deleted."""
    job = get_export_or_raise(session, export_id)
    result = job.result or {}
    if job.status == "done" and result.get("deleted_at"):
        raise ArchiveGone(f"the archive of export {export_id} was deleted on "
                          f"{result['deleted_at'][:10]} (archives are kept "
                          f"{get_settings().export_retention_days:g} days, "
                          "DEXLABEL_EXPORT_RETENTION_DAYS); run the export again")
    key = result.get("key")
    if job.status == "done" and not isinstance(key, str):
        raise ArchiveGone(f"export {export_id} finished before archives were kept in storage; "
                          "run the export again")
    if job.status != "done" or not isinstance(key, str):
        raise Conflict(f"export {export_id} is {job.status}; its archive can be downloaded "
                       "once it is done", state=job.status)
    archive = str((job.args or {}).get("archive", "zip"))
    return StoredArchive(key, f"dexlabel-{archive_name(export_id, archive)}",
                         MEDIA_TYPES.get(archive, "application/octet-stream"))


def open_archive(archive: StoredArchive, export_id: int) -> tuple[int, Iterator[bytes]]:
    """The archive's size and bytes, streamed from storage; 410 when it is not there."""
    try:
        return get_storage().open_stream(archive.key)
    except NotFound:
        raise ArchiveGone(f"the archive of export {export_id} is no longer in storage; run "
                          "the export again") from None


def delete_export(session: Session, export_id: int) -> None:
    """Delete an export's row, and its archive once this unit of work commits (an archive
    whose deletion fails then is removed by the next clean-up). 409 while it runs."""
    job = get_export_or_raise(session, export_id)
    if job.status == "running":
        raise Conflict(f"export {export_id} is running; delete it once it has ended",
                       state=job.status)
    key = (job.result or {}).get("key")
    session.delete(job)
    session.flush()
    if isinstance(key, str):
        enqueue_after_commit(session, _delete_key, key)


def _delete_key(key: str) -> None:
    get_storage().delete_prefix(key)


def clean_up_archives(now: datetime | None = None) -> dict[str, Any]:
    """Delete the archives older than the retention (their exports marked ``deleted_at``)
    and those no export names; counts for the job's result. No transaction is open while
    storage is called."""
    days = get_settings().export_retention_days
    if days <= 0:
        return {"deleted": 0, "message": "archives are kept (DEXLABEL_EXPORT_RETENTION_DAYS=0)"}
    now = now or datetime.now(UTC)
    cutoff = now - timedelta(days=days)
    with session_scope() as session:
        rows = list(session.execute(select(Job.id, Job.status, Job.args, Job.result,
                                           Job.finished_at).where(Job.kind == JOB_KIND)))
    expired: dict[int, str] = {}
    kept: set[str] = set()
    for row in rows:
        result = row.result or {}
        archive = str((row.args or {}).get("archive", "zip"))
        if row.status in ACTIVE:
            kept.add(archive_key(row.id, archive))  # an attempt may be storing it now
        elif row.status == "done" and isinstance(result.get("key"), str) \
                and not result.get("deleted_at"):
            if row.finished_at is not None and row.finished_at < cutoff:
                expired[row.id] = result["key"]
            else:
                kept.add(result["key"])
    storage = get_storage()
    for key in expired.values():
        storage.delete_prefix(key)
    orphans = [obj.key for obj in storage.list_prefix(PREFIX)
               if obj.key not in kept and obj.key not in expired.values()
               and obj.modified < cutoff]
    for key in orphans:
        storage.delete_prefix(key)
    if expired:
        _mark_deleted(expired, now)
    deleted = len(expired) + len(orphans)
    return {"deleted": deleted, "expired_exports": sorted(expired), "orphans": len(orphans),
            "message": f"deleted {deleted} export archive(s) older than {days:g} days"}


def _mark_deleted(expired: dict[int, str], now: datetime) -> None:
    with session_scope() as session:
        for job in session.scalars(select(Job).where(Job.id.in_(expired))):
            if (job.result or {}).get("key") == expired[job.id]:
                job.result = {**(job.result or {}), "key": None,
                              "deleted_at": now.isoformat(timespec="seconds")}
