"""HTTP endpoints of the marketplace.

``POST /mturk`` is the requester API (boto3: ``endpoint_url=<app>/mturk``). It reads the raw
body and headers because the SigV4 signature covers them byte for byte, and it keeps its own
unit of work (``protocol.handle``) because even a failed commit must be answered in the MTurk
wire format, as a ServiceFault. ``POST /mturk/externalSubmit`` is where an ExternalQuestion page
posts its form, exactly as on MTurk (``{turkSubmitTo}/mturk/externalSubmit``).
"""

from __future__ import annotations

import html

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response
from sqlalchemy.exc import DBAPIError
from sqlalchemy.orm.exc import StaleDataError
from starlette.concurrency import run_in_threadpool

from backend.db import session_scope
from backend.errors import DexlabelError
from backend.market import clock, protocol, workers
from backend.market.auth import SignedRequest

router = APIRouter(tags=["marketplace"])


def _signed_request(request: Request, body: bytes) -> SignedRequest:
    scope = request.scope
    raw_path = scope.get("raw_path") or scope["path"].encode()
    headers = [(name.decode("latin-1").lower(), value.decode("latin-1"))
               for name, value in scope["headers"]]
    return SignedRequest(request.method, raw_path.decode("latin-1"),
                         scope.get("query_string", b"").decode("latin-1"), headers, body)


@router.post("/mturk", include_in_schema=False)
@router.post("/mturk/", include_in_schema=False)
async def requester_api(request: Request) -> Response:
    signed = _signed_request(request, await request.body())
    reply = await run_in_threadpool(protocol.handle, signed)
    return Response(reply.body, status_code=reply.status, headers=reply.headers)


def _page(title: str, message: str, status: int) -> HTMLResponse:
    body = (f'<!doctype html><html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
            f"</head><body><h1>{title}</h1><p>{html.escape(message)}</p></body></html>")
    return HTMLResponse(body, status_code=status)


def _submit(assignment_id: str, fields: list[tuple[str, str]]) -> None:
    with session_scope() as session:
        workers.submit_external(session, assignment_id, fields, clock.now())


@router.post("/mturk/externalSubmit", response_class=HTMLResponse)
async def external_submit(request: Request) -> HTMLResponse:
    """The form post of an ExternalQuestion page: ``assignmentId`` plus the answer fields."""
    form = await request.form()
    fields = [(name, value) for name, value in form.multi_items() if isinstance(value, str)]
    if len(fields) != len(form.multi_items()):
        return _page("Not submitted", "File uploads are not accepted here.", 400)
    assignment_id = str(form.get(workers.SUBMIT_ID_FIELD) or "").strip()
    if not assignment_id:
        return _page("Not submitted", "The form has no assignmentId field.", 400)
    try:
        await run_in_threadpool(_submit, assignment_id, fields)
    except DexlabelError as exc:
        return _page("Not submitted", f"Could not submit: {exc.detail}.", 400)
    except (DBAPIError, StaleDataError):
        return _page("Not submitted", "The marketplace was busy; please submit again.", 503)
    return _page("Submitted, thank you",
                 f"Your work on assignment {assignment_id} was received.", 200)
