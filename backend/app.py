"""The FastAPI application: routers, error rendering, static pages, API documentation."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

from backend.accounts.router import router as auth_router
from backend.annotation.router import router as annotation_router
from backend.captures.router import router as captures_router
from backend.crowd.router import router as crowd_router
from backend.errors import install_error_handlers
from backend.jobs.router import router as jobs_router
from backend.market.router import router as market_router
from backend.middleware import install_request_guards
from backend.portal.router import router as portal_router
from backend.progress.router import router as progress_router
from backend.quality.router import router as review_router
from backend.solve.router import router as solve_router

FRONTEND_DIR = Path(__file__).resolve().parent.parent / "frontend"
# Swagger UI as the fastapi-offline package ships it, served by the app itself: FastAPI's own
# /docs loads it from a CDN, which leaves a blank page offline. No /redoc: ReDoc's page always
# fetches its vendor's logo from a CDN, and Swagger UI documents the same operations.
DOCS_ASSETS_DIR = Path(str(files("fastapi_offline") / "static"))
DOCS_ASSETS_URL = "/docs/assets"


def create_app() -> FastAPI:
    app = FastAPI(title="dexlabel", version="0.1.0",
                  description="Crowd-labelled multi-view video to 3D hand and object poses.",
                  docs_url=None, redoc_url=None)
    install_error_handlers(app)
    install_request_guards(app)
    app.include_router(auth_router)
    app.include_router(captures_router)
    app.include_router(annotation_router)
    app.include_router(crowd_router)
    app.include_router(jobs_router)
    app.include_router(review_router)
    app.include_router(market_router)
    app.include_router(portal_router)
    app.include_router(solve_router)
    app.include_router(progress_router)

    @app.get("/healthz", tags=["ops"])
    def healthz() -> dict[str, str]:
        return {"status": "ok"}

    install_api_docs(app)
    if FRONTEND_DIR.is_dir():
        app.mount("/", StaticFiles(directory=FRONTEND_DIR, html=True), name="frontend")
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

