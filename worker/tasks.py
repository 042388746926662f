"""Queue tasks: the only bridge between the pure worker packages and the database.

Every job is a row of the job table (backend.jobs) whose handler is registered here; each takes
ids, is idempotent (it overwrites what an earlier attempt wrote) and is retried with backoff
when it fails. The stage jobs (confirm, QC) run through backend.pipeline.
"""

from __future__ import annotations

import logging
from typing import Any

import cv2
import numpy as np
from huey import crontab
from sqlalchemy import select

from backend import pipeline
from backend.captures.flows import FRAME_STATS
from backend.captures.models import Camera, Frame
from backend.db import session_scope
from backend.exports.flows import export_job
from backend.jobs.service import job_handler, requeue_stale
from backend.queue import huey, queue_lost_messages
from backend.rig.flows import run_rig_health
from backend.storage import get_storage
from worker.quality.frame_stats import frame_statistics, thumbnail_jpeg

log = logging.getLogger(__name__)


@job_handler(FRAME_STATS)
def compute_frame_stats(args: dict[str, Any]) -> dict[str, Any]:
    """Statistics and a thumbnail for every frame of a sequence."""
    sequence_id = int(args["sequence_id"])
    storage = get_storage()
    with session_scope() as session:
        stmt = (select(Frame).join(Camera).where(Camera.sequence_id == sequence_id)
                .order_by(Camera.view_index, Frame.index))
        frames = list(session.scalars(stmt))
        for frame in frames:
            color = cv2.imdecode(np.frombuffer(storage.get_bytes(frame.color_key), np.uint8),
                                 cv2.IMREAD_COLOR)
            if color is None:
                raise ValueError(f"{frame.color_key}: not a decodable colour image")
            depth = None
            if frame.depth_key:
                depth = cv2.imdecode(np.frombuffer(storage.get_bytes(frame.depth_key), np.uint8),
                                     cv2.IMREAD_UNCHANGED)
            thumb_key = frame.color_key.rsplit("/", 1)[0] + f"/thumb_{frame.index:06d}.jpg"
            storage.put_bytes(thumb_key, thumbnail_jpeg(color), "image/jpeg")
            frame.stats = frame_statistics(color, depth)
            frame.thumb_key = thumb_key
    log.info("frame statistics for sequence %d: %d frames", sequence_id, len(frames))
    return {"frames": len(frames),
            "message": f"{len(frames)} frames of sequence {sequence_id}: statistics and "
                       "thumbnails"}


@huey.periodic_task(crontab(minute="*"))
def reap_jobs() -> None:
    """Every minute: re-queue jobs whose worker died or whose queue message was lost (all of
    them at once when the queue's store lost its messages, e.g. a Redis restarted empty)."""
    requeue_stale(queue_reset=queue_lost_messages())


@job_handler("qc")
def quality_check(args: dict[str, Any]) -> dict[str, Any]:
    """Score one target of a sequence, act on the decisions, then ask for the solve."""
    return pipeline.run_qc(int(args["sequence_id"]), str(args["target_key"]))


@job_handler(pipeline.CONFIRM)
def confirm_submission(args: dict[str, Any]) -> dict[str, Any]:
    """The page said an assignment was submitted: check it with the requester API, then QC."""
    return pipeline.confirm(int(args["assignment_id"]))


# No lease of its own: the heartbeat renews a long solve's lease (DEXLABEL_JOB_LEASE_S) while
# it works, so the lease only bounds how soon a killed worker's solve is taken over.
@job_handler("solve")
def solve_run(args: dict[str, Any]) -> dict[str, Any]:
    """Solve run ``args["run_id"]`` of a sequence and store its outputs (idempotent); a done
    run queues the landmark QC of its objects."""
    result = pipeline.run_solve(int(args["run_id"]))
    outcome = f"failed: {result['error']}" if result.get("error") else "done"
    return {**result, "message": f"solve run {result['run_id']} {outcome}"}


@job_handler("rig_health")
def rig_health(args: dict[str, Any]) -> dict[str, Any]:
    """Estimate a sequence's rig from its accepted labels; store a new calibration version."""
    return run_rig_health(int(args["sequence_id"]))


@job_handler("export")
def export_labels(args: dict[str, Any]) -> dict[str, Any]:
    """Write an export's archive (backend.exports), progress on the job's row."""
    return export_job(args)
