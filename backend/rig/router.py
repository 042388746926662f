"""Admin endpoints of rig health: the report, a new estimate, and adopting a version."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path

from backend.accounts.deps import CurrentAdmin
from backend.db import SessionDep
from backend.rig import service
from backend.rig.schemas import RigHealthStatus
from backend.validation import Id

router = APIRouter(prefix="/api", tags=["rig"])
VersionNumber = Annotated[int, Path(ge=0, le=1_000_000, description=(
    "calibration version; 0 is the imported calibration"))]


@router.get("/sequences/{sequence_id}/rig-health", response_model=RigHealthStatus)
def rig_health(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> RigHealthStatus:
    """The newest rig-health report (cameras off, by how much), the version in use and the
    state of the estimate's job."""
    return service.health_status(session, sequence_id)


@router.post("/sequences/{sequence_id}/rig-health", response_model=RigHealthStatus,
             status_code=202)
def estimate_rig_health(sequence_id: Id, session: SessionDep,
                        _: CurrentAdmin) -> RigHealthStatus:
    """Queue a new estimate from the accepted labels; it stores a new calibration version
    (not in use) with its report."""
    service.request_health(session, sequence_id)
    return service.health_status(session, sequence_id)
