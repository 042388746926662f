"""How the annotation page hands a finished assignment back to its crowd, for the start reply.

The annotation domain knows nothing of crowds; the start endpoint (backend.crowd.router) asks
the provider that published the assignment's HIT and adds its answer to the reply, so the page
completes the way that crowd expects: MTurk's externalSubmit form, Prolific's completion link,
the portal's list for a team.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation.schemas import TokenRead
from backend.crowd.models import CrowdHit
from backend.crowd.providers import get_provider


class CompletionRead(BaseModel):
    """``form_post``: post the completion form (``url`` empty: to the ``turkSubmitTo`` the
    page's address carries); ``redirect``: send the browser to ``url``; ``portal``: back to
    the portal's list at ``url``."""

    kind: Literal["form_post", "redirect", "portal"]
    url: str


class StartRead(TokenRead):
    """The assignment token, and how the page completes (null: a HIT published elsewhere,
    which the page completes as MTurk's externalSubmit, as it always has)."""

    completion: CompletionRead | None = None


def completion_for(session: Session, hit_id: str, assignment_id: str) -> CompletionRead | None:
    """The completion of the provider that published ``hit_id`` (the row's ``provider``);
    None for a HIT that is not ours."""
    row = session.scalars(select(CrowdHit).where(CrowdHit.hit_id == hit_id)).one_or_none()
    if row is None:
        return None
    done = get_provider(row.provider).completion(hit_id, assignment_id)
    return CompletionRead(kind=done.kind, url=done.url)
