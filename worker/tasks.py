"""The job handlers: the only bridge between the pure worker packages and the database.

Every job is a row of the job table (backend.jobs) whose kind names one handler here; each
takes ids, is idempotent (it overwrites what an earlier attempt wrote) and is retried with
backoff when it fails. The stage jobs (confirm, QC, solve) run through backend.pipeline.
A command that runs jobs (serve, worker, demo, a ``--now``/``--wait`` command, the tests)
calls :func:`register_handlers` once before it runs any.
"""

from __future__ import annotations

from typing import Any

from backend import pipeline
from backend.captures.flows import FRAME_STATS, compute_frame_stats
from backend.exports.flows import cleanup_job, export_job
from backend.exports.stored import CLEANUP_KIND
from backend.jobs.runner import Handler
from backend.jobs.runner import register_handlers as register
from backend.labels.model_follow import MODEL_FOLLOW_KIND, compute_model_follow
from backend.labels.suggestions import FITTED_KIND, compute_fitted
from backend.rig.flows import run_rig_health


def frame_stats(args: dict[str, Any]) -> dict[str, Any]:
    """Statistics and a thumbnail for every frame of a sequence."""
    return compute_frame_stats(int(args["sequence_id"]))


def quality_check(args: dict[str, Any]) -> dict[str, Any]:
    """Score one target of a sequence, act on the decisions, then ask for the solve."""
    return pipeline.run_qc(int(args["sequence_id"]), str(args["target_key"]))


def confirm_submission(args: dict[str, Any]) -> dict[str, Any]:
    """The page said an assignment was submitted: check it with the requester API, then QC."""
    return pipeline.confirm(int(args["assignment_id"]))


def solve_run(args: dict[str, Any]) -> dict[str, Any]:
    """Solve run ``args["run_id"]`` of a sequence and store its outputs (idempotent); a done
    run queues the landmark QC of its objects."""
    result = pipeline.run_solve(int(args["run_id"]))
    outcome = f"failed: {result['error']}" if result.get("error") else "done"
    return {**result, "message": f"solve run {result['run_id']} {outcome}"}


def publish_views(args: dict[str, Any]) -> dict[str, Any]:
    """After a solve of an adaptively published sequence: publish the views its weak frames
    need, with the reason (backend.crowd.adaptive); after a QC that could not decide for want
    of views (``sequence_id`` and ``target_key`` instead of ``run_id``): one more view."""
    if "run_id" not in args:
        return pipeline.publish_views_to_compare(int(args["sequence_id"]),
                                                 str(args["target_key"]))
    return pipeline.publish_views(int(args["run_id"]))


def rig_health(args: dict[str, Any]) -> dict[str, Any]:
    """Estimate a sequence's rig from its accepted labels; store a new calibration version."""
    return run_rig_health(int(args["sequence_id"]))


def export_labels(args: dict[str, Any]) -> dict[str, Any]:
    """Write an export's archive to storage (backend.exports), progress on the job's row."""
    return export_job(args)


def fitted_suggestions(args: dict[str, Any]) -> dict[str, Any]:
    """Fit a target's model to the accepted work of one or two views; store the suggestions
    of one view (backend.labels.suggestions)."""
    return compute_fitted(int(args["task_id"]), int(args["first_frame"]),
                          int(args["last_frame"]))


def model_follow(args: dict[str, Any]) -> dict[str, Any]:
    """Follow the hand model from a worker's keyframes through one view's depth; store the
    proposals (backend.labels.model_follow)."""
    begin = args.get("begin")
    return compute_model_follow(int(args["task_id"]), args["tracks"],
                                None if begin is None else int(begin))


def clean_up_exports(args: dict[str, Any]) -> dict[str, Any]:
    """Delete export archives past DEXLABEL_EXPORT_RETENTION_DAYS."""
    return cleanup_job(args)


# No lease of its own for the solve: the heartbeat renews a long solve's lease
# (DEXLABEL_JOB_LEASE_S) while it works, so the lease only bounds how soon a killed worker's
# solve is taken over.
HANDLERS: dict[str, Handler] = {
    FRAME_STATS: Handler(frame_stats, None),
    "qc": Handler(quality_check, None),
    pipeline.CONFIRM: Handler(confirm_submission, None),
    "solve": Handler(solve_run, None),
    pipeline.PUBLISH_VIEWS: Handler(publish_views, None),
    "rig_health": Handler(rig_health, None),
    "export": Handler(export_labels, None),
    CLEANUP_KIND: Handler(clean_up_exports, None),
    FITTED_KIND: Handler(fitted_suggestions, None),
    MODEL_FOLLOW_KIND: Handler(model_follow, None),
}


def register_handlers() -> None:
    """Register every job handler in this process (idempotent)."""
    register(HANDLERS)
