"""Admin endpoints of the job table: list, count, read, re-run."""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, Query

from backend.accounts.deps import CurrentAdmin
from backend.db import SessionDep
from backend.jobs import service
from backend.jobs.schemas import JobCounts, JobRead
from backend.validation import Id, QueryKey

router = APIRouter(prefix="/api/jobs", tags=["jobs"])

Status = Literal["queued", "running", "retrying", "waiting", "done", "failed"]


@router.get("", response_model=list[JobRead])
def list_jobs(session: SessionDep, _: CurrentAdmin, status: Status | None = None,
              kind: QueryKey = None, limit: int = Query(100, ge=1, le=1000)) -> list[JobRead]:
    return [JobRead.of(j) for j in service.list_jobs(session, status, kind, limit)]


@router.get("/counts", response_model=JobCounts)
def count_jobs(session: SessionDep, _: CurrentAdmin) -> JobCounts:
    """Jobs per kind and status, for the job table's filters."""
    return JobCounts(kinds=service.count_jobs(session))


@router.get("/{job_id}", response_model=JobRead)
def read_job(job_id: Id, session: SessionDep, _: CurrentAdmin) -> JobRead:
    return JobRead.of(service.get_job_or_raise(session, job_id))


@router.post("/{job_id}/retry", response_model=JobRead)
def retry_job(job_id: Id, session: SessionDep, _: CurrentAdmin) -> JobRead:
    return JobRead.of(service.retry_job(session, job_id))
