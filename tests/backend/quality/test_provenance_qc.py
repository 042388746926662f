"""The QC job honest with suggestions: saved keyframe rows carry their source, and the job
counts each assignment's check suggestions (worker.assist.checks) kept unchanged.

A synthetic capture (6 views x 16 frames) where three views are labelled by hand (4-element
rows, as before suggestions existed) and three from suggestions: a careful worker who dragged
every check suggestion back onto the point ("edited"), a blind one who accepted the tracking
proposals and pre-fill as shown ("tracked"/"prefilled", 15 px off at the check cells), and one
who sent the whole pre-fill unchanged. The real QC job scores them together and the admin API
shows the verdicts, the counts and the reasons.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient
from sqlalchemy import select

from backend.annotation.points import point_names
from backend.db import session_scope
from tests.backend.quality.helpers import submit_direct
from worker.quality.feedback import kept_checks_sentence

HAND_NAMES = point_names("hand")

ADMIN = ("provenance-admin@example.org", "correct horse battery")
BLIND_REASON = ("accepted 4 of 4 check suggestions unchanged (each shown 15 px off the point): "
                "suggestions were accepted without looking")
DECIDED_NOTHING = "decided nothing: every position came from suggestions unchanged"


def _assisted_rows(base: list[list], truth_xy: np.ndarray, truth_visible: np.ndarray,
                   cells: dict[int, tuple[float, float]], at_cell: str, elsewhere: str,
                   rng: np.random.Generator) -> list[list]:
    """One point's keyframe rows from suggestions: the worker's keyframes, inner ones with
    source ``elsewhere`` (the first and last frame keyed by hand, unless the whole pre-fill
    was kept), and at each check cell frame a keyframe with source ``at_cell``: the check
    suggestion where it was kept, the point (careful noise) where it was dragged back
    ("edited")."""
    by_hand = (0, truth_xy.shape[0] - 1) if elsewhere != "prefilled" else ()
    rows = {r[0]: list(r[:4]) + ([] if r[0] in by_hand else [elsewhere]) for r in base}
    for frame, shown in cells.items():
        x, y = shown if at_cell != "edited" \
            else truth_xy[frame] + rng.normal(0.0, 1.0, 2)
        rows[frame] = [frame, float(x), float(y), int(truth_visible[frame]), at_cell]
    return [[v if not isinstance(v, np.generic) else v.item() for v in rows[f]]
            for f in sorted(rows)]


def _submit_assisted(task_id: int, worker: str, xy: np.ndarray, visible: np.ndarray,
                     size: tuple[int, int], at_cell: str, elsewhere: str,
                     rng: np.random.Generator) -> int:
    """A direct-link assignment whose rows came from suggestions (its check cells depend on
    its id, so it is created first and its tracks written once the id is known)."""
    from backend.annotation.models import Assignment
    from backend.config import get_settings
    from worker.assist import checks
    from worker.synth.annotators import annotate

    work = annotate(xy, visible, size, "careful", rng)
    assignment_id = submit_direct(task_id, worker, work.tracks)
    key = checks.check_key(get_settings().signing_key)
    frames, points = visible.shape
    cells: dict[int, dict[int, tuple[float, float]]] = {}
    for point, frame in checks.check_cells(key, assignment_id, points, frames):
        dx, dy = checks.check_offset(key, assignment_id, point, frame)
        cells.setdefault(point, {})[frame] = checks.shift_inside(
            float(xy[frame, point, 0]), float(xy[frame, point, 1]), dx, dy, *size)
    with session_scope() as session:
        assignment = session.get_one(Assignment, assignment_id)
        for track in assignment.tracks:
            p = track.point_index
            track.keyframes = _assisted_rows(track.keyframes, xy[:, p], visible[:, p],
                                             cells.get(p, {}), at_cell, elsewhere, rng)
    return assignment_id


def _planted(assignment_id: int) -> list[tuple[int, int]]:
    from backend.config import get_settings
    from worker.assist.checks import check_cells, check_key

    return check_cells(check_key(get_settings().signing_key), assignment_id, 21, 16)


def test_qc_job_rejects_a_blind_acceptor_by_its_check_suggestions(market_env: dict[str, str],
                                                                  qc_capture: Path) -> None:
    from backend.accounts.service import create_admin
    from backend.annotation.models import Assignment, Task
    from backend.annotation.service import create_tasks
    from backend.app import create_app
    from backend.captures.flows import import_path
    from backend.captures.truth import CaptureTruth
    from backend.jobs.runner import execute
    from backend.quality.models import QCReport
    from backend.quality.service import qc_key, request_qc
    from backend.storage import get_storage
    from worker.synth.annotators import annotate

    sequence_id = import_path(qc_capture)[0].sequence_id
    with session_scope() as session:
        create_admin(session, *ADMIN)
        tasks = [(t.id, t.camera.serial, t.target_key, t.camera.width, t.camera.height)
                 for t in create_tasks(session, get_storage(), sequence_id) if t.kind == "hand"]
    assert len(tasks) == 6
    truth, rng = CaptureTruth(qc_capture), np.random.default_rng(4)
    role: dict[int, str] = {}
    truth_of: dict[int, np.ndarray] = {}
    for i, (task_id, serial, target, width, height) in enumerate(tasks):
        xy, visible = truth.points({"kind": "hand", "serial": serial, "target_key": target,
                                    "num_frames": 16}, rng)
        if i < 3:  # keyed by hand: rows without a source
            work = annotate(xy, visible, (width, height), "careful", rng)
            role[submit_direct(task_id, f"hand-{i}", work.tracks)] = "by hand"
            continue
        at_cell, elsewhere = {3: ("edited", "tracked"), 4: ("tracked", "tracked"),
                              5: ("prefilled", "prefilled")}[i]
        name = {3: "careful", 4: "blind", 5: "all pre-filled"}[i]
        assignment_id = _submit_assisted(task_id, name, xy, visible, (width, height), at_cell,
                                         elsewhere, rng)
        role[assignment_id], truth_of[assignment_id] = name, xy

    with session_scope() as session:
        request_qc(session, session.get_one(Task, tasks[0][0]))
    execute(qc_key(sequence_id, "hand:0"))

    with session_scope() as session:
        reports = {r.assignment_id: r for r in session.scalars(select(QCReport))}
        status = {a.id: a.status for a in session.scalars(select(Assignment))}
    assert set(reports) == set(role)
    by_role = {name: reports[aid] for aid, name in role.items() if name != "by hand"}
    for aid, name in role.items():
        if name == "by hand":
            report = reports[aid]
            assert report.outcome == "approve", report.reasons
            assert (report.metrics["checks_accepted"], report.metrics["checks_corrected"]) \
                == (0, 0)
            assert report.metrics["decided_fraction"] == 1.0
    careful, blind, prefilled = (by_role[n] for n in ("careful", "blind", "all pre-filled"))
    assert not careful.provisional and not blind.provisional
    assert careful.outcome == "approve", careful.reasons
    assert (careful.metrics["checks_accepted"], careful.metrics["checks_corrected"]) == (0, 4)
    assert careful.metrics["median_error_px"] < 5.0
    # The blind acceptor's labels are as good as the suggestions: only the checks tell.
    assert blind.metrics["median_error_px"] < 5.0
    assert (blind.metrics["checks_accepted"], blind.metrics["checks_corrected"]) == (4, 0)
    # Its positions are never what rejects it: at most its tracker-made track shakes a little
    # against a reference of views keyed on nearly every frame of this fast clip (a review).
    assert blind.outcome == "reject" and blind.reasons[0] == BLIND_REASON
    assert all(r == BLIND_REASON or r.startswith("jitter_px") for r in blind.reasons)
    assert "15 px off the point on purpose" in blind.feedback
    # The feedback names the planted cells it kept: each joint and its frames.
    cells = _planted(blind.assignment_id)
    assert len(cells) == 4
    assert kept_checks_sentence([list(c) for c in cells], HAND_NAMES) in blind.feedback
    for point, frame in cells:
        assert HAND_NAMES[point].replace("_", " ") in blind.feedback and str(frame) in \
            blind.feedback
    assert "placed wrong on purpose that you kept" not in careful.feedback
    # Every position a suggestion kept: not judged on position, and its kept checks reject it.
    assert prefilled.metrics["decided_fraction"] == 0.0
    assert prefilled.metrics["own_keyframes"] == 0 and careful.metrics["own_keyframes"] > 4
    assert prefilled.metrics["median_error_px"] is None
    assert prefilled.outcome == "reject"
    assert prefilled.reasons == [BLIND_REASON, DECIDED_NOTHING]
    # Direct links: the decisions are recorded on the assignments.
    assert status[blind.assignment_id] == status[prefilled.assignment_id] == "rejected"
    assert status[careful.assignment_id] == "approved"

    with TestClient(create_app()) as client:
        token = client.post("/api/auth/token", json={"email": ADMIN[0], "password": ADMIN[1]})
        auth = {"Authorization": f"Bearer {token.json()['access_token']}"}
        detail = client.get(f"/api/qc/reports/{blind.assignment_id}", headers=auth).json()
        assert detail["metrics"]["checks_accepted"] == 4
        assert detail["metrics"]["checks_corrected"] == 0
        assert BLIND_REASON in detail["reasons"]
        replay = client.get(f"/api/qc/reports/{blind.assignment_id}/review", headers=auth)
        assert replay.status_code == 200 and BLIND_REASON in replay.json()["reasons"]
        edited = client.get(f"/api/qc/reports/{careful.assignment_id}/review", headers=auth)
        assert edited.json()["metrics"]["checks_corrected"] == 4
        assert not any("check suggestions" in r for r in edited.json()["reasons"])
    # The replay draws the track as saved: each kept check suggestion 15 px from the true
    # joint, each dragged-back one within a careful click of it.
    kept = _off_truth(replay.json(), blind.assignment_id, truth_of[blind.assignment_id])
    fixed = _off_truth(edited.json(), careful.assignment_id, truth_of[careful.assignment_id])
    assert np.allclose(kept, 15.0, atol=0.1), kept
    assert len(fixed) == 4 and max(fixed) < 4.0, fixed


def _off_truth(review: dict, assignment_id: int, truth_xy: np.ndarray) -> list[float]:
    """Distance (px) of the replayed track from the true joint at the assignment's check
    cells."""
    from backend.config import get_settings
    from worker.assist import checks

    key = checks.check_key(get_settings().signing_key)
    out = []
    for point, frame in checks.check_cells(key, assignment_id, 21, review["num_frames"]):
        shown = review["track"]["xy"][frame][point]
        out.append(float(np.linalg.norm(np.asarray(shown) - truth_xy[frame, point])))
    return out

