"""End to end: `solve` on small synthetic scenes with known answers, and its input checks."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tests.worker.solver.test_solver_scene import (
    box,
    cameras,
    hand_pose_m,
    hand_truth,
    pose,
    render_depth,
    visible_vertices,
)
from worker.geometry.transforms import matrix_to_axis_angle
from worker.hand import builtin_hand_model
from worker.solver import (
    HandTarget,
    Landmark,
    ObjectTarget,
    SolveInputs,
    SolveSettings,
    hand_vertices,
    solve,
)

pytestmark = pytest.mark.usefixtures("one_torch_thread")

FRAMES = 3
BETAS = np.linspace(-0.5, 0.5, 10)
BOX_POSE = pose([0.2, 0.1, -0.3], [0.09, 0.06, -0.02])


def _rotation_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(matrix_to_axis_angle(a[:, :3] @ b[:, :3].T))))


def _scene(noise_px: float, with_depth: bool, seed: int = 0):
    """Inputs for a hand and a box seen by 4 cameras over FRAMES frames, and the truth."""
    rng = np.random.default_rng(seed)
    cams = cameras(4, dist=not with_depth)
    truth_pose = hand_pose_m(seed, FRAMES)
    joints, verts = hand_truth(truth_pose, BETAS)
    keypoints = np.stack([c.project(joints) for c in cams]) + rng.normal(0, noise_px,
                                                                        (4, FRAMES, 21, 2))
    visible = np.ones((4, FRAMES, 21), bool)
    model, faces = box()
    world_box = model @ BOX_POSE[:, :3].T + BOX_POSE[:, 3]
    marks = []
    hand_mesh = (verts[0], builtin_hand_model("right").faces)
    for v, cam in enumerate(cams):
        seen = visible_vertices(cam, world_box, faces, [hand_mesh])
        for vid in (seen[0], seen[len(seen) // 2]):
            xy = np.repeat(cam.project(world_box[vid])[None], FRAMES, 0)
            marks.append(Landmark(v, xy + rng.normal(0, noise_px, xy.shape), np.ones(FRAMES, bool)))
    depth = [None] * 4
    if with_depth:
        hand_faces = builtin_hand_model("right").faces
        depth = [np.stack([render_depth(c, [(verts[f], hand_faces), (world_box, faces)])
                           for f in range(FRAMES)]) for c in cams]
    inputs = SolveInputs(cams, FRAMES, HandTarget("right", BETAS, keypoints, visible),
                         [ObjectTarget("box", model, faces, BOX_POSE.copy(), marks)], depth)
    return inputs, joints, verts


class TestEndToEnd:
    def test_default_recovers_hand_and_box_with_depth(self):
        inputs, joints, verts = _scene(0.5, with_depth=True)
        # The scene's frames are independent random poses, not a motion: no pose smoothness.
        result = solve(inputs, SolveSettings(depth_stride=2, w_smooth_pose=0.0))
        assert result.labelled.all()
        mpjpe = np.linalg.norm(result.hand_joints - joints, axis=-1).mean() * 1000.0
        assert mpjpe < 3.0
        assert result.hand_pose_m.shape == (FRAMES, 51)
        box_err = np.linalg.norm(result.object_poses[0, :, :, 3] - BOX_POSE[:, 3], axis=-1)
        assert box_err.max() < 0.003
        assert max(_rotation_deg(p, BOX_POSE) for p in result.object_poses[0]) < 2.0
        assert np.isfinite(result.kpt_error_px).all() and result.kpt_error_px.mean() < 2.0
        assert np.nanmax(result.depth_rms_mm) < 5.0
        assert all(v >= 0 for v in result.landmark_vertices[0])
        assert np.abs(hand_vertices(result, inputs, 1) - verts[1]).max() < 0.01
        summary = result.to_summary()
        assert summary["labelled_frames"] == FRAMES and "total" in summary["timings"]

    def test_paper_optimiser_tracks_the_hand_from_keypoints(self):
        inputs, joints, _ = _scene(0.5, with_depth=False)
        result = solve(inputs, SolveSettings(optimiser="paper"))
        mpjpe = np.linalg.norm(result.hand_joints - joints, axis=-1).mean() * 1000.0
        assert mpjpe < 8.0
        box_err = np.linalg.norm(result.object_poses[0, :, :, 3] - BOX_POSE[:, 3], axis=-1)
        assert box_err.max() < 0.01

    def test_frame_with_too_few_labelled_views_is_left_unlabelled_with_a_reason(self):
        inputs, _, _ = _scene(0.5, with_depth=False)
        inputs.hand.visible[1:, 2] = False  # frame 2: every joint seen in one view only
        result = solve(inputs, SolveSettings(use_depth=False))
        assert result.labelled.tolist() == [True, True, False]
        assert result.reasons[2] is not None and "2 views" in result.reasons[2]
        assert np.isnan(result.hand_pose_m[2]).all() and np.isfinite(result.hand_pose_m[:2]).all()


class TestDepthTerm:
    def _inputs(self, start: np.ndarray):
        cams = cameras(4, dist=False)
        model, faces = box()
        world = model @ BOX_POSE[:, :3].T + BOX_POSE[:, 3]
        depth = [render_depth(c, [(world, faces)])[None] for c in cams]
        return SolveInputs(cams, 1, None, [ObjectTarget("box", model, faces, start, [])], depth)

    def test_depth_alone_moves_a_perturbed_object_back_to_its_true_pose(self):
        turn = pose([0.0, 0.05, 0.04], [0.006, -0.005, 0.004])
        start = np.hstack([turn[:, :3] @ BOX_POSE[:, :3], (BOX_POSE[:, 3] + turn[:, 3])[:, None]])
        inputs = self._inputs(start)
        before = np.linalg.norm(start[:, 3] - BOX_POSE[:, 3])
        result = solve(inputs, SolveSettings(depth_stride=1, icp_rounds=4))
        solved = result.object_poses[0, 0]
        assert before > 0.008 and _rotation_deg(start, BOX_POSE) > 3.0
        assert np.linalg.norm(solved[:, 3] - BOX_POSE[:, 3]) < 0.001
        assert _rotation_deg(solved, BOX_POSE) < 0.5
        assert result.depth_rms_mm[0] < 1.0


class TestInputChecks:
    def test_object_without_initial_pose_or_depth_to_fit_one_is_refused(self):
        inputs, _, _ = _scene(0.5, with_depth=False)
        inputs.objects[0].initial_pose = None
        with pytest.raises(ValueError, match=r"objects\[0\] \(box\) has no initial pose and "
                           "none could be fitted to frame 0: there is no depth to fit it to"):
            solve(inputs)

    def test_wrong_keypoint_shape_names_the_actual_shape(self):
        inputs, _, _ = _scene(0.5, with_depth=False)
        inputs.hand.keypoints = inputs.hand.keypoints[:, :, :20]
        with pytest.raises(ValueError, match=r"hand.keypoints must have shape \(4, 3, 21, 2\), "
                                             r"got \(4, 3, 20, 2\)"):
            solve(inputs)

    def test_unknown_optimiser_and_missing_cuda_are_refused(self):
        inputs, _, _ = _scene(0.5, with_depth=False)
        with pytest.raises(ValueError, match="optimiser"):
            solve(inputs, SolveSettings(optimiser="sgd"))  # type: ignore[arg-type]
        if not torch.cuda.is_available():
            with pytest.raises(RuntimeError, match="CUDA"):
                solve(inputs, SolveSettings(device="cuda"))
