"""Progress endpoint: where a sequence's tasks and solve stand."""

from __future__ import annotations

from fastapi import APIRouter

from backend.accounts.deps import CurrentAdmin
from backend.db import SessionDep
from backend.progress.schemas import SequenceProgress
from backend.progress.service import sequence_progress
from backend.validation import Id

router = APIRouter(prefix="/api", tags=["progress"])


@router.get("/sequences/{sequence_id}/progress", response_model=SequenceProgress)
def get_progress(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> SequenceProgress:
    """Every view x target task's state (open, published, submitted, in review, accepted)
    with its HIT and assignment counts, the totals, and the sequence's latest solve run."""
    return sequence_progress(session, sequence_id)
