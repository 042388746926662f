"""The rig-health estimate: every view's time offset, pose correction and depth fit, and the
views whose figures exceed the thresholds.

Thresholds (``RigThresholds``) come from the noise of a clean rig: on clean synthetic captures
labelled by the simulated careful crowd (2 px), the estimates of healthy views stay below about
half of them (tests/worker/rig/test_rig.py checks a clean rig is named healthy), while the smallest
faults the rig meets (0.2 deg and 2 mm, one frame, 1 % depth scale, 2 px depth shift) exceed
them. Time offsets and depth shifts are already gated by their cost gain in
:mod:`worker.rig.timing` and :mod:`worker.rig.depth`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from worker.geometry.cameras import CameraModel
from worker.rig.common import align_views, check_tracks, observed, shift_frames
from worker.rig.depth import (
    DepthFit,
    correct_depth,
    fit_depth,
    registration_shift,
    view_scale_fit,
)
from worker.rig.extrinsics import ExtrinsicCorrection, describe_corrections, refine_extrinsics
from worker.rig.surface import refine_with_depth, world_time_maps
from worker.rig.timing import TimeOffset, estimate_time_offsets


@dataclass(frozen=True)
class RigThresholds:
    """A view is named off when its correction exceeds any of these."""

    image_shift_px: float = 0.8
    depth_scale_percent: float = 0.5
    depth_shift_px: float = 1.0
    time_offset_frames: int = 1


@dataclass(frozen=True)
class CameraHealth:
    """One view: its figures, and ``faults``, one sentence per figure over its threshold."""

    view: int
    time_offset_frames: int
    rotation_deg: float
    translation_mm: float
    image_shift_px: float
    residual_px_before: float
    residual_px_after: float
    depth_scale: float | None
    depth_shift_px: tuple[int, int] | None
    faults: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class RigEstimate:
    """The refined cameras (V), per-view health and the raw estimates behind it."""

    cameras: list[CameraModel]
    health: list[CameraHealth]
    offsets: list[TimeOffset]
    corrections: list[ExtrinsicCorrection]
    depth: list[DepthFit | None]

    @property
    def faulty_views(self) -> list[int]:
        return [h.view for h in self.health if h.faults]


def _faults(offset: int, corr: ExtrinsicCorrection, fit: DepthFit | None,
            limits: RigThresholds) -> list[str]:
    out = []
    if abs(offset) >= limits.time_offset_frames:
        out.append(f"{abs(offset)} frame{'s' if abs(offset) > 1 else ''} "
                   f"{'late' if offset > 0 else 'early'}")
    if corr.image_shift_px > limits.image_shift_px:
        out.append(f"pose off by {corr.rotation_deg:.2f} deg and {corr.translation_mm:.1f} mm "
                   f"(the labelled points move {corr.image_shift_px:.1f} px)")
    if fit is not None and abs(fit.scale - 1.0) * 100.0 > limits.depth_scale_percent:
        out.append(f"depth scale {100.0 * (fit.scale - 1.0):+.1f} %")
    if fit is not None and np.hypot(*fit.shift_px) >= limits.depth_shift_px:
        out.append(f"depth shifted by ({fit.shift_px[0]}, {fit.shift_px[1]}) px against colour")
    return out


def _depth_pass(cameras: list[CameraModel], corrections: list[ExtrinsicCorrection],
                pixels: np.ndarray, depth: list[np.ndarray | None], offsets: np.ndarray,
                color: list[dict[int, np.ndarray]] | None, free: tuple[int, ...],
                limits: RigThresholds) -> list[ExtrinsicCorrection]:
    """The free views' label-refined poses re-posed against the whole scene's depth
    (:mod:`worker.rig.surface`). Every view's depth shift and the depth scale of the views that
    stay in place are estimated first and applied, so a depth fault is not taken for a pose
    fault. pixels: (V, F, P, 2) px."""
    refined = [c.camera for c in corrections]
    # The scales are judged among the views that stay in place only: against views whose
    # poses are still off by a few mm a scale is off by a few tenths of a percent (at 4 views,
    # the master alone against three moved views reads 0.5 %), and applied to a view that
    # stays in place it would move every free view along with it. A scale of a free view is
    # never applied here: it would itself move the view along its axis (the final fit after
    # the move finds it).
    fits = fit_depth(refined, [None if v in free else d for v, d in enumerate(depth)], offsets,
                     color, passes=1)
    shifts = [f.shift_px if f is not None else
              registration_shift(d, color[v]) if d is not None and color and color[v]
              else (0, 0) for v, (f, d) in enumerate(zip(fits, depth, strict=True))]
    maps = world_time_maps(depth, offsets, [
        (f.scale if f is not None and abs(f.scale - 1.0) * 100.0 > limits.depth_scale_percent
         else 1.0, shift) for f, shift in zip(fits, shifts, strict=True)])
    if not maps:
        return corrections
    moved = refine_with_depth(refined, cameras, free, maps, pixels)
    # A depth scale fault and a move along the optical axis explain one view's depth alike,
    # and the labels cannot tell them apart (a 1 % scale at 0.7 m, 7 mm, moves the labelled
    # points ~1 px). So a free view whose depth the imported pose with a scale of its own
    # explains at least as well as the move stays as imported (the final fit names the
    # scale); a real pose fault leaves the imported pose 3-60 % worse at any scale.
    for v in free:
        if depth[v] is None:
            continue
        stay = [cameras[v] if i == v else c for i, c in enumerate(moved)]
        if view_scale_fit(v, stay, depth, offsets, shifts[v]).cost_mm \
                <= view_scale_fit(v, moved, depth, offsets, shifts[v]).cost_mm:
            moved[v] = cameras[v]
    return describe_corrections(cameras, moved, pixels,
                                [c.residual_px_before for c in corrections])


def estimate_rig(cameras: list[CameraModel], keypoints: np.ndarray, visible: np.ndarray,
                 depth: list[np.ndarray | None] | None = None,
                 color: list[dict[int, np.ndarray]] | None = None, fixed: tuple[int, ...] = (0,),
                 limits: RigThresholds | None = None) -> RigEstimate:
    """Estimate every view's faults from multi-view tracks.

    Args:
        cameras: V views as calibrated. keypoints: (V, F, P, 2) px of the same P points in
            every view (hand joints), NaN where unlabelled. visible: (V, F, P) bool.
        depth: V aligned depth maps (F, H, W) uint16 mm or None (no depth fit).
        color: per view {frame: (H, W, 3) uint8} of a few frames (none: no depth shift).
        fixed: views whose pose and time define the world (the master).
        limits: thresholds for naming a view.
    """
    keypoints, visible = check_tracks(cameras, keypoints, visible)
    limits = limits or RigThresholds()
    offsets = estimate_time_offsets(cameras, keypoints, visible, fixed=fixed)
    k = np.array([o.frames for o in offsets])
    aligned, seen = align_views(keypoints, visible, k)
    corrections = refine_extrinsics(cameras, aligned, seen, fixed=fixed)
    # Second pass: only the views whose correction shows in their labels move; the consistent
    # ones stay as imported and pin the gauge with the master (a hand-sized cloud leaves some
    # directions of a healthy view's pose to noise, which the depth check would then see).
    off = tuple(v for v, c in enumerate(corrections)
                if v not in fixed and c.image_shift_px > limits.image_shift_px)
    if off:
        corrections = refine_extrinsics(
            cameras, aligned, seen, fixed=tuple(v for v in range(len(cameras)) if v not in off))
        if depth is not None:
            corrections = _depth_pass(cameras, corrections, observed(aligned, seen), depth, k,
                                      color, off, limits)
    else:
        corrections = [replace(c, camera=cameras[v], rotation_deg=0.0, translation_mm=0.0,
                               image_shift_px=0.0, residual_px_after=c.residual_px_before)
                       for v, c in enumerate(corrections)]
    refined = [c.camera for c in corrections]
    fits: list[DepthFit | None] = [None] * len(cameras)
    if depth is not None:
        fits = fit_depth(refined, depth, k, color)
    health = [CameraHealth(v, int(k[v]), c.rotation_deg, c.translation_mm, c.image_shift_px,
                           c.residual_px_before, c.residual_px_after,
                           None if f is None else f.scale, None if f is None else f.shift_px,
                           _faults(int(k[v]), c, f, limits))
              for v, (c, f) in enumerate(zip(corrections, fits, strict=True))]
    return RigEstimate(refined, health, offsets, corrections, fits)


def apply_time_offsets(keypoints: np.ndarray, visible: np.ndarray,
                       offsets: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Tracks (V, F, P, 2) px and (V, F, P) bool re-indexed to world time (NaN / False where a
    late or early view has no frame)."""
    return align_views(np.asarray(keypoints, float), np.asarray(visible, bool),
                       np.asarray(offsets, int))


def apply_depth_correction(maps: np.ndarray, offset: int, scale: float,
                           shift_px: tuple[int, int]) -> np.ndarray:
    """A view's depth maps (F, H, W) uint16 mm in world time, re-registered and re-scaled."""
    timed = shift_frames(maps, offset, 0) if offset else maps
    return correct_depth(timed, scale, shift_px)
