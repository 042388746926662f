"""Prolific's webhooks to us: ``POST /api/crowd/prolific/webhook``, and subscribing to them.

Prolific signs each delivery: ``X-Prolific-Request-Signature`` is
base64(HMAC-SHA256(secret, ``X-Prolific-Request-Timestamp`` + body)) with the workspace's
webhook secret. A request is refused with 401, and nothing changes, when the signature does
not match, when its timestamp is older than ``DEXLABEL_PROLIFIC_WEBHOOK_MAX_AGE_S`` or ahead of
our clock, or when the same signed request was acted on before (a replay: each one acted on
is kept by its signature's digest, in the transaction of the change it made).

``submission.status.change``: the submission is read back from Prolific (the webhook names
it; Prolific's record decides) and a collected one (submitted, approved, rejected) is recorded
by ``crowd sync``'s own check (``accept_record``). ``study.status.change``: our study row
takes the new status. A delivery we could not act on answers 5xx and is retried by Prolific;
one never delivered is caught by the periodic sync, which reads ``submissions()``.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import time
from typing import Any

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from backend.config import Settings, get_settings
from backend.crowd.provider import COLLECTED, SubmissionRecord
from backend.crowd.providers.prolific.client import ProlificClient
from backend.crowd.providers.prolific.models import ProlificStudy, ProlificWebhookEvent
from backend.crowd.providers.prolific.provider import ProlificProvider
from backend.crowd.sync import accept_record
from backend.db import session_scope
from backend.errors import DexlabelError, Unauthorized
from backend.middleware import body_limit

EVENT_TYPES = ("submission.status.change", "study.status.change")
SIGNATURE = "X-Prolific-Request-Signature"
TIMESTAMP = "X-Prolific-Request-Timestamp"
# A sender's clock a little ahead of ours is not a forgery.
FUTURE_SKEW_S = 5.0

router = APIRouter(prefix="/api/crowd/prolific", tags=["crowd"])


class BadWebhook(DexlabelError, status_code=422, code="bad_webhook"):
    """A signed webhook whose body is not the JSON event Prolific documents."""


def sign(secret: str, timestamp: str, body: bytes) -> str:
    """Prolific's signature of a delivery."""
    digest = hmac.new(secret.encode(), timestamp.encode() + body, hashlib.sha256).digest()
    return base64.b64encode(digest).decode()


def verify(settings: Settings, timestamp: str | None, signature: str | None, body: bytes,
           now: float | None = None) -> None:
    """Unauthorized (401) unless the delivery is signed with our secret and fresh."""
    secret = settings.prolific_webhook_secret
    if not secret:
        raise Unauthorized("no Prolific webhook secret is set (DEXLABEL_PROLIFIC_WEBHOOK_SECRET)"
                           "; every webhook is refused")
    if not timestamp or not signature:
        raise Unauthorized(f"the webhook has no {TIMESTAMP} or {SIGNATURE} header")
    if not hmac.compare_digest(sign(secret, timestamp, body), signature):
        raise Unauthorized(f"the webhook's {SIGNATURE} does not match its body and timestamp")
    try:
        sent = float(timestamp)
    except ValueError:
        raise Unauthorized(f"the webhook's {TIMESTAMP} is not a Unix time") from None
    age = (time.time() if now is None else now) - sent
    if age > settings.prolific_webhook_max_age_s:
        raise Unauthorized(f"the webhook was sent {age:.0f} s ago, more than "
                           f"{settings.prolific_webhook_max_age_s:.0f} s "
                           "(DEXLABEL_PROLIFIC_WEBHOOK_MAX_AGE_S)")
    if age < -FUTURE_SKEW_S:
        raise Unauthorized(f"the webhook's {TIMESTAMP} is {-age:.0f} s ahead of our clock")


# An event is a few hundred bytes.
WEBHOOK_MAX_BODY_BYTES = 64_000


@router.post("/webhook", openapi_extra=body_limit(WEBHOOK_MAX_BODY_BYTES),
             responses={401: {"description": "not signed by Prolific, stale, or a replay"}})
async def webhook(request: Request) -> dict[str, str]:
    """A Prolific event (``submission.status.change``, ``study.status.change``)."""
    body = await request.body()
    return await run_in_threadpool(receive, get_settings(), request.headers.get(TIMESTAMP),
                                   request.headers.get(SIGNATURE), body)


def receive(settings: Settings, timestamp: str | None, signature: str | None,
            body: bytes) -> dict[str, str]:
    """Check a delivery and act on it; what was done."""
    verify(settings, timestamp, signature, body)
    assert signature is not None
    digest = hashlib.sha256(signature.encode()).hexdigest()
    if _seen(digest):
        raise Unauthorized("this webhook was received before (a replay); nothing changed")
    event = _event(body)
    kind, resource = event["event_type"], event["resource_id"]
    record = None
    if kind == "submission.status.change":
        provider = ProlificProvider(settings)
        try:
            record = provider.submission(resource)
        finally:
            provider.client.close()
    try:
        with session_scope() as session:
            session.add(ProlificWebhookEvent(digest=digest, event_type=kind[:64],
                                             resource_id=resource[:64]))
            session.flush()
            outcome = _act(session, kind, resource, event, record)
    except IntegrityError:
        raise Unauthorized("this webhook was received before (a replay); nothing changed") \
            from None
    return {"event_type": kind, "resource_id": resource, "outcome": outcome}


def _act(session: Session, kind: str, resource: str, event: dict[str, Any],
         record: SubmissionRecord | None) -> str:
    if kind == "study.status.change":
        study = session.scalar(select(ProlificStudy).where(ProlificStudy.study_id == resource))
        if study is None:
            return "unknown"
        study.status = str(event.get("status", ""))[:32]
        return "updated"
    if kind == "submission.status.change":
        if record is None:
            return "unknown"
        if record.status not in COLLECTED:
            return record.status
        outcome, _ = accept_record(session, record)
        return outcome
    return "ignored"


def _seen(digest: str) -> bool:
    with session_scope() as session:
        return session.scalar(select(ProlificWebhookEvent.id)
                              .where(ProlificWebhookEvent.digest == digest)) is not None


def _event(body: bytes) -> dict[str, Any]:
    try:
        event = json.loads(body)
    except ValueError:
        raise BadWebhook("the webhook's body is not JSON") from None
    if not isinstance(event, dict) or not all(isinstance(event.get(name), str) and event[name]
                                              for name in ("event_type", "resource_id")):
        raise BadWebhook("the webhook names no event_type and resource_id")
    return event


def subscribe(settings: Settings, target_url: str) -> dict[str, Any]:
    """Subscribe ``target_url`` (our webhook route, public https) to the events we act on,
    once each; where no secret is set yet, make the workspace's secret and hand it back (set
    it as DEXLABEL_PROLIFIC_WEBHOOK_SECRET)."""
    workspace = settings.prolific_workspace_id
    if not workspace:
        raise DexlabelError("set DEXLABEL_PROLIFIC_WORKSPACE_ID to subscribe to Prolific's "
                            "webhooks", field="prolific_workspace_id")
    client = ProlificClient.from_settings(settings)
    try:
        return _subscribe(client, workspace, settings.prolific_webhook_secret, target_url)
    finally:
        client.close()


def _subscribe(client: ProlificClient, workspace: str, secret_set: str | None,
               target_url: str) -> dict[str, Any]:
    secret = None
    if not secret_set:
        secret = str(client.post("/api/v1/hooks/secrets/", {"workspace_id": workspace})["value"])
    listed = client.get("/api/v1/hooks/subscriptions/", workspace_id=workspace)
    have = {(item.get("event_type"), item.get("target_url")): str(item["id"])
            for item in listed.get("results", [])}
    ids = []
    for event_type in EVENT_TYPES:
        found = have.get((event_type, target_url))
        if found is None:
            found = str(client.post("/api/v1/hooks/subscriptions/", {
                "workspace_id": workspace, "event_type": event_type,
                "target_url": target_url})["id"])
        ids.append(found)
    return {"subscriptions": ids, "secret": secret}
