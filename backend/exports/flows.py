"""The bodies of the export jobs. ``export``: write the archive to a scratch file of this host,
then store it in the instance's storage (backend.exports.stored), recording progress on the
job's row; a retry starts again from nothing and stores over what an earlier attempt stored.
``export_cleanup``: delete archives past their retention, queued every hour by the consumers.
"""

from __future__ import annotations

from typing import Any

from huey import crontab

from backend.db import session_scope
from backend.exports import stored
from backend.exports.service import run_export
from backend.jobs.runner import check_lease, current_job_id, report_progress
from backend.jobs.service import enqueue_job
from backend.queue import huey


def export_job(args: dict[str, Any]) -> dict[str, Any]:
    job_id = current_job_id()
    archive = str(args.get("archive", "zip"))
    report_progress(0, 0, "starting")
    with stored.scratch_file(job_id, archive) as out:
        result = run_export(str(args["format"]), [int(i) for i in args["sequence_ids"]],
                            str(args["include"]), dict(args.get("options") or {}), out,
                            lambda done, total: report_progress(done, total, "writing"))
        check_lease()  # an attempt that lost its job leaves the storing to the newer one
        report_progress(result["sequences"], result["sequences"], "storing")
        key = stored.store_archive(job_id, archive, out)
    report_progress(result["sequences"], result["sequences"], "done")
    result = {k: v for k, v in result.items() if k != "path"}
    return {**result, "key": key,
            "message": f"{args['format']} export of {result['sequences']} sequence(s): "
                       f"{result['frames']} frames, {result['bytes'] / 1e6:.1f} MB"}


def cleanup_job(args: dict[str, Any]) -> dict[str, Any]:
    return stored.clean_up_archives()


def queue_cleanup() -> None:
    """Queue the clean-up job (one at a time: its key is fixed)."""
    with session_scope() as session:
        enqueue_job(session, stored.CLEANUP_KIND, stored.CLEANUP_KIND, {})


@huey.periodic_task(crontab(minute="7"))
def clean_up_exports_hourly() -> None:
    """Every hour, in every consumer: queue the clean-up (a queued one is not queued twice)."""
    queue_cleanup()
