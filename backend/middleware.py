"""Request guards that run for every request, whatever route it reaches: NUL characters and
body size.

A NUL in the path or the query string is refused with 422 naming the parameter, before routing.
A JSON or form body is checked when its last byte arrives, before the handler parses it: a NUL
in any of its strings (keys included) is refused with 422 naming the field. No handler or
database sees a NUL (PostgreSQL text cannot hold one).

Every request body is counted as it arrives, whatever its framing (a Content-Length or chunks):
past the route's limit the request is answered 413 without reading the rest. A route sets its
own limit with ``openapi_extra=body_limit(n)``, which the OpenAPI document then shows as
``x-max-body-bytes``; every other route has the default.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Coroutine
from typing import Any
from urllib.parse import parse_qsl

import msgspec
from fastapi import FastAPI, Request, Response
from fastapi.routing import APIRoute
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.errors import InvalidFields, validation_error
from backend.validation import NUL, NUL_MESSAGE, nul_fields

# The largest body any endpoint takes by default: a whole-assignment save of tracks is the
# largest request the product sends.
DEFAULT_MAX_BODY_BYTES = 1_000_000
BODY_LIMIT_KEY = "x-max-body-bytes"
# How a NUL can appear in a JSON body (raw control characters are invalid JSON anyway) and in
# a form body.
_JSON_NUL = b"\\u0000"
_FORM_NUL = b"%00"


def body_limit(limit: int) -> dict[str, Any]:
    """``openapi_extra`` of a route whose request bodies may be at most ``limit`` bytes."""
    return {BODY_LIMIT_KEY: limit}


def _problems(fields: list[str]) -> list[dict[str, str]]:
    return [{"field": field, "message": NUL_MESSAGE} for field in fields]


def _form_nul_fields(text: str, prefix: str) -> list[str]:
    return [f"{prefix}{name.replace(NUL, '?')}"
            for name, value in parse_qsl(text, keep_blank_values=True)
            if NUL in name or NUL in value]


def address_nul_problems(scope: Scope) -> list[dict[str, str]]:
    """A problem for the path and for each query parameter that holds a NUL character."""
    fields = ["path"] if NUL in scope.get("path", "") else []
    query = scope.get("query_string", b"").decode("latin-1")
    if NUL in query or "%00" in query:
        fields += _form_nul_fields(query, "query.") or ["query"]
    return _problems(fields)


def _media_type(content_type: str) -> str:
    return content_type.split(";", 1)[0].strip().lower()


def _checks_body(content_type: str) -> bool:
    kind = _media_type(content_type)
    return "json" in kind or kind == "application/x-www-form-urlencoded"


def body_nul_fields(body: bytes, content_type: str) -> list[str]:
    """The fields of a JSON or form body whose strings hold a NUL; [] for other bodies and for
    a body that does not parse (the handler reports that)."""
    kind = _media_type(content_type)
    if "json" in kind and _JSON_NUL in body:
        try:
            return nul_fields(json.loads(body))
        except ValueError:
            return []
    if kind == "application/x-www-form-urlencoded" and _FORM_NUL in body:
        return _form_nul_fields(body.decode("latin-1"), "")
    return []


def _route_limit(scope: Scope, default: int) -> int:
    # Routing has happened by the time a handler reads the body: the route is in the scope.
    extra = getattr(scope.get("route"), "openapi_extra", None) or {}
    return int(extra.get(BODY_LIMIT_KEY, default))


def _too_large(limit: int) -> HTTPException:
    return HTTPException(413, f"the request body is larger than {limit} bytes, the most this "
                              "endpoint accepts")


class RequestGuardMiddleware:
    """Refuses NUL characters (422) and bodies past their route's limit (413)."""

    def __init__(self, app: ASGIApp, default_limit: int = DEFAULT_MAX_BODY_BYTES) -> None:
        self.app = app
        self.default_limit = default_limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        problems = address_nul_problems(scope)
        if problems:
            await validation_error(problems)(scope, receive, send)
            return
        headers = Headers(scope=scope)
        content_type = headers.get("content-type", "")
        declared = headers.get("content-length", "")
        checked = _checks_body(content_type)
        body = bytearray()
        received = 0

        async def guarded_receive() -> Message:
            nonlocal received
            limit = _route_limit(scope, self.default_limit)
            if received == 0 and declared.isdigit() and int(declared) > limit:
                raise _too_large(limit)
            message = await receive()
            if message["type"] != "http.request":
                return message
            chunk = message.get("body", b"")
            received += len(chunk)
            if received > limit:
                raise _too_large(limit)
            if checked:
                body.extend(chunk)
            if checked and not message.get("more_body", False):
                fields = body_nul_fields(bytes(body), content_type)
                body.clear()
                if fields:
                    raise InvalidFields(_problems(fields))
            return message

        await self.app(scope, guarded_receive, send)


def install_request_guards(app: FastAPI) -> None:
    app.add_middleware(RequestGuardMiddleware)


_JSON_DECODER = msgspec.json.Decoder()


class _JSONRequest(Request):
    """A request whose JSON body msgspec parses, about twice as fast as the standard library
    on a 32 KB track save (the most frequent request). A body msgspec refuses (bad JSON, but
    also what the standard library takes and msgspec does not: NaN, integers past 64 bits,
    other encodings) goes to the standard library as before, so every body gets the value
    and the error it got before."""

    async def json(self) -> Any:
        if not hasattr(self, "_json"):
            body = await self.body()
            try:
                self._json = _JSON_DECODER.decode(body)
            except msgspec.DecodeError:
                self._json = json.loads(body)
        return self._json


class JSONBodyRoute(APIRoute):
    """A route whose JSON body is parsed by :class:`_JSONRequest`."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def handle(request: Request) -> Response:
            return await handler(_JSONRequest(request.scope, request.receive))

        return handle
