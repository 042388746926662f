"""QC scores a worker on what the worker decided (worker.quality.consensus, decide).

The scene: a ring of 4 calibrated cameras around a moving 21-joint hand, labelled by the
simulated careful annotator (worker.synth.annotators). A view "pre-filled" from the others
holds the reprojection of their consensus, every position a suggestion kept unchanged
(ViewLabels.decided False): it must neither make the others agree more nor be judged itself,
and a point only pre-filled views back is not judged at all. The check-suggestion rule of the
decision is tested on its own metrics.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.quality.test_qc_consensus import (
    camera_ring,
    make_label,
    moving_hand,
    truth_pixels,
)
from worker.quality.consensus import score_hand
from worker.quality.decide import QCThresholds, decide, learn_thresholds
from worker.quality.metrics import AssignmentQC
from worker.quality.view_labels import ViewLabels
from worker.tracks.sources import decided_mask

CAREFUL_VIEWS = (0, 1, 2)
NAMES = [f"joint {p}" for p in range(21)]
# Metrics compared between reports (every number a careful label is judged by).
JUDGED = ("median_error_px", "p90_error_px", "outlier_fraction", "raw_median_error_px",
          "reference_spread_px", "jitter_px", "motion_ratio", "scored_fraction",
          "moved_with_hand")


@pytest.fixture(scope="module")
def ring4():
    cams = camera_ring(4)
    truth = truth_pixels(cams, moving_hand())
    careful = [make_label(f"careful-{v}", v, truth, "careful", 10 + v) for v in CAREFUL_VIEWS]
    return cams, truth, careful


def _prefilled(key: str, view: int, xy: np.ndarray, decided: bool = False) -> ViewLabels:
    """A view whose every position is a suggestion: decided=False as the worker kept them."""
    frames, points = xy.shape[:2]
    return ViewLabels(key=key, view=view, xy=xy, visible=np.ones((frames, points), bool),
                      working_time_s=120.0, decided=np.full((frames, points), decided))


def _same(a: dict, b: dict) -> bool:
    return all((a[m] is None and b[m] is None)
               or (a[m] is not None and b[m] is not None and np.isclose(a[m], b[m], rtol=1e-6))
               for m in JUDGED)


def test_a_view_prefilled_from_the_others_does_not_make_them_agree_more(ring4) -> None:
    cams, _, careful = ring4
    alone = score_hand(cams, careful)
    # The pre-fill: the careful views' own consensus, reprojected into view 3.
    suggestion = cams[3].project(alone.consensus)
    kept = _prefilled("prefilled-3", 3, suggestion)
    with_prefill = score_hand(cams, [*careful, kept])
    for lab in careful:
        before = alone.assignments[lab.key]
        after = with_prefill.assignments[lab.key]
        assert _same(before.metrics, after.metrics), (before.metrics, after.metrics)
        assert np.allclose(np.array(before.per_frame, float), np.array(after.per_frame, float),
                           equal_nan=True)
    np.testing.assert_allclose(with_prefill.consensus, alone.consensus, atol=1e-6)  # 1 um
    assert (with_prefill.support <= 3).all()
    # Counted as the worker's own (no provenance), the copy backs every point as a fourth
    # view: the others' references tighten and the copy agrees with them by construction.
    counted = score_hand(cams, [*careful, ViewLabels("prefilled-3", 3, suggestion,
                                                     kept.visible, 120.0)])
    assert (counted.support == 4).mean() > 0.9
    for lab in careful:
        assert counted.assignments[lab.key].metrics["reference_spread_px"] \
            < 0.8 * alone.assignments[lab.key].metrics["reference_spread_px"]
    assert counted.assignments["prefilled-3"].metrics["median_error_px"] < 1.0


def test_a_view_of_unchanged_suggestions_is_not_judged_on_position(ring4) -> None:
    cams, truth, careful = ring4
    # A poor pre-fill, 25 px off every joint, that the worker kept: no evidence either way.
    kept = _prefilled("prefilled-3", 3, truth[3] + np.array([25.0, 0.0]))
    report = score_hand(cams, [*careful, kept])
    qc = report.assignments["prefilled-3"]
    for name in ("median_error_px", "p90_error_px", "outlier_fraction", "jitter_px",
                 "motion_ratio", "track_jitter_px", "moved_with_hand"):
        assert qc.metrics[name] is None, (name, qc.metrics[name])
    assert qc.metrics["scored_fraction"] == 0.0 and qc.metrics["decided_fraction"] == 0.0
    assert qc.metrics["completeness"] == 1.0
    assert qc.issues == [] and qc.swaps == [] and not qc.provisional
    assert all(v is None for v in qc.per_joint + qc.per_frame)
    thresholds = learn_thresholds([a.metrics for a in report.assignments.values()])
    decision = decide(qc, thresholds, NAMES)
    assert decision.outcome == "review"
    assert decision.reasons == [("decided nothing: every position came from suggestions "
                                 "unchanged")]
    assert "suggestion left unchanged" in decision.feedback
    for lab in careful:
        assert decide(report.assignments[lab.key], thresholds, NAMES).outcome == "approve"
    # The same positions sent as the worker's own are 25 px off: judged, and caught.
    own = score_hand(cams, [*careful, ViewLabels("own-3", 3, kept.xy, kept.visible, 120.0)])
    assert own.assignments["own-3"].metrics["median_error_px"] > 15.0
    assert decide(own.assignments["own-3"], thresholds, NAMES).outcome == "reject"


def test_marking_covered_suggestions_hidden_is_a_decision(ring4) -> None:
    cams, truth, careful = ring4
    # Every visible position kept as suggested, but the worker hid the ones it saw covered
    # (its own keyframes, "edited"): not a label that decided nothing.
    kept = _prefilled("prefilled-3", 3, truth[3])
    report = score_hand(cams, [*careful, kept])
    qc = report.assignments["prefilled-3"]
    assert qc.metrics["decided_fraction"] == 0.0
    thresholds = learn_thresholds([a.metrics for a in report.assignments.values()])
    qc.metrics["own_keyframes"] = 0
    assert decide(qc, thresholds, NAMES).reasons[0].startswith("decided nothing")
    qc.metrics["own_keyframes"] = 6
    decision = decide(qc, thresholds, NAMES)
    assert not any(r.startswith("decided nothing") for r in decision.reasons)
    assert "suggestion left unchanged" not in decision.feedback
    assert decision.outcome == "approve", decision.reasons


def test_the_consensus_reads_only_the_decided_positions_of_a_label(ring4) -> None:
    cams, truth, careful = ring4
    worker = make_label("mixed-3", 3, truth, "careful", 13)
    # Frames 18.. came from a pre-fill 40 px off that the worker kept unchanged.
    xy = worker.xy.copy()
    xy[18:] = truth[3, 18:] + np.array([0.0, 40.0])
    decided = np.ones(worker.visible.shape, bool)
    decided[18:] = False
    mixed = ViewLabels("mixed-3", 3, xy, worker.visible, 120.0, decided)
    report = score_hand(cams, [*careful, mixed])
    qc = report.assignments["mixed-3"]
    assert (report.support[18:] <= 3).all()
    assert (report.support[:18] == 4).mean() > 0.9
    assert all(v is None for v in qc.per_frame[18:])
    assert all(v is not None and v < 5.0 for v in qc.per_frame[:18])
    assert qc.metrics["outlier_fraction"] == 0.0 and qc.issues == []
    assert qc.metrics["decided_fraction"] == pytest.approx(0.5)
    thresholds = learn_thresholds([a.metrics for a in report.assignments.values()])
    assert decide(qc, thresholds, NAMES).outcome == "approve"
    # The consensus there is the careful views' alone: within a few px of the truth.
    err = np.linalg.norm(cams[0].project(report.consensus[18:]) - truth[0, 18:], axis=-1)
    assert np.nanmedian(err) < 3.0
    # Sent as the worker's own, the 40 px frames are far off.
    own = score_hand(cams, [*careful, ViewLabels("mixed-3", 3, xy, worker.visible, 120.0)])
    assert own.assignments["mixed-3"].metrics["outlier_fraction"] > 0.3


def test_points_backed_only_by_prefilled_views_are_not_judged(ring4) -> None:
    cams, truth, careful = ring4
    pair = careful[:2]
    pre = [_prefilled(f"prefilled-{v}", v, truth[v]) for v in (2, 3)]
    report = score_hand(cams, [*pair, *pre])
    assert report.provisional
    assert (report.support <= 2).all()
    for lab in pair:
        qc = report.assignments[lab.key]
        assert qc.metrics["scored_fraction"] == 0.0 and qc.metrics["median_error_px"] is None
        assert qc.provisional
    # Counted as decided, the same pre-fills would make a 4-view verdict on the pair.
    counted = score_hand(cams, [*pair, *(_prefilled(p.key, p.view, p.xy, True) for p in pre)])
    assert not counted.provisional
    assert all(counted.assignments[lab.key].metrics["scored_fraction"] > 0.9 for lab in pair)


def test_decided_mask_of_stored_rows_follows_the_sources() -> None:
    rows = [[0, 10.0, 10.0, 1, "prefilled"], [4, 14.0, 10.0, 1, "prefilled"],
            [8, 18.0, 10.0, 1, "edited"], [12, 22.0, 10.0, 1, "tracked"],
            [14, 24.0, 10.0, 1, "prefilled"]]
    mask = decided_mask(rows, 18)
    expected = [False] * 5 + [True] * 9 + [False] * 4
    assert mask.tolist() == expected
    assert decided_mask([[3, 1.0, 1.0, 1]], 6).tolist() == [False] * 3 + [True] * 3


def _qc(accepted: int | None, corrected: int | None, provisional: bool = False) -> AssignmentQC:
    metrics: dict[str, float | None] = {"median_error_px": 1.7, "p90_error_px": 3.2,
                                        "outlier_fraction": 0.0, "completeness": 1.0,
                                        "working_time_s": 150.0, "decided_fraction": 0.6}
    if accepted is not None:
        metrics["checks_accepted"], metrics["checks_corrected"] = accepted, corrected
    return AssignmentQC(key="a", view=0, metrics=metrics, per_joint=[], per_frame=[],
                        provisional=provisional)


@pytest.mark.parametrize(("accepted", "corrected", "outcome"), [
    (None, None, "approve"),  # no provenance: as before
    (0, 0, "approve"),  # no suggestion met a check cell
    (0, 4, "approve"),  # corrected every one
    (1, 3, "review"),  # a slip among corrected ones
    (1, 0, "review"),  # the only one met, kept
    (2, 2, "reject"),
    (4, 0, "reject"),  # accepts everything
])
def test_check_suggestions_kept_unchanged_flag_the_worker(accepted, corrected, outcome) -> None:
    thresholds = learn_thresholds([], QCThresholds())
    decision = decide(_qc(accepted, corrected), thresholds, NAMES)
    assert decision.outcome == outcome, decision.reasons
    kept = [r for r in decision.reasons if "check suggestions" in r]
    assert len(kept) == (1 if outcome != "approve" else 0)
    if outcome == "approve":
        assert decision.feedback.startswith("Thank you")


def test_a_blind_acceptor_is_told_why() -> None:
    thresholds = learn_thresholds([], QCThresholds())
    decision = decide(_qc(4, 0), thresholds, NAMES)
    assert decision.reasons == [
        ("accepted 4 of 4 check suggestions unchanged (each shown 15 px off the point): "
         "suggestions were accepted without looking")]
    assert "You kept 4 suggested position(s) that were shown 15 px off" in decision.feedback
    # Never rejected while provisional: an admin looks instead.
    assert decide(_qc(4, 0, provisional=True), thresholds, NAMES).outcome == "review"


class TestObjectLandmarks:
    """The same rule for object landmarks (worker.quality.landmarks): 2 landmarks riding on a
    disc that moves 3 px per frame, 320x240."""

    @staticmethod
    def _scene():
        from worker.geometry.cameras import CameraModel, intrinsics_matrix, look_at

        frames = 30
        pose = look_at(np.array([0.0, -0.6, 0.3]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
        camera = CameraModel(intrinsics_matrix(300.0, 300.0, 160.0, 120.0), None, pose, 320, 240)
        centres = np.stack([80.0 + 3.0 * np.arange(frames), np.full(frames, 120.0)], axis=1)
        rows, cols = np.mgrid[0:240, 0:320]
        masks = {f: (cols - c[0]) ** 2 + (rows - c[1]) ** 2 <= 30 ** 2
                 for f, c in enumerate(centres)}
        riding = centres[:, None, :] + np.array([[-12.0, -5.0], [10.0, 8.0]])[None]
        return camera, masks, riding

    @staticmethod
    def _label(key: str, xy: np.ndarray, decided: bool | None = None) -> ViewLabels:
        shape = xy.shape[:2]
        return ViewLabels(key=key, view=0, xy=xy, visible=np.ones(shape, bool),
                          working_time_s=40.0,
                          decided=None if decided is None else np.full(shape, decided))

    def test_landmarks_of_unchanged_suggestions_are_not_judged_against_the_outline(self):
        from worker.quality.landmarks import score_landmarks

        camera, masks, riding = self._scene()
        off = riding + np.array([60.0, 0.0])  # a pre-fill 60 px off the object, kept
        own = score_landmarks(camera, self._label("own", off), masks)
        assert own.metrics["median_error_px"] > 20.0 and own.issues
        kept = score_landmarks(camera, self._label("kept", off, decided=False), masks)
        assert kept.metrics["median_error_px"] is None and kept.metrics["outlier_fraction"] is None
        assert not [i for i in kept.issues if i["about"] == "silhouette"]
        assert kept.metrics["decided_fraction"] == 0.0 and not kept.provisional
        thresholds = learn_thresholds([own.metrics, kept.metrics])
        assert decide(kept, thresholds, ["a", "b"]).outcome == "review"

    def test_a_label_of_suggestions_alone_does_not_witness_the_objects_motion(self):
        from worker.quality.landmarks import score_object

        camera, _, riding = self._scene()
        frozen = np.broadcast_to(riding[5], riding.shape).copy()
        labels = [self._label("careful", riding), self._label("frozen", frozen),
                  self._label("pre-filled", riding + 0.5, decided=False)]
        # Only one worker's own track shows the object moving: too few witnesses to judge.
        scored = score_object([camera], labels)
        assert scored["frozen"].metrics["moved_with_object"] is None
        # Counted as the worker's own, the copy would be the second witness.
        labels[2] = self._label("pre-filled", riding + 0.5)
        assert score_object([camera], labels)["frozen"].metrics["moved_with_object"] < 0.1


def _prefilled_label(decided: float, **metrics: float) -> AssignmentQC:
    """A label whose worker decided ``decided`` of its positions, with the metrics measured on
    those positions alone."""
    base = {"median_error_px": 2.0, "p90_error_px": 4.0, "outlier_fraction": 0.0,
            "jitter_px": 1.5, "motion_ratio": 1.0, "occluded_on_surface": 0.0,
            "moved_with_hand": 0.8, "completeness": 1.0, "working_time_s": 150.0,
            "decided_fraction": decided, "checks_accepted": 0, "checks_corrected": 4}
    base.update(metrics)
    return AssignmentQC(key="a", view=0, metrics=base, per_joint=[], per_frame=[])


# What a careful worker's corrections of a mostly right pre-fill measure (bench/assist.py, 8
# views): the few positions it decided are where the suggestions were off.
BIASED = {"motion_ratio": 0.3, "jitter_px": 6.3, "occluded_on_surface": 0.9,
          "moved_with_hand": 0.15, "median_error_px": 2.9}


def test_a_mostly_prefilled_label_is_judged_by_its_checks_not_its_corrections() -> None:
    thresholds = learn_thresholds([], QCThresholds())
    decision = decide(_prefilled_label(0.08, **BIASED), thresholds, NAMES)
    assert decision.outcome == "approve", decision.reasons
    assert decision.reasons == [("mostly pre-filled (8% of positions the worker's own): "
                                 "judged by its check suggestions, swaps and gross errors")]
    # The same corrections on a label the worker mostly made are judged as ever.
    assert decide(_prefilled_label(0.9, **BIASED), thresholds, NAMES).outcome == "reject"
    # Kept check suggestions and gross errors of its own positions still count.
    kept = decide(_prefilled_label(0.08, checks_accepted=3, checks_corrected=1, **BIASED),
                  thresholds, NAMES)
    assert kept.outcome == "reject"
    gross = dict(BIASED, median_error_px=40.0)
    assert decide(_prefilled_label(0.08, **gross), thresholds, NAMES).outcome == "reject"


def test_mostly_prefilled_labels_do_not_set_the_thresholds() -> None:
    careful = [_prefilled_label(1.0, motion_ratio=float(m)).metrics
               for m in np.linspace(0.9, 1.1, 20)]
    biased = [_prefilled_label(0.1, **BIASED).metrics for _ in range(40)]
    assert learn_thresholds(careful + biased) == learn_thresholds(careful)
