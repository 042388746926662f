"""Job rows as admins read them."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from pydantic import BaseModel, ConfigDict

from backend.jobs.models import Job
from backend.jobs.service import describe


class JobRead(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    kind: str
    key: str
    args: dict[str, Any]
    status: str
    attempts: int
    max_attempts: int
    error: str | None
    result: dict[str, Any] | None
    # The host ("name:pid") whose attempt last claimed it, and each attempt of this run: its
    # number, host, start and the actions it recorded.
    host: str | None
    attempt_log: list[dict[str, Any]] | None
    created_at: datetime
    updated_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    # The outcome in one line (backend.jobs.service.describe).
    message: str = ""

    @classmethod
    def of(cls, job: Job) -> JobRead:
        return cls.model_validate(job).model_copy(update={"message": describe(job)})


class JobCounts(BaseModel):
    # kind -> status -> jobs; kinds and statuses without a job are left out.
    kinds: dict[str, dict[str, int]]
