"""A test double of Prolific's API, written from Prolific's public documentation
(docs.prolific.com): the real service cannot be reached from the test suite.

It serves the endpoints our provider uses, keeps everything in memory, logs every request,
and produces the documented failures on demand:

- 429 when two bonus payments overlap (the workspace wallet takes one at a time), and
  ``faults["throttle_pays"]`` more 429s on the pay call;
- a reply lost after the payment was made (``faults["drop_after_pay"]``): the bulk payment is
  paid, then the connection is cut before the answer is whole;
- ``faults["drop_after_create"]``: the study is made, the reply to its creation lost;
- ``faults["submission_503"]``: a submission read answers 503;
- webhook deliveries to subscribed URLs, signed as Prolific signs them, retried on failure.

Where the documentation leaves a shape open, the double chooses one and our provider reads
that: a submission carries the ``external_url`` of the access detail it was sent to; a bulk
bonus payment can be read back (``GET /api/v1/bulk-bonus-payments/{id}/``) with its status.
"""

from __future__ import annotations

import itertools
import json
import socket
import threading
import time
import uuid
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import httpx
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from backend.crowd.providers.prolific.webhooks import SIGNATURE, TIMESTAMP, sign

TOKEN = "prolific-double-token"
REJECTION_CATEGORIES = {"TOO_QUICKLY", "TOO_SLOWLY", "FAILED_INSTRUCTIONS",
                        "INCOMP_LONGITUDINAL", "FAILED_CHECK", "LOW_EFFORT", "MALINGERING",
                        "NO_CODE", "BAD_CODE", "NO_DATA", "UNSUPP_DEVICE", "OTHER"}
PAGE_SIZE = 200
PAY_TAKES_S = 0.01


class Refusal(Exception):
    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


class ProlificDouble:
    """The double's state; ``app`` serves it."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.ids = itertools.count(1)
        self.studies: dict[str, dict[str, Any]] = {}
        self.submissions: dict[str, dict[str, Any]] = {}
        self.bulks: dict[str, dict[str, Any]] = {}
        self.payments: list[tuple[str, str, str]] = []  # (bulk id, participant, amount)
        self.groups: dict[str, dict[str, Any]] = {}
        self.messages: list[dict[str, Any]] = []
        self.subscriptions: list[dict[str, Any]] = []
        self.secret = ""
        self.url = ""
        self.requests: list[tuple[str, str]] = []
        self.deliveries: list[int] = []
        self.faults: Counter[str] = Counter()
        self.counts: Counter[str] = Counter()
        self.paying = 0
        self.max_paying = 0
        self.app = build_app(self)

    def new_id(self, prefix: str) -> str:
        return f"{prefix}{next(self.ids):06d}{uuid.uuid4().hex[:6]}"

    def fault(self, name: str) -> bool:
        """Use up one of the switched-on faults called ``name``."""
        with self.lock:
            if self.faults[name] <= 0:
                return False
            self.faults[name] -= 1
            return True

    # ----- what participants do (driven by the tests) --------------------------------------

    def take(self, study_id: str, position: int, participant: str,
             status: str = "AWAITING REVIEW") -> str:
        """A participant takes the study's access detail at ``position``; the submission id."""
        with self.lock:
            study = self.studies[study_id]
            submission_id = self.new_id("sub")
            self.submissions[submission_id] = {
                "id": submission_id, "study_id": study_id, "participant_id": participant,
                "status": status, "started_at": time.time(),
                "external_url": study["access_details"][position]["external_url"]}
            study["taken"] += 1
            return submission_id

    def deliver(self, event_type: str, resource_id: str, status: str,
                attempts: int = 3) -> list[int]:
        """Send the event to each subscription of its type, signed, and again on failure
        (up to ``attempts`` times each); the answers' status codes (0: no answer)."""
        body = json.dumps({"event_type": event_type, "resource_id": resource_id,
                           "status": status}).encode()
        timestamp = str(int(time.time()))
        headers = {TIMESTAMP: timestamp, SIGNATURE: sign(self.secret, timestamp, body),
                   "Content-Type": "application/json"}
        codes = []
        for subscription in [s for s in self.subscriptions if s["event_type"] == event_type]:
            for attempt in range(attempts):
                try:
                    code = httpx.post(subscription["target_url"], content=body,
                                      headers=headers, timeout=30).status_code
                except httpx.HTTPError:
                    code = 0
                codes.append(code)
                if 200 <= code < 300:
                    break
                time.sleep(0.05 * 2 ** attempt)
        self.deliveries.extend(codes)
        return codes


class DropReply:
    """Cuts the connection mid-answer for a request whose handler asked for it (its scope
    holds ``drop_reply``): what a client sees when a reply is lost after the work was done."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def guarded(message: Message) -> None:
            if scope.get("drop_reply") and message["type"] == "http.response.start":
                await send({"type": "http.response.start", "status": 200,
                            "headers": [(b"content-length", b"1000")]})
                await send({"type": "http.response.body", "body": b"{", "more_body": True})
                raise ConnectionAbortedError("reply dropped after the work was done")
            await send(message)

        await self.app(scope, receive, guarded)


def build_app(double: ProlificDouble) -> ASGIApp:
    from tests.backend.crowd.prolific_double_routes import add_routes

    app = FastAPI()

    @app.middleware("http")
    async def check_token(request: Request, call_next: Any) -> Any:
        double.requests.append((request.method, request.url.path))
        if request.headers.get("Authorization") != f"Token {TOKEN}":
            return JSONResponse({"error": {"detail": "Invalid token."}}, status_code=401)
        return await call_next(request)

    @app.exception_handler(Refusal)
    async def refused(_request: Request, exc: Refusal) -> JSONResponse:
        return JSONResponse({"error": {"detail": exc.detail}}, status_code=exc.status)

    add_routes(app, double)
    return DropReply(app)


@contextmanager
def serve(app: ASGIApp) -> Iterator[str]:
    """``app`` served by uvicorn on a free loopback port in a thread; its base URL."""
    import uvicorn

    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, log_level="critical", lifespan="off"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    deadline = time.monotonic() + 10
    while not server.started:
        assert thread.is_alive() and time.monotonic() < deadline, "uvicorn did not start"
        time.sleep(0.005)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=10)
        sock.close()
