"""The endpoints that move work between stages (each calls the pipeline): the page's submit,
an admin's sync, approval and rejection, adopting a calibration version, and deleting a
sequence. Each keeps the path and tag of the domain whose work it moves."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Query
from starlette.concurrency import run_in_threadpool

from backend import pipeline
from backend.accounts.deps import CurrentAdmin
from backend.annotation.deps import WriterClaims, assignment_of
from backend.annotation.schemas import MAX_SAVE_BYTES, SaveResult, TracksSave
from backend.captures.schemas import SequenceDeletedRead
from backend.crowd.schemas import ApproveRequest, PaymentRead, RejectRequest, SyncResult
from backend.db import SessionDep
from backend.middleware import JSONBodyRoute, body_limit
from backend.pipeline.deletion import delete_sequence as delete_sequence_flow
from backend.rig.schemas import AdoptRequest, AdoptResult
from backend.validation import Id

router = APIRouter(prefix="/api")
# The page's submit: its JSON body is parsed like the page's saves (msgspec).
page_router = APIRouter(prefix="/api", tags=["annotation"], route_class=JSONBodyRoute)

VersionNumber = Annotated[int, Path(ge=0, le=1_000_000, description=(
    "calibration version; 0 is the imported calibration"))]


@page_router.post("/annotate/submit", response_model=SaveResult,
                  openapi_extra=body_limit(MAX_SAVE_BYTES))
def submit(body: TracksSave, claims: WriterClaims, session: SessionDep) -> SaveResult:
    assignment = pipeline.submit(session, assignment_of(session, claims), body)
    return SaveResult(version=assignment.version, status=assignment.status)


@router.post("/crowd/sync", response_model=SyncResult, tags=["crowd"])
def sync_submissions(session: SessionDep, _: CurrentAdmin) -> SyncResult:
    return pipeline.sync(session)


@router.post("/crowd/assignments/{assignment_id}/approve", response_model=PaymentRead,
             tags=["crowd"])
def approve(assignment_id: Id, body: ApproveRequest, session: SessionDep,
            _: CurrentAdmin) -> PaymentRead:
    return pipeline.approve(session, None, assignment_id, body.feedback)


@router.post("/crowd/assignments/{assignment_id}/reject", response_model=PaymentRead,
             tags=["crowd"])
def reject(assignment_id: Id, body: RejectRequest, session: SessionDep,
           _: CurrentAdmin) -> PaymentRead:
    return pipeline.reject(session, None, assignment_id, body.feedback, body.category)


@router.post("/sequences/{sequence_id}/calibrations/{number}/adopt",
             response_model=AdoptResult, tags=["rig"])
def adopt_calibration(sequence_id: Id, number: VersionNumber, session: SessionDep,
                      _: CurrentAdmin, body: AdoptRequest | None = None) -> AdoptResult:
    """Put a calibration version in use (0: the imported one) and re-solve with it."""
    body = body or AdoptRequest()
    solve = pipeline.adopt_calibration(session, sequence_id, number, body.solve)
    return AdoptResult(sequence_id=sequence_id, version_in_use=number, solve=solve)


@router.delete("/sequences/{sequence_id}", response_model=SequenceDeletedRead,
               tags=["captures"])
async def delete_sequence(
    sequence_id: Id, _: CurrentAdmin,
    force: bool = Query(False, description="delete it even with submitted or approved work"),
) -> SequenceDeletedRead:
    """Delete a sequence: its rows, the tasks and work on it, and its stored files. 409 when it
    has submitted or approved assignments, unless ``force=true``."""
    done = await run_in_threadpool(delete_sequence_flow, sequence_id, force)
    d = done.sequence
    return SequenceDeletedRead(sequence_id=d.sequence_id, subject=d.subject, name=d.name,
                               tasks=d.tasks, assignments=d.assignments,
                               finished_assignments=d.finished_assignments, files=done.files)
