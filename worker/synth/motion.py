"""The grasp-and-lift motion of a synthetic sequence, table frame (metres, radians).

Five keyframes at fixed fractions of the clip: rest (relaxed hand, away from the object), pre-grasp
(open hand a few centimetres short of the grasp, above it), grasp (open hand at the object), closed
(fingers on the object) and lifted. Between keyframes every quantity follows a minimum-jerk
profile s(u) = 10u^3 - 15u^4 + 6u^5, which starts and stops with zero velocity and acceleration;
rotations interpolate along the geodesic, finger poses linearly in axis-angle. From the closed
keyframe on, the object moves rigidly with the hand.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.transforms import (
    axis_angle_to_matrix,
    compose_poses,
    invert_pose,
    make_pose,
    matrix_to_axis_angle,
)
from worker.synth.grasp import Grasp, ShapedHand

KEY_TIMES = np.array([0.0, 0.4, 0.56, 0.7, 1.0])  # rest, pre-grasp, grasp, closed, lifted
CLOSED_KEY = 3


def minimum_jerk(u: np.ndarray) -> np.ndarray:
    """Minimum-jerk blend s(u), u in [0, 1] (clipped): s(0) = 0, s(1) = 1, s' = s'' = 0 at ends."""
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10.0 - 15.0 * u + 6.0 * u * u)


@dataclass(frozen=True)
class Keyframe:
    """Hand state: rotation (3, 3), palm anchor (3,) metres, full finger pose (45,) radians."""

    rotation: np.ndarray
    anchor: np.ndarray
    finger_pose: np.ndarray


@dataclass(frozen=True)
class Trajectory:
    """Per-frame hand and object motion, table frame (F frames, K objects).

    Attributes:
        pose_m: (F, 51) float64 hand pose_m (PCA form).
        object_poses: (F, K, 3, 4) model-to-table poses of the objects.
    """

    pose_m: np.ndarray
    object_poses: np.ndarray


def make_keyframes(rng: np.random.Generator, rig: ShapedHand, grasp: Grasp) -> list[Keyframe]:
    """Rest, pre-grasp, grasp, closed and lifted keyframes around a planned grasp."""
    open_pose = rig.open_pose()
    relaxed = np.array(rig.model.hands_mean)  # zero PCA coefficients
    rest_offset = np.array([rng.uniform(0.08, 0.16), rng.uniform(-0.32, -0.24),
                            rng.uniform(0.06, 0.12)])
    twist = rng.normal(0.0, 1.0, 3)
    twist *= rng.uniform(0.5, 0.9) / np.linalg.norm(twist)
    rest_rot = axis_angle_to_matrix(twist) @ grasp.rotation
    pre = grasp.anchor - 0.06 * grasp.approach + np.array([0.0, 0.0, 0.03])
    lift = np.array([rng.uniform(-0.03, 0.03), rng.uniform(-0.08, -0.03), rng.uniform(0.12, 0.18)])
    tilt = rng.normal(0.0, 1.0, 3)
    tilt *= np.deg2rad(rng.uniform(8.0, 20.0)) / np.linalg.norm(tilt)
    return [
        Keyframe(rest_rot, grasp.anchor + rest_offset, relaxed),
        Keyframe(grasp.rotation, pre, open_pose),
        Keyframe(grasp.rotation, grasp.anchor, open_pose),
        Keyframe(grasp.rotation, grasp.anchor, grasp.closed_pose),
        Keyframe(axis_angle_to_matrix(tilt) @ grasp.rotation, grasp.anchor + lift,
                 grasp.closed_pose),
    ]


def _interpolate(a: Keyframe, b: Keyframe, s: float) -> Keyframe:
    rel = matrix_to_axis_angle(a.rotation.T @ b.rotation)
    return Keyframe(a.rotation @ axis_angle_to_matrix(s * rel),
                    (1.0 - s) * a.anchor + s * b.anchor,
                    (1.0 - s) * a.finger_pose + s * b.finger_pose)


def hand_state(keys: list[Keyframe], t: float) -> Keyframe:
    """The hand at normalised time t in [0, 1]."""
    k = int(np.clip(np.searchsorted(KEY_TIMES, t, side="right") - 1, 0, len(keys) - 2))
    u = (t - KEY_TIMES[k]) / (KEY_TIMES[k + 1] - KEY_TIMES[k])
    return _interpolate(keys[k], keys[k + 1], float(minimum_jerk(np.array(u))))


def _hand_transform(rig: ShapedHand, state: Keyframe) -> np.ndarray:
    """(3, 4) rigid map from the canonical hand to the table frame (anchor -> state.anchor)."""
    return make_pose(state.rotation, state.anchor - state.rotation @ rig.anchor)


def build_trajectory(rig: ShapedHand, keys: list[Keyframe], object_poses: np.ndarray,
                     grasp_ind: int, frames: int) -> Trajectory:
    """Sample the motion at ``frames`` evenly spaced instants (t = i / (frames - 1)).

    Args:
        object_poses: (K, 3, 4) initial model-to-table poses; the grasped object (index
            ``grasp_ind``) follows the hand rigidly from the closed keyframe on.
    """
    times = np.linspace(0.0, 1.0, frames) if frames > 1 else np.zeros(1)
    hold = _hand_transform(rig, keys[CLOSED_KEY])
    obj_in_hand = compose_poses(invert_pose(hold), object_poses[grasp_ind])
    pose_m = np.empty((frames, 51))
    poses = np.repeat(object_poses[None], frames, axis=0)
    for i, t in enumerate(times):
        state = hand_state(keys, float(t))
        root = state.anchor - state.rotation @ (rig.anchor - rig.root)
        pose_m[i] = rig.pose_m(state.rotation, root, state.finger_pose)
        if t >= KEY_TIMES[CLOSED_KEY]:
            poses[i, grasp_ind] = compose_poses(_hand_transform(rig, state), obj_in_hand)
    return Trajectory(pose_m, poses)
