"""Small synthetic scenes shared by the solver tests (cameras, a box, a posed hand, rendered
depth), and a check that the scenes themselves are what the other tests assume."""

from __future__ import annotations

import numpy as np
import torch

from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.geometry.raster import rasterize
from worker.geometry.transforms import axis_angle_to_matrix
from worker.hand import HandLayer, builtin_hand_model

WIDTH, HEIGHT = 160, 120


def cameras(count: int = 4, distance: float = 0.6, dist: bool = True) -> list[CameraModel]:
    """`count` cameras on a ring around the origin, looking at it, 160x120 px."""
    out = []
    for i in range(count):
        angle = 2.0 * np.pi * i / count
        eye = distance * np.array([np.cos(angle), np.sin(angle), 0.6])
        coeffs = np.array([0.02, -0.01, 0.001, -0.001, 0.0]) if dist and i % 2 else None
        out.append(CameraModel(intrinsics_matrix(150.0, 150.0, 80.0, 60.0), coeffs,
                               look_at(eye, np.zeros(3), np.array([0.0, 0.0, 1.0])),
                               WIDTH, HEIGHT))
    return out


def box(size=(0.06, 0.04, 0.08), steps: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A closed box mesh centred on its origin, each face split into steps x steps quads."""
    vertices, faces = [], []
    half = np.asarray(size) / 2.0
    grid = np.linspace(-1.0, 1.0, steps + 1)
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, v = [a for a in range(3) if a != axis]
            base = len(vertices)
            for a in grid:
                for b in grid:
                    p = np.zeros(3)
                    p[axis], p[u], p[v] = sign, a, b
                    vertices.append(p * half)
            for i in range(steps):
                for j in range(steps):
                    k = base + i * (steps + 1) + j
                    quad = [k, k + steps + 1, k + steps + 2, k + 1]
                    if sign < 0:
                        quad.reverse()
                    faces += [[quad[0], quad[1], quad[2]], [quad[0], quad[2], quad[3]]]
    vertices = np.array(vertices)
    unique, inverse = np.unique(np.round(vertices, 9), axis=0, return_inverse=True)
    return unique, inverse.reshape(-1)[np.array(faces)]


def pose(axis_angle, translation) -> np.ndarray:
    """(3, 4) pose from an axis-angle (rad) and a translation (m)."""
    return np.hstack([axis_angle_to_matrix(np.asarray(axis_angle, float)),
                      np.asarray(translation, float)[:, None]])


def render_depth(camera: CameraModel, meshes: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """(H, W) uint16 mm depth of world meshes [(vertices, faces)] seen by an undistorted camera."""
    vertices = np.concatenate([v for v, _ in meshes])
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes[:-1]])
    faces = np.concatenate([f + o for (_, f), o in zip(meshes, offsets, strict=True)])
    T = camera.T_cam_to_world
    cam = (vertices - T[:, 3]) @ T[:, :3]
    frag = rasterize(cam, faces, camera.K, camera.width, camera.height)
    return np.round(frag.depth * 1000.0).astype(np.uint16)


def hand_pose_m(seed: int, frames: int) -> np.ndarray:
    """(F, 51) plausible pose_m: small PCA coefficients, hand near the origin."""
    rng = np.random.default_rng(seed)
    pose = np.zeros((frames, 51))
    pose[:, :3] = np.array([0.3, -1.2, 0.4]) + rng.normal(0, 0.1, (frames, 3))
    pose[:, 3:9] = rng.normal(0, 0.5, (frames, 6))
    pose[:, 48:] = np.array([-0.08, 0.0, 0.02]) + rng.normal(0, 0.01, (frames, 3))
    return pose


def hand_truth(pose_m: np.ndarray, betas: np.ndarray):
    """Joints (F, 21, 3) and vertices (F, 778, 3) of the built-in right hand, metres."""
    layer = HandLayer(builtin_hand_model("right"))
    out = layer.from_pose_m(torch.as_tensor(pose_m), torch.as_tensor(betas))
    return out.joints.numpy(), out.vertices.numpy()


def visible_vertices(camera: CameraModel, vertices: np.ndarray, faces: np.ndarray,
                     occluders: list[tuple[np.ndarray, np.ndarray]] = ()) -> list[int]:
    """World-mesh vertices that are the first surface on their own camera ray."""
    from worker.solver.mesh_query import ray_hits

    centre = camera.T_cam_to_world[:, 3]
    out = []
    for vid, vertex in enumerate(vertices):
        direction = vertex - centre
        distance = np.linalg.norm(direction)
        unit = direction / distance
        nearest = min([ray_hits(centre, unit, vertices[faces]).min()] +
                      [ray_hits(centre, unit, v[f]).min() for v, f in occluders])
        if abs(nearest - distance) < 1e-9:
            out.append(vid)
    return out


def test_rendered_depth_is_the_first_surface_along_each_ray():
    from worker.solver.landmarks import camera_ray
    from worker.solver.mesh_query import ray_hits

    camera = cameras(1, dist=False)[0]
    model, faces = box()
    world = model @ pose([0.2, 0.1, 0.0], [0.0, 0.0, 0.0])[:, :3].T
    depth = render_depth(camera, [(world, faces)])
    ys, xs = np.nonzero(depth)
    assert len(ys) > 100
    for y, x in zip(ys[::25], xs[::25], strict=True):
        origin, direction = camera_ray(camera, np.array([x, y], float))
        hit = ray_hits(origin, direction, world[faces]).min()
        z = hit * (direction @ camera.T_cam_to_world[:, 2])
        assert abs(depth[y, x] * 1e-3 - z) < 0.002
