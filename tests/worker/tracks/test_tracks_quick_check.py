"""The quick pass of keyframe validation accepts exactly what the full check accepts."""

from __future__ import annotations

import math
import random
from typing import Any

from worker.tracks.keyframes import parse_keyframe
from worker.tracks.validate import _plainly_valid, checked_rows, validate_keyframes

NUM_FRAMES, WIDTH, HEIGHT = 12, 64, 48
ODD_VALUES: list[Any] = [None, True, False, 0, 1, 2, -1, 1.0, 0.0, 63.99, 64, 64.0, 47.5, 48,
                         -0.01, math.nan, math.inf, "1", [1], {"x": 1}]


def _valid_rows(rng: random.Random) -> list[list[Any]]:
    frames = sorted(rng.sample(range(NUM_FRAMES), rng.randint(0, NUM_FRAMES)))
    rows: list[list[Any]] = []
    for frame in frames:
        if rng.random() < 0.2:
            rows.append([frame, None, None, 0])
        else:
            rows.append([frame, round(rng.uniform(0, WIDTH - 0.01), 2),
                         rng.choice([rng.randint(0, HEIGHT - 1), rng.uniform(0, HEIGHT - 0.01)]),
                         rng.choice([0, 1, True, False])])
    return rows


def _spoil(rows: list[list[Any]], rng: random.Random) -> list[Any]:
    spoiled: list[Any] = [list(r) for r in rows]
    if not spoiled or rng.random() < 0.1:
        spoiled.append(rng.choice([[NUM_FRAMES, 1, 1, 1], (1, 1.0, 1.0, 1),
                                   {"frame": 0, "x": 1, "y": 1, "visible": True}, [0, 1, 1]]))
        return spoiled
    row = spoiled[rng.randrange(len(spoiled))]
    what = rng.randrange(5)
    if what == 4:
        spoiled.append(list(row))  # a duplicate frame
    else:
        row[what] = rng.choice(ODD_VALUES)
    if rng.random() < 0.1:
        rng.shuffle(spoiled)
    return spoiled


def test_well_formed_rows_pass_the_quick_pass() -> None:
    rng = random.Random(1)
    for _ in range(300):
        rows = _valid_rows(rng)
        assert validate_keyframes(rows, NUM_FRAMES, WIDTH, HEIGHT) == []
        assert _plainly_valid(rows, NUM_FRAMES, WIDTH, HEIGHT)


def test_the_quick_pass_never_accepts_what_the_full_check_refuses() -> None:
    rng = random.Random(2)
    refused = 0
    for _ in range(3000):
        rows = _spoil(_valid_rows(rng), rng)
        if _plainly_valid(rows, NUM_FRAMES, WIDTH, HEIGHT):
            assert validate_keyframes(rows, NUM_FRAMES, WIDTH, HEIGHT) == [], rows
        else:
            refused += 1
    assert refused > 1000  # the spoiled rows did exercise the full check


def _stored(raw: list[Any]) -> list[list[Any]]:
    """What the full check's parser makes of valid rows, in the stored form."""
    return [[kf.frame, kf.x, kf.y, int(kf.visible)] for kf in map(parse_keyframe, raw)]


def test_both_passes_store_the_same_rows_and_the_same_types() -> None:
    rng = random.Random(3)
    for _ in range(500):
        rows = _spoil(_valid_rows(rng), rng) if rng.random() < 0.5 else _valid_rows(rng)
        stored, problems = checked_rows(rows, NUM_FRAMES, WIDTH, HEIGHT)
        assert problems == validate_keyframes(rows, NUM_FRAMES, WIDTH, HEIGHT)
        if problems:
            assert stored == []
            continue
        expected = _stored(rows)
        assert stored == expected
        for got in stored:  # floats for positions and 0/1 for visibility, whatever was sent
            assert type(got[0]) is int and type(got[3]) is int and got[3] in (0, 1)
            assert all(v is None or type(v) is float for v in got[1:3])


def test_a_number_beyond_any_float_is_refused_by_name() -> None:
    stored, problems = checked_rows([[0, 10**400, 5, 1], [2**70, 1, 1, 1]], NUM_FRAMES,
                                    WIDTH, HEIGHT)
    assert stored == []
    assert problems[0] == "keyframe 0 (frame 0): x is too large for a position"
    assert problems[1].startswith(f"keyframe 1 (frame {2**70}): frame out of range")
