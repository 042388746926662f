"""Swapped fingers: a label that fits the reference much better after exchanging fingers.

A worker who confuses two fingers (or labels the hand as if it were the other hand) places good
points on the wrong joints: the label is far from the reference where it claims to be, but close
to where the exchanged joints are. The reference is where the OTHER views place each joint in
this view (leave-one-out), so no second worker of the same view is needed, and its spread (how
well those views fix the point, worker.quality.support) sets how much a pixel counts.

For each candidate permutation, every frame casts a log-likelihood-ratio vote over the joints
the permutation moves: sum of (e_given^2 - e_permuted^2) / (2 sigma^2), errors normalised to
the reference's spread and capped (a wild point counts as far off either way, not as
evidence). A swap is the frame run with the largest summed vote (the maximum-sum
subarray) where that sum is decisive and the permuted label looks like careful work. Fingers
that project a few pixels apart still add up over a run of frames: evidence the per-frame
ratio of a single comparison would miss.

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

# Normalised errors are capped at this many sigmas before they vote: beyond it a point is far off
# whatever it is compared with.
CAP_SIGMAS = 6.0
# A run is a swap when its summed log-likelihood ratio reaches this (the labels as permuted
# are e^40 times likelier), over at least MIN_FRAMES frames that vote for it,
MIN_LOG_RATIO = 40.0
MIN_FRAMES = 4
# and the permuted label then looks like careful work: mean error of the moved joints below
# this many sigmas (a sloppy or random label gains by chance, never this close).
MAX_SWAPPED_SIGMAS = 3.0
# Fewest moved joints, visible in the label, that make a frame's comparison.
MIN_JOINTS = 2
# A run's first and last frames must each favour the permutation by this much, and by this
# share of the run's median vote: a frame interpolated halfway between a swapped and a correct
# keyframe votes about 0, give or take what the hand's motion between keyframes adds.
EDGE_VOTE = 2.0
EDGE_SHARE = 0.35
# Runs looked for per permutation (a worker may swap, fix it, and swap again).
MAX_RUNS = 3


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


def _normalised(offset: np.ndarray, spread: np.ndarray, sigma_px: float) -> np.ndarray:
    """(...,) offsets (..., 2) px against references of covariance spread (..., 2, 2) px^2, in
    px as against an exact reference (see worker.quality.support.normalised_errors)."""
    cov = sigma_px ** 2 * np.eye(2) + spread
    r = np.nan_to_num(offset)
    maha = np.einsum("...a,...ab,...b->...", r, np.linalg.inv(cov), r)
    return np.where(np.isfinite(offset).all(axis=-1), sigma_px * np.sqrt(maha), np.nan)


def _frame_votes(xy: np.ndarray, visible: np.ndarray, reference: np.ndarray,
                 spread: np.ndarray, perm: np.ndarray, sigma_px: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per frame (F,): the log-likelihood ratio of the permutation over the moved joints (0
    where fewer than MIN_JOINTS are measured), the mean normalised error of the permuted
    joints, and the mean raw px errors as labelled and as permuted (NaN where unmeasured)."""
    moved = np.flatnonzero(perm != np.arange(len(perm)))
    lab = np.where(visible[:, moved, None], xy[:, moved], np.nan)
    given_off = lab - reference[:, moved]
    perm_off = lab - reference[:, perm[moved]]
    given = _normalised(given_off, spread[:, moved], sigma_px)
    permuted = _normalised(perm_off, spread[:, perm[moved]], sigma_px)
    ok = np.isfinite(given) & np.isfinite(permuted)
    count = ok.sum(axis=1)
    enough = count >= MIN_JOINTS
    cap = CAP_SIGMAS * sigma_px
    g, p = np.minimum(np.nan_to_num(given), cap), np.minimum(np.nan_to_num(permuted), cap)
    vote = np.where(ok, (g ** 2 - p ** 2) / (2.0 * sigma_px ** 2), 0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_perm = np.where(ok, p, 0.0).sum(axis=1) / count
        raw_given = np.where(ok, np.linalg.norm(given_off, axis=-1), 0.0).sum(axis=1) / count
        raw_perm = np.where(ok, np.linalg.norm(perm_off, axis=-1), 0.0).sum(axis=1) / count
    nan = np.full(len(vote), np.nan)
    return (np.where(enough, vote, 0.0), np.where(enough, mean_perm, nan),
            np.where(enough, raw_given, nan), np.where(enough, raw_perm, nan))


def _best_run(votes: np.ndarray) -> tuple[int, int, float]:
    """The inclusive frame run with the largest sum of ``votes`` (F,) (Kadane), and the sum."""
    best, best_span = -np.inf, (0, -1)
    total, start = 0.0, 0
    for f, vote in enumerate(votes):
        if total <= 0.0:
            total, start = 0.0, f
        total += float(vote)
        if total > best:
            best, best_span = total, (start, f)
    return best_span[0], best_span[1], float(best)


def _describe(kind: str, fingers: tuple[str, ...], first: int, last: int) -> str:
    if kind == "mirror":
        return (f"finger order mirrored (thumb/little, index/ring exchanged) in frames "
                f"{first}-{last}")
    return f"{fingers[0]} and {fingers[1]} swapped in frames {first}-{last}"


def _runs_of(cand: Permutation, votes: tuple[np.ndarray, ...], sigma_px: float) -> list[dict]:
    """The decisive runs of one permutation's frame votes."""
    vote, mean_perm, raw_given, raw_perm = votes
    vote = vote.copy()
    found = []
    for _ in range(MAX_RUNS):
        first, last, total = _best_run(vote)
        if last < first or total < MIN_LOG_RATIO:
            break
        vote_span = vote[first:last + 1].copy()
        vote[first:last + 1] = 0.0
        typical = float(np.median(vote_span[vote_span > 0])) if (vote_span > 0).any() else 0.0
        strong = np.flatnonzero(vote_span >= max(EDGE_VOTE, EDGE_SHARE * typical))
        if strong.size == 0:
            continue
        first, last = first + int(strong[0]), first + int(strong[-1])
        span = slice(first, last + 1)
        for_it = votes[0][span] > 0
        if for_it.sum() < MIN_FRAMES or \
                np.nanmean(mean_perm[span][for_it]) > MAX_SWAPPED_SIGMAS * sigma_px:
            continue
        found.append({
            "kind": cand.kind, "fingers": list(cand.fingers), "frames": [first, last],
            "error_px": round(float(np.nanmean(raw_given[span][for_it])), 1),
            "error_swapped_px": round(float(np.nanmean(raw_perm[span][for_it])), 1),
            "log_ratio": round(float(votes[0][span].sum()), 1),
            "message": _describe(cand.kind, cand.fingers, first, last)})
    return found


def find_swaps(xy: np.ndarray, visible: np.ndarray, reference: np.ndarray,
               spread: np.ndarray | None = None, sigma_px: float = 2.0) -> list[dict]:
    """Finger confusions of one hand label against the reference.

    Args:
        xy: (F, 21, 2) the label's positions, image px (NaN where none).
        visible: (F, 21) bool, the label's visibility flags (only visible points are compared).
        reference: (F, 21, 2) where the other views place each joint in this view, px.
        spread: optional (F, 21, 2, 2) px^2 covariance of the reference (zero: exact).
        sigma_px: per-axis noise of a careful label, px.

    Returns:
        [{"kind": "swap" | "mirror", "fingers": [...], "frames": [first, last],
          "error_px": mean error of the moved joints as labelled,
          "error_swapped_px": the same after the exchange, "log_ratio": the run's summed
          vote (its evidence), "message": text}], by first frame.
    """
    if xy.shape != reference.shape or xy.ndim != 3 or visible.shape != xy.shape[:2]:
        raise ValueError(f"expected xy and reference (F, 21, 2) and visible (F, 21), got "
                         f"{xy.shape}, {reference.shape} and {visible.shape}")
    if spread is None:
        spread = np.zeros(xy.shape + (2,))
    elif spread.shape != xy.shape + (2,):
        raise ValueError(f"expected spread {xy.shape + (2,)}, got {spread.shape}")
    # A reference without a spread (too few other views) casts no vote.
    fixed = np.asarray(np.isfinite(spread).all(axis=(-1, -2)))
    reference = np.where(fixed[..., None], reference, np.nan)
    spread = np.nan_to_num(spread)
    found = []
    for cand in hand_permutations(xy.shape[1]):
        votes = _frame_votes(xy, np.asarray(visible, bool), reference, spread, cand.perm,
                             sigma_px)
        found += _runs_of(cand, votes, sigma_px)
    return sorted(found, key=lambda s: s["frames"][0])


def moved_joints(swaps: list[dict]) -> np.ndarray:
    """(K,) the joints any of ``swaps`` moves, sorted."""
    moved: set[int] = set()
    for swap in swaps:
        perm = permutation_of(swap)
        moved |= set(np.flatnonzero(perm != np.arange(len(perm))).tolist())
    return np.array(sorted(moved), dtype=int)


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


# The palm's joints (wrist and the four finger MCPs) keep their distances to each other
# through a clip, whatever the fingers do.
PALM = (0, 5, 9, 13, 17)
# The consensus is swapped over a span when its palm there matches the rest of the clip this
# much better exchanged than as it is, and is off as it is by at least this much (metres).
PALM_RATIO = 0.5
PALM_MIN_OFF_M = 0.004


def _palm_costs(consensus: np.ndarray, swap: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """Per frame (F,): how far the consensus's palm is, as it is and with the swap's fingers
    exchanged, from the palm outside the swap's span (summed |distance - reference|, m); None
    where nothing outside the span (or no palm joint the swap moves) gives a reference."""
    perm = permutation_of(swap)
    first, last = swap["frames"]
    frames = np.arange(consensus.shape[0])
    outside = np.setdiff1d(frames, frames[first:last + 1])
    pairs = [(i, j) for n, i in enumerate(PALM) for j in PALM[n + 1:]
             if perm[i] != i or perm[j] != j]
    if outside.size == 0 or not pairs:
        return None
    ii, jj = np.array([i for i, _ in pairs]), np.array([j for _, j in pairs])

    def distances(order: np.ndarray) -> np.ndarray:
        return np.linalg.norm(consensus[:, order[ii]] - consensus[:, order[jj]], axis=-1)

    as_is = distances(np.arange(len(perm)))
    if not np.isfinite(as_is[outside]).any():
        return None
    reference = np.nanmedian(np.where(np.isfinite(as_is[outside]), as_is[outside], np.nan),
                             axis=0)

    def cost(dist: np.ndarray) -> np.ndarray:
        off = np.abs(dist - reference)
        return np.where(np.isfinite(off).any(axis=1), np.nansum(off, axis=1), np.nan)

    return cost(as_is), cost(distances(perm))


def _palm_swapped(as_is: np.ndarray, exchanged: np.ndarray) -> bool:
    has = np.isfinite(as_is) & np.isfinite(exchanged)
    if not has.any():
        return False
    a, e = float(np.median(as_is[has])), float(np.median(exchanged[has]))
    return a > PALM_MIN_OFF_M and e < PALM_RATIO * a


def consensus_swapped(consensus: np.ndarray, swap: dict) -> bool:
    """Whether the consensus itself exchanges the swap's fingers over the span: then it was the
    swappers who won that span (several swappers in a small pool), not this label who swapped.

    A hand's palm is rigid: the distances between the wrist and the MCPs outside the span are
    the reference. A consensus that holds the true fingers keeps them inside the span; one
    that exchanged them matches them only once exchanged back. consensus: (F, P, 3) world m.
    """
    costs = _palm_costs(consensus, swap)
    if costs is None:
        return False
    first, last = swap["frames"]
    return _palm_swapped(costs[0][first:last + 1], costs[1][first:last + 1])


def consensus_swapped_span(consensus: np.ndarray, swap: dict) -> list[int]:
    """The swap's span grown over the neighbouring frames where the consensus is swapped too
    (a label that shows the fingers only in part of the span accuses only that part)."""
    costs = _palm_costs(consensus, swap)
    first, last = swap["frames"]
    if costs is None:
        return [first, last]
    as_is, exchanged = costs

    def swapped(f: int) -> bool:
        return bool(np.isfinite(as_is[f]) and np.isfinite(exchanged[f])
                    and as_is[f] > PALM_MIN_OFF_M and exchanged[f] < PALM_RATIO * as_is[f])

    while first > 0 and swapped(first - 1):
        first -= 1
    while last + 1 < len(as_is) and swapped(last + 1):
        last += 1
    return [first, last]


def merge_swaps(swaps: list[dict], gap: int = 10) -> list[dict]:
    """One label's swaps with spans of the same permutation joined across gaps of up to ``gap``
    frames (frames where the label shows too few of the fingers to vote)."""
    out: list[dict] = []
    for swap in sorted(swaps, key=lambda s: (s["kind"], s["fingers"], s["frames"][0])):
        last = out[-1] if out else None
        if last is not None and (last["kind"], last["fingers"]) == (swap["kind"], swap["fingers"]) \
                and swap["frames"][0] - last["frames"][1] <= gap + 1:
            last["frames"] = [last["frames"][0], max(last["frames"][1], swap["frames"][1])]
            last["log_ratio"] = last.get("log_ratio", 0.0) + swap.get("log_ratio", 0.0)
        else:
            out.append(dict(swap, frames=list(swap["frames"])))
    return out


def overlaps(a: dict, b: dict) -> bool:
    """Whether two swaps exchange the same fingers over overlapping frames."""
    return (a["kind"], a["fingers"]) == (b["kind"], b["fingers"]) and \
        a["frames"][0] <= b["frames"][1] and b["frames"][0] <= a["frames"][1]


def swap_corrections(swaps: dict[str, list[dict]],
                     consensus: np.ndarray) -> dict[str, list[dict]]:
    """Swaps to undo per label before the consensus is refitted.

    Args:
        swaps: {label key: its detected swaps} for every label of the target.
        consensus: (F, 21, 3) world metres, the consensus they were detected against.

    Returns:
        {label key: swaps to undo}: a label's own swaps, except where the consensus itself is
        swapped over the span (consensus_swapped); then the labels that agreed with it (not
        flagged with that swap) are the ones to correct.
    """
    own: dict[str, list[dict]] = {key: [] for key in swaps}
    # Flipped spans of one permutation are merged, so that no label is exchanged twice.
    flipped: dict[tuple, dict] = {}
    for key, found in swaps.items():
        for swap in merge_swaps(found):
            if not consensus_swapped(consensus, swap):
                own[key].append(swap)
                continue
            span = consensus_swapped_span(consensus, swap)
            group = flipped.setdefault((swap["kind"], tuple(swap["fingers"])),
                                       {"frames": span, "keys": set()})
            group["frames"] = [min(group["frames"][0], span[0]), max(group["frames"][1], span[1])]
            group["keys"].add(key)
    out = own
    for (kind, fingers), group in flipped.items():
        swap = {"kind": kind, "fingers": list(fingers), "frames": group["frames"]}
        for key in out:
            if key not in group["keys"]:
                out[key].append(swap)
    return out
