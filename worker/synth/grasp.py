"""Hand kinematics for the synthesiser: palm frame, finger flexion and grasp planning.

The hand model's canonical frame (no global rotation, no translation) is whatever the model uses;
everything here is derived from its geometry, so the built-in hand and an official MANO model
both work. ``pose_m`` follows DexYCB: ``[global axis-angle (3), 45 PCA coefficients,
translation (3)]`` with ``flat_hand_mean=False``, i.e. full pose = hands_mean + coeffs @
hands_components, and a global rotation about the root joint J0(betas). Scene quantities are in
the table frame (metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.transforms import matrix_to_axis_angle
from worker.hand import FINGER_NAMES, HandLayer, HandModel, builtin_hand_model
from worker.hand.joints import MANO_FINGER_START
from worker.hand.posing import posed_hand
from worker.synth.scene import PlacedObject, object_sdf

# Flexion (radians) of the three joints of each finger at full closure, proximal first.
_CLOSE_FINGER = (1.35, 1.5, 1.1)
_CLOSE_THUMB = (0.55, 0.7, 0.9)
_OPEN_FLEX = 0.12  # slight pre-shape of the open hand, as a fraction of full closure
CONTACT_M = 0.0015  # a finger stops closing when it comes this close to the object or table
CLEARANCE_M = 0.004  # gap between the open hand and the object at the grasp position
_CLOSURE_STEPS = 41


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class ShapedHand:
    """A shaped hand with its canonical palm frame.

    Attributes:
        model: the hand model; layer: its torch layer (float64, PCA, flat_hand_mean False).
        betas: (10,) shape coefficients.
        root: (3,) root joint J0(betas) in the canonical frame, metres.
        anchor: (3,) palm anchor (centroid of the four finger knuckles), canonical, metres.
        axes: (3, 3) rows = finger direction f, palm normal p (out of the palm), thumb side t;
            canonical, right-handed (t = f x p).
        flex: (5, 45) full-pose flexion direction of each finger (FINGER_NAMES order), radians
            at full closure.
        vertex_finger: (V,) finger index of each vertex (by largest skinning weight), -1 palm.
    """

    model: HandModel
    layer: HandLayer
    betas: np.ndarray
    root: np.ndarray
    anchor: np.ndarray
    axes: np.ndarray
    flex: np.ndarray
    vertex_finger: np.ndarray

    def pca(self, full_pose: np.ndarray) -> np.ndarray:
        """Full 45-d axis-angle hand pose (..., 45) -> PCA coefficients (..., 45)."""
        return (full_pose - self.model.hands_mean) @ np.linalg.pinv(self.model.hands_components)

    def pose_m(self, rotation: np.ndarray, root_position: np.ndarray, full_pose: np.ndarray
               ) -> np.ndarray:
        """(..., 51) pose_m placing the root joint at ``root_position`` with ``rotation``."""
        aa = matrix_to_axis_angle(rotation)
        transl = root_position - self.root
        return np.concatenate([aa, self.pca(full_pose), transl], axis=-1)

    def evaluate(self, pose_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """pose_m (B, 51) -> vertices (B, V, 3) and joints (B, 21, 3) in pose_m's frame."""
        return posed_hand(self.layer, pose_m, self.betas)

    def open_pose(self) -> np.ndarray:
        """(45,) slightly pre-shaped open hand, full axis-angle."""
        return _OPEN_FLEX * self.flex.sum(axis=0)


def _finger_joint_ids(finger: str) -> list[int]:
    start = MANO_FINGER_START[finger]
    return [start, start + 1, start + 2]


def build_shaped_hand(betas: np.ndarray) -> ShapedHand:
    """Shape the built-in right hand and derive its palm frame and flexion directions."""
    model = builtin_hand_model("right")
    layer = HandLayer(model)
    betas = np.asarray(betas, dtype=np.float64)
    rest = model.rest_joints(betas)  # (16, 3) MANO order
    verts = model.v_template + model.shapedirs @ betas
    tips = verts[model.tip_vertex_ids]  # FINGER_NAMES order
    knuckles = rest[[MANO_FINGER_START[f] for f in ("index", "middle", "ring", "little")]]
    f_dir = _unit(rest[MANO_FINGER_START["middle"]] - rest[0])
    radial = knuckles[0] - knuckles[3]  # little -> index knuckle, towards the thumb
    t_dir = _unit(radial - (radial @ f_dir) * f_dir)
    # For a right hand the thumb side is f x p, so the palm normal is t x f.
    p_dir = np.cross(t_dir, f_dir)
    flex = np.zeros((5, 45))
    for f_index, finger in enumerate(FINGER_NAMES):
        ids = _finger_joint_ids(finger)
        chain = np.vstack([rest[ids], tips[f_index]])
        amounts = _CLOSE_THUMB if finger == "thumb" else _CLOSE_FINGER
        for k, joint in enumerate(ids):
            axis = _unit(np.cross(chain[k + 1] - chain[k], p_dir))
            flex[f_index, 3 * (joint - 1):3 * joint] = amounts[k] * axis
    joint_finger = np.full(16, -1)
    for f_index, finger in enumerate(FINGER_NAMES):
        joint_finger[_finger_joint_ids(finger)] = f_index
    return ShapedHand(model, layer, betas, rest[0], knuckles.mean(axis=0),
                   np.stack([f_dir, p_dir, t_dir]), flex,
                   joint_finger[np.argmax(model.weights, axis=1)])


@dataclass(frozen=True)
class Grasp:
    """A planned grasp, table frame.

    Attributes:
        rotation: (3, 3) hand global rotation. anchor: (3,) palm anchor position, metres.
        closed_pose: (45,) full axis-angle finger pose holding the object.
        approach: (3,) unit direction the hand moves along for the last few centimetres.
    """

    rotation: np.ndarray
    anchor: np.ndarray
    closed_pose: np.ndarray
    approach: np.ndarray


def grasp_frame(obj: PlacedObject, finger_yaw: float) -> tuple[np.ndarray, np.ndarray, str]:
    """World palm axes (rows f, p, t) and palm target for a side or top grasp of ``obj``.

    Tall objects get a "handshake" side grasp (palm vertical, thumb up, fingers pointing away
    from the subject); flat ones a top grasp (palm down).
    """
    half = obj.spec.half_extents
    centre = obj.T_obj_to_table[:, 3]
    f_w = np.array([np.sin(finger_yaw), np.cos(finger_yaw), 0.0])
    if 2.0 * half[2] >= 0.06:
        p_w = np.cross([0.0, 0.0, 1.0], f_w)  # thumb (f x p) then points up
        axes = np.stack([f_w, p_w, np.cross(f_w, p_w)])
        reach = np.abs(obj.T_obj_to_table[:, :3].T @ p_w) @ half
        height = np.clip(2.0 * half[2] * 0.45, 0.045, 0.1)
        target = centre - p_w * (reach + 0.02) - 0.015 * f_w
        target[2] = height
        return axes, target, "side"
    p_w = np.array([0.0, 0.0, -1.0])
    axes = np.stack([f_w, p_w, np.cross(f_w, p_w)])
    return axes, centre + [0.0, 0.0, half[2] + 0.018] - 0.03 * f_w, "top"


# Placements tried around the nominal palm target: offsets along the fingers and towards the
# thumb, metres. The one whose fingers close on the object (not on the table, not on air) wins.
_FINGER_OFFSETS = (-0.03, -0.01, 0.01, 0.03)
_THUMB_OFFSETS = (-0.015, 0.0, 0.015)
_THUMB_WEIGHT = 1.5  # an opposed thumb matters most for a stable-looking grasp


@dataclass(frozen=True)
class _CanonicalHand:
    """Canonical-frame vertices: open hand (V, 3) and each finger closing alone (5, S, V, 3)."""

    open: np.ndarray
    closing: np.ndarray
    levels: np.ndarray  # (S,) closure levels of ``closing``


def _canonical_hand(rig: ShapedHand) -> _CanonicalHand:
    levels = np.linspace(_OPEN_FLEX, 1.0, _CLOSURE_STEPS)
    poses = rig.open_pose() + (levels[None, :, None] - _OPEN_FLEX) * rig.flex[:, None]
    poses = np.concatenate([rig.open_pose()[None], poses.reshape(-1, 45)])
    n = len(poses)
    verts, _ = rig.evaluate(rig.pose_m(np.broadcast_to(np.eye(3), (n, 3, 3)),
                                       np.broadcast_to(rig.root, (n, 3)), poses))
    return _CanonicalHand(verts[0], verts[1:].reshape(5, _CLOSURE_STEPS, -1, 3), levels)


def _place(points: np.ndarray, rig: ShapedHand, rotation: np.ndarray, root: np.ndarray
           ) -> np.ndarray:
    """Canonical hand points (..., 3) -> table frame for a hand at (rotation, root)."""
    return (points - rig.root) @ rotation.T + root


def _gaps(verts: np.ndarray, obj: PlacedObject) -> tuple[np.ndarray, np.ndarray]:
    """Distance (..., V) of table-frame points to the object, and their height above the table."""
    rot, trans = obj.T_obj_to_table[:, :3], obj.T_obj_to_table[:, 3]
    return object_sdf(obj.spec, (verts - trans) @ rot), verts[..., 2]


def _settle(hand: _CanonicalHand, rig: ShapedHand, rotation: np.ndarray, root: np.ndarray,
            obj: PlacedObject, p_w: np.ndarray) -> np.ndarray:
    """Slide the open hand along its palm normal p_w (3,) until it is CLEARANCE_M from the
    object, keeping it 8 mm above the table; returns the adjusted root position (3,)."""
    verts = _place(hand.open, rig, rotation, root)
    shift = np.zeros(3)
    for _ in range(8):
        dist, height = _gaps(verts + shift, obj)
        lift = max(0.0, 0.008 - height.min())
        step = dist.min() - CLEARANCE_M
        shift += lift * np.array([0.0, 0.0, 1.0]) + step * p_w
        if abs(step) < 2e-4 and lift < 2e-4:
            break
    return root + shift


def _finger_closure(gap_object: np.ndarray, gap_table: np.ndarray, levels: np.ndarray
                    ) -> tuple[float, bool]:
    """Closure level where a finger first comes within CONTACT_M, from its per-level minimum
    gaps (S,) to the object and to the table; and whether that contact is with the object."""
    gap = np.minimum(gap_object, gap_table)
    touching = np.flatnonzero(gap <= CONTACT_M)
    if len(touching) == 0:
        return float(levels[-1]), False
    k = int(touching[0])
    on_object = bool(gap_object[k] <= gap_table[k])
    if k == 0:
        return float(levels[0]), on_object
    frac = (gap[k - 1] - CONTACT_M) / max(gap[k - 1] - gap[k], 1e-12)
    return float(levels[k - 1] + frac * (levels[k] - levels[k - 1])), on_object


def _closure(hand: _CanonicalHand, rig: ShapedHand, rotation: np.ndarray, root: np.ndarray,
             obj: PlacedObject) -> tuple[np.ndarray, float]:
    """(5,) closure per finger and a score: fingers stopped by the object (thumb weighted)."""
    dist, height = _gaps(_place(hand.closing, rig, rotation, root), obj)
    closure, score = np.ones(5), 0.0
    for f in range(5):
        mine = rig.vertex_finger == f
        closure[f], on_object = _finger_closure(dist[f][:, mine].min(axis=1),
                                                height[f][:, mine].min(axis=1), hand.levels)
        score += (_THUMB_WEIGHT if FINGER_NAMES[f] == "thumb" else 1.0) * on_object
    return closure, score


def plan_grasp(rig: ShapedHand, obj: PlacedObject, finger_yaw: float) -> Grasp:
    """Place the open hand next to ``obj`` and close each finger until it touches.

    Several palm placements around the nominal one are tried; the first with the best score
    (most fingers closing on the object) is kept, so the result is deterministic.
    """
    axes_w, target, _ = grasp_frame(obj, finger_yaw)
    rotation = axes_w.T @ rig.axes
    hand = _canonical_hand(rig)
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    for df in _FINGER_OFFSETS:
        for dt in _THUMB_OFFSETS:
            anchor = target + df * axes_w[0] + dt * axes_w[2]
            root = anchor - rotation @ (rig.anchor - rig.root)
            root = _settle(hand, rig, rotation, root, obj, axes_w[1])
            closure, score = _closure(hand, rig, rotation, root, obj)
            if best is None or score > best[0] + 1e-9:
                best = (score, root, closure)
    if best is None:
        raise ValueError("no palm placement to try")
    _, root, closure = best
    closed = rig.open_pose() + ((closure - _OPEN_FLEX)[:, None] * rig.flex).sum(axis=0)
    return Grasp(rotation, rotation @ (rig.anchor - rig.root) + root, closed, axes_w[1])
