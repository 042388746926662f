"""The assisted simulated crowd against the served app: workers who ask the proposals and
suggestions routes as the annotation page does spend fewer actions than the keyframe worker on
the same tasks, with labels near the truth; a blind acceptor's work is flagged by QC.

The app is served without a queue worker, so the crowd here does not ask for the hand model's
follow (a job; tests/backend/labels/test_model_follow.py takes that path)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select

from backend.config import get_settings
from backend.crowd.simulate import simulate
from backend.db import session_scope
from tests.backend.quality.helpers import ADMIN_EMAIL, ADMIN_PASSWORD, publish_hand_tasks
from worker.assist.checks import check_cells, check_key
from worker.synth.assisted import TOLERANCE_PX, plain_rows
from worker.tracks.interpolate import dense_points

# Long enough that a keyframe every 4 frames costs more than one click per point and the page's
# tracking: the 6-frame small capture is keyed on 3 of its 6 frames.
FRAMES, VIEWS = 20, 4


@pytest.fixture(scope="module")
def assist_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("assist-capture")
    generate_capture(root, seed=13, frames=FRAMES, views=VIEWS, objects=1, workers=1)
    return root


def _publish_hands(capture: Path) -> tuple[int, list[int], list[str]]:
    """One HIT per hand task of the capture (tests.backend.quality.helpers); (sequence id,
    hand task ids, HIT ids)."""
    from backend.annotation.models import Task

    sequence_id, hit_ids = publish_hand_tasks(capture, max_assignments=1)
    with session_scope() as session:
        task_ids = list(session.scalars(select(Task.id).where(
            Task.sequence_id == sequence_id, Task.kind == "hand").order_by(Task.id)))
    return sequence_id, task_ids, hit_ids


def _submitted(worker_ids: list[str]) -> dict[str, tuple[int, int, list]]:
    """worker id -> (task id, edit count, tracks) of its assignment."""
    from backend.annotation.models import Assignment

    with session_scope() as session:
        rows = session.scalars(select(Assignment).where(Assignment.worker_id.in_(worker_ids)))
        return {a.worker_id: (a.task_id, a.edit_count,
                              [t.keyframes for t in sorted(a.tracks,
                                                           key=lambda t: t.point_index)])
                for a in rows}


def test_assisted_workers_spend_fewer_actions_with_labels_near_the_truth(
        crowd_url: str, assist_capture: Path) -> None:
    from backend.annotation.models import Task
    from backend.captures.truth import CaptureTruth
    from backend.crowd.actions import add_assignments

    _, task_ids, hit_ids = _publish_hands(assist_capture)
    plain = simulate(crowd_url, assist_capture, VIEWS, "careful", ADMIN_EMAIL, ADMIN_PASSWORD)
    for hit_id in hit_ids:  # each task once more, for the assisted crowd
        with session_scope() as session:
            add_assignments(session, None, hit_id, 1)
    helped = simulate(crowd_url, assist_capture, VIEWS, "careful", ADMIN_EMAIL, ADMIN_PASSWORD,
                      first_index=VIEWS + 1, protocol="assisted", model_follow=False)
    assert [o.status for o in plain + helped] == ["submitted"] * 2 * VIEWS
    keyed = {w[0]: w[1] for w in _submitted([o.worker_id for o in plain]).values()}
    done = _submitted([o.worker_id for o in helped])
    assert sorted(w[0] for w in done.values()) == sorted(task_ids)

    truth = CaptureTruth(assist_capture)
    errors = []
    for task_id, edits, tracks in done.values():
        # The same task keyed by hand cost more edit actions than with the page's help.
        assert 0 < edits < keyed[task_id], (edits, keyed[task_id])
        with session_scope() as session:
            task = session.get_one(Task, task_id)
            serial, frames = task.camera.serial, task.sequence.num_frames
        joint_2d, _ = truth.view(serial, frames)
        xy, visible = dense_points(((p, plain_rows(rows)) for p, rows in enumerate(tracks)),
                                   frames, 21)
        err = np.linalg.norm(xy - joint_2d, axis=2)[visible]
        errors.append(err[np.isfinite(err)])
        # Proposals came from the routes: accepted "tracked" keyframes are saved as such.
        assert any(len(r) > 4 and r[4] == "tracked" for rows in tracks for r in rows)
    median = float(np.median(np.concatenate(errors)))
    assert median < TOLERANCE_PX / 2, median


def test_a_blind_assisted_acceptor_is_flagged_by_qc(crowd_url: str,
                                                     assist_capture: Path) -> None:
    from backend.annotation.models import Task
    from backend.pipeline import sync
    from backend.quality.flows import run_qc
    from backend.quality.models import QCReport

    sequence_id, task_ids, _ = _publish_hands(assist_capture)
    blind = simulate(crowd_url, assist_capture, 1, "blind", ADMIN_EMAIL, ADMIN_PASSWORD,
                     protocol="assisted", model_follow=False)
    careful = simulate(crowd_url, assist_capture, VIEWS - 1, "careful", ADMIN_EMAIL,
                       ADMIN_PASSWORD, first_index=2, protocol="assisted", model_follow=False)
    assert [o.status for o in careful + blind] == ["submitted"] * VIEWS
    with session_scope() as session:
        target = session.get_one(Task, task_ids[0]).target_key
        sync(session)  # the marketplace's confirmations: the work takes part in QC
    run_qc(sequence_id, target)
    profile_of = {o.worker_id: o.profile for o in careful + blind}
    with session_scope() as session:
        reports = session.execute(select(QCReport.worker_id, QCReport.assignment_id,
                                         QCReport.outcome, QCReport.metrics, QCReport.reasons)
                                  .where(QCReport.sequence_id == sequence_id)).all()
    assert {r.worker_id for r in reports} == set(profile_of)
    tracks = _submitted(list(profile_of))
    key = check_key(get_settings().signing_key)
    for worker, assignment_id, outcome, metrics, reasons in reports:
        if profile_of[worker] == "careful":
            # Every check cell it was shown it moved back onto the point.
            assert outcome == "approve" and metrics["checks_accepted"] == 0, (metrics, reasons)
            continue
        # The blind acceptor kept every proposal as shown, the check cells among them (4 cells
        # drawn; tracking holds on some frames only), and is flagged.
        rows = tracks[worker][2]
        shown = sum(any(len(r) > 4 and r[0] == f and r[4] == "tracked" for r in rows[p])
                    for p, f in check_cells(key, assignment_id, 21, FRAMES))
        assert metrics["checks_accepted"] == shown
        assert outcome in ("review", "reject"), reasons
