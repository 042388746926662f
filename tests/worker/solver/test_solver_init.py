"""worker.solver.init.initial_object_poses (and worker.solver.triangulate.linear_poses) in a
capture's master frame (world = camera 0's
frame, as in DexYCB): frames whose landmarks cannot give a linear pose (none seen, or seen
only by the master camera, whose centre is the origin) keep the previous start, without a
numpy warning, and every other frame gets what it gets alone."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from tests.worker.solver.test_solver_scene import box, cameras, pose
from worker.geometry.cameras import CameraModel
from worker.solver import ObjectTarget, SolveInputs, SolveSettings
from worker.solver.init import initial_object_poses
from worker.solver.problem import MappedLandmarks, Problem
from worker.solver.triangulate import linear_poses

VIEWS = 4
FRAMES = 5
# Two landmarks per view, as object tasks ask: box vertex ids.
LANDMARK_VIEWS = np.repeat(np.arange(VIEWS), 2)
LANDMARK_VERTICES = np.array([0, 9, 14, 23, 28, 37, 42, 51])


@pytest.fixture(autouse=True)
def numpy_warnings_fail() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def _master_frame(cams: list[CameraModel]) -> tuple[list[CameraModel], np.ndarray]:
    """The cameras in camera 0's frame (camera 0: exactly [I | 0]) and the 4x4 map into it."""
    to_master = np.linalg.inv(np.vstack([cams[0].T_cam_to_world, [0.0, 0.0, 0.0, 1.0]]))
    out = [CameraModel(c.K, c.dist, (to_master @ np.vstack([c.T_cam_to_world, [0, 0, 0, 1]]))[:3],
                       c.width, c.height) for c in cams[1:]]
    master = CameraModel(cams[0].K, cams[0].dist, np.hstack([np.eye(3), np.zeros((3, 1))]),
                         cams[0].width, cams[0].height)
    return [master, *out], to_master


def _problem():
    """A box moving over FRAMES frames seen by VIEWS cameras, its true poses (F, 3, 4) in the
    master frame, and its landmarks' pixels (F, L, 2)."""
    cams, to_master = _master_frame(cameras(VIEWS, dist=False))
    model, faces = box()
    truth = []
    for f in range(FRAMES):
        p = np.vstack([pose([0.1, 0.05 * f, -0.2], [0.01 * f, -0.005 * f, 0.0]), [0, 0, 0, 1]])
        truth.append((to_master @ p)[:3])
    truth = np.stack(truth)
    xy = np.stack([[cams[v].project(model[vid] @ truth[f, :, :3].T + truth[f, :, 3])
                    for v, vid in zip(LANDMARK_VIEWS, LANDMARK_VERTICES, strict=True)]
                   for f in range(FRAMES)])
    inputs = SolveInputs(cams, FRAMES, None, [ObjectTarget("box", model, faces, truth[0], [])],
                         [None] * VIEWS)
    return Problem(inputs, SolveSettings(use_depth=False)), truth, xy


def _marks(xy: np.ndarray, seen: np.ndarray) -> MappedLandmarks:
    return MappedLandmarks(LANDMARK_VIEWS, LANDMARK_VERTICES, np.where(seen[..., None], xy,
                                                                       np.nan), seen)


class TestInitialObjectPoses:
    def test_frames_without_a_linear_pose_keep_the_previous_start(self):
        problem, truth, xy = _problem()
        seen = np.ones((FRAMES, len(LANDMARK_VIEWS)), bool)
        seen[1, 2:] = False  # only the master camera's two landmarks
        seen[3] = False  # none
        poses = initial_object_poses(problem, 0, _marks(xy, seen))
        assert np.isfinite(poses).all()
        assert np.array_equal(poses[0], truth[0])
        assert np.array_equal(poses[1], poses[0]) and np.array_equal(poses[3], poses[2])
        for f in (2, 4):  # noise-free landmarks in every view: the linear pose is the truth
            assert np.abs(poses[f] - truth[f]).max() < 1e-6

    def test_a_frame_gets_the_same_start_whatever_the_other_frames_see(self):
        problem, _, xy = _problem()
        seen = np.ones((FRAMES, len(LANDMARK_VIEWS)), bool)
        everything = initial_object_poses(problem, 0, _marks(xy, seen))
        seen[1, 2:] = False
        seen[3] = False
        partial = initial_object_poses(problem, 0, _marks(xy, seen))
        assert np.array_equal(partial[[0, 2, 4]], everything[[0, 2, 4]])

    def test_no_landmark_seen_anywhere_keeps_the_initial_pose_throughout(self):
        problem, truth, xy = _problem()
        poses = initial_object_poses(problem, 0, _marks(xy, np.zeros(xy.shape[:2], bool)))
        assert np.array_equal(poses, np.repeat(truth[:1], FRAMES, axis=0))


class TestLinearPoses:
    """Frames whose linear system has only the zero solution (no landmark seen; landmarks seen
    only by the master camera, whose centre is the origin) have no scale to divide by."""

    def test_a_frame_with_no_landmark_seen_is_not_ok_without_a_warning(self):
        problem, truth, xy = _problem()
        seen = np.ones(xy.shape[:2], bool)
        seen[1] = False
        model = problem.object_vertices[0][LANDMARK_VERTICES]
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            poses, ok = linear_poses(problem.cameras, LANDMARK_VIEWS, model,
                                     np.where(seen[..., None], xy, np.nan), seen)
        assert ok.tolist() == [True, False, True, True, True]
        assert np.isnan(poses[1, :, 3]).all()
        for f in (0, 2, 3, 4):
            assert np.abs(poses[f] - truth[f]).max() < 1e-6

    def test_landmarks_seen_only_by_the_master_camera_are_not_ok_without_a_warning(self):
        problem, truth, _ = _problem()
        model = problem.object_vertices[0][LANDMARK_VERTICES]
        master = problem.cameras[0]
        xy = np.stack([master.project(model @ truth[f, :, :3].T + truth[f, :, 3])
                       for f in range(FRAMES)])  # (F, L, 2), all in view 0
        views = np.zeros(len(model), int)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            poses, ok = linear_poses(problem.cameras, views, model, xy,
                                     np.ones(xy.shape[:2], bool))
        assert not ok.any()
        assert np.isnan(poses[:, :, 3]).all()
