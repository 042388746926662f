"""The calibration version in use applied to a solve's inputs: a late view's labels and depth
move to world time, its depth is re-registered and re-scaled; the imported calibration passes
everything through unchanged."""

from __future__ import annotations

import numpy as np

from backend.solve.calibrated import (
    depth_in_world_time,
    hand_in_world_time,
    objects_in_world_time,
)
from worker.solver import HandTarget, Landmark, ObjectTarget

IMPORTED = {"time_offset_frames": 0, "depth_scale": 1.0, "depth_shift_px": [0, 0]}


def test_a_late_view_is_read_one_frame_on() -> None:
    keypoints = np.arange(2 * 4 * 21 * 2, dtype=float).reshape(2, 4, 21, 2)
    hand = HandTarget("right", np.zeros(10), keypoints, np.ones((2, 4, 21), bool))
    late = dict(IMPORTED, time_offset_frames=1)
    out = hand_in_world_time(hand, [IMPORTED, late])
    assert out is not None
    assert np.array_equal(out.keypoints[0], keypoints[0])
    assert np.array_equal(out.keypoints[1, :3], keypoints[1, 1:])
    assert np.isnan(out.keypoints[1, 3]).all() and not out.visible[1, 3].any()
    mark = Landmark(view=1, xy=np.arange(8.0).reshape(4, 2), visible=np.ones(4, bool))
    obj = ObjectTarget("box", np.zeros((3, 3)), np.zeros((1, 3), int), None, [mark])
    moved = objects_in_world_time([obj], [IMPORTED, late])[0].landmarks[0]
    assert moved.xy[0].tolist() == [2.0, 3.0] and not moved.visible[3]
    assert hand_in_world_time(hand, [IMPORTED, IMPORTED]) is hand


def test_depth_is_shifted_in_time_space_and_scale() -> None:
    maps = np.zeros((3, 6, 8), np.uint16)
    for f in range(3):
        maps[f, 2, 3] = 1010 * (f + 1)
    entry = {"time_offset_frames": 1, "depth_scale": 1.01, "depth_shift_px": [1, 0]}
    out = depth_in_world_time([maps, maps], [IMPORTED, entry])
    assert out[0] is maps
    fixed = out[1]
    assert fixed is not None
    # World frame 0 is the view's frame 1; its pixel (x=3, y=2) now reads at x=2.
    assert fixed[0, 2, 2] == 2000 and fixed[0, 2, 3] == 0
    assert not fixed[2].any()
