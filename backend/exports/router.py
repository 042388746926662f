"""Admin endpoints of the export: start an export job, read its state, download its archive."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.responses import FileResponse

from backend.accounts.deps import CurrentAdmin
from backend.db import SessionDep
from backend.exports import service
from backend.exports.schemas import ExportRead, ExportRequest
from backend.validation import Id

router = APIRouter(prefix="/api/exports", tags=["exports"])

_ARCHIVE: dict[int | str, dict[str, Any]] = {
    200: {"content": {"application/zip": {}, "application/x-tar": {}}}}


@router.post("", response_model=ExportRead)
def start_export(body: ExportRequest, session: SessionDep, _: CurrentAdmin) -> ExportRead:
    if body.all == (body.sequences is not None):
        raise service.InvalidExport("give either sequences (a list of ids) or all: true",
                                    field="sequences")
    if body.options.frames == "link":
        # Links name files in the server's own storage: a downloaded archive would hold
        # server paths and no frames.
        raise service.InvalidExport(
            "options.frames=link is for `dexlabel export --link-frames` on the server only; "
            "an HTTP export copies the frames (options.frames=copy)", field="options.frames")
    job = service.request_export(session, body.format, None if body.all else body.sequences,
                                 body.include, body.options.model_dump(), body.archive)
    return ExportRead.of(job)


@router.get("/{export_id}", response_model=ExportRead)
def read_export(export_id: Id, session: SessionDep, _: CurrentAdmin) -> ExportRead:
    return ExportRead.of(service.get_export_or_raise(session, export_id))


@router.get("/{export_id}/download", response_class=FileResponse, responses=_ARCHIVE)
def download_export(export_id: Id, session: SessionDep, _: CurrentAdmin) -> FileResponse:
    """The finished archive, streamed from disk in chunks (never read whole into memory)."""
    path = service.finished_archive(session, export_id)
    media = "application/zip" if path.suffix == ".zip" else "application/x-tar"
    return FileResponse(path, media_type=media, filename=f"dexlabel-{path.name}")
