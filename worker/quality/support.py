"""How well the other views fix a point: the leave-one-out reference's spread in each view.

A label is judged against the point its OTHER views triangulate. How far off a careful label
may be depends on that geometry: many well spread views pin the point to a fraction of a
pixel; two views on a narrow baseline leave it free along their common epipolar direction,
by several pixels in this view. Propagating the other labels' noise (their 1 / sigma^2
weights) through the triangulation gives the reference's covariance in this view:

    A_-i = sum over the other inliers j of w_j J_j^T J_j           (3 x 3, per point)
    P_i  = J_i A_-i^-1 J_i^T                                        (2 x 2 px^2)

and a careful label of noise sigma0 differs from the reference by r ~ N(0, sigma0^2 I + P_i).
The normalised error sigma0 * sqrt(r^T (sigma0^2 I + P_i)^-1 r) reads in pixels as the same
label would against an exact reference, so one threshold holds at 8 views and at 4.

For an inlier, A_-i is A (the fit's sum) less its own term; by the Woodbury identity
P_i = M (I - w_i M)^-1 with M = J_i A^-1 J_i^T. An outlier took no part: P_i = M.

The three-views rule: a point is judged only where at least two OTHER views are inliers
(three views in all, this one included); elsewhere the spread is NaN and the label is not
scored there.

N points, L labels; pixels x right, y down; world metres.
"""

from __future__ import annotations

import numpy as np

from worker.geometry.refine import CameraStack, project_stack

# Fewest views that make a verdict on a point: this label's and two others to triangulate it.
MIN_VIEWS = 3
MIN_OTHER_VIEWS = MIN_VIEWS - 1


def reference_spread(stack: CameraStack, points: np.ndarray, inliers: np.ndarray,
                     weights: np.ndarray, views: np.ndarray,
                     trusted: np.ndarray | None = None) -> np.ndarray:
    """(N, L, 2, 2) covariance px^2 of each label's leave-one-out reference in its own view.

    Args:
        stack: the L labels' cameras (one per label, repeated for labels of the same view).
        points: (N, 3) fitted world points, metres (NaN: none).
        inliers: (N, L) bool, the observations the fit used.
        weights: (N, L) or (L,) 1 / sigma^2 px^-2 of each observation in the fit.
        views: (L,) the view of each label (labels of one view count as one view).
        trusted: optional (L,) bool, the labels whose views count toward MIN_OTHER_VIEWS (a
            spammer's point that happens to lie near another view's epipolar line makes a
            two-view "consensus" that proves nothing).

    Returns:
        NaN where the point is missing or fewer than MIN_OTHER_VIEWS other distinct views are
        trusted inliers (no verdict there).
    """
    n, labels = inliers.shape
    if points.shape != (n, 3) or np.shape(views) != (labels,):
        raise ValueError(f"expected points (N={n}, 3) and views (L={labels},), got "
                         f"{points.shape} and {np.shape(views)}")
    w = np.broadcast_to(np.asarray(weights, np.float64), inliers.shape)
    w = np.where(inliers, w, 0.0)
    fitted = np.isfinite(points).all(axis=1)
    jac = np.full((n, labels, 2, 3), np.nan)
    _, z, jacobian = project_stack(stack, points[fitted], jacobian=True)
    assert jacobian is not None
    jac[fitted] = np.where((z > 0)[..., None, None], jacobian, np.nan)
    used = np.where(inliers[..., None, None], np.nan_to_num(jac), 0.0)
    hess = np.einsum("nl,nlai,nlaj->nij", w, used, used)
    scale = np.einsum("nii->n", hess) ** 3
    ok = fitted & (np.linalg.det(hess) > 1e-12 * np.maximum(scale, 1e-300))
    hess_inv = np.full_like(hess, np.nan)
    hess_inv[ok] = np.linalg.inv(hess[ok])
    m = np.einsum("nlai,nij,nlbj->nlab", jac, hess_inv, jac)
    own = w[..., None, None] * m
    keep = np.eye(2) - own
    det = np.linalg.det(np.nan_to_num(keep))
    # Removing the label leaves the point free (det ~ 0): no verdict, like too few views.
    solvable = np.isfinite(m).all(axis=(2, 3)) & (det > 1e-9)
    spread = np.full(m.shape, np.nan)
    keep_inv = np.linalg.inv(np.where(solvable[..., None, None], keep, np.eye(2)))
    spread[solvable] = np.einsum("kab,kbc->kac", m[solvable], keep_inv[solvable])
    spread = 0.5 * (spread + np.swapaxes(spread, -1, -2))
    counted = inliers if trusted is None else inliers & np.asarray(trusted, bool)[None, :]
    others = _other_views(counted, views)
    spread[others < MIN_OTHER_VIEWS] = np.nan
    return spread


def _other_views(inliers: np.ndarray, views: np.ndarray) -> np.ndarray:
    """(N, L) distinct views other than the label's own with an inlier observation."""
    ids = np.unique(views)
    per_view = np.stack([inliers[:, views == v].any(axis=1) for v in ids], axis=1)
    total = per_view.sum(axis=1)
    own = per_view[:, np.searchsorted(ids, views)]
    return total[:, None] - own


def normalised_errors(residuals: np.ndarray, spread: np.ndarray, sigma_px: float) -> np.ndarray:
    """(...,) px: residuals (..., 2) px against a reference of covariance spread (..., 2, 2) px^2,
    as a label of noise ``sigma_px`` would show against an exact reference; NaN where either
    is missing."""
    cov = sigma_px ** 2 * np.eye(2) + np.nan_to_num(spread)
    good = np.isfinite(residuals).all(axis=-1) & np.isfinite(spread).all(axis=(-1, -2))
    r = np.nan_to_num(residuals)
    maha = np.einsum("...a,...ab,...b->...", r, np.linalg.inv(cov), r)
    return np.where(good, sigma_px * np.sqrt(np.maximum(maha, 0.0)), np.nan)


def spread_px(spread: np.ndarray) -> np.ndarray:
    """(...,) px: the reference's RMS uncertainty per axis, sqrt(trace / 2) of (..., 2, 2)."""
    return np.sqrt(np.maximum(np.einsum("...aa->...", spread), 0.0) / 2.0)
