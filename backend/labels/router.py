"""The annotation page's pre-fill suggestions, read from the accepted labels of other views."""

from __future__ import annotations

from fastapi import APIRouter, Query

from backend.annotation.deps import WorkerClaims
from backend.db import SessionDep
from backend.labels import suggestions
from backend.storage import get_storage
from backend.validation import MAX_INT32

page_router = APIRouter(prefix="/api", tags=["annotation"])


@page_router.get("/annotate/suggestions", response_model=suggestions.SuggestionsRead)
def prefill_suggestions(claims: WorkerClaims, session: SessionDep,
                        first_frame: int | None = Query(None, ge=0, le=MAX_INT32),
                        last_frame: int | None = Query(None, ge=0, le=MAX_INT32)
                        ) -> suggestions.SuggestionsRead:
    """Pre-fill suggestions for the assignment's view once its target has accepted work in
    another view: per point and frame (``first_frame``..``last_frame``, default the whole
    clip) a position triangulated from the work of 3 or more views, or from the target's
    model fitted to 1 or 2 views (a job on the worker queue: until it has run the answer is
    ``preparing``, to be asked again in a few seconds), a visibility from this view's depth,
    and per labelled view a fundamental matrix and its labels for epipolar lines. Nothing
    the worker sees is stored; a review link may read them, a preview link may not (401).
    422 names a frame outside the clip."""
    return suggestions.suggestions(session, get_storage(),
                                   suggestions.assignment_of(session, claims), first_frame,
                                   last_frame)
