"""Posing MANO: the one place a hand's vertices and joints are computed from pose_m and betas.

- :func:`posed_hand`: the whole hand for DexYCB pose_m rows, as NumPy arrays, through
  :class:`worker.hand.HandLayer` (the synthetic ground truth, calibration views and every caller
  that wants a mesh);
- :class:`SubjectHand`: the same posing for one subject (betas fixed) evaluated only where the
  solver looks. The solver's residuals need the 21 joints and, for the depth term, the few
  hundred vertices that depth points are matched to; skinning all 778 vertices in every
  Jacobian column would dominate the solve. With the subject's betas fixed, the shaped
  template and rest joints are computed once; each evaluation then poses the skeleton and
  skins only the requested vertices.

Both pose through :meth:`worker.hand.HandLayer.pose_vertices`, the one implementation of MANO's
forward kinematics and skinning (pose correctives, rigid transforms, LBS), in a form that stays
fast under vmap.

pose_m (B, 51): global axis-angle (rad), 45 PCA coefficients, translation (metres); outputs in
metres in pose_m's frame; joints in DexYCB order.
"""

from __future__ import annotations

import numpy as np
import torch

from worker.hand.layer import HandLayer
from worker.hand.lbs import axis_angle_to_matrix, axis_angle_to_matrix_derivative


class SubjectHand:
    """A HandLayer's model with one subject's betas (K,) baked in; float64 on the layer's device."""

    def __init__(self, layer: HandLayer, betas: torch.Tensor) -> None:
        self.layer = layer
        betas = betas.to(layer.v_template)
        self.v_shaped = layer.v_template + torch.einsum("k,vck->vc", betas, layer.shapedirs)
        self.rest_joints = layer.J_regressor @ self.v_shaped
        self.tips = layer.tip_vertex_ids
        self.num_vertices = self.v_shaped.shape[0]
        self.faces = layer.faces
        # posedirs per vertex: (V, 3, F), for the closed-form Jacobian's gathers.
        self.pose_dirs = layer.posedirs.reshape(layer.posedirs.shape[0], -1, 3) \
            .permute(1, 2, 0).contiguous()

    def pose(self, pose_m: torch.Tensor, vertex_ids: torch.Tensor | None = None
             ) -> tuple[torch.Tensor, torch.Tensor]:
        """Joints (B, 21, 3) in DexYCB order and vertices (B, K, 3), metres, for pose_m (B, 51).

        vertex_ids: (K,) which vertices to skin, or (B, K) a different set per frame; None
        skins all of them.
        """
        batch = pose_m.shape[0]
        full = self.layer.full_pose(pose_m[:, :3], pose_m[:, 3:48])
        ids = torch.arange(self.num_vertices, device=pose_m.device) if vertex_ids is None \
            else vertex_ids
        if ids.ndim == 1:
            ids = ids.expand(batch, -1)
        wanted = torch.cat((self.tips.expand(batch, -1), ids), dim=1)  # (B, 5 + K)
        skeleton, verts = self.layer.pose_vertices(full, self.v_shaped, self.rest_joints, wanted)
        shift = pose_m[:, None, 48:51]
        joints = torch.cat((skeleton, verts[:, :5]), dim=1)[:, self.layer.joint_order]
        return joints + shift, verts[:, 5:] + shift


    def pose_jacobian(self, pose_m: torch.Tensor, vertex_ids: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """:meth:`pose` with its derivatives in closed form, for Levenberg-Marquardt.

        Returns joints (B, 21, 3), vertices (B, K, 3) and their derivatives with respect to
        pose_m, (B, 21, 3, 51) and (B, K, 3, 51). The chain rule through MANO: each joint's
        rotation (Rodrigues' derivative), the kinematic chain (every ancestor's rotation moves
        a joint), the pose correctives (linear in the rotations) and the blended transforms.
        vertex_ids: (K,) or (B, K).
        """
        layer = self.layer
        batch = pose_m.shape[0]
        with torch.no_grad():
            full = layer.full_pose(pose_m[:, :3], pose_m[:, 3:48]).reshape(batch, -1, 3)
            count = full.shape[1]
            rot = axis_angle_to_matrix(full)  # (B, J, 3, 3)
            d_rot = axis_angle_to_matrix_derivative(full)  # (B, J, 3, 3, 3): [..., i] = dR/dr_i
            ids = vertex_ids.expand(batch, -1) if vertex_ids.ndim == 1 else vertex_ids
            wanted = torch.cat((self.tips.expand(batch, -1), ids), dim=1)  # (B, 5 + K)
            # Tangents along the 3 J axis-angle coordinates q = 3 j + i of the full pose.
            tangents = 3 * count
            parents = layer.parents
            rest = self.rest_joints
            world_r: list[torch.Tensor] = []
            world_t: list[torch.Tensor] = []
            d_world_r: list[torch.Tensor] = []
            d_world_t: list[torch.Tensor] = []
            for j in range(count):
                d_own = pose_m.new_zeros(batch, tangents, 3, 3)
                if parents[j] < 0:
                    world_r.append(rot[:, j])
                    world_t.append(rest[j].expand(batch, 3))
                    d_own[:, 3 * j:3 * j + 3] = d_rot[:, j].permute(0, 3, 1, 2)
                    d_world_r.append(d_own)
                    d_world_t.append(pose_m.new_zeros(batch, tangents, 3))
                    continue
                p = parents[j]
                rel = rest[j] - rest[p]
                world_r.append(world_r[p] @ rot[:, j])
                world_t.append(world_t[p] + world_r[p] @ rel)
                d_own[:, 3 * j:3 * j + 3] = world_r[p][:, None] @ d_rot[:, j].permute(0, 3, 1, 2)
                d_world_r.append(d_world_r[p] @ rot[:, j][:, None] + d_own)
                d_world_t.append(d_world_t[p] + d_world_r[p] @ rel)
            r_w = torch.stack(world_r, 1)  # (B, J, 3, 3)
            t_w = torch.stack(world_t, 1)  # (B, J, 3): the posed skeleton
            d_r_w = torch.stack(d_world_r, 2)  # (B, Q, J, 3, 3)
            d_t_w = torch.stack(d_world_t, 2)  # (B, Q, J, 3)
            # Skinning transforms act on rest-frame points: t - R J_rest.
            t_skin = t_w - (r_w @ rest[..., None])[..., 0]
            d_t_skin = d_t_w - (d_r_w @ rest[..., None])[..., 0]
            # Pose correctives of the wanted vertices: (R_j - I) for j >= 1, flattened (F
            # features), through posedirs. Tangents last from here on: (B, N, 3, Q).
            dirs = self.pose_dirs[wanted].flatten(1, 2)  # (B, 3 (5 + K), F)
            eye = torch.eye(3, dtype=rot.dtype, device=rot.device)
            features = (rot[:, 1:] - eye).flatten(1)  # (B, F)
            d_features = pose_m.new_zeros(batch, features.shape[1], tangents)
            for j in range(1, count):
                d_features[:, 9 * (j - 1):9 * j, 3 * j:3 * j + 3] = d_rot[:, j].flatten(1, 2)
            size = wanted.shape[1]
            points = self.v_shaped[wanted] + (dirs @ features[..., None]).view(batch, size, 3)
            d_points = (dirs @ d_features).view(batch, size, 3, tangents)
            # Blended transforms [R | t] per vertex, and their tangents (one product with the
            # skinning weights for all of them).
            weights = layer.lbs_weights[wanted]  # (B, 5 + K, J)
            blend = weights @ torch.cat((r_w, t_skin[..., None]), -1).flatten(2)
            blend = blend.view(batch, size, 3, 4)
            d_skin = torch.cat((d_r_w, d_t_skin[..., None]), -1).permute(0, 2, 3, 4, 1)
            d_blend = (weights @ d_skin.flatten(2)).view(batch, size, 3, 4, tangents)
            homogeneous = torch.cat((points, points.new_ones(batch, size, 1)), -1)
            verts = (blend @ homogeneous[..., None])[..., 0]
            d_verts = (d_blend * homogeneous[:, :, None, :, None]).sum(3) \
                + blend[..., :3] @ d_points  # (B, 5 + K, 3, Q)
            # From the full pose's coordinates to pose_m's 51: the wrist's 3 as they are, the
            # fingers' 45 through the PCA basis (full = pca @ components), translation 1.
            basis = layer.hands_components if layer.use_pca else eye.new_ones(45).diag()
            to_params = pose_m.new_zeros(tangents, 51)
            to_params[:3, :3] = eye
            to_params[3:48, 3:48] = basis.T
            joints = torch.cat((t_w, verts[:, :5]), 1)[:, layer.joint_order]
            d_skeleton = d_t_w.permute(0, 2, 3, 1)
            d_joints = torch.cat((d_skeleton, d_verts[:, :5]), 1)[:, layer.joint_order]
            d_joints = d_joints @ to_params
            d_vertices = d_verts[:, 5:] @ to_params
            d_joints[..., 48:51] = eye
            d_vertices[..., 48:51] = eye
            shift = pose_m[:, None, 48:51]
        return joints + shift, verts[:, 5:] + shift, d_joints, d_vertices

def posed_hand(layer: HandLayer, pose_m: np.ndarray, betas: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (B, V, 3) and joints (B, 21, 3), metres, float64 NumPy, of ``layer``'s hand
    for pose_m (B, 51) and betas (K,) or (B, K); no gradients.

    The layer must be built for pose_m (use_pca=True, flat_hand_mean=False, as by default).
    """
    with torch.no_grad():
        out = layer.from_pose_m(torch.as_tensor(pose_m, dtype=torch.float64),
                                torch.as_tensor(betas, dtype=torch.float64))
    return out.vertices.detach().numpy(), out.joints.detach().numpy()
