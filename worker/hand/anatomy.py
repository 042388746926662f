"""Anatomy of the built-in hand: skeleton, bone frames and flesh radii of a reference adult.

Frame of the right hand (the left hand is its mirror image in x), metres:
  origin at the wrist joint, +x distal (wrist towards the middle finger's knuckle),
  +y palmar (the palm faces +y), +z radial (towards the thumb); x cross y = z.
In the rest pose the hand is flat with straight, slightly spread fingers and the thumb set out
radially and a little palmar, at about 35 degrees to the index finger.

Every bone gets a frame: `direction` d (joint to child joint), `palmar` p (towards the flexor side,
perpendicular to d) and `flexion` axis r = d x p. A positive rotation about r bends the bone towards
its palmar side; for the fingers of the right hand r is +z, so positive rotation about the model's
z-axis flexes them (about -z for the left hand).

Reference sizes follow adult anthropometry: hand length (wrist crease to middle tip) ~18.5 cm,
palm (wrist to middle knuckle) ~9 cm, palm breadth at the knuckles ~8.5 cm, phalanx lengths in the
usual ~ 1 : 0.6 : 0.45 proportion, finger widths ~2 cm at the base.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from worker.hand.joints import FINGER_NAMES, MANO_FINGER_START

# Reference adult right hand. Fingers: knuckle (MCP) position (x, z) in metres, spread angle in
# degrees (towards +z), phalanx lengths MCP->PIP, PIP->DIP, DIP->tip (tip = end of the pad), and
# flesh half-axes (lateral, palmar) at the MCP, PIP, DIP and at the tip.
_FINGERS = {
    "index": ((0.086, 0.025), 6.0, (0.040, 0.023, 0.020),
              ((0.0100, 0.0090), (0.0090, 0.0080), (0.0082, 0.0072), (0.0075, 0.0065))),
    "middle": ((0.090, 0.005), 0.0, (0.045, 0.027, 0.021),
               ((0.0102, 0.0092), (0.0092, 0.0082), (0.0084, 0.0074), (0.0077, 0.0067))),
    "ring": ((0.085, -0.0145), -5.0, (0.042, 0.026, 0.021),
             ((0.0096, 0.0087), (0.0087, 0.0078), (0.0080, 0.0070), (0.0073, 0.0064))),
    "little": ((0.077, -0.032), -11.0, (0.033, 0.019, 0.019),
               ((0.0086, 0.0078), (0.0078, 0.0070), (0.0071, 0.0063), (0.0065, 0.0057))),
}
# Thumb: base joint (MANO's first thumb joint, anatomically the CMC) position, per bone the
# direction as (azimuth from +x towards +z, elevation towards +y) in degrees, bone lengths, flesh
# half-axes at the four nodes, and a hint for the pad direction (palmar and towards the fingers).
_THUMB_BASE = (0.020, 0.006, 0.018)
_THUMB_DIRECTIONS = ((40.0, 20.0), (31.0, 12.0), (25.0, 6.0))
_THUMB_LENGTHS = (0.046, 0.032, 0.027)
_THUMB_RADII = ((0.0180, 0.0150), (0.0120, 0.0105), (0.0105, 0.0090), (0.0092, 0.0080))
_THUMB_PAD_HINT = (0.0, 1.0, -1.0)
# How far each finger tube reaches back into the palm from its first joint, metres.
_FINGER_ROOT_DEPTH = 0.016
_THUMB_ROOT_DEPTH = 0.012
# Palm cross-sections along x: station x, half breadth (z), half thickness (y), metres.
_PALM_X = (-0.022, -0.010, 0.000, 0.015, 0.030, 0.045, 0.060, 0.072, 0.084)
_PALM_HALF_WIDTH = (0.026, 0.027, 0.028, 0.032, 0.036, 0.039, 0.041, 0.042, 0.042)
_PALM_HALF_THICKNESS = (0.0120, 0.0125, 0.0130, 0.0140, 0.0145, 0.0145, 0.0140, 0.0132, 0.0122)
_PALM_ULNAR_SHIFT = -0.004  # the palm's centre line drifts ulnarly towards the knuckles
_PALM_CAPS = (0.006, 0.012)  # proximal and distal end-cap lengths, metres
PALM_WRIST_STATION = 2  # the palm cross-section through the wrist joint (x = 0)


@dataclass(frozen=True)
class HandAnatomy:
    """Multipliers of the reference hand; all 1.0 is the reference adult right hand.

    scale: whole hand. palm_length / palm_width / palm_thickness: palm extents (x / z / y).
    finger_length: bone lengths per finger (thumb, index, middle, ring, little).
    girth: finger flesh radii. taper: how much the radii shrink from knuckle to tip.
    """

    scale: float = 1.0
    palm_length: float = 1.0
    palm_width: float = 1.0
    palm_thickness: float = 1.0
    finger_length: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0)
    girth: float = 1.0
    taper: float = 1.0


@dataclass(frozen=True)
class Chain:
    """One finger's tube: three MANO joints and the tip, at rest, metres.

    nodes: (4, 3) the three joints and the tip. palmar: (3, 3) per-bone palmar unit vectors.
    radii: (4, 2) flesh half-axes (lateral, palmar) at the nodes. root_depth: how far the tube
    extends back from nodes[0] into the palm. joint_ids: MANO ids of the three joints.
    """

    finger: str
    joint_ids: tuple[int, int, int]
    nodes: np.ndarray
    palmar: np.ndarray
    radii: np.ndarray
    root_depth: float

    @property
    def directions(self) -> np.ndarray:
        """(3, 3) unit bone directions, joint to child."""
        d = np.diff(self.nodes, axis=0)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    @property
    def flexion_axes(self) -> np.ndarray:
        """(3, 3) unit flexion axes r = d x p per bone (positive rotation flexes)."""
        r = np.cross(self.directions, self.palmar)
        return r / np.linalg.norm(r, axis=1, keepdims=True)


@dataclass(frozen=True)
class Palm:
    """The palm as a lofted slab along x: centres (S, 3), half breadth and thickness (S,)."""

    centres: np.ndarray
    half_width: np.ndarray
    half_thickness: np.ndarray
    cap_lengths: tuple[float, float] = field(default=_PALM_CAPS)


@dataclass(frozen=True)
class HandRig:
    """The built-in right hand at rest: palm plus five chains in FINGER_NAMES order."""

    palm: Palm
    chains: tuple[Chain, ...]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _orthogonal_palmar(directions: np.ndarray, hint: np.ndarray) -> np.ndarray:
    """(N, 3) unit vectors: `hint` made perpendicular to each direction."""
    p = hint - (directions @ hint)[:, None] * directions
    return _unit(p)


def _finger_chain(name: str, a: HandAnatomy, length: float) -> Chain:
    (x, z), spread, bones, radii = _FINGERS[name]
    knuckle = np.array([x * a.palm_length, 0.0, z * a.palm_width])
    angle = np.radians(spread)
    direction = np.array([np.cos(angle), 0.0, np.sin(angle)])
    offsets = np.cumsum((0.0, *bones)) * length
    nodes = knuckle + offsets[:, None] * direction
    palmar = _orthogonal_palmar(np.tile(direction, (3, 1)), np.array([0.0, 1.0, 0.0]))
    return Chain(name, _joint_ids(name), nodes, palmar, _tapered(radii, a), _FINGER_ROOT_DEPTH)


def _thumb_chain(a: HandAnatomy, length: float) -> Chain:
    base = np.array(_THUMB_BASE) * (a.palm_length, a.palm_thickness, a.palm_width)
    az, el = np.radians(np.array(_THUMB_DIRECTIONS)).T
    directions = np.stack((np.cos(el) * np.cos(az), np.sin(el), np.cos(el) * np.sin(az)), axis=1)
    steps = directions * (np.array(_THUMB_LENGTHS) * length)[:, None]
    nodes = np.vstack((base, base + np.cumsum(steps, axis=0)))
    palmar = _orthogonal_palmar(directions, _unit(np.array(_THUMB_PAD_HINT)))
    return Chain("thumb", _joint_ids("thumb"), nodes, palmar, _tapered(_THUMB_RADII, a),
                 _THUMB_ROOT_DEPTH)


def _joint_ids(finger: str) -> tuple[int, int, int]:
    start = MANO_FINGER_START[finger]
    return (start, start + 1, start + 2)


def _tapered(radii: tuple, a: HandAnatomy) -> np.ndarray:
    r = np.array(radii, dtype=np.float64)
    return (r[0] + a.taper * (r - r[0])) * a.girth


def _palm(a: HandAnatomy) -> Palm:
    x = np.array(_PALM_X)
    z = _PALM_ULNAR_SHIFT * np.clip(x, 0.0, None) / _PALM_X[-1]
    centres = np.stack((x * a.palm_length, np.zeros_like(x), z * a.palm_width), axis=1)
    return Palm(
        centres=centres,
        half_width=np.array(_PALM_HALF_WIDTH) * a.palm_width,
        half_thickness=np.array(_PALM_HALF_THICKNESS) * a.palm_thickness,
        cap_lengths=(_PALM_CAPS[0] * a.palm_length, _PALM_CAPS[1] * a.palm_length),
    )


def _scaled_chain(chain: Chain, s: float) -> Chain:
    return Chain(chain.finger, chain.joint_ids, chain.nodes * s, chain.palmar, chain.radii * s,
                 chain.root_depth * s)


def build_rig(anatomy: HandAnatomy | None = None) -> HandRig:
    """The built-in right hand's rest skeleton and flesh for `anatomy` (default: the reference
    hand), metres, model frame."""
    anatomy = HandAnatomy() if anatomy is None else anatomy
    if len(anatomy.finger_length) != len(FINGER_NAMES):
        raise ValueError(f"finger_length needs 5 values, got {len(anatomy.finger_length)}")
    lengths = dict(zip(FINGER_NAMES, anatomy.finger_length, strict=True))
    chains = [_thumb_chain(anatomy, lengths["thumb"])]
    chains += [_finger_chain(name, anatomy, lengths[name]) for name in FINGER_NAMES[1:]]
    s = anatomy.scale
    palm = _palm(anatomy)
    palm = Palm(palm.centres * s, palm.half_width * s, palm.half_thickness * s,
                (palm.cap_lengths[0] * s, palm.cap_lengths[1] * s))
    return HandRig(palm=palm, chains=tuple(_scaled_chain(c, s) for c in chains))
