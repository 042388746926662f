"""Request guards that run before routing: NUL characters in the address, and body size.

A NUL in the path or the query string is refused with 422 naming the parameter (no handler or
database sees it). Every request body is counted as it arrives, whatever its framing (a
Content-Length or chunks): past the route's limit the request is answered 413 without reading
the rest. A route sets its own limit with ``openapi_extra=body_limit(n)``, which the OpenAPI
document then shows as ``x-max-body-bytes``; every other route has the default.
"""

from __future__ import annotations

from typing import Any
from urllib.parse import parse_qsl

from fastapi import FastAPI
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.errors import validation_error
from backend.validation import NUL, NUL_MESSAGE

# The largest body any endpoint takes by default: a whole-assignment save of tracks is the
# largest request the product sends.
DEFAULT_MAX_BODY_BYTES = 1_000_000
BODY_LIMIT_KEY = "x-max-body-bytes"


def body_limit(limit: int) -> dict[str, Any]:
    """``openapi_extra`` of a route whose request bodies may be at most ``limit`` bytes."""
    return {BODY_LIMIT_KEY: limit}


def nul_problems(scope: Scope) -> list[dict[str, str]]:
    """A problem for the path and for each query parameter that holds a NUL character."""
    problems = []
    if NUL in scope.get("path", ""):
        problems.append({"field": "path", "message": NUL_MESSAGE})
    query = scope.get("query_string", b"").decode("latin-1")
    if NUL in query or "%00" in query:
        fields = [f"query.{name.replace(NUL, '?')}"
                  for name, value in parse_qsl(query, keep_blank_values=True)
                  if NUL in name or NUL in value]
        problems += [{"field": field, "message": NUL_MESSAGE} for field in fields or ["query"]]
    return problems


class RequestGuardMiddleware:
    """Refuses a NUL character anywhere in the path or query string with 422."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http":
            problems = nul_problems(scope)
            if problems:
                await validation_error(problems)(scope, receive, send)
                return
        await self.app(scope, receive, send)


def _route_limit(scope: Scope, default: int) -> int:
    # Routing has happened by the time a handler reads the body: the route is in the scope.
    extra = getattr(scope.get("route"), "openapi_extra", None) or {}
    return int(extra.get(BODY_LIMIT_KEY, default))


def _too_large(limit: int) -> HTTPException:
    return HTTPException(413, f"the request body is larger than {limit} bytes, the most this "
                              "endpoint accepts")


class BodyLimitMiddleware:
    """Counts each request body's bytes as the app reads them; 413 once past the limit."""

    def __init__(self, app: ASGIApp, default_limit: int = DEFAULT_MAX_BODY_BYTES) -> None:
        self.app = app
        self.default_limit = default_limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        received = 0

        async def counted_receive() -> Message:
            nonlocal received
            limit = _route_limit(scope, self.default_limit)
            if received == 0:
                declared = Headers(scope=scope).get("content-length", "")
                if declared.isdigit() and int(declared) > limit:
                    raise _too_large(limit)
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise _too_large(limit)
            return message

        await self.app(scope, counted_receive, send)


def install_request_guards(app: FastAPI) -> None:
    app.add_middleware(BodyLimitMiddleware)
    app.add_middleware(RequestGuardMiddleware)
