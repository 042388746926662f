"""A differentiable MANO layer in PyTorch that runs any `HandModel` (official or built-in).

Semantics are MANO's as implemented by smplx: full pose = [global_orient, hand pose], the hand
pose mapped through hands_components when PCA is used, plus hands_mean unless flat_hand_mean;
v_shaped = v_template + shapedirs . betas; rest joints = J_regressor . v_shaped; pose correctives
from (R_j - I), j = 1..15; rigid transforms along the kinematic tree; linear blend skinning; then
+ transl. Outputs are metres in the frame the pose is expressed in (the model frame rotated by
global_orient about the wrist, then translated).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import torch
from torch import nn

from worker.hand.joints import NUM_SKELETON_JOINTS, SKELETON_TO_DEXYCB
from worker.hand.lbs import (
    axis_angle_to_matrix,
    blend_shapes,
    linear_blend_skinning,
    pose_features,
    rigid_transforms,
)
from worker.hand.params import NUM_HAND_POSE, HandModel

POSE_M_SIZE = 51  # DexYCB pose_m: 3 global axis-angle + 45 PCA coefficients + 3 translation


@dataclass
class HandOutput:
    """Posed hand, metres.

    vertices: (B, V, 3). joints: (B, 21, 3) in DexYCB order (wrist; thumb, index, middle, ring,
    little: mcp, pip, dip, tip), tips read from the model's tip vertices. skeleton: (B, 16, 3)
    MANO-order joints. full_pose: (B, 48) axis-angle actually applied (global + 15 joints), rad.
    """

    vertices: torch.Tensor
    joints: torch.Tensor
    skeleton: torch.Tensor
    full_pose: torch.Tensor


def _as_batch(
    value: torch.Tensor | npt.ArrayLike,
    name: str,
    width: int,
    batch: int | None,
    like: torch.Tensor,
) -> torch.Tensor:
    """`value` as a (B, width) tensor of `like`'s dtype/device; ValueError naming the shape."""
    tensor = torch.as_tensor(value, dtype=like.dtype, device=like.device)
    expected = f"(B, {width})" if batch is None else f"({batch}, {width})"
    wrong_batch = batch is not None and tensor.ndim == 2 and tensor.shape[0] != batch
    if tensor.ndim != 2 or tensor.shape[1] != width or wrong_batch:
        raise ValueError(f"{name} must have shape {expected}, got {tuple(tensor.shape)}")
    return tensor


class HandLayer(nn.Module):
    """MANO forward kinematics and skinning for one `HandModel`.

    flat_hand_mean: when False (MANO's and DexYCB's default) hands_mean is added to the hand
    pose, so zero pose = the relaxed mean hand. use_pca: hand_pose holds 45 coefficients of
    hands_components (all components, as DexYCB uses) instead of 15 x 3 axis-angle.
    """

    # Buffers registered in __init__, declared so that they read as tensors, not modules.
    v_template: torch.Tensor
    shapedirs: torch.Tensor
    posedirs: torch.Tensor
    J_regressor: torch.Tensor
    lbs_weights: torch.Tensor
    hands_components: torch.Tensor
    pose_mean: torch.Tensor
    faces: torch.Tensor
    tip_vertex_ids: torch.Tensor
    joint_order: torch.Tensor

    def __init__(
        self,
        model: HandModel,
        *,
        flat_hand_mean: bool = False,
        use_pca: bool = True,
        dtype: torch.dtype = torch.float64,
        device: str | torch.device = "cpu",
    ) -> None:
        super().__init__()
        self.side = model.side
        self.flat_hand_mean = flat_hand_mean
        self.use_pca = use_pca
        self.num_betas = model.num_betas
        self.parents = [int(p) for p in model.parents]

        def buffer(name: str, array: npt.ArrayLike, kind: torch.dtype = dtype) -> None:
            tensor = torch.as_tensor(np.array(array), dtype=kind, device=device)
            self.register_buffer(name, tensor)

        buffer("v_template", model.v_template)
        buffer("shapedirs", model.shapedirs)
        # (V, 3, 135) -> (135, V * 3): pose features (B, 135) @ posedirs give flat offsets.
        buffer("posedirs", model.posedirs.reshape(-1, model.posedirs.shape[-1]).T)
        buffer("J_regressor", model.J_regressor)
        buffer("lbs_weights", model.weights)
        buffer("hands_components", model.hands_components)
        mean = model.hands_mean * (0.0 if flat_hand_mean else 1.0)
        buffer("pose_mean", np.concatenate((np.zeros(3), mean)))
        buffer("faces", model.faces, torch.long)
        buffer("tip_vertex_ids", model.tip_vertex_ids, torch.long)
        buffer("joint_order", SKELETON_TO_DEXYCB, torch.long)

    def full_pose(self, global_orient: torch.Tensor, hand_pose: torch.Tensor) -> torch.Tensor:
        """(B, 48) axis-angle of all 16 joints from global_orient (B, 3) and hand_pose (B, 45)."""
        if self.use_pca:
            hand_pose = hand_pose @ self.hands_components
        return torch.cat((global_orient, hand_pose), dim=1) + self.pose_mean

    def forward(
        self,
        global_orient: torch.Tensor,
        hand_pose: torch.Tensor,
        betas: torch.Tensor | None = None,
        transl: torch.Tensor | None = None,
    ) -> HandOutput:
        """Pose the hand.

        global_orient: (B, 3) axis-angle of the wrist, radians. hand_pose: (B, 45) PCA
        coefficients (use_pca) or axis-angle of joints 1..15, radians. betas: (B, K) shape, zeros
        when None. transl: (B, 3) metres added to everything, zeros when None.
        """
        global_orient = _as_batch(global_orient, "global_orient", 3, None, self.v_template)
        batch = global_orient.shape[0]
        hand_pose = _as_batch(hand_pose, "hand_pose", NUM_HAND_POSE, batch, self.v_template)
        zeros = self.v_template.new_zeros
        betas = zeros(batch, self.num_betas) if betas is None else betas
        betas = _as_batch(betas, "betas", self.num_betas, batch, self.v_template)
        transl = zeros(batch, 3) if transl is None else transl
        transl = _as_batch(transl, "transl", 3, batch, self.v_template)
        full_pose = self.full_pose(global_orient, hand_pose)
        vertices, skeleton = self._skin(full_pose, betas)
        vertices = vertices + transl[:, None, :]
        skeleton = skeleton + transl[:, None, :]
        tips = vertices[:, self.tip_vertex_ids]
        joints = torch.cat((skeleton, tips), dim=1)[:, self.joint_order]
        return HandOutput(vertices=vertices, joints=joints, skeleton=skeleton, full_pose=full_pose)

    def _skin(self, full_pose: torch.Tensor, betas: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Shape, pose-correct and skin: vertices (B, V, 3), skeleton (B, 16, 3), model frame."""
        v_shaped = self.v_template + blend_shapes(betas, self.shapedirs)
        rest_joints = torch.einsum("jv,bvc->bjc", self.J_regressor, v_shaped)
        skeleton, vertices = self.pose_vertices(full_pose, v_shaped, rest_joints)
        return vertices, skeleton

    def pose_vertices(
        self,
        full_pose: torch.Tensor,
        v_shaped: torch.Tensor,
        rest_joints: torch.Tensor,
        vertex_ids: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """MANO's forward kinematics and skinning: the one place vertices are posed.

        full_pose: (B, 48) axis-angle of the 16 joints, rad (see :meth:`full_pose`).
        v_shaped: (V, 3) or (B, V, 3) shaped template, metres; rest_joints: (16, 3) or
        (B, 16, 3) its rest skeleton. vertex_ids: (B, K) the vertices to skin per frame, or
        None for all V. Returns the posed skeleton (B, 16, 3) and vertices (B, K or V, 3),
        metres, in the model frame (no translation).
        """
        batch = full_pose.shape[0]
        rotations = axis_angle_to_matrix(full_pose.reshape(batch, NUM_SKELETON_JOINTS, 3))
        skeleton, transforms = rigid_transforms(
            rotations, rest_joints.expand(batch, -1, -1), self.parents)
        # One dense product for all vertices, then a gather: a plain matrix product stays fast
        # under vmap, where a per-frame gather of the basis first would be copied per tangent.
        offsets = (pose_features(rotations) @ self.posedirs).reshape(batch, -1, 3)
        weights = self.lbs_weights
        if vertex_ids is not None:
            index = vertex_ids[..., None].expand(-1, -1, 3)
            offsets = torch.gather(offsets, 1, index)
            v_shaped = (v_shaped[vertex_ids] if v_shaped.ndim == 2
                        else torch.gather(v_shaped, 1, index))
            weights = weights[vertex_ids]
        return skeleton, linear_blend_skinning(v_shaped + offsets, transforms, weights)

    def from_pose_m(self, pose_m: torch.Tensor, betas: torch.Tensor) -> HandOutput:
        """Pose the hand from a DexYCB label's pose_m.

        pose_m: (B, 51): [:, :3] global axis-angle (rad), [:, 3:48] 45 PCA coefficients with
        flat_hand_mean False, [:, 48:51] translation (metres). betas: (B, K) or (K,).
        Requires a layer built with use_pca=True and flat_hand_mean=False.
        """
        if not self.use_pca or self.flat_hand_mean:
            raise ValueError(
                "from_pose_m needs a HandLayer built with use_pca=True and flat_hand_mean=False, "
                f"this one has use_pca={self.use_pca}, flat_hand_mean={self.flat_hand_mean}"
            )
        pose_m = _as_batch(pose_m, "pose_m", POSE_M_SIZE, None, self.v_template)
        betas = torch.as_tensor(betas, dtype=self.v_template.dtype, device=self.v_template.device)
        if betas.ndim == 1:
            betas = betas.expand(pose_m.shape[0], -1)
        return self(pose_m[:, :3], pose_m[:, 3:48], betas, pose_m[:, 48:51])
