"""Simulated assisted annotators on a textured clip with a known motion: the careful worker
ends within its tolerance of the truth with fewer actions than the keyframe worker, corrects
every check cell, the blind acceptor keeps them, and every keyframe carries the right source."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from worker.assist.checks import CHECK_OFFSET_PX, check_cells, check_key, check_offset
from worker.synth.annotators import annotate, keyframe_actions
from worker.synth.assisted import (
    TOLERANCE_PX,
    AssistedWork,
    AssistSetting,
    Prefill,
    assisted_annotate,
    plain_rows,
    row_source,
)
from worker.tracks.interpolate import dense_track

WIDTH, HEIGHT, FRAMES, POINTS = 320, 240, 24, 21
MARGIN = 120
KEY = check_key("test signing key")
ASSIGNMENT = 17
OCCLUDED_POINT, OCCLUDED = 3, range(9, 14)


def _clip() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, H, W) uint8 frames of a blurred-noise texture moving with an accelerating, swinging
    shift; (F, P, 2) true positions of points on it (px) and (F, P) visibility (one point
    occluded over frames 9-13)."""
    rng = np.random.default_rng(4)
    noise = rng.integers(0, 256, (HEIGHT + 2 * MARGIN, WIDTH + 2 * MARGIN)).astype(np.uint8)
    texture = cv2.GaussianBlur(noise, (5, 5), 1.5)
    t = np.linspace(0.0, 1.0, FRAMES)
    shift = np.stack([40.0 * t ** 2, 12.0 * np.sin(2 * np.pi * t)], axis=1)
    grey = np.stack([cv2.warpAffine(texture, np.float32([[1, 0, s[0] - MARGIN],
                                                          [0, 1, s[1] - MARGIN]]),
                                    (WIDTH, HEIGHT), flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REFLECT) for s in shift])
    start = rng.uniform([40, 40], [240, 180], (POINTS, 2))
    truth = start[None] + (shift - shift[0])[:, None]
    visible = np.ones((FRAMES, POINTS), dtype=bool)
    visible[list(OCCLUDED), OCCLUDED_POINT] = False
    return grey, truth, visible


@pytest.fixture(scope="module")
def clip() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return _clip()


def _work(clip: tuple[np.ndarray, np.ndarray, np.ndarray], profile: str,
          prefill: Prefill | None = None, seed: int = 0) -> AssistedWork:
    grey, truth, visible = clip
    setting = AssistSetting(grey, KEY, ASSIGNMENT, prefill)
    return assisted_annotate(truth, visible, setting, profile, np.random.default_rng(seed))


def _row_at(track: list[list], frame: int) -> list | None:
    return next((row for row in track if row[0] == frame), None)


def _inner_cells() -> list[tuple[int, int]]:
    return check_cells(KEY, ASSIGNMENT, POINTS, FRAMES)


class TestCarefulAssisted:
    def test_every_shown_position_ends_within_tolerance_of_where_it_sees_the_point(
            self, clip) -> None:
        _, truth, visible = clip
        work = _work(clip, "careful")
        for p, track in enumerate(work.tracks):
            dense = dense_track(plain_rows(track), FRAMES).xy
            sources = {row[0]: row_source(row) for row in track}
            for f in np.flatnonzero(visible[:, p]):
                if sources.get(f) in ("placed", "edited"):
                    # Its own click or drag: at the seen position, 2 px noise.
                    assert np.linalg.norm(dense[f] - work.seen[f, p]) < 0.01
                    continue
                assert np.linalg.norm(dense[f] - work.judged[f, p]) <= TOLERANCE_PX
                # Judging noise is 1 px per axis: never 4 px beyond the tolerance.
                assert np.linalg.norm(dense[f] - truth[f, p]) <= TOLERANCE_PX + 4.0

    def test_spends_fewer_actions_than_the_keyframe_worker_at_lower_error(self, clip) -> None:
        _, truth, visible = clip
        work = _work(clip, "careful")
        today = annotate(truth, visible, (WIDTH, HEIGHT), "careful", np.random.default_rng(0),
                         follow_motion=False)
        mine, theirs = work.actions, keyframe_actions(today.tracks)

        def total(actions: dict[str, int]) -> int:
            return actions["clicks"] + actions["drags"] + actions["keys"]

        assert total(mine) < total(theirs) / 2

        def error(tracks: list) -> float:
            dense = np.stack([dense_track(plain_rows(t), FRAMES).xy for t in tracks], axis=1)
            return float(np.linalg.norm(dense - truth, axis=2)[visible].mean())

        assert error(work.tracks) < error(today.tracks)

    def test_corrects_every_check_cell(self, clip) -> None:
        _, truth, _ = clip
        work = _work(clip, "careful")
        for point, frame in _inner_cells():
            row = _row_at(work.tracks[point], frame)
            assert row is not None and row_source(row) == "edited"
            assert np.hypot(row[1] - truth[frame, point, 0],
                            row[2] - truth[frame, point, 1]) < 8.0

    def test_keys_by_hand_the_ends_and_the_visibility_changes(self, clip) -> None:
        work = _work(clip, "careful")
        for track in work.tracks:
            assert row_source(track[0]) == "placed" and track[0][0] == 0
            assert row_source(track[-1]) == "placed" and track[-1][0] == FRAMES - 1
        rows = {row[0]: row for row in work.tracks[OCCLUDED_POINT]}
        first, last = OCCLUDED[0], OCCLUDED[-1]
        assert rows[first - 1][3] == 1 and rows[first][3] == 0 and rows[last + 1][3] == 1
        assert all(len(rows[f]) == 4 for f in (first - 1, first, last + 1))
        # Nothing is tracked through the occlusion: its frames interpolate the occluded key.
        assert not any(f in rows for f in range(first + 1, last + 1))

    def test_rows_carry_a_source_only_when_not_placed(self, clip) -> None:
        work = _work(clip, "careful")
        rows = [row for track in work.tracks for row in track]
        assert {row_source(r) for r in rows} == {"placed", "tracked", "edited"}
        assert all(len(r) == 4 for r in rows if row_source(r) == "placed")
        assert all(len(r) == 5 for r in rows if row_source(r) != "placed")
        placed = sum(row_source(r) == "placed" for r in rows)
        assert work.actions["keyframes_placed"] == placed
        assert work.actions["drags"] == sum(row_source(r) == "edited" for r in rows)


class TestFollowedOnThePage:
    """The worker of the annotation page: points followed from one keyframe, and the page's
    own re-tracks after a correction (AssistSetting follows and retracks)."""

    @staticmethod
    def _page_work(clip, profile: str) -> AssistedWork:
        grey, truth, visible = clip
        setting = AssistSetting(grey, KEY, ASSIGNMENT, None, follows=True, retracks=True)
        return assisted_annotate(truth, visible, setting, profile, np.random.default_rng(0))

    def test_keys_no_last_frame_and_ends_within_tolerance(self, clip) -> None:
        _, _, visible = clip
        work = self._page_work(clip, "careful")
        last = [_row_at(t, FRAMES - 1) for t in work.tracks]
        assert sum(row is not None and row_source(row) == "placed" for row in last) < POINTS
        for p, track in enumerate(work.tracks):
            dense = dense_track(plain_rows(track), FRAMES).xy
            seen = visible[:, p]
            err = np.linalg.norm(dense[seen] - work.judged[seen, p], axis=1)
            sources = {row[0]: row_source(row) for row in track}
            by_hand = np.array([sources.get(f) in ("placed", "edited")
                                for f in np.flatnonzero(seen)])
            assert (err[~by_hand] <= TOLERANCE_PX).all()
        for point, frame in _inner_cells():
            row = _row_at(work.tracks[point], frame)
            assert row is None or row_source(row) != "tracked"

    def test_the_page_counts_the_workers_edits_not_requests_nor_its_own_re_tracks(
            self, clip) -> None:
        work = self._page_work(clip, "careful")
        acts = work.actions
        assert acts["requests"] == 1  # one T; the re-tracks after corrections are the page's
        assert acts["writes"] > 0
        assert acts["edits"] == acts["clicks"] + acts["drags"] + acts["keys"] - acts["requests"]

    def test_the_blind_acceptor_keys_the_last_frame_and_keeps_what_it_is_shown(self,
                                                                              clip) -> None:
        work = self._page_work(clip, "blind")
        assert all(row_source(t[-1]) == "placed" and t[-1][0] == FRAMES - 1
                   for t in work.tracks)
        assert work.actions["drags"] == 0 and work.actions["requests"] == 1


class TestModelFollow:
    """A model follow offered on the page (worker.solver.follow's place, here a stand-in that
    sits on the truth until frame OFF_FROM and 20 px off after it): the careful worker takes it
    only up to where it comes off and tracks the rest; the blind acceptor takes it all."""

    OFF_FROM = 12

    @classmethod
    def _setting(cls, clip, asked: list) -> AssistSetting:
        grey, truth, visible = clip

        def model(anchors, begin=None):
            asked.append(anchors)
            xy = truth.copy()
            xy[cls.OFF_FROM:] += 20.0
            return xy, np.ones(visible.shape, bool)

        return AssistSetting(grey, KEY, ASSIGNMENT, None, follows=True, retracks=True,
                             model=model)

    def test_the_careful_worker_takes_the_model_where_it_sits_and_tracks_the_rest(
            self, clip) -> None:
        _, truth, visible = clip
        asked: list = []
        work = assisted_annotate(truth, visible, self._setting(clip, asked), "careful",
                                 np.random.default_rng(0))
        without = TestFollowedOnThePage._page_work(clip, "careful")
        # Asked once, with the keyframes placed by hand (the first frame of every point).
        assert len(asked) == 1 and all(rows and rows[0][0] == 0 for rows in asked[0])
        on_model = before = 0
        for p, track in enumerate(work.tracks):
            sources = {row[0]: row_source(row) for row in track}
            rows = {row[0]: row for row in track}
            for f in range(1, self.OFF_FROM):
                if visible[f, p] and (p, f) not in _inner_cells():
                    before += 1
                    row = rows.get(f)
                    # The stand-in's own positions (rounded as saved), not LK's.
                    on_model += row is not None and row_source(row) == "tracked" and np.hypot(
                        row[1] - truth[f, p, 0], row[2] - truth[f, p, 1]) < 0.01
            dense = dense_track(plain_rows(track), FRAMES).xy
            seen = visible[:, p]
            err = np.linalg.norm(dense[seen] - work.judged[seen, p], axis=1)
            by_hand = np.array([sources.get(f) in ("placed", "edited")
                                for f in np.flatnonzero(seen)])
            assert (err[~by_hand] <= TOLERANCE_PX).all(), p
        assert on_model >= 0.9 * before, (on_model, before)
        # Every check cell in the frames taken is corrected, as every check cell.
        for point, frame in _inner_cells():
            row = _row_at(work.tracks[point], frame)
            if frame < self.OFF_FROM and row is not None:
                assert row_source(row) != "tracked"
        assert work.actions["requests"] == 2  # the model's and one T
        assert work.actions["edits"] < without.actions["edits"]

    def test_a_few_joints_off_are_dragged_and_the_model_asked_again_from_there(
            self, clip) -> None:
        """A stand-in that puts 4 joints 20 px off from frame OFF_FROM on, until it is asked
        from that frame (begin), when it sits on the truth to the end."""
        grey, truth, visible = clip
        asked: list = []

        def model(anchors, begin=None):
            asked.append((anchors, begin))
            xy = truth.copy()
            if begin is None:
                xy[self.OFF_FROM:, :4] += 20.0
            return xy, np.ones(visible.shape, bool)

        setting = AssistSetting(grey, KEY, ASSIGNMENT, None, follows=True, retracks=True,
                                model=model)
        work = assisted_annotate(truth, visible, setting, "careful", np.random.default_rng(0))
        assert [begin for _, begin in asked] == [None, self.OFF_FROM]
        # The second ask carries the first's accepted rows and the corrected frame.
        again = asked[1][0]
        for p in range(POINTS):
            frames = {row[0] for row in again[p]}
            assert set(np.flatnonzero(visible[:self.OFF_FROM + 1, p])) <= frames, p
        for p in range(4):
            if not visible[self.OFF_FROM, p]:
                continue
            row = _row_at(work.tracks[p], self.OFF_FROM)
            assert row is not None and row_source(row) == "edited"
            assert np.hypot(row[1] - truth[self.OFF_FROM, p, 0],
                            row[2] - truth[self.OFF_FROM, p, 1]) < 10.0
        # After it every visible joint is the model's, but the check cells (dragged) and the
        # frame the occluded point shows again (keyed by hand).
        cells = set(_inner_cells()) | {(OCCLUDED_POINT, OCCLUDED.stop)}
        for p in range(POINTS):
            for f in range(self.OFF_FROM + 1, FRAMES):
                row = _row_at(work.tracks[p], f)
                if visible[f, p] and (p, f) not in cells:
                    assert row is not None and row_source(row) == "tracked", (p, f)
        # Two model asks, no tracking asked for: Enter twice and the drags.
        assert work.actions["requests"] == 2
        dragged = work.actions["drags"]
        assert work.actions["edits"] == work.actions["clicks"] + work.actions["keys"] - 2 \
            + dragged
        assert dragged <= 4 + len(cells)

    def test_the_blind_acceptor_takes_the_whole_model_follow(self, clip) -> None:
        _, truth, visible = clip
        work = assisted_annotate(truth, visible, self._setting(clip, []), "blind",
                                 np.random.default_rng(0))
        off = 0
        for p, track in enumerate(work.tracks):
            for row in track:
                if row[0] >= self.OFF_FROM and row_source(row) == "tracked":
                    off += np.hypot(row[1] - truth[row[0], p, 0],
                                    row[2] - truth[row[0], p, 1]) > 15.0
        assert off > 0.5 * visible[self.OFF_FROM:].sum()
        assert work.actions["drags"] == 0


class TestBlindAcceptor:
    def test_keeps_the_check_cells_offsets(self, clip) -> None:
        _, truth, _ = clip
        work = _work(clip, "blind")
        careful = _work(clip, "careful")
        for point, frame in _inner_cells():
            row = _row_at(work.tracks[point], frame)
            assert row is not None and row_source(row) == "tracked"
            off = np.hypot(row[1] - truth[frame, point, 0], row[2] - truth[frame, point, 1])
            assert CHECK_OFFSET_PX - 5 < off < CHECK_OFFSET_PX + 5
            # Off in the cell's own drawn direction (within the tracking's few px).
            dx, dy = check_offset(KEY, ASSIGNMENT, point, frame)
            moved = np.array([row[1], row[2]]) - truth[frame, point]
            assert float(np.dot(moved, [dx, dy])) > 0.5 * CHECK_OFFSET_PX ** 2
        assert work.actions["drags"] == 0
        assert work.actions["clicks"] + work.actions["keys"] < (
            careful.actions["clicks"] + careful.actions["drags"] + careful.actions["keys"])


class TestPrefill:
    def _prefill(self, truth: np.ndarray, visible: np.ndarray) -> Prefill:
        """Suggestions 1 px off the truth with point 5's visibility wrong on frames 4-6 and
        nothing for point 7 (it must be keyed and tracked)."""
        xy = truth + np.random.default_rng(8).normal(0.0, 0.7, truth.shape)
        xy[:, 7] = np.nan
        suggested = visible.copy()
        suggested[4:7, 5] = False
        return Prefill(xy=xy, visible=suggested)

    def test_careful_fixes_visibility_and_check_cells_and_tracks_the_gaps(self, clip) -> None:
        _, truth, visible = clip
        work = _work(clip, "careful", self._prefill(truth, visible))
        for f in range(4, 7):
            row = _row_at(work.tracks[5], f)
            assert row is not None and row[3] == 1 and row_source(row) == "edited"
        sources = {row_source(r) for r in work.tracks[7]}
        assert "prefilled" not in sources and "placed" in sources
        for point, frame in _inner_cells():
            row = _row_at(work.tracks[point], frame)
            assert row is not None and row_source(row) == "edited"
        # One key takes the whole pre-fill; 3 visibility fixes; point 7 keyed at its ends.
        assert work.actions["keys"] >= 1 + 3
        assert sum(row_source(r) == "prefilled" for t in work.tracks for r in t) > (
            0.8 * (POINTS - 1) * FRAMES)

    def test_careful_leaves_suggestions_that_mostly_miss_the_points(self, clip) -> None:
        # Suggestions of other spots (20 px off every point): dragging each back would cost a
        # drag per frame and point; the careful worker labels the view as if none were shown.
        # The blind acceptor takes them all the same.
        _, truth, visible = clip
        elsewhere = Prefill(xy=truth + 20.0, visible=visible.copy())
        work = _work(clip, "careful", elsewhere)
        alone = _work(clip, "careful", None)
        assert not any(row_source(r) == "prefilled" for t in work.tracks for r in t)
        assert work.actions == alone.actions
        blind = _work(clip, "blind", elsewhere)
        assert sum(row_source(r) == "prefilled" for t in blind.tracks for r in t) > (
            0.8 * POINTS * FRAMES)

    def test_blind_keeps_wrong_visibility_and_prefilled_check_cells(self, clip) -> None:
        _, truth, visible = clip
        work = _work(clip, "blind", self._prefill(truth, visible))
        for f in range(4, 7):
            row = _row_at(work.tracks[5], f)
            assert row is not None and row[3] == 0 and row_source(row) == "prefilled"
        for point, frame in _inner_cells():
            row = _row_at(work.tracks[point], frame)
            assert row is not None and row_source(row) in ("prefilled", "tracked")
            off = np.hypot(row[1] - truth[frame, point, 0], row[2] - truth[frame, point, 1])
            assert off > CHECK_OFFSET_PX - 5

    def _hiding(self, truth: np.ndarray, visible: np.ndarray
                ) -> tuple[Prefill, tuple, tuple, list]:
        """Suggestions 0.7 px off the truth where two of the four check cells are suggested
        otherwise: one occluded (known; the route plants nothing there) and one of unknown
        visibility (the page shows it as visible, so the route plants it); the other two cells
        are shown visible."""
        cells = _inner_cells()
        hidden, unknown = cells[1], cells[0]
        xy = truth + np.random.default_rng(8).normal(0.0, 0.7, truth.shape)
        suggested, known = visible.copy(), np.ones_like(visible)
        suggested[hidden[1], hidden[0]] = False
        known[unknown[1], unknown[0]] = False
        return (Prefill(xy=xy, visible=suggested, known=known), hidden, unknown,
                [c for c in cells if c != hidden])

    def test_check_cells_are_planted_wherever_a_suggestion_is_shown_visible(self, clip) -> None:
        _, truth, visible = clip
        prefill, hidden, unknown, planted = self._hiding(truth, visible)
        assert visible[hidden[1], hidden[0]] and unknown in planted
        work = _work(clip, "blind", prefill)
        row = _row_at(work.tracks[hidden[0]], hidden[1])
        assert row is not None and row_source(row) == "prefilled" and row[3] == 0
        # The suggestion itself, not moved 15 px off.
        assert np.hypot(row[1] - prefill.xy[hidden[1], hidden[0], 0],
                        row[2] - prefill.xy[hidden[1], hidden[0], 1]) < 0.01
        for point, frame in planted:
            row = _row_at(work.tracks[point], frame)
            assert row is not None
            off = np.hypot(row[1] - truth[frame, point, 0], row[2] - truth[frame, point, 1])
            assert CHECK_OFFSET_PX - 5 < off < CHECK_OFFSET_PX + 5

    def test_careful_fixes_the_hidden_cell_and_every_planted_one(self, clip) -> None:
        _, truth, visible = clip
        prefill, hidden, _, planted = self._hiding(truth, visible)
        work = _work(clip, "careful", prefill)
        row = _row_at(work.tracks[hidden[0]], hidden[1])
        assert row is not None and row[3] == 1 and row_source(row) == "edited"
        for point, frame in planted:
            row = _row_at(work.tracks[point], frame)
            assert row is not None and row_source(row) == "edited"
            assert np.hypot(row[1] - truth[frame, point, 0],
                            row[2] - truth[frame, point, 1]) < 8.0


class TestKeyframeActions:
    def test_counts_a_click_per_visible_keyframe_and_a_key_per_occluded_one(self) -> None:
        tracks = [[[0, 1.0, 2.0, 1], [4, None, None, 0], [8, 3.0, 4.0, 1]],
                  [[0, 5.0, 6.0, 0], [8, 7.0, 8.0, 1]]]
        assert keyframe_actions(tracks) == {"clicks": 3, "drags": 0, "keys": 2,
                                            "keyframes_placed": 5}


class TestBadInput:
    def test_rejects_truth_whose_frames_differ_from_the_clip(self, clip) -> None:
        grey, truth, visible = clip
        with pytest.raises(ValueError, match=r"expected truth \(F, P, 2\)"):
            assisted_annotate(truth[:-1], visible[:-1], AssistSetting(grey, KEY, 1), "careful",
                              np.random.default_rng(0))

    def test_rejects_an_unknown_profile(self, clip) -> None:
        grey, truth, visible = clip
        with pytest.raises(ValueError, match="unknown assisted profile 'lazy'"):
            assisted_annotate(truth, visible, AssistSetting(grey, KEY, 1), "lazy",
                              np.random.default_rng(0))
