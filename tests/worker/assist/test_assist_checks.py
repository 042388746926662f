"""Check suggestions (worker.assist.checks): which cells, how far off, and how a saved
assignment's acceptance of them is counted."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.assist.checks import (
    CHECK_COUNT,
    CHECK_OFFSET_PX,
    accepted_checks,
    check_cells,
    check_key,
    check_offset,
    plant,
    shift_inside,
)

KEY = check_key("a test signing key")


def test_cells_are_inner_frames_one_per_frame_and_repeatable() -> None:
    cells = check_cells(KEY, 17, 21, 72)
    assert len(cells) == CHECK_COUNT
    frames = [frame for _, frame in cells]
    assert len(set(frames)) == len(frames)
    assert all(1 <= frame <= 70 for frame in frames)
    assert all(0 <= point < 21 for point, _ in cells)
    assert cells == check_cells(KEY, 17, 21, 72)


def test_cells_differ_by_assignment_and_by_key() -> None:
    mine = check_cells(KEY, 17, 21, 72)
    assert mine != check_cells(KEY, 18, 21, 72)
    assert mine != check_cells(check_key("another instance"), 17, 21, 72)


@pytest.mark.parametrize(("frames", "expected"), [(1, 0), (2, 0), (3, 1), (4, 2), (5, 3)])
def test_short_clips_get_fewer_cells(frames: int, expected: int) -> None:
    assert len(check_cells(KEY, 3, 2, frames)) == expected


def test_offset_has_the_stated_length() -> None:
    for point, frame in check_cells(KEY, 5, 21, 72):
        dx, dy = check_offset(KEY, 5, point, frame)
        assert math.hypot(dx, dy) == pytest.approx(CHECK_OFFSET_PX)


def test_shift_stays_inside_the_image() -> None:
    x, y = shift_inside(1.0, 1.0, -15.0, 0.0, 640, 480)
    assert (x, y) == (16.0, 1.0)
    x, y = shift_inside(630.0, 470.0, 12.0, 9.0, 640, 480)
    assert 0 <= x <= 639 and 0 <= y <= 479
    assert math.hypot(x - 630.0, y - 470.0) == pytest.approx(15.0)


def test_plant_moves_exactly_the_shown_check_cells() -> None:
    num_points, num_frames = 21, 72
    xy = np.full((num_points, num_frames, 2), 200.0)
    shown = np.ones((num_points, num_frames), bool)
    out = plant(KEY, 9, xy, shown, 0, num_frames, num_points, 640, 480)
    moved = {(int(p), int(f)) for p, f in np.argwhere(np.abs(out - xy).sum(-1) > 0)}
    assert moved == set(check_cells(KEY, 9, num_points, num_frames))
    for point, frame in moved:
        assert np.hypot(*(out[point, frame] - xy[point, frame])) == pytest.approx(15.0)
    # A range that starts later, rows for a subset of points, a cell not shown: the same cells
    # move by the same offsets, the hidden one stays.
    (p0, f0), (p1, f1) = sorted(moved)[:2]
    sub = xy[[p0, p1], 1:]
    sub_shown = np.ones(sub.shape[:2], bool)
    sub_shown[1, f1 - 1] = False
    part = plant(KEY, 9, sub, sub_shown, 1, num_frames, num_points, 640, 480, points=[p0, p1])
    assert np.allclose(part[0, f0 - 1], out[p0, f0])
    assert np.allclose(part[1, f1 - 1], xy[p1, f1])


def test_accepted_and_corrected_cells_are_counted_from_sources() -> None:
    num_points, num_frames = 21, 24
    cells = check_cells(KEY, 4, num_points, num_frames)
    tracks: list[list[list[object]]] = [[[0, 10.0, 10.0, 1]] for _ in range(num_points)]
    sources = ["tracked", "prefilled", "edited", None]
    for (point, frame), source in zip(cells, sources, strict=True):
        row: list[object] = [frame, 20.0, 20.0, 1]
        if source is not None:
            row.append(source)
        tracks[point].append(row)
    assert accepted_checks(KEY, 4, tracks, num_points, num_frames) == (2, 1)
    # A suggestion kept occluded was never shown off the point: it counts as neither.
    (point, frame) = cells[1]
    tracks[point][-1] = [frame, 20.0, 20.0, 0, "prefilled"]
    assert accepted_checks(KEY, 4, tracks, num_points, num_frames) == (1, 1)
    # Without keyframes at the cells (keyed by hand elsewhere, interpolated) nothing counts.
    bare: list[list[list[object]]] = [[[0, 10.0, 10.0, 1]] for _ in range(num_points)]
    assert accepted_checks(KEY, 4, bare, num_points, num_frames) == (0, 0)
