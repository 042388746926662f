"""Frame spans: runs of frames as [first, last] pairs, and how messages name them."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def frame_spans(flags: Sequence[bool] | np.ndarray) -> list[list[int]]:
    """Inclusive [start, end] spans of the frames where flags is true."""
    spans: list[list[int]] = []
    for f, flag in enumerate(flags):
        if not flag:
            continue
        if spans and spans[-1][1] == f - 1:
            spans[-1][1] = f
        else:
            spans.append([f, f])
    return spans


def format_spans(spans: list[list[int]]) -> str:
    """'frame 5' or 'frames 0-11, 20'."""
    single = len(spans) == 1 and spans[0][0] == spans[0][1]
    text = ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in spans)
    return f"{'frame' if single else 'frames'} {text}"
