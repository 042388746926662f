"""Pre-fill suggestions: where the accepted work of a target's other views places its points in
one more view, and the epipolar lines that guide a worker there.

A target (a hand or an object of a sequence) is labelled in every camera view. Once its work is
accepted in at least MIN_ACCEPTED_VIEWS other views, each point is triangulated per frame from
the views that saw it (at least MIN_VIEWS; robustly, worker.geometry.triangulate) and projected
into the target view with its lens distortion: a suggested position, image px. Its suggested
visibility comes from the target view's depth map, with QC's own rule
(worker.assist.visibility.surface_check): occluded where something other than the hand covers the
point by more than HIDDEN_MARGIN_M, or where the point projects outside the image or behind the
camera; visible where the depth map reads at its pixel and covers nothing; unknown where the map
has no reading there (or there is no map).

Only decided positions count (worker.tracks.sources.decided_mask): a keyframe the worker took
unchanged from a pre-fill suggestion (source "prefilled") is the suggestion's own echo, not
evidence; nor is a span between two such keyframes.

Conventions as in worker.geometry.cameras: pixels x right, y down; world metres; depth maps
(F, H, W) uint16 millimetres along the camera's z axis, 0 = no reading. F frames, P points,
L labels (accepted assignments; a view may have several), V cameras.

Pure: arrays in, arrays out (a depth reader given as a callable is called from a few threads).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from worker.assist.visibility import HIDDEN_MARGIN_M, WINDOW_RADIUS_PX, surface_check
from worker.geometry.cameras import CameraModel, pixels_to_rays
from worker.geometry.triangulate import triangulate_points
from worker.tracks.interpolate import dense_points
from worker.tracks.sources import decided_mask

# Fewest other views with decided work on a point before it is suggested: two rays fix it.
MIN_VIEWS = 2
# Fewest other views with accepted work before a view's suggestions are triangulated. QC
# judges a point only where three views decide it (each view's labels against the other two),
# so from three on the work the suggestions come from has been judged; with one or two the
# hand model (or the object's mesh) fitted to that work suggests instead
# (worker.solver.suggest). Pre-filled positions are never evidence either way.
MIN_ACCEPTED_VIEWS = 3
# Reprojection error (px) above which a label is an outlier of the triangulation: five times
# the 2 px per-axis noise of a careful label at 640x480, as QC's consensus (HandOptions).
OUTLIER_PX = 10.0
# Depth maps decoded at once when the depth is given as a reader.
_READ_THREADS = 4

DepthReader = Callable[[int], np.ndarray]


@dataclass(frozen=True)
class ViewWork:
    """One accepted assignment's labels of one view, dense.

    view: index into the cameras. xy: (F, P, 2) image px, NaN where there is no position.
    visible: (F, P) bool. decided: (F, P) bool, the positions the worker decided (not echoes
    of a pre-fill suggestion).
    """

    view: int
    xy: np.ndarray
    visible: np.ndarray
    decided: np.ndarray


@dataclass(frozen=True)
class Prefill:
    """Suggestions for the target view.

    xy: (F, P, 2) image px, NaN where nothing is suggested (fewer than MIN_VIEWS views, no
    consistent triangulation, or the point falls outside the image).
    visible: (F, P) bool suggested visibility, meaningful where ``known``.
    known: (F, P) bool, whether a visibility is suggested (no depth reading: unknown).
    views: (F, P) int, distinct views the point was triangulated from (0: none).
    points: (F, P, 3) world metres, NaN where not triangulated.
    """

    xy: np.ndarray
    visible: np.ndarray
    known: np.ndarray
    views: np.ndarray
    points: np.ndarray


def view_work(view: int, tracks: Iterable[tuple[int, Sequence[Any]]], num_frames: int,
              num_points: int) -> ViewWork:
    """An assignment's stored tracks, given as (point index, keyframe rows) pairs, as dense
    ViewWork (image px); decided as worker.tracks.sources.decided_mask has it (not unplaced, not
    only from unedited pre-filled keyframes)."""
    tracks = list(tracks)
    xy, visible = dense_points(tracks, num_frames, num_points)
    decided = np.zeros((num_frames, num_points), dtype=bool)
    for point, rows in tracks:
        if 0 <= point < num_points:
            decided[:, point] = decided_mask(rows, num_frames)
    return ViewWork(view=view, xy=xy, visible=visible, decided=decided)


def _check_work(cameras: list[CameraModel], work: list[ViewWork], target: int
                ) -> tuple[int, int]:
    """(F, P) shared by all the work; ValueError naming the problem otherwise."""
    if not 0 <= target < len(cameras):
        raise ValueError(f"target view {target} is not in 0..{len(cameras) - 1}")
    if not work:
        raise ValueError("work must not be empty")
    frames, points = np.shape(work[0].xy)[:2]
    for i, w in enumerate(work):
        shapes = (np.shape(w.xy), np.shape(w.visible), np.shape(w.decided))
        if shapes != ((frames, points, 2), (frames, points), (frames, points)):
            raise ValueError(f"work {i}: xy must have shape (F={frames}, P={points}, 2), visible "
                             f"and decided (F, P); got {shapes[0]}, {shapes[1]}, {shapes[2]}")
        if not 0 <= w.view < len(cameras) or w.view == target:
            raise ValueError(f"work {i}: view {w.view} is not another view of 0..{len(cameras) - 1}"
                             f" than the target {target}")
    return frames, points


def distinct_views(work: list[ViewWork]) -> list[int]:
    """The views the work covers, sorted."""
    return sorted({w.view for w in work})


def triangulate_work(cameras: list[CameraModel], work: list[ViewWork],
                     outlier_px: float = OUTLIER_PX) -> tuple[np.ndarray, np.ndarray]:
    """(F, P, 3) world metres of every point from the decided visible labels (NaN where fewer
    than MIN_VIEWS distinct views agree) and (F, P) how many distinct views it rests on."""
    frames, points = np.shape(work[0].xy)[:2]
    columns = [cameras[w.view] for w in work]
    pixels = np.stack([np.where((w.visible & w.decided)[..., None], w.xy, np.nan)
                       for w in work], axis=2).reshape(frames * points, len(work), 2)
    observed = np.isfinite(pixels).all(axis=-1)
    views = np.array([w.view for w in work])
    seen_in = np.stack([(observed & (views == v)).any(axis=1) for v in np.unique(views)], axis=1)
    out = np.full((frames * points, 3), np.nan)
    counts = np.zeros(frames * points, dtype=int)
    enough = seen_in.sum(axis=1) >= MIN_VIEWS
    if enough.any():
        fit = triangulate_points(columns, pixels[enough], outlier_px=outlier_px)
        inlier_views = np.stack([(fit.inliers & (views == v)).any(axis=1)
                                 for v in np.unique(views)], axis=1).sum(axis=1)
        good = (inlier_views >= MIN_VIEWS) & np.isfinite(fit.points).all(axis=1)
        out[np.flatnonzero(enough)[good]] = fit.points[good]
        counts[np.flatnonzero(enough)[good]] = inlier_views[good]
    return out.reshape(frames, points, 3), counts.reshape(frames, points)


class _DepthFrames:
    """(F, H, W) depth maps as surface_check indexes them, from an array or a reader of one
    frame; each frame is read at most once. A reader's frames can be started early (a few
    at once, in threads: decoding releases the GIL) and are waited for when needed."""

    ndim = 3

    def __init__(self, depth: np.ndarray | DepthReader, shape: tuple[int, int, int]) -> None:
        self.shape = shape
        self._cache: dict[int, np.ndarray] = {}
        self._pending: dict[int, Future[np.ndarray]] = {}
        self._reader: DepthReader | None = None
        if callable(depth):
            self._reader = depth
            return
        array = np.asarray(depth)
        if array.shape != shape:
            raise ValueError(f"depth must have shape (F, H, W) = {shape}, got {array.shape}")
        self._cache = dict(enumerate(array))

    def start(self, frames: Iterable[int]) -> None:
        """Start reading these frames in the background."""
        if self._reader is None:
            return
        todo = sorted({int(f) for f in frames} - set(self._cache) - set(self._pending))
        if todo:
            pool = ThreadPoolExecutor(_READ_THREADS)
            self._pending.update((f, pool.submit(self._reader, f)) for f in todo)
            pool.shutdown(wait=False)

    def read(self, frames: Iterable[int]) -> None:
        """Have these frames read (waits for those started)."""
        frames = [int(f) for f in frames]
        self.start(frames)
        for frame in frames:
            if frame not in self._pending:
                continue
            depth = np.asarray(self._pending.pop(frame).result())
            if depth.shape != self.shape[1:]:
                raise ValueError(f"depth of frame {frame} must have shape (H, W) = "
                                 f"{self.shape[1:]}, got {depth.shape}")
            self._cache[frame] = depth

    def __getitem__(self, index: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        frames, rows, cols = (np.asarray(i, dtype=np.int64) for i in index)
        self.read(np.unique(frames).tolist())
        out = np.zeros(frames.shape, dtype=np.uint16)
        for frame in np.unique(frames):
            at = frames == frame
            out[at] = self._cache[int(frame)][rows[at], cols[at]]
        return out


def _window_readings(maps: _DepthFrames, pix: np.ndarray, inside: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(centre, farthest), each (F, P) metres (0 = no reading): the depth at each inside
    point's pixel and the farthest within WINDOW_RADIUS_PX of it."""
    frames, height, width = maps.shape
    r = WINDOW_RADIUS_PX
    offsets = np.array([(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)])
    f_idx = np.broadcast_to(np.arange(frames)[:, None], inside.shape)[inside]
    rows = np.clip(np.rint(pix[inside][:, 1]).astype(int)[:, None] + offsets[:, 0], 0,
                   height - 1)
    cols = np.clip(np.rint(pix[inside][:, 0]).astype(int)[:, None] + offsets[:, 1], 0,
                   width - 1)
    window = maps[np.broadcast_to(f_idx[:, None], rows.shape), rows, cols] / 1000.0
    centre, farthest = np.zeros(inside.shape), np.zeros(inside.shape)
    centre[inside] = window[:, len(offsets) // 2]
    farthest[inside] = window.max(axis=1)
    return centre, farthest


def suggested_visibility(camera: CameraModel, points: np.ndarray,
                         depth: np.ndarray | DepthReader | _DepthFrames | None
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(inside, visible, known), each (F, P) bool, for world points (F, P, 3) in one view.

    inside: the point projects into the image (0 <= x < width, 0 <= y < height) in front of
    the camera; outside it is occluded (known). Inside, with QC's rule (surface_check): hidden
    is occluded; a reading at the point's pixel that hides nothing is visible. Where the pixel
    itself has no reading (sensors drop out at depth edges, along every finger), a reading
    within WINDOW_RADIUS_PX that sees as far as the point (less HIDDEN_MARGIN_M) makes it
    visible; with none, the visibility is unknown.
    """
    frames = points.shape[0]
    pix, z = camera.project(points), camera.depth_of(points)
    with np.errstate(invalid="ignore"):
        inside = (np.isfinite(pix).all(axis=-1) & (z > 0) & (pix[..., 0] >= 0)
                  & (pix[..., 0] < camera.width) & (pix[..., 1] >= 0)
                  & (pix[..., 1] < camera.height))
    known = np.isfinite(points).all(axis=-1) & ~inside
    visible = np.zeros(inside.shape, dtype=bool)
    if depth is None or not inside.any():
        return inside, visible, known
    maps = depth if isinstance(depth, _DepthFrames) else \
        _DepthFrames(depth, (frames, camera.height, camera.width))
    maps.read(np.flatnonzero(inside.any(axis=1)).tolist())
    hidden = surface_check(camera, points, maps).hidden
    centre, farthest = _window_readings(maps, pix, inside)
    read = inside & (centre > 0)
    with np.errstate(invalid="ignore"):
        seen_beside = inside & ~read & (farthest > 0) & (z - farthest <= HIDDEN_MARGIN_M)
    visible = (read & ~hidden) | seen_beside
    return inside, visible, known | read | seen_beside


def prefill(cameras: list[CameraModel], work: list[ViewWork], target: int,
            depth: np.ndarray | DepthReader | None = None,
            outlier_px: float = OUTLIER_PX) -> Prefill:
    """Suggestions for view ``target`` from the accepted work of the other views.

    Args:
        cameras: the sequence's V views (``ViewWork.view`` and ``target`` index them).
        work: the target's accepted assignments in other views (at least one).
        target: the view to suggest for.
        depth: the target view's depth maps, (F, H, W) uint16 mm (0 = no reading), or a
            reader ``frame -> (H, W)`` of them; None: visibility is known only off the image.
        outlier_px: the triangulation's inlier threshold, px.
    """
    frames = _check_work(cameras, work, target)[0]
    camera = cameras[target]
    maps = None if depth is None else \
        _DepthFrames(depth, (frames, camera.height, camera.width))
    if maps is not None:
        maps.start(range(frames))  # read while the points are triangulated
    world, views = triangulate_work(cameras, work, outlier_px)
    inside, visible, known = suggested_visibility(camera, world, maps)
    xy = np.where(inside[..., None], camera.project(world), np.nan)
    return Prefill(xy=xy, visible=visible, known=known, views=views, points=world)


def fundamental_matrix(source: CameraModel, target: CameraModel) -> np.ndarray:
    """(3, 3) F with ``F @ [x, y, 1]`` the epipolar line (a, b, c), a x + b y + c = 0, in the
    target view of pixel (x, y) of the source view; both in undistorted pinhole pixels (see
    undistorted_pixels). Scaled to unit Frobenius norm; divide each line by hypot(a, b) for
    distances in px (epipolar_lines)."""
    rot_s, centre_s = source.T_cam_to_world[:, :3], source.T_cam_to_world[:, 3]
    rot_t, centre_t = target.T_cam_to_world[:, :3], target.T_cam_to_world[:, 3]
    # Source camera frame -> target camera frame: x_t = R x_s + t.
    rot = rot_t.T @ rot_s
    t = rot_t.T @ (centre_s - centre_t)
    cross = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    essential = cross @ rot
    f = np.linalg.inv(target.K).T @ essential @ np.linalg.inv(source.K)
    return f / np.linalg.norm(f)


def undistorted_pixels(camera: CameraModel, xy: np.ndarray) -> np.ndarray:
    """Pixels (..., 2) of the camera -> where an ideal pinhole with the same K puts them (the
    lens distortion removed), NaN stays NaN."""
    rays = pixels_to_rays(xy, camera.K, camera.dist)
    return np.asarray(rays[..., :2] @ camera.K[:2, :2].T + camera.K[:2, 2])


def epipolar_lines(f: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Lines (..., 3) (a, b, c) with a^2 + b^2 = 1 of source pixels xy (..., 2) under F
    (fundamental_matrix): the signed distance of a target pixel (u, v) is a u + b v + c px."""
    xy = np.asarray(xy, dtype=np.float64)
    hom = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    lines = hom @ np.asarray(f, dtype=np.float64).T
    with np.errstate(invalid="ignore", divide="ignore"):
        return lines / np.hypot(lines[..., 0], lines[..., 1])[..., None]


@dataclass(frozen=True)
class EpipolarView:
    """One labelled view's guide for the target view: view index, F (3, 3) (source pixels to
    target lines, undistorted pinhole pixels) and xy (F, P, 2) the view's decided visible
    labels in undistorted pinhole pixels (the mean of its assignments), NaN where none."""

    view: int
    fundamental: np.ndarray
    xy: np.ndarray


def epipolar_guide(cameras: list[CameraModel], work: list[ViewWork], target: int
                   ) -> list[EpipolarView]:
    """Per labelled view (in view order), what the page needs to draw the epipolar line of
    each labelled point in the target view."""
    _check_work(cameras, work, target)
    out = []
    for view in distinct_views(work):
        mine = [w for w in work if w.view == view]
        stack = np.stack([np.where((w.visible & w.decided)[..., None], w.xy, np.nan)
                          for w in mine])
        seen = np.isfinite(stack).all(axis=-1)
        total = np.where(seen[..., None], stack, 0.0).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = total / seen.sum(axis=0)[..., None]
        out.append(EpipolarView(view=view,
                                fundamental=fundamental_matrix(cameras[view], cameras[target]),
                                xy=undistorted_pixels(cameras[view], mean)))
    return out
