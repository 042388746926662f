"""The hand model's parameter arrays, in MANO's parameter format.

A `HandModel` holds exactly what a MANO pickle holds (with J_regressor dense and the root's parent
written as -1), whether it came from the official MANO files or from our built-in hand. All
lengths are metres in the model's rest frame; the 16 skeleton joints use MANO's order (see
`worker.hand.joints`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from worker.hand.joints import MANO_PARENTS, NUM_POSE_JOINTS, NUM_SKELETON_JOINTS

HandSide = Literal["right", "left"]
SIDES: tuple[HandSide, ...] = ("right", "left")

NUM_POSE_FEATURES = 9 * NUM_POSE_JOINTS  # 135: (R_j - I) flattened for joints 1..15
NUM_HAND_POSE = 3 * NUM_POSE_JOINTS  # 45: axis-angle of joints 1..15


def check_side(side: str) -> HandSide:
    """Return `side` if it is "right" or "left"; raise ValueError naming the bad value otherwise."""
    if side in SIDES:
        return side
    raise ValueError(f"side must be 'right' or 'left', got {side!r}")


def _frozen(array: np.ndarray, dtype: type) -> np.ndarray:
    out: np.ndarray = np.array(array, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class HandModel:
    """A linear-blend-skinned hand in MANO's parameter format (V vertices, F faces, K=10 betas).

    Arrays are float64 (int64 for indices), copied and read-only.

    v_template: (V, 3) rest-pose mesh, metres, model frame.
    shapedirs: (V, 3, K) metres per unit beta.
    posedirs: (V, 3, 135) metres per unit of the pose feature (R_j - I), joints 1..15 row-major.
    J_regressor: (16, V) dense; rest joints = J_regressor @ v_template.
    weights: (V, 16) skinning weights, rows sum to 1.
    kintree_table: (2, 16) int; row 0 the parents (-1 for the root), row 1 the joint ids 0..15.
    hands_components: (45, 45) rows are pose-space basis vectors (axis-angle of joints 1..15).
    hands_mean: (45,) mean hand pose, axis-angle, radians.
    faces: (F, 3) int64 vertex indices, counter-clockwise seen from outside.
    side: "right" or "left".
    tip_vertex_ids: (5,) vertex ids of the thumb, index, middle, ring and little fingertips.
    """

    v_template: np.ndarray
    shapedirs: np.ndarray
    posedirs: np.ndarray
    J_regressor: np.ndarray
    weights: np.ndarray
    kintree_table: np.ndarray
    hands_components: np.ndarray
    hands_mean: np.ndarray
    faces: np.ndarray
    side: HandSide
    tip_vertex_ids: np.ndarray

    def __post_init__(self) -> None:
        check_side(self.side)
        for name in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights",
                     "hands_components", "hands_mean"):
            object.__setattr__(self, name, _frozen(getattr(self, name), np.float64))
        for name in ("kintree_table", "faces", "tip_vertex_ids"):
            object.__setattr__(self, name, _frozen(getattr(self, name), np.int64))
        self._check_shapes()
        self._check_indices()

    def _check_shapes(self) -> None:
        v = self.v_template.shape[0]
        j = NUM_SKELETON_JOINTS
        expected = {
            "v_template": (v, 3),
            "posedirs": (v, 3, NUM_POSE_FEATURES),
            "J_regressor": (j, v),
            "weights": (v, j),
            "kintree_table": (2, j),
            "hands_components": (NUM_HAND_POSE, NUM_HAND_POSE),
            "hands_mean": (NUM_HAND_POSE,),
            "tip_vertex_ids": (5,),
        }
        for name, shape in expected.items():
            actual = getattr(self, name).shape
            if actual != shape:
                raise ValueError(f"{name} must have shape {shape}, got {actual}")
        if self.shapedirs.ndim != 3 or self.shapedirs.shape[:2] != (v, 3):
            raise ValueError(f"shapedirs must have shape ({v}, 3, K), got {self.shapedirs.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise ValueError(f"faces must have shape (F, 3), got {self.faces.shape}")

    def _check_indices(self) -> None:
        v = self.v_template.shape[0]
        if self.faces.size and (self.faces.min() < 0 or self.faces.max() >= v):
            raise ValueError(f"faces index vertices outside [0, {v})")
        if self.tip_vertex_ids.min() < 0 or self.tip_vertex_ids.max() >= v:
            raise ValueError(f"tip_vertex_ids index vertices outside [0, {v})")
        parents = self.kintree_table[0]
        if parents[0] != -1 or any(not 0 <= p < i for i, p in enumerate(parents[1:], start=1)):
            raise ValueError(
                "kintree_table[0] must give -1 for the root and a lower-numbered parent for "
                f"every other joint, got {parents.tolist()}"
            )

    @property
    def num_vertices(self) -> int:
        """V, the number of mesh vertices."""
        return int(self.v_template.shape[0])

    @property
    def num_betas(self) -> int:
        """K, the number of shape coefficients (10 for MANO)."""
        return int(self.shapedirs.shape[2])

    @property
    def parents(self) -> np.ndarray:
        """(16,) int64 parent of each skeleton joint, -1 for the wrist."""
        return self.kintree_table[0]

    def rest_joints(self, betas: np.ndarray | None = None) -> np.ndarray:
        """(16, 3) skeleton joints of the unposed hand for shape `betas` (K,), metres."""
        vertices = self.v_template
        if betas is not None:
            vertices = vertices + self.shapedirs @ np.asarray(betas, dtype=np.float64)
        return self.J_regressor @ vertices


def mano_kintree_table() -> np.ndarray:
    """(2, 16) int64 MANO kinematic tree with -1 as the root's parent."""
    return np.array([MANO_PARENTS, range(NUM_SKELETON_JOINTS)], dtype=np.int64)
