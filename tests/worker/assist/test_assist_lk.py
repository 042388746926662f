"""Lucas-Kanade proposals between keyframes on a synthetic translating texture with a known
motion: proposals land on the true positions, and the forward-backward check stops a point
that leaves the image or is covered by something else; a point followed from one keyframe
alone holds on the truth until those checks stop it, and says why it stopped."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from worker.assist.lk import STOP_END, STOP_LEFT_IMAGE, STOP_LOST, _lk, follow, propose

WIDTH, HEIGHT = 320, 240
MARGIN = 120


def _texture(seed: int, size: tuple[int, int]) -> np.ndarray:
    """Blurred noise: a corner-rich texture LK locks onto."""
    rng = np.random.default_rng(seed)
    noise = rng.integers(0, 256, (size[1], size[0])).astype(np.uint8)
    return cv2.GaussianBlur(noise, (5, 5), 1.5)


def _frames(shift: np.ndarray, seed: int = 0) -> np.ndarray:
    """(F, H, W) uint8: the texture moved by shift[f] (px, x and y) in frame f; a texture
    point q shows at q - MARGIN + shift[f]."""
    tex = _texture(seed, (WIDTH + 2 * MARGIN, HEIGHT + 2 * MARGIN))
    return np.stack([cv2.warpAffine(tex, np.float32([[1, 0, s[0] - MARGIN], [0, 1, s[1] - MARGIN]]),
                                    (WIDTH, HEIGHT), flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_REFLECT) for s in shift])


def _keys(truth: np.ndarray, frames: list[int]) -> list[list[list[float]]]:
    return [[[f, float(truth[f, p, 0]), float(truth[f, p, 1]), 1] for f in frames]
            for p in range(truth.shape[1])]


def _accelerating(count: int) -> np.ndarray:
    """A motion linear interpolation gets wrong: x accelerates, y swings."""
    t = np.linspace(0.0, 1.0, count)
    return np.stack([40.0 * t ** 2, 12.0 * np.sin(2 * np.pi * t)], axis=1)


class TestPropose:
    def test_proposals_lie_within_half_a_pixel_of_the_truth(self) -> None:
        count = 24
        shift = _accelerating(count)
        frames = _frames(shift)
        start = np.random.default_rng(1).uniform([40, 40], [240, 180], (21, 2))
        truth = start[None] + (shift - shift[0])[:, None]
        keys = [0, 8, 16, 23]
        out = propose(frames, _keys(truth, keys))
        inner = np.ones(count, bool)
        inner[keys] = False
        assert out.xy.shape == (count, 21, 2) and out.ok.shape == (count, 21)
        assert out.ok[inner].all() and not out.ok[keys].any()
        error = np.linalg.norm(out.xy - truth, axis=2)[inner]
        assert error.max() < 0.5
        assert np.nanmax(out.fb_error[inner]) < 0.2
        # The same keyframes interpolated linearly miss the accelerating motion by far more.
        lerp = np.stack([np.interp(np.arange(count), keys, truth[keys, p, a])
                         for p in range(21) for a in range(2)], axis=1).reshape(count, 21, 2)
        assert np.linalg.norm(lerp - truth, axis=2)[inner].max() > 2.0

    def test_a_range_of_frames_is_proposed_alone_in_clip_frames(self) -> None:
        count = 24
        shift = _accelerating(count)
        frames = _frames(shift)
        truth = np.array([[[100.0, 90.0]]]) + (shift - shift[0])[:, None]
        out = propose(frames[8:17], _keys(truth, [0, 8, 16, 23]), first_frame=8)
        assert out.first_frame == 8 and out.xy.shape == (9, 1, 2)
        assert out.ok[1:8, 0].all() and not out.ok[[0, 8], 0].any()
        assert np.linalg.norm(out.xy[1:8, 0] - truth[9:16, 0], axis=1).max() < 0.5

    def test_a_point_that_leaves_the_image_is_stopped_where_it_is_outside(self) -> None:
        count = 31
        t = np.linspace(0.0, 1.0, count)
        shift = np.stack([70.0 * np.sin(np.pi * t), np.zeros(count)], axis=1)
        frames = _frames(shift)
        truth = np.array([[[WIDTH - 30.0, 120.0], [60.0, 120.0]]]) + shift[:, None]
        out = propose(frames, _keys(truth, [0, count - 1]))
        outside = truth[:, 0, 0] > WIDTH - 1
        assert outside.any()
        assert not out.ok[outside, 0].any()
        assert out.ok[1:count - 1, 1].all()  # the point that stays in view is kept throughout
        kept = out.ok[:, 0]
        assert kept.sum() >= 4
        assert np.linalg.norm(out.xy[kept, 0] - truth[kept, 0], axis=1).max() < 0.5

    def test_a_covered_point_is_stopped_by_the_forward_backward_check(self) -> None:
        count = 31
        shift = np.stack([np.linspace(0.0, 30.0, count), np.zeros(count)], axis=1)
        frames = _frames(shift)
        # Another textured object covers a patch of the image over frames 10-20.
        cover = _texture(9, (80, 80))
        frames[10:21, 80:160, 100:180] = cover
        truth = np.array([[[125.0, 120.0], [60.0, 40.0]]]) + shift[:, None]
        assert (truth[10:21, 0, 0] >= 100).all() and (truth[10:21, 0, 0] < 180).all()
        out = propose(frames, _keys(truth, [0, count - 1]))
        assert not out.ok[10:21, 0].any()
        assert out.ok[1:10, 0].all() and out.ok[21:count - 1, 0].all()
        kept = out.ok[:, 0]
        assert np.linalg.norm(out.xy[kept, 0] - truth[kept, 0], axis=1).max() < 0.5
        assert out.ok[1:count - 1, 1].all()

    def test_only_spans_between_visible_keyframes_are_tracked(self) -> None:
        count = 12
        frames = _frames(np.zeros((count, 2)))
        tracks = [[[0, 50.0, 50.0, 1], [5, 50.0, 50.0, 0], [11, 50.0, 50.0, 1]],
                  [[0, 80.0, 80.0, 1], [6, None, None, 0], [11, 80.0, 80.0, 1]],
                  [[3, 20.0, 20.0, 1]]]
        out = propose(frames, tracks)
        assert not out.ok.any() and np.isnan(out.xy).all()

    def test_frames_that_are_not_grey_images_are_refused_naming_the_shape(self) -> None:
        with pytest.raises(ValueError, match=r"\(4, 5, 6, 3\)"):
            propose(np.zeros((4, 5, 6, 3), np.uint8), [])


class TestFollow:
    def test_a_point_followed_forward_from_one_keyframe_holds_to_the_last_frame(self) -> None:
        count = 24
        shift = _accelerating(count)
        frames = _frames(shift)
        truth = np.array([[[100.0, 90.0], [200.0, 150.0]]]) + (shift - shift[0])[:, None]
        out = follow(frames, [(0, *truth[0, 0], True), (4, *truth[4, 1], True)])
        assert out.xy.shape == (count, 2, 2) and out.stopped == [STOP_END, STOP_END]
        assert out.reached.tolist() == [count - 1, count - 1]
        assert out.ok[1:, 0].all() and not out.ok[0, 0]
        assert out.ok[5:, 1].all() and not out.ok[:5, 1].any()
        error = np.linalg.norm(out.xy - truth, axis=2)
        assert np.nanmax(error[out.ok]) < 0.5

    def test_a_point_followed_backward_holds_on_the_frames_before_its_keyframe(self) -> None:
        count = 20
        shift = _accelerating(count)
        frames = _frames(shift)
        truth = np.array([[[120.0, 100.0]]]) + (shift - shift[0])[:, None]
        out = follow(frames[4:], [(15, *truth[15, 0], False)], first_frame=4)
        assert out.ok[:11, 0].all() and not out.ok[11:, 0].any()
        assert out.reached.tolist() == [4] and out.stopped == [STOP_END]
        assert np.linalg.norm(out.xy[:11, 0] - truth[4:15, 0], axis=1).max() < 0.5

    def test_a_covered_point_stops_where_it_is_lost_and_says_so(self) -> None:
        count = 31
        shift = np.stack([np.linspace(0.0, 30.0, count), np.zeros(count)], axis=1)
        frames = _frames(shift)
        frames[10:21, 80:160, 100:180] = _texture(9, (80, 80))
        truth = np.array([[[125.0, 120.0]]]) + shift[:, None]
        out = follow(frames, [(0, *truth[0, 0], True)])
        assert out.stopped == [STOP_LOST] and out.reached.tolist() == [9]
        assert out.ok[1:10, 0].all() and not out.ok[10:, 0].any()

    def test_a_point_leaving_the_image_stops_at_the_edge(self) -> None:
        count = 16
        shift = np.stack([np.linspace(0.0, 60.0, count), np.zeros(count)], axis=1)
        frames = _frames(shift)
        truth = np.array([[[WIDTH - 30.0, 120.0]]]) + shift[:, None]
        out = follow(frames, [(0, *truth[0, 0], True)])
        last_inside = int(np.flatnonzero(truth[:, 0, 0] <= WIDTH - 1).max())
        assert out.stopped == [STOP_LEFT_IMAGE]
        assert 1 <= out.reached[0] <= last_inside
        kept = out.ok[:, 0]
        # Next to the edge LK's window is cut: within the forward-backward threshold.
        assert np.linalg.norm(out.xy[kept, 0] - truth[kept, 0], axis=1).max() < 1.0

    def test_a_step_of_points_that_are_all_outside_the_image_finds_nothing(self) -> None:
        """A followed chain can step out of the image; the check of that step (forward-backward,
        every point of the frame out) has no pixels to look at and holds nothing."""
        frames = _frames(np.zeros((2, 2)))
        outside = np.array([[100.0, HEIGHT + 200.0], [140.0, HEIGHT + 210.0]], np.float32)
        moved, found, residual = _lk(frames[0], frames[1], outside)
        assert not found.any() and np.isinf(residual).all()
        np.testing.assert_array_equal(moved, outside)

    def test_a_start_outside_the_frames_given_is_refused_naming_the_frame(self) -> None:
        with pytest.raises(ValueError, match="start frame 9"):
            follow(_frames(np.zeros((4, 2))), [(9, 10.0, 10.0, True)])
