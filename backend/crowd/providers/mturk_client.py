"""The requester's boto3 ``mturk`` client, used only by the mturk provider
(``backend.crowd.providers.mturk``): with it, the only module of the crowd domain touching boto3.

It points at the built-in marketplace by default (``{INTERNAL_URL}/mturk``, or without one
``{PUBLIC_URL}/mturk``, with the dev requester pair; with neither set, at the address this
instance's running ``serve`` or ``demo`` recorded) and at AWS or any MTurk-compatible endpoint
by setting. Marketplace errors, and a marketplace that cannot be reached, come back as our own
errors so routers and the CLI render them like every other failure (one line naming the URL
and the setting, no botocore traceback).
A refusal of the request's values (a worker id of the wrong form, an unknown qualification
type) is the caller's input at fault: 422 naming the fields; any other failure is 502.

The errors are the provider errors of ``backend.crowd.provider`` (their ``reason`` mapped from
MTurk's TurkErrorCodes, see ``reason_of``), under the names and ``error`` codes API clients
have seen since before there were other providers ("marketplace_error", "marketplace_refused",
"marketplace_unreachable"), and carrying the ``turk_code``.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Iterator, Mapping
from typing import Any
from urllib.parse import urlparse

import boto3
import botocore.session
from botocore.config import Config
from botocore.exceptions import (
    BotoCoreError,
    ClientError,
    ConnectTimeoutError,
    HTTPClientError,
    ParamValidationError,
    ReadTimeoutError,
    SSLError,
)
from botocore.exceptions import ConnectionError as BotoConnectionError

from backend.config import DEV_MARKET_REQUESTERS, Settings
from backend.crowd.provider import ProviderError, ProviderRefused, ProviderUnreachable
from backend.errors import DexlabelError
from backend.instance import public_url, recorded_server, server_file

REGION = "us-east-1"
AWS_PRODUCTION_ENDPOINT = "https://mturk-requester.us-east-1.amazonaws.com"
AWS_SANDBOX_ENDPOINT = "https://mturk-requester-sandbox.us-east-1.amazonaws.com"
BUILTIN_PATH = "/mturk"
# Standard-mode retries: 5xx (ServiceFault) and throttling are retried by botocore itself,
# which is why every call that pays or publishes carries a UniqueRequestToken.
DEFAULT_ATTEMPTS = 5
# The client's note of what to check when its endpoint does not answer (see unreachable()).
HINT = "dexlabel_hint"

# boto3 builds the client class at run time; there is no class to name in annotations.
MTurkClient = Any


class MarketplaceError(ProviderError):
    """The marketplace refused a request; ``turk_code`` is its TurkErrorCode; ``retryable``
    when it did not answer or answered "try again" (a 5xx or throttling) rather than no."""

    code = "marketplace_error"

    def __init__(self, detail: str, operation: str, turk_code: str = "",
                 retryable: bool = False, reason: str | None = None,
                 unit_id: str | None = None) -> None:
        ProviderError.__init__(self, detail, operation,
                               reason or reason_of(turk_code, detail, retryable), retryable,
                               unit_id, provider_code=turk_code)
        self.extra["turk_code"] = turk_code
        self.turk_code = turk_code


class MarketplaceRefused(MarketplaceError, ProviderRefused):
    """The marketplace refused the request's values: the caller's input, so 422; ``fields``
    names our fields behind the marketplace parameters it objected to."""

    status_code = 422
    code = "marketplace_refused"

    def __init__(self, detail: str, operation: str, turk_code: str,
                 fields: list[dict[str, str]]) -> None:
        MarketplaceError.__init__(self, detail, operation, turk_code, reason="refused")
        if fields:
            self.extra["fields"] = fields


# TurkErrorCodes of refusals caused by the values sent (botocore's own checks of the request
# shape count too): the marketplace's validation codes, and an unknown qualification type
# (its id is only ever the caller's).
PARAMETER_VALIDATION = "ParameterValidationError"
INPUT_REFUSALS = frozenset({
    PARAMETER_VALIDATION,
    "ValidationException",
    "AWS.MechanicalTurk.InvalidParameterValue",
    "AWS.MechanicalTurk.QualificationTypeDoesNotExist",
    "AWS.MechanicalTurk.InvalidMaximumAssignmentsIncrease",
})
# Answers that mean "not now" rather than "no".
THROTTLING = frozenset({"Throttling", "ThrottlingException", "RequestLimitExceeded",
                        "ServiceUnavailable", "AWS.ServiceUnavailable"})
# The parameter a refusal is about, where its message does not name it.
REFUSED_PARAMETER = {
    "AWS.MechanicalTurk.InvalidMaximumAssignmentsIncrease": "NumberOfAdditionalAssignments",
}


# Markers of the other reasons: "already exists" (HitAlreadyExists, whose message names the
# HIT), a decision on an assignment in another state, a token used before within 24 hours.
ALREADY_EXISTS = "AlreadyExists"
INVALID_STATE = "AWS.MechanicalTurk.InvalidAssignmentState"
REPLAYED = "already been processed"
_HIT_ID_IN_MESSAGE = re.compile(r"HIT\s?Id\W*([A-Za-z0-9]+)", re.IGNORECASE)


def reason_of(turk_code: str, message: str, retryable: bool) -> str:
    """The provider-neutral reason (``backend.crowd.provider.REASONS``) of a marketplace
    answer."""
    if REPLAYED in message:
        return "replayed"
    if turk_code in INPUT_REFUSALS:
        return "refused"
    if turk_code.endswith(ALREADY_EXISTS):
        return "already_exists"
    if turk_code == INVALID_STATE:
        return "invalid_state"
    if "DoesNotExist" in turk_code or "does not exist" in message:
        return "not_found"
    if retryable:
        return "throttled"
    return "other"


def hit_id_in(message: str) -> str | None:
    """The HIT id a HitAlreadyExists message names."""
    match = _HIT_ID_IN_MESSAGE.search(message)
    return match.group(1) if match else None


class MarketplaceUnreachable(MarketplaceError, ProviderUnreachable):
    """No answer from the marketplace at ``url`` (refused, timed out, closed, TLS)."""

    code = "marketplace_unreachable"

    def __init__(self, detail: str, operation: str) -> None:
        MarketplaceError.__init__(self, detail, operation, reason="throttled", retryable=True)


class CrowdConfigError(DexlabelError, status_code=500, code="crowd_config_error"):
    pass


def builtin_endpoint(settings: Settings) -> str:
    """The built-in marketplace as this process reaches it: at DEXLABEL_INTERNAL_URL when set
    (a worker container, for which the browsers' PUBLIC_URL is not the app), else at the
    public address."""
    base = settings.internal_url or public_url(settings)
    return base.rstrip("/") + BUILTIN_PATH


def endpoint_hint(settings: Settings) -> str:
    """What to check when the requester endpoint does not answer: the setting that chose it."""
    if settings.mturk_endpoint_url:
        return "check DEXLABEL_MTURK_ENDPOINT_URL"
    if settings.mturk_use_aws:
        return "check DEXLABEL_MTURK_USE_AWS, DEXLABEL_MTURK_SANDBOX and the network"
    if settings.internal_url:
        return ("check DEXLABEL_INTERNAL_URL (the app's address from this host; the built-in "
                "marketplace is served at its /mturk)")
    if "public_url" in settings.model_fields_set:
        return "check DEXLABEL_PUBLIC_URL (the built-in marketplace is served at its /mturk)"
    if recorded_server(settings):
        return (f"the server recorded in {server_file(settings)} does not answer; "
                "or set DEXLABEL_PUBLIC_URL to the app's address")
    return ("no `dexlabel serve` or `dexlabel demo` of this instance is running: start one, "
            "or set DEXLABEL_PUBLIC_URL to the app's address")


def endpoint_url(settings: Settings) -> str:
    """The requester endpoint; anything but the built-in marketplace must be HTTPS."""
    if settings.mturk_endpoint_url:
        url = settings.mturk_endpoint_url.rstrip("/")
    elif settings.mturk_use_aws:
        url = AWS_SANDBOX_ENDPOINT if settings.mturk_sandbox else AWS_PRODUCTION_ENDPOINT
    else:
        return builtin_endpoint(settings)
    if url != builtin_endpoint(settings) and urlparse(url).scheme != "https":
        raise CrowdConfigError(
            f"DEXLABEL_MTURK_ENDPOINT_URL {url} must use https (only the built-in marketplace "
            f"at {builtin_endpoint(settings)} may be plain http)")
    return url


def credentials(settings: Settings) -> tuple[str, str]:
    """(access key id, secret); unset = the built-in marketplace's dev requester pair."""
    key, secret = settings.mturk_access_key_id, settings.mturk_secret_access_key
    if bool(key) != bool(secret):
        raise CrowdConfigError(
            "set both DEXLABEL_MTURK_ACCESS_KEY_ID and DEXLABEL_MTURK_SECRET_ACCESS_KEY")
    if key and secret:
        return key, secret
    dev_key, dev_secret = DEV_MARKET_REQUESTERS.split(":", 1)
    return dev_key, dev_secret


# One botocore session for every client: it loads the service model once (a new session per
# client reads it again, about 0.2 s a request). A session is not safe to build clients from in
# several threads at once, hence the lock; the clients themselves are.
_botocore_session: botocore.session.Session | None = None
_session_lock = threading.Lock()


def make_client(settings: Settings, attempts: int = DEFAULT_ATTEMPTS) -> MTurkClient:
    global _botocore_session
    key, secret = credentials(settings)
    config = Config(retries={"total_max_attempts": attempts, "mode": "standard"})
    url = endpoint_url(settings)
    with _session_lock:
        if _botocore_session is None:
            _botocore_session = botocore.session.get_session()
        client = boto3.session.Session(botocore_session=_botocore_session).client(
            "mturk", endpoint_url=url, region_name=REGION,
            aws_access_key_id=key, aws_secret_access_key=secret, config=config)
    # Read back by unreachable() to name the setting in the message (ClientMeta declares no
    # such attribute, hence setattr).
    setattr(client.meta, HINT, endpoint_hint(settings))
    return client


def unreachable(client: MTurkClient, operation: str, exc: BotoCoreError) -> MarketplaceError:
    """The error for a marketplace that did not answer: its URL and the setting behind it."""
    if isinstance(exc, (ConnectTimeoutError, ReadTimeoutError)):
        reason = "timed out"
    elif isinstance(exc, SSLError):
        reason = "TLS failed"
    elif isinstance(exc, HTTPClientError):
        reason = "connection closed"
    else:
        reason = "no connection"
    hint = getattr(client.meta, HINT, "check DEXLABEL_MTURK_ENDPOINT_URL")
    return MarketplaceUnreachable(
        f"the marketplace at {client.meta.endpoint_url} cannot be reached ({reason}); {hint}",
        operation)


def snake_case(name: str) -> str:
    """A marketplace parameter's name as our fields spell it: HITId -> hit_id."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", name).lower()


def refused_fields(message: str, turk_code: str, params: Mapping[str, Any],
                   fields: Mapping[str, str] | None = None) -> list[dict[str, str]]:
    """Our fields behind the parameters a refusal names (``fields`` maps a marketplace
    parameter to our field where the names differ; others are the snake_case name)."""
    named = set()
    for param in params:
        if re.search(rf"\b{re.escape(param)}\b", message):
            named.add(param)
    missing = re.fullmatch(r"AWS\.MechanicalTurk\.(\w+)DoesNotExist", turk_code)
    if missing and f"{missing[1]}Id" in params:
        named.add(f"{missing[1]}Id")
    if REFUSED_PARAMETER.get(turk_code) in params:
        named.add(REFUSED_PARAMETER[turk_code])
    names = fields or {}
    return [{"field": names.get(param, snake_case(param)), "message": message}
            for param in params if param in named]


def _failure(exc: Exception, operation: str, params: Mapping[str, Any],
             fields: Mapping[str, str] | None) -> MarketplaceError:
    """The MarketplaceError for a botocore failure other than an unreachable marketplace."""
    retryable = False
    if isinstance(exc, ClientError):
        error = exc.response.get("Error", {})
        turk_code = str(exc.response.get("TurkErrorCode", "") or error.get("Code", ""))
        message = str(error.get("Message", str(exc)))
        status = int(exc.response.get("ResponseMetadata", {}).get("HTTPStatusCode", 0) or 0)
        retryable = status >= 500 or turk_code in THROTTLING
    else:
        turk_code = PARAMETER_VALIDATION if isinstance(exc, ParamValidationError) else ""
        message = str(exc)
    if turk_code in INPUT_REFUSALS:
        return MarketplaceRefused(f"{operation}: {message}", operation, turk_code,
                                  refused_fields(message, turk_code, params, fields))
    unit_id = hit_id_in(message) if turk_code.endswith("HitAlreadyExists") else None
    return MarketplaceError(f"{operation}: {message}", operation, turk_code, retryable,
                            unit_id=unit_id)


def call(client: MTurkClient, operation: str, /, **params: Any) -> dict[str, Any]:
    """``client.<operation>(**params)`` with marketplace failures as MarketplaceError."""
    return call_naming(client, operation, None, **params)


def call_naming(client: MTurkClient, operation: str, fields: Mapping[str, str] | None, /,
                **params: Any) -> dict[str, Any]:
    """``call``, where ``fields`` maps a parameter to the request field it came from where the
    names differ (``{"MessageText": "message"}``), for a refusal of its value to name it."""
    try:
        reply: dict[str, Any] = getattr(client, operation)(**params)
        return reply
    except (BotoConnectionError, HTTPClientError) as exc:
        raise unreachable(client, operation, exc) from exc
    except (ClientError, BotoCoreError) as exc:
        raise _failure(exc, operation, params, fields) from exc


def paginate(client: MTurkClient, operation: str, key: str, **params: Any) -> Iterator[Any]:
    """Every item under ``key`` across the pages of ``operation`` (botocore's paginator)."""
    try:
        for page in client.get_paginator(operation).paginate(**params):
            yield from page.get(key, [])
    except (BotoConnectionError, HTTPClientError) as exc:
        raise unreachable(client, operation, exc) from exc
    except (ClientError, BotoCoreError) as exc:
        raise _failure(exc, operation, params, None) from exc
