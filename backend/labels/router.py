"""The annotation page's pre-fill suggestions, read from the accepted labels of other views."""

from __future__ import annotations

from fastapi import APIRouter, Query

from backend.annotation.deps import WorkerClaims, WriterClaims
from backend.db import SessionDep
from backend.labels import model_follow, suggestions
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


@page_router.post("/annotate/model-follow", response_model=model_follow.ModelFollowRead,
                  responses={422: {"description": "keyframes the page could not save, an "
                                                  "object task, or begin outside the clip"}})
def hand_model_follow(body: model_follow.ModelFollowRequest, claims: WriterClaims,
                      session: SessionDep) -> model_follow.ModelFollowRead:
    """Proposals for a hand view from the hand model, fitted to the worker's keyframes of the
    first frame with enough visible joints on this view's depth and carried frame by frame
    through the clip until the depth no longer fits it. The follow runs on the worker queue:
    until it has run for these keyframes the answer is ``preparing``, to be asked again in a
    few seconds with the same body. Check cells are planted as in every proposal; nothing is
    stored for the assignment (an accepted proposal is saved as a tracked keyframe). Needs an
    assignment's writing token (it queues work)."""
    return model_follow.model_follow(session, get_storage(),
                                     suggestions.assignment_of(session, claims), body)
