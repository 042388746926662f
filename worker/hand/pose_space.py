"""Pose space of the built-in hand: joint axes, MANO-style pose basis and relaxed mean pose.

MANO expresses the hand pose (45,) as axis-angle rotations of joints 1..15, each relative to its
parent, in the axes of the rest-pose model frame. For each of those joints we name three axes from
the bone it moves (see `worker.hand.anatomy`):
  flexion r = d x p: positive rotation bends the bone towards the palm;
  abduction -p: positive rotation swings the bone towards its r side (radially, towards the
  thumb, for the four fingers of the right hand);
  twist d: rotation about the bone itself.

The basis (hands_components, rows) starts with grasp synergies, in the order a principal component
analysis of everyday grasps ranks them (whole-hand closing first, then thumb opposition, finger
spread, ...), orthonormalised in that order, and is completed to all 45 dimensions with the
per-joint axes (flexions first, then abductions, then twists). The mean (hands_mean) is a relaxed
hand: fingers slightly curled, increasingly towards the little finger, thumb resting half opposed.
"""

from __future__ import annotations

import numpy as np

from worker.hand.anatomy import HandRig
from worker.hand.joints import MANO_FINGER_START, NUM_POSE_JOINTS

_FOUR = ("index", "middle", "ring", "little")
_PALMAR = np.array([0.0, 1.0, 0.0])  # palm normal of the right hand's model frame
_MIN_RESIDUAL = 1e-6


def joint_axes(rig: HandRig) -> np.ndarray:
    """(15, 3, 3) unit axes (flexion, abduction, twist) of MANO joints 1..15, right-hand frame."""
    axes = np.zeros((NUM_POSE_JOINTS, 3, 3))
    for chain in rig.chains:
        for k, joint in enumerate(chain.joint_ids):
            axes[joint - 1] = (chain.flexion_axes[k], -chain.palmar[k], chain.directions[k])
    return axes


def opposition_axis(rig: HandRig) -> np.ndarray:
    """(3,) unit axis that swings the thumb's first bone towards the fingers' pads.

    The target is a point palmar of the middle finger's knuckle by half a palm breadth, where the
    thumb's metacarpal points in a pinch or a grip.
    """
    thumb, middle = rig.chains[0], rig.chains[2]
    breadth = 2.0 * rig.palm.half_width.max()
    target = middle.nodes[0] + 0.5 * breadth * _PALMAR - thumb.nodes[0]
    axis = np.cross(thumb.directions[0], target)
    return axis / np.linalg.norm(axis)


class _PoseBuilder:
    """Accumulates a (15, 3) axis-angle pose from per-joint rotations about named axes."""

    def __init__(self, rig: HandRig) -> None:
        self.axes = joint_axes(rig)
        self.opposition = opposition_axis(rig)
        self.pose = np.zeros((NUM_POSE_JOINTS, 3))

    def rotate(self, finger: str, level: int, flex: float = 0.0, abduct: float = 0.0,
               twist: float = 0.0, in_palm: float = 0.0) -> _PoseBuilder:
        """Add rotations (rad) about joint axes; in_palm turns about the palm normal (for the
        thumb's base, positive brings the thumb towards the index finger in the palm plane)."""
        joint = MANO_FINGER_START[finger] + level
        r, a, d = self.axes[joint - 1]
        self.pose[joint - 1] += flex * r + abduct * a + twist * d + in_palm * _PALMAR
        return self

    def oppose(self, angle: float, pronation: float) -> _PoseBuilder:
        """Swing the thumb's base towards the finger pads (rad), turning its pad to face them."""
        self.pose[MANO_FINGER_START["thumb"] - 1] += angle * self.opposition
        return self.rotate("thumb", 0, twist=-pronation)

    def fingers(self, levels: tuple[float, float, float],
                factors: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
                ) -> _PoseBuilder:
        """Flex the four fingers' joints by levels (rad) times a per-finger factor."""
        for finger, factor in zip(_FOUR, factors, strict=True):
            for level, amount in enumerate(levels):
                self.rotate(finger, level, flex=factor * amount)
        return self

    def vector(self) -> np.ndarray:
        return self.pose.ravel().copy()


def _synergies(rig: HandRig) -> list[np.ndarray]:
    """Grasp synergies (45,) in decreasing order of how much grasps vary along them."""
    def new() -> _PoseBuilder:
        return _PoseBuilder(rig)

    closing = new().fingers((0.8, 1.0, 0.6), (1.0, 1.0, 1.05, 1.1)).oppose(0.3, 0.1)
    closing.rotate("thumb", 1, flex=0.4).rotate("thumb", 2, flex=0.5)
    opposition = new().oppose(0.9, 0.4).rotate("thumb", 1, flex=0.25).rotate("thumb", 2, flex=0.25)
    spread = new()
    for finger, amount in zip(_FOUR, (0.35, 0.05, -0.25, -0.45), strict=True):
        spread.rotate(finger, 0, abduct=amount)
    knuckle_vs_curl = new().fingers((0.8, -0.5, -0.4))
    radial_vs_ulnar = new().fingers((0.8, 0.8, 0.8), (1.0, 0.4, -0.4, -1.0))
    thumb_curl = new().rotate("thumb", 1, flex=0.7).rotate("thumb", 2, flex=0.9)
    pointing = new().fingers((0.7, 0.8, 0.5), (1.0, -0.2, -0.2, -0.2))
    tip_curl = new().fingers((0.0, -0.5, 0.9))
    thumb_sweep = new().rotate("thumb", 0, in_palm=0.8).rotate("thumb", 1, flex=-0.2)
    little_curl = new().fingers((0.6, 0.7, 0.5), (-0.1, -0.1, 0.3, 1.0))
    return [b.vector() for b in (closing, opposition, spread, knuckle_vs_curl, radial_vs_ulnar,
                                 thumb_curl, pointing, tip_curl, thumb_sweep, little_curl)]


def _axis_vectors(axes: np.ndarray) -> list[np.ndarray]:
    """Single-joint rotations about each named axis: flexions, then abductions, then twists."""
    vectors = []
    for kind in range(3):
        for joint in range(NUM_POSE_JOINTS):
            v = np.zeros((NUM_POSE_JOINTS, 3))
            v[joint] = axes[joint, kind]
            vectors.append(v.ravel())
    return vectors


def pose_basis(rig: HandRig) -> np.ndarray:
    """(45, 45) orthonormal rows: synergies first, completed by single-joint axes."""
    axes = joint_axes(rig)
    basis: list[np.ndarray] = []
    for candidate in _synergies(rig) + _axis_vectors(axes):
        residual = candidate.copy()
        for _ in range(2):  # twice, for orthogonality to rounding error
            for row in basis:
                residual -= (residual @ row) * row
        norm = np.linalg.norm(residual)
        if norm > _MIN_RESIDUAL * np.linalg.norm(candidate):
            basis.append(residual / norm)
    if len(basis) != 3 * NUM_POSE_JOINTS:
        raise RuntimeError(f"pose basis spans {len(basis)} dimensions, expected 45")
    return np.stack(basis)


def relaxed_pose(rig: HandRig) -> np.ndarray:
    """(45,) axis-angle, radians: the relaxed hand (MANO's hands_mean for our model)."""
    pose = _PoseBuilder(rig)
    curl = {"index": (0.25, 0.35, 0.15), "middle": (0.3, 0.4, 0.15),
            "ring": (0.35, 0.45, 0.2), "little": (0.4, 0.5, 0.25)}
    towards_middle = {"index": -0.06, "middle": 0.0, "ring": 0.04, "little": 0.08}
    for finger in _FOUR:
        pose.rotate(finger, 0, abduct=towards_middle[finger])
        for level, amount in enumerate(curl[finger]):
            pose.rotate(finger, level, flex=amount)
    pose.oppose(0.35, 0.15).rotate("thumb", 1, flex=0.15).rotate("thumb", 2, flex=0.2)
    return pose.vector()
