"""Progress endpoints: where a sequence's tasks and solve stand."""

from __future__ import annotations

from fastapi import APIRouter, Query
from sqlalchemy import select

from backend.accounts.deps import CurrentAdmin
from backend.captures.models import Sequence
from backend.db import SessionDep
from backend.progress.schemas import SequenceProgress
from backend.progress.service import sequence_progress, sequences_progress
from backend.validation import Id, Offset

router = APIRouter(prefix="/api", tags=["progress"])


@router.get("/progress", response_model=list[SequenceProgress])
def list_progress(session: SessionDep, _: CurrentAdmin, limit: int = Query(50, ge=1, le=1000),
                  offset: Offset = 0) -> list[SequenceProgress]:
    """The progress of sequences in id order, ``limit`` (50, at most 1,000) from ``offset`` on:
    the same page as GET /api/sequences with the same ``limit`` and ``offset``."""
    ids = list(session.scalars(select(Sequence.id).order_by(Sequence.id)
                               .offset(offset).limit(limit)))
    return sequences_progress(session, ids)


@router.get("/sequences/{sequence_id}/progress", response_model=SequenceProgress)
def get_progress(sequence_id: Id, session: SessionDep, _: CurrentAdmin) -> SequenceProgress:
    """Every view x target task's state (open, published, submitted, in review, accepted)
    with its HIT and assignment counts, the totals, and the sequence's latest solve run."""
    return sequence_progress(session, sequence_id)
