"""A small client of Prolific's API (docs.prolific.com): there is no official Python SDK.

Every request carries ``Authorization: Token <token>``. Answers become our errors: 429 and 5xx
are "throttled" and retried here with exponential backoff and full jitter (at most
``MAX_ATTEMPTS`` tries, ``MAX_DELAY_S`` between two), 404 "not_found", a 400 about the state of
a study or submission "invalid_state", any other 4xx ``ProviderRefused``; no answer at all is
``ProviderUnreachable`` (never retried here: the request may have been carried out, and only
the caller knows whether it is safe to send again).
"""

from __future__ import annotations

import logging
import random
import time
from typing import Any

import httpx

from backend.config import Settings
from backend.crowd.provider import ProviderError, ProviderRefused, ProviderUnreachable

log = logging.getLogger(__name__)

MAX_ATTEMPTS = 6
BASE_DELAY_S = 0.05
MAX_DELAY_S = 2.0
TIMEOUT_S = 30.0
# Words of a 400's detail that say the thing is in the wrong state, not that a value is wrong.
STATE_WORDS = ("status", "state", "already", "transition")


class ProlificClient:
    """One workspace's API access; thread-safe (one httpx connection pool)."""

    def __init__(self, base_url: str, token: str | None, *, max_attempts: int = MAX_ATTEMPTS,
                 base_delay_s: float = BASE_DELAY_S) -> None:
        self.base_url = base_url.rstrip("/")
        self.token = token
        self.max_attempts = max_attempts
        self.base_delay_s = base_delay_s
        self._http = httpx.Client(base_url=self.base_url, timeout=TIMEOUT_S)

    @classmethod
    def from_settings(cls, settings: Settings) -> ProlificClient:
        return cls(settings.prolific_api_url, settings.prolific_token)

    def close(self) -> None:
        self._http.close()

    def get(self, path: str, **params: Any) -> Any:
        return self.request("GET", path, params=params or None)

    def post(self, path: str, body: dict[str, Any] | None = None) -> Any:
        return self.request("POST", path, json=body or {})

    def patch(self, path: str, body: dict[str, Any]) -> Any:
        return self.request("PATCH", path, json=body)

    def request(self, method: str, path: str, **kwargs: Any) -> Any:
        """The answer's JSON (None for an empty answer); throttled answers are tried again
        after a growing, jittered pause."""
        operation = f"{method} {path}"
        if not self.token:
            raise ProviderError("no Prolific API token: set DEXLABEL_PROLIFIC_TOKEN", operation)
        headers = {"Authorization": f"Token {self.token}"}
        for attempt in range(1, self.max_attempts + 1):
            try:
                reply = self._http.request(method, path, headers=headers, **kwargs)
            except httpx.HTTPError as exc:
                raise ProviderUnreachable(f"Prolific did not answer {operation}: {exc}",
                                          operation) from exc
            throttled = reply.status_code == 429 or reply.status_code >= 500
            if throttled and attempt < self.max_attempts:
                time.sleep(self.backoff_s(attempt, reply))
                continue
            return _answer(reply, operation)
        raise AssertionError("unreachable")  # pragma: no cover

    def backoff_s(self, attempt: int, reply: httpx.Response | None = None) -> float:
        """Full jitter over an exponentially growing ceiling, or the server's Retry-After
        where it names a longer wait (capped at MAX_DELAY_S either way)."""
        ceiling = min(MAX_DELAY_S, self.base_delay_s * 2 ** (attempt - 1))
        wait = random.uniform(0, ceiling)
        retry_after = reply.headers.get("Retry-After") if reply is not None else None
        if retry_after and retry_after.replace(".", "", 1).isdigit():
            wait = max(wait, min(float(retry_after), MAX_DELAY_S))
        log.info("Prolific throttled (attempt %d); waiting %.3f s", attempt, wait)
        return wait


def _answer(reply: httpx.Response, operation: str) -> Any:
    status = reply.status_code
    if status < 400:
        return reply.json() if reply.content else None
    detail = _detail(reply)
    message = f"Prolific refused {operation} ({status}): {detail}"
    if status == 429 or status >= 500:
        raise ProviderError(message, operation, "throttled", provider_code=str(status))
    if status == 404:
        raise ProviderError(message, operation, "not_found", provider_code="404")
    if status in (401, 403):
        raise ProviderError(message, operation, "other", provider_code=str(status))
    if status in (400, 409) and any(word in detail.lower() for word in STATE_WORDS):
        raise ProviderError(message, operation, "invalid_state", provider_code=str(status))
    raise ProviderRefused(message, operation, provider_code=str(status))


def _detail(reply: httpx.Response) -> str:
    """Prolific's error text: ``{"error": {"detail": ...}}`` or a plain body."""
    try:
        body = reply.json()
    except ValueError:
        return reply.text[:300] or reply.reason_phrase
    if isinstance(body, dict):
        error = body.get("error", body)
        if isinstance(error, dict):
            return str(error.get("detail") or error.get("title") or error)[:300]
        return str(error)[:300]
    return str(body)[:300]
