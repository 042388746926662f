"""Export requests and export jobs as the API reads and writes them."""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from backend.jobs.models import Job
from backend.validation import BodyId

MAX_SEQUENCES = 100_000


class ExportOptions(BaseModel):
    """Format options: ``frames`` (dexycb, bop: colour and depth frames copied or linked),
    ``split`` (dexycb: write DexYCB's split lists of that setup), ``labels`` (coco: hand
    keypoints from the crowd's 2D labels or the solve projected)."""

    model_config = ConfigDict(extra="forbid")

    frames: Literal["copy", "link"] | None = None
    split: Literal["s0", "s1", "s2", "s3"] | None = None
    labels: Literal["2d", "3d"] | None = None


class ExportRequest(BaseModel):
    """Body of POST /api/exports: a format, the sequences (or ``all``), what to include."""

    model_config = ConfigDict(extra="forbid")

    format: str = Field(min_length=1, max_length=32,
                        description="dexycb, coco, bop, cvat or json")
    sequences: list[BodyId] | None = Field(None, max_length=MAX_SEQUENCES)
    all: bool = False
    include: Literal["accepted", "submitted"] = "accepted"
    archive: Literal["zip", "tar"] = "zip"
    options: ExportOptions = Field(default_factory=ExportOptions)


class ExportRead(BaseModel):
    id: int
    status: str
    format: str
    include: str
    archive: str
    sequence_ids: list[int]
    # A whole-project export leaves out the sequences that cannot be exported yet, each with
    # the reason ("sequence 3 (s/n) has no finished solve; ...").
    skipped: list[str]
    options: dict[str, Any]
    progress: dict[str, Any] | None
    result: dict[str, Any] | None
    error: str | None
    created_at: datetime
    finished_at: datetime | None
    download_url: str | None

    @classmethod
    def of(cls, job: Job) -> ExportRead:
        args = job.args or {}
        # Where the archive is stored is the server's business: the download URL serves it.
        result = {k: v for k, v in (job.result or {}).items() if k not in ("path", "key")} or None
        gone = bool((job.result or {}).get("deleted_at"))
        return cls(id=job.id, status=job.status, format=str(args.get("format")),
                   include=str(args.get("include")), archive=str(args.get("archive", "zip")),
                   sequence_ids=list(args.get("sequence_ids") or []),
                   skipped=[str(r) for r in args.get("skipped") or []],
                   options=dict(args.get("options") or {}), progress=job.progress,
                   result=result, error=job.error, created_at=job.created_at,
                   finished_at=job.finished_at,
                   download_url=(f"/api/exports/{job.id}/download"
                                 if job.status == "done" and not gone else None))


class ExportDeleted(BaseModel):
    id: int
    state: Literal["deleted"]
