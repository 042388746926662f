"""The FastAPI application: routers, error rendering, static pages, API documentation."""

from __future__ import annotations

import gc
import logging
import time
from collections.abc import AsyncIterator
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from contextlib import asynccontextmanager
from functools import lru_cache
from importlib.resources import files
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles
from sqlalchemy import Engine, create_engine, text
from sqlalchemy.pool import NullPool

from backend.accounts.router import router as auth_router
from backend.annotation.router import router as annotation_router
from backend.captures.router import router as captures_router
from backend.config import get_settings
from backend.crowd.manage import router as crowd_manage_router
from backend.crowd.providers.prolific.webhooks import router as prolific_webhook_router
from backend.crowd.router import page_router as crowd_page_router
from backend.crowd.router import router as crowd_router
from backend.db import get_engine, install_request_limits
from backend.errors import (
    install_api_fallback,
    install_database_outage_answer,
    install_error_handlers,
)
from backend.exports.router import router as exports_router
from backend.jobs.router import router as jobs_router
from backend.labels.router import page_router as labels_page_router
from backend.market.router import router as market_router
from backend.middleware import install_request_guards
from backend.page_headers import install_page_headers
from backend.pipeline.router import page_router as pipeline_page_router
from backend.pipeline.router import router as pipeline_router
from backend.portal.router import router as portal_router
from backend.progress.router import page_router as progress_page_router
from backend.progress.router import router as progress_router
from backend.progress.router import tasks_router as progress_tasks_router
from backend.quality.router import records_router as worker_records_router
from backend.quality.router import router as review_router
from backend.queue import check_queue
from backend.rig.router import router as rig_router
from backend.server_process import exit_with_parent
from backend.solve.router import router as solve_router

FRONTEND_DIR = Path(__file__).resolve().parent.parent / "frontend"
# Swagger UI as the fastapi-offline package ships it, served by the app itself: FastAPI's own
# /docs loads it from a CDN, which leaves a blank page offline. No /redoc: ReDoc's page always
# fetches its vendor's logo from a CDN, and Swagger UI documents the same operations.
DOCS_ASSETS_DIR = Path(str(files("fastapi_offline") / "static"))
DOCS_ASSETS_URL = "/docs/assets"

log = logging.getLogger(__name__)


def create_app() -> FastAPI:
    app = FastAPI(title="dexlabel", version="0.1.0",
                  description="Crowd-labelled multi-view video to 3D hand and object poses.",
                  docs_url=None, redoc_url=None)
    install_error_handlers(app)
    install_request_limits(app)
    install_request_guards(app)
    install_page_headers(app)
    app.include_router(auth_router)
    app.include_router(captures_router)
    app.include_router(annotation_router)
    app.include_router(progress_tasks_router)
    app.include_router(progress_page_router)
    app.include_router(labels_page_router)
    app.include_router(crowd_page_router)
    app.include_router(pipeline_page_router)
    app.include_router(crowd_router)
    app.include_router(prolific_webhook_router)
    app.include_router(crowd_manage_router)
    app.include_router(pipeline_router)
    app.include_router(jobs_router)
    app.include_router(review_router)
    app.include_router(worker_records_router)
    app.include_router(market_router)
    app.include_router(portal_router)
    app.include_router(solve_router)
    app.include_router(rig_router)
    app.include_router(progress_router)
    app.include_router(exports_router)

    @app.get("/healthz", tags=["ops"], responses={503: {"description": "something is down"}})
    def healthz() -> JSONResponse:
        """Whether this server can do its work: the database answers a query and the queue
        answers (Redis's ping, or the SQLite queue file's read), each within a few seconds.
        503 names what is down."""
        return health_answer()

    install_api_docs(app)
    install_api_fallback(app)
    # Added last, so it wraps every other middleware.
    install_database_outage_answer(app)
    if FRONTEND_DIR.is_dir():
        app.mount("/", StaticFiles(directory=FRONTEND_DIR, html=True), name="frontend")
    return app


def create_served_app() -> FastAPI:
    """The app as `dexlabel serve` runs it in each server process: :func:`create_app`, and
    once it has started, everything built so far (modules, the app, its routes and models,
    ~300,000 objects that live as long as the process) is moved out of the garbage
    collector's reach, so that its passes stop walking them again and again as requests
    allocate (a track save makes ~3,000 lists). Server CPU per autosave under a crowd of 200:
    14.9 -> 9.2 ms (bench/load.py). Not for tests: frozen objects are never collected.
    A server process of `serve --workers N` also ends when its supervisor dies
    (backend.server_process)."""
    exit_with_parent()
    app = create_app()
    inner = app.router.lifespan_context

    @asynccontextmanager
    async def lifespan(app_: FastAPI) -> AsyncIterator[Any]:
        async with inner(app_) as state:
            gc.collect()
            gc.freeze()
            yield state

    app.router.lifespan_context = lifespan
    return app


def install_api_docs(app: FastAPI) -> None:
    """/docs: Swagger UI with every script, style and icon from the app."""
    assert app.openapi_url is not None
    openapi_url = app.openapi_url
    favicon = f"{DOCS_ASSETS_URL}/favicon.png"
    app.mount(DOCS_ASSETS_URL, StaticFiles(directory=DOCS_ASSETS_DIR), name="docs-assets")

    @app.get("/docs", include_in_schema=False)
    def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=openapi_url, title=f"{app.title} API",
            swagger_js_url=f"{DOCS_ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{DOCS_ASSETS_URL}/swagger-ui.css", swagger_favicon_url=favicon,
            # No badge from the public validator service: the page makes no outside request.
            swagger_ui_parameters={"validatorUrl": None})


# ----- /healthz --------------------------------------------------------------------------

HEALTH_TIMEOUT_S = 3.0
_health_checks = ThreadPoolExecutor(max_workers=4, thread_name_prefix="healthz")


@lru_cache(maxsize=4)
def _health_engine(url: str) -> Engine:
    """An engine that opens a new connection for each check, with a connect timeout: the
    check sees whether the database answers now, not whether the app's pool has a free
    connection."""
    if url.startswith("postgresql"):
        return create_engine(url, poolclass=NullPool, connect_args={
            "connect_timeout": max(2, int(HEALTH_TIMEOUT_S)),
            "options": f"-c statement_timeout={int(HEALTH_TIMEOUT_S * 1000)}"})
    return get_engine()


def _check_database() -> str | None:
    try:
        with _health_engine(get_settings().database_url).connect() as conn:
            conn.execute(text("SELECT 1"))
    except Exception as exc:  # any failure to reach it is the answer
        log.warning("health: the database does not answer: %s", exc)
        return f"no answer ({type(exc).__name__})"
    return None


def _check_queue() -> str | None:
    problem = check_queue(HEALTH_TIMEOUT_S)
    if problem is not None:
        log.warning("health: the queue does not answer: %s", problem)
        return f"no answer ({problem.split(':', 1)[0]})"
    return None


def health_answer() -> JSONResponse:
    """Run both checks at once, each given HEALTH_TIMEOUT_S; 200 when both answer, else 503
    with Retry-After and ``detail`` naming what is down."""
    checks = {"database": _health_checks.submit(_check_database),
              "queue": _health_checks.submit(_check_queue)}
    deadline = time.monotonic() + HEALTH_TIMEOUT_S + 1.0
    states: dict[str, str] = {}
    for name, check in checks.items():
        try:
            problem = check.result(timeout=max(deadline - time.monotonic(), 0.0))
        except FutureTimeout:
            problem = f"no answer within {HEALTH_TIMEOUT_S:g} s"
        states[name] = problem or "ok"
    down = [f"{name}: {state}" for name, state in states.items() if state != "ok"]
    if not down:
        return JSONResponse({"status": "ok", **states})
    return JSONResponse({"status": "unavailable", "error": "unavailable",
                         "detail": "; ".join(down), **states},
                        status_code=503, headers={"Retry-After": "5"})
