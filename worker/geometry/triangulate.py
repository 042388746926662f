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

# Pairs of columns whose camera centres are closer than this (metres) share a centre: their rays
# meet only there, so they cannot triangulate.
SAME_CENTRE_M = 1e-6
LM_ITERATIONS = 12


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


@dataclass(frozen=True)
class CameraStack:
    """V cameras as stacked arrays: rot (V, 3, 3) and trans (V, 3) world-to-camera (metres),
    K (V, 3, 3) pixels, dist (V, 5) OpenCV coefficients (zeros for an ideal pinhole),
    centres (V, 3) camera centres in world metres."""

    rot: np.ndarray
    trans: np.ndarray
    K: np.ndarray
    dist: np.ndarray
    centres: np.ndarray

    @classmethod
    def of(cls, cameras: list[CameraModel]) -> CameraStack:
        if not cameras or not all(isinstance(c, CameraModel) for c in cameras):
            raise ValueError("cameras must be a non-empty list of CameraModel")
        rot_c2w = np.stack([c.T_cam_to_world[:, :3] for c in cameras])
        centres = np.stack([c.T_cam_to_world[:, 3] for c in cameras])
        rot = np.transpose(rot_c2w, (0, 2, 1))
        trans = -np.einsum("vij,vj->vi", rot, centres)
        dist = np.stack([np.zeros(5) if c.dist is None else c.dist for c in cameras])
        return cls(rot, trans, np.stack([c.K for c in cameras]), dist, centres)

    @property
    def projections(self) -> np.ndarray:
        """(V, 3, 4) normalised projection matrices [R | t] (world -> undistorted z=1 plane)."""
        return np.concatenate([self.rot, self.trans[:, :, None]], axis=2)


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


def _to_cameras(stack: CameraStack, points: np.ndarray) -> np.ndarray:
    """World points (..., 3) -> camera frames (..., V, 3), metres, as one matrix product."""
    v = len(stack.rot)
    with np.errstate(invalid="ignore"):
        flat = points.reshape(-1, 3) @ stack.rot.transpose(2, 0, 1).reshape(3, 3 * v)
    return flat.reshape(points.shape[:-1] + (v, 3)) + stack.trans


def project_stack(stack: CameraStack, points: np.ndarray,
                  jacobian: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Project world points into every camera of the stack.

    Args:
        stack: V cameras.
        points: (N, 3) world metres (or (N, V, 3): one point per view).
        jacobian: also return d pixel / d point.

    Returns:
        pixels (N, V, 2), camera depth z (N, V) metres, and the Jacobian (N, V, 2, 3) or None.
    """
    if points.ndim == 3:
        cam = np.einsum("vij,nvj->nvi", stack.rot, points) + stack.trans
    else:
        cam = _to_cameras(stack, points)
    z = cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = cam[..., 0] / z, cam[..., 1] / z
    distorted = bool(stack.dist.any())
    if distorted:
        k1, k2, p1, p2, k3 = (stack.dist[:, i] for i in range(5))
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    else:
        xd, yd = x, y
    K = stack.K
    u = K[:, 0, 0] * xd + K[:, 0, 1] * yd + K[:, 0, 2]
    v = K[:, 1, 1] * yd + K[:, 1, 2]
    pix = np.stack([u, v], axis=-1)
    if not jacobian:
        return pix, z, None
    jn = np.zeros(x.shape + (2, 3))
    jn[..., 0, 0] = jn[..., 1, 1] = 1.0 / z
    jn[..., 0, 2] = -x / z
    jn[..., 1, 2] = -y / z
    if not distorted:
        return pix, z, K[:, :2, :2] @ (jn @ stack.rot)
    d_radial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    # d(xd, yd) / d(x, y) of OpenCV's radial-tangential model.
    jd = np.empty(x.shape + (2, 2))
    jd[..., 0, 0] = radial + 2.0 * x * x * d_radial + 2.0 * p1 * y + 6.0 * p2 * x
    jd[..., 0, 1] = 2.0 * x * y * d_radial + 2.0 * p1 * x + 2.0 * p2 * y
    jd[..., 1, 0] = jd[..., 0, 1]
    jd[..., 1, 1] = radial + 2.0 * y * y * d_radial + 6.0 * p1 * y + 2.0 * p2 * x
    jac = K[:, :2, :2] @ jd @ (jn @ stack.rot)
    return pix, z, jac


def reprojection_errors(stack: CameraStack, pixels: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, V) pixel distance between observations (N, V, 2) and projected points (N, 3); NaN
    where unobserved (or the point is NaN), +inf where the point is behind the camera."""
    pix, z, _ = project_stack(stack, points)
    err = np.linalg.norm(pix - pixels, axis=-1)
    observed = np.isfinite(pixels).all(axis=-1) & np.isfinite(points).all(axis=-1)[:, None]
    err = np.where(z > 0, err, np.inf)
    return np.where(observed, err, np.nan)


def cauchy_weights(errors: np.ndarray, scales: np.ndarray | None) -> np.ndarray:
    """IRLS weights 1 / (1 + (e / c)^2) of the Cauchy loss for errors (N, V) px at scales c
    (broadcast to (N, V)); ones where scales is None."""
    if scales is None:
        return np.ones_like(errors)
    return 1.0 / (1.0 + (errors / scales) ** 2)


def _weighted_cost(stack, pixels, points, mask, weights, scales=None) -> np.ndarray:
    """(n,) sum of w * rho(e) over the masked observations: rho = e^2, or the Cauchy loss
    c^2 log(1 + (e / c)^2) with scales c; infinite where a point falls behind a camera."""
    err = reprojection_errors(stack, pixels, points)
    err = np.where(mask, np.where(np.isfinite(err), err, np.inf), 0.0)
    rho = err ** 2 if scales is None else scales ** 2 * np.log1p((err / scales) ** 2)
    return np.where(mask, weights * rho, 0.0).sum(axis=1)


def _lm_step(stack: CameraStack, pixels: np.ndarray, x: np.ndarray, mask: np.ndarray,
             w: np.ndarray, damping: np.ndarray, scales: np.ndarray | None) -> np.ndarray:
    """One damped (iteratively re-weighted) Gauss-Newton step (n, 3) metres for x (n, 3)."""
    pix, _, jac = project_stack(stack, x, jacobian=True)
    res = np.where(mask[..., None], pix - pixels, 0.0)
    w = w * cauchy_weights(np.linalg.norm(res, axis=-1), scales)
    flat = jac.reshape(len(x), -1, 3)  # (n, 2V, 3)
    weighted = np.swapaxes(flat * np.repeat(w, 2, axis=1)[..., None], 1, 2)
    hess = weighted @ flat
    grad = (weighted @ res.reshape(len(x), -1, 1))[..., 0]
    diag = np.einsum("nii->ni", hess)
    lhs = hess + (damping[:, None] * diag)[:, :, None] * np.eye(3) + 1e-18 * np.eye(3)
    return np.linalg.solve(lhs, -grad[..., None])[..., 0]


def refine_points(stack: CameraStack, pixels: np.ndarray, points: np.ndarray, mask: np.ndarray,
                  weights: np.ndarray | None = None, scales: np.ndarray | None = None,
                  iterations: int = LM_ITERATIONS) -> np.ndarray:
    """Levenberg-Marquardt on the (distorted) pixel reprojection error, all points at once.

    Args:
        stack: V cameras.
        pixels: (N, V, 2) observations, px.
        points: (N, 3) starting points, world metres (NaN rows are left alone).
        mask: (N, V) bool, the observations that enter the cost.
        weights: (N, V) or (V,) non-negative weights of the squared errors (default 1).
        scales: (N, V) or (V,) Cauchy scales in px for a robust cost (default: least squares);
            an observation c px off weighs half, one 3c off a tenth, so a minority inside the
            inlier threshold no longer drags the point.
        iterations: LM steps; each point keeps its own damping and only accepts improving steps.

    Returns:
        (N, 3) refined world points, metres.
    """
    w = np.broadcast_to(np.ones(mask.shape[1]) if weights is None else weights, mask.shape)
    w = np.where(mask, w, 0.0)
    c = None if scales is None else np.broadcast_to(scales, mask.shape)
    active = np.flatnonzero(np.isfinite(points).all(axis=1) & (mask.sum(axis=1) >= 2))
    x = points.copy()
    damping = np.full(len(x), 1e-3)
    cost = np.full(len(x), np.inf)

    def part(rows):
        return pixels[rows], mask[rows], w[rows], None if c is None else c[rows]

    pix_a, mask_a, w_a, c_a = part(active)
    cost[active] = _weighted_cost(stack, pix_a, x[active], mask_a, w_a, c_a)
    for _ in range(iterations):
        if active.size == 0:
            break
        pix_a, mask_a, w_a, c_a = part(active)
        step = _lm_step(stack, pix_a, x[active], mask_a, w_a, damping[active], c_a)
        trial = x[active] + step
        new_cost = _weighted_cost(stack, pix_a, trial, mask_a, w_a, c_a)
        better = new_cost < cost[active]
        x[active[better]], cost[active[better]] = trial[better], new_cost[better]
        damping[active] = np.where(better, damping[active] / 3.0, damping[active] * 4.0)
        # A point stops once its step is below a nanometre or its damping has run away
        # (no improving step left: it sits at the minimum up to rounding).
        moving = (np.linalg.norm(step, axis=1) > 1e-9) & (damping[active] < 1e6)
        active = active[moving]
    return x


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
    cam = _to_cameras(stack, points)
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
    pix, _, jac = project_stack(stack, np.nan_to_num(points), jacobian=True)
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
