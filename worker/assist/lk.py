"""Proposals between a worker's keyframes: pyramidal Lucas-Kanade run from both keyframes.

Conventions: ``frames`` (F, H, W) uint8 grey images of one view, ``frames[i]`` being clip frame
``first_frame + i``; positions in image pixels (x right, y down, the centre of the top-left
pixel at (0, 0), as OpenCV); keyframes per point as the annotation page saves them
(``[frame, x, y, visible01]`` rows or dicts, worker.tracks).

For each span between two consecutive keyframes k0 < k1 of a point, both visible with a
position and both among the frames given, the point is tracked frame by frame forward from
k0 and backward from k1 (every point of every span moves in one LK call per frame pair). Each
step is checked forward-backward: the tracked point is tracked back to the frame it came
from, and a step that does not come back within ``fb_threshold_px``, that LK reports lost
(status 0), whose window no longer looks like the point's (LK's residual over
RESIDUAL_LIMIT: something else moved over it) or that leaves the image stops that
direction's chain there for the rest of the span. At an inner frame f the two directions
are blended by distance to their keyframes (weight (f - k0) / (k1 - k0) on the backward
one); where only one direction still holds, it alone is the proposal; where neither does,
there is none (ok false) and the stored keyframes' linear interpolation stays the answer.

Pure: arrays in, arrays out. OpenCV's Python binding takes images, not prebuilt pyramids, so
each LK call builds the pyramids of its two frames, cut to the box around the points it
tracks; the calls are few (one per frame pair and direction, one per frame pair and direction
for the checks), the two directions run side by side and the checks of different frame pairs
in parallel threads (OpenCV releases the GIL).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from worker.tracks.keyframes import as_keyframes

# LK window and pyramid: 21 px windows over 4 levels follow a point moving up to about
# 2^3 x 10 = 80 px between frames, more than a hand moves between two 30 fps frames.
WINDOW_PX = 21
PYRAMID_LEVELS = 3
# A step that does not come back within a pixel has slid off its feature: textureless skin
# and occlusion boundaries give errors of several pixels, a tracked corner hundredths.
FB_THRESHOLD_PX = 1.0
# A step whose window changes by more than this mean absolute difference (grey levels, LK's
# own residual) is something else moving over the point: a point covered by another textured
# surface can come back through the forward-backward check, but never with its own look.
RESIDUAL_LIMIT = 12.0
# Room around the points' box for the motion between two frames and the LK window: a fast
# hand moves up to about 40 px between frames (24-frame clips), the window reaches 10 px.
CROP_MARGIN_PX = 64
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01)
_THREADS = 4


@dataclass(frozen=True)
class Proposals:
    """Proposed positions of P points over the F frames given.

    xy: (F, P, 2) float64 image px; NaN where there is no proposal.
    ok: (F, P) bool; True where ``xy`` is a proposal (an inner frame of a tracked span whose
        forward or backward chain still holds there). Keyframes themselves are never proposed.
    fb_error: (F, P) float64 px; the larger forward-backward error of the steps that reached
        the frame (of the directions used), or of the step that stopped a chain there; NaN
        where nothing was tracked.
    first_frame: the clip frame of ``xy[0]``.
    """

    xy: np.ndarray
    ok: np.ndarray
    fb_error: np.ndarray
    first_frame: int


@dataclass(frozen=True)
class _Spans:
    """S spans as parallel arrays, frames local to ``frames`` (0..F-1)."""

    point: np.ndarray   # (S,) int
    k0: np.ndarray      # (S,) int
    k1: np.ndarray      # (S,) int
    start: np.ndarray   # (S, 2) float32 position at k0
    end: np.ndarray     # (S, 2) float32 position at k1


def _check_frames(frames: np.ndarray) -> np.ndarray:
    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.dtype != np.uint8:
        raise ValueError(f"frames must be (F, H, W) uint8 grey images, got {frames.shape} "
                         f"{frames.dtype}")
    return frames


def tracked_spans(keyframes: Sequence[Sequence[Any]], first_frame: int, num_frames: int,
                  min_gap: int = 2
                  ) -> list[tuple[int, int, int, tuple[float, float], tuple[float, float]]]:
    """(point, k0, k1, start xy, end xy) of every span worth tracking: consecutive keyframes
    of a point at least ``min_gap`` frames apart (2: a frame between them), both visible with
    a position and both within clip frames first_frame .. first_frame + num_frames - 1 (k0, k1
    are clip frames)."""
    out = []
    last = first_frame + num_frames - 1
    for point, rows in enumerate(keyframes):
        kfs = as_keyframes(rows)
        for a, b in itertools.pairwise(kfs):
            if (b.frame - a.frame >= min_gap and a.visible and b.visible and a.has_position
                    and b.has_position and first_frame <= a.frame and b.frame <= last):
                out.append((point, a.frame, b.frame, (float(a.x or 0.0), float(a.y or 0.0)),
                            (float(b.x or 0.0), float(b.y or 0.0))))
    return out


def _as_spans(found: list[tuple[int, int, int, tuple[float, float], tuple[float, float]]],
              first_frame: int) -> _Spans:
    return _Spans(
        point=np.array([s[0] for s in found], dtype=np.int64),
        k0=np.array([s[1] - first_frame for s in found], dtype=np.int64),
        k1=np.array([s[2] - first_frame for s in found], dtype=np.int64),
        start=np.array([s[3] for s in found], dtype=np.float32).reshape(-1, 2),
        end=np.array([s[4] for s in found], dtype=np.float32).reshape(-1, 2),
    )


def _lk(a: np.ndarray, b: np.ndarray, pts: np.ndarray
        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LK from image a to image b: (N, 2) float32 tracked positions, (N,) bool status and (N,)
    residual (mean absolute difference of the two windows, grey levels).

    Both images are cut to the points' box with CROP_MARGIN_PX around it first, so that the
    pyramids and gradients OpenCV makes for each call cover the points, not the whole frame.
    """
    start = np.ascontiguousarray(pts, dtype=np.float32).reshape(-1, 2)
    height, width = a.shape
    low = np.floor(start.min(axis=0)).astype(int) - CROP_MARGIN_PX
    high = np.ceil(start.max(axis=0)).astype(int) + CROP_MARGIN_PX + 1
    x0, y0 = max(int(low[0]), 0), max(int(low[1]), 0)
    x1, y1 = min(int(high[0]), width), min(int(high[1]), height)
    if x1 <= x0 or y1 <= y0:
        # Every point has left the image (a followed chain can step out): nothing to track.
        count = len(start)
        return start, np.zeros(count, dtype=bool), np.full(count, np.inf, dtype=np.float32)
    offset = np.array([x0, y0], dtype=np.float32)
    local = (start - offset).reshape(-1, 1, 2)
    moved, status, residual = cv2.calcOpticalFlowPyrLK(
        np.ascontiguousarray(a[y0:y1, x0:x1]), np.ascontiguousarray(b[y0:y1, x0:x1]), local,
        local.copy(), winSize=(WINDOW_PX, WINDOW_PX), maxLevel=PYRAMID_LEVELS,
        criteria=_CRITERIA)
    return (moved.reshape(-1, 2) + offset, status.reshape(-1).astype(bool),
            residual.reshape(-1))


def _chain(frames: np.ndarray, spans: _Spans, forward: bool
           ) -> tuple[np.ndarray, np.ndarray]:
    """One direction's chains, unchecked: (F, S, 2) positions (NaN outside each span's inner
    frames) and (F, S) whether LK found the step that reached each frame and within
    RESIDUAL_LIMIT."""
    count = frames.shape[0]
    xy = np.full((count, len(spans.point), 2), np.nan, dtype=np.float32)
    status = np.zeros((count, len(spans.point)), dtype=bool)
    pos = (spans.start if forward else spans.end).copy()
    steps = range(count - 1) if forward else range(count - 1, 0, -1)
    for t in steps:
        to = t + 1 if forward else t - 1
        # Forward: frames k0 .. k1-2 step to k0+1 .. k1-1; backward: k1 .. k0+2 to k1-1 .. k0+1.
        active = ((spans.k0 <= t) & (to <= spans.k1 - 1) if forward
                  else (t <= spans.k1) & (to >= spans.k0 + 1))
        idx = np.flatnonzero(active)
        if idx.size == 0:
            continue
        moved, found, residual = _lk(frames[t], frames[to], pos[idx])
        pos[idx] = moved
        xy[to, idx] = moved
        status[to, idx] = found & (residual <= RESIDUAL_LIMIT)
    return xy, status


def _fb_errors(frames: np.ndarray, xy: np.ndarray, tracked: np.ndarray, forward: bool
               ) -> np.ndarray:
    """(F, S) forward-backward error (px) of each step of one direction's chains: the position
    reached at frame f (``tracked``) taken back to the frame it came from, against where it
    was there (``xy`` holds each span's keyframe at its start). inf where tracking back
    fails, NaN where nothing was tracked."""
    err = np.full(tracked.shape, np.nan)

    def check(f: int) -> None:
        came = f - 1 if forward else f + 1
        idx = np.flatnonzero(tracked[f])
        if idx.size == 0:
            return
        back, ok, _ = _lk(frames[f], frames[came], xy[f, idx])
        err[f, idx] = np.where(ok, np.linalg.norm(back - xy[came, idx], axis=1), np.inf)

    with ThreadPoolExecutor(_THREADS) as pool:
        list(pool.map(check, range(frames.shape[0])))
    return err


def _held(xy: np.ndarray, status: np.ndarray, err: np.ndarray, size: tuple[int, int],
          threshold: float, forward: bool) -> np.ndarray:
    """(F, S) bool: frames where the chain still holds, i.e. every step up to that one was
    found, inside the image and came back within the threshold."""
    width, height = size
    inside = ((xy[..., 0] >= 0) & (xy[..., 0] <= width - 1)
              & (xy[..., 1] >= 0) & (xy[..., 1] <= height - 1))
    good = status & inside & (err <= threshold)
    tracked = np.isfinite(xy[..., 0])
    # A chain holds at a frame while no tracked step before it (in its direction) failed.
    failed = tracked & ~good
    order = slice(None) if forward else slice(None, None, -1)
    failed_so_far = np.cumsum(failed[order], axis=0)[order] > 0
    return tracked & ~failed_so_far


def _origin_fill(xy: np.ndarray, spans: _Spans, forward: bool) -> np.ndarray:
    """The chain positions with each span's keyframe written at its start frame, so that
    the first step's check compares with the keyframe."""
    out = xy.copy()
    s = np.arange(len(spans.point))
    if forward:
        out[spans.k0, s] = spans.start
    else:
        out[spans.k1, s] = spans.end
    return out


def _direction(frames: np.ndarray, spans: _Spans, forward: bool, threshold: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, S, 2) positions, (F, S) held and (F, S) step error of one direction."""
    xy, status = _chain(frames, spans, forward)
    tracked = np.isfinite(xy[..., 0])
    err = _fb_errors(frames, _origin_fill(xy, spans, forward), tracked, forward)
    size = (frames.shape[2], frames.shape[1])
    return xy.astype(np.float64), _held(xy, status, err, size, threshold, forward), err


def propose(frames: np.ndarray, keyframes: Sequence[Sequence[Any]], *, first_frame: int = 0,
            fb_threshold_px: float = FB_THRESHOLD_PX) -> Proposals:
    """Proposals for P points over the given frames.

    Args:
        frames: (F, H, W) uint8 grey images; frames[i] is clip frame first_frame + i.
        keyframes: P tracks, each a list of keyframe rows (clip frames; any frame, only spans
            with both keyframes within the frames given are tracked).
        first_frame: the clip frame of frames[0].
        fb_threshold_px: largest forward-backward error (px) of a step that is kept.

    Returns:
        :class:`Proposals` (F, P) over the frames given.
    """
    frames = _check_frames(frames)
    count, points = frames.shape[0], len(keyframes)
    xy = np.full((count, points, 2), np.nan)
    ok = np.zeros((count, points), dtype=bool)
    fb = np.full((count, points), np.nan)
    found = tracked_spans(keyframes, first_frame, count)
    if found:
        spans = _as_spans(found, first_frame)
        with ThreadPoolExecutor(2) as pool:
            fwd_job = pool.submit(_direction, frames, spans, True, fb_threshold_px)
            bwd_job = pool.submit(_direction, frames, spans, False, fb_threshold_px)
            fwd, bwd = fwd_job.result(), bwd_job.result()
        _blend(spans, fwd, bwd, xy, ok, fb)
    return Proposals(xy=xy, ok=ok, fb_error=fb, first_frame=first_frame)


def _blend(spans: _Spans, fwd: tuple[np.ndarray, np.ndarray, np.ndarray],
           bwd: tuple[np.ndarray, np.ndarray, np.ndarray], xy: np.ndarray, ok: np.ndarray,
           fb: np.ndarray) -> None:
    """Write each span's inner frames into the (F, P) outputs: the held directions blended by
    distance to their keyframes."""
    (xf, hf, ef), (xb, hb, eb) = fwd, bwd
    frame = np.arange(xy.shape[0])[:, None].astype(np.float64)
    length = (spans.k1 - spans.k0).astype(np.float64)[None, :]
    w_back = np.clip((frame - spans.k0[None, :]) / length, 0.0, 1.0)
    wf, wb = np.where(hf, 1.0 - w_back, 0.0), np.where(hb, w_back, 0.0)
    total = wf + wb
    held = total > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        blended = (np.nan_to_num(xf) * wf[..., None] + np.nan_to_num(xb) * wb[..., None]) \
            / total[..., None]
        used_err = np.fmax(np.where(hf, ef, np.nan), np.where(hb, eb, np.nan))
    stopped_err = np.fmax(ef, eb)
    inner = (frame > spans.k0[None, :]) & (frame < spans.k1[None, :])
    for s, point in enumerate(spans.point):
        rows = np.flatnonzero(inner[:, s])
        xy[rows, point] = np.where(held[rows, s, None], blended[rows, s], np.nan)
        ok[rows, point] = held[rows, s]
        fb[rows, point] = np.where(held[rows, s], used_err[rows, s], stopped_err[rows, s])


# Why a one-sided chain stopped (Followed.stopped).
STOP_LOST = "lost"          # LK lost the point, its look changed or it did not come back
STOP_LEFT_IMAGE = "left_image"
STOP_END = "end"            # it held to the last frame given


@dataclass(frozen=True)
class Followed:
    """S points followed from one keyframe each, in one direction, over the F frames given.

    xy: (F, S, 2) float64 image px; NaN where the chain does not hold (and at the start).
    ok: (F, S) bool; True on the frames after (forward) or before (backward) the start up to
        the last one the chain holds at.
    fb_error: (F, S) float64 px; as Proposals.fb_error.
    reached: (S,) int; the clip frame the chain last holds at (the start when none).
    stopped: S reasons, STOP_*.
    """

    xy: np.ndarray
    ok: np.ndarray
    fb_error: np.ndarray
    reached: np.ndarray
    stopped: list[str]


def follow(frames: np.ndarray, starts: Sequence[tuple[int, float, float, bool]], *,
           first_frame: int = 0, fb_threshold_px: float = FB_THRESHOLD_PX) -> Followed:
    """Each start keyframe followed frame by frame, forward or backward, until a step fails
    the checks of :func:`propose` (LK status, residual, forward-backward error, the image's
    edge) or the frames end.

    Args:
        frames: (F, H, W) uint8 grey images; frames[i] is clip frame first_frame + i.
        starts: S (clip frame, x px, y px, forward) keyframes to follow; each frame among
            those given.
        first_frame: the clip frame of frames[0].
        fb_threshold_px: largest forward-backward error (px) of a step that is kept.
    """
    frames = _check_frames(frames)
    count, total = frames.shape[0], len(starts)
    xy = np.full((count, total, 2), np.nan)
    ok = np.zeros((count, total), dtype=bool)
    fb = np.full((count, total), np.nan)
    reached = np.array([int(s[0]) for s in starts], dtype=np.int64)
    stopped = [STOP_END] * total
    for s in starts:
        if not 0 <= int(s[0]) - first_frame < count:
            raise ValueError(f"start frame {s[0]} is outside frames {first_frame}-"
                             f"{first_frame + count - 1}")
    size = (frames.shape[2], frames.shape[1])
    for forward in (True, False):
        idx = [i for i, s in enumerate(starts) if bool(s[3]) == forward]
        if not idx:
            continue
        at = np.array([int(starts[i][0]) - first_frame for i in idx], dtype=np.int64)
        pos = np.array([starts[i][1:3] for i in idx], dtype=np.float32).reshape(-1, 2)
        # An open span: the far end one frame past the frames given, so every frame after
        # (before) the start is an inner frame of it.
        far = np.full_like(at, count if forward else -1)
        spans = _Spans(point=np.arange(len(idx)), k0=at if forward else far,
                       k1=far if forward else at, start=pos, end=pos)
        chain, status = _chain(frames, spans, forward)
        tracked = np.isfinite(chain[..., 0])
        err = _fb_errors(frames, _origin_fill(chain, spans, forward), tracked, forward)
        held = _held(chain, status, err, size, fb_threshold_px, forward)
        width, height = size
        inside = ((chain[..., 0] >= 0) & (chain[..., 0] <= width - 1)
                  & (chain[..., 1] >= 0) & (chain[..., 1] <= height - 1))
        for j, i in enumerate(idx):
            rows = np.flatnonzero(held[:, j])
            xy[rows, i] = chain[rows, j]
            ok[rows, i] = True
            fb[rows, i] = err[rows, j]
            if rows.size:
                reached[i] = first_frame + int(rows.max() if forward else rows.min())
            failed = np.flatnonzero(tracked[:, j] & ~held[:, j])
            if failed.size:
                first_failed = int(failed.min() if forward else failed.max())
                fb[first_failed, i] = err[first_failed, j]
                stopped[i] = STOP_LOST if inside[first_failed, j] else STOP_LEFT_IMAGE
    return Followed(xy=xy, ok=ok, fb_error=fb, reached=reached, stopped=stopped)
