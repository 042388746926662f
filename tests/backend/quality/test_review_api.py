"""The review endpoints against the simulated workers' known truth: a swapper's replay shows its
swap span and large errors on the swapped fingers only there, the reference it is judged by
lies on the true joints, a careful worker's errors stay small; the queue lists waiting work
worst first; an object's landmarks are replayed against the solved object."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.db import session_scope
from tests.backend.quality.helpers import ADMIN_EMAIL, ADMIN_PASSWORD, store_solve, submit_direct

FRAMES = 16
RING, LITTLE = [13, 14, 15, 16], [17, 18, 19, 20]
# The hand in 6 views: a swapper on the first, careful workers on the others.
PROFILES = ("swapper", "careful", "careful", "careful", "careful", "careful")


def _array(rows: list) -> np.ndarray:
    return np.array([[[np.nan if v is None else v for v in p] for p in f] for f in rows], float)


def _matrix(rows: list) -> np.ndarray:
    return np.array([[np.nan if v is None else v for v in f] for f in rows], float)


@pytest.fixture
def scored(market_env: dict[str, str], qc_capture: Path) -> dict:
    """The capture imported, its hand labelled in every view (and its object in two), scored;
    an admin's client."""
    from backend.accounts.service import create_admin
    from backend.annotation.service import create_tasks
    from backend.app import create_app
    from backend.captures.flows import import_path
    from backend.captures.truth import CaptureTruth
    from backend.quality.service import score_target
    from backend.storage import get_storage
    from worker.synth.annotators import annotate

    sequence_id = import_path(qc_capture)[0].sequence_id
    with session_scope() as session:
        create_admin(session, ADMIN_EMAIL, ADMIN_PASSWORD)
        tasks = [{"id": t.id, "kind": t.kind, "serial": t.camera.serial,
                  "target_key": t.target_key, "num_frames": FRAMES,
                  "size": (t.camera.width, t.camera.height)}
                 for t in create_tasks(session, get_storage(), sequence_id)]
    truth, rng = CaptureTruth(qc_capture), np.random.default_rng(7)
    hands = [t for t in tasks if t["kind"] == "hand"]
    work: dict[int, dict] = {}
    for task, profile in zip(hands, PROFILES, strict=True):
        xy, visible = truth.points(task, rng)
        labels = annotate(xy, visible, task["size"], profile, rng)
        aid = submit_direct(task["id"], f"{profile}-{task['serial']}", labels.tracks)
        work[aid] = {"profile": profile, "truth": xy, "task": task}
    objects = [t for t in tasks if t["kind"] == "object"][:2]
    for i, task in enumerate(objects):
        xy, visible = truth.points(task, rng)
        labels = annotate(xy, visible, task["size"], "careful", rng)
        aid = submit_direct(task["id"], f"object-{i}", labels.tracks)
        work[aid] = {"profile": "object", "truth": xy, "task": task}
    with session_scope() as session:
        score_target(session, sequence_id, "hand:0")
        score_target(session, sequence_id, "object:0")
    client = TestClient(create_app())
    token = client.post("/api/auth/token", json={"email": ADMIN_EMAIL,
                                                 "password": ADMIN_PASSWORD}).json()
    client.headers["Authorization"] = f"Bearer {token['access_token']}"
    return {"client": client, "work": work, "sequence_id": sequence_id, "truth": truth}


def _review(client: TestClient, aid: int) -> dict:
    resp = client.get(f"/api/qc/reports/{aid}/review")
    assert resp.status_code == 200, resp.text
    return resp.json()


def test_review_shows_the_swappers_span_and_errors_on_the_swapped_fingers(scored: dict) -> None:
    from worker.synth.annotators import swap_window

    client, work = scored["client"], scored["work"]
    swapper = next(a for a, w in work.items() if w["profile"] == "swapper")
    review = _review(client, swapper)
    assert review["num_frames"] == FRAMES and (review["width"], review["height"]) == (320, 240)
    assert review["point_names"][0] == "wrist" and len(review["point_names"]) == 21
    assert review["reference_source"] == "consensus" and review["reference_note"] is None
    lo, hi = swap_window(FRAMES)
    assert review["swaps"], review["reasons"]
    swap = review["swaps"][0]
    assert sorted(swap["fingers"]) == ["little", "ring"]
    first, last = swap["frames"]
    assert abs(first - lo) <= 1 and abs(last - hi) <= 1, (swap, lo, hi)
    errors = _matrix(review["errors"])
    assert errors.shape == (FRAMES, 21)
    # Inside the span the swapped fingers are a finger's width off; the thumb is not.
    inside = errors[lo + 1:hi][:, RING + LITTLE]
    assert np.nanmedian(inside) > 8.0, inside
    assert np.nanmedian(errors[lo + 1:hi, [1, 2, 3, 4]]) < 4.0
    # Away from the span (the keyframes around it interpolate towards it) they are fine.
    away = np.r_[0:max(lo - 2, 1), hi + 2:FRAMES]
    outside = np.nanmedian(errors[away][:, RING + LITTLE])
    assert outside < 5.0 and np.nanmedian(inside) > 2 * outside
    # The reference lies on the true joints wherever the other views fix it and clicked them
    # (between their keyframes it follows their interpolation, as the consensus does).
    reference = _array(review["reference"])
    truth = work[swapper]["truth"]
    fixed = np.isfinite(reference).all(axis=-1)
    assert fixed.mean() > 0.5
    clicked = np.ones((FRAMES, 21), bool)
    for aid in (a for a, w in work.items() if w["profile"] == "careful"):
        keyed = np.zeros((FRAMES, 21), bool)
        for p, frames in enumerate(_review(client, aid)["track"]["keyframes"]):
            keyed[frames, p] = True
        clicked &= keyed
    at = fixed & clicked
    assert at.sum() >= 21
    assert np.median(np.linalg.norm(reference[at] - truth[at], axis=-1)) < 2.5
    # The track is the worker's own, swapped fingers and all.
    xy = _array(review["track"]["xy"])
    visible = np.array(review["track"]["visible"], bool)
    assert xy.shape == (FRAMES, 21, 2) and visible.shape == (FRAMES, 21)
    keyed = [f for f in review["track"]["keyframes"][16] if lo <= f <= hi and visible[f, 16]]
    assert keyed
    assert np.median(np.linalg.norm(xy[keyed, 16] - truth[keyed, 20], axis=-1)) < 5.0
    assert review["frames"]["urls"][3].startswith(
        f"/api/sequences/{scored['sequence_id']}/views/{work[swapper]['task']['serial']}"
        "/frames/3.jpg?token=")
    frame = client.get(review["frames"]["urls"][3], headers={"Authorization": ""})
    assert frame.status_code == 200 and frame.headers["content-type"] == "image/jpeg"


def test_review_of_careful_work_has_small_errors_and_no_spans(scored: dict) -> None:
    client, work = scored["client"], scored["work"]
    careful = next(a for a, w in work.items() if w["profile"] == "careful")
    review = _review(client, careful)
    errors = _matrix(review["errors"])
    assert np.isfinite(errors).mean() > 0.5 and np.nanmedian(errors) < 4.0
    assert review["swaps"] == [] and review["highlight"] is None


def test_queue_lists_waiting_work_worst_first(scored: dict) -> None:
    client, work = scored["client"], scored["work"]
    queue = client.get("/api/qc/queue?limit=3").json()
    assert queue["total"] == len(work) and len(queue["items"]) == 3
    swapper = next(a for a, w in work.items() if w["profile"] == "swapper")
    first = queue["items"][0]
    assert first["assignment_id"] == swapper and first["outcome"] in ("reject", "review")
    assert first["swaps"] >= 1 and first["sequence"].count("/") == 1
    everything = client.get("/api/qc/queue?limit=500").json()["items"]
    ranks = [(r["provisional"], {"reject": 0, "review": 1, "approve": 2}[r["outcome"]])
             for r in everything]
    assert ranks == sorted(ranks)
    rest = client.get("/api/qc/queue?limit=3&offset=3").json()["items"]
    assert [r["assignment_id"] for r in rest] == [r["assignment_id"] for r in everything[3:6]]


def test_object_review_replays_landmarks_and_after_a_solve_their_reprojection(
        scored: dict) -> None:
    from backend.quality.service import score_target

    client, work = scored["client"], scored["work"]
    obj = next(a for a, w in work.items() if w["profile"] == "object")
    before = _review(client, obj)
    assert before["kind"] == "object" and before["reference"] is None
    assert "solved" in before["reference_note"]
    assert before["highlight"] and len(before["highlight"]["polygon"]) >= 3
    assert np.isfinite(_array(before["track"]["xy"])).any()

    store_solve(scored["sequence_id"], scored["truth"].object_poses())
    with session_scope() as session:
        score_target(session, scored["sequence_id"], "object:0")
    after = _review(client, obj)
    assert after["reference_source"] == "anchored"
    reference, truth = _array(after["reference"]), work[obj]["truth"]
    shown = np.array(after["reference_shown"], bool) & np.isfinite(reference).all(axis=-1)
    assert shown.any()
    assert np.median(np.linalg.norm(reference[shown] - truth[shown], axis=-1)) < 3.0


def test_a_report_scored_before_the_replay_still_shows_the_track(scored: dict) -> None:
    from sqlalchemy import select

    from backend.quality.models import QCReport

    client, work = scored["client"], scored["work"]
    careful = next(a for a, w in work.items() if w["profile"] == "careful")
    with session_scope() as session:
        session.scalars(select(QCReport).where(QCReport.assignment_id == careful)).one() \
            .replay = None
    review = _review(client, careful)
    assert review["reference"] is None and review["errors"] is None
    assert "POST /api/qc/runs" in review["reference_note"]
    assert np.isfinite(_array(review["track"]["xy"])).mean() > 0.5


def test_review_endpoints_refuse_bad_ids_and_anonymous_callers(scored: dict) -> None:
    client = scored["client"]
    missing = client.get("/api/qc/reports/999999/review")
    assert missing.status_code == 404 and "no QC report" in missing.json()["detail"]
    for bad in ("0", "abc", "99999999999"):
        resp = client.get(f"/api/qc/reports/{bad}/review")
        assert resp.status_code == 422, (bad, resp.text)
        assert "assignment_id" in resp.text
    for query in ("limit=0", "limit=501", "offset=-1", "limit=x"):
        resp = client.get(f"/api/qc/queue?{query}")
        assert resp.status_code == 422, (query, resp.text)
    anonymous = TestClient(client.app)
    assert anonymous.get("/api/qc/queue").status_code == 401
    some = next(iter(scored["work"]))
    assert anonymous.get(f"/api/qc/reports/{some}/review").status_code == 401
