"""The project-control endpoints: each worker's record (GET /api/crowd/workers and
/api/crowd/workers/{id}), costs named by sequence, the progress of a page of sequences
(GET /api/progress) and the job table's counts (GET /api/jobs/counts)."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

import pytest
from sqlalchemy import select, update

from backend.annotation.models import Assignment, Task
from backend.db import session_scope
from tests.backend.crowd.test_costs import reviewed  # noqa: F401  (fixture)
from tests.backend.market.helpers import WORKER, WORKER_2, WORKER_3

# WORKER's QC reports by date: (days before now, outcome, median error px or None).
REPORTS = ((3, "approve", 2.0), (2, "review", None), (1, "approve", 4.0))


def _add_reports(assignment_ids: list[int], worker: str) -> None:
    """QC reports with known dates and errors on the worker's assignments (the tasks' work
    is never scored here: the reports stand in for QC's)."""
    from backend.quality.models import QCReport

    now = datetime.now(UTC)
    with session_scope() as session:
        for aid, (days, outcome, error) in zip(assignment_ids, REPORTS, strict=False):
            a = session.get_one(Assignment, aid)
            task = session.get_one(Task, a.task_id)
            session.add(QCReport(assignment_id=aid, task_id=task.id, sequence_id=task.sequence_id,
                                 target_key=task.target_key, worker_id=worker,
                                 metrics={"median_error_px": error}, outcome=outcome,
                                 created_at=now - timedelta(days=days)))


def _assignment_of(worker: str) -> list[int]:
    with session_scope() as session:
        return list(session.scalars(select(Assignment.id).where(Assignment.worker_id == worker)
                                    .order_by(Assignment.id)))


@pytest.fixture
def scored(reviewed: tuple[int, int]) -> tuple[int, int]:  # noqa: F811
    """The costs scenario, with WORKER's approved assignment's QC report and working time,
    and two more scored assignments of theirs on the open HIT's task."""
    [approved] = _assignment_of(WORKER)
    with session_scope() as session:
        a = session.get_one(Assignment, approved)
        a.working_time_s, a.submitted_at = 90.0, datetime.now(UTC)
        for extra, seconds in (("EXTRA-1", 30.0), ("EXTRA-2", 300.0)):
            session.add(Assignment(task_id=a.task_id, worker_id=WORKER, external_id=extra,
                                   status="submitted", working_time_s=seconds,
                                   submitted_at=datetime.now(UTC)))
    _add_reports(_assignment_of(WORKER), WORKER)
    return reviewed


def test_worker_listing_gives_rates_errors_times_earnings_and_history(
    scored: tuple[int, int], api: Any,
) -> None:
    resp = api.get("/api/crowd/workers")
    assert resp.status_code == 200, resp.text
    rows = {w["worker_id"]: w for w in resp.json()}
    assert list(rows) == sorted([WORKER, WORKER_2, WORKER_3])
    w = rows[WORKER]
    # One approved and two submitted assignments; QC: two approvals and a review.
    assert (w["submitted"], w["approved"], w["rejected"]) == (3, 1, 0)
    assert w["approval_rate"] == 1.0
    assert (w["scored"], w["score"]) == (3, pytest.approx((2 + 0.5) / 3, abs=1e-4))
    assert w["median_error_px"] == 3.0  # of 2.0 and 4.0; the unmeasured report left out
    assert w["median_working_time_s"] == 90.0  # of 30, 90 and 300 s
    # The $0.50 reward and the $1.00 bonus paid; the pending $0.50 bonus is not earned yet.
    assert (w["earned_rewards"], w["earned_bonuses"], w["earned"]) == ("0.50", "1.00", "1.50")
    assert [(p["outcome"], p["median_error_px"]) for p in w["history"]] == \
        [(o, e) for _, o, e in REPORTS]
    dates = [p["at"] for p in w["history"]]
    assert dates == sorted(dates)
    w2 = rows[WORKER_2]
    assert (w2["approved"], w2["rejected"], w2["approval_rate"], w2["earned"]) == \
        (0, 1, 0.0, "0.00")
    assert rows[WORKER_3]["approval_rate"] is None and rows[WORKER_3]["score"] is None

    page = api.get("/api/crowd/workers?offset=1&limit=1").json()
    assert [p["worker_id"] for p in page] == [sorted(rows)[1]]


def test_one_worker_lists_assignments_with_sequence_names_and_bonuses(
    scored: tuple[int, int], api: Any,
) -> None:
    resp = api.get(f"/api/crowd/workers/{WORKER}")
    assert resp.status_code == 200, resp.text
    detail = resp.json()
    assert detail["worker_id"] == WORKER and len(detail["history"]) == len(REPORTS)
    [paid] = [a for a in detail["assignments"] if a["status"] == "approved"]
    assert paid["confirmed"] and paid["reward"] == "0.50" and paid["bonuses"] == "1.00"
    assert paid["sequence"].endswith("/grasp") and paid["qc_outcome"] == "approve"
    assert paid["working_time_s"] == 90.0
    others = [a for a in detail["assignments"] if a["assignment_id"] != paid["assignment_id"]]
    assert len(others) == 2 and not any(a["confirmed"] for a in others)
    assert [a["assignment_id"] for a in detail["assignments"]] == \
        sorted((a["assignment_id"] for a in detail["assignments"]), reverse=True)


def test_a_blocked_worker_shows_blocked_with_the_reason_until_unblocked(
    scored: tuple[int, int], api: Any,
) -> None:
    resp = api.post(f"/api/crowd/workers/{WORKER_2}/block", json={"reason": "Random points"})
    assert resp.status_code == 200, resp.text
    w = api.get(f"/api/crowd/workers/{WORKER_2}").json()
    assert w["blocked"] and w["block_reason"] == "Random points"
    assert api.post(f"/api/crowd/workers/{WORKER_2}/block",
                    json={"reason": "again"}).status_code == 409
    assert api.delete(f"/api/crowd/workers/{WORKER_2}/block").status_code == 200
    assert not api.get(f"/api/crowd/workers/{WORKER_2}").json()["blocked"]


def test_worker_endpoints_refuse_bad_input_unknown_workers_and_anonymous_callers(
    scored: tuple[int, int], api: Any,
) -> None:
    from fastapi.testclient import TestClient

    for query, field in (("limit=0", "query.limit"), ("limit=1001", "query.limit"),
                         ("offset=-1", "query.offset"), ("limit=ten", "query.limit")):
        resp = api.get(f"/api/crowd/workers?{query}")
        assert resp.status_code == 422, query
        assert resp.json()["fields"][0]["field"] == field, resp.json()
    resp = api.get("/api/crowd/workers/NOBODY")
    assert resp.status_code == 404
    assert resp.json()["detail"] == "worker NOBODY has no work and no block in this project"
    assert api.get(f"/api/crowd/workers/{'W' * 129}").status_code == 422
    anonymous = TestClient(api.app)
    for path in ("/api/crowd/workers", f"/api/crowd/workers/{WORKER}", "/api/progress",
                 "/api/jobs/counts"):
        assert anonymous.get(path).status_code == 401, path


def test_costs_name_each_sequence_by_subject_and_name(
    scored: tuple[int, int], api: Any,
) -> None:
    from backend.captures.models import Sequence, Subject

    seq_a, seq_b = scored
    with session_scope() as session:
        names = {str(i): f"{s}/{n}" for i, s, n in session.execute(
            select(Sequence.id, Subject.name, Sequence.name).join(Subject))}
    costs = api.get("/api/crowd/costs").json()
    assert [(line["key"], line["name"]) for line in costs["by_sequence"]] == \
        [(str(seq_a), names[str(seq_a)]), (str(seq_b), names[str(seq_b)])]
    assert names[str(seq_a)].endswith("/grasp") and names[str(seq_b)].endswith("/pour")
    assert costs["total"]["name"] == "project"
    assert {line["name"] for line in costs["by_worker"]} == {WORKER, WORKER_2, WORKER_3}


def test_progress_pages_hold_the_same_sequences_as_the_sequence_listing(
    scored: tuple[int, int], api: Any,
) -> None:
    seq_a, seq_b = scored
    everything = api.get("/api/progress").json()
    assert [p["sequence_id"] for p in everything] == [seq_a, seq_b]
    a = everything[0]
    # Sequence A: approved (accepted), rejected with its HIT still live (published), open.
    assert a["counts"] == {"open": 0, "published": 2, "submitted": 0, "in review": 0,
                           "accepted": 1}
    states = sorted(t["state"] for t in a["tasks"])
    assert states == ["accepted", "published", "published"], states
    assert a == api.get(f"/api/sequences/{seq_a}/progress").json()
    listed = [s["id"] for s in api.get("/api/sequences?offset=1&limit=1").json()]
    assert [p["sequence_id"] for p in api.get("/api/progress?offset=1&limit=1").json()] == listed
    assert api.get("/api/progress?limit=0").status_code == 422
    assert api.get("/api/progress?offset=-5").status_code == 422


def test_job_counts_per_kind_and_status(crowd_url: str, api: Any) -> None:
    from backend.jobs.models import Job
    from backend.jobs.service import enqueue_job

    with session_scope() as session:
        for key in ("a", "b", "c"):
            enqueue_job(session, "qc", f"qc:{key}")
        enqueue_job(session, "solve", "solve:1")
    with session_scope() as session:
        session.execute(update(Job).where(Job.key == "qc:c").values(status="failed"))
    resp = api.get("/api/jobs/counts")
    assert resp.status_code == 200, resp.text
    assert resp.json() == {"kinds": {"qc": {"queued": 2, "failed": 1}, "solve": {"queued": 1}}}
    failed = api.get("/api/jobs?status=failed&kind=qc").json()
    assert [j["key"] for j in failed] == ["qc:c"]
    assert api.get("/api/jobs?status=broken").status_code == 422
