"""Per-frame provenance of a view's label: keyframed, tracked, prefilled, interpolated, none;
and how many views decided each frame."""

from __future__ import annotations

import pytest

from worker.formats.provenance import frame_provenance, view_states, views_decided


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
