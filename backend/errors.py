"""Error classes that carry their HTTP status, the handlers that render them, and their shape
in the OpenAPI document.

Every error answer is ``{"error", "detail"}`` (plus ``fields`` on validation errors, and
whatever an error adds about itself); the OpenAPI document declares exactly that shape for the
4xx answers of every operation.
"""

from __future__ import annotations

from collections.abc import Callable
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.routing import APIRoute, iter_route_contexts
from pydantic import BaseModel, ConfigDict
from sqlalchemy.exc import NoResultFound
from sqlalchemy.orm.exc import StaleDataError
from starlette.exceptions import HTTPException
from starlette.routing import compile_path


class DexlabelError(Exception):
    """Base of every error the product raises on purpose; rendered as {"error", "detail"}."""

    status_code = 400
    code = "bad_request"

    def __init__(self, detail: str, **extra: Any) -> None:
        super().__init__(detail)
        self.detail = detail
        self.extra = extra

    def __init_subclass__(cls, status_code: int | None = None, code: str | None = None,
                          **kwargs: Any) -> None:
        """``class NotFound(DexlabelError, status_code=404, code="not_found")``: an error
        kind's HTTP status and its ``error`` code, given where it is declared."""
        super().__init_subclass__(**kwargs)
        if status_code is not None:
            cls.status_code = status_code
        if code is not None:
            cls.code = code


class NotFound(DexlabelError, status_code=404, code="not_found"):
    """No such record (or none the caller may see)."""


class Conflict(DexlabelError, status_code=409, code="conflict"):
    """The request contradicts the state of the records it touches."""


class Unauthorized(DexlabelError, status_code=401, code="unauthorized"):
    """No credentials, or credentials that are not valid (any more)."""


class Forbidden(DexlabelError, status_code=403, code="forbidden"):
    """Valid credentials that do not allow this request."""


class PayloadTooLarge(DexlabelError, status_code=413, code="payload_too_large"):
    """A request body over its route's limit."""


class InvalidCapture(DexlabelError):
    """A capture on disk is missing a file or has a malformed one; ``path`` names it."""

    status_code = 422
    code = "invalid_capture"

    def __init__(self, path: str, problem: str) -> None:
        super().__init__(f"{path}: {problem}", path=path)
        self.path = path
        self.problem = problem


class Busy(DexlabelError, status_code=503, code="busy"):
    """A concurrent request changed the same records first; the same request again works."""


class StorageError(DexlabelError, status_code=502, code="storage_error"):
    """The storage backend failed or refused a read or write."""


class FieldProblem(BaseModel):
    """One invalid input: `field` is where it is (`email`, `path.task_id`, `query.limit`,
    `tracks.0.point`), `message` what is wrong with it."""

    field: str
    message: str


class ErrorRead(BaseModel):
    """The body of every error answer."""

    # Errors add what they know about themselves (the operation, the current version, ...).
    model_config = ConfigDict(extra="allow", title="Error")

    error: str
    detail: str
    fields: list[FieldProblem] | None = None


class InvalidFields(HTTPException):
    """Invalid input found by a request guard while the body is read: 422 naming the fields,
    like a validation error (``problems`` are ``{"field", "message"}``)."""

    def __init__(self, problems: list[dict[str, str]]) -> None:
        super().__init__(422, "; ".join(f"{p['field']}: {p['message']}" for p in problems))
        self.problems = problems


def validation_error(problems: list[dict[str, str]]) -> JSONResponse:
    """422 naming each invalid field: ``problems`` are ``{"field", "message"}``."""
    detail = "; ".join(f"{p['field']}: {p['message']}" for p in problems)
    return JSONResponse({"error": "validation_error", "detail": detail, "fields": problems},
                        status_code=422)


def _field_problem(err: Any) -> dict[str, str]:
    loc = [str(p) for p in err.get("loc", ()) if p != "body"]
    if err.get("type") == "json_invalid":
        reason = (err.get("ctx") or {}).get("error", "")
        return {"field": "body", "message": f"invalid JSON at character {'.'.join(loc)}: {reason}"}
    message = str(err.get("msg", ""))
    if err.get("type") == "value_error" and (err.get("ctx") or {}).get("error") is not None:
        message = str(err["ctx"]["error"])  # our validators' own words, without a prefix
    return {"field": ".".join(loc) or "body", "message": message}


# The error word of framework answers (an unknown route, a wrong method, a body too large).
_HTTP_CODES = {404: NotFound.code, 401: Unauthorized.code, 403: Forbidden.code,
               409: Conflict.code, 413: PayloadTooLarge.code}


def _http_code(status: int) -> str:
    if status in _HTTP_CODES:
        return _HTTP_CODES[status]
    try:
        return HTTPStatus(status).phrase.lower().replace(" ", "_").replace("-", "_")
    except ValueError:
        return "error"


def install_error_handlers(app: FastAPI) -> None:
    """Render our errors, the framework's and request-validation errors in one shape, and
    declare that shape in the OpenAPI document."""
    install_error_schema(app)

    @app.exception_handler(DexlabelError)
    async def _dexlabel_error(_: Request, exc: DexlabelError) -> JSONResponse:
        body: dict[str, Any] = {"error": exc.code, "detail": exc.detail}
        body.update(exc.extra)
        # An error may carry response headers (a 429's Retry-After).
        headers: dict[str, str] | None = getattr(exc, "headers", None)
        return JSONResponse(body, status_code=exc.status_code, headers=headers)

    @app.exception_handler(StaleDataError)
    async def _lost_race(_: Request, exc: StaleDataError) -> JSONResponse:
        # A row's version changed under this request (optimistic locking): nothing of it was
        # written; asking again sees the winner's state.
        return JSONResponse({"error": Busy.code, "detail": "a concurrent request changed the "
                             "same records; please try again"}, status_code=Busy.status_code,
                            headers={"Retry-After": "1"})

    @app.exception_handler(NoResultFound)
    async def _gone(_: Request, exc: NoResultFound) -> JSONResponse:
        # A row read a moment before was deleted by a request that committed in between (a
        # forced delete racing a save): the answer of a record that is not there.
        return JSONResponse({"error": NotFound.code, "detail": "a record this request works on "
                             "was deleted meanwhile"}, status_code=NotFound.status_code)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(_: Request, exc: RequestValidationError) -> JSONResponse:
        return validation_error([_field_problem(err) for err in exc.errors()])

    @app.exception_handler(HTTPException)
    async def _http_error(_: Request, exc: HTTPException) -> JSONResponse:
        if isinstance(exc, InvalidFields):
            return validation_error(exc.problems)
        return JSONResponse({"error": _http_code(exc.status_code), "detail": str(exc.detail)},
                            status_code=exc.status_code, headers=exc.headers)


# ----- the database is down: 503 with Retry-After ------------------------------------------

DATABASE_RETRY_AFTER_S = 5


def install_database_outage_answer(app: FastAPI) -> None:
    """Answer a request that could not reach the database 503 ``{"error": "unavailable"}``
    with Retry-After, instead of a plain-text 500: a connection refused or lost, or any other
    operational error of the database (``OperationalError``, ``InterfaceError``, or a DBAPI
    error that invalidated its connection). Nothing of the request was committed; the same
    request works once the database is back.

    It wraps the exception handlers (an ASGI middleware), so it also answers for errors that a
    more specific handler passes on; an error after the answer started is left alone.
    """
    import logging

    from sqlalchemy.exc import DBAPIError, InterfaceError, OperationalError
    from starlette.types import ASGIApp, Message, Receive, Scope, Send

    log = logging.getLogger(__name__)

    def database_down(exc: BaseException) -> bool:
        return isinstance(exc, OperationalError | InterfaceError) or (
            isinstance(exc, DBAPIError) and exc.connection_invalidated)

    class DatabaseOutage:
        def __init__(self, inner: ASGIApp) -> None:
            self.inner = inner

        async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
            if scope["type"] != "http":
                await self.inner(scope, receive, send)
                return
            started = False

            async def sending(message: Message) -> None:
                nonlocal started
                started = started or message["type"] == "http.response.start"
                await send(message)

            try:
                await self.inner(scope, receive, sending)
            except Exception as exc:
                if started or not database_down(exc):
                    raise
                log.warning("%s %s: the database is unavailable: %s", scope.get("method"),
                            scope.get("path"), str(exc).strip().splitlines()[0])
                answer = JSONResponse(
                    {"error": "unavailable",
                     "detail": "the database is unavailable; please try again shortly"},
                    status_code=503, headers={"Retry-After": str(DATABASE_RETRY_AFTER_S)})
                await answer(scope, receive, send)

    app.add_middleware(DatabaseOutage)


# ----- the error shape in the OpenAPI document -------------------------------------------

_METHODS = ("get", "put", "post", "delete", "patch", "head", "options", "trace")
_REF = "#/components/schemas/{model}"


def _error_response(description: str) -> dict[str, Any]:
    return {"description": description,
            "content": {"application/json": {"schema": {"$ref": _REF.format(model="Error")}}}}


def document_errors(schema: dict[str, Any]) -> dict[str, Any]:
    """Declare ``ErrorRead`` as every operation's 422 and 4XX answer, in place of FastAPI's
    default validation-error schema (which is not what the API sends)."""
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    for name in ("HTTPValidationError", "ValidationError"):
        components.pop(name, None)
    error_schema = ErrorRead.model_json_schema(ref_template=_REF)
    components.update(error_schema.pop("$defs", {}))
    components["Error"] = error_schema
    for operations in schema.get("paths", {}).values():
        for method, operation in operations.items():
            if method not in _METHODS:
                continue
            responses = operation.setdefault("responses", {})
            responses["422"] = _error_response(
                "Invalid input: `fields` names each invalid field and what is wrong with it")
            refused = responses.setdefault("4XX", _error_response(
                "Refused: `error` says why in a word, `detail` in a sentence"))
            if "text/html" in responses.get("200", {}).get("content", {}):
                # A page's own refusals are pages too (the guards' are still JSON).
                refused["content"].setdefault("text/html", {"schema": {"type": "string"}})
    return schema


def install_error_schema(app: FastAPI) -> None:
    """Make ``app.openapi()`` document the error shape (see ``document_errors``)."""
    generate: Callable[[], dict[str, Any]] = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = document_errors(generate())
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


def install_api_fallback(app: FastAPI, prefixes: tuple[str, ...] = ("/api", "/mturk")) -> None:
    """Every address under ``prefixes`` that no route serves answers in the error shape: 405
    with an ``Allow`` header naming the methods the path has, or 404. Call it after the API's
    routers are included and before anything mounted at "/" (the static pages)."""
    paths: list[tuple[Any, set[str]]] = []

    def allowed_methods(path: str) -> list[str]:
        if not paths:
            for route in iter_route_contexts(app.routes):
                original = route.original_route
                if (isinstance(original, APIRoute) and route.path
                        and original.endpoint is not no_such_route):
                    paths.append((compile_path(route.path)[0], set(route.methods or ())))
        return sorted({m for regex, methods in paths if regex.match(path) for m in methods})

    async def no_such_route(request: Request) -> JSONResponse:
        allowed = allowed_methods(request.url.path)
        if allowed:
            return JSONResponse(
                {"error": "method_not_allowed",
                 "detail": f"{request.method} is not allowed here; allowed: {', '.join(allowed)}"},
                status_code=405, headers={"Allow": ", ".join(allowed)})
        return JSONResponse({"error": NotFound.code,
                             "detail": f"no API endpoint at {request.url.path}"},
                            status_code=404)

    for prefix in prefixes:
        app.add_api_route(f"{prefix}/{{rest:path}}", no_such_route, include_in_schema=False,
                          methods=["GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"])
