"""worker.solver.follow: the hand model carried through one view's depth from a worker's
keyframes, for a view no other view can suggest for.

On a rendered synthetic capture (seed 5, 2 views x 72 frames at 640x480, the pace of the
default clips; depth with sensor noise and dropouts), the first FRAMES frames of view 1: a
careful worker's keyframes of one frame (2 px noise) start the follow, and its proposals are
compared with the view's true joints.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.solver.test_solver_suggest import Scene
from worker.solver.follow import STOP_DEPTH, follow_hand

VIEW = 1
# Frames followed: each takes about a second of CPU.
FRAMES = 8


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Scene:
    from worker.synth import generate_capture

    root = tmp_path_factory.mktemp("follow-capture")
    generate_capture(root, seed=5, frames=72, views=2, objects=1, workers=1)
    return Scene(root)


def _first_frame_keys(scene: Scene, frame: int = 0, shift: tuple[float, float] = (0.0, 0.0),
                      seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A careful worker's keyframes of one frame of VIEW: (F, 21, 2) px and (F, 21) keyed."""
    truth, visible = scene.xy[VIEW][:FRAMES], scene.visible[VIEW][:FRAMES]
    keypoints = np.full(truth.shape, np.nan)
    keyed = np.zeros(visible.shape, bool)
    noise = np.random.default_rng(seed).normal(0.0, 2.0, truth[frame].shape)
    keypoints[frame] = truth[frame] + noise + np.asarray(shift)
    keyed[frame] = visible[frame]
    return keypoints, keyed


def _follow(scene: Scene, keypoints: np.ndarray, keyed: np.ndarray, **kw):
    return follow_hand(scene.cameras[VIEW], scene.depth[VIEW][:FRAMES], keypoints, keyed,
                       scene.side, scene.betas, **kw)


def test_a_hand_keyed_once_is_followed_through_the_clip_close_to_the_truth(
        scene: Scene) -> None:
    keypoints, keyed = _first_frame_keys(scene)
    found = _follow(scene, keypoints, keyed)
    truth, visible = scene.xy[VIEW][:FRAMES], scene.visible[VIEW][:FRAMES]
    later = np.zeros(visible.shape, bool)
    later[1:] = visible[1:]
    # Proposed on most of the later frames' visible joints, where tracking image patches of
    # skin loses most of them.
    assert (found.ok & later).sum() >= 0.8 * later.sum(), found.stops
    err = np.linalg.norm(found.xy - truth, axis=-1)[found.ok & later]
    assert np.median(err) < 2.0, np.median(err)
    assert np.percentile(err, 90) < 5.0, np.percentile(err, 90)
    assert found.start == 0
    assert np.isfinite(found.depth_rms_mm[found.ok.any(axis=1)]).all()


def test_a_keyed_frame_without_depth_gives_no_proposals(scene: Scene) -> None:
    # The sensor read nothing at the keyed frame: there is no surface to put the hand on.
    keypoints, keyed = _first_frame_keys(scene)
    depth = scene.depth[VIEW][:FRAMES].copy()
    depth[0] = 0
    found = follow_hand(scene.cameras[VIEW], depth, keypoints, keyed, scene.side, scene.betas)
    assert not found.ok.any()
    assert found.stops["forward"] == (0, STOP_DEPTH)


def test_a_correction_proposes_from_its_frame_on_close_to_the_truth(scene: Scene) -> None:
    # The worker keyed frame 0, then frame 4 again, and asks from frame 3: the follow is
    # carried from frame 0 through frame 4's keys and started afresh at frame 4, and the one
    # the depth fits better proposes, from frame 3 on only.
    keypoints, keyed = _first_frame_keys(scene)
    later_keys, later_keyed = _first_frame_keys(scene, frame=4, seed=1)
    keypoints[4], keyed[4] = later_keys[4], later_keyed[4]
    found = _follow(scene, keypoints, keyed, begin=3)
    assert found.start in (0, 4)
    assert not found.ok[:3].any()
    assert found.ok[5:].all()
    assert "backward" not in found.stops
    truth, visible = scene.xy[VIEW][:FRAMES], scene.visible[VIEW][:FRAMES]
    err = np.linalg.norm(found.xy[5:] - truth[5:], axis=-1)[visible[5:]]
    assert np.median(err) < 2.0, np.median(err)


def test_a_correction_starts_at_its_own_frame_where_the_first_start_is_refused(
        scene: Scene) -> None:
    # No depth at frame 0: the first start is refused, so the follow starts from the first
    # frame keyed whole at or after ``begin``.
    keypoints, keyed = _first_frame_keys(scene)
    later_keys, later_keyed = _first_frame_keys(scene, frame=4, seed=1)
    keypoints[4], keyed[4] = later_keys[4], later_keyed[4]
    depth = scene.depth[VIEW][:FRAMES].copy()
    depth[0] = 0
    found = follow_hand(scene.cameras[VIEW], depth, keypoints, keyed, scene.side, scene.betas,
                        begin=3)
    assert found.start == 4
    assert not found.ok[:4].any()
    assert found.ok[5:].all()
    assert "backward" not in found.stops


def test_a_correction_the_carried_follow_does_not_sit_on_starts_at_the_corrected_frame(
        scene: Scene) -> None:
    # Frame 4 keyed 20 px off the hand the depth holds: the follow carried from frame 0 does
    # not sit on those keys (over MAX_START_PX), so only the start from frame 4's keys is
    # left.
    keypoints, keyed = _first_frame_keys(scene)
    later_keys, later_keyed = _first_frame_keys(scene, frame=4, seed=1, shift=(20.0, 0.0))
    keypoints[4], keyed[4] = later_keys[4], later_keyed[4]
    found = _follow(scene, keypoints, keyed, begin=3)
    assert found.start == 4
    assert not found.ok[:4].any()


def test_too_few_keyed_joints_or_wrong_shapes_are_refused(scene: Scene) -> None:
    keypoints, keyed = _first_frame_keys(scene)
    keyed[0, 5:] = False  # 5 joints: the model cannot start
    assert _follow(scene, keypoints, keyed).start == -1
    with pytest.raises(ValueError, match="expected keypoints"):
        _follow(scene, keypoints[:, :20], keyed[:, :20])
    with pytest.raises(ValueError, match="depth has"):
        follow_hand(scene.cameras[VIEW], scene.depth[VIEW][:5], keypoints, keyed,
                    scene.side, scene.betas)
