"""Shape and pose-corrective blend shapes of the built-in hand (MANO's shapedirs and posedirs).

Shape: ten modes, each a change of the hand's anatomy (`HandAnatomy`) per unit beta, so that
beta ~ N(0, 1) spans a plausible adult population, roughly as MANO's betas do. The blend shapes are
the derivatives of the generated mesh with respect to those changes (central differences: the
mesh generator is smooth in the anatomy), made mutually orthogonal in vertex space in the order
listed (as principal components are) and rescaled to keep each mode's size.

Pose correctives: linear blend skinning thins a tube where two bones meet (a vertex blended 50/50
between two bones rotated by theta relative to each other moves towards the joint by a factor
cos(theta / 2) in the bending plane). The correctives push such vertices back out along their
flesh radius, in the plane perpendicular to the joint's rotation axis, in proportion to 1 - cos.
Both quantities are linear in MANO's pose feature (R - I): its symmetric part is
-(1 - cos theta) (I - a a^T) for a rotation by theta about the unit axis a.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from worker.hand.anatomy import HandAnatomy, build_rig
from worker.hand.joints import NUM_POSE_JOINTS
from worker.hand.mesh import HandMesh, build_mesh

# Anatomy change per unit beta, in mode order. Sizes are about one population standard deviation
# of adult hand measures (hand length ~5%, breadth ~5%, finger girth ~7%).
SHAPE_MODES: tuple[tuple[str, dict[str, float | tuple[float, ...]]], ...] = (
    ("scale", {"scale": 0.045}),
    ("palm_width", {"palm_width": 0.05}),
    ("finger_length", {"finger_length": (0.05, 0.05, 0.05, 0.05, 0.05)}),
    ("girth", {"girth": 0.07}),
    ("palm_length", {"palm_length": 0.04}),
    ("thumb_length", {"finger_length": (0.06, 0.0, 0.0, 0.0, 0.0)}),
    ("palm_thickness", {"palm_thickness": 0.07}),
    ("digit_ratio", {"finger_length": (0.0, 0.035, 0.0, -0.035, 0.0)}),
    ("little_length", {"finger_length": (0.0, 0.0, 0.0, 0.0, 0.05)}),
    ("taper", {"taper": 0.15}),
)
NUM_BETAS = len(SHAPE_MODES)

_DIFF_STEP = 1e-3  # beta units for the central differences
# Fraction of the flesh radius restored per unit of (1 - cos theta) on a joint's ring. A 50/50
# vertex loses r (1 - cos(theta / 2)); over 0..90 degrees that is 0.25..0.29 r (1 - cos theta).
_CORRECTIVE_GAIN = 0.27


def _perturbed(
    anatomy: HandAnatomy, change: dict[str, float | tuple[float, ...]], t: float
) -> HandAnatomy:
    values: dict[str, Any] = {}  # each field's own type: a float or a tuple of floats
    for name, delta in change.items():
        base = getattr(anatomy, name)
        if isinstance(delta, tuple):
            values[name] = tuple(b + t * d for b, d in zip(base, delta, strict=True))
        else:
            values[name] = base + t * delta
    return dataclasses.replace(anatomy, **values)


def _mesh_vertices(anatomy: HandAnatomy) -> np.ndarray:
    return build_mesh(build_rig(anatomy)).vertices


def shape_directions(anatomy: HandAnatomy | None = None) -> np.ndarray:
    """(V, 3, 10) shape blend shapes around `anatomy` (default: the reference hand), metres per
    unit beta, model frame."""
    anatomy = HandAnatomy() if anatomy is None else anatomy
    raw = []
    for _, change in SHAPE_MODES:
        plus = _mesh_vertices(_perturbed(anatomy, change, _DIFF_STEP))
        minus = _mesh_vertices(_perturbed(anatomy, change, -_DIFF_STEP))
        raw.append(((plus - minus) / (2.0 * _DIFF_STEP)).ravel())
    basis: list[np.ndarray] = []
    for direction in raw:
        residual = direction.copy()
        for earlier in basis:
            residual -= (residual @ earlier) / (earlier @ earlier) * earlier
        basis.append(residual * (np.linalg.norm(direction) / np.linalg.norm(residual)))
    return np.stack(basis, axis=-1).reshape(-1, 3, NUM_BETAS)


def pose_correctives(mesh: HandMesh, gain: float = _CORRECTIVE_GAIN) -> np.ndarray:
    """(V, 3, 135) pose blend shapes, metres per unit of the pose feature (R_j - I), j = 1..15.

    The offset of vertex v for joint j is -gain * bend_j(v) * sym(R_j - I) @ o_v, with o_v the
    vertex's flesh radius vector at rest; feature index 9 (j - 1) + 3 row + column.
    """
    n_vertices = mesh.vertices.shape[0]
    # coefficient of feature (row, col) on offset component c: 1/2 o_col [c == row] +
    # 1/2 o_row [c == col], times -gain * bend.
    half = -0.5 * gain * mesh.bend[:, 1:, None] * mesh.offsets[:, None, :]  # (V, 15, 3)
    posedirs = np.zeros((n_vertices, 3, NUM_POSE_JOINTS, 3, 3))
    for c in range(3):
        posedirs[:, c, :, c, :] += half
        posedirs[:, c, :, :, c] += half
    return posedirs.reshape(n_vertices, 3, 9 * NUM_POSE_JOINTS)
