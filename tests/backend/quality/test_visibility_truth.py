"""The product's QC (backend.quality.service.score_target: stored tracks, depth maps read from
storage) judges hand visibility flags as the synthetic ground truth does: careful workers, whose
flags are the truth's (worker.synth.annotators.hand_visibility), hardly disagree with the depth
map; workers who mark joints occluded for long spans disagree as much as they do with the
truth, and are caught."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.quality.helpers import submit_direct


def test_hand_visibility_metrics_follow_the_true_flags(app_env: dict,
                                                       visibility_capture: Path) -> None:
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.captures.truth import CaptureTruth
    from backend.quality.models import QCReport
    from backend.quality.service import score_target
    from backend.storage import get_storage
    from worker.synth.annotators import annotate
    from worker.tracks.interpolate import dense_track

    sequence_id = import_path(visibility_capture)[0].sequence_id
    with session_scope() as session:
        tasks = [{"id": t.id, "kind": t.kind, "serial": t.camera.serial, "num_frames": 72,
                  "target_key": t.target_key, "size": (t.camera.width, t.camera.height)}
                 for t in create_tasks(session, get_storage(), sequence_id)
                 if t.kind == "hand"]
    truth, rng = CaptureTruth(visibility_capture), np.random.default_rng(4)
    profile_of, true_disagreement = {}, {}
    for task in tasks:
        xy, visible = truth.points(task, rng)
        for profile in ("careful", "occluder"):
            work = annotate(xy, visible, task["size"], profile, rng)
            flags = np.stack([dense_track(t, 72).visible for t in work.tracks], axis=1)
            aid = submit_direct(task["id"], f"{profile}-{task['serial']}", work.tracks)
            profile_of[aid] = profile
            true_disagreement[aid] = float((flags != visible).mean())

    with session_scope() as session:
        score_target(session, sequence_id, "hand:0")
    with session_scope() as session:
        reports = {r.assignment_id: r for r in session.scalars(select(QCReport))}
    assert set(reports) == set(profile_of)
    careful = [reports[a].metrics for a, p in profile_of.items() if p == "careful"]
    for aid, profile in profile_of.items():
        metrics, true = reports[aid].metrics, true_disagreement[aid]
        if profile == "careful":
            assert true == 0.0
            assert metrics["visibility_disagreement"] < 0.06, metrics
            assert metrics["occluded_on_surface"] < 0.02, metrics
        else:
            assert true > 0.4 and reports[aid].outcome != "approve", reports[aid].reasons
            assert metrics["visibility_disagreement"] == pytest.approx(true, abs=0.08), metrics
            assert metrics["occluded_on_surface"] > 0.4, metrics
    assert np.median([m["visibility_disagreement"] for m in careful]) < 0.03
    covered = [m["visible_behind_surface"] for m in careful
               if m["visible_behind_surface"] is not None]
    assert covered and np.median(covered) < 0.5
