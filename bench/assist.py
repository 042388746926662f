"""Benchmark: tracking proposals between a careful worker's keyframes, against ground truth.

On a synthetic capture (``--capture DIR``, or one generated with ``--capture-seed`` and
``--frames``; 24 frames is the same motion three times faster per frame), every view's hand
is labelled by the simulated careful worker (worker.synth.annotators: a keyframe every
``--every`` frames plus visibility changes, Gaussian noise of 2 px). The label error against
the true joints (px, at frames where the joint is visible) is measured for

    interpolation   the keyframes interpolated linearly (what is stored today);
    assisted        the LK proposals (worker.tracking.lk) accepted where they hold (ok),
                    added as keyframes, interpolation elsewhere.

Both over all frames and over the frames between keyframes ("between"), where they differ;
"proposed" is the share of those frames with a proposal that holds, and "on_proposed" the
two errors on just those frames. Timing: the proposals for 21 points over the clip (median
of ``--runs``), of the pure function on decoded frames and of the endpoint
(POST /api/annotate/proposals in process: token, keyframe checks, reading and decoding the
frames from storage, tracking, the answer).

Prints one JSON line: {"capture", "frames", "every", "views", "interpolation", "assisted",
"timing_ms"}.
Usage: python bench/assist.py [--capture DIR] [--capture-seed 7] [--frames 72] [--every 4]
                              [--runs 5] [--worker-seed 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from _server import isolated_workdir


def _errors(dense_xy: np.ndarray, truth: np.ndarray, visible: np.ndarray,
            mask: np.ndarray) -> np.ndarray:
    """Errors (px) at visible joints within ``mask`` (F, P); a missing position counts as
    missing (not as zero)."""
    keep = visible & mask & np.isfinite(truth).all(axis=2)
    return np.linalg.norm(dense_xy - truth, axis=2)[keep]


def _summary(err: np.ndarray) -> dict[str, float | int]:
    finite = err[np.isfinite(err)]
    if finite.size == 0:
        return {"n": 0}
    return {"n": int(finite.size), "mean_px": round(float(finite.mean()), 3),
            "median_px": round(float(np.median(finite)), 3),
            "p90_px": round(float(np.percentile(finite, 90)), 3),
            "max_px": round(float(finite.max()), 3)}


def _dense(tracks: list[list[list[Any]]], frames: int) -> np.ndarray:
    from worker.tracks import dense_track

    return np.stack([dense_track(rows, frames).xy for rows in tracks], axis=1)


def _accepted(tracks: list[list[list[Any]]], xy: np.ndarray, ok: np.ndarray
              ) -> list[list[list[Any]]]:
    """The worker's keyframes with every proposal that holds added as a visible keyframe."""
    out = []
    for p, rows in enumerate(tracks):
        keyed = {int(r[0]): r for r in rows}
        for f in np.flatnonzero(ok[:, p]):
            keyed.setdefault(int(f), [int(f), float(xy[f, p, 0]), float(xy[f, p, 1]), 1])
        out.append([keyed[f] for f in sorted(keyed)])
    return out


def _grey(view_dir: Path, frames: int) -> np.ndarray:
    from worker.formats import dexycb

    return np.stack([cv2.imread(str(view_dir / dexycb.color_file(f)), cv2.IMREAD_GRAYSCALE)
                     for f in range(frames)])


def _accuracy(capture: Path, frames: int, every: int, seed: int) -> dict[str, Any]:
    from backend.crowd.simulate import CaptureTruth
    from worker.formats import dexycb
    from worker.synth.annotators import annotate, hand_visibility
    from worker.tracking.lk import propose

    truth_of = CaptureTruth(capture)
    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    serials = sorted(p.name for p in seq_dir.iterdir() if p.is_dir())
    rng = np.random.default_rng(seed)
    parts: dict[str, list[np.ndarray]] = {k: [] for k in (
        "interp_all", "interp_between", "assist_all", "assist_between", "interp_on", "lk_on")}
    between_total = proposed = 0
    for serial in serials:
        joint_2d, seg = truth_of.view(serial, frames)
        truth = np.where((joint_2d == dexycb.NO_LABEL).all(axis=2, keepdims=True), np.nan,
                         joint_2d)
        visible = hand_visibility(joint_2d, seg)
        grey = _grey(seq_dir / serial, frames)
        size = (grey.shape[2], grey.shape[1])
        work = annotate(truth, visible, size, "careful", rng, key_step=every)
        found = propose(grey, work.tracks)
        keyed = np.zeros(visible.shape, bool)
        for p, rows in enumerate(work.tracks):
            keyed[[int(r[0]) for r in rows], p] = True
        interp = _dense(work.tracks, frames)
        assisted = _dense(_accepted(work.tracks, found.xy, found.ok), frames)
        everywhere = np.ones(visible.shape, bool)
        parts["interp_all"].append(_errors(interp, truth, visible, everywhere))
        parts["interp_between"].append(_errors(interp, truth, visible, ~keyed))
        parts["assist_all"].append(_errors(assisted, truth, visible, everywhere))
        parts["assist_between"].append(_errors(assisted, truth, visible, ~keyed))
        parts["interp_on"].append(_errors(interp, truth, visible, found.ok))
        parts["lk_on"].append(_errors(found.xy, truth, visible, found.ok))
        between_total += int((visible & ~keyed).sum())
        proposed += int((visible & found.ok).sum())
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    return {
        "views": len(serials),
        "interpolation": {"all": _summary(cat["interp_all"]),
                          "between": _summary(cat["interp_between"])},
        "assisted": {"all": _summary(cat["assist_all"]),
                     "between": _summary(cat["assist_between"]),
                     "proposed": round(proposed / max(between_total, 1), 3),
                     "on_proposed": {"interpolation": _summary(cat["interp_on"]),
                                     "lk": _summary(cat["lk_on"])}},
    }


def _median_ms(fn: Any, runs: int) -> float:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1000)
    return round(statistics.median(times), 1)


def _timing(capture: Path, frames: int, every: int, runs: int) -> dict[str, Any]:
    """Median ms of 21-point proposals over the clip: pure function and endpoint."""
    from fastapi.testclient import TestClient

    from backend.accounts.service import create_admin
    from backend.annotation.models import Task
    from backend.annotation.service import create_assignment, create_tasks
    from backend.annotation.tokens import assignment_token
    from backend.app import create_app
    from backend.captures.flows import import_path
    from backend.config import get_settings
    from backend.crowd.simulate import CaptureTruth
    from backend.db import session_scope
    from backend.migrate import upgrade
    from backend.storage import get_storage
    from worker.formats import dexycb
    from worker.synth.annotators import annotate, hand_visibility
    from worker.tracking.lk import propose

    upgrade(get_settings().database_url)
    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        create_admin(session, "bench@example.org", "bench password 1234")
        task = next(t for t in create_tasks(session, get_storage(), sequence_id)
                    if t.kind == "hand")
        task = session.get_one(Task, task.id)
        token = assignment_token(task, create_assignment(session, task, "bench"))
        serial = task.camera.serial
    joint_2d, seg = CaptureTruth(capture).view(serial, frames)
    grey = _grey(next(capture.glob(dexycb.META_GLOB)).parent / serial, frames)
    work = annotate(joint_2d, hand_visibility(joint_2d, seg), (grey.shape[2], grey.shape[1]),
                    "careful", np.random.default_rng(0), key_step=every)
    body = {"tracks": [{"point": p, "keyframes": rows} for p, rows in enumerate(work.tracks)]}
    client = TestClient(create_app())
    headers = {"Authorization": f"Bearer {token}"}

    def endpoint() -> None:
        resp = client.post("/api/annotate/proposals", json=body, headers=headers)
        if resp.status_code != 200:
            raise RuntimeError(f"proposals failed: {resp.status_code} {resp.text}")

    endpoint()  # warm: imports, the first connection
    return {"points": 21, "frames": frames, "size": [grey.shape[2], grey.shape[1]],
            "runs": runs, "pure": _median_ms(lambda: propose(grey, work.tracks), runs),
            "endpoint": _median_ms(endpoint, runs)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--capture", type=Path, help="a synthetic capture (default: generate)")
    parser.add_argument("--capture-seed", type=int, default=7)
    parser.add_argument("--frames", type=int, default=72,
                        help="frames of a generated capture (24: the same motion, faster)")
    parser.add_argument("--views", type=int, default=2, help="views of a generated capture")
    parser.add_argument("--every", type=int, default=4, help="the worker keys every K frames")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--worker-seed", type=int, default=3)
    args = parser.parse_args()
    work = isolated_workdir("assist")
    capture = args.capture
    if capture is None:
        from worker.synth import generate_capture

        capture = work / f"capture-s{args.capture_seed}-f{args.frames}"
        generate_capture(capture, seed=args.capture_seed, frames=args.frames,
                         views=args.views, workers=1)
    capture = capture.resolve()
    frames = _frames(capture)
    result = {"capture": str(capture), "frames": frames, "every": args.every,
              **_accuracy(capture, frames, args.every, args.worker_seed),
              "timing_ms": _timing(capture, frames, args.every, args.runs)}
    print(json.dumps(result))


def _frames(capture: Path) -> int:
    import yaml

    from worker.formats import dexycb

    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    return int(yaml.safe_load((seq_dir / dexycb.META_FILE).read_text())["num_frames"])


if __name__ == "__main__":
    main()
