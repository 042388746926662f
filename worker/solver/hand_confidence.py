"""How far each solved hand frame can be trusted, from how its labels were decided.

Agreement between views proves little where every view interpolated the same frames: their
straight lines between keyframes are wrong the same way when the hand moves fast, and the
solve fits them well. So a frame is judged by its evidence, per view:

  decided view   most of the view's labelled visible joints there are keyframes (the worker
                 placed them on this frame) or interpolated positions the view's own images
                 confirm (worker.assist.stretches: the tracked point follows the line);
  guessing view  labelled there, but mostly by interpolation the images could not check;
  reprojection   median reprojection error (px) of the solved joints against the labels;
  depth          the frame's depth agreement (RMS point-to-mesh distance, mm).

A hand frame is flagged, with the reason, when fewer than MIN_DECIDED_VIEWS views decided it
(the rest interpolate without image support, or do not label it), when its joints reproject
far from the labels, or when it has no solution. confidence (0..1) is the weakest of the
factors, each 1 when well supported and 0 at twice its flag's threshold. Labels the images
contradict (EVIDENCE_CONTRADICTED) are left out of the solve before it runs; where such
labels were all a view had, the view does not decide the frame.
"""

from __future__ import annotations

import numpy as np

from worker.assist.stretches import EVIDENCE_CONFIRMED, EVIDENCE_KEYED, EVIDENCE_NONE

# Two views pin a point in 3D; fewer, and the solve leans on the hand model's prior alone.
MIN_DECIDED_VIEWS = 2
# Views of decided evidence that make a frame fully supported.
FULL_DECIDED_VIEWS = 3
# A careful label reprojects ~2-3 px from a good solve (DexYCB reports 4-5 px on fingertips);
# a frame whose joints reproject beyond this median is not where its labels say.
KPT_FLAG_PX = 10.0
# The whole scene's depth within about 6 mm RMS on a good frame (bench/solve.py at 640x480).
DEPTH_FLAG_MM = 20.0


def decided_views(evidence: np.ndarray, visible: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F,) views that decided each frame and (F,) views that label it at all.

    evidence: (V, F, J) EVIDENCE_* codes; visible: (V, F, J) bool labelled visible with a
    position (contradicted labels already removed). A view decides a frame where at least
    half of its labelled visible joints are keyed or confirmed."""
    labelled = visible & (evidence != EVIDENCE_NONE)
    decided = labelled & ((evidence == EVIDENCE_KEYED) | (evidence == EVIDENCE_CONFIRMED))
    count = labelled.sum(axis=2)
    decides = (count > 0) & (2 * decided.sum(axis=2) >= count)
    return decides.sum(axis=0), (count > 0).sum(axis=0)


def _plural(count: int, word: str) -> str:
    return f"{count} {word}" + ("" if count == 1 else "s")


def judge_frame(decided: int, labelling: int, kpt_px: float, depth_mm: float
                ) -> tuple[float, str | None]:
    """(confidence, reason or None) of one solved hand frame from its evidence."""
    factors = [min(decided / FULL_DECIDED_VIEWS, 1.0)]
    if np.isfinite(kpt_px):
        factors.append(1.0 - min(max(kpt_px - KPT_FLAG_PX / 2, 0.0) / KPT_FLAG_PX, 1.0))
    if np.isfinite(depth_mm):
        factors.append(1.0 - min(max(depth_mm - DEPTH_FLAG_MM / 2, 0.0) / DEPTH_FLAG_MM, 1.0))
    confidence = float(min(factors))
    if decided < MIN_DECIDED_VIEWS:
        guessing = labelling - decided
        return confidence, (f"hand decided by {_plural(decided, 'view')} from keyframes or "
                            f"tracking; {_plural(guessing, 'view')} only interpolate there "
                            "without support from the images")
    if np.isfinite(kpt_px) and kpt_px > KPT_FLAG_PX:
        return confidence, f"hand joints reproject {kpt_px:.0f} px from the labels"
    if np.isfinite(depth_mm) and depth_mm > DEPTH_FLAG_MM:
        return confidence, f"depth disagrees with the solved scene by {depth_mm:.0f} mm RMS"
    return confidence, None


def hand_confidence(evidence: np.ndarray | None, visible: np.ndarray, labelled: np.ndarray,
                    reasons: list[str | None], kpt_error_px: np.ndarray,
                    depth_rms_mm: np.ndarray) -> tuple[np.ndarray, list[str | None]]:
    """(F,) confidence in [0, 1] and (F,) reasons (None = trusted) of a solve's hand frames.

    evidence: (V, F, J) codes or None (every label keyed); visible: (V, F, J) bool, labels
    the solve used; labelled: (F,) bool, frames with a hand solution; reasons: (F,) why a
    frame has none; kpt_error_px: (F, V, J) px; depth_rms_mm: (F,) mm.
    """
    visible = np.asarray(visible, bool)
    if visible.ndim != 3:
        raise ValueError(f"expected visible (V, F, J), got {visible.shape}")
    codes = (np.where(visible, EVIDENCE_KEYED, EVIDENCE_NONE) if evidence is None
             else np.asarray(evidence))
    decided, labelling = decided_views(codes, visible)
    frames = visible.shape[1]
    confidence = np.zeros(frames)
    flags: list[str | None] = [None] * frames
    errors = np.asarray(kpt_error_px, np.float64)
    for f in range(frames):
        if not labelled[f]:
            flags[f] = reasons[f] or "hand not solved on this frame"
            continue
        finite = errors[f][np.isfinite(errors[f])]
        kpt = float(np.median(finite)) if finite.size else float("nan")
        confidence[f], flags[f] = judge_frame(int(decided[f]), int(labelling[f]), kpt,
                                              float(depth_rms_mm[f]))
    return confidence, flags
