"""Tracking proposals for the annotation page: positions between a worker's keyframes, found in
the view's own frames (worker.assist.lk: Lucas-Kanade from both keyframes, stopped by a
forward-backward check).

The page sends the keyframes it holds (the form it saves) and, if it wants, a frame range; the
answer has, per point and per frame of the range, a proposed position (image px), whether it
holds (ok) and its forward-backward error (px); at the assignment's check cells
(worker.assist.checks) an ok proposal is shown CHECK_OFFSET_PX off. Nothing is stored: the
stored model stays keyframes with linear interpolation, and a proposal the worker accepts is
saved as a keyframe.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.annotation import service
from backend.annotation.models import Assignment
from backend.annotation.schemas import MAX_POINTS, TrackIn, TracksSave
from backend.captures.models import Frame
from backend.config import get_settings
from backend.errors import DexlabelError, StorageError
from backend.storage import Storage
from backend.validation import MAX_INT32
from worker.assist.checks import check_key, plant
from worker.assist.lk import FB_THRESHOLD_PX, propose, tracked_spans

# Frames decoded for one request at most: 300 grey 640x480 frames are 92 MB in memory and
# about half a second of decoding; a longer stretch is asked for in parts.
MAX_PROPOSAL_FRAMES = 300
_DECODE_THREADS = 8


class InvalidProposalRequest(DexlabelError, status_code=422, code="invalid_proposal_request"):
    pass


class ProposalsRequest(BaseModel):
    """Keyframes to propose between (as saved: per point ``[frame, x, y, visible01]`` rows)
    and the clip frames to propose for (``first_frame``..``last_frame``, inclusive; default
    the whole clip)."""

    model_config = ConfigDict(extra="forbid")

    tracks: list[TrackIn] = Field(max_length=MAX_POINTS)
    first_frame: int | None = Field(default=None, ge=0, le=MAX_INT32)
    last_frame: int | None = Field(default=None, ge=0, le=MAX_INT32)


class PointProposals(BaseModel):
    """One point over the range: per frame a position [x, y] (image px) or null, whether it
    is a proposal that holds (ok; never at a keyframe), and the forward-backward error (px)
    of the tracking steps that reached it, or null where nothing was tracked."""

    point: int
    xy: list[list[float] | None]
    ok: list[bool]
    fb_error: list[float | None]


class ProposalsRead(BaseModel):
    first_frame: int
    last_frame: int
    fb_threshold_px: float
    points: list[PointProposals]


def _frame_range(body: ProposalsRequest, num_frames: int) -> tuple[int, int]:
    first = 0 if body.first_frame is None else body.first_frame
    last = num_frames - 1 if body.last_frame is None else body.last_frame
    problems = [f"{name} {value} is out of range 0-{num_frames - 1}"
                for name, value in (("first_frame", first), ("last_frame", last))
                if value >= num_frames]
    if not problems and first > last:
        problems.append(f"first_frame {first} is after last_frame {last}")
    if problems:
        raise InvalidProposalRequest("; ".join(problems))
    return first, last


def _window(rows: list[list[list[Any]]], first: int, last: int, num_frames: int
            ) -> tuple[int, int] | None:
    """The frames to read: from the first keyframe to the last of every span with inner
    frames in first..last; None when there is none."""
    spans = [(k0, k1) for _, k0, k1, _, _ in tracked_spans(rows, 0, num_frames)
             if k0 < last and k1 > first]
    if not spans:
        return None
    start, end = min(s[0] for s in spans), max(s[1] for s in spans)
    if end - start + 1 > MAX_PROPOSAL_FRAMES:
        raise InvalidProposalRequest(
            f"the keyframes around frames {first}-{last} span frames {start}-{end} "
            f"({end - start + 1} frames); at most {MAX_PROPOSAL_FRAMES} are tracked in one "
            "request: ask for a shorter frame range")
    return start, end


def grey_frames(session: Session, storage: Storage, camera_id: int, start: int, end: int,
                size: tuple[int, int]) -> np.ndarray:
    """(end - start + 1, H, W) uint8 grey images of one view's frames start..end, decoded
    in parallel from storage (cv2 releases the GIL)."""
    keys = list(session.scalars(select(Frame.color_key).where(
        Frame.camera_id == camera_id, Frame.index >= start, Frame.index <= end)
        .order_by(Frame.index)))
    if len(keys) != end - start + 1:
        raise StorageError(f"frames {start}-{end} of this view are not all stored")

    def decode(key: str) -> np.ndarray:
        image = cv2.imdecode(np.frombuffer(storage.get_bytes(key), np.uint8),
                             cv2.IMREAD_GRAYSCALE)
        if image is None or image.shape != (size[1], size[0]):
            raise StorageError(f"{key}: not a {size[0]}x{size[1]} image")
        return image

    with ThreadPoolExecutor(_DECODE_THREADS) as pool:
        return np.stack(list(pool.map(decode, keys)))


def _rounded(value: float) -> float | None:
    return None if value != value else round(value, 3)


def proposals(session: Session, storage: Storage, assignment: Assignment,
              body: ProposalsRequest) -> ProposalsRead:
    """Proposals for the points in ``body`` over its frame range, from the assignment's view.

    Raises InvalidTracks (422) for keyframes the page could not save, and
    InvalidProposalRequest (422) for a frame range outside the clip or too long to track.
    """
    task = service.get_task_or_raise(session, assignment.task_id)
    num_frames, size = task.sequence.num_frames, (task.camera.width, task.camera.height)
    # The same checks as a save, so that what the page can save it can also ask about.
    rows = service.check_tracks(service.clip_of(session, task.id),
                                TracksSave(version=0, tracks=body.tracks))
    first, last = _frame_range(body, num_frames)
    count, wanted = last - first + 1, sorted({t.point for t in body.tracks})
    xy = np.full((count, len(rows), 2), np.nan)
    ok = np.zeros((count, len(rows)), dtype=bool)
    fb = np.full((count, len(rows)), np.nan)
    window = _window(rows, first, last, num_frames)
    if window is not None:
        start, end = window
        frames = grey_frames(session, storage, task.camera_id, start, end, size)
        found = propose(frames, rows, first_frame=start)
        lo, hi = max(first, start), min(last, end)
        xy[lo - first:hi - first + 1] = found.xy[lo - start:hi - start + 1]
        ok[lo - first:hi - first + 1] = found.ok[lo - start:hi - start + 1]
        fb[lo - first:hi - first + 1] = found.fb_error[lo - start:hi - start + 1]
    # The assignment's check cells, as in every suggestion the page shows.
    xy = np.swapaxes(plant(check_key(get_settings().signing_key), assignment.id,
                           np.swapaxes(xy, 0, 1), ok.T, first, num_frames, task.num_points,
                           *size), 0, 1)
    points = [PointProposals(
        point=p,
        xy=[[round(float(v[0]), 3), round(float(v[1]), 3)] if np.isfinite(v).all() else None
            for v in xy[:, p]],
        ok=ok[:, p].tolist(),
        fb_error=[_rounded(float(e)) for e in fb[:, p]],
    ) for p in wanted]
    return ProposalsRead(first_frame=first, last_frame=last, fb_threshold_px=FB_THRESHOLD_PX,
                         points=points)
