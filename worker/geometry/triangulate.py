"""Triangulation of many world points at once from calibrated views, robust to wrong observations.

Conventions as in worker.geometry.cameras: pixels x right and y down, world frame in metres,
``CameraModel.T_cam_to_world`` camera-to-world, OpenCV (k1, k2, p1, p2, k3) lens distortion.

Pipeline of :func:`triangulate_points` for N points seen by up to V views:

1. every observation is undistorted to normalised coordinates once;
2. each pair of observing views proposes the point (two-view linear DLT); its inliers are the
   views whose reprojection lies within ``outlier_px``; the pair with the lowest MSAC cost
   (squared errors capped at ``outlier_px``^2) wins (RANSAC with exhaustive hypotheses);
3. the winning inlier set is re-triangulated by DLT and refined by Levenberg-Marquardt on the
   distorted reprojection error in pixels; inliers are re-evaluated on the refined point.

A "view" is a column of the pixel array: the same camera may appear in several columns (several
people labelling one view), pairs of columns from one camera centre are never hypotheses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.geometry.cameras import CameraModel, undistort_normalized
from worker.geometry.refine import (
    CameraStack,
    camera_frames,
    project_stack,
    refine_points,
    reprojection_errors,
)

# Pairs of columns whose camera centres are closer than this (metres) share a centre: their rays
# meet only there, so they cannot triangulate.
SAME_CENTRE_M = 1e-6


@dataclass
class Triangulation:
    """Result of :func:`triangulate_points`.

    points: (N, 3) world metres, NaN where fewer than 2 inlier views.
    inliers: (N, V) bool, the views the point was fitted to.
    errors_px: (N, V) reprojection error of every observation in pixels (inliers and outliers),
        NaN where unobserved, +inf where the point lies behind that camera.
    """

    points: np.ndarray
    inliers: np.ndarray
    errors_px: np.ndarray


def check_pixels(cameras: list[CameraModel], pixels: np.ndarray) -> np.ndarray:
    """``pixels`` as float64 (N, V, 2) with V = len(cameras); ValueError naming the shape."""
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim != 3 or pixels.shape[2] != 2 or pixels.shape[1] != len(cameras):
        raise ValueError(f"pixels must have shape (N, V={len(cameras)}, 2), got {pixels.shape}")
    return pixels


def normalized_observations(cameras: list[CameraModel], pixels: np.ndarray) -> np.ndarray:
    """Pixels (N, V, 2) -> undistorted normalised coordinates (N, V, 2), NaN stays NaN."""
    out = np.empty_like(pixels)
    for v, cam in enumerate(cameras):
        K = cam.K
        y = (pixels[:, v, 1] - K[1, 2]) / K[1, 1]
        x = (pixels[:, v, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        xy = np.stack([x, y], axis=-1)
        # An all-zero distortion is the identity: skip the fixed-point iterations.
        out[:, v] = xy if cam.dist is None or not cam.dist.any() else \
            undistort_normalized(xy, cam.dist)
    return out


def _dlt_rows(proj: np.ndarray, xn: np.ndarray) -> np.ndarray:
    """DLT rows (..., V, 2, 4) of observations xn (..., V, 2) under proj (V, 3, 4); zero rows
    where xn is NaN, so unobserved views drop out of the system."""
    seen = np.isfinite(xn).all(axis=-1)
    xn = np.where(seen[..., None], xn, 0.0)
    rows = xn[..., :, None] * proj[:, 2][:, None, :] - proj[:, :2]
    return np.where(seen[..., None, None], rows, 0.0)


def _solve_rows(rows: np.ndarray) -> np.ndarray:
    """Homogeneous least squares: rows (..., R, 4) -> (..., 3) from the smallest right singular
    vector (float64 SVD; NaN where the last coordinate vanishes)."""
    _, _, vh = np.linalg.svd(rows, full_matrices=False)
    hom = vh[..., -1, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        return hom[..., :3] / hom[..., 3:4]


def _solve_affine(rows: np.ndarray) -> np.ndarray:
    """The same least squares with the last coordinate fixed to 1: rows (..., R, 4) -> (..., 3)
    by the 3x3 normal equations in closed form (Cramer's rule), fast for millions of small
    systems. Fine for hypotheses, which only sort inliers; final points use the SVD."""
    a, b = rows[..., :3], -rows[..., 3]
    m = np.einsum("...ri,...rj->...ij", a, a)
    r = np.einsum("...ri,...r->...i", a, b)
    c0 = np.cross(m[..., 1, :], m[..., 2, :])
    c1 = np.cross(m[..., 2, :], m[..., 0, :])
    c2 = np.cross(m[..., 0, :], m[..., 1, :])
    det = np.einsum("...i,...i->...", m[..., 0, :], c0)
    adj = np.stack([c0, c1, c2], axis=-1)  # inverse of a symmetric m is adj / det
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.einsum("...ij,...j->...i", adj, r) / det[..., None]


def triangulate_dlt(cameras: list[CameraModel], pixels: np.ndarray) -> np.ndarray:
    """Linear DLT on undistorted normalised coordinates, every observation used, no rejection.

    Args:
        cameras: V calibrated views.
        pixels: (N, V, 2) observed pixels, NaN where a view does not observe the point.

    Returns:
        (N, 3) world points in metres, NaN where fewer than 2 views observe the point.
    """
    pixels = check_pixels(cameras, pixels)
    stack = CameraStack.of(cameras)
    xn = normalized_observations(cameras, pixels)
    return _dlt_masked(stack, xn, np.isfinite(xn).all(axis=-1))


def _dlt_masked(stack: CameraStack, xn: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """DLT over the views in ``mask`` (N, V) bool; (N, 3), NaN with fewer than 2 views."""
    n = xn.shape[0]
    out = np.full((n, 3), np.nan)
    ok = mask.sum(axis=1) >= 2
    if ok.any():
        obs = np.where(mask[ok, :, None], xn[ok], np.nan)
        rows = _dlt_rows(stack.projections, obs).reshape(int(ok.sum()), -1, 4)
        out[ok] = _solve_rows(rows)
    return out


def column_pairs(stack: CameraStack, columns: np.ndarray | None = None) -> np.ndarray:
    """(H, 2) int index pairs i < j of columns with distinct camera centres, among ``columns``
    (default all)."""
    cols = np.arange(len(stack.centres)) if columns is None else np.asarray(columns, dtype=int)
    i, j = np.triu_indices(len(cols), k=1)
    i, j = cols[i], cols[j]
    apart = np.linalg.norm(stack.centres[i] - stack.centres[j], axis=1) > SAME_CENTRE_M
    return np.stack([i[apart], j[apart]], axis=1)


# Hypothesis points x views scored at once; bounds the temporaries to some tens of megabytes.
_CHUNK_ELEMENTS = 1_500_000


def _score_hypotheses(stack: CameraStack, xn: np.ndarray, seen: np.ndarray, rows: np.ndarray,
                      chunk: np.ndarray, outlier_px: float,
                      votes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Scores (N, h) (-inf where invalid) and inlier masks (N, h, V) of the points proposed by
    the column pairs ``chunk`` (h, 2)."""
    a, b = chunk[:, 0], chunk[:, 1]
    points = _solve_affine(np.concatenate([rows[:, a], rows[:, b]], axis=2))  # (N, h, 3)
    cam = camera_frames(stack, points)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_z = 1.0 / cam[..., 2]
        dx = (cam[..., 0] * inv_z - xn[:, None, :, 0]) * stack.K[:, 0, 0]
        dy = (cam[..., 1] * inv_z - xn[:, None, :, 1]) * stack.K[:, 0, 0]
    err = np.sqrt(dx * dx + dy * dy)
    inl = seen[:, None] & (inv_z > 0) & (err < outlier_px)
    hyp = np.arange(len(chunk))
    valid = inl[:, hyp, a] & inl[:, hyp, b] & (inl.sum(axis=2) >= 2)
    # MSAC: every observation costs its squared error, capped at the threshold's square, so a
    # hypothesis is judged by how well its inliers fit, not only by their number. A point
    # between two clusters (e.g. ring and little finger 17 px apart, from a mix of careful and
    # swapped labels) keeps everyone within the threshold but loses to either cluster.
    capped = np.where(inl, err, outlier_px) ** 2
    cost = np.where(seen[:, None], votes * capped, 0.0).sum(axis=2)
    return np.where(valid, -cost, -np.inf), inl


def consensus_inliers(stack: CameraStack, xn: np.ndarray, outlier_px: float,
                      pairs: np.ndarray | None = None,
                      votes: np.ndarray | None = None) -> np.ndarray:
    """The best set of mutually consistent views of every point (MSAC: lowest capped cost).

    Args:
        stack: V cameras.
        xn: (N, V, 2) undistorted normalised observations, NaN where unobserved.
        outlier_px: inlier threshold; errors are measured on the undistorted image plane scaled
            by fx, which equals the pixel error up to the lens distortion's local scale (a few
            percent for RGB-D cameras), enough to sort inliers from gross outliers.
        pairs: (H, 2) column pairs used as hypotheses (default: every pair of distinct centres).
        votes: (V,) weight of each column's cost (default 1 each): a set of trusted columns
            then beats an equally large set of doubtful ones.

    Returns:
        (N, V) bool inlier mask of the winning hypothesis (all False where no pair observes).
    """
    n, v = xn.shape[:2]
    pairs = column_pairs(stack) if pairs is None else np.asarray(pairs, dtype=int).reshape(-1, 2)
    seen = np.isfinite(xn).all(axis=-1)
    votes = np.ones(v) if votes is None else np.asarray(votes, dtype=np.float64)
    rows = _dlt_rows(stack.projections, xn)
    best_score = np.full(n, -np.inf)
    best = np.zeros((n, v), dtype=bool)
    step = max(1, _CHUNK_ELEMENTS // max(1, n * v))
    for start in range(0, len(pairs), step):
        chunk = pairs[start:start + step]
        score, inl = _score_hypotheses(stack, xn, seen, rows, chunk, outlier_px, votes)
        h = np.argmax(score, axis=1)
        top = score[np.arange(n), h]
        better = top > best_score
        best_score = np.where(better, top, best_score)
        best[better] = inl[np.flatnonzero(better), h[better]]
    return best


def triangulate_points(cameras: list[CameraModel], pixels: np.ndarray, *,
                       outlier_px: float = 15.0, refine: bool = True,
                       pairs: np.ndarray | None = None,
                       weights: np.ndarray | None = None,
                       votes: np.ndarray | None = None) -> Triangulation:
    """Robust triangulation of N points from V calibrated views.

    Args:
        cameras: V calibrated views (a camera may repeat: several labels of one view).
        pixels: (N, V, 2) observed pixels, NaN where a view does not observe the point.
        outlier_px: reprojection error (px) above which an observation is an outlier.
        refine: refine the linear estimate by Levenberg-Marquardt on the pixel error.
        pairs: (H, 2) column pairs to use as hypotheses (default every pair of distinct centres).
        weights: (V,) or (N, V) weights of the squared pixel errors in the refinement
            (e.g. 1 / sigma^2 per column); default 1.
        votes: (V,) weight of each column's vote when hypotheses are compared; default 1.

    Returns:
        Triangulation with points (N, 3) world metres, inliers (N, V), errors_px (N, V).
    """
    pixels = check_pixels(cameras, pixels)
    if not outlier_px > 0:
        raise ValueError(f"outlier_px must be positive, got {outlier_px}")
    stack = CameraStack.of(cameras)
    xn = normalized_observations(cameras, pixels)
    inliers = consensus_inliers(stack, xn, outlier_px, pairs, votes)
    # Two rounds: a refined point may win back views the two-view hypothesis just missed.
    for _ in range(2):
        points = _dlt_masked(stack, xn, inliers)
        if refine:
            points = refine_points(stack, pixels, points, inliers, weights)
        errors = reprojection_errors(stack, pixels, points)
        new_inliers = np.isfinite(errors) & (errors < outlier_px)
        new_inliers &= (new_inliers.sum(axis=1) >= 2)[:, None]
        if np.array_equal(new_inliers, inliers):
            break
        inliers = new_inliers
    points = np.where((inliers.sum(axis=1) >= 2)[:, None], points, np.nan)
    errors = reprojection_errors(stack, pixels, points)
    observed = np.isfinite(pixels).all(axis=-1)
    errors = np.where(observed & np.isnan(errors), np.nan, errors)
    return Triangulation(points=points, inliers=inliers, errors_px=errors)


def leave_one_out_residuals(cameras: list[CameraModel], pixels: np.ndarray, points: np.ndarray,
                            inliers: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Residual of every observation against the point fitted without it (linearised).

    For an inlier i of a least-squares fit, removing it moves the point by one Gauss-Newton step;
    by the Woodbury identity its residual becomes (I - w_i J_i A^-1 J_i^T)^-1 r_i with
    A = sum_j w_j J_j^T J_j over the inliers. Outliers did not take part, so their residual stays.

    Args:
        cameras: V views; pixels: (N, V, 2) observations px; points: (N, 3) fitted world points
        (metres); inliers: (N, V) bool, the fit's observations; weights as in refine_points.

    Returns:
        (N, V, 2) residual (observation - prediction) px, NaN where unobserved, where the point
        is NaN, or where removing the observation leaves fewer than 2 views.
    """
    pixels = check_pixels(cameras, pixels)
    stack = CameraStack.of(cameras)
    w = np.broadcast_to(np.ones(len(cameras)) if weights is None else weights, inliers.shape)
    w = np.where(inliers, w, 0.0)
    # Only points that exist are projected, and only their inliers' Jacobians enter the sums:
    # an outlier view may see the point on or behind its principal plane, where the
    # Jacobian is NaN.
    fitted = np.isfinite(points).all(axis=1)
    pix = np.full(pixels.shape, np.nan)
    jac = np.zeros(inliers.shape + (2, 3))
    pix[fitted], _, jac[fitted] = project_stack(stack, points[fitted], jacobian=True)
    jac = np.where(inliers[..., None, None], jac, 0.0)
    res = pixels - pix
    hess = np.einsum("nv,nvai,nvaj->nij", w, jac, jac)
    scale = np.einsum("nii->n", hess) ** 3
    ok = (inliers.sum(axis=1) >= 3) & np.isfinite(points).all(axis=1)
    ok &= np.linalg.det(hess) > 1e-12 * scale
    hess_inv = np.zeros_like(hess)
    hess_inv[ok] = np.linalg.inv(hess[ok])
    keep = np.eye(2) - w[..., None, None] * np.einsum("nvai,nij,nvbj->nvab", jac, hess_inv, jac)
    # The rest of the views no longer fix the point (e.g. all from one camera centre).
    alone = np.linalg.det(keep) < 1e-9
    keep[alone] = np.eye(2)
    rhs = np.where(np.isfinite(res), res, 0.0)[..., None]
    loo = np.linalg.solve(keep, rhs)[..., 0]
    out = np.where(inliers[..., None], loo, res)
    bad = ~np.isfinite(points).all(axis=1)[:, None] | (inliers & (~ok[:, None] | alone))
    out[bad] = np.nan
    return out
