"""Publishing names its provider: the rows it writes, the cost in that provider's fees and
currency, the cost report's per-provider line, and a provider this installation lacks."""

from __future__ import annotations

from typing import Any

from sqlalchemy import select

from backend.crowd import costs
from backend.db import session_scope
from tests.backend.crowd.test_costs import PROJECT, _split, reviewed

__all__ = ["reviewed"]


def test_a_publish_names_its_provider_and_prices_in_its_fees(tasks: list[int], api: Any) -> None:
    from backend.crowd.models import CrowdHit

    dry = api.post("/api/crowd/publish", json={"provider": "mturk", "dry_run": True,
                                               "min_approval_rate": None})
    assert dry.status_code == 200, dry.text
    cost = dry.json()["cost"]
    assert (cost["provider"], cost["currency"], cost["hits"], cost["total"]) == (
        "mturk", "USD", 5, "3.00")
    done = api.post("/api/crowd/publish", json={"provider": "mturk", "min_approval_rate": None})
    assert done.status_code == 200 and done.json()["created"] == 5, done.text
    with session_scope() as session:
        assert set(session.scalars(select(CrowdHit.provider))) == {"mturk"}
    refused = api.post("/api/crowd/publish", json={"provider": "mechanical"})
    assert refused.status_code == 422 and refused.json()["fields"][0]["field"] == "provider"


def test_the_cost_report_has_a_line_per_provider_in_its_currency(
    reviewed: tuple[int, int],
) -> None:
    from backend.crowd.models import CrowdPayment, CrowdSubmission

    with session_scope() as session:
        report = costs.costs(session)
        providers = {*session.scalars(select(CrowdPayment.provider)),
                     *session.scalars(select(CrowdSubmission.provider))}
    assert providers == {"mturk"}
    assert [(line.key, line.currency, _split(line)) for line in report.by_provider] == [
        ("mturk", "USD", PROJECT)]
    assert report.total.currency == "USD"
