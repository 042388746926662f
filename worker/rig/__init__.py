"""Rig health: per-camera faults estimated from the crowd's multi-view correspondences.

From tracks of the same points labelled in V calibrated views (hand joints: (V, F, P, 2) px)
it estimates, per camera, a whole-frame time offset (:mod:`worker.rig.timing`), an extrinsic
correction (:mod:`worker.rig.extrinsics`) and a depth scale and pixel shift of the aligned
depth against the triangulated points (:mod:`worker.rig.depth`), and names the cameras whose
estimates exceed thresholds set from the noise of a clean rig (:mod:`worker.rig.health`).
Pure NumPy/OpenCV: arrays in, arrays and diagnostics out.
"""

from worker.rig.health import (
    CameraHealth,
    RigEstimate,
    RigThresholds,
    apply_depth_correction,
    apply_time_offsets,
    estimate_rig,
)

__all__ = ["CameraHealth", "RigEstimate", "RigThresholds", "apply_depth_correction",
           "apply_time_offsets", "estimate_rig"]
