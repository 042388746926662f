"""Subject shape from labelled joints: fit MANO betas so the model's bone lengths match.

The 20 bones are the DexYCB joint tree (`JOINT_PARENTS`): each joint to its parent, metres.
With the hand in its rest pose (all 16 joint rotations zero) the skeleton joints are
``J_regressor (v_template + shapedirs betas)`` and the tips are the shaped tip vertices, so every
joint position is *affine* in betas. The layer is evaluated once at betas = 0 and once per unit
beta to read that affine map exactly; the bone lengths ``|d_k + D_k betas|`` are then fitted by
Gauss-Newton with a small ridge on betas (shape space is Gaussian with unit variance).

Skeleton bones are pose-invariant under linear blend skinning (rigid transforms along the tree);
tip bones move by well under a millimetre with pose, which is why the fit uses the rest pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.geometry.triangulate import triangulate_points
from worker.hand.joints import JOINT_PARENTS, NUM_JOINTS
from worker.hand.params import HandModel

# Ridge weight (m^2 per unit beta^2): 1e-8 is (0.1 mm)^2, small beside the bone-length residuals,
# enough to keep directions the bones cannot see at zero.
DEFAULT_RIDGE = 1e-8
# Ridge for bones measured from labels: the per-bone median of careful labels triangulated over
# a short clip is off by about 0.5 mm, so (0.55 mm)^2 is the prior's weight. With the exact
# ridge above, that noise moves the surface by up to 2.7 mm in shape directions the bones
# barely see (on 8-view captures of seed 7311); with this one by 0.3-1.1 mm.
LABELLED_RIDGE = 3e-7
# A joint is triangulated only from observations that agree within this many pixels.
OUTLIER_PX = 15.0
# The calibration's hand shape is named off when its bones differ from the labels' by more than
# this, as the median over the 20 bones. Label noise alone (2 px careful labels, 4-8 views,
# 24 frames) leaves the median under about 0.5 mm; another subject's betas (drawn from the
# shape space, sigma 0.6) differ by 1.5-4 mm (bench/rig_faults.py --fault betas).
SHAPE_BONE_MM = 1.0
_BONES = np.array([(j, p) for j, p in enumerate(JOINT_PARENTS) if p >= 0])  # (20, 2)
NUM_BONES = len(_BONES)


@dataclass
class BetaFit:
    """Result of :func:`fit_betas`.

    betas: (K,) shape coefficients. lengths: (20,) the fitted model's bone lengths, metres.
    residual_mm: (20,) model minus target bone length, millimetres. iterations: steps taken.
    """

    betas: np.ndarray
    lengths: np.ndarray
    residual_mm: np.ndarray
    iterations: int


def bone_lengths(joints: np.ndarray) -> np.ndarray:
    """Bone lengths (..., 20) metres of joints (..., 21, 3) metres in DexYCB order (NaN kept)."""
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim < 2 or joints.shape[-2:] != (NUM_JOINTS, 3):
        raise ValueError(f"joints must have shape (..., {NUM_JOINTS}, 3), got {joints.shape}")
    child, parent = joints[..., _BONES[:, 0], :], joints[..., _BONES[:, 1], :]
    return np.linalg.norm(child - parent, axis=-1)


def median_bone_lengths(joints: np.ndarray, min_frames: int = 3) -> np.ndarray:
    """Per-bone median (20,) metres over frames of joints (F, 21, 3) metres, NaN = missing.

    The median ignores the frames where either end of a bone is missing and is robust to a few
    badly triangulated frames. Raises ValueError naming the bones seen in fewer than
    ``min_frames`` frames.
    """
    lengths = bone_lengths(joints)
    if lengths.ndim != 2:
        raise ValueError(f"joints must have shape (F, {NUM_JOINTS}, 3), got {np.shape(joints)}")
    counts = np.isfinite(lengths).sum(axis=0)
    few = np.flatnonzero(counts < min_frames)
    if len(few):
        raise ValueError(f"bones {few.tolist()} are measured in fewer than {min_frames} frames")
    return np.nanmedian(lengths, axis=0)


def rest_joint_map(model: HandModel) -> tuple[np.ndarray, np.ndarray]:
    """The affine map betas -> rest-pose joints: base (21, 3) and basis (21, 3, K), metres."""
    # PyTorch loads here, not with the module: the API checks shapes with this module's other
    # functions and never poses a hand.
    import torch

    from worker.hand.layer import HandLayer

    layer = HandLayer(model, flat_hand_mean=True, use_pca=False)
    k = model.num_betas
    betas = torch.cat((torch.zeros(1, k, dtype=torch.float64),
                       torch.eye(k, dtype=torch.float64)))
    zeros = torch.zeros(k + 1, 3, dtype=torch.float64)
    with torch.no_grad():
        joints = layer(zeros, torch.zeros(k + 1, 45, dtype=torch.float64), betas).joints.numpy()
    base = joints[0]
    return base, np.moveaxis(joints[1:] - base, 0, -1)


def fit_betas(target_lengths: np.ndarray, model: HandModel, *, ridge: float = DEFAULT_RIDGE,
              iterations: int = 30, tol: float = 1e-12) -> BetaFit:
    """Betas whose rest-pose bone lengths match ``target_lengths`` (20,) metres.

    Gauss-Newton on sum_k (|d_k + D_k b| - L_k)^2 + ridge |b|^2, started from b = 0 (the mean
    shape); stops when the step's squared norm falls under ``tol``.
    """
    target = np.asarray(target_lengths, dtype=np.float64)
    if target.shape != (NUM_BONES,) or not np.isfinite(target).all():
        raise ValueError(f"target_lengths must be {NUM_BONES} finite lengths, got {target.shape}")
    base, basis = rest_joint_map(model)
    d = base[_BONES[:, 0]] - base[_BONES[:, 1]]  # (20, 3)
    D = basis[_BONES[:, 0]] - basis[_BONES[:, 1]]  # (20, 3, K)
    betas = np.zeros(basis.shape[-1])
    steps = 0
    while steps < iterations:
        steps += 1
        vec = d + D @ betas
        length = np.linalg.norm(vec, axis=1)
        jac = np.einsum("kc,kcb->kb", vec / length[:, None], D)
        lhs = jac.T @ jac + ridge * np.eye(len(betas))
        rhs = jac.T @ (target - length) - ridge * betas
        step = np.linalg.solve(lhs, rhs)
        betas = betas + step
        if step @ step < tol:
            break
    lengths = np.linalg.norm(d + D @ betas, axis=1)
    return BetaFit(betas=betas, lengths=lengths, residual_mm=(lengths - target) * 1000.0,
                  iterations=steps)


@dataclass
class ShapeCheck:
    """A hand shape (betas) checked against the labels' triangulated bones.

    fit: the betas the labels call for. bone_diff_mm: (20,) the checked shape's rest-pose bone
    lengths minus the labels' median bone lengths. frames: frames with every joint triangulated.
    """

    fit: BetaFit
    bone_diff_mm: np.ndarray
    frames: int

    @property
    def median_diff_mm(self) -> float:
        return float(np.median(np.abs(self.bone_diff_mm)))

    @property
    def max_diff_mm(self) -> float:
        return float(np.abs(self.bone_diff_mm).max())

    def fault(self, limit_mm: float = SHAPE_BONE_MM) -> str | None:
        """One sentence when the checked shape is off, else None."""
        if self.median_diff_mm <= limit_mm:
            return None
        longer = int((self.bone_diff_mm > 0).sum())
        return (f"hand shape off: its bones differ from the labelled ones by "
                f"{self.median_diff_mm:.1f} mm (median of 20), up to {self.max_diff_mm:.1f} mm; "
                f"{longer} of 20 are longer")


def triangulate_joints(cameras: list[CameraModel], keypoints: np.ndarray,
                       visible: np.ndarray, outlier_px: float = OUTLIER_PX) -> np.ndarray:
    """Joints (F, 21, 3) world metres from labels (V, F, 21, 2) px and (V, F, 21) bool; NaN
    where fewer than two views saw a joint. Occluded labels are guesses and are left out."""
    keypoints, visible = np.asarray(keypoints, float), np.asarray(visible, bool)
    views, frames = keypoints.shape[:2]
    pixels = np.where(visible[..., None], keypoints, np.nan)
    pixels = pixels.transpose(1, 2, 0, 3).reshape(frames * NUM_JOINTS, views, 2)
    seen = np.isfinite(pixels).all(axis=-1).sum(axis=1) >= 2
    points = np.full((frames * NUM_JOINTS, 3), np.nan)
    if seen.any():
        points[seen] = triangulate_points(cameras, pixels[seen], outlier_px=outlier_px).points
    return points.reshape(frames, NUM_JOINTS, 3)


def check_shape(joints: np.ndarray, betas: np.ndarray, model: HandModel,
                min_frames: int = 3) -> ShapeCheck:
    """``betas`` (K,) against triangulated joints (F, 21, 3) metres: the bone-length difference
    and the betas that fit the labels. Raises ValueError when a bone is seen in fewer than
    ``min_frames`` frames."""
    target = median_bone_lengths(joints, min_frames=min_frames)
    base, basis = rest_joint_map(model)
    current = bone_lengths(base + basis @ np.asarray(betas, dtype=np.float64))
    frames = int(np.isfinite(np.asarray(joints)).all(axis=(1, 2)).sum())
    return ShapeCheck(fit=fit_betas(target, model, ridge=LABELLED_RIDGE),
                      bone_diff_mm=(current - target) * 1000.0, frames=frames)
