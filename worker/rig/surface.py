"""Extrinsic corrections of views from their depth maps and their labels together.

The hand alone is too small a volume to pin a view's whole pose (a small rotation and a
translation that undoes it look alike in its pixels). The depth maps cover the whole scene
(table, objects, hand), so each free view is re-posed by robust point-to-plane ICP of its own
back-projected depth against the other views' surfaces (each point paired with the surface at
the pixel it projects to in every other view), jointly with the pixel error of its labels
against the other views' triangulated points (as :mod:`worker.rig.extrinsics`) and the same
prior on the move away from the imported pose; the ICP pose is then finished on the depth
differences along the other views' rays, which have no bias at the true pose. A few sweeps
over the free views let them settle together; the fixed views (the master) pin the world
frame.

Depth must already be corrected for its scale and pixel shift (:mod:`worker.rig.depth`):
otherwise a view's scale fault would be taken for a move along its optical axis.

Units: world and camera points in metres, depth residuals in mm, label residuals in px.
Depth maps (H, W) uint16 mm (0 = none), all of one world time per sample frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from worker.geometry.cameras import CameraModel, camera_to_world, pixels_to_rays
from worker.rig.common import leave_one_out_points, reprojection_px
from worker.rig.depth import _bilinear, correct_depth
from worker.rig.extrinsics import (
    CAUCHY_PX,
    INLIER_FACTOR,
    MIN_INLIER_PX,
    PRIOR_M,
    PRIOR_RAD,
    SIGMA_PX,
    posed,
)

# Sample grid (px) of the moving view's points; the other views' maps are used at every pixel.
SOURCE_STEP_PX = 8
# Normals from neighbours this far apart on the depth grid (px); a jump beyond EDGE_JUMP_MM
# between them means an occluding edge, where no normal is taken.
NORMAL_REACH_PX = 2
EDGE_JUMP_MM = 15.0
# Pairs: nearest neighbour within the gate (mm), normals within MIN_NORMAL_COS; the gate
# shrinks to max(MIN_GATE_MM, GATE_FACTOR x the median point-to-plane distance).
START_GATE_MM = 30.0
MIN_GATE_MM = 3.0
GATE_FACTOR = 3.0
MIN_NORMAL_COS = 0.7
MIN_PAIRS = 200
# Depth noise (mm) and the Huber scale of its robust loss.
SIGMA_MM = 2.0
HUBER_MM = 3.0
ICP_ITERATIONS = 25
# The finish: depth differences along the other views' rays, pairs gated at
# max(MIN_RAY_GATE_MM, GATE_FACTOR x their median).
RAY_ITERATIONS = 20
MIN_RAY_GATE_MM = 10.0
SWEEPS = 3


@dataclass(frozen=True)
class Surface:
    """Points (N, 3) and unit normals (N, 3), one frame's; camera or world frame as said."""

    points: np.ndarray
    normals: np.ndarray


def ray_image(camera: CameraModel) -> np.ndarray:
    """(H, W, 3) camera-frame rays (z = 1) of every pixel."""
    q = np.stack(np.meshgrid(np.arange(camera.width), np.arange(camera.height)), axis=-1)
    return pixels_to_rays(q.astype(np.float64), camera.K, camera.dist)


def depth_surface(camera: CameraModel, depth: np.ndarray, step: int,
                  rays: np.ndarray | None = None) -> Surface:
    """Camera-frame points (m) and normals (facing the camera) of one depth map (H, W) mm,
    on a grid of ``step`` px; pixels without depth or next to an occluding edge left out.
    rays: the camera's :func:`ray_image` if already computed."""
    return _sampled(camera, depth, step, rays)[2]


def _sampled(camera: CameraModel, depth: np.ndarray, step: int, rays: np.ndarray | None
             ) -> tuple[np.ndarray, np.ndarray, Surface]:
    """:func:`depth_surface` with the rows (N,) and columns (N,) of its points."""
    if depth.shape != (camera.height, camera.width):
        raise ValueError(f"depth map must have shape ({camera.height}, {camera.width}), "
                         f"got {depth.shape}")
    rays = ray_image(camera) if rays is None else rays
    r = NORMAL_REACH_PX
    xs = np.arange(r, camera.width - r, step)
    ys = np.arange(r, camera.height - r, step)
    gx, gy = np.meshgrid(xs, ys)
    offsets = [(0, 0), (r, 0), (-r, 0), (0, r), (0, -r)]
    z = np.stack([depth[gy + dy, gx + dx] for dx, dy in offsets]).astype(np.float64)
    ok = (z > 0).all(axis=0) & (np.abs(z[1:] - z[0]).max(axis=0) < EDGE_JUMP_MM)
    pts = []
    for (dx, dy), zk in zip(offsets, z, strict=True):
        pts.append(rays[gy[ok] + dy, gx[ok] + dx] * (zk[ok] / 1000.0)[:, None])
    normals = np.cross(pts[1] - pts[2], pts[3] - pts[4])
    length = np.linalg.norm(normals, axis=1)
    good = length > 0
    normals = normals[good] / length[good, None]
    centre = pts[0][good]
    normals *= -np.sign(np.einsum("ij,ij->i", normals, centre))[:, None]
    return gy[ok][good], gx[ok][good], Surface(centre, normals)


@dataclass(frozen=True)
class SurfaceImage:
    """One view's depth map as world points (H, W, 3) m and unit normals (H, W, 3), NaN where
    :func:`depth_surface` takes none, with the camera that sees them and the map (H, W) mm."""

    camera: CameraModel
    points: np.ndarray
    normals: np.ndarray
    depth: np.ndarray


def surface_image(camera: CameraModel, depth: np.ndarray, rays: np.ndarray) -> SurfaceImage:
    """Every pixel's world point and normal of one depth map (H, W) mm; rays: the camera's
    :func:`ray_image`."""
    ys, xs, surf = _sampled(camera, depth, 1, rays)
    points = np.full(depth.shape + (3,), np.nan)
    normals = np.full(depth.shape + (3,), np.nan)
    points[ys, xs] = camera_to_world(surf.points, camera.T_cam_to_world)
    normals[ys, xs] = surf.normals @ camera.T_cam_to_world[:, :3].T
    return SurfaceImage(camera, points, normals, depth)


def params_of(anchor: CameraModel, camera: CameraModel) -> np.ndarray:
    """The params (6,) of :func:`worker.rig.extrinsics.posed` taking ``anchor`` to ``camera``."""
    rel = camera.T_cam_to_world[:, :3].T @ anchor.T_cam_to_world[:, :3]
    rvec = cv2.Rodrigues(rel)[0].ravel()
    return np.concatenate([rvec, camera.T_cam_to_world[:, 3] - anchor.T_cam_to_world[:, 3]])


@dataclass(frozen=True)
class _Terms:
    """One view's data: its own surfaces (camera frame) with the other views' surface images,
    one pair per sample frame; label points (N, 3) m and pixels (N, 2)."""

    own: list[Surface]
    others: list[list[SurfaceImage]]
    points: np.ndarray
    pixels: np.ndarray


def _pairs(camera: CameraModel, terms: _Terms, gate_mm: float
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Matched source points (M, 3) camera frame, target points and normals (M, 3) world.

    Each source point is matched in every other view to the surface at the pixel it projects
    to there (projective association): the pair is where that view's depth puts the point,
    so pairs do not slide along the surfaces from one iteration to the next the way nearest
    neighbours among sparse noisy samples do."""
    src, tgt, nrm = [], [], []
    rot = camera.T_cam_to_world[:, :3]
    for own, others in zip(terms.own, terms.others, strict=True):
        if len(own.points) == 0:
            continue
        world = camera_to_world(own.points, camera.T_cam_to_world)
        facing = own.normals @ rot.T
        for other in others:
            h, w = other.points.shape[:2]
            with np.errstate(invalid="ignore"):
                uv = np.rint(other.camera.project(world))
                inside = (other.camera.depth_of(world) > 0) & (uv[:, 0] >= 0) \
                    & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
            idx = np.flatnonzero(inside)
            x, y = uv[idx, 0].astype(int), uv[idx, 1].astype(int)
            t, n = other.points[y, x], other.normals[y, x]
            with np.errstate(invalid="ignore"):
                hit = (np.linalg.norm(world[idx] - t, axis=1) < gate_mm / 1000.0) \
                    & (np.einsum("ij,ij->i", facing[idx], n) > MIN_NORMAL_COS)
            src.append(own.points[idx[hit]])
            tgt.append(t[hit])
            nrm.append(n[hit])
    if not src:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
    return np.concatenate(src), np.concatenate(tgt), np.concatenate(nrm)


def _residuals(anchor: CameraModel, params: np.ndarray, src: np.ndarray, tgt: np.ndarray,
               nrm: np.ndarray, terms: _Terms) -> tuple[np.ndarray, np.ndarray]:
    """Point-to-plane distances (M,) mm and label errors (2N,) px at ``params``."""
    cam = posed(anchor, params)
    plane = np.einsum("ij,ij->i", camera_to_world(src, cam.T_cam_to_world) - tgt, nrm) * 1000.0
    return plane, (cam.project(terms.points) - terms.pixels).ravel()


def _step(anchor: CameraModel, params: np.ndarray,
          pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
          terms: _Terms) -> np.ndarray:
    """One Gauss-Newton step of the joint robust cost (Huber on depth, Cauchy on labels,
    the Gaussian prior on the move)."""
    plane, pix = _residuals(anchor, params, *pairs, terms)
    res = np.concatenate([plane, pix])
    jac = np.empty((len(res), 6))
    for i in range(6):
        step = np.zeros(6)
        step[i] = 1e-7
        jac[:, i] = (np.concatenate(_residuals(anchor, params + step, *pairs, terms)) - res) / 1e-7
    err = np.hypot(pix[0::2], pix[1::2])
    w_pix = np.repeat(1.0 / (1.0 + (err / CAUCHY_PX) ** 2), 2) / SIGMA_PX ** 2
    w_depth = np.minimum(1.0, HUBER_MM / np.maximum(np.abs(plane), 1e-9)) / SIGMA_MM ** 2
    w = np.concatenate([w_depth, w_pix])
    prior = np.repeat([1.0 / PRIOR_RAD, 1.0 / PRIOR_M], 3) ** 2
    lhs = (jac * w[:, None]).T @ jac + np.diag(prior)
    rhs = (jac * w[:, None]).T @ res + prior * params
    return params + np.linalg.solve(lhs, -rhs)


def _repose(camera: CameraModel, anchor: CameraModel, terms: _Terms) -> CameraModel:
    """``camera`` re-posed by ICP with the labels, as a move of ``anchor`` (imported)."""
    params = params_of(anchor, camera)
    gate = START_GATE_MM
    for _ in range(ICP_ITERATIONS):
        current = posed(anchor, params)
        pairs = _pairs(current, terms, gate)
        if len(pairs[0]) < MIN_PAIRS:
            return camera
        plane, _ = _residuals(anchor, params, *pairs, terms)
        gate = max(MIN_GATE_MM, GATE_FACTOR * float(np.median(np.abs(plane))))
        new = _step(anchor, params, pairs, terms)
        moved = np.abs(new - params).max()
        params = new
        if moved < 1e-7:
            break
    return posed(anchor, _finish(anchor, params, terms))


def _ray_residuals(camera: CameraModel, terms: _Terms) -> np.ndarray:
    """(M,) mm: for every own point and other view, its depth in that view minus the depth
    that view sees where it projects (bilinear); NaN where that view has none."""
    out = []
    for own, others in zip(terms.own, terms.others, strict=True):
        world = camera_to_world(own.points, camera.T_cam_to_world)
        for other in others:
            with np.errstate(invalid="ignore"):
                z = other.camera.depth_of(world) * 1000.0
                seen = _bilinear(other.depth, other.camera.project(world))
            out.append(np.where((seen > 0) & (z > 0), z - seen, np.nan))
    return np.concatenate(out) if out else np.zeros(0)


def _finish(anchor: CameraModel, params: np.ndarray, terms: _Terms) -> np.ndarray:
    """The ICP result refined on depth differences along the other views' rays, with the
    labels and the prior. Point-to-plane pairs leave a bias of a few mm along the scene's
    weakly curved directions (a table plane with a few objects: noisy normals and pairs at
    occluding edges pull the pose along the surfaces); the depth each view sees where the
    point projects has none at the true pose, as :mod:`worker.rig.depth` relies on."""
    gate = START_GATE_MM
    prior = np.repeat([1.0 / PRIOR_RAD, 1.0 / PRIOR_M], 3) ** 2
    for _ in range(RAY_ITERATIONS):
        cam = posed(anchor, params)
        ray = _ray_residuals(cam, terms)
        keep = np.isfinite(ray)
        keep[keep] = np.abs(ray[keep]) < gate
        if keep.sum() < MIN_PAIRS:
            return params
        gate = max(MIN_RAY_GATE_MM, GATE_FACTOR * float(np.median(np.abs(ray[keep]))))
        pix = (cam.project(terms.points) - terms.pixels).ravel()
        res = np.concatenate([ray[keep], pix])
        jac = np.empty((len(res), 6))
        for i in range(6):
            step = np.zeros(6)
            step[i] = 1e-6
            moved = posed(anchor, params + step)
            jac[:, i] = (np.concatenate([_ray_residuals(moved, terms)[keep],
                                         (moved.project(terms.points) - terms.pixels).ravel()])
                         - res) / 1e-6
        usable = np.isfinite(jac).all(axis=1)
        jac[~usable] = 0.0
        err = np.hypot(pix[0::2], pix[1::2])
        w_pix = np.repeat(1.0 / (1.0 + (err / CAUCHY_PX) ** 2), 2) / SIGMA_PX ** 2
        w_ray = np.minimum(1.0, HUBER_MM / np.maximum(np.abs(ray[keep]), 1e-9)) / SIGMA_MM ** 2
        w = np.concatenate([w_ray, w_pix]) * usable
        lhs = (jac * w[:, None]).T @ jac + np.diag(prior)
        rhs = (jac * w[:, None]).T @ np.where(usable, res, 0.0) + prior * params
        delta = np.linalg.solve(lhs, -rhs)
        params = params + delta
        if np.abs(delta).max() < 1e-7:
            break
    return params


def _label_terms(camera: CameraModel, points: np.ndarray, pixels: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Label points (N, 3) m and pixels (N, 2) px kept as inliers under ``camera``."""
    ok = np.isfinite(points).all(axis=1) & np.isfinite(pixels).all(axis=1)
    points, pixels = points[ok], pixels[ok]
    err = reprojection_px(camera, points, pixels)
    inl = np.isfinite(err)
    if inl.any():
        inl &= err < max(MIN_INLIER_PX, INLIER_FACTOR * float(np.median(err[inl])))
    return points[inl], pixels[inl]


def refine_with_depth(cameras: list[CameraModel], anchors: list[CameraModel],
                      free: tuple[int, ...], maps: list[list[np.ndarray | None]],
                      pixels: np.ndarray, sweeps: int = SWEEPS) -> list[CameraModel]:
    """The free views re-posed against the others' depth and points; the rest unchanged.

    Args:
        cameras: V views, the starting poses (e.g. refined from labels alone).
        anchors: V views as imported (the prior's centre).
        free: the views to move (never the master).
        maps: per sample frame, V depth maps (H, W) uint16 mm of one world time, corrected
            for scale and shift (None: a view without depth there).
        pixels: (V, F, P, 2) px labels in world time, NaN where unlabelled.
        sweeps: passes over the free views.
    """
    if len(cameras) != len(anchors) or pixels.ndim != 4 or pixels.shape[0] != len(cameras) \
            or pixels.shape[-1] != 2:
        raise ValueError(f"cameras ({len(cameras)}), anchors ({len(anchors)}) and pixels "
                         f"{pixels.shape} must cover the same views, pixels as (V, F, P, 2)")
    if not set(free) < set(range(len(cameras))):
        raise ValueError(f"free views {free} must leave at least one of {len(cameras)} fixed")
    refined = list(cameras)
    rays = [ray_image(c) for c in cameras]
    settled = [v for v in range(len(cameras)) if v not in free]
    for sweep in range(sweeps):
        for view in _order(refined, free, settled) if sweep == 0 else free:
            if any(frame[view] is None for frame in maps):
                continue
            # First sweep: against the settled views only (the fixed ones and those already
            # re-posed), so the master's gauge spreads out instead of the faulty consensus.
            rest = settled if sweep == 0 else [v for v in range(len(cameras)) if v != view]
            refined[view] = _repose(refined[view], anchors[view],
                                    _terms_of(refined, view, rest, maps, pixels, rays))
            settled.append(view)
    return refined


def _order(cameras: list[CameraModel], free: tuple[int, ...], settled: list[int]) -> list[int]:
    """The free views, each next the one whose centre is nearest a settled or ordered one."""
    centres = np.array([c.T_cam_to_world[:, 3] for c in cameras])
    done, out = list(settled), []
    left = list(free)
    while left:
        gaps = [np.linalg.norm(centres[done] - centres[v], axis=1).min() for v in left]
        out.append(left.pop(int(np.argmin(gaps))))
        done.append(out[-1])
    return out


def _terms_of(cameras: list[CameraModel], view: int, rest: list[int],
              maps: list[list[np.ndarray | None]], pixels: np.ndarray,
              rays: list[np.ndarray]) -> _Terms:
    """One view's data under the current poses: its own depth, the ``rest`` views'
    surface and its labels against the points of all other views; rays: per view (H, W, 3)."""
    others = [[surface_image(cameras[v], frame[v], rays[v])  # type: ignore[arg-type]
               for v in rest if frame[v] is not None] for frame in maps]
    own = [depth_surface(cameras[view], frame[view], SOURCE_STEP_PX,  # type: ignore[arg-type]
                         rays[view]) for frame in maps]
    points, pix = _label_terms(
        cameras[view], leave_one_out_points(cameras, pixels, view).reshape(-1, 3),
        pixels[view].reshape(-1, 2))
    return _Terms(own, others, points, pix)


def world_time_maps(depth: list[np.ndarray | None], offsets: np.ndarray,
                    corrections: list[tuple[float, tuple[int, int]]], count: int = 2
                    ) -> list[list[np.ndarray | None]]:
    """``count`` world times every view with depth shows (the first and evenly after it,
    within the first half of the clip, where the scene is near its start): per time, V maps
    (H, W) uint16 mm corrected by each view's (scale, (dx, dy) px) as
    :func:`worker.rig.depth.correct_depth`.

    depth: V maps (F, H, W) uint16 mm in the view's own frames, or None. offsets: (V,) whole
    frames (a view shows world time t at its frame t + offset).
    """
    have = [v for v, m in enumerate(depth) if m is not None]
    if not have:
        return []
    lo = max(max(0, -int(offsets[v])) for v in have)
    hi = min(len(depth[v]) - max(0, int(offsets[v])) for v in have)  # type: ignore[arg-type]
    if hi <= lo:
        return []
    times = np.unique(np.linspace(lo, lo + (hi - 1 - lo) // 2, count).round().astype(int))
    out: list[list[np.ndarray | None]] = []
    for t in times:
        frame: list[np.ndarray | None] = []
        for v, m in enumerate(depth):
            if m is None:
                frame.append(None)
                continue
            f = int(t) + int(offsets[v])
            scale, shift = corrections[v]
            frame.append(correct_depth(m[f:f + 1], scale, shift)[0])
        out.append(frame)
    return out
