"""Tracking proposals for the annotation page: positions between a worker's keyframes, found in
the view's own frames (worker.assist.lk: Lucas-Kanade from both keyframes, stopped by a
forward-backward check), and positions after a point's last keyframe or before its first,
followed from that one keyframe until the same checks stop it (``follow``).

The page sends the keyframes it holds (the form it saves) and, if it wants, a frame range; the
answer has, per point and per frame of the range, a proposed position (image px), whether it
holds (ok) and its forward-backward error (px); at the assignment's check cells
(worker.assist.checks) an ok proposal is shown CHECK_OFFSET_PX off. Nothing is stored: the
stored model stays keyframes with linear interpolation, and a proposal the worker accepts is
saved as a keyframe.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any, Literal

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
from worker.assist.lk import FB_THRESHOLD_PX, Followed, follow, propose, tracked_spans
from worker.tracks.keyframes import as_keyframes

# Frames decoded for one request at most: 300 grey 640x480 frames are 92 MB in memory and
# about half a second of decoding; a longer stretch is asked for in parts.
MAX_PROPOSAL_FRAMES = 300
_DECODE_THREADS = 8


class InvalidProposalRequest(DexlabelError, status_code=422, code="invalid_proposal_request"):
    pass


class FollowIn(BaseModel):
    """Follow a point from one keyframe: forward from its last keyframe (to ``last_frame``) or
    backward from its first (to ``first_frame``)."""

    model_config = ConfigDict(extra="forbid")

    point: int = Field(ge=0, lt=MAX_POINTS)
    direction: Literal["forward", "backward"]


class ProposalsRequest(BaseModel):
    """Keyframes to propose between (as saved: per point ``[frame, x, y, visible01]`` rows),
    the clip frames to propose for (``first_frame``..``last_frame``, inclusive; default the
    whole clip) and the points to follow beyond their outermost keyframe."""

    model_config = ConfigDict(extra="forbid")

    tracks: list[TrackIn] = Field(max_length=MAX_POINTS)
    first_frame: int | None = Field(default=None, ge=0, le=MAX_INT32)
    last_frame: int | None = Field(default=None, ge=0, le=MAX_INT32)
    follow: list[FollowIn] = Field(default_factory=list, max_length=2 * MAX_POINTS)


class FollowStop(BaseModel):
    """Where a followed point stopped: the keyframe it started from (``from_frame``), the last
    frame it holds at (``reached``; ``from_frame`` when none) and why: ``lost`` (the tracker
    lost the point or its look changed), ``left_image`` or ``end`` (it held to the end of the
    range)."""

    point: int
    direction: Literal["forward", "backward"]
    from_frame: int
    reached: int
    stopped: str


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
    stops: list[FollowStop] = Field(default_factory=list)


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


def _window(rows: list[list[list[Any]]], first: int, last: int, num_frames: int,
            starts: list[tuple[int, int, float, float, bool]]) -> tuple[int, int] | None:
    """The frames to read: from the first keyframe to the last of every span with inner
    frames in first..last, and each followed point's range; None when there is none."""
    spans = [(k0, k1) for _, k0, k1, _, _ in tracked_spans(rows, 0, num_frames)
             if k0 < last and k1 > first]
    spans += [(frame, last) if forward else (first, frame)
              for _, frame, _, _, forward in starts]
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


def _follow_starts(body: ProposalsRequest, rows: list[list[list[Any]]], first: int, last: int
                   ) -> list[tuple[int, int, float, float, bool]]:
    """(point, frame, x, y, forward) of each follow asked for: the point's last keyframe
    (forward) or first (backward), which must be visible with a position inside the range."""
    starts, problems = [], []
    for f in body.follow:
        forward = f.direction == "forward"
        kfs = as_keyframes(rows[f.point]) if f.point < len(rows) else []
        if not kfs:
            problems.append(f"point {f.point} has no keyframe to follow from")
            continue
        k = kfs[-1] if forward else kfs[0]
        if not (k.visible and k.has_position):
            problems.append(f"point {f.point}: its {'last' if forward else 'first'} keyframe "
                            f"(frame {k.frame}) is occluded; a followed point starts visible")
        elif not first <= k.frame <= last:
            problems.append(f"point {f.point}: its keyframe at frame {k.frame} is outside "
                            f"frames {first}-{last}")
        else:
            starts.append((f.point, k.frame, float(k.x or 0.0), float(k.y or 0.0), forward))
    if problems:
        raise InvalidProposalRequest("; ".join(problems))
    return starts


def _followed(frames: np.ndarray, start: int, first: int, last: int,
              starts: list[tuple[int, int, float, float, bool]], forward: bool
              ) -> tuple[list[tuple[int, int, float, float, bool]], Followed, int] | None:
    """One direction's follows over frames (clip frames start..): the starts, what
    worker.assist.lk.follow found and the clip frame of its first row; None when none."""
    mine = [s for s in starts if s[4] == forward]
    if not mine:
        return None
    lo = min(s[1] for s in mine) if forward else first
    hi = last if forward else max(s[1] for s in mine)
    found = follow(frames[lo - start:hi - start + 1],
                   [(frame, x, y, fwd) for _, frame, x, y, fwd in mine], first_frame=lo)
    return mine, found, lo


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
    starts = _follow_starts(body, rows, first, last)
    stops: list[FollowStop] = []
    window = _window(rows, first, last, num_frames, starts)
    if window is not None:
        start, end = window
        frames = grey_frames(session, storage, task.camera_id, start, end, size)
        found = propose(frames, rows, first_frame=start)
        lo, hi = max(first, start), min(last, end)
        xy[lo - first:hi - first + 1] = found.xy[lo - start:hi - start + 1]
        ok[lo - first:hi - first + 1] = found.ok[lo - start:hi - start + 1]
        fb[lo - first:hi - first + 1] = found.fb_error[lo - start:hi - start + 1]
        for forward in (True, False):
            part = _followed(frames, start, first, last, starts, forward)
            if part is not None:
                stops += _write_followed(*part, first, xy, ok, fb)
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
                         points=points, stops=stops)


def _write_followed(mine: list[tuple[int, int, float, float, bool]], found: Followed, lo: int,
                    first: int, xy: np.ndarray, ok: np.ndarray, fb: np.ndarray
                    ) -> list[FollowStop]:
    """Writes the held frames of each follow into the range's (R, P) outputs; their stops."""
    stops = []
    for i, (point, frame, _, _, forward) in enumerate(mine):
        rows = np.flatnonzero(found.ok[:, i])
        xy[rows + lo - first, point] = found.xy[rows, i]
        ok[rows + lo - first, point] = True
        fb[rows + lo - first, point] = found.fb_error[rows, i]
        stops.append(FollowStop(point=point, direction="forward" if forward else "backward",
                                from_frame=frame, reached=int(found.reached[i]),
                                stopped=found.stopped[i]))
    return stops
