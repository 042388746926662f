"""The QC job judges object landmarks for what they are: two landmarks of one object must be
distinct points of its surface. On an object nobody grasps (it stays where it was put) that is
judged against its pose at import before any solve; after a solve, against the solved poses,
on every object. Careful work (distinct points, followed) is approved."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import select

from backend.db import session_scope
from tests.backend.quality.helpers import store_solve, submit_direct

# One careful worker per view but the last, whose worker puts both landmarks on one spot.
VIEWS = 4


@pytest.fixture(scope="module")
def two_object_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """4 views x 12 frames, 320x240, two objects: the grasped one and one left on the table."""
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("landmark-points-capture")
    generate_capture(root, seed=9, frames=12, views=VIEWS, objects=2, width=320, height=240)
    return root


def _object_tasks(capture: Path) -> tuple[int, dict[str, list[tuple]], dict[str, bool]]:
    """Import the capture and create its tasks: (sequence id, {target: [(task id, serial,
    width, height), ...] in view order}, {target: grasped})."""
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.captures.models import SceneObject
    from backend.storage import get_storage

    sequence_id = import_path(capture)[0].sequence_id
    tasks: dict[str, list[tuple]] = {}
    with session_scope() as session:
        for t in create_tasks(session, get_storage(), sequence_id):
            if t.kind == "object":
                tasks.setdefault(t.target_key, []).append(
                    (t.id, t.camera.serial, t.camera.width, t.camera.height))
        grasped = {f"object:{o.index}": o.grasped for o in session.scalars(
            select(SceneObject).where(SceneObject.sequence_id == sequence_id))}
    return sequence_id, tasks, grasped


def _crowd(capture: Path, tasks: list[tuple], target: str, seed: int) -> dict[int, str]:
    """Careful workers on every view but the last, one-spot work on the last:
    {assignment id: profile}."""
    from backend.captures.truth import CaptureTruth
    from worker.synth.annotators import annotate

    truth, rng = CaptureTruth(capture), np.random.default_rng(seed)
    out = {}
    for i, (task_id, serial, width, height) in enumerate(tasks):
        xy, visible = truth.points({"kind": "object", "serial": serial, "target_key": target,
                                    "num_frames": 12}, rng)
        profile = "same_spot" if i == len(tasks) - 1 else "careful"
        work = annotate(xy, visible, (width, height), profile, rng)
        out[submit_direct(task_id, f"{profile}-{target}-{i}", work.tracks)] = profile
    return out


def _reports(profile_of: dict[int, str]) -> dict[int, object]:
    from backend.quality.models import QCReport

    with session_scope() as session:
        rows = session.scalars(select(QCReport).where(QCReport.assignment_id.in_(profile_of)))
        return {r.assignment_id: (r.outcome, r.metrics, list(r.reasons), r.feedback)
                for r in rows}


def test_qc_rejects_two_landmarks_on_one_spot_of_a_static_object_before_any_solve(
        market_env: dict[str, str], two_object_capture: Path) -> None:
    from backend.quality.flows import run_qc

    sequence_id, tasks, grasped = _object_tasks(two_object_capture)
    static = next(target for target, moves in grasped.items() if not moves)
    profile_of = _crowd(two_object_capture, tasks[static], static, seed=4)

    run_qc(sequence_id, static)

    reports = _reports(profile_of)
    assert set(reports) == set(profile_of)
    for assignment_id, profile in profile_of.items():
        outcome, metrics, reasons, feedback = reports[assignment_id]
        # Judged against the pose given at import: no solve run behind it.
        assert metrics["solve_run"] is None and metrics["anchored_median_px"] is not None
        if profile == "careful":
            assert outcome == "approve", reasons
            assert metrics["landmark_separation_mm"] > 20.0
        else:
            # Both landmarks follow the (unmoving) object perfectly well: only their
            # separation on its surface tells them apart from careful work.
            assert metrics["anchored_median_px"] < 4.0
            assert metrics["landmark_separation_mm"] < 8.0
            assert outcome == "reject", (metrics, reasons)
            assert any(r.startswith("landmark_separation_mm") for r in reasons), reasons
            assert "distinct points" in feedback


def test_after_a_solve_one_spot_is_rejected_on_every_object(
        market_env: dict[str, str], two_object_capture: Path) -> None:
    from backend.captures.truth import CaptureTruth
    from backend.quality.flows import run_qc

    sequence_id, tasks, _ = _object_tasks(two_object_capture)
    profile_of: dict[str, dict[int, str]] = {
        target: _crowd(two_object_capture, rows, target, seed=5 + i)
        for i, (target, rows) in enumerate(sorted(tasks.items()))}
    run_id = store_solve(sequence_id, CaptureTruth(two_object_capture).object_poses())

    for target in sorted(tasks):
        run_qc(sequence_id, target)
        for outcome, metrics, reasons, _ in (
                r for a, r in _reports(profile_of[target]).items()
                if profile_of[target][a] == "same_spot"):
            assert metrics["solve_run"] == run_id
            assert outcome == "reject", (target, metrics, reasons)
