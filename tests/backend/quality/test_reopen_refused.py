"""A re-open the marketplace refuses is recorded as refused, with its reason, on the report an
admin reads; one the marketplace did not answer stays pending and the job's retry does it."""

from __future__ import annotations

from pathlib import Path

from fastapi.testclient import TestClient
from sqlalchemy import select

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


def _spend_the_balance(base: str) -> None:
    """The requester's money goes elsewhere (another project on the same account): the
    marketplace's own ledger takes the whole available balance and $100 more, so the money a
    rejection releases cannot pay for a new slot either."""
    from backend.market import clock, ledger

    available = float(_requester(base).get_account_balance()["AvailableBalance"])
    with session_scope() as session:
        ledger.record(session, DEV_MARKET_ACCESS_KEY, "bonus", clock.now(),
                      available=-round(available * 100) - 10_000)


def _reports() -> dict[str, tuple[str | None, str | None]]:
    from backend.annotation.models import Assignment
    from backend.quality.models import QCReport

    with session_scope() as session:
        return {a.external_id: (r.action, r.action_detail) for r, a in session.execute(
            select(QCReport, Assignment).join(Assignment, Assignment.id == QCReport.assignment_id))}


def _score(crowd_url: str, qc_capture: Path, seed: int) -> tuple[int, list[str], list, str]:
    from backend.quality.service import qc_key

    sequence_id, hit_ids = publish_hand_tasks(qc_capture, max_assignments=2)
    outcomes = crowd_submits(crowd_url, qc_capture, ["careful", "spammer"] * 6, seed=seed)
    assert [o.status for o in outcomes] == ["submitted"] * 12
    sync_submissions()
    return sequence_id, hit_ids, outcomes, qc_key(sequence_id, "hand:0")


def test_a_refused_reopen_is_recorded_as_refused_with_its_reason(
    crowd_url: str, qc_capture: Path
) -> None:
    from backend.app import create_app
    from backend.jobs.runner import execute

    sequence_id, hit_ids, outcomes, key = _score(crowd_url, qc_capture, seed=0)
    _spend_the_balance(crowd_url)
    execute(key)

    reports = _reports()
    requester = _requester(crowd_url)
    spam = [o for o in outcomes if o.profile == "spammer"]
    for o in spam:
        action, detail = reports[o.assignment_id]
        assert action == "rejected"
        assert detail is not None and "NOT re-opened" in detail, detail
        assert "Insufficient funds" in detail and o.hit_id in detail
    for hit_id in hit_ids:  # nothing was added on the marketplace
        assert requester.get_hit(HITId=hit_id)["HIT"]["MaxAssignments"] == 2
    with TestClient(create_app()) as client:  # what an admin sees
        token = client.post("/api/auth/token", json={"email": ADMIN_EMAIL,
                                                     "password": ADMIN_PASSWORD})
        headers = {"Authorization": f"Bearer {token.json()['access_token']}"}
        listed = client.get(f"/api/qc/reports?sequence_id={sequence_id}", headers=headers)
        assert listed.status_code == 200, listed.text
        details = [r["action_detail"] for r in listed.json()
                   if r["action"] == "rejected"]
        assert len(details) == len(spam)
        assert all("NOT re-opened" in d and "Insufficient funds" in d for d in details)


def test_a_reopen_the_marketplace_did_not_answer_is_retried(
    crowd_url: str, qc_capture: Path
) -> None:
    from backend.jobs.models import Job
    from backend.market import protocol
    from backend.quality.flows import REOPEN_PENDING, REOPENED

    _, hit_ids, outcomes, key = _score(crowd_url, qc_capture, seed=1)
    protocol.inject_faults("CreateAdditionalAssignmentsForHIT", 1000)
    from backend.jobs.runner import execute

    execute(key)
    with session_scope() as session:
        job = session.scalar(select(Job).where(Job.key == key))
        assert job is not None and job.status == "retrying", job.status
    pending = [d for _, d in _reports().values() if d and d.startswith(REOPEN_PENDING)]
    assert pending and "could not take it now" in pending[0]

    protocol.clear_faults()
    execute(key)
    spam = [o for o in outcomes if o.profile == "spammer"]
    reports = _reports()
    assert all(reports[o.assignment_id] == ("rejected", REOPENED) for o in spam)
    requester = _requester(crowd_url)
    for hit_id in hit_ids:
        assert requester.get_hit(HITId=hit_id)["HIT"]["MaxAssignments"] == 3
