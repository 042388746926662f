"""Landmark QC after the solve: a finished solve run queues the QC of every object target, and
each worker's landmarks are then checked against the solved objects (reprojection of the
anchored surface point, visibility against the meshes and depth)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.quality.helpers import store_solve, submit_direct


def test_a_finished_solve_checks_each_workers_landmarks_against_the_solved_object(
        market_env: dict[str, str], qc_capture: Path) -> None:
    from backend.annotation.models import Task
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.captures.truth import CaptureTruth
    from backend.jobs.models import Job
    from backend.jobs.runner import execute
    from backend.pipeline import run_solve
    from backend.quality.models import QCReport
    from backend.storage import get_storage
    from worker.synth.annotators import annotate

    sequence_id = import_path(qc_capture)[0].sequence_id
    with session_scope() as session:
        tasks = [(t.id, t.camera.serial, t.target_key, t.camera.width, t.camera.height)
                 for t in create_tasks(session, get_storage(), sequence_id)
                 if t.kind == "object"]
    truth, rng = CaptureTruth(qc_capture), np.random.default_rng(3)
    profile_of = {}
    for i, (task_id, serial, target, width, height) in enumerate(tasks):
        xy, visible = truth.points({"kind": "object", "serial": serial, "target_key": target,
                                    "num_frames": 16}, rng)
        profile = ("careful", "occluder", "spammer")[i % 3]
        work = annotate(xy, visible, (width, height), profile, rng)
        profile_of[submit_direct(task_id, f"w{i}", work.tracks)] = profile
    run_id = store_solve(sequence_id, truth.object_poses())

    result = run_solve(run_id)  # the run is done: the job only queues the landmark QC
    assert result["landmark_qc"] == 1
    with session_scope() as session:
        keys = list(session.scalars(select(Job.key).where(Job.kind == "qc",
                                                          Job.status == "queued")))
        assert keys == [f"qc:{sequence_id}:object:0"]
    for key in keys:
        execute(key)

    with session_scope() as session:
        reports = {r.assignment_id: r for r in session.scalars(select(QCReport))}
        assert set(reports) == set(profile_of)
        for assignment_id, profile in profile_of.items():
            report = reports[assignment_id]
            assert report.metrics["solve_run"] == run_id
            if profile == "careful":
                assert report.outcome == "approve", report.reasons
                assert report.metrics["anchored_median_px"] < 3.0
            else:
                assert report.outcome != "approve", (profile, report.metrics)
        assert session.scalar(select(Task.id).where(Task.sequence_id == sequence_id))
