from __future__ import annotations

import numpy as np
import pytest
import torch

from worker.hand import HandLayer, builtin_hand_model
from worker.hand.calibrate import (
    NUM_BONES,
    bone_lengths,
    fit_betas,
    median_bone_lengths,
    rest_joint_map,
)


def _posed_joints(model, betas: np.ndarray, frames: int, seed: int) -> np.ndarray:
    """Joints (F, 21, 3) metres of the hand in random poses, orientations and places."""
    rng = np.random.default_rng(seed)
    pose_m = np.concatenate([rng.normal(0, 1.0, (frames, 3)), rng.normal(0, 0.8, (frames, 45)),
                             rng.normal(0, 0.3, (frames, 3))], axis=1)
    layer = HandLayer(model)
    with torch.no_grad():
        out = layer.from_pose_m(torch.as_tensor(pose_m), torch.as_tensor(betas))
    return out.joints.numpy()


@pytest.mark.parametrize("side", ["right", "left"])
def test_fit_recovers_the_bone_lengths_of_known_betas_from_posed_joints(side: str) -> None:
    model = builtin_hand_model(side)
    betas = np.random.default_rng(4).normal(0, 1.0, model.num_betas)
    joints = _posed_joints(model, betas, frames=12, seed=5)
    fit = fit_betas(median_bone_lengths(joints), model)
    base, basis = rest_joint_map(model)
    true_lengths = bone_lengths(base + basis @ betas)
    assert np.abs(fit.lengths - true_lengths).max() < 1e-3  # the 1 mm target
    assert np.abs(fit.residual_mm).max() < 0.1
    # The fitted shape poses into the same hand: joints agree to a millimetre at the same pose.
    refit = _posed_joints(model, fit.betas, frames=12, seed=5)
    assert np.linalg.norm(refit - joints, axis=-1).max() < 2e-3


def test_fit_of_the_mean_shape_stays_at_zero() -> None:
    model = builtin_hand_model("right")
    base, _ = rest_joint_map(model)
    fit = fit_betas(bone_lengths(base), model)
    assert np.abs(fit.betas).max() < 1e-6


def test_bigger_hands_get_longer_bones_and_the_fit_follows() -> None:
    model = builtin_hand_model("right")
    base, _ = rest_joint_map(model)
    target = bone_lengths(base) * 1.08
    fit = fit_betas(target, model)
    assert np.abs(fit.lengths - target).max() < 1e-3
    assert np.abs(fit.betas).max() > 0.1


def test_median_bone_lengths_ignore_missing_joints_and_a_few_wild_frames() -> None:
    model = builtin_hand_model("right")
    joints = _posed_joints(model, np.zeros(model.num_betas), frames=9, seed=1)
    expected = bone_lengths(joints[0])
    joints[2, 8] = np.nan  # index tip missing in one frame
    joints[3, 5] += 0.05  # a badly triangulated index mcp in another
    lengths = median_bone_lengths(joints)
    assert lengths.shape == (NUM_BONES,)
    assert np.abs(lengths - expected).max() < 1e-6


def test_median_bone_lengths_refuse_bones_seen_too_rarely() -> None:
    joints = np.full((5, 21, 3), np.nan)
    joints[:, :4] = np.random.default_rng(0).normal(size=(5, 4, 3))
    with pytest.raises(ValueError, match="fewer than 3 frames"):
        median_bone_lengths(joints)


def test_bad_shapes_are_refused_with_the_shape_named() -> None:
    model = builtin_hand_model("right")
    with pytest.raises(ValueError, match=r"\(\.\.\., 21, 3\), got \(4, 20, 3\)"):
        bone_lengths(np.zeros((4, 20, 3)))
    with pytest.raises(ValueError, match="20 finite lengths"):
        fit_betas(np.ones(19), model)
