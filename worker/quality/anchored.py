"""Object-landmark QC after the solve: every landmark anchored to the solved object's surface.

Once the objects are solved (poses in every frame), a worker's landmark is a point on the
object: its ray at a frame where it is labelled visible hits the object's surface there (the
paper maps each landmark once, at its first visible frame). A careful track then follows that
point's projection through every frame, and is marked occluded exactly where the point is
hidden. So each landmark is anchored at the candidate hit (over a few of its visible frames)
whose projection the track follows best, and judged:

- error: pixels between the track and the anchored point's projection, over the frames where
  the track shows it (median, 90th percentile), also where the solve hides it: a careful
  worker shows a point only where it shows, on it;
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

from dataclasses import dataclass, field

import numpy as np

from worker.assist.visibility import DepthMaps
from worker.geometry.cameras import CameraModel, pixels_to_rays
from worker.quality.landmark_points import facing, separation_mm, shown_fraction
from worker.quality.metrics import (
    AssignmentQC,
    error_issues,
    jitter_px,
    num,
    per_point_and_frame,
)
from worker.quality.object_views import (
    DEPTH_MARGIN_M,
    SEEN_SURFACE_M,
    SHOWN_SHARE,
    PixelMap,
    at_reading,
    object_shown,
    point_visibility,
    ray_hits,
    readings_m,
    surface_nearest,
)
from worker.quality.solved_scene import SolvedObjects
from worker.quality.view_labels import ViewLabels, decided_of

# Visible frames tried as the anchor's frame (evenly over the track): a sloppy first click
# does not decide where a careful track is anchored.
ANCHOR_TRIES = 12
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
                            self.swaps, self.issues, self.provisional,
                            self.kept_checks).to_dict()


def _ray(camera: CameraModel, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre (3,) and unit world directions (K, 3) through pixels (K, 2)."""
    rays_cam = pixels_to_rays(np.atleast_2d(xy), camera.K, camera.dist)
    dirs = rays_cam @ camera.T_cam_to_world[:, :3].T
    return camera.T_cam_to_world[:, 3], dirs / np.linalg.norm(dirs, axis=1, keepdims=True)


def _seen_point(camera: CameraModel, hit: np.ndarray, tri: np.ndarray,
                reading: float) -> np.ndarray:
    """The world point (3,) a visible click marks: the mesh hit ``hit`` of its ray, unless the
    depth camera sees a surface well in front of that hit (more than DEPTH_MARGIN_M) that
    is the object's own (within SEEN_SURFACE_M of its mesh ``tri``): then the ray went past
    an edge of the face the worker sees to a face behind (a camera pose a little off, a click
    a pixel over the edge), and the point marked is the surface point nearest where the
    reading puts it."""
    if not np.isfinite(reading) or camera.depth_of(hit) - reading <= DEPTH_MARGIN_M:
        return hit
    nearest, gap = surface_nearest(at_reading(camera, hit, reading), tri)
    return nearest if gap <= SEEN_SURFACE_M else hit


def _candidates(camera: CameraModel, xy: np.ndarray, ok: np.ndarray, scene: SolvedObjects,
                target: int, depth: DepthMaps | None = None,
                image_map: PixelMap | None = None) -> np.ndarray:
    """(K, 3) object-frame surface points the landmark's rays hit at a few visible frames
    (within SNAP_PX of the click); with the view's depth, the point it sees there
    (_seen_point)."""
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
            if depth is not None:
                click = xy[f] + _SNAPS[hit[0]]
                seen_at = image_map(click[None]) if image_map is not None else click[None]
                world = _seen_point(camera, world, tri,
                                    float(readings_m(depth, camera, np.array([f]), seen_at)[0]))
            pose = scene.poses[target, f]
            out.append(pose[:, :3].T @ (world - pose[:, 3]))
    return np.array(out).reshape(-1, 3)


def _track_of(camera: CameraModel, point: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(F, 3) world positions of an object-frame point under poses (F, 3, 4)."""
    return np.einsum("fij,j->fi", poses[:, :, :3], point) + poses[:, :, 3]


def anchor(camera: CameraModel, xy: np.ndarray, visible: np.ndarray, scene: SolvedObjects,
           target: int, depth: DepthMaps | None = None,
           image_map: PixelMap | None = None) -> np.ndarray | None:
    """The object-frame point (3,) of one landmark track (xy (F, 2) px, visible (F,)) whose
    projection the track follows best (least median error), or None where no ray hits.
    depth, image_map: the view's depth maps and where it truly shows a model pixel (see
    _seen_point)."""
    ok = np.asarray(visible, bool) & np.isfinite(xy).all(axis=1)
    candidates = _candidates(camera, xy, ok, scene, target, depth, image_map)
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
        frames the track shows it), anchored_visible_occluded (share of the point's visible
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
    frames = visible.shape[0]
    if scene.poses.shape[:2] != (len(scene.vertices), frames) or not 0 <= target < len(
            scene.vertices):
        raise ValueError(f"scene poses must have shape (O={len(scene.vertices)}, F={frames}, 3, "
                         f"4) and target be an object index, got {scene.poses.shape}, {target}")
    # Only the worker's own decisions are judged (a pre-filled suggestion kept unchanged is
    # not); the anchor, which object point a landmark marks, reads the whole track.
    found = _anchored_tracks(camera, xy, visible, decided_of(label), scene, target, depth,
                             image_map)
    # Frames without a solved pose of the object judge nothing.
    known = np.isfinite(scene.poses[target]).all(axis=(1, 2))
    metrics = _anchored_metrics(found, xy, visible, decided_of(label), known)
    shake = _anchored_shake(found, xy, visible)
    if shake is not None:
        # The object's known motion stands in for the other views' tracks (SUPERSEDED).
        metrics["jitter_px"] = shake
    if not (visible & np.isfinite(xy).all(axis=2)).any() and known.any():
        metrics["anchored_visible_occluded"] = _hidden_while_shown(camera, label, scene, target,
                                                                   depth)
    per_joint, per_frame = per_point_and_frame(found.errors)
    issues = [dict(i, about="anchored") for i in error_issues(found.errors, ISSUE_PX)]
    return AnchoredQC(key=label.key, view=label.view, metrics=metrics, per_joint=per_joint,
                      per_frame=per_frame, issues=issues, provisional=not known.any(),
                      reprojection=np.where(known[:, None, None], found.reprojection, np.nan),
                      shown=found.shown, errors=found.errors)


def _hidden_while_shown(camera: CameraModel, label: ViewLabels, scene: SolvedObjects,
                        target: int, depth: DepthMaps | None) -> float | None:
    """A label with every landmark marked hidden all through: right where the object never
    shows; the share of its decided frames where the object does show (marked occluded while
    it can be seen). None where no frame is known."""
    share = object_shown(camera, scene, target, depth)
    asked = np.isfinite(share) & decided_of(label).any(axis=1)
    return num((share[asked] >= SHOWN_SHARE).sum() / asked.sum()) if asked.any() else None


@dataclass
class _Tracks:
    """A label's landmarks anchored on the solved object, (F, P) each unless named: errors px
    (track against its anchored point where the track shows it, NaN elsewhere),
    reprojection (F, P, 2) px of the anchored points, shown (the point shows in the view),
    edge (at a depth edge: visibility undecided), points {landmark: object point (3,) m},
    faced: each anchored landmark's median cosine of the surface's turn to the camera."""

    errors: np.ndarray
    reprojection: np.ndarray
    shown: np.ndarray
    edge: np.ndarray
    points: dict[int, np.ndarray]
    faced: list[float]


def _anchored_tracks(camera: CameraModel, xy: np.ndarray, visible: np.ndarray,
                     decided: np.ndarray, scene: SolvedObjects, target: int,
                     depth: DepthMaps | None, image_map: PixelMap | None) -> _Tracks:
    """Each landmark anchored on object ``target`` and followed through its solved poses."""
    frames, points = visible.shape
    out = _Tracks(np.full((frames, points), np.nan), np.full((frames, points, 2), np.nan),
                  np.zeros((frames, points), bool), np.zeros((frames, points), bool), {}, [])
    for p in range(points):
        point = anchor(camera, xy[:, p], visible[:, p], scene, target, depth, image_map)
        if point is None:
            continue
        out.points[p] = point
        world = _track_of(camera, point, scene.poses[target])
        out.shown[:, p], out.edge[:, p] = point_visibility(camera, world, scene, depth,
                                                           image_map)
        cosine = facing(camera, point, world, out.shown[:, p], scene, target)
        if cosine is not None:
            out.faced.append(cosine)
        # Every position the worker shows is judged, also where the solve hides the point: a
        # careful worker shows it only where it shows, on it; a landmark shown where the other
        # one is (two swapped while one is hidden) is far from its own point.
        both = visible[:, p] & decided[:, p] & np.isfinite(xy[:, p]).all(axis=1)
        out.reprojection[:, p] = camera.project(world)
        out.errors[both, p] = np.linalg.norm(out.reprojection[both, p] - xy[both, p], axis=1)
    return out


def _anchored_shake(found: _Tracks, xy: np.ndarray, visible: np.ndarray) -> float | None:
    """The track's own shake (px per frame^2): that of its offset from its anchored points
    (worker.quality.metrics.jitter_px), so the known object's motion is taken out exactly and
    a leap (two landmarks swapped, a slip) is not hidden in it. Only the positions the label
    shows: an interpolation through frames marked hidden is not a label of anything."""
    if not found.points:
        return None
    shown = visible & np.isfinite(xy).all(axis=-1)
    return jitter_px(np.where(shown[..., None], xy, np.nan), found.reprojection)


def _anchored_metrics(found: _Tracks, xy: np.ndarray, visible: np.ndarray, decided: np.ndarray,
                      known: np.ndarray) -> dict[str, float | None]:
    """The metrics of score_anchored (see there) from the anchored tracks."""
    errors, shown, edge = found.errors, found.shown, found.edge
    anchored = len(found.points)
    judged = np.isfinite(errors)
    # Visibility is judged where the views say plainly whether the point shows.
    hidden = ~shown & known[:, None] & decided & ~edge
    seen = shown & decided & ~edge
    # Landmarks the worker shows somewhere: only these can be anchored.
    placed = int((visible & np.isfinite(xy).all(axis=2)).any(axis=0).sum())
    return {
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
        "landmark_separation_mm": separation_mm(list(found.points.values())),
        "anchored_facing": num(min(found.faced)) if found.faced else None,
        "anchored_shown_fraction": shown_fraction(
            shown, known, np.isin(np.arange(visible.shape[1]), list(found.points))),
    }


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
    out = AnchoredQC(key=before.key, view=before.view, metrics=metrics,
                     per_joint=anchored.per_joint, per_frame=anchored.per_frame,
                     swaps=before.swaps, issues=issues,
                     provisional=before.provisional and anchored.provisional,
                     kept_checks=before.kept_checks)
    if isinstance(anchored, AnchoredQC):
        out.reprojection, out.shown, out.errors = (anchored.reprojection, anchored.shown,
                                                   anchored.errors)
    return out
