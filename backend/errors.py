"""Error classes that carry their HTTP status, and the one handler that renders them."""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.orm.exc import StaleDataError


class DexlabelError(Exception):
    """Base of every error the product raises on purpose; rendered as {"error", "detail"}."""

    status_code = 400
    code = "bad_request"

    def __init__(self, detail: str, **extra: Any) -> None:
        super().__init__(detail)
        self.detail = detail
        self.extra = extra


class NotFound(DexlabelError):
    status_code = 404
    code = "not_found"


class Conflict(DexlabelError):
    status_code = 409
    code = "conflict"


class Unauthorized(DexlabelError):
    status_code = 401
    code = "unauthorized"


class Forbidden(DexlabelError):
    status_code = 403
    code = "forbidden"


class PayloadTooLarge(DexlabelError):
    status_code = 413
    code = "payload_too_large"


class InvalidCapture(DexlabelError):
    """A capture on disk is missing a file or has a malformed one; ``path`` names it."""

    status_code = 422
    code = "invalid_capture"

    def __init__(self, path: str, problem: str) -> None:
        super().__init__(f"{path}: {problem}", path=path)
        self.path = path
        self.problem = problem


class Busy(DexlabelError):
    """A concurrent request changed the same records first; the same request again works."""

    status_code = 503
    code = "busy"


class StorageError(DexlabelError):
    status_code = 502
    code = "storage_error"


def install_error_handlers(app: FastAPI) -> None:
    """Render our errors and request-validation errors in one shape."""

    @app.exception_handler(DexlabelError)
    async def _dexlabel_error(_: Request, exc: DexlabelError) -> JSONResponse:
        body: dict[str, Any] = {"error": exc.code, "detail": exc.detail}
        body.update(exc.extra)
        return JSONResponse(body, status_code=exc.status_code)

    @app.exception_handler(StaleDataError)
    async def _lost_race(_: Request, exc: StaleDataError) -> JSONResponse:
        # A row's version changed under this request (optimistic locking): nothing of it was
        # written; asking again sees the winner's state.
        return JSONResponse({"error": Busy.code, "detail": "a concurrent request changed the "
                             "same records; please try again"}, status_code=Busy.status_code,
                            headers={"Retry-After": "1"})

    @app.exception_handler(RequestValidationError)
    async def _validation_error(_: Request, exc: RequestValidationError) -> JSONResponse:
        problems = [
            {"field": ".".join(str(p) for p in err["loc"] if p != "body"), "message": err["msg"]}
            for err in exc.errors()
        ]
        detail = "; ".join(f"{p['field']}: {p['message']}" for p in problems)
        return JSONResponse(
            {"error": "validation_error", "detail": detail, "fields": problems}, status_code=422
        )
