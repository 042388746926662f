"""Simulated annotators: ground truth of one view turned into the keyframe tracks a person sends.

Everything is in image pixels (x right, y down) of one camera view with F frames and P points
(21 hand joints in DexYCB order, or 2 object landmarks). A worker's output is a list of P tracks,
each a list of keyframe rows ``[frame, x, y, visible01]`` as the annotation page saves them
(see worker.tracks): a keyframe every ``key_step`` frames plus the last frame, plus the frames
where the worker's visibility or labelling changes, positions clamped inside the image. A
worker who follows the motion (careful, and the swapper and occluder where they are careful)
also keys where the point's true path leaves the straight line between its keyframes by more
than FOLLOW_TOLERANCE_PX (`follow_path`): as often as the motion demands, so that the
interpolated frames walk the real path; the sloppy worker keys every ``key_step``-th frame
whatever the motion.

Profiles (what each worker does wrong):
    careful   Gaussian noise, sigma 2 px; a keyframe added where the path bends is placed
              against the track already there (ADDED_KEY_SIGMA_PX, see `annotate`).
    sloppy    Gaussian noise, sigma 8 px.
    swapper   exchanges the ring and little fingers (the two landmarks on objects) over the
              frames 20/72 to 45/72 of the clip; careful elsewhere.
    lazy      places every point once, on one frame, and copies it to all frames (no motion).
    spammer   uniform random points anywhere in the image, all marked visible.
    occluder  marks every point occluded over a long span (60% of the clip); careful elsewhere.
    same_spot puts every point on one spot (object landmarks: both on the first one's surface
              point), followed carefully: two landmarks that say nothing more than one.

``mixed`` draws profiles with MIXED_WEIGHTS for hands (half careful, a tenth each of the
others) and OBJECT_MIXED_WEIGHTS for objects (half careful, the rest shared by every other
profile, same_spot among them).
Pure numpy; every random choice comes from the ``rng`` passed in.
"""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from worker.formats.dexycb import HAND_SEG_VALUE
from worker.geometry.cameras import CameraModel
from worker.quality.landmark_points import separation_mm

Profile = Literal["careful", "sloppy", "swapper", "lazy", "spammer", "occluder", "same_spot"]
# Every profile; PROFILES are those of hand work (same_spot is an object worker's mistake).
OBJECT_PROFILES: tuple[str, ...] = get_args(Profile)
PROFILES: tuple[str, ...] = tuple(p for p in OBJECT_PROFILES if p != "same_spot")
MIXED_WEIGHTS: dict[str, float] = {"careful": 0.5, "sloppy": 0.1, "swapper": 0.1, "lazy": 0.1,
                                   "spammer": 0.1, "occluder": 0.1}
OBJECT_MIXED_WEIGHTS: dict[str, float] = {"careful": 0.5, **{
    p: 0.5 / (len(OBJECT_PROFILES) - 1) for p in OBJECT_PROFILES if p != "careful"}}
CAREFUL_SIGMA_PX = 2.0
SLOPPY_SIGMA_PX = 8.0
# The swap window as a fraction of the clip: frames 20 to 45 of a 72-frame clip.
SWAP_WINDOW = (20 / 72, 45 / 72)
OCCLUDED_SPAN = 0.6
KEY_STEP = 4
# A person picks an object's landmarks as distinct points, well apart on its surface (metres):
# twice the least separation QC asks of two landmarks (worker.quality.decide.QCThresholds
# .landmark_min_separation_mm, 15 mm), where the visible side of the object allows it.
LANDMARK_SEPARATION_M = 0.03
# ... and in plain view: where the view shows enough of them, on surface turned at most 60
# degrees from the camera (cosine 0.5); a point seen edge-on slides off its spot with the
# slightest turn of the object.
PLAIN_VIEW_COS = 0.5
# A suggested landmark marks the spot whose projection lies within this many px of it (the
# suggestion's own error from the views it comes from, a few px; worker.synth.annotators
# suggested_landmarks): further off, a person sees no spot it marks and picks its own.
SUGGESTED_SPOT_PX = 8.0
# A keyframe added between two others (where the path bends) is placed by dragging the
# interpolated point onto the joint: it keeps the neighbouring keyframes' error (where the
# worker sees the joint's centre) plus a small click error of its own, px per axis. So keys
# on neighbouring frames do not shake against each other.
ADDED_KEY_SIGMA_PX = 0.7
# How far (px) a careful worker lets the true path stray from the straight line between two
# keyframes before keying the frame in between: about what a person sees while scrubbing a
# 640x480 clip, and near the careful label noise (CAREFUL_SIGMA_PX) itself.
FOLLOW_TOLERANCE_PX = 2.0
# Profiles that key where the path bends (the others key every KEY_STEP-th frame only).
FOLLOWS_MOTION = ("careful", "swapper", "occluder")
RING = (13, 14, 15, 16)
LITTLE = (17, 18, 19, 20)
# Half-width (px) of the square around a point's rounded pixel searched for its own label: a
# joint sits on the hand's surface, and the rendered silhouette edge may miss it by a pixel.
VISIBILITY_RADIUS_PX = 2


@dataclass(frozen=True)
class SimulatedWork:
    """One simulated worker's annotation of one view.

    profile: the profile's name.
    tracks: P lists of [frame, x, y, visible01] rows; x, y in image px, or None (no position).
    """

    profile: str
    tracks: list[list[list[float | None]]]


def draw_profiles(count: int, profile: str, rng: np.random.Generator,
                  kind: Literal["hand", "object"] = "hand") -> list[str]:
    """``count`` profile names: all ``profile``, or for ``mixed`` drawn with MIXED_WEIGHTS
    (``kind`` "hand") or OBJECT_MIXED_WEIGHTS ("object")."""
    known = PROFILES if kind == "hand" else OBJECT_PROFILES
    if profile == "mixed":
        mix = MIXED_WEIGHTS if kind == "hand" else OBJECT_MIXED_WEIGHTS
        names = list(mix)
        weights = np.array([mix[n] for n in names])
        return [names[i] for i in rng.choice(len(names), size=count, p=weights / weights.sum())]
    if profile not in known:
        raise ValueError(f"unknown profile {profile!r} for {kind} work; one of "
                         f"{', '.join(known)} or mixed")
    return [profile] * count


def _labelled_near(seg: np.ndarray, points: np.ndarray, value: int) -> np.ndarray:
    """(F, P) bool: inside the image and ``value`` within VISIBILITY_RADIUS_PX of the rounded
    pixel (in the same frame). seg: (F, H, W) uint8; points: (F, P, 2) px."""
    frames, height, width = seg.shape
    pix = np.rint(points).astype(np.int64)
    inside = ((pix[..., 0] >= 0) & (pix[..., 0] < width)
              & (pix[..., 1] >= 0) & (pix[..., 1] < height))
    found = np.zeros(inside.shape, dtype=bool)
    f_idx = np.broadcast_to(np.arange(frames)[:, None], inside.shape)
    r = VISIBILITY_RADIUS_PX
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            x = np.clip(pix[..., 0] + dx, 0, width - 1)
            y = np.clip(pix[..., 1] + dy, 0, height - 1)
            found |= seg[f_idx, y, x] == value
    return inside & found


def hand_visibility(joint_2d: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """(F, 21) bool: a joint is visible where it lies inside the image and either on the hand's
    pixels or on background (not covered by an object). joint_2d: (F, 21, 2) px; seg: (F, H, W)
    uint8 with HAND_SEG_VALUE on the hand, object ids elsewhere, 0 background."""
    if joint_2d.ndim != 3 or joint_2d.shape[2] != 2 or seg.ndim != 3:
        raise ValueError(f"expected joint_2d (F, P, 2) and seg (F, H, W), got {joint_2d.shape} "
                         f"and {seg.shape}")
    on_hand = _labelled_near(seg, joint_2d, HAND_SEG_VALUE)
    on_background = _labelled_near(seg, joint_2d, 0)
    return on_hand | on_background


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N, 3) unit normals of a mesh's vertices (area-weighted face normals summed)."""
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    out = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(out, faces[:, k], normal)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)


def visible_vertices(camera: CameraModel, seg: np.ndarray, value: int, points: np.ndarray,
                     normals: np.ndarray) -> np.ndarray:
    """(N,) whether points (N, 3) with normals (N, 3), in the camera's world frame, show in the
    view: facing the camera, inside the image, on a pixel labelled ``value`` with at least a
    third of its 3x3 neighbourhood too (a box corner sits on the silhouette)."""
    centre = camera.T_cam_to_world[:, 3]
    facing = np.einsum("ni,ni->n", normals, centre - points) > 0
    px = np.rint(camera.project(points)).astype(int)
    inside = ((px[:, 0] >= 1) & (px[:, 0] < camera.width - 1) & (px[:, 1] >= 1)
              & (px[:, 1] < camera.height - 1))
    xs = np.clip(px[:, 0], 0, camera.width - 1)
    ys = np.clip(px[:, 1], 0, camera.height - 1)
    count = np.zeros(len(points), int)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            count += seg[np.clip(ys + dy, 0, camera.height - 1),
                         np.clip(xs + dx, 0, camera.width - 1)] == value
    return facing & inside & (count >= 3) & (seg[ys, xs] == value)


def distinct_points(points: np.ndarray, candidates: np.ndarray, count: int,
                    separation_m: float, rng: np.random.Generator) -> np.ndarray:
    """``count`` ids out of ``candidates`` (ids into points (N, 3), metres) as a person picks
    distinct landmarks: the first at random, each next at random among those at least
    ``separation_m`` from every one taken, or the farthest from them where none is."""
    ids = [int(rng.choice(candidates))]
    while len(ids) < count:
        rest = np.setdiff1d(candidates, ids)
        gap = np.linalg.norm(points[rest][:, None] - points[ids][None], axis=2).min(axis=1)
        apart = rest[gap >= separation_m]
        ids.append(int(rng.choice(apart)) if apart.size else int(rest[np.argmax(gap)]))
    return np.array(ids)


def mesh_landmarks(camera: CameraModel, seg: np.ndarray, value: int, vertices: np.ndarray,
                   faces: np.ndarray, poses: np.ndarray, rng: np.random.Generator,
                   count: int = 2, separation_m: float = LANDMARK_SEPARATION_M,
                   shown: tuple[np.ndarray, np.ndarray] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``count`` landmarks a person would pick on an object in one view: distinct mesh
    vertices (distinct_points), visible and in plain view (PLAIN_VIEW_COS, where enough are)
    on the first frame where the object shows that offers them ``separation_m`` apart (the
    page asks for points far apart: a person looks into the clip for them), else the first
    such frame's pick; followed through the object's true motion from where it first shows.

    shown: the landmarks the page already suggests, (F, count, 2) px (NaN where none) and
        (F, count) shown visible: a person takes the spots they mark (suggested_landmarks)
        instead of picking its own, where the suggestions mark one.

    seg: (F, H, W) labels; vertices (N, 3) object frame, metres; poses (F, 3, 4) object to the
    camera's world frame. Returns (F, count, 2) px (NaN before the object shows), (F, count)
    visibility, and the vertex ids (count,) (-1 when the object never shows enough).
    """
    frames = seg.shape[0]
    normals = vertex_normals(vertices, faces)
    ids = np.full(count, -1)
    if shown is not None and np.shape(shown[0])[1:] == (count, 2):
        ids = suggested_landmarks(camera, seg, value, vertices, normals, poses, *shown)
    suggested = bool(ids[0] >= 0)
    xy = np.full((frames, count, 2), np.nan)
    visible = np.zeros((frames, count), dtype=bool)
    centre = camera.T_cam_to_world[:, 3]
    seen: list[tuple[np.ndarray, np.ndarray]] = []  # (world, visible vertices) per frame
    first = None  # the first frame where the object shows enough
    fallback = None
    for f in range(frames):
        world = vertices @ poses[f, :, :3].T + poses[f, :, 3]
        turned = normals @ poses[f, :, :3].T
        ok = visible_vertices(camera, seg[f], value, world, turned)
        seen.append((world, ok))
        if ok.sum() < count:
            continue
        first = f if first is None else first
        if ids[0] >= 0:
            continue
        towards = centre - world
        cosine = np.einsum("ni,ni->n", turned, towards) / np.linalg.norm(towards, axis=1)
        plain = ok & (cosine >= PLAIN_VIEW_COS)
        pick = distinct_points(vertices, np.flatnonzero(plain if plain.sum() >= count else ok),
                               count, separation_m, rng)
        fallback = pick if fallback is None else fallback
        # The page asks for points far apart: a person who sees none such on this frame
        # looks further into the clip (and labels back to where the object first shows).
        gap_mm = separation_mm(list(vertices[pick]))
        if gap_mm is None or gap_mm >= 1000.0 * separation_m:
            ids = pick
    if ids[0] < 0 and fallback is not None:
        ids = fallback
    # Suggested spots are followed through the whole clip; one's own from where the object
    # first shows enough.
    start = 0 if suggested else first
    if ids[0] >= 0 and start is not None:
        for f in range(start, frames):
            world, ok = seen[f]
            xy[f] = camera.project(world[ids])
            visible[f] = ok[ids]
    return xy, visible, ids


def suggested_landmarks(camera: CameraModel, seg: np.ndarray, value: int, vertices: np.ndarray,
                        normals: np.ndarray, poses: np.ndarray, xy: np.ndarray,
                        shown: np.ndarray) -> np.ndarray:
    """(count,) the vertex ids of the spots suggested landmarks mark, as a person reads them
    off the page: for each landmark the vertex whose projection lies nearest the suggested
    positions over the frames both show (the median distance, so a check cell planted off
    the spot in a frame or two does not move it), among those within SUGGESTED_SPOT_PX;
    all -1 (the person picks its own) unless every landmark marks a spot.
    xy: (F, count, 2) px, NaN where nothing is suggested; shown: (F, count) bool."""
    count = xy.shape[1]
    frames = [f for f in range(len(seg)) if (shown[f] & np.isfinite(xy[f]).all(-1)).any()]
    if not frames:
        return np.full(count, -1)
    dist = np.full((len(frames), count, len(vertices)), np.nan)
    for i, f in enumerate(frames):
        world = vertices @ poses[f, :, :3].T + poses[f, :, 3]
        ok = visible_vertices(camera, seg[f], value, world, normals @ poses[f, :, :3].T)
        at = camera.project(world)
        for p in np.flatnonzero(shown[f] & np.isfinite(xy[f]).all(-1)):
            dist[i, p, ok] = np.linalg.norm(at[ok] - xy[f, p], axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a vertex never shown: all NaN
        typical = np.nanmedian(dist, axis=0)  # (count, N)
    typical = np.where(np.isfinite(typical), typical, np.inf)
    ids = typical.argmin(axis=1)
    if not (typical[np.arange(count), ids] <= SUGGESTED_SPOT_PX).all() \
            or len(set(ids.tolist())) < count:
        return np.full(count, -1)
    return ids


def swap_window(frames: int) -> tuple[int, int]:
    """First and last frame (inclusive) a swapper exchanges the fingers in a clip of F frames."""
    return (min(frames - 1, round(SWAP_WINDOW[0] * frames)),
            min(frames - 1, round(SWAP_WINDOW[1] * frames)))


def _swap_pairs(points: int) -> tuple[list[int], list[int]]:
    return (list(RING), list(LITTLE)) if points == 21 else ([0], [1])


def _apply_profile(profile: str, xy: np.ndarray, vis: np.ndarray, size: tuple[int, int],
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, set[int]]:
    """The worker's dense (F, P, 2) positions, (F, P) visibility and extra keyframes."""
    frames, points = vis.shape
    width, height = size
    extra: set[int] = set()
    if profile == "spammer":
        scale = np.array([width - 1, height - 1], dtype=np.float64)
        return rng.uniform(0, 1, (frames, points, 2)) * scale, np.ones_like(vis), extra
    sigma = SLOPPY_SIGMA_PX if profile == "sloppy" else CAREFUL_SIGMA_PX
    xy, vis = xy.copy(), vis.copy()
    if profile == "swapper":
        lo, hi = swap_window(frames)
        a, b = _swap_pairs(points)
        xy[lo:hi + 1, a + b] = xy[lo:hi + 1, b + a]
        vis[lo:hi + 1, a + b] = vis[lo:hi + 1, b + a]
        extra |= {lo, hi} | ({hi + 1} if hi + 1 < frames else set())
    elif profile == "lazy":
        frame = int(rng.integers(frames))
        xy[:], vis[:] = xy[frame], vis[frame]
        return xy + rng.normal(0, sigma, (1, points, 2)), vis, extra
    elif profile == "same_spot":
        # Every point where the first one is: its position and its visibility.
        xy[:], vis[:] = xy[:, :1], vis[:, :1]
    elif profile == "occluder":
        span = max(1, round(OCCLUDED_SPAN * frames))
        for p in range(points):
            start = int(rng.integers(frames - span + 1))
            vis[start:start + span, p] = False
    return xy + rng.normal(0, sigma, xy.shape), vis, extra


def _added_keys(seen: np.ndarray, noisy: np.ndarray, regular: list[int], keys: list[int],
                rng: np.random.Generator) -> np.ndarray:
    """(F, 2) one point's positions with each added keyframe (in ``keys``, not in
    ``regular``) placed on the seen path with the error interpolated from the regular
    keyframes around it plus ADDED_KEY_SIGMA_PX of its own. seen, noisy: (F, 2) px."""
    out = noisy.copy()
    error = noisy - seen
    known = [k for k in regular if np.isfinite(error[k]).all()]
    added = [k for k in keys if k not in set(regular) and np.isfinite(seen[k]).all()]
    if not known or not added:
        return out
    for axis in (0, 1):
        around = np.interp(added, known, error[known, axis])
        out[added, axis] = seen[added, axis] + around + rng.normal(0, ADDED_KEY_SIGMA_PX,
                                                                   len(added))
    return out


def keyframe_indices(frames: int, key_step: int, visible: np.ndarray,
                     extra: Iterable[int] = ()) -> list[int]:
    """Frames a person keys for one point: every ``key_step``-th, the last, each change of
    visibility (visible: (F,) bool) and ``extra``."""
    keys = set(range(0, frames, key_step)) | {frames - 1} | set(extra)
    keys |= {int(f) for f in np.flatnonzero(visible[1:] != visible[:-1]) + 1}
    return sorted(k for k in keys if 0 <= k < frames)


def follow_path(path: np.ndarray, visible: np.ndarray, keys: Iterable[int],
                tolerance_px: float = FOLLOW_TOLERANCE_PX) -> list[int]:
    """Keyframes of one point refined until its linear interpolation follows the true path.

    path: (F, 2) true positions, image px (NaN where unknown); visible: (F,) bool; keys: the
    frames keyed so far. Between two consecutive keys the frame (visible, with a position)
    where the true path is farthest from the straight line between them is keyed, while that
    distance exceeds ``tolerance_px``. A span with an unknown position at one end (the point
    goes out of sight or comes into it) first gets its frame nearest that end where the point
    is still seen keyed: a careful worker marks where it was last (or first) seen, not a line
    towards where it hides. Spans unknown at both ends are left alone. Returns the sorted
    keyframes, ``keys`` included.
    """
    path = np.asarray(path, np.float64)
    known = np.isfinite(path).all(axis=1) & np.asarray(visible, bool)
    out = sorted({int(k) for k in keys})
    pending = list(itertools.pairwise(out))
    while pending:
        a, b = pending.pop()
        if b - a < 2 or not (known[a] or known[b]):
            continue
        if known[a] != known[b]:
            seen = np.flatnonzero(known[a + 1:b]) + a + 1
            if seen.size:
                edge = int(seen[-1] if known[a] else seen[0])
                out.append(edge)
                pending.append((a, edge) if known[a] else (edge, b))
            continue
        inner = np.arange(a + 1, b)
        t = ((inner - a) / (b - a))[:, None]
        line = path[a] * (1.0 - t) + path[b] * t
        off = np.where(known[inner], np.linalg.norm(path[inner] - line, axis=1), 0.0)
        worst = int(np.argmax(off))
        if off[worst] > tolerance_px:
            mid = int(inner[worst])
            out.append(mid)
            pending += [(a, mid), (mid, b)]
    return sorted(out)


def keyframe_actions(tracks: list[list[list[float | None]]]) -> dict[str, int]:
    """What a keyframe worker did to make ``tracks`` (P lists of [frame, x, y, visible01]
    rows), counted by worker.synth.assisted's rule: a click per visible keyframe, a key per
    occluded one (marking it occluded), no drags; navigation is free."""
    visible = sum(int(bool(row[3])) for rows in tracks for row in rows)
    placed = sum(len(rows) for rows in tracks)
    return {"clicks": visible, "drags": 0, "keys": placed - visible, "keyframes_placed": placed}


def _position(xy: np.ndarray) -> list[float | None]:
    if not np.isfinite(xy).all():
        return [None, None]
    return [round(float(xy[0]), 2), round(float(xy[1]), 2)]


def _seen_path(truth: np.ndarray, profile: str, point: int) -> np.ndarray:
    """(F, 2) the path the worker follows for one point: the true one, with the swapper's
    exchanged points inside its window (it follows the finger it believes it labels)."""
    path = truth[:, point].copy()
    if profile == "swapper":
        lo, hi = swap_window(truth.shape[0])
        a, b = _swap_pairs(truth.shape[1])
        pairs = dict(zip(a + b, b + a, strict=True))
        if point in pairs:
            path[lo:hi + 1] = truth[lo:hi + 1, pairs[point]]
    return path


def annotate(xy: np.ndarray, visible: np.ndarray, size: tuple[int, int], profile: str,
             rng: np.random.Generator, key_step: int = KEY_STEP,
             follow_motion: bool | None = None) -> SimulatedWork:
    """One simulated worker's tracks for one view.

    xy: (F, P, 2) true positions, image px (NaN where unknown: such keyframes carry no
    position); visible: (F, P) bool; size: (width, height) px. follow_motion: also key where
    the path bends (`follow_path`); None: as the profile does (FOLLOWS_MOTION), hand joints
    and object landmarks alike; False: every ``key_step``-th frame only (studies of keyframe
    spacing).
    """
    if xy.ndim != 3 or xy.shape[2] != 2 or visible.shape != xy.shape[:2]:
        raise ValueError(f"expected xy (F, P, 2) and visible (F, P), got {xy.shape} and "
                         f"{visible.shape}")
    if profile not in OBJECT_PROFILES:
        raise ValueError(f"unknown profile {profile!r}; one of {', '.join(OBJECT_PROFILES)}")
    width, height = size
    noisy, vis, extra = _apply_profile(profile, np.asarray(xy, np.float64),
                                       np.asarray(visible, bool), size, rng)
    # Strictly inside the image: the page and the server accept 0 <= x < width.
    noisy[..., 0] = np.clip(noisy[..., 0], 0.0, width - 1.0)
    noisy[..., 1] = np.clip(noisy[..., 1], 0.0, height - 1.0)
    tracks = []
    truth = np.asarray(xy, np.float64)
    if follow_motion is None:
        follow_motion = profile in FOLLOWS_MOTION
    for p in range(xy.shape[1]):
        keys = keyframe_indices(xy.shape[0], key_step, vis[:, p], extra)
        placed = noisy[:, p]
        if follow_motion:
            # The worker's own visibility marks which frames they look at.
            seen = _seen_path(truth, profile, p)
            regular, keys = keys, follow_path(seen, vis[:, p], keys)
            placed = _added_keys(seen, placed, regular, keys, rng)
            placed[:, 0] = np.clip(placed[:, 0], 0.0, width - 1.0)
            placed[:, 1] = np.clip(placed[:, 1], 0.0, height - 1.0)
        tracks.append([[f, *_position(placed[f]), int(vis[f, p])] for f in keys])
    return SimulatedWork(profile=profile, tracks=tracks)
