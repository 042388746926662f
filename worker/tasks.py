"""Queue tasks: the only bridge between the pure worker packages and the database.

Every task takes ids, is idempotent (it overwrites what an earlier attempt wrote) and is retried
with a delay when it fails.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np
from sqlalchemy import select

from huey import crontab

from backend.captures.models import Camera, Frame
from backend.db import session_scope
from backend.jobs.service import job_handler, requeue_stale
from backend.queue import huey
from backend.storage import get_storage
from worker.quality.frame_stats import frame_statistics, thumbnail_jpeg

log = logging.getLogger(__name__)


@huey.task(retries=3, retry_delay=10)
def compute_frame_stats(sequence_id: int) -> int:
    """Statistics and a thumbnail for every frame of a sequence; returns frames processed."""
    storage = get_storage()
    with session_scope() as session:
        stmt = (select(Frame).join(Camera).where(Camera.sequence_id == sequence_id)
                .order_by(Camera.view_index, Frame.index))
        frames = list(session.scalars(stmt))
        for frame in frames:
            color = cv2.imdecode(np.frombuffer(storage.get_bytes(frame.color_key), np.uint8),
                                 cv2.IMREAD_COLOR)
            depth = None
            if frame.depth_key:
                depth = cv2.imdecode(np.frombuffer(storage.get_bytes(frame.depth_key), np.uint8),
                                     cv2.IMREAD_UNCHANGED)
            thumb_key = frame.color_key.rsplit("/", 1)[0] + f"/thumb_{frame.index:06d}.jpg"
            storage.put_bytes(thumb_key, thumbnail_jpeg(color), "image/jpeg")
            frame.stats = frame_statistics(color, depth)
            frame.thumb_key = thumb_key
    log.info("frame statistics for sequence %d: %d frames", sequence_id, len(frames))
    return len(frames)


@huey.periodic_task(crontab(minute="*"))
def reap_jobs() -> None:
    """Every minute: re-queue jobs whose worker died or whose queue message was lost."""
    requeue_stale()


@job_handler("qc")
def quality_check(args: dict) -> dict:
    """Score one target of a sequence and act on the decisions (backend.quality.flows)."""
    from backend.quality.flows import run_qc

    return run_qc(int(args["sequence_id"]), str(args["target_key"]))


@job_handler("confirm")
def confirm_submission(args: dict) -> dict:
    """The page said an assignment was submitted: check it with the requester API, then QC."""
    from backend.crowd.confirm import confirm

    return confirm(int(args["assignment_id"]))


# --- solve (issue 6): the "solve" job fits MANO hand and 6D object poses of one run --------


@job_handler("solve", lease_s=3600)
def solve_run(args: dict) -> dict:
    """Solve run ``args["run_id"]`` of a sequence and store its outputs (idempotent)."""
    from backend.solve.flows import run_solve

    return run_solve(int(args["run_id"]))
