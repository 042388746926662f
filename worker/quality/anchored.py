"""Object-landmark QC after the solve: every landmark anchored to the solved object's surface.

Once the objects are solved (poses in every frame), a worker's landmark is a point on the
object: its ray at a frame where it is labelled visible hits the object's surface there (the
paper maps each landmark once, at its first visible frame). A careful track then follows that
point's projection through every frame, and is marked occluded exactly where the point is
hidden. So each landmark is anchored at the candidate hit (over a few of its visible frames)
whose projection the track follows best, and judged:

- error: pixels between the track and the anchored point's projection, over the frames where
  both the track and the solve say it is visible (median, 90th percentile);
- visibility: the point is hidden where it faces away, where another solved mesh (or its own)
  is nearer along the ray, or where the depth camera reads a surface well in front of it (a
  hand); the share of visible frames marked occluded and of hidden frames marked visible;
- drift: how much the error grows from the first third of the clip to the last.
- the points themselves: distinct on the surface, in plain view, shown through the clip
  (worker.quality.landmark_points).

The poses are the solve's, or before any solve an unmoved object's pose given at import.

Pixels x right, y down, one view; world metres; poses object-to-world (3, 4).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from worker.assist.visibility import DepthMaps
from worker.geometry.cameras import CameraModel, pixels_to_rays
from worker.quality.consensus import ViewLabels, decided_of
from worker.quality.landmark_points import facing, separation_mm, shown_fraction
from worker.quality.metrics import (
    AssignmentQC,
    error_issues,
    num,
    per_point_and_frame,
)
from worker.quality.solved_scene import SolvedObjects

# Visible frames tried as the anchor's frame (evenly over the track): a sloppy first click
# does not decide where a careful track is anchored.
ANCHOR_TRIES = 12
# A mesh nearer than the point by this much along its ray hides it (metres): the point lies on
# a face, and the face it lies on must not hide it.
MESH_MARGIN_M = 0.004
# The depth camera hides a point when it reads a surface this much nearer (metres): a hand
# over the object reads 1-3 cm nearer; sensor noise at 0.7 m is ~1 mm.
DEPTH_MARGIN_M = 0.012
# The depth camera hides a point only when every reading within this many px of its pixel
# (a square) is that much nearer: a rig whose calibration or depth registration is a few
# pixels off (a camera turned by 0.5 degrees or moved by 5 mm shows 3-8 px, less what the
# view's offset takes out; depth images 2-3 px off their colour images) reads a point near an
# edge, or on a slope of its own surface, at a neighbouring pixel that is nearer, while a
# hand over the point covers the whole square.
DEPTH_WINDOW_PX = 3
_WINDOW = np.array([(dy, dx) for dy in range(-DEPTH_WINDOW_PX, DEPTH_WINDOW_PX + 1)
                    for dx in range(-DEPTH_WINDOW_PX, DEPTH_WINDOW_PX + 1)])
# A click this close to the object's outline (px) is on it: a careful click lands within ~2 px,
# and a landmark near the silhouette may miss by that much.
SNAP_PX = 4.0
_SNAPS = np.array([[0.0, 0.0]] + [[r * np.cos(a), r * np.sin(a)] for r in (SNAP_PX / 2, SNAP_PX)
                                  for a in np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)])
# Hidden frames (summed over the landmarks) needed to judge visible flags there: a landmark hidden
# for a frame or two at the hand's edge says little.
MIN_HIDDEN_FRAMES = 6
# An issue span: the track this far off the anchored point (px).
ISSUE_PX = 10.0
# A label that marks none of its landmarks visible anywhere has nothing to anchor; it is judged
# by the object itself: a frame shows the object when at least SHOWN_SHARE of SHOWN_SAMPLES
# surface points (its vertices, evenly taken) are in view, about a fifth of the side facing
# the camera, enough for a careful worker to place a landmark. An object that never shows in
# the view (out of the image, behind another object or the hand) is rightly labelled hidden.
SHOWN_SHARE = 0.1
SHOWN_SAMPLES = 64


# Pixels (..., 2) of the camera model -> where the camera truly shows them.
PixelMap = Callable[[np.ndarray], np.ndarray]


@dataclass
class AnchoredQC(AssignmentQC):
    """An AssignmentQC with what a reviewer's replay draws: reprojection (F, P, 2) px of each
    anchored landmark (NaN where it could not be anchored or the pose is unknown), shown (F, P)
    whether the solve sees it there, errors (F, P) px from the track to it (NaN where not
    judged). Not part of to_dict (the report's numbers)."""

    reprojection: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 2)))
    shown: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))
    errors: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def to_dict(self) -> dict:
        return AssignmentQC(self.key, self.view, self.metrics, self.per_joint, self.per_frame,
                            self.swaps, self.issues, self.provisional).to_dict()


def ray_hits(origin: np.ndarray, dirs: np.ndarray,
             tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of each ray with the triangles (Moller-Trumbore).

    origin (3,), dirs (R, 3) unit, tri (M, 3, 3) world metres. Returns (R,) distance along the
    ray (inf where none) and (R,) the face hit (-1 where none).
    """
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(dirs[:, None, :], e2[None])
    det = np.einsum("mk,rmk->rm", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    s = origin - tri[:, 0]
    u = np.einsum("mk,rmk->rm", s, p) * inv
    q = np.cross(s, e1)
    v = np.einsum("rk,mk->rm", dirs, q) * inv
    t = np.einsum("mk,mk->m", e2, q)[None] * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & np.isfinite(t)
    dist = np.where(hit, t, np.inf)
    face = np.argmin(dist, axis=1)
    best = dist[np.arange(len(dirs)), face]
    return best, np.where(np.isfinite(best), face, -1)


def _ray(camera: CameraModel, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre (3,) and unit world directions (K, 3) through pixels (K, 2)."""
    rays_cam = pixels_to_rays(np.atleast_2d(xy), camera.K, camera.dist)
    dirs = rays_cam @ camera.T_cam_to_world[:, :3].T
    return camera.T_cam_to_world[:, 3], dirs / np.linalg.norm(dirs, axis=1, keepdims=True)


def _candidates(camera: CameraModel, xy: np.ndarray, ok: np.ndarray, scene: SolvedObjects,
                target: int) -> np.ndarray:
    """(K, 3) object-frame surface points the landmark's rays hit at a few visible frames
    (within SNAP_PX of the click)."""
    frames = np.flatnonzero(ok)
    if frames.size > ANCHOR_TRIES:
        frames = frames[np.linspace(0, frames.size - 1, ANCHOR_TRIES).astype(int)]
    out = []
    for f in frames:
        tri = scene.triangles(target, int(f))
        if not np.isfinite(tri).all():
            continue
        # The click itself, else the nearest of a few points around it that is on the object.
        origin, dirs = _ray(camera, xy[f] + _SNAPS)
        dist, _ = ray_hits(origin, dirs, tri)
        hit = np.flatnonzero(np.isfinite(dist))
        if hit.size:
            world = origin + dist[hit[0]] * dirs[hit[0]]
            pose = scene.poses[target, f]
            out.append(pose[:, :3].T @ (world - pose[:, 3]))
    return np.array(out).reshape(-1, 3)


def _track_of(camera: CameraModel, point: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(F, 3) world positions of an object-frame point under poses (F, 3, 4)."""
    return np.einsum("fij,j->fi", poses[:, :, :3], point) + poses[:, :, 3]


def anchor(camera: CameraModel, xy: np.ndarray, visible: np.ndarray, scene: SolvedObjects,
           target: int) -> np.ndarray | None:
    """The object-frame point (3,) of one landmark track (xy (F, 2) px, visible (F,)) whose
    projection the track follows best (least median error), or None where no ray hits."""
    ok = np.asarray(visible, bool) & np.isfinite(xy).all(axis=1)
    candidates = _candidates(camera, xy, ok, scene, target)
    if not len(candidates):
        return None
    errors = []
    for c in candidates:
        dist = np.linalg.norm(
            camera.project(_track_of(camera, c, scene.poses[target]))[ok] - xy[ok], axis=1)
        # Frames whose pose the solve left unknown say nothing about the anchor.
        dist = dist[np.isfinite(dist)]
        errors.append(float(np.median(dist)) if dist.size else np.inf)
    return candidates[int(np.argmin(errors))]


def point_visibility(camera: CameraModel, world: np.ndarray, scene: SolvedObjects,
                     depth: DepthMaps | None, image_map: PixelMap | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(F,) whether the world track (F, 3) shows in the view: in front, inside the image, no
    solved mesh nearer along its ray, and no depth reading well in front of it; and (F,) the
    shown frames where the point sits at the edge of something in front of it
    (``at_depth_edge``): its visibility there says nothing of the worker. image_map: where the
    camera truly shows a projected pixel (a camera offset, worker.quality.view_offset), so the
    depth map is read where the point is seen."""
    frames = len(world)
    pix = camera.project(world)
    if image_map is not None:
        pix = image_map(pix)
    z = camera.depth_of(world)
    inside = np.isfinite(z) & (z > 0) & (pix[:, 0] >= 0) & (pix[:, 0] < camera.width) \
        & (pix[:, 1] >= 0) & (pix[:, 1] < camera.height)
    shown = inside.copy()
    origin = camera.T_cam_to_world[:, 3]
    for f in np.flatnonzero(inside):
        offset = world[f] - origin
        reach = float(np.linalg.norm(offset))
        dirs = (offset / reach)[None]
        for index in range(len(scene.vertices)):
            tri = scene.triangles(index, int(f))
            if np.isfinite(tri).all() and ray_hits(origin, dirs, tri)[0][0] < reach - MESH_MARGIN_M:
                shown[f] = False
                break
    edge = np.zeros(frames, bool)
    if depth is not None:
        at = np.flatnonzero(shown)
        if at.size:
            hidden, near_edge = depth_cover(depth, camera, at, pix[at], z[at])
            edge[at[near_edge]] = True
            shown[at[hidden]] = False
    assert shown.shape == (frames,)
    return shown, edge


def depth_cover(depth: DepthMaps, camera: CameraModel, frames: np.ndarray, pix: np.ndarray,
                z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From one read of the square of DEPTH_WINDOW_PX around each point's pixel: (N,) whether
    the point is ``covered`` and (N,) whether it is ``at_depth_edge``. frames (N,) int; pix
    (N, 2) px; z (N,) metres."""
    rows = np.rint(pix[:, 1]).astype(int)[:, None] + _WINDOW[:, 0]
    cols = np.rint(pix[:, 0]).astype(int)[:, None] + _WINDOW[:, 1]
    reading = depth[(np.broadcast_to(frames[:, None], rows.shape),
                     rows.clip(0, camera.height - 1), cols.clip(0, camera.width - 1))] / 1000.0
    read = reading > 0
    nearer = read & (z[:, None] - reading > DEPTH_MARGIN_M)
    hidden = nearer[:, len(_WINDOW) // 2] & (nearer | ~read).all(axis=1)
    return hidden, nearer.any(axis=1) & ~hidden


def covered(depth: DepthMaps, camera: CameraModel, frames: np.ndarray, pix: np.ndarray,
            z: np.ndarray) -> np.ndarray:
    """(N,) whether the depth camera reads something well in front of each point: the reading
    at its pixel and every other within DEPTH_WINDOW_PX (those with a reading) more than
    DEPTH_MARGIN_M nearer than its depth. frames (N,) int; pix (N, 2) px; z (N,) metres."""
    return depth_cover(depth, camera, frames, pix, z)[0]


def at_depth_edge(depth: DepthMaps, camera: CameraModel, frames: np.ndarray, pix: np.ndarray,
                  z: np.ndarray) -> np.ndarray:
    """(N,) whether something in front of each point covers part of the square around its
    pixel but not the point (``covered``): the edge of a hand or another object, where a rig
    a few pixels off cannot say which side the point is on."""
    return depth_cover(depth, camera, frames, pix, z)[1]


def object_shown(camera: CameraModel, scene: SolvedObjects, target: int,
                 depth: DepthMaps | None) -> np.ndarray:
    """(F,) share of object ``target``'s sampled surface points (SHOWN_SAMPLES vertices) the
    view shows, by the rules of point_visibility (in the image, no solved mesh nearer along the
    ray, no depth reading well in front); NaN where the pose is unknown."""
    vertices = scene.vertices[target]
    samples = vertices[np.unique(np.linspace(0, len(vertices) - 1,
                                             min(SHOWN_SAMPLES, len(vertices))).astype(int))]
    origin = camera.T_cam_to_world[:, 3]
    out = np.full(scene.poses.shape[1], np.nan)
    for f in range(scene.poses.shape[1]):
        pose = scene.poses[target, f]
        if not np.isfinite(pose).all():
            continue
        world = samples @ pose[:, :3].T + pose[:, 3]
        pix, z = camera.project(world), camera.depth_of(world)
        shown = np.isfinite(z) & (z > 0) & (pix[:, 0] >= 0) & (pix[:, 0] < camera.width) \
            & (pix[:, 1] >= 0) & (pix[:, 1] < camera.height)
        reach = np.linalg.norm(world - origin, axis=1)
        dirs = (world - origin) / reach[:, None]
        for index in range(len(scene.vertices)):
            tri = scene.triangles(index, f)
            if shown.any() and np.isfinite(tri).all():
                shown &= ~(ray_hits(origin, dirs, tri)[0] < reach - MESH_MARGIN_M)
        at = np.flatnonzero(shown)
        if depth is not None and at.size:
            shown[at[covered(depth, camera, np.full(at.size, f), pix[at], z[at])]] = False
        out[f] = shown.mean()
    return out


def _drift(errors: np.ndarray) -> float | None:
    """Median error of the last third of the clip less that of the first third, px (the
    largest over the landmarks)."""
    third = max(1, errors.shape[0] // 3)
    out = []
    for p in range(errors.shape[1]):
        first, last = errors[:third, p], errors[-third:, p]
        if np.isfinite(first).any() and np.isfinite(last).any():
            out.append(np.nanmedian(last) - np.nanmedian(first))
    return num(max(out)) if out else None


def score_anchored(camera: CameraModel, label: ViewLabels, scene: SolvedObjects, target: int,
                   depth: DepthMaps | None = None, image_map: PixelMap | None = None
                   ) -> AnchoredQC:
    """One worker's landmark label of object ``target`` against the solved scene.

    Args:
        camera: the label's view. label: xy (F, P, 2) px, visible (F, P).
        scene: the solved objects; target: the labelled object's index in it.
        depth: optional (F, H, W) uint16 mm of the view.
        image_map: optional, where the camera truly shows a projected pixel (its offset);
            the label is then in the camera model's pixels, the depth map in the camera's.

    Returns:
        AnchoredQC with metrics anchored_median_px, anchored_p90_px (track vs anchored point,
        frames both call visible), anchored_visible_occluded (share of the point's visible
        frames marked occluded), anchored_hidden_visible (share of its hidden frames marked
        visible), anchored_drift_px, anchored_fraction (of the landmarks marked visible
        somewhere, those that could be anchored; None when none is: then
        anchored_visible_occluded is the share of frames where the object shows, see
        SHOWN_SHARE); landmark_separation_mm (least distance between anchored points),
        anchored_facing (least, over the landmarks, median cosine of the surface's turn
        towards the camera), anchored_shown_fraction (least share of the known frames a
        landmark's point shows in): see worker.quality.landmark_points;
        per_joint / per_frame median errors; issues where a landmark is over ISSUE_PX off.
    """
    xy = np.asarray(label.xy, np.float64)
    visible = np.asarray(label.visible, bool)
    # Only the worker's own decisions are judged (a pre-filled suggestion kept unchanged is
    # not); the anchor, which object point a landmark marks, reads the whole track.
    decided = decided_of(label)
    frames, points = visible.shape
    if scene.poses.shape[:2] != (len(scene.vertices), frames) or not 0 <= target < len(
            scene.vertices):
        raise ValueError(f"scene poses must have shape (O={len(scene.vertices)}, F={frames}, 3, "
                         f"4) and target be an object index, got {scene.poses.shape}, {target}")
    errors = np.full((frames, points), np.nan)
    reprojection = np.full((frames, points, 2), np.nan)
    shown = np.zeros((frames, points), bool)
    edge = np.zeros((frames, points), bool)
    # Frames without a solved pose of the object judge nothing.
    known = np.isfinite(scene.poses[target]).all(axis=(1, 2))
    found: dict[int, np.ndarray] = {}
    faced: list[float] = []
    for p in range(points):
        point = anchor(camera, xy[:, p], visible[:, p], scene, target)
        if point is None:
            continue
        found[p] = point
        world = _track_of(camera, point, scene.poses[target])
        shown[:, p], edge[:, p] = point_visibility(camera, world, scene, depth, image_map)
        cosine = facing(camera, point, world, shown[:, p], scene, target)
        if cosine is not None:
            faced.append(cosine)
        both = shown[:, p] & visible[:, p] & decided[:, p] & np.isfinite(xy[:, p]).all(axis=1)
        reprojection[:, p] = camera.project(world)
        errors[both, p] = np.linalg.norm(reprojection[both, p] - xy[both, p], axis=1)
    anchored = len(found)
    judged = np.isfinite(errors)
    # Visibility is judged where the views say plainly whether the point shows.
    hidden = ~shown & known[:, None] & decided & ~edge
    seen = shown & decided & ~edge
    # Landmarks the worker shows somewhere: only these can be anchored.
    placed = int((visible & np.isfinite(xy).all(axis=2)).any(axis=0).sum())
    metrics: dict[str, float | None] = {
        "anchored_median_px": num(np.median(errors[judged])) if judged.any() else None,
        "anchored_p90_px": num(np.percentile(errors[judged], 90)) if judged.any() else None,
        "anchored_visible_occluded": num((seen & ~visible).sum() / seen.sum())
        if anchored and seen.any() else None,
        "anchored_hidden_visible": num((hidden & visible).sum() / hidden.sum())
        if anchored and hidden.sum() >= MIN_HIDDEN_FRAMES else None,
        "anchored_drift_px": _drift(errors),
        "anchored_fraction": num(anchored / placed) if placed else None,
        # Distinct points of the surface, in plain view, shown through the clip
        # (worker.quality.landmark_points).
        "landmark_separation_mm": separation_mm(list(found.values())),
        "anchored_facing": num(min(faced)) if faced else None,
        "anchored_shown_fraction": shown_fraction(
            shown, known, np.isin(np.arange(points), list(found))),
    }
    if not placed and known.any():
        # Every landmark marked hidden all through: right where the object never shows; the
        # frames where it does are frames marked occluded while it can be seen.
        share = object_shown(camera, scene, target, depth)
        asked = np.isfinite(share) & decided.any(axis=1)
        if asked.any():
            metrics["anchored_visible_occluded"] = num(
                (share[asked] >= SHOWN_SHARE).sum() / asked.sum())
    per_joint, per_frame = per_point_and_frame(errors)
    issues = [dict(i, about="anchored") for i in error_issues(errors, ISSUE_PX)]
    return AnchoredQC(key=label.key, view=label.view, metrics=metrics, per_joint=per_joint,
                      per_frame=per_frame, issues=issues, provisional=not known.any(),
                      reprojection=np.where(known[:, None, None], reprojection, np.nan),
                      shown=shown, errors=errors)


# What the label's own track says (worker.quality.landmarks) only stands in for the solved
# object: a landmark that follows its anchored point moves with the object and does not leap,
# whatever the other views' tracks suggest (with one worker per view, half of them may be
# random or frozen), and its distance to the object in every frame says more than its
# distance to the outline of the initial pose in the first.
SUPERSEDED = ("moved_with_object", "jump_fraction", "max_step_ratio", "median_error_px",
              "mean_error_px", "p90_error_px", "outlier_fraction", "motion_ratio")


def merge_anchored(before: AssignmentQC, anchored: AssignmentQC,
                   run_id: int | None) -> AnchoredQC:
    """A landmark label's QC with the known object's verdict added: the anchored metrics
    join the label's own (replacing the SUPERSEDED motion guesses where the label could be
    judged), its per-landmark and per-frame errors are the anchored ones, and it is
    provisional only where neither check could judge it. run_id: the solve run whose poses
    were used, None for the poses given at import (an object that stays where it was put)."""
    metrics = {**before.metrics, **anchored.metrics,
               "solve_run": None if run_id is None else float(run_id)}
    if anchored.metrics.get("anchored_median_px") is not None:
        metrics.update(dict.fromkeys(SUPERSEDED))
    issues = anchored.issues + [i for i in before.issues
                                if i.get("about") not in ("jump", "silhouette")] \
        if anchored.metrics.get("anchored_median_px") is not None \
        else anchored.issues + before.issues
    return AnchoredQC(key=before.key, view=before.view, metrics=metrics,
                      per_joint=anchored.per_joint, per_frame=anchored.per_frame,
                      swaps=before.swaps, issues=issues,
                      provisional=before.provisional and anchored.provisional,
                      **({"reprojection": anchored.reprojection, "shown": anchored.shown,
                          "errors": anchored.errors} if isinstance(anchored, AnchoredQC) else {}))
