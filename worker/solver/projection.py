"""Camera projection in PyTorch for a fixed rig of V calibrated views, and rigid-pose helpers.

World points are metres in the capture's master frame; pixels are x right, y down, with
OpenCV's (k1, k2, p1, p2, k3) distortion (worker.geometry.distortion, the same code as
`worker.geometry.cameras.project_points`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import torch

from worker.geometry.cameras import CameraModel
from worker.geometry.distortion import distort, distort_partials
from worker.hand.lbs import axis_angle_to_matrix


class Rig:
    """V cameras as tensors: rotation world-to-camera (V, 3, 3), camera centres (V, 3), K, dist."""

    def __init__(self, cameras: list[CameraModel], dtype: torch.dtype = torch.float64,
                 device: str | torch.device = "cpu") -> None:
        def tensor(array: npt.ArrayLike) -> torch.Tensor:
            return torch.as_tensor(np.asarray(array, dtype=np.float64), dtype=dtype, device=device)

        T = np.stack([c.T_cam_to_world for c in cameras])
        self.R_wc = tensor(np.transpose(T[:, :, :3], (0, 2, 1)))
        self.centre = tensor(T[:, :, 3])
        self.K = tensor(np.stack([c.K for c in cameras]))
        self.dist = tensor(np.stack([c.dist if c.dist is not None else np.zeros(5)
                                     for c in cameras]))
        self.num_views = len(cameras)

    def project(self, points: torch.Tensor) -> torch.Tensor:
        """World points (..., N, 3) -> pixels (..., V, N, 2) in every view.

        Points behind a camera get their depth clamped to 1 mm so values stay finite.
        """
        rel = points[..., None, :, :] - self.centre[:, None, :]
        cam = rel @ self.R_wc.transpose(1, 2)
        return _pixels(cam, self.K[:, None], self.dist[:, None])

    def project_derivative(self, points: torch.Tensor) -> torch.Tensor:
        """(..., V, N, 2, 3) derivative of each world point's pixels (:meth:`project`) in each
        view with respect to its position, in closed form (the chain through the rotation,
        the perspective division, the distortion and K); zero along z where the depth is
        clamped."""
        rel = points[..., None, :, :] - self.centre[:, None, :]
        cam = rel @ self.R_wc.transpose(1, 2)
        return _pixels_derivative(cam, self.K[:, None], self.dist[:, None]) \
            @ self.R_wc[:, None]

    def project_each(self, points: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
        """Points (..., L, 3) -> pixels (..., L, 2), point l in view views[l] only."""
        rel = points - self.centre[views]
        cam = (rel[..., None, :] @ self.R_wc[views].transpose(1, 2))[..., 0, :]
        return _pixels(cam, self.K[views], self.dist[views])

    def project_each_derivative(self, points: torch.Tensor, views: torch.Tensor
                                ) -> torch.Tensor:
        """(..., L, 2, 3): the derivative of :meth:`project_each` with respect to each point."""
        rel = points - self.centre[views]
        cam = (rel[..., None, :] @ self.R_wc[views].transpose(1, 2))[..., 0, :]
        return _pixels_derivative(cam, self.K[views], self.dist[views]) @ self.R_wc[views]


def _pixels(cam: torch.Tensor, K: torch.Tensor, dist: torch.Tensor) -> torch.Tensor:
    """Camera-frame points (..., 3) -> pixels (..., 2); K (..., 3, 3) and dist (..., 5)
    broadcast against the points' leading dimensions."""
    z = cam[..., 2].clamp(min=1e-3)
    xd, yd = distort(cam[..., 0] / z, cam[..., 1] / z, dist)
    u = K[..., 0, 0] * xd + K[..., 0, 1] * yd + K[..., 0, 2]
    v = K[..., 1, 1] * yd + K[..., 1, 2]
    return torch.stack((u, v), dim=-1)


def _pixels_derivative(cam: torch.Tensor, K: torch.Tensor, dist: torch.Tensor) -> torch.Tensor:
    """(..., 2, 3) derivative of :func:`_pixels` with respect to the camera-frame point."""
    raw = cam[..., 2]
    z = raw.clamp(min=1e-3)
    x, y = cam[..., 0] / z, cam[..., 1] / z
    inv_z = 1.0 / z
    along = torch.where(raw >= 1e-3, inv_z, torch.zeros_like(inv_z))
    zero = torch.zeros_like(inv_z)
    normalised = torch.stack((torch.stack((inv_z, zero, -x * along), dim=-1),
                              torch.stack((zero, inv_z, -y * along), dim=-1)), dim=-2)
    (a, b), (c, d) = distort_partials(x, y, dist)
    lens = torch.stack((torch.stack((a, b), dim=-1), torch.stack((c, d), dim=-1)), dim=-2)
    return K[..., :2, :2] @ lens @ normalised


def pose_matrix(delta: torch.Tensor, base: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Object pose from a 6-vector increment on a base pose.

    delta: (..., 6) = axis-angle (rad, applied on the left, world axes) and translation (m).
    base: (..., 3, 4) object-to-world. Returns R (..., 3, 3) and t (..., 3).
    """
    rot = axis_angle_to_matrix(delta[..., :3]) @ base[..., :3]
    return rot, base[..., 3] + delta[..., 3:]


def transform(rot: torch.Tensor, trans: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Apply R (..., 3, 3), t (..., 3) to points (..., N, 3) -> (..., N, 3)."""
    return points @ rot.transpose(-1, -2) + trans[..., None, :]
