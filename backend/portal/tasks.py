"""What each HIT of the portal's list is about: the dexlabel task behind it (target, view,
frames) and a small picture of the view's first frame.

A HIT is ours when the crowd module published it (``crowd_hits``) or when its ExternalURL is
the annotation page with a valid task token (a HIT a requester made by hand); any other HIT is
listed by its title alone.

The thumbnail is an <img> on the portal page, which cannot send the worker's bearer header, so
its URL carries a token of its own: scope ``portal-thumbnail``, one HIT, THUMBNAIL_TTL_S. It
reads that one small picture and nothing else: no frames, no task, no writes.
"""

from __future__ import annotations

from urllib.parse import parse_qs, urlsplit

import cv2
import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session, selectinload

from backend.annotation.models import Task
from backend.annotation.tokens import TASK_SCOPE
from backend.captures import service as captures
from backend.config import get_settings
from backend.crowd.models import CrowdHit
from backend.crowd.titles import TaskFacts, task_facts
from backend.errors import DexlabelError, Forbidden, NotFound
from backend.market.models import Hit
from backend.market.questions import external_url
from backend.security import sign_token, verify_token
from backend.storage import get_storage

THUMBNAIL_SCOPE = "portal-thumbnail"
# Long enough for a worker to look through the list; a new listing gives new URLs.
THUMBNAIL_TTL_S = 15 * 60
THUMBNAIL_WIDTH_PX = 160
THUMBNAIL_JPEG_QUALITY = 80


def _task_ids(session: Session, hits: list[Hit]) -> dict[str, int | None]:
    """The task id behind each HIT (None: not one of ours): the crowd module's record of what
    it published (one query for all), else the task token in the HIT's ExternalURL."""
    published = dict(session.execute(select(CrowdHit.hit_id, CrowdHit.task_id).where(
        CrowdHit.hit_id.in_([hit.hit_id for hit in hits]))).all())
    return {hit.hit_id: published.get(hit.hit_id) or _task_id_in_url(hit.question)
            for hit in hits}


def hit_task(session: Session, hit: Hit) -> Task | None:
    """The task behind the HIT, or None when the HIT is not one of ours."""
    task_id = _task_ids(session, [hit])[hit.hit_id]
    return session.get(Task, task_id) if task_id is not None else None


def _task_id_in_url(question: str) -> int | None:
    url = external_url(question)
    if not url:
        return None
    tokens = parse_qs(urlsplit(url).query).get("task", [])
    if len(tokens) != 1:
        return None
    try:
        payload = verify_token(tokens[0], get_settings().signing_key, TASK_SCOPE)
    except DexlabelError:
        return None
    task_id = payload.get("task_id")
    return task_id if isinstance(task_id, int) else None


def hit_facts(session: Session, hits: list[Hit]) -> dict[str, TaskFacts | None]:
    """What each HIT of a listing is about, by HIT id (None: not one of ours). The tasks are
    found with one query for all the HITs the crowd module published and read with their
    views and sequences in one more, not a few queries per HIT."""
    task_ids = _task_ids(session, hits)
    found = {task.id: task for task in session.scalars(
        select(Task).where(Task.id.in_({t for t in task_ids.values() if t is not None}))
        .options(selectinload(Task.camera), selectinload(Task.sequence)))}
    return {hit_id: task_facts(session, found[task_id])
            if task_id is not None and task_id in found else None
            for hit_id, task_id in task_ids.items()}


def thumbnail_url(hit_id: str) -> str:
    token = sign_token({"scope": THUMBNAIL_SCOPE, "hit_id": hit_id}, get_settings().signing_key,
                       THUMBNAIL_TTL_S)
    return f"/api/portal/hits/{hit_id}/thumbnail.jpg?token={token}"


def check_thumbnail_token(token: str, hit_id: str) -> None:
    """Unauthorized for a token that is not a live thumbnail token; Forbidden for another
    HIT's."""
    payload = verify_token(token, get_settings().signing_key, THUMBNAIL_SCOPE)
    if payload.get("hit_id") != hit_id:
        raise Forbidden("this thumbnail token is for another HIT")


def thumbnail_jpeg(session: Session, hit_id: str) -> bytes:
    """The first frame of the HIT's view, THUMBNAIL_WIDTH_PX wide, as a JPEG."""
    hit = session.scalar(select(Hit).where(Hit.hit_id == hit_id))
    if hit is None or hit.disposed_at is not None:
        raise NotFound(f"HIT {hit_id} does not exist")
    task = hit_task(session, hit)
    if task is None:
        raise NotFound(f"HIT {hit_id} has no thumbnail: it is not a dexlabel task")
    frame = captures.get_frame_or_raise(session, task.sequence_id, task.camera.serial, 0)
    image = cv2.imdecode(np.frombuffer(get_storage().get_bytes(frame.color_key), np.uint8),
                         cv2.IMREAD_COLOR)
    if image is None:
        raise NotFound(f"the first frame of HIT {hit_id}'s view is not a readable image")
    height, width = image.shape[:2]
    size = (THUMBNAIL_WIDTH_PX, max(1, round(height * THUMBNAIL_WIDTH_PX / width)))
    small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    ok, data = cv2.imencode(".jpg", small, [cv2.IMWRITE_JPEG_QUALITY, THUMBNAIL_JPEG_QUALITY])
    if not ok:
        raise NotFound(f"the first frame of HIT {hit_id}'s view could not be encoded")
    return data.tobytes()
