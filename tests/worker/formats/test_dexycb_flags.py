"""The DexYCB layout as the DexYCB toolkit documents and reads it, with our flags beside it.

The toolkit's rules, restated here (not its code): a label file's hand is absent when
``joint_3d`` (and ``joint_2d``) are all -1 and ``pose_m`` is all 0 (its README; the HPE
evaluation skips ``joint_3d == -1``, the grasp evaluation ``pose_m == 0``); every ``pose_y``
row is read as a pose; in ``pose.npz`` the viewer treats a ``pose_m`` row of zeros and a
``pose_y`` row equal to [0, 0, 0, 1, 0, 0, 0] as absent.
"""

from __future__ import annotations

import numpy as np
import pytest

from worker.formats import dexycb, dexycb_flags, dexycb_frames
from worker.geometry.transforms import axis_angle_to_matrix, make_pose

K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
CAMERAS = [make_pose(axis_angle_to_matrix(np.array(aa)), np.array(t))
           for aa, t in (((0, 0, 0), (0, 0, -0.8)), ((0.3, -0.5, 0.1), (0.4, 0.1, -0.7)),
                         ((-0.2, 0.6, 0.0), (-0.5, 0.0, -0.6)))]
OBJECTS = np.stack([make_pose(axis_angle_to_matrix(np.array(aa)), np.array(t))
                    for aa, t in (((0.1, 0.2, 0.3), (0.05, 0.0, 0.1)),
                                  ((1.0, -0.4, 0.2), (-0.1, 0.05, 0.0)))])
SEG = np.zeros((480, 640), np.uint8)


def _hand_absent(label: dict[str, np.ndarray]) -> bool:
    """The toolkit's rule for a label file's hand."""
    joint_absent = bool((label["joint_3d"] == -1).all() and (label["joint_2d"] == -1).all())
    return joint_absent and bool((label["pose_m"] == 0).all())


class TestLabelFiles:
    def test_an_unlabelled_or_flagged_hand_reads_as_absent_and_objects_as_poses(self) -> None:
        for T in CAMERAS:
            label = dexycb_frames.camera_frame_labels(T, K, OBJECTS, None, None, None, SEG)
            assert _hand_absent(label)
            assert label["joint_3d"].shape == (1, 21, 3) and label["pose_m"].shape == (1, 51)
            for row in label["pose_y"].astype(np.float64):
                R = row[:, :3]
                np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-6)
                assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-6)

    def test_every_pose_y_row_maps_to_one_world_pose_over_the_cameras(self) -> None:
        worlds = []
        for T in CAMERAS:
            label = dexycb_frames.camera_frame_labels(T, K, OBJECTS, None, None, None, SEG)
            pose_y = label["pose_y"].astype(np.float64)
            worlds.append(np.einsum("ij,ojk->oik", T[:, :3], pose_y)
                          + np.pad(T[:, 3][None, :, None], ((0, 0), (0, 0), (3, 0))))
        for world in worlds:
            np.testing.assert_allclose(world, OBJECTS, atol=2e-6)

    def test_the_flag_array_stands_beside_the_pose(self) -> None:
        flags = dexycb_flags.frame_flag_arrays(np.array([True, False]))
        assert flags[dexycb_flags.POSE_Y_VALID].tolist() == [1, 0]
        assert flags[dexycb_flags.POSE_Y_VALID].dtype == np.uint8


class TestPoseFile:
    def test_the_viewer_reads_missing_rows_as_absent_and_flagged_ones_as_poses(self) -> None:
        poses = np.repeat(OBJECTS[None], 3, axis=0)  # (F, O, 3, 4)
        poses[2, 1] = np.nan  # no pose at all
        pose_m = np.zeros((3, 1, 51))
        pose_m[0, 0, :3] = 0.1
        pose_m[1] = np.nan  # unlabelled (or flagged) hand frame
        pose_m[2, 0, 48:] = (0.1, 0.2, 0.5)
        arrays = dexycb.pose_arrays(poses, pose_m)
        present = np.any(arrays["pose_y"] != list(dexycb.NO_POSE_ROW), axis=2)
        assert present.tolist() == [[True, True], [True, True], [True, False]]
        assert np.any(arrays["pose_m"] != 0.0, axis=2)[:, 0].tolist() == [True, False, True]

    def test_flag_arrays_and_reasons(self) -> None:
        object_flags = np.array([["", "slipped", ""], ["", "", ""]])
        confidence = np.array([[0.9, 0.2, 0.8], [1.0, 1.0, 1.0]])
        hand_flags = np.array(["", "", "not pinned down"])
        arrays = dexycb_flags.pose_flag_arrays(
            object_flags, confidence, np.array([[True] * 3, [True, True, False]]), hand_flags,
            np.array([0.9, 0.9, 0.1]), np.array([True, True, True]), 1)
        assert arrays[dexycb_flags.POSE_Y_VALID].tolist() == [[1, 1], [0, 1], [1, 0]]
        assert arrays[dexycb_flags.POSE_Y_CONFIDENCE].shape == (3, 2)
        assert arrays[dexycb_flags.POSE_M_VALID].tolist() == [[1], [1], [0]]
        doc = dexycb_flags.flags_doc(object_flags, hand_flags)
        assert doc == {"pose_y": {1: {0: "slipped"}}, "hand": {2: "not pinned down"}}
        with pytest.raises(ValueError, match="same 2-d shape"):
            dexycb_flags.pose_flag_arrays(object_flags, confidence[:, :2], object_flags == "",
                                          hand_flags, np.ones(3), np.ones(3, bool), 1)

