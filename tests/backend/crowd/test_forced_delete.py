"""A forced sequence delete expires the sequence's open HITs on the marketplace before its rows
go, and the money its ledger recorded stays in the cost report under the deleted sequence's
name; a refused delete touches no HIT."""

from __future__ import annotations

import time
from typing import Any

from backend.crowd import costs
from backend.db import session_scope
from tests.backend.crowd.test_costs import PROJECT, _split, reviewed
from tests.backend.market.helpers import WORKER, WORKER_2, WORKER_3

__all__ = ["reviewed"]


def _hits_of(sequence_id: int) -> list[str]:
    from sqlalchemy import select

    from backend.annotation.models import Task
    from backend.crowd.models import CrowdHit

    with session_scope() as session:
        return [h for h in session.scalars(
            select(CrowdHit.hit_id).join(Task, Task.id == CrowdHit.task_id)
            .where(Task.sequence_id == sequence_id).order_by(CrowdHit.id)) if h]


def _status(mturk: Any, hit_id: str) -> str:
    return str(mturk.get_hit(HITId=hit_id)["HIT"]["HITStatus"])


def test_a_forced_delete_expires_the_hits_and_keeps_the_money_in_the_report(
    reviewed: tuple[int, int], api: Any, mturk: Any,
) -> None:
    seq_a, seq_b = reviewed
    hits = _hits_of(seq_a)
    assert _status(mturk, hits[2]) == "Assignable"  # the open one

    refused = api.delete(f"/api/sequences/{seq_a}")
    assert refused.status_code == 409, refused.text
    assert _status(mturk, hits[2]) == "Assignable", "a refused delete expired a HIT"

    resp = api.delete(f"/api/sequences/{seq_a}?force=true")
    assert resp.status_code == 200, resp.text
    for hit_id in hits:  # no worker can take work of the deleted sequence
        assert _status(mturk, hit_id) in ("Unassignable", "Reviewable"), hit_id
        expires = mturk.get_hit(HITId=hit_id)["HIT"]["Expiration"]
        assert expires.timestamp() <= time.time() + 1

    with session_scope() as session:
        report = costs.costs(session)
    # Spent is what it was; committed lost the open slot (the HIT expired), not the bonus
    # still pending.
    assert _split(report.total)[:4] == PROJECT[:4]
    assert _split(report.total)[4:] == ("0.50", "0.50", "0.20", "1.20")
    lines = {line.key: line for line in report.by_sequence}
    deleted = lines[f"deleted:{seq_a}"]
    assert deleted.name.endswith("/grasp (deleted)")
    assert _split(deleted) == ("0.50", "1.00", "0.30", "1.80", "0.00", "0.50", "0.10", "0.60")
    assert _split(lines[str(seq_b)])[-1] == "0.60"
    assert [(line.key, _split(line)) for line in report.by_worker] == [
        (WORKER, ("0.50", "1.00", "0.30", "1.80", "0.00", "0.50", "0.10", "0.60")),
        (WORKER_2, ("0.00",) * 8),
        (WORKER_3, ("0.00", "0.00", "0.00", "0.00", "0.50", "0.00", "0.10", "0.60"))]
    # The endpoint shows the same.
    listed = api.get("/api/crowd/costs").json()
    assert any(line["key"] == f"deleted:{seq_a}" and line["spent"] == "1.80"
               for line in listed["by_sequence"])


def test_a_delete_stops_when_the_marketplace_cannot_expire_a_hit(
    reviewed: tuple[int, int], api: Any, mturk: Any,
) -> None:
    from backend.market import protocol

    seq_a, _ = reviewed
    protocol.inject_faults("UpdateExpirationForHIT", 1000)
    try:
        resp = api.delete(f"/api/sequences/{seq_a}?force=true")
    finally:
        protocol.clear_faults()
    assert resp.status_code >= 500 and "update_expiration_for_hit" in resp.text, resp.text
    assert len(_hits_of(seq_a)) == 3, "the sequence was deleted though its HITs stayed open"
    assert api.delete(f"/api/sequences/{seq_a}?force=true").status_code == 200
