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
