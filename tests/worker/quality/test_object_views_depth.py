"""worker.quality.object_views: what the depth camera may hide.

The scene: a 10 cm box 0.6 m in front of a camera a little above it. The depth maps are what
the true camera reads (every asked pixel's ray cast against the box and an optional ball, a
hand's stand-in); the camera model the check works with is the true one, or the true one
moved 8 mm up (a calibration a little off). A landmark just under the box's top front edge
is then, through the model, a point on the top face behind it.
"""

from __future__ import annotations

import numpy as np

from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at, pixels_to_rays
from worker.quality.object_views import point_visibility, ray_hits
from worker.quality.solved_scene import SolvedObjects

FRAMES, WIDTH, HEIGHT, HALF = 3, 640, 480, 0.05
EYE = np.array([0.0, -0.6, 0.08])


def _box() -> SolvedObjects:
    v = np.array([[x, y, z] for x in (-HALF, HALF) for y in (-HALF, HALF) for z in (-HALF, HALF)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    poses = np.broadcast_to(np.hstack([np.eye(3), np.zeros((3, 1))]), (1, FRAMES, 3, 4)).copy()
    return SolvedObjects([v], [faces], poses)


def _camera(up_m: float = 0.0) -> CameraModel:
    """The camera looking at the box, moved ``up_m`` straight up (turned no further)."""
    pose = look_at(EYE, np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    pose[:, 3] += [0.0, 0.0, up_m]
    return CameraModel(intrinsics_matrix(615.0, 615.0, 320.0, 240.0), None, pose, WIDTH,
                       HEIGHT)


class RayDepth:
    """(F, H, W) uint16 mm depth maps of the scene (and a ball: centre, radius) as ``camera``
    reads them, each asked pixel ray cast on demand."""

    def __init__(self, camera: CameraModel, scene: SolvedObjects,
                 ball: tuple[np.ndarray, float] | None = None) -> None:
        self.camera, self.scene, self.ball = camera, scene, ball
        self.shape = (FRAMES, HEIGHT, WIDTH)

    def __getitem__(self, index: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        frames, rows, cols = (np.asarray(i) for i in index)
        pix = np.stack([cols.ravel(), rows.ravel()], axis=1).astype(np.float64)
        dirs = pixels_to_rays(pix, self.camera.K, None) @ self.camera.T_cam_to_world[:, :3].T
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        origin = self.camera.T_cam_to_world[:, 3]
        dist, _ = ray_hits(origin, dirs, self.scene.triangles(0, 0))
        if self.ball is not None:
            centre, radius = self.ball
            along = dirs @ (centre - origin)
            miss = np.linalg.norm(origin + along[:, None] * dirs - centre, axis=1)
            inside = miss < radius
            near = along - np.sqrt(np.maximum(radius ** 2 - miss ** 2, 0.0))
            dist = np.where(inside & (near < dist), near, dist)
        z = self.camera.depth_of(origin + dist[:, None] * dirs)
        return np.where(np.isfinite(z), np.rint(z * 1000.0), 0).astype(np.uint16).reshape(
            frames.shape)


# Just under the top front edge, on the face towards the camera.
LANDMARK = np.array([0.01, -HALF, HALF - 0.003])


def _through(model: CameraModel, truth: CameraModel, scene: SolvedObjects) -> np.ndarray:
    """(F, 3) where the model's ray through the landmark's true pixel meets the box."""
    dirs = pixels_to_rays(truth.project(LANDMARK)[None], model.K, None) \
        @ model.T_cam_to_world[:, :3].T
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dist, _ = ray_hits(model.T_cam_to_world[:, 3], dirs, scene.triangles(0, 0))
    return np.repeat(model.T_cam_to_world[:, 3] + dist[0] * dirs, FRAMES, axis=0)


def test_a_camera_a_little_off_does_not_hide_the_point_behind_its_own_object():
    scene, truth = _box(), _camera()
    model = _camera(0.008)
    world = _through(model, truth, scene)
    # Through the model the click is on the top face, well behind the face the camera sees.
    assert world[0, 2] > HALF - 1e-6 and world[0, 1] > -HALF + 0.02
    assert model.depth_of(world[0]) - truth.depth_of(LANDMARK) > 0.02
    shown, edge = point_visibility(model, world, scene, RayDepth(truth, scene))
    # What reads nearer is the box itself: its meshes judge that, and the frames stay
    # undecided instead of hidden.
    assert shown.all() and edge.all()


def test_a_hand_over_the_point_still_hides_it():
    scene, truth = _box(), _camera()
    world = np.repeat(LANDMARK[None], FRAMES, axis=0)
    shown, edge = point_visibility(truth, world, scene, RayDepth(truth, scene))
    assert shown.all() and not edge.any()
    # A 2 cm ball 1 cm in front of the face, right over the landmark.
    ball = (LANDMARK + [0.0, -0.03, 0.0], 0.02)
    shown, edge = point_visibility(truth, world, scene, RayDepth(truth, scene, ball))
    assert not shown.any()
    # The same ball seen through the camera a little off still hides it.
    model = _camera(0.008)
    shown, _ = point_visibility(model, world, scene, RayDepth(truth, scene, ball))
    assert not shown.any()
