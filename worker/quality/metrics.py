"""Per-assignment quality metrics of one view's labels against a reference (the consensus).

Everything is in one camera view: F frames, P points (21 hand joints in DexYCB order or 2 object
landmarks), positions in image pixels (x right, y down). Errors are pixel distances between a
label and where the other views place the point. Outputs are plain floats, lists and dicts (None
for "not measurable"), so they go to JSON as they are.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Protocol

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.hand.joints import JOINT_PARENTS

# Depth margins (metres) for the visibility check, from the synthetic capture (seed 7, 8 views,
# 72 frames): a visible joint lies under the skin, so the depth camera sees the surface a little
# nearer (z - depth: median 12.5 mm, 75th percentile 22 mm, sensor noise ~1 mm at 0.7 m); an
# object-covered joint reads 5-11 cm nearer (10th percentile 51 mm). Between the margins the
# verdict is left open (hand self-occlusion by a finger or the palm falls there or above).
SURFACE_MARGIN_M = 0.025
HIDDEN_MARGIN_M = 0.05
# A hand covers its own joints (a finger curled in front of another, the back of the hand in
# front of the palm side): the reading then lies on the hand itself, and whether a worker marks
# such a joint occluded is left open (the synthetic ground truth calls it visible, the page's
# instructions occluded); only something other than the hand makes it hidden. Synthetic
# capture seed 7, 8 views: such readings lie 7-18 mm from the hand's skeleton (bones and palm;
# 99th percentile), up to 23 mm at the palm's edge; an object's surface in front of a joint
# 15-64 mm (median 29 mm). Nearer than this the reading is taken for the hand's
# own surface and judges nothing. At the true joints of seeds 5 (320x240), 7 and 23: 0.4-7 % of
# the joints judged hidden are visible in truth (at an object's outline), against 33-71 % with
# the hand's own surface counted; 66-78 % of the truly occluded joints are judged hidden
# (70-88 % counting the hand's own surface too).
OWN_SURFACE_M = 0.02
# The hand's skeleton in DexYCB joint order (worker.hand.joints): each bone, the knuckle line and
# the thumb's base to the index knuckle; the palm as the triangles between them.
_HAND_JOINTS = 21
_HAND_SEGMENTS = np.array([(j, p) for j, p in enumerate(JOINT_PARENTS) if p >= 0]
                          + [(1, 5), (5, 9), (9, 13), (13, 17)])
_PALM = np.array([(0, 1, 5), (0, 5, 9), (0, 9, 13), (0, 13, 17)])
# Half-width (px) of the square around a point searched for a reading that sees as far as the
# point (as the ground truth of the synthetic annotators looks 2 px around a joint).
WINDOW_RADIUS_PX = 2
# visible_behind_surface is a share of the points the depth camera finds covered, and only
# reads as one over at least this many (point, frame) pairs: careful work sees a covered point
# in a frame or two at an object's outline, where the reference sits a pixel off the edge, and
# 1 of 1 read "100 % marked visible" on an approved careful label (synthetic capture seed 31,
# 8 views, careful labels: 1, 0, 0, 0, 22, 55, 497 and 586 covered points, of which 1, 0, 0,
# 0, 1, 0, 1 and 5 marked visible).
MIN_COVERED_POINTS = 10
# A span of at least this many frames with errors above the issue threshold is reported.
ISSUE_MIN_FRAMES = 3
# Gaps of up to this many frames inside a span are bridged (a close miss mid-span).
ISSUE_GAP_FRAMES = 2


def num(value: float | np.floating | None, digits: int = 4) -> float | None:
    """A JSON-friendly float: None for None, NaN or infinity."""
    if value is None or not np.isfinite(value):
        return None
    return round(float(value), digits)


def num_list(values: np.ndarray, digits: int = 3) -> list[float | None]:
    return [num(v, digits) for v in np.asarray(values, dtype=np.float64).ravel()]


@dataclass
class AssignmentQC:
    """Quality of one assignment (one worker's labels of one view).

    metrics: named numbers (None where not measurable), see hand_metrics / score_landmarks.
    per_joint: (P,) median error per point, px. per_frame: (F,) median error per frame, px.
    swaps: detected label permutations (worker.quality.swaps). issues: spans where one point is
    far off: {"point", "frames": [first, last], "error_px", "views"}. provisional: too few
    other views to judge (never auto-rejected).
    """

    key: str
    view: int
    metrics: dict[str, float | None]
    per_joint: list[float | None]
    per_frame: list[float | None]
    swaps: list[dict] = field(default_factory=list)
    issues: list[dict] = field(default_factory=list)
    provisional: bool = False

    def to_dict(self) -> dict:
        return asdict(self)


def _nan_median(values: np.ndarray, axis: int) -> np.ndarray:
    """np.nanmedian without the all-NaN warning: NaN where a slice has no value."""
    finite = np.isfinite(values)
    out = np.full(values.shape[:axis] + values.shape[axis + 1:], np.nan)
    has = finite.any(axis=axis)
    if has.any():
        moved = np.moveaxis(np.where(finite, values, np.nan), axis, -1)
        out[has] = np.nanmedian(moved[has], axis=-1)
    return out


def error_summary(errors: np.ndarray) -> dict[str, float | None]:
    """median, mean and 90th percentile (px) of the finite values of errors (F, P)."""
    e = errors[np.isfinite(errors)]
    if e.size == 0:
        return {"median_error_px": None, "mean_error_px": None, "p90_error_px": None}
    return {"median_error_px": num(np.median(e)), "mean_error_px": num(e.mean()),
            "p90_error_px": num(np.percentile(e, 90))}


def per_point_and_frame(errors: np.ndarray) -> tuple[list[float | None], list[float | None]]:
    """Median error per point (P,) and per frame (F,) of errors (F, P) px."""
    return num_list(_nan_median(errors, 0)), num_list(_nan_median(errors, 1))


def jitter_px(xy: np.ndarray, reference: np.ndarray) -> float | None:
    """Root-mean-square second difference (px per frame^2) of the label's offset from the
    reference, over runs of three frames where both exist. Removing the reference's motion
    leaves the label's own shake. xy, reference: (F, P, 2) px, NaN where absent."""
    d = xy - reference
    acc = d[2:] - 2.0 * d[1:-1] + d[:-2]
    ok = np.isfinite(acc).all(axis=-1)
    if not ok.any():
        return None
    return num(np.sqrt(np.mean(np.sum(acc[ok] ** 2, axis=-1))))


def motion_ratio(xy: np.ndarray, reference: np.ndarray) -> float | None:
    """Path length of the label divided by the reference's, over consecutive frame pairs where
    both have positions. xy, reference: (F, P, 2) px. ~1 for a good label, ~0 for one frame
    copied to all; None where the reference does not move (nothing to compare)."""
    step_label = np.linalg.norm(np.diff(xy, axis=0), axis=-1)
    step_ref = np.linalg.norm(np.diff(reference, axis=0), axis=-1)
    ok = np.isfinite(step_label) & np.isfinite(step_ref)
    ref_total = step_ref[ok].sum()
    if not ok.any() or ref_total < 1e-6:
        return None
    return num(step_label[ok].sum() / ref_total)


def static_fraction(xy: np.ndarray, still_px: float = 0.25) -> float | None:
    """Fraction of consecutive frame pairs in which no point of the label moves more than
    ``still_px``. xy: (F, P, 2) px."""
    step = np.linalg.norm(np.diff(xy, axis=0), axis=-1)
    has = np.isfinite(step).any(axis=1)
    if not has.any():
        return None
    moving = np.where(np.isfinite(step), step, 0.0).max(axis=1) > still_px
    return num(1.0 - moving[has].mean())


def completeness(xy: np.ndarray, visible: np.ndarray) -> float | None:
    """Share of (frame, point) entries that are placed or marked occluded: a point hidden all
    clip long needs no position. xy: (F, P, 2) px, NaN = no position; visible: (F, P)."""
    return num((np.isfinite(xy).all(axis=-1) | ~np.asarray(visible, bool)).mean())


def track_metrics(xy: np.ndarray, visible: np.ndarray, reference: np.ndarray,
                  working_time_s: float | None) -> dict[str, float | None]:
    """The label's own behaviour against a reference (consensus or gold) of the same view.

    xy: (F, P, 2) px, NaN = no position; visible: (F, P); reference: (F, P, 2) px, NaN where
    unknown. Returns jitter_px, motion_ratio, completeness, visible_fraction, working_time_s.
    """
    shown = np.where(visible[..., None], xy, np.nan)
    return {"jitter_px": jitter_px(shown, reference),
            "motion_ratio": motion_ratio(xy, reference),
            "completeness": completeness(xy, visible),
            "visible_fraction": num(visible.mean()),
            "working_time_s": num(working_time_s, 1)}


class DepthMaps(Protocol):
    """One view's (F, H, W) uint16 depth maps as the visibility check reads them: an ndarray,
    or anything with its ``shape`` and (frames, rows, cols) integer-array indexing (a stack
    read lazily, for one)."""

    @property
    def shape(self) -> tuple[int, ...]: ...

    def __getitem__(self, index: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray: ...


@dataclass(frozen=True)
class SurfaceCheck:
    """What one view's depth map says of the reference points, (F, P) bool each: on_surface
    (the reading at the point's pixel is at most the surface margin nearer than the point:
    nothing covers it) and hidden (that reading and every other within WINDOW_RADIUS_PX more
    than the hidden margin nearer, and for a hand not its own surface: something else covers
    it). Points in between, covered by the hand itself, off-image or without a reading at
    their pixel are neither."""

    on_surface: np.ndarray
    hidden: np.ndarray


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(F, N, S) distance from points (F, N, 3) to segments a-b (F, S, 3), metres."""
    ab = (b - a)[:, None]
    ap = points[:, :, None] - a[:, None]
    t = np.clip(np.sum(ap * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-12), 0, 1)
    return np.linalg.norm(ap - t[..., None] * ab, axis=-1)


def _plane_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray,
                    c: np.ndarray) -> np.ndarray:
    """(F, N, T) distance from points (F, N, 3) to triangles abc (F, T, 3) where the point's
    foot on the triangle's plane falls inside it; infinity elsewhere (an edge is nearer)."""
    u, v = (b - a)[:, None], (c - a)[:, None]
    w = points[:, :, None] - a[:, None]
    uu, vv, uv = np.sum(u * u, -1), np.sum(v * v, -1), np.sum(u * v, -1)
    wu, wv = np.sum(w * u, -1), np.sum(w * v, -1)
    det = uu * vv - uv * uv
    ok = det > 1e-18
    det = np.where(ok, det, 1.0)
    s, t = (vv * wu - uv * wv) / det, (uu * wv - uv * wu) / det
    inside = ok & (s >= 0) & (t >= 0) & (s + t <= 1)
    foot = s[..., None] * u + t[..., None] * v
    return np.where(inside, np.linalg.norm(w - foot, axis=-1), np.inf)


def distance_to_hand(points: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(F, N) distance (metres) from points (F, N, 3) to the hand's skeleton given by its 21
    joints (F, 21, 3) in the same frame: the nearest bone, knuckle line or palm triangle.
    Parts with a missing (NaN) joint are left out; infinity where none is left."""
    if joints.ndim != 3 or joints.shape[1:] != (_HAND_JOINTS, 3) or points.ndim != 3 \
            or points.shape[0] != joints.shape[0] or points.shape[2] != 3:
        raise ValueError(f"expected points (F, N, 3) and joints (F={points.shape[0]}, 21, 3), "
                         f"got {points.shape} and {joints.shape}")
    seg = _segment_distance(points, joints[:, _HAND_SEGMENTS[:, 0]],
                            joints[:, _HAND_SEGMENTS[:, 1]])
    palm = _plane_distance(points, *(joints[:, _PALM[:, k]] for k in range(3)))
    both = np.concatenate([seg, palm], axis=-1)
    return np.where(np.isnan(both), np.inf, both).min(axis=-1)


def surface_check(camera: CameraModel, points_world: np.ndarray, depth_mm: DepthMaps,
                  surface_margin_m: float = SURFACE_MARGIN_M,
                  hidden_margin_m: float = HIDDEN_MARGIN_M,
                  own_surface_m: float = OWN_SURFACE_M) -> SurfaceCheck:
    """Look the reference points up in the view's depth map (once per view: every label of the
    view is judged against the same points).

    Args:
        camera: the view. points_world: (F, P, 3) reference points, world metres (NaN: none);
            with P = 21 they are a hand's joints, and a nearer reading on that hand itself
            (within own_surface_m of its skeleton) hides nothing.
        depth_mm: (F, H, W) uint16 depth along the camera's z axis, millimetres, 0 = no
            reading (any array-like that supports ``shape`` and (frames, rows, cols) indexing).
        surface_margin_m, hidden_margin_m, own_surface_m: see SurfaceCheck, OWN_SURFACE_M.
    """
    frames, height, width = depth_mm.shape
    if depth_mm.shape[0] != points_world.shape[0]:
        raise ValueError(f"depth_mm must have shape (F={points_world.shape[0]}, H, W), "
                         f"got {depth_mm.shape}")
    pix = camera.project(points_world)
    z = camera.depth_of(points_world)
    col, row = np.rint(pix[..., 0]), np.rint(pix[..., 1])
    inside = np.isfinite(z) & (z > 0) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
    # One lookup of the window around each point: its centre, and every pixel of it.
    r = WINDOW_RADIUS_PX
    offsets = np.array([(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)])
    f_idx = np.broadcast_to(np.arange(frames)[:, None], z.shape)[inside]
    rows = np.clip(row[inside].astype(int)[:, None] + offsets[:, 0], 0, height - 1)
    cols = np.clip(col[inside].astype(int)[:, None] + offsets[:, 1], 0, width - 1)
    window = np.asarray(depth_mm[np.broadcast_to(f_idx[:, None], rows.shape), rows, cols],
                        dtype=np.float64) / 1000.0
    reading, farthest = np.zeros(z.shape), np.zeros(z.shape)
    reading[inside] = window[:, len(offsets) // 2]
    farthest[inside] = window.max(axis=1)
    judged = inside & (reading > 0)
    on_surface = judged & (z - reading <= surface_margin_m)
    # Hidden only where no pixel of the window sees as far as the point: a reference point a
    # pixel or two off (the consensus, or a joint at an outline) lands on whatever lies beside.
    # Its own pixel must read too: a dropout there marks a depth edge, where nothing is sure.
    hidden = judged & (z - farthest > hidden_margin_m)
    if points_world.shape[1] == _HAND_JOINTS and hidden.any():
        # The surface the camera sees along the point's ray, at the reading's depth.
        centre = camera.T_cam_to_world[:, 3]
        scale = np.where(hidden, farthest / np.where(hidden, z, 1.0), np.nan)
        surface = centre + (points_world - centre) * scale[..., None]
        hidden &= ~(distance_to_hand(surface, points_world) < own_surface_m)
    return SurfaceCheck(on_surface=on_surface, hidden=hidden)


def depth_visibility(visible: np.ndarray, check: SurfaceCheck) -> dict[str, float | None]:
    """How often the label's visibility flags (F, P) contradict the view's depth map.

    Returns:
        visibility_disagreement (contradicted fraction of the judged points),
        occluded_on_surface (of the points on the surface, fraction marked occluded),
        visible_behind_surface (of the hidden points, fraction marked visible; None below
        MIN_COVERED_POINTS of them); None where nothing was judged.
    """
    on_surface, hidden = check.on_surface, check.hidden
    wrong = (on_surface & ~visible) | (hidden & visible)
    n_judged = on_surface.sum() + hidden.sum()

    def fraction(part: np.ndarray, whole: np.ndarray) -> float | None:
        return num(part.sum() / whole.sum()) if whole.any() else None

    return {"visibility_disagreement": num(wrong.sum() / n_judged) if n_judged else None,
            "occluded_on_surface": fraction(on_surface & ~visible, on_surface),
            "visible_behind_surface": fraction(hidden & visible, hidden)
            if hidden.sum() >= MIN_COVERED_POINTS else None}


def error_issues(errors: np.ndarray, threshold_px: float, other_views: np.ndarray | None = None,
                 min_frames: int = ISSUE_MIN_FRAMES) -> list[dict]:
    """Spans of frames where one point's error stays above ``threshold_px``.

    Args:
        errors: (F, P) px, NaN where not measured (a NaN frame neither starts nor breaks a span).
        threshold_px: what counts as far off.
        other_views: (F, P) number of other views behind the reference, for the message.
        min_frames: shortest span reported (frames over the threshold inside it).

    Returns:
        [{"point": p, "frames": [first, last], "error_px": median in the span, "views": n}],
        worst first.
    """
    issues = []
    for p in range(errors.shape[1]):
        far = np.flatnonzero(errors[:, p] > threshold_px)
        if far.size == 0:
            continue
        breaks = np.flatnonzero(np.diff(far) > ISSUE_GAP_FRAMES + 1)
        for run in np.split(far, breaks + 1):
            if run.size < min_frames:
                continue
            first, last = int(run[0]), int(run[-1])
            span = errors[first:last + 1, p]
            issue = {"point": p, "frames": [first, last],
                     "error_px": num(np.nanmedian(span[np.isfinite(span)]), 1)}
            if other_views is not None:
                issue["views"] = int(np.median(other_views[first:last + 1, p]))
            issues.append(issue)
    return sorted(issues, key=lambda i: -(i["error_px"] or 0.0))
