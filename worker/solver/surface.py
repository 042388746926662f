"""What the depth images say about an object pose: its surface seen where it should be, or seen
through.

Points sampled on the mesh's faces (area-weighted, fixed seed) are posed, projected into every
view that has depth, and compared with the depth measured at their pixel (nearest pixel, camera
z, metres):
  agree    |measured - expected| <= AGREE_M: the surface is there;
  through  measured > expected + AGREE_M: the camera sees past where the surface should be, so
           the object is not there (a free-space violation);
  occluded measured < expected - AGREE_M, or no depth (0): something in front (the hand,
           another object) or nothing measured; evidence neither way.
Only samples whose normal faces the camera (cosine > FACING_COS) count: grazing ones fall off
the silhouette with a pixel of error. World frame, metres; pixels x right, y down.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel

# A D415 at 0.5-1 m measures to ~1-2 mm; 1 cm leaves room for a pose a few mm off and a pixel
# of rounding, while a lifted object (centimetres) or a missing one (the table far behind) is
# well beyond it.
AGREE_M = 0.01
FACING_COS = 0.3
SAMPLES = 300
# A view supports a pose when at least this many samples agree and most seen ones agree.
SUPPORT_SAMPLES = 8


@dataclass
class SurfaceSamples:
    """points (N, 3) on the mesh's faces, object frame metres; normals (N, 3) unit, outward as
    the faces wind."""

    points: np.ndarray
    normals: np.ndarray


def surface_samples(vertices: np.ndarray, faces: np.ndarray, count: int = SAMPLES,
                    seed: int = 0) -> SurfaceSamples:
    """`count` area-weighted random points on the faces (M, 3) of vertices (N, 3)."""
    tri = np.asarray(vertices, np.float64)[np.asarray(faces, np.int64)]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1)
    if area.sum() <= 0:
        return SurfaceSamples(np.zeros((0, 3)), np.zeros((0, 3)))
    rng = np.random.default_rng(seed)
    face = rng.choice(len(tri), count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[face]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    normals = cross[face] / np.maximum(area[face], 1e-18)[:, None]
    return SurfaceSamples(points, normals)


@dataclass
class DepthSupport:
    """Per frame and view: agree (F, V) and through (F, V) sample counts (views without depth
    count 0)."""

    agree: np.ndarray
    through: np.ndarray

    def support_views(self) -> np.ndarray:
        """(F,) views whose depth confirms the surface (SUPPORT_SAMPLES agree, most agree)."""
        ok = (self.agree >= SUPPORT_SAMPLES) & (self.agree > self.through)
        return ok.sum(axis=1)

    def through_fraction(self) -> np.ndarray:
        """(F,) share of the seen samples the cameras see through (0 where none is seen)."""
        agree, through = self.agree.sum(axis=1), self.through.sum(axis=1)
        return np.where(agree + through > 0, through / np.maximum(agree + through, 1), 0.0)


def depth_support(cameras: list[CameraModel], depth: list[np.ndarray | None],
                  samples: SurfaceSamples, poses: np.ndarray, frames: np.ndarray) -> DepthSupport:
    """Agree / see-through counts of the samples posed at poses (B, 3, 4) object-to-world in
    frames (B,) of the depth maps (per view (F, H, W) uint16 mm, or None)."""
    batch, views = len(frames), len(cameras)
    agree = np.zeros((batch, views), np.int64)
    through = np.zeros((batch, views), np.int64)
    if not len(samples.points) or not batch:
        return DepthSupport(agree, through)
    rot, trans = poses[:, :, :3], poses[:, :, 3]
    world = np.einsum("bij,nj->bni", rot, samples.points) + trans[:, None]
    normals = np.einsum("bij,nj->bni", rot, samples.normals)
    for v, (camera, images) in enumerate(zip(cameras, depth, strict=True)):
        if images is None:
            continue
        centre = camera.T_cam_to_world[:, 3]
        sight = centre - world
        cos = (normals * sight).sum(-1) / np.maximum(np.linalg.norm(sight, axis=-1), 1e-12)
        expected = camera.depth_of(world)
        px = np.round(camera.project(world)).astype(np.int64)
        inside = ((cos > FACING_COS) & (expected > 0) & (px[..., 0] >= 0)
                  & (px[..., 0] < camera.width) & (px[..., 1] >= 0) & (px[..., 1] < camera.height))
        b, n = np.nonzero(inside)
        measured = np.asarray(images[frames[b], px[b, n, 1], px[b, n, 0]], np.float64) * 1e-3
        gap = measured - expected[b, n]
        seen = measured > 0
        np.add.at(agree[:, v], b[seen & (np.abs(gap) <= AGREE_M)], 1)
        np.add.at(through[:, v], b[seen & (gap > AGREE_M)], 1)
    return DepthSupport(agree, through)
