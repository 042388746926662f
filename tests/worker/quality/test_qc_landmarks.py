"""worker.quality.landmarks: one object-landmark label against its silhouette and its own motion."""

from __future__ import annotations

import json

import numpy as np
import pytest

from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at
from worker.quality.decide import decide, learn_thresholds
from worker.quality.landmarks import score_landmarks, score_object
from worker.quality.view_labels import ViewLabels

FRAMES, WIDTH, HEIGHT = 30, 320, 240
RADIUS = 30


@pytest.fixture(scope="module")
def camera() -> CameraModel:
    pose = look_at(np.array([0.0, -0.6, 0.3]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
    return CameraModel(intrinsics_matrix(300.0, 300.0, 160.0, 120.0), None, pose, WIDTH, HEIGHT)


def _centres() -> np.ndarray:
    """(F, 2) px: the object's silhouette centre moving 3 px per frame to the right."""
    return np.stack([80.0 + 3.0 * np.arange(FRAMES), np.full(FRAMES, 120.0)], axis=1)


@pytest.fixture(scope="module")
def masks() -> dict[int, np.ndarray]:
    """A disc silhouette per frame."""
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    return {f: (cols - c[0]) ** 2 + (rows - c[1]) ** 2 <= RADIUS ** 2
            for f, c in enumerate(_centres())}


def _label(xy: np.ndarray, key: str = "w") -> ViewLabels:
    return ViewLabels(key=key, view=0, xy=xy, visible=np.ones(xy.shape[:2], bool),
                      working_time_s=40.0)


def _careful(seed: int = 0) -> np.ndarray:
    """(F, 2, 2) two landmarks riding on the object, 1 px noise."""
    offsets = np.array([[-12.0, -5.0], [10.0, 8.0]])
    xy = _centres()[:, None, :] + offsets[None]
    return xy + np.random.default_rng(seed).normal(0.0, 1.0, xy.shape)


class TestScoreLandmarks:
    def test_careful_landmarks_sit_on_the_silhouette_and_move_with_it(self, camera, masks):
        qc = score_landmarks(camera, _label(_careful()), masks)
        m = qc.metrics
        assert m["median_error_px"] == 0.0 and m["outlier_fraction"] == 0.0
        assert m["jump_fraction"] == 0.0 and 0.8 < m["motion_ratio"] < 1.3
        assert m["static_fraction"] == 0.0 and m["completeness"] == 1.0
        assert not qc.issues and not qc.provisional
        assert len(qc.per_joint) == 2 and len(qc.per_frame) == FRAMES

    def test_landmarks_off_the_object_are_measured_in_pixels(self, camera, masks):
        xy = _careful()
        xy[:, 1] = _centres() + [RADIUS + 20.0, 0.0]  # 20 px right of the disc's edge
        qc = score_landmarks(camera, _label(xy), masks)
        assert 19.0 <= qc.per_joint[1] <= 21.0 and qc.per_joint[0] == 0.0
        assert qc.metrics["outlier_fraction"] == pytest.approx(0.5)
        assert qc.issues[0]["about"] == "silhouette" and qc.issues[0]["point"] == 1

    def test_frozen_landmarks_are_static_and_do_not_follow_the_object(self, camera, masks):
        xy = np.broadcast_to(_careful()[5], (FRAMES, 2, 2)).copy()
        qc = score_landmarks(camera, _label(xy), masks)
        assert qc.metrics["static_fraction"] == 1.0 and qc.metrics["motion_ratio"] == 0.0

    def test_exchanged_landmarks_show_as_jumps(self, camera, masks):
        xy = _careful()
        xy[12:] = xy[12:, ::-1]  # the worker swaps the two landmarks from frame 12 on
        qc = score_landmarks(camera, _label(xy), masks)
        jumps = [i for i in qc.issues if i["about"] == "jump"]
        assert {tuple(i["frames"]) for i in jumps} == {(11, 12)}
        assert {i["point"] for i in jumps} == {0, 1} and qc.metrics["jump_fraction"] > 0
        assert qc.metrics["max_step_ratio"] > 6.0

    def test_without_masks_only_the_label_itself_is_judged(self, camera):
        qc = score_landmarks(camera, _label(_careful()))
        assert qc.metrics["median_error_px"] is None and qc.metrics["motion_ratio"] is None
        assert qc.metrics["jump_fraction"] == 0.0 and qc.provisional

    def test_result_is_json_friendly(self, camera, masks):
        xy = _careful()
        xy[3:6, 0] = np.nan
        text = json.dumps(score_landmarks(camera, _label(xy), masks).to_dict(), allow_nan=False)
        assert '"completeness"' in text

    def test_mask_of_the_wrong_size_raises_naming_its_shape(self, camera):
        with pytest.raises(ValueError, match=r"masks\[2\].*\(10, 10\)"):
            score_landmarks(camera, _label(_careful()), {2: np.zeros((10, 10), bool)})

    def test_label_shape_mismatch_raises(self, camera):
        bad = ViewLabels("w", 0, np.zeros((FRAMES, 2, 3)), np.ones((FRAMES, 2), bool))
        with pytest.raises(ValueError, match=r"\(30, 2, 3\)"):
            score_landmarks(camera, bad)


class TestLandmarkDecision:
    def test_careful_tracks_pass_and_exchanged_landmarks_go_to_review(self, camera, masks):
        pool = [score_landmarks(camera, _label(_careful(seed), f"w{seed}"), masks)
                for seed in range(10)]
        swapped = _careful(99)
        swapped[12:] = swapped[12:, ::-1]
        bad = score_landmarks(camera, _label(swapped, "bad"), masks)
        learned = learn_thresholds([qc.metrics for qc in pool + [bad]])
        names = ["landmark 1", "landmark 2"]
        assert all(decide(qc, learned, names).outcome == "approve" for qc in pool)
        decision = decide(bad, learned, names)
        assert decision.outcome == "review"
        assert "the landmark 1 jumped" in decision.feedback


def _lifted(seed: int, scale: float = 1.0) -> np.ndarray:
    """(F, 2, 2) landmarks of an object resting for 10 frames, then lifted 6 px per frame
    (``scale`` times that in this view), 1 px click noise."""
    centre = np.stack([np.full(FRAMES, 150.0),
                       120.0 - scale * 6.0 * np.clip(np.arange(FRAMES) - 10, 0, None)], axis=1)
    xy = centre[:, None, :] + np.array([[-12.0, -5.0], [10.0, 8.0]])[None]
    return xy + np.random.default_rng(seed).normal(0.0, 1.0, xy.shape)


class TestScoreObject:
    """Several views' labels of one object: each judged against the motion the others show."""

    def _views(self, camera: CameraModel, extra: ViewLabels) -> list:
        views = [ViewLabels(key=f"v{i}", view=0, xy=_lifted(i, scale), visible=np.ones((FRAMES, 2),
                            bool)) for i, scale in enumerate((1.0, 0.6, 1.5, 0.8))]
        return [*views, extra]

    def test_a_frozen_track_of_a_lifted_object_is_rejected(self, camera):
        frozen = np.repeat(_lifted(9)[:1], FRAMES, axis=0)
        labels = self._views(camera, _label(frozen, key="lazy"))
        scored = score_object([camera], labels)
        assert scored["lazy"].metrics["moved_with_object"] == 0.0
        assert all(scored[f"v{i}"].metrics["moved_with_object"] > 0.5 for i in range(4))
        thresholds = learn_thresholds([qc.metrics for qc in scored.values()])
        decision = decide(scored["lazy"], thresholds, ["landmark 1", "landmark 2"])
        assert decision.outcome == "reject", decision.reasons
        assert "as far as the object does" in decision.feedback
        assert decide(scored["v1"], thresholds, ["a", "b"]).outcome == "approve"

    def test_landmarks_hidden_while_the_object_moves_are_not_called_frozen(self, camera):
        # A careful label whose landmarks the hand covers from the lift on: it shows them at
        # rest only, so it cannot show the motion; it is not judged by it (the frozen copy,
        # which shows them throughout, still is).
        hidden = _lifted(7)
        visible = np.ones((FRAMES, 2), bool)
        visible[12:] = False
        hidden[12:] = np.nan
        covered = ViewLabels(key="covered", view=0, xy=hidden, visible=visible,
                             working_time_s=40.0)
        scored = score_object([camera], self._views(camera, covered))
        assert scored["covered"].metrics["moved_with_object"] is None
        thresholds = learn_thresholds([qc.metrics for qc in scored.values()])
        assert decide(scored["covered"], thresholds, ["a", "b"]).outcome != "reject"

    def test_the_object_s_own_motion_is_not_a_jump(self, camera):
        labels = self._views(camera, _label(_lifted(5, 2.0), key="fast"))
        scored = score_object([camera], labels)
        assert scored["fast"].metrics["jump_fraction"] == 0.0
        swapped = _lifted(6)
        swapped[15:20] = swapped[15:20, ::-1]
        labels = self._views(camera, _label(swapped, key="swap"))
        assert score_object([camera], labels)["swap"].metrics["jump_fraction"] > 0.0

    def test_a_landmark_hidden_through_the_lift_does_not_jump_where_it_was_hidden(self, camera):
        # A fast lift (15 px a frame in this view, 12-18 in the others). The hand covers
        # landmark 2 from frame 8, before the lift, to frame 18: the track as stored runs
        # straight from where it was last shown to where it is shown again, 11 px a frame
        # while the object still rests (frames 8-10). Those in-betweens are no steps the
        # worker placed.
        others = [ViewLabels(key=f"v{i}", view=0, xy=_lifted(i, scale),
                             visible=np.ones((FRAMES, 2), bool))
                  for i, scale in enumerate((2.0, 2.5, 3.0, 2.2))]
        xy = _lifted(8, 2.5)
        visible = np.ones((FRAMES, 2), bool)
        visible[8:19, 1] = False
        xy[8:19, 1] = xy[7, 1] + (xy[19, 1] - xy[7, 1]) * (np.arange(8, 19) - 7)[:, None] / 12
        covered = ViewLabels(key="covered", view=0, xy=xy, visible=visible,
                             working_time_s=40.0)
        scored = score_object([camera], [*others, covered])
        assert scored["covered"].metrics["jump_fraction"] == 0.0
        assert not [i for i in scored["covered"].issues if i.get("about") == "jump"]
        # Shown all along, the same track slides 11 px a frame over the resting object: jumps
        # (as the hidden one read before).
        visible[8:19, 1] = True
        shown = ViewLabels(key="shown", view=0, xy=xy, visible=visible, working_time_s=40.0)
        assert score_object([camera], [*others, shown])["shown"].metrics[
            "jump_fraction"] > 0.0

    def test_a_lift_no_other_view_shows_yet_is_not_a_jump(self, camera):
        # The first view of an object scored alone: it rests for 20 frames, then is lifted
        # faster and faster (5 to 30 px a frame). Its own typical step is the resting clicks'
        # noise, so every step of the lift is over 6 times that; none stands out from the
        # steps beside it.
        frames = np.arange(FRAMES)
        rise = np.cumsum(np.clip(5.0 * (frames - 20), 0, 30))
        xy = np.repeat(_lifted(3)[:1], FRAMES, axis=0) \
            + np.random.default_rng(3).normal(0.0, 1.0, (FRAMES, 2, 2))
        xy[..., 1] -= rise[:, None]
        alone = score_object([camera], [_label(xy, key="first")])["first"]
        assert alone.metrics["jump_fraction"] == 0.0, alone.issues
        # The same track with landmark 1 placed 30 px off in one frame of the lift (15 px a
        # frame there), and with the two landmarks swapped from frame 15 on, at rest: jumps.
        wrong = xy.copy()
        wrong[23, 0] += [30.0, 0.0]
        issues = score_object([camera], [_label(wrong, key="w")])["w"].issues
        assert {(i["point"], *i["frames"]) for i in issues if i["about"] == "jump"} \
            == {(0, 22, 23), (0, 23, 24)}
        swapped = xy.copy()
        swapped[15:] = swapped[15:, ::-1]
        issues = score_object([camera], [_label(swapped, key="s")])["s"].issues
        assert {(i["point"], *i["frames"]) for i in issues if i["about"] == "jump"} \
            == {(0, 14, 15), (1, 14, 15)}

    @pytest.mark.parametrize("how", ["suggested", "hidden"])
    def test_where_no_other_label_shows_the_lift_it_is_not_a_jump(self, camera, how):
        # The other views show the object at rest, then nothing: their workers kept
        # suggestions through the lift (positions that are not their own), or the hand hid
        # their landmarks (the stored positions stay where they were last shown). This view's
        # careful track of the lift (12 px a frame) is judged against its own steps there, not
        # against a motion of zero; its landmarks swapped during the lift still jump.
        shown, decided = np.ones((FRAMES, 2), bool), np.ones((FRAMES, 2), bool)
        (decided if how == "suggested" else shown)[11:] = False
        others = []
        for i, scale in enumerate((1.0, 0.6, 1.5, 0.8)):
            xy = _lifted(i, scale)
            if how == "hidden":
                xy[11:] = xy[10]
            others.append(ViewLabels(key=f"v{i}", view=0, xy=xy, visible=shown,
                                     decided=decided))
        scored = score_object([camera], [*others, _label(_lifted(5, 2.0), key="lift")])
        assert scored["lift"].metrics["jump_fraction"] == 0.0, scored["lift"].issues
        swapped = _lifted(6, 2.0)
        swapped[20:] = swapped[20:, ::-1]
        scored = score_object([camera], [*others, _label(swapped, key="swap")])
        assert {tuple(i["frames"]) for i in scored["swap"].issues if i["about"] == "jump"} \
            == {(19, 20)}

    def test_a_view_that_sees_the_lift_larger_is_judged_at_its_scale(self, camera):
        # A camera near the object sees the lift at 3.5 times the others' median step (21 px
        # a frame against 6): the others' step times 3 would call each of its steps a jump.
        others = [ViewLabels(key=f"v{i}", view=0, xy=_lifted(i, scale),
                             visible=np.ones((FRAMES, 2), bool))
                  for i, scale in enumerate((0.8, 1.0, 1.0, 1.2))]
        scored = score_object([camera], [*others, _label(_lifted(5, 3.5), key="near")])
        assert scored["near"].metrics["jump_fraction"] == 0.0, scored["near"].issues
        # Its landmarks swapped at rest, or moved 40 px in one frame of the lift: jumps.
        swapped = _lifted(6, 3.5)
        swapped[5:] = swapped[5:, ::-1]
        wrong = _lifted(7, 3.5)
        wrong[20, 1] += [40.0, 0.0]
        scored = score_object([camera], [*others, _label(swapped, key="swap"),
                                          _label(wrong, key="wrong")])
        assert {tuple(i["frames"]) for i in scored["swap"].issues if i["about"] == "jump"} \
            == {(4, 5)}
        assert {tuple(i["frames"]) for i in scored["wrong"].issues if i["about"] == "jump"} \
            == {(19, 20), (20, 21)}

    def test_a_still_object_is_not_judged_by_motion(self, camera):
        still = [ViewLabels(key=f"s{i}", view=0, xy=np.repeat(_lifted(i)[:1], FRAMES, axis=0),
                            visible=np.ones((FRAMES, 2), bool)) for i in range(4)]
        scored = score_object([camera], still)
        assert all(qc.metrics["moved_with_object"] is None for qc in scored.values())
