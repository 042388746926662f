"""Suggestions from one or two accepted views: the hand model fitted to their labels and depth,
projected into another view.

Pre-fill by triangulation (worker.assist.prefill) needs accepted work in three other views.
Before that, one view's labels fix each joint's ray and that view's depth map fixes how far
along it the hand's surface is; the hand model (its bone lengths, joint limits and pose prior)
fills in the rest. So the hand is fitted to the accepted views alone, with the solver's own
energy (E_kpt + E_depth + E_reg + the pose smoothing, worker.solver.default.fit_hand) and a
start from the labels lifted onto the depth (a joint seen in two views: triangulated); the
fitted joints are projected into the target view, with a visibility from the target view's
depth (worker.assist.prefill.suggested_visibility: a joint behind the depth map by more than
HIDDEN_MARGIN_M is proposed occluded).

Conventions as in worker.geometry.cameras: pixels x right, y down; world metres; depth maps
(F, H, W) uint16 millimetres along the camera's z axis, 0 = no reading. F frames, V cameras.
Pure: arrays in, arrays out.
"""

from __future__ import annotations

import numpy as np

from worker.assist.prefill import (
    DepthReader,
    Prefill,
    ViewWork,
    distinct_views,
    suggested_visibility,
    triangulate_work,
)
from worker.geometry.cameras import CameraModel, camera_to_world, pixels_to_rays
from worker.hand.joints import NUM_JOINTS
from worker.hand.params import HandModel
from worker.solver.default import fit_hand
from worker.solver.init import hand_from_joints
from worker.solver.problem import Problem
from worker.solver.state import SolveState
from worker.solver.types import (
    HandTarget,
    Landmark,
    ObjectTarget,
    SolveInputs,
    SolveSettings,
)

# A joint lies inside the finger, behind the skin the depth camera sees: about a finger's
# radius (adult fingers are 14-20 mm thick).
JOINT_BEHIND_SURFACE_M = 0.008
# Pixels around a label searched for the nearest depth reading: labels sit on thin fingers
# whose edges read as background or drop out.
LIFT_RADIUS_PX = 3
# Most views the model fit is used for: from this many on, triangulation
# (worker.assist.prefill.MIN_ACCEPTED_VIEWS) takes over.
MAX_FIT_VIEWS = 2
# The fit's settings: the solve's energy, one view enough for a frame (6 joints, as the solve).
FIT_SETTINGS = SolveSettings(min_views=1, icp_rounds=1)
# Robust keypoint rounds before the depth round, and LM iterations of the start's fit to the
# lifted joints: fewer than the solve's (a suggestion is checked by a person; seconds matter).
FIT_ROUNDS = 2
START_ITERATIONS = 5


def lift_labels(cameras: list[CameraModel], work: list[ViewWork],
                depth: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(F, P, 3) world metres and (F, P) bool: each decided visible label put on its view's
    depth (the nearest reading within LIFT_RADIUS_PX, pushed JOINT_BEHIND_SURFACE_M further
    along the camera's z), averaged over a point's views; where two views see it, triangulated
    instead. depth: view -> (F, H, W) uint16 mm; a view without it lifts nothing."""
    frames, points = np.shape(work[0].xy)[:2]
    total, count = np.zeros((frames, points, 3)), np.zeros((frames, points))
    for w in work:
        if w.view not in depth:
            continue
        lifted = _lift_view(cameras[w.view], w, depth[w.view])
        read = np.isfinite(lifted).all(axis=-1)
        total[read] += lifted[read]
        count += read
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / count[..., None]
    if len(distinct_views(work)) >= 2:
        tri, views = triangulate_work(cameras, work)
        out = np.where((views >= 2)[..., None], tri, out)
    return out, np.asarray(np.isfinite(out).all(axis=-1))


def _lift_view(camera: CameraModel, work: ViewWork, depth: np.ndarray) -> np.ndarray:
    """(F, P, 3) world metres of one view's decided visible labels on its depth; NaN elsewhere."""
    depth = np.asarray(depth)
    height, width = depth.shape[1:]
    use = work.visible & work.decided & np.isfinite(work.xy).all(axis=-1)
    out = np.full(work.xy.shape[:2] + (3,), np.nan)
    if not use.any():
        return out
    f_idx, p_idx = np.nonzero(use)
    xy = work.xy[f_idx, p_idx]
    r = LIFT_RADIUS_PX
    offsets = np.array([(dy, dx) for dy in range(-r, r + 1) for dx in range(-r, r + 1)])
    rows = np.clip(np.rint(xy[:, 1]).astype(int)[:, None] + offsets[:, 0], 0, height - 1)
    cols = np.clip(np.rint(xy[:, 0]).astype(int)[:, None] + offsets[:, 1], 0, width - 1)
    window = depth[f_idx[:, None], rows, cols].astype(np.float64) / 1000.0
    window[window <= 0] = np.inf
    # The nearest reading: the finger in front, not the background beside it.
    z = window.min(axis=1) + JOINT_BEHIND_SURFACE_M
    read = np.isfinite(z)
    rays = pixels_to_rays(xy[read], camera.K, camera.dist)  # (N, 3), z = 1
    cam = rays * z[read, None]
    world = camera_to_world(cam, camera.T_cam_to_world)
    out[f_idx[read], p_idx[read]] = world
    return out


def fit_hand_joints(cameras: list[CameraModel], work: list[ViewWork],
                    depth: dict[int, np.ndarray], side: str, betas: np.ndarray,
                    hand_model: HandModel | None = None,
                    settings: SolveSettings = FIT_SETTINGS, rounds: int = FIT_ROUNDS
                    ) -> np.ndarray:
    """(F, 21, 3) world metres: the hand model fitted to the work's views alone (their decided
    visible labels and their depth maps, view -> (F, H, W) uint16 mm); NaN in frames with
    fewer than settings.min_joints labelled joints or no start."""
    frames = np.shape(work[0].xy)[0]
    # Only views with decided labels: one with only pre-filled echoes adds neither its labels
    # nor its depth.
    work = [w for w in work if w.decided.any()]
    out = np.full((frames, NUM_JOINTS, 3), np.nan)
    if not work:
        return out
    views = distinct_views(work)
    local = {v: i for i, v in enumerate(views)}
    keypoints = np.full((len(views), frames, NUM_JOINTS, 2), np.nan)
    visible = np.zeros((len(views), frames, NUM_JOINTS), bool)
    for w in work:  # a view's first decided label wins where it has several assignments
        use = w.visible & w.decided & ~visible[local[w.view]]
        keypoints[local[w.view]][use] = w.xy[use]
        visible[local[w.view]] |= use
    inputs = SolveInputs(
        cameras=[cameras[v] for v in views], num_frames=frames,
        hand=HandTarget(side=side, betas=np.asarray(betas, np.float64), keypoints=keypoints,
                        visible=visible),
        objects=[], depth=[depth.get(v) for v in views], hand_model=hand_model)
    problem = Problem(inputs, settings)
    state = SolveState.empty(problem)
    lifted, ok = lift_labels(cameras, work, depth)
    started = ok[state.hand_frames].sum(axis=1) >= 3
    state.hand_frames = state.hand_frames[started]
    if not len(state.hand_frames):
        return out
    state.hand_pose[state.hand_frames] = hand_from_joints(
        problem, lifted[state.hand_frames], ok[state.hand_frames], START_ITERATIONS)
    fit_hand(problem, state, None, settings.lm_iterations, rounds)
    robust_mm = settings.depth_robust_mm if settings.robust else None
    for _ in range(settings.icp_rounds if problem.clouds else 0):
        matches = state.match_all(problem)
        data = problem.depth_data(0, [matches[f] for f in state.hand_frames],
                                  problem.hand_faces, robust_mm)
        fit_hand(problem, state, data, settings.lm_iterations, 1)
    out[state.hand_frames] = state.joints(problem)
    return out


def fitted_prefill(cameras: list[CameraModel], work: list[ViewWork], target: int,
                   joints: np.ndarray,
                   depth: np.ndarray | DepthReader | None = None) -> Prefill:
    """Suggestions for view ``target`` from fitted world joints (F, P, 3) (fit_hand_joints):
    projected, with a visibility from the target view's depth maps (as
    worker.assist.prefill.prefill). ``views`` counts the accepted views the fit rests on."""
    camera = cameras[target]
    inside, visible, known = suggested_visibility(camera, joints, depth)
    xy = np.where(inside[..., None], camera.project(joints), np.nan)
    fitted = np.isfinite(joints).all(axis=-1)
    views = np.where(fitted, len(distinct_views(work)), 0)
    return Prefill(xy=xy, visible=visible, known=known, views=views, points=joints)


def fit_object_points(cameras: list[CameraModel], work: list[ViewWork],
                      depth: dict[int, np.ndarray], vertices: np.ndarray, faces: np.ndarray,
                      initial_pose: np.ndarray | None = None,
                      settings: SolveSettings = FIT_SETTINGS) -> tuple[np.ndarray, np.ndarray]:
    """(F, P, 3) world metres and (P, 3) object frame metres: the landmarks of the first
    assignment with decided labels (P of them, in its point order), each mapped onto the mesh
    (vertices (N, 3), faces (M, 3), object frame, metres) and carried by the object's poses.
    The solver fits those poses to the landmarks and depth maps (view -> (F, H, W) uint16 mm)
    of the work's views alone (worker.solver.entry.solve without a hand: each frame from its
    own landmarks and depth). initial_pose: (3, 4) object-to-world at frame 0, None: fitted to
    frame 0. NaN where a landmark could not be mapped; ValueError where the solve refuses (no
    initial pose fits)."""
    from worker.solver.entry import solve

    frames, points = np.shape(work[0].xy)[:2]
    work = [w for w in work if w.decided.any()]
    out, local_points = np.full((frames, points, 3), np.nan), np.full((points, 3), np.nan)
    if not work:
        return out, local_points
    views = distinct_views(work)
    local = {v: i for i, v in enumerate(views)}
    landmarks = [Landmark(view=local[w.view], xy=np.where(w.decided[:, p, None], w.xy[:, p],
                                                          np.nan),
                          visible=w.visible[:, p] & w.decided[:, p])
                 for w in work for p in range(points)]
    inputs = SolveInputs(
        cameras=[cameras[v] for v in views], num_frames=frames, hand=None,
        objects=[ObjectTarget(name="object", vertices=np.asarray(vertices, float),
                              faces=np.asarray(faces, np.int64), initial_pose=initial_pose,
                              landmarks=landmarks)],
        depth=[depth.get(v) for v in views])
    result = solve(inputs, settings)
    poses = result.object_poses[0]  # (F, 3, 4)
    for p, point in enumerate(result.landmark_points[0][:points]):
        if point is not None:
            local_points[p] = point
            out[:, p] = np.einsum("fij,j->fi", poses[:, :, :3], local_points[p]) + poses[:, :, 3]
    return out, local_points
