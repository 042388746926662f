"""Hand proposals for the views of a synthetic capture, scored against its truth: what
`dexlabel prelabel` and bench/prelabel.py report.

The prelabeler sees only the colour images; the truth (joint_2d and the hand's segmentation in
each label file) is read afterwards, to score what it proposed.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from backend.captures.layout import read_sequence
from backend.captures.truth import CaptureTruth
from backend.errors import DexlabelError
from worker.assist.prelabel import HAND_SIDES, HandSide, Prelabeler, PrelabelScore, score_proposals
from worker.formats import dexycb
from worker.hand.joints import JOINT_NAMES
from worker.synth.annotators import hand_visibility


@dataclass(frozen=True)
class ViewPrelabel:
    """One view's proposals scored: its serial, the score and the seconds the model took."""

    serial: str
    score: PrelabelScore
    seconds: float

    def summary(self) -> dict[str, Any]:
        s = self.score
        median = s.median_px()
        return {"serial": self.serial, "frames": s.frames, "visible": s.visible,
                "found": s.found, "clear": s.clear, "found_clear": s.found_clear,
                "proposed_unseen": s.proposed_unseen, "detection_rate": _rate(s.found, s.visible),
                "clear_detection_rate": _rate(s.found_clear, s.clear),
                "median_px": None if median is None else round(median, 2),
                "seconds": round(self.seconds, 2)}


def _rate(found: int, of: int) -> float | None:
    return round(found / of, 4) if of else None


def _sequence(root: Path) -> tuple[Path, list[str], int, HandSide]:
    """The capture's one sequence folder (read and checked as an import reads it), its
    serials, frame count and first hand's side."""
    metas = sorted(root.glob(dexycb.META_GLOB))
    if len(metas) != 1:
        raise DexlabelError(f"{root} holds {len(metas)} sequences ({dexycb.META_GLOB}); "
                         "give a capture with exactly one")
    plan = read_sequence(metas[0].parent)
    side = plan.hands[0].side if plan.hands else "right"
    if side not in HAND_SIDES:
        raise DexlabelError(f"{metas[0]}: mano_sides names {side!r}, not one of {HAND_SIDES}")
    return plan.seq_dir, [c.serial for c in plan.cameras], plan.num_frames, side


def prelabel_capture(root: Path, prelabeler: Prelabeler, *,
                     views: Sequence[str] | None = None) -> list[ViewPrelabel]:
    """Propose the hand in every frame of each view (all, or the serials ``views``) and score
    the proposals against the capture's labels (a synthetic capture's ``labels_*.npz``)."""
    seq_dir, serials, frames, side = _sequence(Path(root))
    unknown = sorted(set(views or ()) - set(serials))
    if unknown:
        raise DexlabelError(f"the capture has no view {unknown}; its views: {', '.join(serials)}")
    if not (seq_dir / serials[0] / dexycb.labels_file(0)).exists():
        raise DexlabelError(f"{seq_dir / serials[0]} has no {dexycb.labels_file(0)}: scoring "
                         "proposals needs a synthetic capture's ground truth (dexlabel synth)")
    truth = CaptureTruth(Path(root))
    out = []
    for serial in [s for s in serials if views is None or s in views]:
        images = []
        for f in range(frames):
            image = cv2.imread(str(seq_dir / serial / dexycb.color_file(f)), cv2.IMREAD_COLOR)
            if image is None:
                raise DexlabelError(f"cannot read {seq_dir / serial / dexycb.color_file(f)}")
            images.append(image)
        started = time.perf_counter()
        proposals = prelabeler.propose(images, side)
        seconds = time.perf_counter() - started
        joint_2d, seg = truth.view(serial, frames)
        hand_pixels = (seg == dexycb.HAND_SEG_VALUE).reshape(frames, -1).sum(axis=1)
        in_view = hand_visibility(joint_2d, seg).sum(axis=1)
        out.append(ViewPrelabel(
            serial, score_proposals(proposals, joint_2d, hand_pixels, in_view), seconds))
    return out


def overall(views: Sequence[ViewPrelabel]) -> dict[str, Any]:
    """Every view's frames together: detection rate over the visible frames and the median
    error of every proposed joint."""
    visible = sum(v.score.visible for v in views)
    found = sum(v.score.found for v in views)
    clear = sum(v.score.clear for v in views)
    found_clear = sum(v.score.found_clear for v in views)
    errors = np.concatenate([v.score.errors_px for v in views]) if views else np.zeros(0)
    return {"frames": sum(v.score.frames for v in views), "visible": visible, "found": found,
            "clear": clear, "found_clear": found_clear,
            "proposed_unseen": sum(v.score.proposed_unseen for v in views),
            "detection_rate": _rate(found, visible),
            "clear_detection_rate": _rate(found_clear, clear),
            "median_px": round(float(np.median(errors)), 2) if errors.size else None,
            # Per joint in DexYCB order: a model's joint conventions (where on the hand it puts
            # the wrist or a knuckle) show as joints off by more than the others.
            "median_px_by_joint": dict(zip(JOINT_NAMES, np.round(np.median(
                errors.reshape(-1, len(JOINT_NAMES)), axis=0), 2).tolist(), strict=True))
            if errors.size else None,
            "p90_px": round(float(np.percentile(errors, 90)), 2) if errors.size else None}
