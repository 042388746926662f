"""Prolific's webhooks to our route: a signed, fresh delivery records the submission as
`crowd sync` does; a wrong signature, a stale timestamp or a replay answers 401 and changes
nothing; a delivery we could not act on is retried by the sender and then recorded."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from fastapi import FastAPI
from sqlalchemy import func, select

from backend.crowd.models import CrowdSubmission
from backend.crowd.providers.prolific.models import ProlificStudy, ProlificWebhookEvent
from backend.crowd.providers.prolific.webhooks import SIGNATURE, TIMESTAMP, sign
from backend.db import session_scope
from tests.backend.crowd.conftest import WEBHOOK_SECRET
from tests.backend.crowd.prolific_double import serve
from tests.backend.crowd.test_prolific_publish import units


@pytest.fixture
def our_route(prolific: Any) -> Iterator[str]:
    """Our webhook route served on loopback and subscribed at the double; its URL."""
    from backend.config import get_settings
    from backend.crowd.providers.prolific.webhooks import router, subscribe
    from backend.errors import install_error_handlers

    app = FastAPI()
    install_error_handlers(app)
    app.include_router(router)
    with serve(app) as base:
        url = f"{base}/api/crowd/prolific/webhook"
        made = subscribe(get_settings(), url)
        assert made["secret"] is None and len(made["subscriptions"]) == 2
        assert subscribe(get_settings(), url)["subscriptions"] == made["subscriptions"]
        yield url


@pytest.fixture
def submitted(prolific: Any, prolific_provider: Any) -> tuple[str, int]:
    """A participant took unit 0 of a published study, our page opened their assignment,
    and they submitted; (Prolific's submission id, our assignment id)."""
    from backend.annotation.models import Assignment
    from tests.backend.crowd.helpers import make_tasks

    (task_id,) = make_tasks(1)
    (unit,) = prolific_provider.publish(units(1))
    study_id = unit.unit_id.split(":")[0]
    submission = prolific.take(study_id, 0, "PIDA")
    with session_scope() as session:
        ours = Assignment(task_id=task_id, worker_id="PIDA", external_id=submission,
                          hit_id=unit.unit_id, status="submitted")
        session.add(ours)
        session.flush()
        return submission, ours.id


def signed(body: dict[str, Any], sent: float | None = None,
           secret: str = WEBHOOK_SECRET) -> tuple[bytes, dict[str, str]]:
    raw = json.dumps(body).encode()
    timestamp = str(int(time.time() if sent is None else sent))
    return raw, {TIMESTAMP: timestamp, SIGNATURE: sign(secret, timestamp, raw),
                 "Content-Type": "application/json"}


def recorded() -> list[tuple[str, str, str]]:
    with session_scope() as session:
        return [tuple(row) for row in session.execute(select(
            CrowdSubmission.hit_id, CrowdSubmission.worker_id, CrowdSubmission.market_status))]


def events() -> int:
    with session_scope() as session:
        return session.scalar(select(func.count()).select_from(ProlificWebhookEvent)) or 0


def test_a_delivered_submission_is_recorded_as_sync_records_it(
        prolific: Any, our_route: str, submitted: tuple[str, int]) -> None:
    submission, _ = submitted
    assert prolific.deliver("submission.status.change", submission, "AWAITING REVIEW") == [200]
    ((unit, worker, status),) = recorded()
    assert (unit.endswith(":0"), worker, status) == (True, "PIDA", "Submitted")


@pytest.mark.parametrize("how", ["wrong secret", "body changed", "no signature"])
def test_a_wrong_signature_answers_401_and_changes_nothing(
        prolific: Any, our_route: str, submitted: tuple[str, int], how: str) -> None:
    body = {"event_type": "submission.status.change", "resource_id": submitted[0],
            "status": "AWAITING REVIEW"}
    raw, headers = signed(body, secret="not-the-secret" if how == "wrong secret"
                          else WEBHOOK_SECRET)
    if how == "body changed":
        raw = raw.replace(b"AWAITING REVIEW", b"APPROVED")
    if how == "no signature":
        del headers[SIGNATURE]
    reply = httpx.post(our_route, content=raw, headers=headers)
    assert reply.status_code == 401, reply.text
    assert (recorded(), events()) == ([], 0)
    assert not any(path.startswith("/api/v1/submissions/") for _, path in prolific.requests)


@pytest.mark.parametrize("offset_s", [-301, -3600, 120])
def test_a_stale_or_future_timestamp_answers_401(
        prolific: Any, our_route: str, submitted: tuple[str, int], offset_s: int) -> None:
    raw, headers = signed({"event_type": "submission.status.change",
                           "resource_id": submitted[0]}, sent=time.time() + offset_s)
    reply = httpx.post(our_route, content=raw, headers=headers)
    assert reply.status_code == 401
    assert ("ago" if offset_s < 0 else "ahead") in reply.json()["detail"]
    assert (recorded(), events()) == ([], 0)


def test_a_replayed_webhook_changes_nothing(
        prolific: Any, prolific_provider: Any, our_route: str,
        submitted: tuple[str, int]) -> None:
    submission, _ = submitted
    raw, headers = signed({"event_type": "submission.status.change",
                           "resource_id": submission, "status": "AWAITING REVIEW"})
    assert httpx.post(our_route, content=raw, headers=headers).status_code == 200
    assert recorded()[0][2] == "Submitted"
    # Prolific's record moves on; the old delivery sent again must not act on it.
    prolific.submissions[submission]["status"] = "APPROVED"
    reads = len(prolific.requests)

    reply = httpx.post(our_route, content=raw, headers=headers)
    assert reply.status_code == 401 and "replay" in reply.json()["detail"]
    assert recorded()[0][2] == "Submitted"
    assert events() == 1
    assert len(prolific.requests) == reads


def test_a_delivery_we_could_not_act_on_is_retried_and_then_recorded(
        prolific: Any, our_route: str, submitted: tuple[str, int]) -> None:
    prolific.faults["submission_503"] = 6  # our read of it fails past the client's retries
    codes = prolific.deliver("submission.status.change", submitted[0], "AWAITING REVIEW")
    assert codes == [502, 200]
    assert [status for _, _, status in recorded()] == ["Submitted"]
    assert events() == 1


def test_a_study_status_change_updates_our_study(prolific: Any, prolific_provider: Any,
                                                 our_route: str) -> None:
    (unit,) = prolific_provider.publish(units(1))
    study_id = unit.unit_id.split(":")[0]
    assert prolific.deliver("study.status.change", study_id, "AWAITING REVIEW") == [200]
    with session_scope() as session:
        status = session.scalar(select(ProlificStudy.status)
                                .where(ProlificStudy.study_id == study_id))
    assert status == "AWAITING REVIEW"


def test_subscribing_without_a_secret_makes_the_workspaces_secret(
        prolific: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    from backend.config import get_settings
    from backend.crowd.providers.prolific.webhooks import EVENT_TYPES, subscribe

    monkeypatch.delenv("DEXLABEL_PROLIFIC_WEBHOOK_SECRET")
    get_settings.cache_clear()
    made = subscribe(get_settings(), "https://labs.example.org/api/crowd/prolific/webhook")
    assert made["secret"] == prolific.secret != WEBHOOK_SECRET
    assert sorted(s["event_type"] for s in prolific.subscriptions) == sorted(EVENT_TYPES)


def test_the_app_serves_the_route_and_refuses_an_unsigned_event(prolific: Any) -> None:
    from fastapi.testclient import TestClient

    from backend.app import create_app

    with TestClient(create_app()) as client:
        reply = client.post("/api/crowd/prolific/webhook",
                            json={"event_type": "study.status.change", "resource_id": "x"})
    assert reply.status_code == 401
    assert reply.json()["error"] == "unauthorized"
    assert events() == 0


def test_a_missed_webhook_is_caught_by_reading_the_submissions(
        prolific: Any, prolific_provider: Any, submitted: tuple[str, int]) -> None:
    """No delivery at all: the periodic sync's read of ``submissions()`` records it alike."""
    from backend.crowd.sync import sync

    submission, ours = submitted
    unit_id = f"{prolific.submissions[submission]['study_id']}:0"
    with session_scope() as session:
        result = sync(session, prolific_provider, [unit_id])
        assert (result.accepted, result.accepted_ids) == (1, [ours])
    assert [status for _, _, status in recorded()] == ["Submitted"]
