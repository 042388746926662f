"""Benchmark: the optional hand prelabeler (MediaPipe's hand landmarker, extra ``prelabel``)
on synthetic captures, scored against their truth.

For one seed, up to four captures are rendered from the same scene (``--renders``): "plain",
the default renders (a hand with no arm, the fixed light); "forearm" (``synth --forearm``:
bare forearm and sleeve, worker.synth.forearm); "light" (``synth --varied-light``: a room's
light drawn from the seed, worker.synth.render.varied_lighting); "forearm_light", both. On
each, every view's colour frames go to the prelabeler (images only; the truth is read
afterwards) and per view and over all views it reports:

    detection_rate  frames where the hand is visible (at least 500 px of its segmentation) and
                    a hand of the capture's side was proposed, over the visible frames;
    clear_detection_rate  the same over the visible frames with 16 or more of the 21 joints
                    in view (inside the image, not covered by an object: the grasped box
                    hides the fingers from some cameras for most of a clip);
    median_px       median distance of every proposed joint (21 per found frame) to the true
                    joint, pixels; p90_px its 90th percentile;
    proposed_unseen proposals on frames where the hand is not visible.

Without MediaPipe (the extra is not installed) it renders nothing and prints
``{"available": false, ...}``, exit status 0, so CI's smoke run needs no extra.

Prints one JSON line: {"available", "model", "video", "seed", "frames", "views", "renders":
{name: {"overall", "views": [...]}}, "seconds"}.
Usage: python bench/prelabel.py [--seed 901] [--frames 24] [--views 4] [--still]
                                [--renders plain,forearm,light,forearm_light]
       (pip install 'dexlabel[prelabel]' first)
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RENDERS = {"plain": {}, "forearm": {"forearm": True}, "light": {"varied_light": True},
           "forearm_light": {"forearm": True, "varied_light": True}}


def _run(capture: Path, still: bool) -> dict[str, Any]:
    from backend.captures.prelabel import overall, prelabel_capture
    from worker.assist.prelabel import MediaPipeHands

    views = prelabel_capture(capture, MediaPipeHands(video=not still))
    return {"overall": overall(views), "views": [v.summary() for v in views]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=901, help="capture seed (no test uses it)")
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--still", action="store_true",
                        help="each frame on its own, not followed as a clip")
    parser.add_argument("--renders", default=",".join(RENDERS),
                        help=f"comma-separated, of {', '.join(RENDERS)}")
    args = parser.parse_args()
    renders = [r.strip() for r in args.renders.split(",") if r.strip()]
    unknown = sorted(set(renders) - set(RENDERS))
    if unknown or not renders:
        parser.error(f"unknown renders {unknown}; choose from {', '.join(RENDERS)}")
    sys.path.insert(0, str(ROOT))
    from worker.assist.prelabel import (
        MEDIAPIPE_REQUIREMENT,
        MediaPipeHands,
        PrelabelUnavailable,
        mediapipe_available,
    )

    result: dict[str, Any] = {"available": mediapipe_available(), "model": "mediapipe-hands-full",
                              "video": not args.still, "seed": args.seed,
                              "frames": args.frames, "views": args.views}
    reason = (f"mediapipe is not installed (pip install 'dexlabel[prelabel]', "
              f"{MEDIAPIPE_REQUIREMENT})")
    if result["available"]:
        try:
            MediaPipeHands()  # installed but not importable (a broken install) is unavailable
        except PrelabelUnavailable as exc:
            result["available"], reason = False, str(exc)
    if not result["available"]:
        result["reason"] = reason
        print(json.dumps(result))
        return
    from worker.synth import generate_capture

    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="dexlabel-bench-prelabel-") as work:
        result["renders"] = {}
        for name in renders:
            capture = Path(work) / name
            generate_capture(capture, seed=args.seed, frames=args.frames, views=args.views,
                             objects=1, **RENDERS[name])
            result["renders"][name] = _run(capture, args.still)
            o = result["renders"][name]["overall"]
            print(f"{name}: found {o['found']} of {o['visible']} visible, {o['found_clear']} of "
                  f"{o['clear']} clear, median {o['median_px']} px", flush=True)
    result["seconds"] = round(time.perf_counter() - started, 1)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
