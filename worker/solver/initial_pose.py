"""An object's pose at the first frame from that frame's depth and the object's landmarks, when
none is given, checked so that a person is asked for one only where the fit fails.

The landmarks labelled visible at frame 0 that have depth under them are back-projected to world
points on the object's surface: their median places the object. The merged depth of all views
around it, less the supporting plane (the table: the plane most points in a wider crop lie on),
is the object's visible surface. Trimmed point-to-surface ICP is started from 24 rotations
(the cube's rotation group) at that place; the result that explains the most points, less the
share of its surface the cameras see through, wins, unless another pose does as well (a
symmetric shape: then the pose is left to a person); a pose that sinks into the table loses
what sinks. The fit is accepted when most of those points lie on the posed surface, the cameras
do not see through it, and the landmarks' points lie on it too. World frame, metres; pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel, pixels_to_rays
from worker.solver.depth import DepthClouds
from worker.solver.init import kabsch
from worker.solver.mesh_query import AABBTree
from worker.solver.surface import depth_support, surface_samples
from worker.solver.types import Landmark

ICP_ITERATIONS = 30
TRIM_M = (0.05, 0.02, 0.01)
MAX_POINTS = 800
PLANE_M = 0.004  # a depth point this close to the supporting plane belongs to it
FIT_M = 0.005  # a point this close to the posed surface is explained by it
MIN_POINTS = 40
MIN_EXPLAINED = 0.6
MAX_THROUGH = 0.1
SEED_M = 0.01  # landmark points' median distance from the posed surface
MIN_SEEDS = 3
AMBIGUOUS = 0.03  # another pose explaining this close a share of the points is as good


@dataclass
class InitialFit:
    """pose (3, 4) object-to-world at frame 0 or None; reason: why there is none (or "")."""

    pose: np.ndarray | None
    reason: str = ""


def cube_rotations() -> np.ndarray:
    """(24, 3, 3) the rotations of the cube: signed axis permutations with determinant +1."""
    out = []
    for perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        for signs in np.ndindex(2, 2, 2):
            rot = np.zeros((3, 3))
            rot[np.arange(3), perm] = [1 - 2 * s for s in signs]
            if np.linalg.det(rot) > 0:
                out.append(rot)
    return np.stack(out)


def landmark_points(cameras: list[CameraModel], depth: list[np.ndarray | None],
                    landmarks: list[Landmark]) -> np.ndarray:
    """(K, 3) world points under the landmarks labelled visible at frame 0, from depth."""
    points = []
    for mark in landmarks:
        images = depth[mark.view]
        xy = np.asarray(mark.xy[0], np.float64)
        if images is None or not mark.visible[0] or not np.isfinite(xy).all():
            continue
        camera = cameras[mark.view]
        x, y = round(float(xy[0])), round(float(xy[1]))
        if not (0 <= x < camera.width and 0 <= y < camera.height) or images[0, y, x] == 0:
            continue
        ray = pixels_to_rays(xy[None], camera.K, camera.dist)[0]
        cam = ray * float(images[0, y, x]) * 1e-3
        points.append(camera.T_cam_to_world[:, :3] @ cam + camera.T_cam_to_world[:, 3])
    return np.array(points).reshape(-1, 3)


def _without_plane(points: np.ndarray, rng: np.random.Generator
                   ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """points (N, 3) less those on the plane most of them lie on (RANSAC, 200 tries), and that
    plane (a point on it, unit normal) or None."""
    if len(points) < 3:
        return points, None
    best = np.zeros(len(points), bool)
    plane = None
    for _ in range(200):
        a, b, c = points[rng.choice(len(points), 3, replace=False)]
        normal = np.cross(b - a, c - a)
        if np.linalg.norm(normal) < 1e-9:
            continue
        on = np.abs((points - a) @ (normal / np.linalg.norm(normal))) < PLANE_M
        if on.sum() > best.sum():
            best, plane = on, (a, normal / np.linalg.norm(normal))
    return points[~best], plane


def _sunk(cameras: list[CameraModel], plane: tuple[np.ndarray, np.ndarray] | None,
          samples: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(K,) share of the surface samples (N, 3) posed by poses (K, 3, 4) that lie more than
    PLANE_M beyond the supporting plane, on the side away from the cameras (0 without one)."""
    if plane is None:
        return np.zeros(len(poses))
    point, normal = plane
    eyes = np.mean([c.T_cam_to_world[:, 3] for c in cameras], axis=0)
    normal = normal if (eyes - point) @ normal > 0 else -normal
    world = np.einsum("kij,nj->kni", poses[:, :, :3], samples) + poses[:, None, :, 3]
    return np.asarray(((world - point) @ normal < -PLANE_M).mean(axis=1))


def _icp(tree: AABBTree, points: np.ndarray, rot: np.ndarray, trans: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray, float]:
    """Trimmed point-to-surface ICP of world points (N, 3) onto the object's surface from
    object-to-world (rot, trans); returns rot, trans and the share of points within FIT_M."""
    for step in range(ICP_ITERATIONS):
        local = (points - trans) @ rot
        dist, face, bary = tree.closest(local)
        near = np.einsum("ni,nij->nj", bary, tree.vertices[tree.faces[face]])
        # Trimmed loosely first (a start centimetres off), then tightly (other surfaces out).
        keep = dist < TRIM_M[min(step * len(TRIM_M) // ICP_ITERATIONS, len(TRIM_M) - 1)]
        if keep.sum() < 3:
            return rot, trans, 0.0
        r, t = kabsch(near[keep][None], points[keep][None], np.ones((1, int(keep.sum()))))
        rot, trans = r[0], t[0]
    dist = tree.closest((points - trans) @ rot)[0]
    return rot, trans, float((dist < FIT_M).mean())


def _object_points(cameras: list[CameraModel], depth: list[np.ndarray | None],
                   centre: np.ndarray, radius: float, rng: np.random.Generator
                   ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
    """World points (N, 3) of the object's visible surface at frame 0: the merged depth of all
    views within 1.5 radii of centre, less the supporting plane found within 3 radii; and that
    plane (see _without_plane)."""
    cloud = DepthClouds(cameras, [None if d is None else d[:1] for d in depth], 2).points(0)
    wide = cloud[np.linalg.norm(cloud - centre, axis=1) < 3 * radius]
    wide, plane = _without_plane(wide, rng)
    return wide[np.linalg.norm(wide - centre, axis=1) < 1.5 * radius], plane


def _rivals(vertices: np.ndarray, poses: np.ndarray, scores: np.ndarray, best: int) -> int:
    """How many poses (K, 3, 4) other than the best score within AMBIGUOUS of it while placing
    the corners of the object's bounding box more than 1 cm (mean) away from the best's."""
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]) \
        * np.ptp(vertices, axis=0) + vertices.min(0)
    posed = np.einsum("kij,nj->kni", poses[:, :, :3], corners) + poses[:, None, :, 3]
    apart = np.linalg.norm(posed - posed[best], axis=-1).mean(-1) > 0.01
    return int((apart & (scores >= scores[best] - AMBIGUOUS)).sum())


def _verdict(pose: np.ndarray, rivals: int, explained: float, through: float,
            off: float) -> InitialFit:
    """The best fit accepted, or None with the first check it fails."""
    if rivals:
        return InitialFit(None, "its shape fits its depth equally well in "
                                f"{rivals + 1} distinct poses")
    if explained < MIN_EXPLAINED:
        return InitialFit(None, f"the best fit explains {explained:.0%} of its depth points "
                                f"(need {MIN_EXPLAINED:.0%})")
    if through > MAX_THROUGH:
        return InitialFit(None, f"the cameras see through {through:.0%} of the fitted surface")
    if off > SEED_M:
        return InitialFit(None, f"its landmarks lie {off * 1000:.0f} mm off the fitted surface")
    return InitialFit(pose)


def fit_initial_pose(cameras: list[CameraModel], depth: list[np.ndarray | None],
                     vertices: np.ndarray, faces: np.ndarray, landmarks: list[Landmark],
                     seed: int = 0) -> InitialFit:
    """The object's pose at frame 0 from depth and landmarks, or None with the reason."""
    if all(d is None for d in depth):
        return InitialFit(None, "there is no depth to fit it to")
    seeds = landmark_points(cameras, depth, landmarks)
    if len(seeds) < MIN_SEEDS:
        return InitialFit(None, f"only {len(seeds)} of its landmarks are labelled visible with "
                                f"depth under them at frame 0 (need {MIN_SEEDS})")
    vertices = np.asarray(vertices, np.float64)
    centre = np.median(seeds, axis=0)
    radius = float(np.linalg.norm(vertices - vertices.mean(0), axis=1).max())
    rng = np.random.default_rng(seed)
    points, plane = _object_points(cameras, depth, centre, radius, rng)
    if len(points) < MIN_POINTS:
        return InitialFit(None, f"only {len(points)} depth points of it at frame 0")
    if len(points) > MAX_POINTS:
        points = points[rng.choice(len(points), MAX_POINTS, replace=False)]
    tree = AABBTree.build(vertices, faces)
    fits = [_icp(tree, points, start, points.mean(0) - start @ vertices.mean(0))
            for start in cube_rotations()]
    poses = np.stack([np.concatenate([r, t[:, None]], axis=1) for r, t, _ in fits])
    support = depth_support(cameras, depth, surface_samples(vertices, faces, seed=seed), poses,
                            np.zeros(len(poses), np.int64))
    # A pose scores the share of the depth points it explains less the share of its own
    # surface the cameras see through: covering the points is not enough, it must not stand
    # where the cameras see past it.
    through_all = support.through_fraction()
    scores = np.array([fit[2] for fit in fits]) - through_all - _sunk(
        cameras, plane, surface_samples(vertices, faces, seed=seed).points, poses)
    best = int(np.argmax(scores))
    pose, explained, through = poses[best], fits[best][2], float(through_all[best])
    # A shape that fits its depth as well in another pose (a box turned over, a can about its
    # axis) leaves the pose to the texture, which depth does not see: a person must say.
    rivals = _rivals(vertices, poses, scores, best)
    off = float(np.median(tree.closest((seeds - pose[:, 3]) @ pose[:, :3])[0]))
    return _verdict(pose, rivals, explained, through, off)
