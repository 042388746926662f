"""The QC job end to end: simulated workers submit through the portal, the submissions are
synced, the QC job scores the views against each other, pays the careful workers, rejects the
spammers with evidence, re-opens their HITs, and never acts twice."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient
from sqlalchemy import func, select

from backend.config import DEV_MARKET_ACCESS_KEY, DEV_MARKET_REQUESTERS
from backend.db import session_scope
from tests.backend.market.helpers import make_client as boto3_client
from tests.backend.quality.helpers import (
    ADMIN_EMAIL,
    ADMIN_PASSWORD,
    crowd_submits,
    publish_hand_tasks,
    sync_submissions,
)


def _requester(base: str):
    return boto3_client(base, (DEV_MARKET_ACCESS_KEY, DEV_MARKET_REQUESTERS.split(":")[1]))


def _payments() -> list[tuple[str, int]]:
    from backend.crowd.models import CrowdPayment

    with session_scope() as session:
        return sorted((p.kind, p.assignment_id) for p in session.scalars(select(CrowdPayment)))


def test_qc_job_pays_careful_work_and_rejects_spam_once(crowd_url: str, qc_capture: Path,
                                                       monkeypatch) -> None:
    from backend.annotation.models import Assignment
    from backend.config import get_settings
    from backend.crowd.models import CrowdWorkerAction

    monkeypatch.setenv("DEXLABEL_QC_BLOCK_AFTER_FAILURES", "1")
    get_settings.cache_clear()
    from backend.jobs.models import Job
    from backend.jobs.runner import execute
    from backend.jobs.service import enqueue_job
    from backend.quality.models import QCReport
    from backend.quality.service import qc_key

    sequence_id, hit_ids = publish_hand_tasks(qc_capture, max_assignments=2)
    outcomes = crowd_submits(crowd_url, qc_capture, ["careful", "spammer"] * 6)
    assert [o.status for o in outcomes] == ["submitted"] * 12
    sync_submissions()
    key = qc_key(sequence_id, "hand:0")
    with session_scope() as session:  # syncing the submissions queued the target's QC once
        assert session.scalar(select(func.count()).select_from(Job).where(Job.key == key)) == 1
    execute(key)

    profile = {o.assignment_id: o.profile for o in outcomes}
    with session_scope() as session:
        reports = {a.external_id: r for r, a in session.execute(
            select(QCReport, Assignment).join(Assignment, Assignment.id == QCReport.assignment_id))}
        assert len(reports) == 12
        for market_id, report in reports.items():
            if profile[market_id] == "careful":
                assert (report.outcome, report.action) == ("approve", "approved"), report.reasons
                assert report.metrics["median_error_px"] < 5.0
                # the visibility check read the view's depth maps
                assert report.metrics["visibility_disagreement"] is not None
            else:
                assert (report.outcome, report.action) == ("reject", "rejected")
                assert "px" in report.feedback and report.feedback.strip()
            assert len(report.per_joint) == 21 and len(report.per_frame) == 16
    requester = _requester(crowd_url)
    for o in outcomes:
        record = requester.get_assignment(AssignmentId=o.assignment_id)["Assignment"]
        expected = "Approved" if o.profile == "careful" else "Rejected"
        assert record["AssignmentStatus"] == expected
        if expected == "Rejected":
            assert record["RequesterFeedback"] == reports[o.assignment_id].feedback
    for hit_id in hit_ids:  # each rejected piece of work re-opened its HIT
        assert requester.get_hit(HITId=hit_id)["HIT"]["MaxAssignments"] == 3

    with session_scope() as session:  # one failure blocks a worker in this project
        blocked = set(session.scalars(select(CrowdWorkerAction.worker_id).where(
            CrowdWorkerAction.kind == "block")))
    assert blocked == {o.worker_id for o in outcomes if o.profile == "spammer"}

    paid = _payments()
    with session_scope() as session:  # a second run (another submission, a retry) acts on nothing
        enqueue_job(session, "qc", key, {"sequence_id": sequence_id, "target_key": "hand:0"})
    execute(key)
    assert _payments() == paid
    assert sum(1 for kind, _ in paid if kind == "approval") == 6
    assert sum(1 for kind, _ in paid if kind == "rejection") == 6
    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == key))
        # rejected work leaves the pool: the second run scored the six approved ones
        assert job.status == "done" and job.result["scored"]["approve"] == 6
        assert job.result["actions"] == {}
        # the object tasks were never published: no solve yet, and the job says why
        assert job.result["solve"].startswith("waiting:")


def test_admin_reads_reports_and_worker_quality(crowd_url: str, qc_capture: Path) -> None:
    from backend.app import create_app
    from backend.jobs.runner import execute
    from backend.quality.service import qc_key

    sequence_id, _ = publish_hand_tasks(qc_capture, max_assignments=1)
    crowd_submits(crowd_url, qc_capture, ["careful"] * 5 + ["lazy"])
    sync_submissions()
    execute(qc_key(sequence_id, "hand:0"))
    with TestClient(create_app()) as client:
        token = client.post("/api/auth/token", json={"email": ADMIN_EMAIL,
                                                     "password": ADMIN_PASSWORD}).json()
        auth = {"Authorization": f"Bearer {token['access_token']}"}
        reports = client.get(f"/api/qc/reports?sequence_id={sequence_id}", headers=auth).json()
        assert len(reports) == 6
        detail = client.get(f"/api/qc/reports/{reports[0]['assignment_id']}", headers=auth)
        assert detail.status_code == 200 and len(detail.json()["per_joint"]) == 21
        workers = client.get("/api/qc/workers", headers=auth).json()
        assert len(workers) == 6 and all(0.0 <= w["score"] <= 1.0 for w in workers)
        missing = client.get("/api/qc/reports/999999", headers=auth)
        assert missing.status_code == 404 and "no QC report" in missing.json()["detail"]
        none = client.post("/api/qc/runs", headers=auth, json={"sequence_id": 999999})
        assert none.status_code == 404
        bad = client.post("/api/qc/runs", headers=auth,
                          json={"sequence_id": sequence_id, "target_key": "foot:1"})
        assert bad.status_code == 422
