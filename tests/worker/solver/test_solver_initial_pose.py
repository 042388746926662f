"""worker.solver.initial_pose: an object's pose at frame 0 fitted to depth and landmarks, and
the reasons it is refused."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tests.worker.solver.test_solver_scene import box, cameras, pose, render_depth, visible_vertices
from worker.solver import Landmark
from worker.solver.initial_pose import cube_rotations, fit_initial_pose

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TRUE_POSE = pose([0.1, -0.2, 0.9], [0.01, -0.02, 0.03])


def _l_shape() -> tuple[np.ndarray, np.ndarray]:
    """An L of two boxes with a knob on one side: no rotation maps it onto itself."""
    parts = [(box((0.10, 0.06, 0.03))[0], box()[1]),
             (box((0.03, 0.06, 0.07))[0] + [0.035, 0.0, 0.05], box()[1]),
             (box((0.04, 0.03, 0.03))[0] + [-0.02, 0.015, 0.03], box()[1])]
    offsets = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
    return (np.vstack([v for v, _ in parts]),
            np.vstack([f + o for (_, f), o in zip(parts, offsets, strict=True)]))


def _scene(model: np.ndarray, faces: np.ndarray):
    """4 cameras (640x480) over the object on a table; its landmarks at frame 0."""
    # The helper's 160x120 cameras at 4x the resolution.
    cams = [dataclasses.replace(c, K=c.K * np.array([[4.0], [4.0], [1.0]]), width=640,
                                height=480) for c in cameras(4, dist=False)]
    world = model @ TRUE_POSE[:, :3].T + TRUE_POSE[:, 3]
    table, table_faces = box((0.6, 0.6, 0.02))
    table = table + [0.0, 0.0, world[:, 2].min() - 0.01]
    depth = [render_depth(c, [(world, faces), (table, table_faces)])[None] for c in cams]
    marks = []
    for v, cam in enumerate(cams):
        seen = visible_vertices(cam, world, faces)
        marks.extend(Landmark(v, cam.project(world[vid])[None], np.ones(1, bool))
                     for vid in seen[:: max(len(seen) // 3, 1)][:3])
    return cams, depth, marks


class TestFitInitialPose:
    def test_the_cube_group_has_24_proper_rotations(self):
        rots = cube_rotations()
        assert rots.shape == (24, 3, 3)
        assert np.allclose(np.linalg.det(rots), 1.0)
        assert len({r.tobytes() for r in rots}) == 24

    def test_an_asymmetric_object_is_fitted_to_within_millimetres(self):
        model, faces = _l_shape()
        cams, depth, marks = _scene(model, faces)
        fit = fit_initial_pose(cams, depth, model, faces, marks)
        assert fit.pose is not None, fit.reason
        error = np.linalg.norm((model @ fit.pose[:, :3].T + fit.pose[:, 3])
                               - (model @ TRUE_POSE[:, :3].T + TRUE_POSE[:, 3]), axis=1)
        assert error.mean() < 0.003

    def test_a_box_fits_in_several_poses_and_is_refused_saying_so(self):
        model, faces = box()
        cams, depth, marks = _scene(model, faces)
        fit = fit_initial_pose(cams, depth, model, faces, marks)
        assert fit.pose is None and "fits its depth equally well in" in fit.reason

    def test_without_depth_or_landmarks_the_reason_says_which(self):
        model, faces = _l_shape()
        cams, depth, marks = _scene(model, faces)
        assert fit_initial_pose(cams, [None] * 4, model, faces, marks).reason == \
            "there is no depth to fit it to"
        reason = fit_initial_pose(cams, depth, model, faces, marks[:2]).reason
        assert reason.startswith("only 2 of its landmarks are labelled visible")
