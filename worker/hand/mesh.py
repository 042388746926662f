"""The built-in hand's skinned mesh: palm slab and five finger tubes, with weights and regressor.

The surface is six closed, outward-wound components: the palm (a rounded slab lofted along x from
the wrist to past the knuckles) and one tube per finger that starts inside the palm and ends in a
rounded fingertip. Each tube has a ring of vertices centred exactly on each of its three joints,
and the palm has one centred on the wrist, so J_regressor (each joint = mean of its ring) gives the
rest joints exactly and follows any shape change. Lengths are metres, right-hand model frame
(see `worker.hand.anatomy`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.hand.anatomy import PALM_WRIST_STATION, Chain, HandRig, Palm
from worker.hand.joints import NUM_SKELETON_JOINTS
from worker.hand.loft import Loft, loft

PALM_RING_SIZE = 20
PALM_EXPONENT = 3.0  # rounded-rectangle cross-section
FINGER_RING_SIZE = 10
# Ring intervals along each finger: root (inside the palm) -> joint 1 -> joint 2 -> joint 3 ->
# start of the fingertip cap. Rings fall on the joints, where the regressor reads them.
_INTERVALS = (1, 4, 3, 2)
_TIP_CAP_RINGS = 2
_TIP_CAP_FRACTION = 0.9  # fingertip cap length / mean tip radius (a slightly flattened dome)
_ROOT_CAP_FRACTION = 0.5
# Skinning blend half-width around a finger joint, as a fraction of the flesh radius there: the
# ring on the joint splits 50/50, the next rings (>= 7 mm away) belong to a single bone.
_BLEND_FRACTION = 0.6
# Palm skin over the knuckles follows the finger's first joint (up to this weight), and the thenar
# skin follows the thumb's base joint, both fading with distance.
_KNUCKLE_WEIGHT = 0.5
_THENAR_WEIGHT = 0.4


@dataclass(frozen=True)
class HandMesh:
    """The built-in right hand's rest mesh and rigging, metres, model frame.

    vertices: (V, 3). faces: (F, 3) int64 outward winding. weights: (V, 16) rows sum to 1.
    J_regressor: (16, V) rows sum to 1. tip_vertex_ids: (5,) thumb..little fingertip poles.
    bend: (V, 16) 4 w (1 - w) across each joint's blend zone (1 on the joint ring), for the pose
    correctives. offsets: (V, 3) vertex minus its ring centre (the local flesh radius vector).
    """

    vertices: np.ndarray
    faces: np.ndarray
    weights: np.ndarray
    J_regressor: np.ndarray
    tip_vertex_ids: np.ndarray
    bend: np.ndarray
    offsets: np.ndarray


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _palm_loft(palm: Palm) -> Loft:
    n = palm.centres.shape[0]
    lateral = np.tile([0.0, 0.0, 1.0], (n, 1))
    palmar = np.tile([0.0, 1.0, 0.0], (n, 1))
    half_axes = np.stack((palm.half_width, palm.half_thickness), axis=1)
    caps = ((palm.cap_lengths[0], 1), (palm.cap_lengths[1], 2))
    return loft(palm.centres, lateral, palmar, half_axes, palm.centres[:, 0],
                ring_size=PALM_RING_SIZE, exponent=PALM_EXPONENT, caps=caps)


def _chain_frames(chain: Chain) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]:
    """Ring centres, tangents and palmar vectors along a finger, and the rings on its joints."""
    d, p = chain.directions, chain.palmar
    cap = _TIP_CAP_FRACTION * chain.radii[3].mean()
    root, end = chain.nodes[0] - chain.root_depth * d[0], chain.nodes[3] - cap * d[2]
    points = (root, *chain.nodes[:3], end)
    seg_d, seg_p = (d[0], d[0], d[1], d[2]), (p[0], p[0], p[1], p[2])
    centres, tangents, palmars, joint_rings = [points[0]], [d[0]], [p[0]], []
    for i, count in enumerate(_INTERVALS):
        for k in range(1, count + 1):
            centres.append(points[i] + (k / count) * (points[i + 1] - points[i]))
            on_joint = k == count and i + 1 < len(_INTERVALS)
            tangents.append(_unit(seg_d[i] + seg_d[i + 1]) if on_joint else seg_d[i])
            palmars.append(seg_p[i] + seg_p[i + 1] if on_joint else seg_p[i])
        joint_rings.append(len(centres) - 1)
    tangents_a = np.array(tangents)
    palmar_a = np.array(palmars)
    palmar_a = _unit(palmar_a - np.sum(palmar_a * tangents_a, 1, keepdims=True) * tangents_a)
    return np.array(centres), tangents_a, palmar_a, joint_rings[:3]


def _chain_loft(chain: Chain) -> tuple[Loft, list[int]]:
    """A finger's tube and the indices (into its main rings) of the rings on its three joints."""
    centres, tangents, palmar, joint_rings = _chain_frames(chain)
    arc = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(centres, axis=0), axis=1))))
    tip_cap = _TIP_CAP_FRACTION * chain.radii[3].mean()
    node_arc = np.concatenate(([arc[0]], arc[joint_rings], [arc[-1] + tip_cap]))
    node_radii = np.vstack((chain.radii[0], chain.radii))
    half_axes = np.stack([np.interp(arc, node_arc, node_radii[:, k]) for k in range(2)], axis=1)
    lateral = _unit(np.cross(tangents, palmar))
    caps = ((_ROOT_CAP_FRACTION * chain.radii[0].mean(), 0), (tip_cap, _TIP_CAP_RINGS))
    tube = loft(centres, lateral, palmar, half_axes, arc, ring_size=FINGER_RING_SIZE, caps=caps)
    return tube, joint_rings


def _chain_weights(
    chain: Chain, tube: Loft, joint_rings: list[int]
) -> tuple[np.ndarray, np.ndarray]:
    """(V_tube, 16) skinning weights and (V_tube, 16) bend factors along a finger tube."""
    weights = np.zeros((tube.arc.shape[0], NUM_SKELETON_JOINTS))
    bend = np.zeros_like(weights)
    steps = []
    for k, ring in enumerate(joint_rings):
        half_width = _BLEND_FRACTION * chain.radii[k].mean()
        joint_arc = tube.arc[tube.ring_starts[ring]]
        step = _smoothstep((tube.arc - joint_arc) / (2.0 * half_width) + 0.5)
        bend[:, chain.joint_ids[k]] = 4.0 * step * (1.0 - step)
        steps.append(step)
    steps.append(np.zeros_like(tube.arc))
    weights[:, 0] = 1.0 - steps[0]
    for k, joint in enumerate(chain.joint_ids):
        weights[:, joint] = steps[k] - steps[k + 1]
    return weights, bend


def _palm_weights(vertices: np.ndarray, chains: tuple[Chain, ...]) -> np.ndarray:
    """(V_palm, 16) palm skinning: wrist, plus knuckle and thenar skin following the fingers."""
    weights = np.zeros((vertices.shape[0], NUM_SKELETON_JOINTS))
    for chain in chains:
        rel = vertices - chain.nodes[0]
        d, p = chain.directions[0], chain.palmar[0]
        radius = chain.radii[0].mean()
        along = rel @ d
        if chain.finger == "thumb":
            bone = np.linalg.norm(chain.nodes[1] - chain.nodes[0])
            nearest = np.clip(along, 0.0, bone)[:, None] * d
            dist = np.linalg.norm(rel - nearest, axis=1)
            weights[:, chain.joint_ids[0]] = _THENAR_WEIGHT * np.exp(-((dist / radius) ** 2))
        else:
            across = np.linalg.norm(rel - np.outer(along, d) - np.outer(rel @ p, p), axis=1)
            rise = _smoothstep((along + 2.0 * radius) / (2.0 * radius))
            falloff = np.exp(-((across / radius) ** 2))
            weights[:, chain.joint_ids[0]] = _KNUCKLE_WEIGHT * rise * falloff
    total = weights.sum(axis=1, keepdims=True)
    weights *= np.minimum(1.0, (1.0 - 1e-3) / np.maximum(total, 1e-12))
    weights[:, 0] = 1.0 - weights.sum(axis=1)
    return weights


def _ring_rows(regressor: np.ndarray, joint: int, first: int, ring_size: int) -> None:
    regressor[joint, first:first + ring_size] = 1.0 / ring_size


def build_mesh(rig: HandRig) -> HandMesh:
    """Mesh, skinning weights, joint regressor and fingertips of `rig`, metres, model frame."""
    palm = _palm_loft(rig.palm)
    n_palm = palm.vertices.shape[0]
    parts: list[tuple[Loft, np.ndarray, np.ndarray]] = [
        (palm, _palm_weights(palm.vertices, rig.chains), np.zeros((n_palm, 16)))]
    tubes = [_chain_loft(chain) for chain in rig.chains]
    parts += [(tube, *_chain_weights(chain, tube, rings))
              for chain, (tube, rings) in zip(rig.chains, tubes, strict=True)]
    starts = np.cumsum([0] + [part[0].vertices.shape[0] for part in parts])
    regressor = np.zeros((NUM_SKELETON_JOINTS, int(starts[-1])))
    _ring_rows(regressor, 0, int(palm.ring_starts[PALM_WRIST_STATION]), palm.ring_size)
    tips = []
    for chain, (tube, rings), start in zip(rig.chains, tubes, starts[1:-1], strict=True):
        for joint, ring in zip(chain.joint_ids, rings, strict=True):
            _ring_rows(regressor, joint, int(start + tube.ring_starts[ring]), tube.ring_size)
        tips.append(int(start + tube.tip))
    return HandMesh(
        vertices=np.vstack([part[0].vertices for part in parts]),
        faces=np.vstack([part[0].faces + s for part, s in zip(parts, starts[:-1], strict=True)]),
        weights=np.vstack([part[1] for part in parts]),
        J_regressor=regressor,
        tip_vertex_ids=np.array(tips, dtype=np.int64),
        bend=np.vstack([part[2] for part in parts]),
        offsets=np.vstack([part[0].vertices - part[0].centres for part in parts]),
    )
