"""Hand accuracy of the default solve against the ground truth on a small, smooth clip.

A hand closes its fingers into a grasp over FRAMES frames (the second half of the clip holds
PCA pose coefficients about as large as a real grasp's), seen by 8 cameras with noisy keypoint
labels. The clip is short so the test runs in seconds; the solve is the product's, with its
default settings, and the checks are against the clip's ground-truth joints.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.solver.test_solver_scene import cameras, hand_truth
from worker.solver import HandTarget, SolveInputs, SolveSettings, solve
from worker.solver.default import neighbour_mean

pytestmark = pytest.mark.usefixtures("one_torch_thread")

FRAMES = 16
BETAS = np.linspace(-0.5, 0.5, 10)
NOISE_PX = 0.5  # at 150 px focal length and 0.6 m, about 2 mm: a 3 px label on a D415
# The fingertips, DexYCB order.
TIPS = [4, 8, 12, 16, 20]


def _grasp_clip(seed: int) -> np.ndarray:
    """(FRAMES, 51) pose_m: the hand moves steadily while its fingers close from the mean pose
    to a grasp (minimum-jerk timing over the first 10 frames), then holds it."""
    rng = np.random.default_rng(seed)
    grasp = np.zeros(45)
    grasp[:10] = rng.normal(0.0, 0.45, 10)
    grasp *= 1.0 / np.linalg.norm(grasp)  # a tight grasp: norm 1 rad
    s = np.clip(np.arange(FRAMES) / 10.0, 0.0, 1.0)
    closing = 10 * s**3 - 15 * s**4 + 6 * s**5
    pose = np.zeros((FRAMES, 51))
    pose[:, :3] = np.array([0.3, -1.2, 0.4])
    pose[:, 3:48] = closing[:, None] * grasp
    pose[:, 48:] = np.array([-0.08, 0.0, 0.02]) + np.outer(np.arange(FRAMES), [0.002, 0.001, 0])
    return pose


def _solve_clip(seed: int, settings: SolveSettings, noise_px: float = NOISE_PX
                ) -> tuple[np.ndarray, np.ndarray]:
    """Solved and true joints (FRAMES, 21, 3), metres, of the grasp clip with label noise."""
    rng = np.random.default_rng(seed)
    cams = cameras(8, dist=False)
    joints, _ = hand_truth(_grasp_clip(seed), BETAS)
    keypoints = np.stack([c.project(joints) for c in cams])
    keypoints += rng.normal(0.0, noise_px, keypoints.shape)
    visible = np.ones((len(cams), FRAMES, 21), bool)
    inputs = SolveInputs(cams, FRAMES, HandTarget("right", BETAS, keypoints, visible), [],
                         [None] * len(cams))
    return solve(inputs, settings).hand_joints, joints


class TestGraspAccuracy:
    @pytest.mark.parametrize("seed", [3, 4])
    def test_grasping_fingertips_are_not_pulled_towards_the_mean_pose(self, seed):
        solved, truth = _solve_clip(seed, SolveSettings())
        error = np.linalg.norm(solved - truth, axis=-1) * 1000.0  # (F, 21) mm
        held = slice(10, FRAMES)
        # The solve as it was (w_reg 10, no pose smoothness): 3.5-3.7 mm, tips 8.3-8.6 mm.
        assert error.mean() < 1.5
        assert error[held][:, TIPS].mean() < 2.5

    def test_noiseless_labels_give_the_true_grasp(self):
        solved, truth = _solve_clip(5, SolveSettings(), noise_px=0.0)
        error = np.linalg.norm(solved - truth, axis=-1) * 1000.0
        # A floor of the prior, not of the labels: 2.3 mm with w_reg 10 and no pose smoothness.
        assert error.mean() < 0.6


class TestNeighbourMean:
    def test_inner_frames_get_their_neighbours_mean_and_run_ends_none(self):
        values = np.arange(6, dtype=float)[:, None] ** 2
        frames = np.array([0, 1, 2, 4, 5, 6])
        target, inner = neighbour_mean(values, frames)
        assert inner.tolist() == [0.0, 1.0, 0.0, 0.0, 1.0, 0.0]
        assert target[:, 0].tolist() == [0.0, 2.0, 4.0, 9.0, 17.0, 25.0]


class TestFrameFittedAlone:
    """A frame fitted on its own (worker.solver.follow: one view's depth, frame by frame),
    where only the wrist, thumb and index finger are keyed: the other fingers are what the
    view cannot see."""

    KEYED = slice(0, 9)

    def _fit(self, prior: bool) -> np.ndarray:
        """Fingertip errors (5,) mm of the grasp's last frame, fitted alone from the true pose
        with exact keys on KEYED only, with or without the pull towards the true coefficients
        (as the follow pulls each frame towards the previous one's)."""
        from worker.solver.default import fit_hand
        from worker.solver.problem import Problem
        from worker.solver.state import SolveState

        cams = cameras(1, dist=False)
        truth_pose = _grasp_clip(3)
        joints, _ = hand_truth(truth_pose, BETAS)
        keypoints = np.stack([c.project(joints) for c in cams])
        visible = np.zeros((1, FRAMES, 21), bool)
        visible[0, -1, self.KEYED] = True
        inputs = SolveInputs(cams, FRAMES, HandTarget("right", BETAS, keypoints, visible), [],
                             [None])
        problem = Problem(inputs, SolveSettings(use_depth=False))
        state = SolveState.empty(problem)
        state.hand_frames = np.array([FRAMES - 1])
        state.hand_pose[-1] = truth_pose[-1]
        fit_hand(problem, state, None, 4, 3,
                 (truth_pose[-1:, 3:48], 40.0) if prior else None)
        solved = state.joints(problem)[0]
        return np.linalg.norm(solved[TIPS] - joints[-1, TIPS], axis=-1) * 1000.0

    def test_a_pose_prior_holds_the_fingers_no_key_reaches(self):
        held, loose = self._fit(prior=True), self._fit(prior=False)
        # Held: 0.3-1.2 mm at every fingertip. Without the pull only the weak prior towards
        # the mean (open) hand acts on the ring and little fingers, and they open (12-44 mm
        # at the tips that one view and nine keys leave free).
        assert held.max() < 2.0, held
        assert loose[3:].min() > 5.0 * held[3:].max(), (held, loose)
