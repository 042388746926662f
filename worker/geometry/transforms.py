"""Rotations and rigid 3x4 poses on batched float64 arrays.

Conventions used throughout dexlabel:

- a rotation matrix ``R`` (..., 3, 3) maps vectors of a child frame into its parent frame;
- a pose ``T`` (..., 3, 4) = ``[R | t]`` maps points of frame A into frame B (``x_B = R x_A + t``),
  named ``T_a_to_b``; translations in metres;
- axis-angle (..., 3) is the rotation axis times the angle in radians;
- quaternions (..., 4) are ``(x, y, z, w)``, scalar last, as scipy's ``Rotation.as_quat``;
  ``matrix_to_quaternion`` returns the representative with ``w >= 0``.
"""

from __future__ import annotations

import numpy as np

# Below this angle (radians) Rodrigues' coefficients are replaced by their Taylor series,
# which keeps full float64 accuracy where sin(a)/a would lose digits.
_SMALL_ANGLE = 1e-6


def _check_last(name: str, array: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Return ``array`` as float64 after checking that its trailing dims equal ``shape``."""
    array = np.asarray(array, dtype=np.float64)
    if array.ndim < len(shape) or array.shape[array.ndim - len(shape):] != shape:
        want = "(..., " + ", ".join(str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {array.shape}")
    return array


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices: (..., 3) -> (..., 3, 3) with ``skew(a) @ b == cross(a, b)``."""
    v = _check_last("v", v, (3,))
    zero = np.zeros(v.shape[:-1])
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    rows = [[zero, -z, y], [z, zero, -x], [-y, x, zero]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def axis_angle_to_matrix(axis_angle: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: axis-angle (..., 3) radians -> rotation matrices (..., 3, 3)."""
    aa = _check_last("axis_angle", axis_angle, (3,))
    theta2 = np.sum(aa * aa, axis=-1)
    theta = np.sqrt(theta2)
    small = theta < _SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    k = skew(aa)
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + a[..., None, None] * k + b[..., None, None] * (k @ k)


def matrix_to_quaternion(matrix: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> unit quaternions (..., 4) ``(x, y, z, w)``, ``w >= 0``.

    Shepperd's method: every branch divides by the largest of the four candidate magnitudes,
    so the result is accurate for all rotations, including angles near pi.
    """
    m = _check_last("matrix", matrix, (3, 3))
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    trace = m00 + m11 + m22
    cand = np.stack([trace, m00, m11, m22], axis=-1)
    choice = np.argmax(cand, axis=-1)
    q = np.empty(m.shape[:-2] + (4,))
    d21, d12 = m[..., 2, 1], m[..., 1, 2]
    d02, d20 = m[..., 0, 2], m[..., 2, 0]
    d10, d01 = m[..., 1, 0], m[..., 0, 1]
    branches = [
        (1.0 + trace, [d21 - d12, d02 - d20, d10 - d01, None]),
        (1.0 + m00 - m11 - m22, [None, d01 + d10, d02 + d20, d21 - d12]),
        (1.0 - m00 + m11 - m22, [d01 + d10, None, d12 + d21, d02 - d20]),
        (1.0 - m00 - m11 + m22, [d02 + d20, d12 + d21, None, d10 - d01]),
    ]
    # Quaternion component order per branch: the "None" slot holds the large component.
    big_slot = [3, 0, 1, 2]
    for idx, (big2, others) in enumerate(branches):
        sel = choice == idx
        if not np.any(sel):
            continue
        s = np.sqrt(np.maximum(big2[sel], 1e-300))
        for slot, val in enumerate(others):
            q[sel, slot] = 0.5 * s if val is None else 0.5 * val[sel] / s
        q[sel, big_slot[idx]] = 0.5 * s
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def quaternion_to_matrix(quaternion: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) ``(x, y, z, w)``, normalised here -> rotation matrices (..., 3, 3)."""
    q = _check_last("quaternion", quaternion, (4,))
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm == 0.0):
        raise ValueError("quaternion must be non-zero")
    x, y, z, w = np.moveaxis(q / norm, -1, 0)
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def matrix_to_axis_angle(matrix: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> axis-angle (..., 3) with angle in [0, pi] radians."""
    q = matrix_to_quaternion(matrix)
    vec, w = q[..., :3], q[..., 3]
    sin_half = np.linalg.norm(vec, axis=-1)
    angle = 2.0 * np.arctan2(sin_half, w)
    small = sin_half < 1e-12
    # angle / sin(angle/2) -> 2 as the angle -> 0 (w ~ 1 there).
    scale = np.where(small, 2.0 / np.where(small, w, 1.0), angle / np.where(small, 1.0, sin_half))
    return vec * scale[..., None]


def quaternion_to_axis_angle(quaternion: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) ``(x, y, z, w)`` -> axis-angle (..., 3) radians."""
    return matrix_to_axis_angle(quaternion_to_matrix(quaternion))


def axis_angle_to_quaternion(axis_angle: np.ndarray) -> np.ndarray:
    """Axis-angle (..., 3) radians -> quaternions (..., 4) ``(x, y, z, w)``, ``w >= 0``."""
    return matrix_to_quaternion(axis_angle_to_matrix(axis_angle))


def make_pose(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Stack rotations (..., 3, 3) and translations (..., 3) metres into poses (..., 3, 4)."""
    rotation = _check_last("rotation", rotation, (3, 3))
    translation = _check_last("translation", translation, (3,))
    batch = np.broadcast_shapes(rotation.shape[:-2], translation.shape[:-1])
    rotation = np.broadcast_to(rotation, batch + (3, 3))
    translation = np.broadcast_to(translation[..., None], batch + (3, 1))
    return np.concatenate([rotation, translation], axis=-1)


def compose_poses(t_b_to_c: np.ndarray, t_a_to_b: np.ndarray) -> np.ndarray:
    """Chain poses: ``T_a_to_c = T_b_to_c o T_a_to_b``; (..., 3, 4) x (..., 3, 4) -> (..., 3, 4)."""
    t_b_to_c = _check_last("t_b_to_c", t_b_to_c, (3, 4))
    t_a_to_b = _check_last("t_a_to_b", t_a_to_b, (3, 4))
    rot = t_b_to_c[..., :3] @ t_a_to_b[..., :3]
    trans = (t_b_to_c[..., :3] @ t_a_to_b[..., 3:])[..., 0] + t_b_to_c[..., 3]
    return make_pose(rot, trans)


def invert_pose(t_a_to_b: np.ndarray) -> np.ndarray:
    """Inverse of rigid poses (..., 3, 4): ``T_b_to_a`` (uses R^T, so R must be a rotation)."""
    t_a_to_b = _check_last("t_a_to_b", t_a_to_b, (3, 4))
    rot_t = np.swapaxes(t_a_to_b[..., :3], -1, -2)
    return make_pose(rot_t, -(rot_t @ t_a_to_b[..., 3:])[..., 0])


def transform_points(t_a_to_b: np.ndarray, points_a: np.ndarray) -> np.ndarray:
    """Apply a pose (3, 4) to points (..., 3) of frame A, giving points (..., 3) in frame B."""
    t_a_to_b = _check_last("t_a_to_b", t_a_to_b, (3, 4))
    if t_a_to_b.ndim != 2:
        raise ValueError(f"t_a_to_b must have shape (3, 4), got {t_a_to_b.shape}")
    points_a = _check_last("points_a", points_a, (3,))
    return points_a @ t_a_to_b[:, :3].T + t_a_to_b[:, 3]


def transform_pose_m(
    pose_m: np.ndarray, t_a_to_b: np.ndarray, root_joint: np.ndarray
) -> np.ndarray:
    """Re-express MANO ``pose_m`` (..., 51) given in frame A in frame B.

    MANO (linear blend skinning) rotates the hand about its root joint ``J0(betas)`` and then
    translates: ``x_A = R_g (x_c - J0) + J0 + t`` for a canonical point ``x_c``. Applying
    ``x_B = R x_A + p`` gives ``R_g' = R R_g`` and ``t' = R (J0 + t) + p - J0``: the translation
    changes by more than a rotation of ``t``.

    Args:
        pose_m: (..., 51) ``[global axis-angle (3), hand pose (45), translation (3) metres]``; the
            45 hand-pose entries (PCA or full) are frame independent and copied.
        t_a_to_b: (3, 4) rigid pose from frame A to frame B, metres.
        root_joint: (3,) root joint J0 of the shaped rest hand (no pose, no translation), metres.

    Returns:
        (..., 51) pose_m in frame B.
    """
    pose_m = _check_last("pose_m", pose_m, (51,))
    t_a_to_b = _check_last("t_a_to_b", t_a_to_b, (3, 4))
    root = _check_last("root_joint", root_joint, (3,))
    if t_a_to_b.ndim != 2 or root.ndim != 1:
        raise ValueError(
            f"t_a_to_b must be (3, 4) and root_joint (3,), got {t_a_to_b.shape}, {root.shape}"
        )
    rot, shift = t_a_to_b[:, :3], t_a_to_b[:, 3]
    global_rot = rot @ axis_angle_to_matrix(pose_m[..., :3])
    transl = (pose_m[..., 48:51] + root) @ rot.T + shift - root
    out = pose_m.copy()
    out[..., :3] = matrix_to_axis_angle(global_rot)
    out[..., 48:51] = transl
    return out
