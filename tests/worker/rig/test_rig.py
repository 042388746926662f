"""Rig health on a synthetic rig with known faults (tests/worker/rig/rig_scene.py): every faulty
view is named with the right figure and no healthy view is, and the refined calibration
brings the faulty views' residuals back to the label noise."""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.rig.rig_scene import make_scene, one_frame_late, perturbed
from worker.rig import apply_depth_correction, apply_time_offsets, estimate_rig
from worker.rig.common import shift_frames
from worker.rig.depth import correct_depth
from worker.rig.extrinsics import pose_change
from worker.rig.surface import depth_surface, refine_with_depth

pytestmark = pytest.mark.slow


def test_clean_rig_is_named_healthy() -> None:
    scene = make_scene(seed=1)
    est = estimate_rig(scene.cameras, scene.keypoints, scene.visible, scene.depth,
                       scene.color)
    assert est.faulty_views == []
    for h in est.health:
        # Healthy views keep their imported pose; depth figures stay under the thresholds.
        assert h.time_offset_frames == 0 and h.image_shift_px == 0.0
        assert est.cameras[h.view] is scene.cameras[h.view]
        assert h.depth_scale is not None and abs(h.depth_scale - 1.0) < 0.003
        assert h.depth_shift_px == (0, 0)


def test_extrinsic_faults_are_named_and_corrected() -> None:
    scene = make_scene(seed=2)
    rng = np.random.default_rng(7)
    faulty = list(scene.cameras)
    faulty[3] = perturbed(scene.cameras[3], 0.5, 5.0, rng)
    faulty[6] = perturbed(scene.cameras[6], 0.3, 3.0, rng)
    est = estimate_rig(faulty, scene.keypoints, scene.visible)
    assert est.faulty_views == [3, 6]
    assert all(est.cameras[v] is scene.cameras[v] for v in (0, 1, 2, 4, 5, 7))
    for v in (3, 6):
        h = est.health[v]
        assert "pose off" in h.faults[0]
        assert h.residual_px_after < h.residual_px_before - 0.5
        assert h.residual_px_after < 2.5  # labels carry 1.5 px noise per axis
        # The refined pose images the labelled points where the true one does.
        seen = scene.visible[v]
        moved = np.linalg.norm(est.cameras[v].project(scene.points[seen])
                               - scene.cameras[v].project(scene.points[seen]), axis=-1)
        assert moved.mean() < 0.5
    before = pose_change(scene.cameras[3], faulty[3])
    after = pose_change(scene.cameras[3], est.cameras[3])
    assert after[0] < before[0] and after[1] < before[1]


def test_depth_pins_the_poses_the_labels_leave_loose_and_keeps_scale_faults_apart() -> None:
    # Two views off in pose, a third's depth 1 % long: the pose views are re-posed against the
    # whole scene's depth (far closer to the truth than the hand's labels alone bring them),
    # the scale view keeps its pose and is named for its depth.
    scene = make_scene(frames=12, seed=2)
    rng = np.random.default_rng(7)
    faulty = list(scene.cameras)
    faulty[3] = perturbed(scene.cameras[3], 0.5, 5.0, rng)
    faulty[6] = perturbed(scene.cameras[6], 0.3, 3.0, rng)
    depth = list(scene.depth)
    depth[4] = np.clip(np.rint(depth[4] * 1.01), 0, 65535).astype(np.uint16)
    labels_only = estimate_rig(faulty, scene.keypoints, scene.visible)
    est = estimate_rig(faulty, scene.keypoints, scene.visible, depth, scene.color)
    assert est.faulty_views == [3, 4, 6]
    assert est.health[4].faults == ["depth scale +0.9 %"]
    assert all(est.cameras[v] is scene.cameras[v] for v in (0, 1, 2, 4, 5, 7))
    for v in (3, 6):
        deg, mm = pose_change(scene.cameras[v], est.cameras[v])
        assert deg < 0.1 and mm < 0.8
        assert mm < 0.5 * pose_change(scene.cameras[v], labels_only.cameras[v])[1]


def test_late_cameras_are_named_with_their_offset() -> None:
    scene = make_scene(seed=3)
    one_frame_late(scene, 2)
    one_frame_late(scene, 5)
    est = estimate_rig(scene.cameras, scene.keypoints, scene.visible)
    assert [h.time_offset_frames for h in est.health] == [0, 0, 1, 0, 0, 1, 0, 0]
    assert est.faulty_views == [2, 5]
    assert est.health[2].faults == ["1 frame late"]
    kp, vis = apply_time_offsets(scene.keypoints, scene.visible, [0, 0, 1, 0, 0, 1, 0, 0])
    assert np.allclose(kp[2, 3], scene.keypoints[2, 4]) and not vis[2, -1].any()


def test_half_of_a_small_rig_late_is_found_against_the_master() -> None:
    # 4 views, 2 late: judged one view at a time, the others split two against two and the
    # sound views look early; judged together, with the master's time held, they do not.
    scene = make_scene(seed=5, views=4)
    one_frame_late(scene, 1)
    one_frame_late(scene, 2)
    est = estimate_rig(scene.cameras, scene.keypoints, scene.visible)
    assert [h.time_offset_frames for h in est.health] == [0, 1, 1, 0]
    assert est.faulty_views == [1, 2]


def test_a_depth_scale_is_not_taken_for_a_move_along_the_axis() -> None:
    # 4 views; view 3's depth 1 % long and its labels 2 % too spread about the principal
    # point (what a move along its axis would show): a move along the axis and the depth
    # scale explain its depth alike, but the imported pose with the scale explains it at
    # least as well, so the view keeps its pose and is named for its depth.
    scene = make_scene(frames=12, seed=1, views=4)
    centre = scene.cameras[3].K[:2, 2]
    scene.keypoints[3] = centre + (scene.keypoints[3] - centre) * 1.02
    depth = list(scene.depth)
    depth[3] = np.clip(np.rint(depth[3] * 1.01), 0, 65535).astype(np.uint16)
    est = estimate_rig(scene.cameras, scene.keypoints, scene.visible, depth, scene.color)
    assert est.faulty_views == [3]
    assert est.health[3].faults == ["depth scale +0.9 %"]
    assert est.cameras[3] is scene.cameras[3]


def test_depth_scale_and_shift_are_found() -> None:
    scene = make_scene(frames=12, seed=4)
    depth = list(scene.depth)
    depth[4] = np.clip(np.rint(depth[4] * 1.01), 0, 65535).astype(np.uint16)
    shifted = np.zeros_like(depth[6])
    shifted[:, 3:, 2:] = depth[6][:, :-3, :-2]  # content moved 2 px right, 3 px down
    depth[6] = shifted
    est = estimate_rig(scene.cameras, scene.keypoints, scene.visible, depth, scene.color)
    assert est.faulty_views == [4, 6]
    assert est.health[4].depth_scale == pytest.approx(1.01, abs=0.002)
    assert est.health[6].depth_shift_px == (2, 3)
    assert abs(est.health[6].depth_scale - 1.0) < 0.002
    fixed = apply_depth_correction(depth[6], 0, 1.0, (2, 3))
    inner = (slice(None), slice(10, -10), slice(10, -10))
    assert np.array_equal(fixed[inner], scene.depth[6][inner])


def test_corrections_keep_missing_depth_missing_and_shift_time() -> None:
    maps = np.array([[[0, 1000], [2000, 3000]]], dtype=np.uint16)
    out = correct_depth(maps, 1.01, (0, 0))
    assert out[0, 0, 0] == 0 and out[0, 1, 1] == round(3000 / 1.01)
    track = np.arange(5.0)
    assert shift_frames(track, 1)[:4].tolist() == [1.0, 2.0, 3.0, 4.0]
    assert np.isnan(shift_frames(track, 1)[4])


def test_rig_health_refuses_bad_shapes() -> None:
    scene = make_scene(frames=4, seed=5)
    with pytest.raises(ValueError, match=r"keypoints must have shape \(V=8"):
        estimate_rig(scene.cameras, scene.keypoints[:3], scene.visible[:3])
    with pytest.raises(ValueError, match="at least 3 views"):
        estimate_rig(scene.cameras[:2], scene.keypoints[:2], scene.visible[:2])
    with pytest.raises(ValueError, match="at least one of 8 fixed"):
        refine_with_depth(scene.cameras, scene.cameras, tuple(range(8)), [], scene.keypoints)
    with pytest.raises(ValueError, match=r"pixels as \(V, F, P, 2\)"):
        refine_with_depth(scene.cameras, scene.cameras, (1,), [], scene.keypoints[0])
    with pytest.raises(ValueError, match=r"depth map must have shape \(240, 320\)"):
        depth_surface(scene.cameras[0], scene.depth[0], 8)
