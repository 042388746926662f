"""Admin endpoints of quality control: reports, worker quality, QC runs, training clips."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, Query

from backend.accounts.deps import CurrentAdmin
from backend.crowd.schemas import WorkerDetailRead, WorkerStatsRead
from backend.db import SessionDep
from backend.jobs.schemas import JobRead
from backend.quality import admin_queue, gold, service, worker_records
from backend.quality.schemas import (
    QCReportDetail,
    QCReportRead,
    QCRunRequest,
    TrainingClipCreate,
    TrainingClipRead,
    WorkerQualityRead,
)
from backend.validation import Id, Key, Offset, QueryId, QueryKey

router = APIRouter(prefix="/api/qc", tags=["quality"])
router.include_router(admin_queue.router)

Outcome = Literal["approve", "review", "reject"]


@router.get("/reports", response_model=list[QCReportRead])
def list_reports(session: SessionDep, _: CurrentAdmin, sequence_id: QueryId = None,
                 outcome: Outcome | None = None, worker_id: QueryKey = None,
                 limit: int = Query(500, ge=1, le=5000)) -> list[QCReportRead]:
    rows = service.list_reports(session, sequence_id, outcome, worker_id, limit)
    return [QCReportRead.model_validate(r) for r in rows]


@router.get("/reports/{assignment_id}", response_model=QCReportDetail)
def read_report(assignment_id: Id, session: SessionDep, _: CurrentAdmin) -> QCReportDetail:
    return QCReportDetail.model_validate(service.get_report_or_raise(session, assignment_id))


@router.post("/runs", response_model=list[JobRead])
def run_qc(body: QCRunRequest, session: SessionDep, _: CurrentAdmin) -> list[JobRead]:
    """Queue the QC job of one target (or of every target with submitted work)."""
    jobs = service.request_qc_for(session, body.sequence_id, body.target_key)
    return [JobRead.model_validate(j) for j in jobs]


@router.get("/workers", response_model=list[WorkerQualityRead])
def workers(session: SessionDep, _: CurrentAdmin, limit: int = Query(500, ge=1, le=5000),
            offset: Offset = 0) -> list[WorkerQualityRead]:
    """Workers by id, ``limit`` (500, at most 5,000) from ``offset`` on."""
    return [WorkerQualityRead(**row)
            for row in service.worker_quality(session, limit=limit, offset=offset)]


@router.post("/training-clips", response_model=TrainingClipRead)
def create_training_clip(body: TrainingClipCreate, session: SessionDep,
                         _: CurrentAdmin) -> TrainingClipRead:
    return TrainingClipRead.model_validate(gold.create_clip(session, body))


# ----- each crowd worker's record (quality over time, approval, earnings), under the crowd's
# paths with the admin's other worker actions

records_router = APIRouter(prefix="/api/crowd", tags=["crowd"])


@records_router.get("/workers", response_model=list[WorkerStatsRead])
def list_workers(session: SessionDep, _: CurrentAdmin, limit: int = Query(200, ge=1, le=1000),
                 offset: Offset = 0) -> list[WorkerStatsRead]:
    """Workers by id, ``limit`` (200, at most 1,000) from ``offset`` on: approval rate, median
    error, working time, earnings, block, and their newest QC reports by date."""
    return worker_records.list_workers(session, limit, offset)


@records_router.get("/workers/{worker_id}", response_model=WorkerDetailRead)
def read_worker(worker_id: Key, session: SessionDep, _: CurrentAdmin) -> WorkerDetailRead:
    """One worker's stats, every QC report by date and their newest assignments (404 for a
    worker with no work and no block here)."""
    return worker_records.get_worker_or_raise(session, worker_id)
