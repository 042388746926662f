"""Per-frame provenance of a view's label: keyframed, tracked, prefilled, interpolated, none;
and how many views decided each frame."""

from __future__ import annotations

import numpy as np
import pytest

from worker.formats.provenance import (
    deciding_views,
    frame_actions,
    frame_provenance,
    view_states,
    views_decided,
)


class TestViewStates:
    def test_each_frame_takes_the_state_of_most_of_its_points(self) -> None:
        points = [
            [[1, 10, 10, 1], [3, 12, 10, 1, "tracked"], [5, 14, 10, 1, "prefilled"]],
            [[1, 20, 10, 1], [3, 22, 10, 1, "tracked"], [5, 24, 10, 1, "edited"]],
            [[1, 30, 10, 1], [3, 32, 10, 1], [5, 34, 10, 1, "prefilled"]],
        ]
        assert view_states(points, 8) == [
            "none", "keyframed", "interpolated", "tracked", "interpolated", "prefilled",
            "interpolated", "interpolated"]  # held after the last keyframe: not decided there

    def test_a_tie_goes_to_the_stronger_state(self) -> None:
        points = [[[0, 1, 1, 1, "tracked"]], [[0, 2, 2, 1]]]
        assert view_states(points, 1) == ["keyframed"]

    def test_an_occluded_keyframe_without_a_position_labels_nothing(self) -> None:
        points = [[[0, None, None, 0], [2, 5, 5, 1]]]
        assert view_states(points, 3) == ["none", "none", "keyframed"]

    def test_rejects_a_negative_clip_length(self) -> None:
        with pytest.raises(ValueError, match="num_frames"):
            view_states([], -1)


class TestViewsDecided:
    def test_counts_views_whose_own_keyframes_decided_the_frame(self) -> None:
        states = [["keyframed", "interpolated", "prefilled"],
                  ["tracked", "interpolated", "none"],
                  ["interpolated", "keyframed", "none"]]
        assert views_decided(states) == [2, 1, 0]
        assert frame_provenance(states, ["a", "b", "c"], 2) == {
            "views_decided": 0, "views": {"a": "prefilled"}}
        assert views_decided([]) == []


class TestDecidingViews:
    def test_names_the_views_whose_own_keyframes_decided_each_frame(self) -> None:
        states = [["keyframed", "interpolated", "prefilled"],
                  ["tracked", "interpolated", "none"],
                  ["interpolated", "keyframed", "none"]]
        assert deciding_views(states, ["a", "b", "c"]) == [["a", "b"], ["c"], []]
        assert deciding_views([], []) == []


class TestFrameActions:
    def test_shares_each_assignments_actions_among_its_keyframes(self) -> None:
        # View 1: 12 actions over 4 keyframes (frames 0, 0, 2, 3); view 2: 6 over frame 2's 2.
        first = [[[0, 1, 1, 1], [2, 2, 2, 1, "tracked"]], [[0, 5, 5, 1], [3, 6, 6, 0]]]
        second = [[[2, 1, 1, 1, "prefilled"]], [[2, 3, 3, 1]]]
        out = frame_actions([(12, first), (6, second)], 5)
        assert out.tolist() == [6.0, 0.0, 3.0 + 6.0, 3.0, 0.0]
        assert out.sum() == 18  # every accepted action goes to some frame

    def test_work_without_keyframes_in_the_clip_spreads_over_every_frame(self) -> None:
        out = frame_actions([(8, [[[9, 1, 1, 1]]]), (0, [])], 4)
        assert np.allclose(out, 2.0)

    def test_refuses_negative_actions_and_clip_lengths(self) -> None:
        with pytest.raises(ValueError, match="actions"):
            frame_actions([(-1, [])], 3)
        with pytest.raises(ValueError, match="num_frames"):
            frame_actions([], -2)
        assert frame_actions([(5, [])], 0).shape == (0,)
