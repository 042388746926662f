"""Track interpolation, completeness and suspicious-work checks (the golden vectors shared with
the annotation page's interpolate.js), and keyframe validation."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from worker.tracks import (
    STATE_INTERPOLATED,
    STATE_KEYFRAME,
    STATE_UNPLACED,
    DenseTrack,
    completeness,
    dense_track,
    parse_keyframe,
    suspicious,
    validate_keyframes,
)

GOLDEN_PATH = Path(__file__).resolve().parents[1] / "fixtures" / "interpolation_golden.json"
GOLDEN = json.loads(GOLDEN_PATH.read_text())


def as_golden(dense: DenseTrack) -> list[dict]:
    """The dense track in the golden file's form (null positions, bool visibility)."""
    out = []
    for (x, y, visible), state in zip(dense.values, dense.state_names(), strict=True):
        out.append(
            {
                "x": None if math.isnan(x) else float(x),
                "y": None if math.isnan(y) else float(y),
                "visible": bool(visible),
                "state": state,
            }
        )
    return out


def to_compact(keyframes: list[dict]) -> list[list]:
    return [[k["frame"], k["x"], k["y"], int(k["visible"])] for k in keyframes]


class TestDenseTrackGolden:
    @pytest.mark.parametrize("case", GOLDEN["dense_cases"], ids=lambda c: c["name"])
    def test_matches_golden_exactly(self, case):
        assert as_golden(dense_track(case["keyframes"], case["num_frames"])) == case["dense"]

    @pytest.mark.parametrize("case", GOLDEN["dense_cases"], ids=lambda c: c["name"])
    def test_compact_keyframes_give_the_same_track(self, case):
        compact = dense_track(to_compact(case["keyframes"]), case["num_frames"])
        assert as_golden(compact) == case["dense"]

    def test_golden_covers_the_required_cases(self):
        names = {c["name"] for c in GOLDEN["dense_cases"]}
        required = {
            "empty",
            "single keyframe",
            "two keyframes linear",
            "occluded span in the middle",
            "occluded keyframe without position",
            "fractional coordinates",
            "frames after last keyframe",
            "frame 0 not a keyframe",
        }
        assert required <= names


class TestDenseTrack:
    def test_shape_and_dtype(self):
        dense = dense_track([{"frame": 1, "x": 2.0, "y": 3.0, "visible": True}], 5)
        assert dense.values.shape == (5, 3)
        assert dense.values.dtype == np.float64
        assert dense.state.shape == (5,)
        assert dense.xy.shape == (5, 2)

    def test_unplaced_frames_are_nan_and_invisible(self):
        dense = dense_track([[2, 10.0, 20.0, 1]], 4)
        assert np.isnan(dense.values[:2, :2]).all()
        assert not dense.visible[:2].any()
        expected = [STATE_UNPLACED, STATE_UNPLACED, STATE_KEYFRAME, STATE_INTERPOLATED]
        assert list(dense.state) == expected

    def test_unsorted_input_is_sorted_by_frame(self):
        dense = dense_track([[4, 40.0, 0.0, 1], [0, 0.0, 0.0, 1]], 5)
        np.testing.assert_array_equal(dense.values[:, 0], [0.0, 10.0, 20.0, 30.0, 40.0])

    def test_empty_clip(self):
        assert dense_track([[0, 1.0, 1.0, 1]], 0).values.shape == (0, 3)

    def test_dict_without_xy_is_an_occluded_keyframe_without_position(self):
        dense = dense_track([{"frame": 0, "visible": False}], 2)
        assert np.isnan(dense.values[:, :2]).all()
        assert list(dense.state) == [STATE_KEYFRAME, STATE_INTERPOLATED]


class TestCompletenessGolden:
    @pytest.mark.parametrize("case", GOLDEN["completeness_cases"], ids=lambda c: c["name"])
    def test_matches_golden(self, case):
        result = completeness(case["tracks"], case["num_frames"], case["point_names"])
        assert result == {"complete": case["complete"], "problems": case["problems"]}

    def test_compact_tracks_are_accepted(self):
        tracks = [[[0, 1.5, 2.5, 1], [2, None, None, 0]]]
        assert completeness(tracks, 3, ["p"]) == {"complete": True, "problems": []}

    def test_missing_track_for_a_named_point_has_no_keyframes(self):
        result = completeness([[[0, 1.0, 1.0, 1]]], 2, ["a", "b"])
        expected = [{"point": 1, "frames": [[0, 1]], "message": "b: no keyframes"}]
        assert result["problems"] == expected


class TestSuspiciousGolden:
    @pytest.mark.parametrize("case", GOLDEN["suspicious_cases"], ids=lambda c: c["name"])
    def test_matches_golden(self, case):
        warnings = suspicious(case["tracks"], case["num_frames"], case["point_names"])
        assert warnings == case["warnings"]

    def test_no_points_no_warnings(self):
        assert suspicious([], 5) == []


class TestParseKeyframe:
    def test_dict_and_compact_forms_agree(self):
        a = parse_keyframe({"frame": 3, "x": 1, "y": 2.5, "visible": True})
        b = parse_keyframe([3, 1, 2.5, 1])
        assert a == b
        assert isinstance(a.x, float)

    @pytest.mark.parametrize(
        ("raw", "match"),
        [
            ([1, 2, 3], "expected"),
            ({"x": 1, "y": 1, "visible": True}, "missing frame"),
            ([1.5, 2, 3, 1], "frame must be an integer"),
            ([True, 2, 3, 1], "frame must be an integer"),
            ([1, "2", 3, 1], "x must be a number"),
            ([1, 2, None, 1], "both be numbers"),
            ([1, 2, 3, 2], "visible must be"),
        ],
    )
    def test_rejects_malformed(self, raw, match):
        with pytest.raises(ValueError, match=match):
            parse_keyframe(raw)


class TestValidateKeyframes:
    def test_valid_track_has_no_problems(self):
        keyframes = [[0, 0.0, 0.0, 1], [5, 639.99, 479.99, 1], [9, None, None, 0]]
        assert validate_keyframes(keyframes, 10, 640, 480) == []

    def test_frame_out_of_range_is_named(self):
        problems = validate_keyframes([[0, 1, 1, 1], [10, 1, 1, 1], [-1, 1, 1, 1]], 10, 640, 480)
        assert "keyframe 1 (frame 10): frame out of range 0-9" in problems
        assert "keyframe 2 (frame -1): frame out of range 0-9" in problems

    def test_duplicate_frame_is_named(self):
        problems = validate_keyframes([[2, 1, 1, 1], [2, 5, 5, 1]], 10, 640, 480)
        assert problems == ["keyframe 1 (frame 2): duplicate of keyframe 0 at the same frame"]

    def test_unsorted_frames_are_reported(self):
        problems = validate_keyframes([[5, 1, 1, 1], [2, 5, 5, 1]], 10, 640, 480)
        assert problems == ["keyframe 1 (frame 2): not sorted by frame (follows frame 5)"]

    @pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
    def test_non_finite_position_is_reported(self, bad):
        keyframe = {"frame": 0, "x": bad, "y": 3.0, "visible": True}
        problems = validate_keyframes([keyframe], 4, 640, 480)
        assert len(problems) == 1
        assert problems[0].startswith("keyframe 0 (frame 0): position (")
        assert "not finite" in problems[0]

    def test_position_outside_the_image_is_reported_per_axis(self):
        problems = validate_keyframes([[0, 640.0, -0.5, 0]], 4, 640, 480)
        assert problems == [
            "keyframe 0 (frame 0): x = 640 outside the image (0 <= x < 640)",
            "keyframe 0 (frame 0): y = -0.5 outside the image (0 <= y < 480)",
        ]

    def test_visible_keyframe_needs_a_position(self):
        problems = validate_keyframes([[3, None, None, 1]], 4, 640, 480)
        assert problems == ["keyframe 0 (frame 3): visible keyframe has no position"]

    def test_malformed_entry_is_named_and_others_still_checked(self):
        problems = validate_keyframes([[0, 1, 1], [1, 700, 1, 1]], 4, 640, 480)
        assert problems[0].startswith("keyframe 0 (frame 0): expected")
        assert problems[1] == "keyframe 1 (frame 1): x = 700 outside the image (0 <= x < 640)"

    def test_occluded_guess_must_still_be_inside_the_image(self):
        problems = validate_keyframes([[0, 10, 500, 0]], 4, 640, 480)
        assert problems == ["keyframe 0 (frame 0): y = 500 outside the image (0 <= y < 480)"]
