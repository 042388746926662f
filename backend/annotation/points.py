"""What a task's points are called, how they are drawn, and how hand joints connect."""

from __future__ import annotations

from worker.hand import JOINT_NAMES, JOINT_PARENTS

HAND_POINTS = 21
OBJECT_POINTS = 2

# One colour per finger (wrist grey), so a swapped finger stands out on the canvas.
FINGER_COLOURS = {
    "wrist": "#9aa3ad",
    "thumb": "#e6550d",
    "index": "#31a354",
    "middle": "#3182bd",
    "ring": "#756bb1",
    "little": "#d6338a",
}
LANDMARK_COLOURS = ("#ff7f0e", "#17becf")


def point_names(kind: str) -> list[str]:
    if kind == "hand":
        return list(JOINT_NAMES)
    return [f"landmark_{i + 1}" for i in range(OBJECT_POINTS)]


def point_colours(kind: str) -> list[str]:
    if kind == "hand":
        return [FINGER_COLOURS[name.split("_")[0]] for name in JOINT_NAMES]
    return list(LANDMARK_COLOURS)


def skeleton(kind: str) -> list[list[int]]:
    """Bones as [parent, child] point indices (hands only)."""
    if kind != "hand":
        return []
    return [[parent, child] for child, parent in enumerate(JOINT_PARENTS) if parent >= 0]
