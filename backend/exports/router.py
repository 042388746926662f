"""Admin endpoints of the export: start an export job, read its state, download its archive
(streamed from the instance's storage, whichever host wrote it), delete it."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.responses import StreamingResponse

from backend.accounts.deps import CurrentAdmin
from backend.db import SessionDep
from backend.exports import service, stored
from backend.exports.schemas import ExportDeleted, ExportRead, ExportRequest
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


@router.delete("/{export_id}", response_model=ExportDeleted)
def delete_export(export_id: Id, session: SessionDep, _: CurrentAdmin) -> ExportDeleted:
    """Delete an export and its archive; 409 while it runs."""
    stored.delete_export(session, export_id)
    return ExportDeleted(id=export_id, state="deleted")


@router.get("/{export_id}/download", response_class=StreamingResponse, responses=_ARCHIVE)
def download_export(export_id: Id, session: SessionDep, _: CurrentAdmin) -> StreamingResponse:
    """The finished archive, streamed from storage in chunks (never read whole into memory);
    410 once it was deleted (DEXLABEL_EXPORT_RETENTION_DAYS)."""
    archive = stored.finished_archive(session, export_id)
    size, chunks = stored.open_archive(archive, export_id)
    return StreamingResponse(chunks, media_type=archive.media_type, headers={
        "Content-Length": str(size),
        "Content-Disposition": f'attachment; filename="{archive.filename}"'})
