"""The requester's boto3 ``mturk`` client: the only module of the crowd domain touching boto3.

It points at the built-in marketplace by default (``{PUBLIC_URL}/mturk`` with the dev requester
pair; with PUBLIC_URL unset, at the address this instance's running ``serve`` or ``demo``
recorded) and at AWS or any MTurk-compatible endpoint by setting. Marketplace errors, and a
marketplace that cannot be reached, come back as our own errors so routers and the CLI render
them like every other failure (one line naming the URL and the setting, no botocore traceback).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any
from urllib.parse import urlparse

import boto3
from botocore.config import Config
from botocore.exceptions import (
    BotoCoreError,
    ClientError,
    ConnectTimeoutError,
    HTTPClientError,
    ReadTimeoutError,
    SSLError,
)
from botocore.exceptions import ConnectionError as BotoConnectionError

from backend.config import DEV_MARKET_REQUESTERS, Settings
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


class MarketplaceError(DexlabelError):
    """The marketplace refused a request; ``turk_code`` is its TurkErrorCode."""

    status_code = 502
    code = "marketplace_error"

    def __init__(self, detail: str, operation: str, turk_code: str = "") -> None:
        super().__init__(detail, operation=operation, turk_code=turk_code)
        self.operation = operation
        self.turk_code = turk_code


class MarketplaceUnreachable(MarketplaceError):
    """No answer from the marketplace at ``url`` (refused, timed out, closed, TLS)."""

    code = "marketplace_unreachable"


class CrowdConfigError(DexlabelError):
    status_code = 500
    code = "crowd_config_error"


def builtin_endpoint(settings: Settings) -> str:
    return public_url(settings).rstrip("/") + BUILTIN_PATH


def endpoint_hint(settings: Settings) -> str:
    """What to check when the requester endpoint does not answer: the setting that chose it."""
    if settings.mturk_endpoint_url:
        return "check DEXLABEL_MTURK_ENDPOINT_URL"
    if settings.mturk_use_aws:
        return "check DEXLABEL_MTURK_USE_AWS, DEXLABEL_MTURK_SANDBOX and the network"
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


def make_client(settings: Settings, attempts: int = DEFAULT_ATTEMPTS) -> MTurkClient:
    key, secret = credentials(settings)
    config = Config(retries={"total_max_attempts": attempts, "mode": "standard"})
    client = boto3.session.Session().client(
        "mturk", endpoint_url=endpoint_url(settings), region_name=REGION,
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


def call(client: MTurkClient, operation: str, **params: Any) -> dict[str, Any]:
    """``client.<operation>(**params)`` with marketplace failures as MarketplaceError."""
    try:
        reply: dict[str, Any] = getattr(client, operation)(**params)
        return reply
    except ClientError as exc:
        error = exc.response.get("Error", {})
        turk_code = str(exc.response.get("TurkErrorCode", "") or error.get("Code", ""))
        raise MarketplaceError(
            f"{operation}: {error.get('Message', str(exc))}", operation, turk_code) from exc
    except (BotoConnectionError, HTTPClientError) as exc:
        raise unreachable(client, operation, exc) from exc
    except BotoCoreError as exc:
        raise MarketplaceError(f"{operation}: {exc}", operation) from exc


def paginate(client: MTurkClient, operation: str, key: str, **params: Any) -> Iterator[Any]:
    """Every item under ``key`` across the pages of ``operation`` (botocore's paginator)."""
    try:
        for page in client.get_paginator(operation).paginate(**params):
            yield from page.get(key, [])
    except ClientError as exc:
        error = exc.response.get("Error", {})
        raise MarketplaceError(f"{operation}: {error.get('Message', str(exc))}", operation,
                               str(exc.response.get("TurkErrorCode", ""))) from exc
    except (BotoConnectionError, HTTPClientError) as exc:
        raise unreachable(client, operation, exc) from exc
    except BotoCoreError as exc:
        raise MarketplaceError(f"{operation}: {exc}", operation) from exc
