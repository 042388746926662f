"""The body of the ``export`` job: write the archive under a temporary name, then move it into
place, recording progress on the job's row. A retry starts again from nothing."""

from __future__ import annotations

from typing import Any

from backend.exports.service import archive_path, run_export
from backend.jobs.runner import current_job_id, report_progress


def export_job(args: dict[str, Any]) -> dict[str, Any]:
    job_id = current_job_id()
    out = archive_path(job_id, str(args.get("archive", "zip")))
    out.unlink(missing_ok=True)  # an earlier attempt that finished but was not recorded
    report_progress(0, 0, "starting")
    result = run_export(str(args["format"]), [int(i) for i in args["sequence_ids"]],
                        str(args["include"]), dict(args.get("options") or {}), out,
                        lambda done, total: report_progress(done, total, "writing"))
    report_progress(result["sequences"], result["sequences"], "done")
    return {**result, "message": f"{args['format']} export of {result['sequences']} "
                                 f"sequence(s): {result['frames']} frames, "
                                 f"{result['bytes'] / 1e6:.1f} MB"}
