"""The FastAPI application: routers, error rendering, static pages."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from backend.accounts.router import router as auth_router
from backend.annotation.router import router as annotation_router
from backend.captures.router import router as captures_router
from backend.crowd.router import router as crowd_router
from backend.errors import install_error_handlers
from backend.jobs.router import router as jobs_router
from backend.market.router import router as market_router
from backend.portal.router import router as portal_router
from backend.solve.router import router as solve_router
from backend.quality.router import router as review_router

FRONTEND_DIR = Path(__file__).resolve().parent.parent / "frontend"


def create_app() -> FastAPI:
    app = FastAPI(title="dexlabel", version="0.1.0",
                  description="Crowd-labelled multi-view video to 3D hand and object poses.")
    install_error_handlers(app)
    app.include_router(auth_router)
    app.include_router(captures_router)
    app.include_router(annotation_router)
    app.include_router(crowd_router)
    app.include_router(jobs_router)
    app.include_router(review_router)
    app.include_router(market_router)
    app.include_router(portal_router)
    app.include_router(solve_router)

    @app.get("/healthz", tags=["ops"])
    def healthz() -> dict[str, str]:
        return {"status": "ok"}

    if FRONTEND_DIR.is_dir():
        app.mount("/", StaticFiles(directory=FRONTEND_DIR, html=True), name="frontend")
    return app
