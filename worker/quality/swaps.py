"""Swapped fingers: a label that fits the reference much better after exchanging fingers.

A worker who confuses two fingers (or labels the hand as if it were the other hand) places good
points on the wrong joints: the label is far from the reference where it claims to be, but close
to where the exchanged joints are. For each candidate permutation we compare, frame by frame,
the label's error as given with its error after the permutation, over the joints it moves, and
report runs of frames where the permuted error is decisively lower.

Swaps feed back into the consensus (swap_corrections): the consensus is refitted with them
undone; when the consensus itself jumps between the fingers at a span's edges, the swappers
outvoted the others there, and the labels that agreed with it are the ones corrected.

Hand joints in DexYCB order (0 wrist; thumb 1-4, index 5-8, middle 9-12, ring 13-16,
little 17-20); positions in image pixels of one view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.hand.joints import FINGER_NAMES

# A frame votes "swapped" when the permuted error is below this fraction of the error as given
WEAK_RATIO = 0.8
# and small in absolute terms: the permuted points must then look like good labels.
MAX_SWAPPED_PX = 10.0
# A vote is strong when the permuted error is also below half the error as given and lower by
# at least 4 px (careful labels differ from the reference by ~2.5 px of noise).
STRONG_RATIO = 0.5
STRONG_GAIN_PX = 4.0
# A run of votes is a swap with this many strong votes, or, where the fingers project close
# together (a few px apart), with this many votes whose mean errors differ decisively.
MIN_STRONG_FRAMES = 4
MIN_WEAK_FRAMES = 8
WEAK_RUN_RATIO = 0.6
WEAK_RUN_GAIN_PX = 2.0
# Up to this many frames without a vote (none of them clearly against) do not break a run.
GAP_FRAMES = 3
# Fewest moved joints, visible in the label, that make a frame's comparison.
MIN_JOINTS = 2


@dataclass(frozen=True)
class Permutation:
    """One candidate confusion: ``perm[j]`` is the joint the label of joint j really shows.

    kind: "swap" (two adjacent fingers exchanged) or "mirror" (finger order reversed).
    fingers: the finger names involved, as reported.
    """

    kind: str
    fingers: tuple[str, ...]
    perm: np.ndarray


def _finger(index: int) -> list[int]:
    return [1 + 4 * index + k for k in range(4)]


def hand_permutations(points: int = 21) -> list[Permutation]:
    """Adjacent finger exchanges and the mirrored finger order, as permutations of 21 joints."""
    if points != 21:
        raise ValueError(f"finger permutations need the 21 hand joints, got {points} points")
    out = []
    for a in range(len(FINGER_NAMES) - 1):
        perm = np.arange(points)
        perm[_finger(a)], perm[_finger(a + 1)] = _finger(a + 1), _finger(a)
        out.append(Permutation("swap", (FINGER_NAMES[a], FINGER_NAMES[a + 1]), perm))
    perm = np.arange(points)
    for a in range(len(FINGER_NAMES)):
        perm[_finger(a)] = _finger(len(FINGER_NAMES) - 1 - a)
    out.append(Permutation("mirror", ("thumb", "little", "index", "ring"), perm))
    return out


def _frame_costs(xy: np.ndarray, visible: np.ndarray, reference: np.ndarray,
                 perm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean error (F,) of the moved joints as labelled and as permuted; NaN where fewer than
    half of them can be measured."""
    moved = np.flatnonzero(perm != np.arange(len(perm)))
    lab = np.where(visible[:, moved, None], xy[:, moved], np.nan)
    given = np.linalg.norm(lab - reference[:, moved], axis=-1)
    swapped = np.linalg.norm(lab - reference[:, perm[moved]], axis=-1)
    ok = np.isfinite(given) & np.isfinite(swapped)
    count = ok.sum(axis=1)
    enough = count >= MIN_JOINTS
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_given = np.where(ok, given, 0.0).sum(axis=1) / count
        mean_swapped = np.where(ok, swapped, 0.0).sum(axis=1) / count
    return np.where(enough, mean_given, np.nan), np.where(enough, mean_swapped, np.nan)


def _runs(votes: np.ndarray, against: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive frame runs of ``votes`` (F,) bool, bridging up to GAP_FRAMES frames that do not
    vote ``against`` (F,) bool."""
    frames: list[int] = np.flatnonzero(votes).tolist()
    if not frames:
        return []
    runs: list[tuple[int, int]] = []
    start = last = frames[0]
    for f in frames[1:]:
        if f - last - 1 > GAP_FRAMES or against[last + 1:f].any():
            runs.append((start, last))
            start = f
        last = f
    runs.append((start, last))
    return runs


def _decisive(given: np.ndarray, swapped: np.ndarray, weak: np.ndarray, strong: np.ndarray) -> bool:
    """Whether a run's votes (arrays over the run's frames) make a swap."""
    if strong.sum() >= MIN_STRONG_FRAMES:
        return True
    if weak.sum() < MIN_WEAK_FRAMES:
        return False
    mean_given, mean_swapped = given[weak].mean(), swapped[weak].mean()
    return mean_swapped <= WEAK_RUN_RATIO * mean_given and \
        mean_given - mean_swapped >= WEAK_RUN_GAIN_PX


def _describe(kind: str, fingers: tuple[str, ...], first: int, last: int) -> str:
    if kind == "mirror":
        return (f"finger order mirrored (thumb/little, index/ring exchanged) in frames "
                f"{first}-{last}")
    return f"{fingers[0]} and {fingers[1]} swapped in frames {first}-{last}"


def find_swaps(xy: np.ndarray, visible: np.ndarray, reference: np.ndarray) -> list[dict]:
    """Finger confusions of one hand label against the reference.

    Args:
        xy: (F, 21, 2) the label's positions, image px (NaN where none).
        visible: (F, 21) bool, the label's visibility flags (only visible points are compared).
        reference: (F, 21, 2) where the other views place each joint in this view, px.

    Returns:
        [{"kind": "swap" | "mirror", "fingers": [...], "frames": [first, last],
          "error_px": mean error of the moved joints as labelled,
          "error_swapped_px": the same after the exchange, "message": text}], by first frame.
    """
    if xy.shape != reference.shape or xy.ndim != 3 or visible.shape != xy.shape[:2]:
        raise ValueError(f"expected xy and reference (F, 21, 2) and visible (F, 21), got "
                         f"{xy.shape}, {reference.shape} and {visible.shape}")
    found = []
    for cand in hand_permutations(xy.shape[1]):
        given, swapped = _frame_costs(xy, visible, reference, cand.perm)
        with np.errstate(invalid="ignore"):
            weak = (swapped < WEAK_RATIO * given) & (swapped < MAX_SWAPPED_PX)
            strong = weak & (swapped < STRONG_RATIO * given) & (given - swapped > STRONG_GAIN_PX)
            # Only frames where the labels as given fit clearly better break a run.
            against = given < WEAK_RATIO * swapped
        for first, last in _runs(weak, against):
            span = slice(first, last + 1)
            ok = weak[span]
            if not _decisive(given[span], swapped[span], ok, strong[span]):
                continue
            found.append({
                "kind": cand.kind, "fingers": list(cand.fingers), "frames": [first, last],
                "error_px": round(float(np.mean(given[span][ok])), 1),
                "error_swapped_px": round(float(np.mean(swapped[span][ok])), 1),
                "message": _describe(cand.kind, cand.fingers, first, last)})
    return sorted(found, key=lambda s: s["frames"][0])


def permutation_of(swap: dict) -> np.ndarray:
    """(21,) the joint permutation of a reported swap (its "kind" and "fingers")."""
    for cand in hand_permutations():
        if cand.kind == swap["kind"] and list(cand.fingers) == list(swap["fingers"]):
            return cand.perm
    raise ValueError(f"no permutation for {swap['kind']} of {swap['fingers']}")


def undo_swaps(xy: np.ndarray, visible: np.ndarray,
               swaps: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """The label with its reported swaps undone over their frames, (F, 21, 2) and (F, 21): the
    points a swapping worker placed are good observations of the exchanged joints. Every
    candidate permutation is its own inverse, so undoing applies it once more."""
    xy, visible = xy.copy(), visible.copy()
    for swap in swaps:
        perm = permutation_of(swap)
        first, last = swap["frames"]
        span = slice(first, last + 1)
        xy[span] = xy[span][:, perm]
        visible[span] = visible[span][:, perm]
    return xy, visible


def consensus_swapped(consensus: np.ndarray, swap: dict) -> bool:
    """Whether the consensus itself exchanges the swap's fingers at the span's edges: then it
    was the swappers who won that span (several swappers in a small pool), not this label who
    swapped. consensus: (F, P, 3) world metres; a true swap leaves it smooth across the edges."""
    perm = permutation_of(swap)
    moved = np.flatnonzero(perm != np.arange(len(perm)))
    first, last = swap["frames"]
    edges = [(first - 1, first)] if first > 0 else []
    edges += [(last, last + 1)] if last + 1 < consensus.shape[0] else []
    ratios = []
    for before, after in edges:
        a = consensus[before, moved]
        as_is = np.nansum(np.linalg.norm(consensus[after, moved] - a, axis=-1))
        exchanged = np.nansum(np.linalg.norm(consensus[after, perm[moved]] - a, axis=-1))
        ratios.append(exchanged / max(as_is, 1e-9))
    # One clean edge suffices (the other may be blurred by interpolated keyframes), as long as
    # no edge speaks against it.
    return bool(ratios) and min(ratios) < 0.5 and max(ratios) < 1.0


def merge_swaps(swaps: list[dict], gap: int = 10) -> list[dict]:
    """One label's swaps with spans of the same permutation joined across gaps of up to ``gap``
    frames (frames where the label shows too few of the fingers to vote)."""
    out: list[dict] = []
    for swap in sorted(swaps, key=lambda s: (s["kind"], s["fingers"], s["frames"][0])):
        last = out[-1] if out else None
        if last is not None and (last["kind"], last["fingers"]) == (swap["kind"], swap["fingers"]) \
                and swap["frames"][0] - last["frames"][1] <= gap + 1:
            last["frames"] = [last["frames"][0], max(last["frames"][1], swap["frames"][1])]
        else:
            out.append(dict(swap, frames=list(swap["frames"])))
    return out


def swap_corrections(swaps: dict[str, list[dict]],
                     consensus: np.ndarray) -> dict[str, list[dict]]:
    """Swaps to undo per label before the consensus is refitted.

    Args:
        swaps: {label key: its detected swaps} for every label of the target.
        consensus: (F, 21, 3) world metres, the consensus they were detected against.

    Returns:
        {label key: swaps to undo}: a label's own swaps, except where the consensus jumps at the
        span's edges; then the consensus was swapped there, and the labels that agreed with it
        (not flagged with that swap) are the ones to correct.
    """
    out: dict[str, list[dict]] = {key: [] for key in swaps}
    # Flipped spans of one permutation are merged, so that no label is exchanged twice.
    flipped: dict[tuple, dict] = {}
    for key, found in swaps.items():
        for swap in merge_swaps(found):
            if not consensus_swapped(consensus, swap):
                out[key].append(swap)
                continue
            group = flipped.setdefault((swap["kind"], tuple(swap["fingers"])),
                                       {"frames": list(swap["frames"]), "keys": set()})
            group["frames"] = [min(group["frames"][0], swap["frames"][0]),
                               max(group["frames"][1], swap["frames"][1])]
            group["keys"].add(key)
    for (kind, fingers), group in flipped.items():
        swap = {"kind": kind, "fingers": list(fingers), "frames": group["frames"]}
        for key in out:
            if key not in group["keys"]:
                out[key].append(swap)
    return out
