"""Capture endpoints: import, list, read, and fast per-view frame delivery."""

from __future__ import annotations

from fastapi import APIRouter, Depends, Query, Request, Response
from fastapi.concurrency import run_in_threadpool

from backend.accounts.deps import VIEW_SCOPE, CurrentAdmin, require_view_access
from backend.captures import flows, service
from backend.captures.frames import BUNDLE_MEDIA_TYPE, build_bundle, bundle_etag
from backend.captures.models import Sequence
from backend.captures.schemas import (
    CameraRead,
    FrameRef,
    FramesManifest,
    HandRead,
    ImportRequest,
    ImportResultRead,
    ObjectRead,
    SequenceRead,
    ViewTokenRead,
)
from backend.config import get_settings
from backend.db import SessionDep
from backend.errors import NotFound, PayloadTooLarge
from backend.security import sign_token
from backend.storage import get_storage
from backend.validation import Id, Index, Key, Offset

router = APIRouter(prefix="/api", tags=["captures"])

VIEW_TOKEN_TTL_S = 7 * 24 * 3600
# Frames are immutable once imported; the ETag changes if a sequence is re-imported.
FRAME_CACHE_CONTROL = "private, max-age=86400"


def _sequence_read(seq: Sequence) -> SequenceRead:
    return SequenceRead(
        id=seq.id, subject=seq.subject.name, name=seq.name, num_frames=seq.num_frames,
        fps=seq.fps, master_serial=seq.master_serial, source_kind=seq.source_kind,
        created_at=seq.created_at,
        cameras=[CameraRead.model_validate(c) for c in seq.cameras],
        objects=[ObjectRead.model_validate(o) for o in seq.objects],
        hands=[HandRead.model_validate(h) for h in seq.hands],
    )


@router.post("/captures/import", response_model=list[ImportResultRead])
async def import_capture(body: ImportRequest, _: CurrentAdmin) -> list[ImportResultRead]:
    """Import a capture that is on the server's disk (DexYCB layout or per-camera videos),
    inside one of the folders of DEXLABEL_CAPTURE_ROOTS (403 outside them)."""
    roots = flows.allowed_capture_roots(get_settings())
    results = await run_in_threadpool(flows.import_path, body.path, None, roots)
    return list(results)


@router.get("/sequences", response_model=list[SequenceRead])
def list_sequences(session: SessionDep, _: CurrentAdmin,
                   limit: int = Query(50, ge=1, le=1000),
                   offset: Offset = 0) -> list[SequenceRead]:
    """Sequences in id order, ``limit`` (50, at most 1,000) from ``offset`` on."""
    return [_sequence_read(s) for s in service.list_sequences(session, limit, offset)]


@router.get("/sequences/{sequence_id}", response_model=SequenceRead)
def get_sequence(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> SequenceRead:
    return _sequence_read(service.get_sequence_or_raise(session, sequence_id))


@router.post("/sequences/{sequence_id}/views/{serial}/token", response_model=ViewTokenRead)
def create_view_token(
    sequence_id: Id, serial: Key, session: SessionDep, _: CurrentAdmin
) -> ViewTokenRead:
    """A token that lets its holder read this one view's frames (for sharing a clip)."""
    service.get_camera_or_raise(session, sequence_id, serial)
    payload = {"scope": VIEW_SCOPE, "sequence_id": sequence_id, "serial": serial}
    token = sign_token(payload, get_settings().signing_key, VIEW_TOKEN_TTL_S)
    return ViewTokenRead(token=token, expires_in=VIEW_TOKEN_TTL_S)


def _frame_url(request: Request, sequence_id: int, serial: str, tail: str) -> str:
    url = f"/api/sequences/{sequence_id}/views/{serial}/{tail}"
    token = request.query_params.get("token")
    return f"{url}?token={token}" if token else url


@router.get("/sequences/{sequence_id}/views/{serial}/frames", response_model=FramesManifest,
            dependencies=[Depends(require_view_access)])
def frames_manifest(
    sequence_id: Id, serial: Key, request: Request, session: SessionDep
) -> FramesManifest:
    """Every frame of one view: direct (signed) URLs on S3, API URLs on local storage."""
    camera = service.get_camera_or_raise(session, sequence_id, serial)
    storage = get_storage()
    refs = []
    for frame in service.list_frames(session, camera.id):
        url = storage.url_for(frame.color_key) or _frame_url(
            request, sequence_id, serial, f"frames/{frame.index}.jpg")
        depth_url = None
        if frame.depth_key:
            depth_url = storage.url_for(frame.depth_key) or _frame_url(
                request, sequence_id, serial, f"frames/{frame.index}/depth.png")
        refs.append(FrameRef(index=frame.index, url=url, bytes=frame.color_bytes,
                             depth_url=depth_url))
    return FramesManifest(
        sequence_id=sequence_id, serial=serial, width=camera.width, height=camera.height,
        num_frames=len(refs), bundle_url=_frame_url(request, sequence_id, serial, "frames.bin"),
        frames=refs,
    )


@router.get("/sequences/{sequence_id}/views/{serial}/frames.bin",
            dependencies=[Depends(require_view_access)],
            responses={200: {"content": {BUNDLE_MEDIA_TYPE: {}}}})
def frames_bundle(sequence_id: Id, serial: Key, request: Request, session: SessionDep) -> Response:
    """All colour frames of one view in one response (format in backend/captures/frames.py)."""
    camera = service.get_camera_or_raise(session, sequence_id, serial)
    seq = session.get(Sequence, sequence_id)
    assert seq is not None
    etag = bundle_etag(camera, seq.fingerprint)
    headers = {"ETag": etag, "Cache-Control": FRAME_CACHE_CONTROL}
    if request.headers.get("if-none-match") == etag:
        return Response(status_code=304, headers=headers)
    frames = service.list_frames(session, camera.id)
    limit = get_settings().max_bundle_frames
    if len(frames) > limit:
        raise PayloadTooLarge(
            f"view has {len(frames)} frames, more than one bundle serves ({limit}); "
            "use the per-frame URLs of the manifest")
    data = build_bundle(get_storage(), camera, frames, etag)
    return Response(data, media_type=BUNDLE_MEDIA_TYPE, headers=headers)


@router.get("/sequences/{sequence_id}/views/{serial}/frames/{index}.jpg",
            dependencies=[Depends(require_view_access)], response_class=Response,
            responses={200: {"content": {"image/jpeg": {}}}})
def frame_color(sequence_id: Id, serial: Key, index: Index, session: SessionDep) -> Response:
    frame = service.get_frame_or_raise(session, sequence_id, serial, index)
    return Response(get_storage().get_bytes(frame.color_key), media_type="image/jpeg",
                    headers={"Cache-Control": FRAME_CACHE_CONTROL})


@router.get("/sequences/{sequence_id}/views/{serial}/frames/{index}/depth.png",
            dependencies=[Depends(require_view_access)], response_class=Response,
            responses={200: {"content": {"image/png": {}}}})
def frame_depth(sequence_id: Id, serial: Key, index: Index, session: SessionDep) -> Response:
    frame = service.get_frame_or_raise(session, sequence_id, serial, index)
    if frame.depth_key is None:
        raise NotFound(f"camera {serial!r} has no depth (imported from video)")
    return Response(get_storage().get_bytes(frame.depth_key), media_type="image/png",
                    headers={"Cache-Control": FRAME_CACHE_CONTROL})
