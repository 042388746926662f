"""The calibration version in use applied to a solve's inputs: each view's labels and depth
re-indexed to world time by its time offset, its depth re-registered and re-scaled.

Entries are :func:`backend.captures.calibration.camera_entry` dicts, one per view in view
order; with the imported calibration (offset 0, scale 1, no shift) everything passes unchanged.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from worker.rig import apply_depth_correction, apply_time_offsets
from worker.rig.common import shift_frames
from worker.solver import HandTarget, ObjectTarget


def _offsets(entries: list[dict[str, Any]]) -> list[int]:
    return [int(e["time_offset_frames"]) for e in entries]


def hand_in_world_time(hand: HandTarget | None, entries: list[dict[str, Any]]
                       ) -> HandTarget | None:
    """The hand's (V, F, 21, 2) labels (and their evidence codes) with each view shifted by its
    time offset."""
    offsets = _offsets(entries)
    if hand is None or not any(offsets):
        return hand
    keypoints, visible = apply_time_offsets(hand.keypoints, hand.visible, offsets)
    evidence = hand.evidence
    if evidence is not None:
        # How each label was decided moves with it (0, "no label", where a view has no frame).
        evidence = np.stack([shift_frames(np.asarray(codes), offset, 0)
                             for codes, offset in zip(evidence, offsets, strict=True)])
    return replace(hand, keypoints=keypoints, visible=visible, evidence=evidence)


def objects_in_world_time(objects: list[ObjectTarget], entries: list[dict[str, Any]]
                          ) -> list[ObjectTarget]:
    """Every landmark's (F, 2) track shifted by its view's time offset."""
    offsets = _offsets(entries)
    if not any(offsets):
        return objects
    return [replace(obj, landmarks=[
        replace(mark, xy=shift_frames(mark.xy, offsets[mark.view]),
                visible=shift_frames(mark.visible, offsets[mark.view], False))
        for mark in obj.landmarks]) for obj in objects]


def depth_in_world_time(depth: list[np.ndarray | None], entries: list[dict[str, Any]]
                        ) -> list[np.ndarray | None]:
    """Each view's (F, H, W) uint16 mm maps shifted in time, re-registered and re-scaled."""
    out: list[np.ndarray | None] = []
    for maps, entry in zip(depth, entries, strict=True):
        shift = tuple(int(s) for s in entry["depth_shift_px"])
        scale, offset = float(entry["depth_scale"]), int(entry["time_offset_frames"])
        if maps is None or (offset == 0 and scale == 1.0 and shift == (0, 0)):
            out.append(maps)
            continue
        out.append(apply_depth_correction(maps, offset, scale, (shift[0], shift[1])))
    return out
