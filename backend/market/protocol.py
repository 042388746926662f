"""The requester API's wire protocol: JSON 1.1 over POST, as botocore speaks it.

One request: authenticate (SigV4), read ``X-Amz-Target: MTurkRequesterServiceV20170117.<Op>``,
parse the JSON body, validate it against the operation's input shape, run the operation in one
unit of work, check the result against the output shape and answer. Every failure becomes an
error body botocore parses: RequestError / ServiceFault with a TurkErrorCode, or the generic
AWS types for authentication and framing. A failed commit is a ServiceFault (the caller may
retry), never a half-written change.
"""

from __future__ import annotations

import json
import logging
import threading
import uuid
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from botocore.model import OperationModel
from sqlalchemy.exc import DBAPIError
from sqlalchemy.orm.exc import StaleDataError

from backend.config import MarketRequester, get_settings
from backend.db import session_scope
from backend.market import clock, ledger, lifecycle, validation
from backend.market.auth import SignedRequest, authenticate
from backend.market.context import Call
from backend.market.errors import (
    PARAMETER_VALIDATION,
    SERVICE_UNAVAILABLE,
    UNSUPPORTED_OPERATION,
    MarketError,
    ProtocolError,
    RequestError,
    ServiceFault,
)
from backend.market.operations import HANDLERS, SPENDING, Handler

log = logging.getLogger(__name__)

TARGET_PREFIX = "MTurkRequesterServiceV20170117."
CONTENT_TYPE = "application/x-amz-json-1.1"


@dataclass(frozen=True)
class WireResponse:
    status: int
    body: bytes
    headers: dict[str, str] = field(default_factory=dict)


def handle(request: SignedRequest) -> WireResponse:
    """Answer one requester API request."""
    request_id = str(uuid.uuid4())
    try:
        return _reply(200, _process(request, request_id), request_id)
    except MarketError as exc:
        return _reply(exc.status_code, exc.body(), request_id)
    except Exception:  # any other failure is ours; the caller may retry
        log.exception("marketplace request %s failed", request_id)
        fault = ServiceFault("The marketplace could not process the request; try again.",
                             SERVICE_UNAVAILABLE)
        return _reply(fault.status_code, fault.body(), request_id)


def _reply(status: int, payload: dict[str, Any], request_id: str) -> WireResponse:
    body = json.dumps(payload, separators=(",", ":")).encode()
    return WireResponse(status, body, {"x-amzn-RequestId": request_id,
                                       "Content-Type": CONTENT_TYPE})


def _operation(request: SignedRequest) -> tuple[str, OperationModel]:
    target = request.header("x-amz-target") or ""
    name = target[len(TARGET_PREFIX):] if target.startswith(TARGET_PREFIX) else ""
    model = validation.operation(name) if name else None
    if model is None:
        raise ProtocolError("UnknownOperationException",
                            f"X-Amz-Target {target!r} is not an operation of {TARGET_PREFIX}")
    return name, model


def _parse_body(request: SignedRequest) -> Any:
    content_type = request.header("content-type") or ""
    if not content_type.startswith(CONTENT_TYPE):
        raise ProtocolError("SerializationException",
                            f"Content-Type must be {CONTENT_TYPE}, got {content_type!r}.")
    if not request.body.strip():
        return {}
    try:
        return json.loads(request.body)
    except (ValueError, UnicodeDecodeError) as exc:
        raise ProtocolError("SerializationException", f"The body is not JSON: {exc}") from None


def _process(request: SignedRequest, request_id: str) -> dict[str, Any]:
    settings = get_settings()
    requester = authenticate(request, settings.market_accounts, datetime.now(UTC))
    name, model = _operation(request)
    params = _parse_body(request)
    found = validation.problems(model.input_shape, params)
    if found:
        raise RequestError(validation.describe(found), PARAMETER_VALIDATION)
    handler = HANDLERS.get(name)
    if handler is None:
        raise RequestError(f"{name} is not offered by this marketplace.", UNSUPPORTED_OPERATION)
    _take_fault(name, after_commit=False)
    result = _run(handler, name, requester, request_id, params)
    _take_fault(name, after_commit=True)
    if settings.market_check_responses:
        broken = validation.problems(model.output_shape, result)
        if broken:
            log.error("%s answered outside its output shape: %s", name, broken)
            raise ServiceFault(f"{name} produced a response outside its output shape: "
                               f"{validation.describe(broken)}", SERVICE_UNAVAILABLE)
    return result


def _run(
    handler: Handler, name: str, requester: MarketRequester, request_id: str,
    params: dict[str, Any],
) -> dict[str, Any]:
    """The operation as one unit of work, after what the clock made due is settled."""
    try:
        with session_scope() as session:
            if name in SPENDING:
                ledger.lock_requester(session, requester.access_key)
            call = Call(session, requester, request_id, clock.now())
            lifecycle.settle_due(session, requester.access_key, call.now)
            return handler(call, params)
    except (DBAPIError, StaleDataError) as exc:
        # A concurrent change won (a unique token, a HIT's version, a lock): nothing was
        # written, and the retry botocore makes will see the winner's result.
        log.warning("%s lost a concurrent write: %s", name, exc)
        raise ServiceFault("A concurrent request changed the same records; try again.",
                           SERVICE_UNAVAILABLE) from exc


# Fault injection, for exercising retries: the next N calls of an operation answer with a
# ServiceFault, before doing anything or after committing (a reply lost on the way back).
_faults: dict[tuple[str, bool], int] = {}
_faults_lock = threading.Lock()


def inject_faults(operation: str, times: int = 1, *, after_commit: bool = False) -> None:
    with _faults_lock:
        _faults[(operation, after_commit)] = times


def clear_faults() -> None:
    with _faults_lock:
        _faults.clear()


def _take_fault(operation: str, after_commit: bool) -> None:
    with _faults_lock:
        left = _faults.get((operation, after_commit), 0)
        if left <= 0:
            return
        _faults[(operation, after_commit)] = left - 1
    raise ServiceFault("Injected fault: the marketplace is temporarily unable to process "
                       "this request.", SERVICE_UNAVAILABLE)
