"""Track interpolation, completeness and suspicious-work checks (the golden vectors shared with
the annotation page's interpolate.js), and keyframe validation."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from worker.tracks.interpolate import (
    STATE_INTERPOLATED,
    STATE_KEYFRAME,
    STATE_UNPLACED,
    DenseTrack,
    dense_track,
)
from worker.tracks.keyframes import Keyframe, parse_keyframe
from worker.tracks.readiness import completeness, suspicious
from worker.tracks.sources import SOURCE_NAMES, decided_mask, keyframe_sources, own_keyframes
from worker.tracks.validate import checked_rows, validate_keyframes

GOLDEN_PATH = Path(__file__).resolve().parents[2] / "fixtures" / "interpolation_golden.json"
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

    @pytest.mark.parametrize("case", GOLDEN["dense_cases"], ids=lambda c: c["name"])
    def test_sources_do_not_change_the_track(self, case):
        sources = ["tracked", "prefilled", "edited", "placed"]
        rows = [row + [sources[i % 4]] for i, row in enumerate(to_compact(case["keyframes"]))]
        assert as_golden(dense_track(rows, case["num_frames"])) == case["dense"]

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


ALLOWED = "source must be one of placed, tracked, prefilled, edited, got"


def source_names(codes: np.ndarray) -> list[str]:
    return [SOURCE_NAMES[c] for c in codes]


class TestKeyframeSource:
    def test_default_source_is_placed_in_every_form(self):
        assert parse_keyframe([3, 1, 2, 1]).source == "placed"
        assert parse_keyframe({"frame": 3, "x": 1, "y": 2, "visible": True}).source == "placed"
        assert parse_keyframe([3, 1, 2, 1, "placed"]) == parse_keyframe([3, 1, 2, 1])

    def test_list_and_dict_forms_carry_the_source(self):
        assert parse_keyframe([3, 1, 2, 1, "tracked"]) == Keyframe(3, 1.0, 2.0, True, "tracked")
        raw = {"frame": 4, "x": None, "y": None, "visible": False, "source": "prefilled"}
        assert parse_keyframe(raw) == Keyframe(4, None, None, False, "prefilled")

    def test_unknown_source_is_named_with_its_keyframe(self):
        rows = [[0, 1, 1, 1], [1, 1, 1, 1], [2, 1, 1, 1, "edited"], [12, 5, 5, 1, "x"]]
        assert validate_keyframes(rows, 20, 640, 480) == [f"keyframe 3 (frame 12): {ALLOWED} 'x'"]
        problems = validate_keyframes([[0, 1, 1, 1, None], [1, 1, 1, 1, 2]], 20, 640, 480)
        assert problems == [f"keyframe 0 (frame 0): {ALLOWED} None",
                            f"keyframe 1 (frame 1): {ALLOWED} 2"]

    def test_a_six_element_row_is_refused(self):
        problems = validate_keyframes([[0, 1, 1, 1, "tracked", 0]], 4, 640, 480)
        assert len(problems) == 1
        assert problems[0].startswith("keyframe 0 (frame 0): expected")

    def test_stored_rows_write_the_source_only_when_not_placed(self):
        rows = [[0, 1, 2, 1], [1, 3, 4, 0, "placed"], [2, 5, 6, 1, "tracked"],
                [3, None, None, 0, "prefilled"], [4, 7, 8, True, "edited"]]
        expected = [[0, 1.0, 2.0, 1], [1, 3.0, 4.0, 0], [2, 5.0, 6.0, 1, "tracked"],
                    [3, None, None, 0, "prefilled"], [4, 7.0, 8.0, 1, "edited"]]
        assert checked_rows(rows, 10, 640, 480) == (expected, [])
        # The full check (here: dicts and tuples) stores exactly the same rows.
        slow = [tuple(rows[0]), {"frame": 1, "x": 3, "y": 4, "visible": False},
                {"frame": 2, "x": 5, "y": 6, "visible": True, "source": "tracked"},
                tuple(rows[3]), tuple(rows[4])]
        assert checked_rows(slow, 10, 640, 480) == (expected, [])
        assert [parse_keyframe(r).row() for r in expected] == expected

    def test_bad_source_in_an_otherwise_plain_save_is_refused(self):
        stored, problems = checked_rows([[0, 1, 1, 1], [1, 1, 1, 1, "Tracked"]], 4, 640, 480)
        assert stored == []
        assert problems == [f"keyframe 1 (frame 1): {ALLOWED} 'Tracked'"]


class TestKeyframeSources:
    def test_keyframes_between_and_after(self):
        rows = [[2, 1, 1, 1, "prefilled"], [5, 1, 1, 1, "prefilled"], [8, 1, 1, 1],
                [10, 1, 1, 1, "tracked"], [12, 1, 1, 1, "prefilled"], [14, 1, 1, 0, "edited"]]
        assert source_names(keyframe_sources(rows, 17)) == [
            "none", "none",
            "prefilled", "prefilled", "prefilled", "prefilled",  # 2..5: both ends prefilled
            "placed", "placed", "placed",  # 6..7 between prefilled and placed, 8 placed
            "placed",  # 9: placed and tracked
            "tracked", "tracked", "prefilled",  # 11: tracked and prefilled
            "edited", "edited",  # 13: prefilled and edited; 14 edited
            "edited", "edited",  # held after the last keyframe
        ]

    def test_no_keyframes_is_none_everywhere(self):
        assert source_names(keyframe_sources([], 3)) == ["none"] * 3
        assert keyframe_sources([[0, 1, 1, 1]], 0).shape == (0,)

    def test_unsorted_and_dict_keyframes(self):
        raw = [{"frame": 4, "x": 1, "y": 1, "visible": True, "source": "tracked"},
               [1, 1, 1, 1, "prefilled"]]
        codes = keyframe_sources(raw, 6)
        assert codes.dtype == np.int8 and codes.shape == (6,)
        assert source_names(codes) == ["none", "prefilled", "tracked", "tracked", "tracked",
                                       "tracked"]

    def test_decided_mask_leaves_out_unplaced_and_prefilled_only(self):
        rows = [[1, 1, 1, 1, "prefilled"], [3, 1, 1, 1, "prefilled"], [5, 1, 1, 1, "edited"],
                [7, None, None, 0, "prefilled"], [9, 1, 1, 1, "tracked"]]
        mask = decided_mask(rows, 11)
        assert mask.dtype == bool
        # 7 is an unedited prefilled keyframe itself; 4, 6 and 8 take their decided neighbour.
        assert mask.tolist() == [False, False, False, False, True, True, True, False, True,
                                 True, True]
        only_prefilled = [[0, 1, 1, 1, "prefilled"], [6, 2, 2, 1, "prefilled"]]
        assert not decided_mask(only_prefilled, 8).any()
        assert decided_mask([[0, 1, 1, 1]], 8).all()


def test_own_keyframes_counts_every_change_the_worker_made():
    kept = [[0, 10.0, 10.0, 1, "prefilled"], [5, 12.0, 10.0, 1, "prefilled"]]
    assert own_keyframes([kept, kept]) == 0
    hidden = [[0, 10.0, 10.0, 1, "prefilled"], [5, 12.0, 10.0, 0, "edited"]]
    placed = [[0, 10.0, 10.0, 1], [3, 11.0, 10.0, 1, "tracked"]]
    assert own_keyframes([kept, hidden]) == 1
    assert own_keyframes([placed, hidden, []]) == 3
