"""Import as a whole unit of work: plan, copy, commit, then enqueue the frame-statistics job.

Every sequence is its own transaction. If anything fails (a bad file, storage, the commit),
the sequence's rows are rolled back and its files removed, so no partial sequence survives.
"""

from __future__ import annotations

from pathlib import Path

from backend.captures import layout, service
from backend.db import session_scope
from backend.jobs.service import enqueue_job
from backend.storage import Storage, get_storage

# The job kind of a sequence's frame statistics and thumbnails (worker.tasks runs it).
FRAME_STATS = "frame_stats"


def import_path(path: str | Path, storage: Storage | None = None) -> list[service.ImportResult]:
    """Import every sequence under ``path`` (a capture root or one sequence folder).

    All sequences are parsed and checked before the first one is written.
    """
    storage = storage or get_storage()
    plans = [layout.read_sequence(d) for d in layout.find_sequence_dirs(Path(path))]
    results = []
    for plan in plans:
        prefix = f"captures/{service.storage_uid(plan.subject, plan.name)}"
        created = False
        try:
            with session_scope() as session:
                result = service.import_sequence(session, storage, plan)
                created = result.created
                if created:
                    enqueue_job(session, FRAME_STATS, f"{FRAME_STATS}:{result.sequence_id}",
                                {"sequence_id": result.sequence_id})
        except BaseException:
            if created:
                storage.delete_prefix(prefix)
            raise
        results.append(result)
    return results
