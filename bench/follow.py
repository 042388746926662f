"""Benchmark: a first view's hand labelled with the hand model followed through the view's depth
(worker.solver.follow) against tracking alone (worker.assist.lk), in process.

A first view is one no accepted view can suggest for: its worker starts from nothing. On each
view of a synthetic capture (``--capture``, or generated from ``--seed`` with ``--views`` x
``--frames``, one object), for up to ``--max-views`` views:

    follow    the hand model fitted to a careful worker's first keyframes (the first frame and
              the visibility changes, CAREFUL_SIGMA_PX noise) and carried through the view's
              depth until the depth stops supporting it: the share of the visible
              joint-frames it proposes ("proposed"), its error against the true joints where it
              proposes (median and p90 px, share within the careful worker's tolerance), where
              it stopped and the seconds it took;
    lk        the careful assisted worker of worker.synth.assisted with the page's tracking
              (follows, re-tracks), no suggestions: the page's edit count and the error of its
              labels (px at visible joints, over all frames);
    model     the same worker asking for the model follow first (accepting it, dragging what
              is off, asking again from a frame where a few joints came off, as the page
              says), then tracking the rest.

Both workers draw the same noise (``--crowd-seed`` and the view). Effort is the page's edit
counter (clicks, drags, occlusion keys, Enter), as bench/cost.py reports "first_view_actions".
The synthetic world is kind to a model follow: the capture's hand is drawn from the solver's own
hand model and its depth is exact, so these figures are an upper bound for real footage.

Prints a line per view, then one JSON line: {"capture", "frames", "views", "crowd_seed",
"tolerance_px", "per_view": [...], "mean": {"lk_edits", "model_edits", ...}, "seconds"}.
Usage: python bench/follow.py [--capture DIR | --seed 5151 --frames 72 --views 8]
                              [--max-views 8] [--crowd-seed 3]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from _crowd_labels import grey_view

ROOT = Path(__file__).resolve().parents[1]


def _scene(capture: Path) -> dict[str, Any]:
    from backend.captures.layout import read_sequence
    from backend.captures.truth import CaptureTruth
    from worker.formats import dexycb
    from worker.geometry.cameras import CameraModel, intrinsics_matrix

    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    plan = read_sequence(seq_dir)
    hand = plan.hands[0]
    return {"dir": seq_dir, "plan": plan, "truth": CaptureTruth(capture), "side": hand.side,
            "betas": np.asarray(hand.betas or np.zeros(10), float),
            "cameras": [CameraModel(intrinsics_matrix(c.fx, c.fy, c.ppx, c.ppy),
                                    np.asarray(c.distortion), np.asarray(c.extrinsics),
                                    c.width, c.height) for c in plan.cameras]}


def _stat(err: np.ndarray, tolerance: float) -> dict[str, float | int | None]:
    if not err.size:
        return {"n": 0, "median_px": None, "p90_px": None, "within_tolerance": None}
    return {"n": int(err.size), "median_px": round(float(np.median(err)), 2),
            "p90_px": round(float(np.percentile(err, 90)), 2),
            "within_tolerance": round(float(np.mean(err <= tolerance)), 3)}


def _label_error(tracks: list[list[list[Any]]], truth: np.ndarray, visible: np.ndarray
                 ) -> float:
    """Median px of the saved labels (dense) from the truth at visible joints."""
    from worker.tracks.interpolate import dense_points

    xy, _ = dense_points([(p, [r[:4] for r in rows]) for p, rows in enumerate(tracks)],
                         truth.shape[0], truth.shape[1])
    err = np.linalg.norm(xy - truth, axis=-1)[visible]
    return round(float(np.median(np.where(np.isfinite(err), err, np.inf))), 2)


def _view(scene: dict[str, Any], index: int, crowd_seed: int) -> dict[str, Any]:
    from worker.assist.checks import check_key
    from worker.formats import dexycb
    from worker.solver.follow import follow_hand
    from worker.synth.annotators import CAREFUL_SIGMA_PX, hand_visibility
    from worker.synth.assisted import (
        TOLERANCE_PX,
        AssistSetting,
        _must_frames,
        _seen,
        assisted_annotate,
    )

    plan, cam = scene["plan"], scene["cameras"][index]
    serial, frames = plan.cameras[index].serial, plan.num_frames
    joint_2d, seg = scene["truth"].view(serial, frames)
    visible = hand_visibility(joint_2d, seg)
    truth = np.where((joint_2d == dexycb.NO_LABEL).all(axis=2, keepdims=True), np.nan,
                     joint_2d.astype(np.float64))
    grey = grey_view(scene["dir"] / serial, frames)
    depth = np.stack([cv2.imread(str(scene["dir"] / serial / dexycb.depth_file(f)),
                                 cv2.IMREAD_UNCHANGED) for f in range(frames)])

    def model(anchors: list[list[list[Any]]], begin: int | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
        keypoints = np.full((frames, len(anchors), 2), np.nan)
        keyed = np.zeros((frames, len(anchors)), bool)
        for p, rows in enumerate(anchors):
            for f, x, y, vis in (r[:4] for r in rows):
                if vis and x is not None:
                    keypoints[f, p], keyed[f, p] = (x, y), True
        found = follow_hand(cam, depth, keypoints, keyed, scene["side"], scene["betas"],
                            begin=begin)
        return found.xy, found.ok

    # The follow alone, from the careful worker's first keyframes.
    seen = _seen(truth, (cam.width, cam.height), np.random.default_rng((crowd_seed, index)),
                 CAREFUL_SIGMA_PX)
    keypoints = np.full(truth.shape, np.nan)
    keyed = np.zeros(visible.shape, bool)
    for p in range(truth.shape[1]):
        for f in _must_frames(visible[:, p], np.ones(frames, bool), last=False):
            if visible[f, p]:
                keypoints[f, p], keyed[f, p] = seen[f, p], True
    tick = time.perf_counter()
    found = follow_hand(cam, depth, keypoints, keyed, scene["side"], scene["betas"])
    seconds = time.perf_counter() - tick
    err = np.linalg.norm(found.xy - truth, axis=-1)
    out: dict[str, Any] = {
        "serial": serial, "visible_share": round(float(visible.mean()), 3),
        "follow": {**_stat(err[found.ok & visible], TOLERANCE_PX),
                   "proposed": round(float((found.ok & visible).sum() / max(visible.sum(), 1)),
                                     3),
                   "start": found.start, "stops": found.stops,
                   "seconds": round(seconds, 1)}}
    key = check_key("bench-follow")
    for name, with_model in (("lk", False), ("model", True)):
        setting = AssistSetting(grey, key, 1000 + index, follows=True, retracks=True,
                                model=model if with_model else None)
        work = assisted_annotate(truth, visible, setting, "careful",
                                 np.random.default_rng((crowd_seed, index, 1)))
        out[name] = {"edits": work.actions["edits"], "actions": work.actions,
                     "label_median_px": _label_error(work.tracks, truth, visible)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--capture", type=Path, help="a capture folder (else one is generated)")
    parser.add_argument("--seed", type=int, default=5151, help="capture seed (no test uses it)")
    parser.add_argument("--frames", type=int, default=72)
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--max-views", type=int, default=8)
    parser.add_argument("--crowd-seed", type=int, default=3)
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    from worker.synth.assisted import TOLERANCE_PX

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        capture = args.capture
        if capture is None:
            from worker.synth.capture import generate_capture

            capture = Path(tmp) / f"s{args.seed}"
            generate_capture(capture, seed=args.seed, frames=args.frames, views=args.views,
                             objects=1)
        scene = _scene(capture)
        views = min(args.max_views, len(scene["cameras"]))
        per_view = []
        for index in range(views):
            row = _view(scene, index, args.crowd_seed)
            per_view.append(row)
            print(f"view {row['serial']}: follow {row['follow']['proposed']:.0%} proposed, "
                  f"median {row['follow']['median_px']} px, {row['follow']['seconds']} s; "
                  f"edits lk {row['lk']['edits']} model {row['model']['edits']}", flush=True)
    mean = {f"{k}_edits": round(float(np.mean([r[k]["edits"] for r in per_view])), 1)
            for k in ("lk", "model")}
    mean.update({f"{k}_label_median_px": round(float(np.mean(
        [r[k]["label_median_px"] for r in per_view])), 2) for k in ("lk", "model")})
    mean["follow_proposed"] = round(float(np.mean([r["follow"]["proposed"]
                                                   for r in per_view])), 3)
    print(json.dumps({"capture": str(args.capture or f"seed {args.seed}"),
                      "frames": scene["plan"].num_frames, "views": views,
                      "crowd_seed": args.crowd_seed, "tolerance_px": TOLERANCE_PX,
                      "per_view": per_view, "mean": mean,
                      "seconds": round(time.perf_counter() - started, 1)}))


if __name__ == "__main__":
    main()
