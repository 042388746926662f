"""Benchmark: COCOeval of the COCO export of a simulated crowd's labels against the ground truth.

A synthetic capture (``dexlabel synth --seed N --views V --frames F``) is imported into a fresh
embedded setup and its hand tasks are worked by the simulated crowd: each round, one worker of
the mixed profile (backend.crowd.simulate's profiles and ground-truth points, submitted as the
annotation page stores them) per hand task still without accepted work, then the product's QC
job scores and decides them all; after the rounds the demo admin approves, for each task still
without accepted work, the assignment QC left for review with the smallest error
(picked as backend.demo.approve_reviewed picks it; decided as direct-link work, which has no
marketplace submission to pay). The accepted labels are exported as COCO (the product's export,
``labels=2d``), and the capture's ground truth (per camera ``labels_*.npz`` joint_2d, raw image
pixels, with the visibility the synthetic annotators see: backend.crowd.simulate's
hand_visibility) is written by the same COCO writer the same way (same images, no seg, so both
boxes come from the keypoints). COCOeval (iouType keypoints, the export's own
``info.oks_sigmas``, the hand category) then scores the export, each hand a detection of score 1,
against that ground truth.

Prints a JSON object on its last line: AP, AP50, AP75 (COCOeval stats 0-2), mean_px_error (per
image the mean distance over joints labelled in both, then the mean over images) with its
median and 95th percentile, the images with a hand in each, who accepted the work, the time
and the machine's load.

    python bench/coco_eval.py [--seed 101] [--views 4] [--frames 36] [--rounds 3]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _server import isolated_workdir


def _hand_tasks(sequence_id: int) -> list[dict[str, Any]]:
    from sqlalchemy import select

    from backend.annotation.models import Task
    from backend.db import session_scope

    with session_scope() as session:
        return [{"id": t.id, "serial": t.camera.serial, "kind": t.kind,
                 "num_frames": t.sequence.num_frames, "target_key": t.target_key,
                 "width": t.camera.width, "height": t.camera.height, "moving": False}
                for t in session.scalars(select(Task).where(Task.sequence_id == sequence_id,
                                                            Task.kind == "hand"))]


def _unaccepted(tasks: list[dict[str, Any]]) -> list[dict[str, Any]]:
    from sqlalchemy import select

    from backend.annotation.models import Assignment
    from backend.db import session_scope
    from backend.labels import ACCEPTED

    with session_scope() as session:
        done = set(session.scalars(select(Assignment.task_id).where(
            Assignment.status == ACCEPTED)))
    return [t for t in tasks if t["id"] not in done]


def _submit(task: dict[str, Any], profile: str, worker: str, truth: Any,
            rng: np.random.Generator) -> None:
    """One simulated worker's submission, stored as the annotation page's submit stores it."""
    from backend.annotation.models import Assignment, Track
    from backend.db import session_scope, utcnow
    from worker.synth.annotators import annotate

    xy, visible = truth.points(task, rng)
    work = annotate(xy, visible, (task["width"], task["height"]), profile, rng)
    with session_scope() as session:
        assignment = Assignment(task_id=task["id"], worker_id=worker,
                                external_id=f"bench-{worker}", status="submitted", version=1,
                                working_time_s=150.0, submitted_at=utcnow())
        assignment.tracks = [Track(point_index=p, keyframes=rows)
                             for p, rows in enumerate(work.tracks)]
        session.add(assignment)


def crowd(sequence_id: int, capture: Path, rounds: int, seed: int) -> dict[str, Any]:
    """Rounds of simulated workers and QC, then the admin's approvals; who accepted what."""
    from backend.captures.truth import CaptureTruth
    from backend.quality.flows import run_qc
    from worker.synth.annotators import draw_profiles

    truth = CaptureTruth(capture)
    rng = np.random.default_rng(seed)
    tasks = _hand_tasks(sequence_id)
    profiles: Counter[str] = Counter()
    for round_ in range(rounds):
        open_tasks = _unaccepted(tasks)
        if not open_tasks:
            break
        for i, (task, profile) in enumerate(zip(open_tasks, draw_profiles(
                len(open_tasks), "mixed", rng), strict=True)):
            profiles[profile] += 1
            _submit(task, profile, f"{profile}-r{round_}-{i}-{task['id']}", truth, rng)
        run_qc(sequence_id, "hand:0")
    by_qc = len(tasks) - len(_unaccepted(tasks))
    by_admin = _approve_reviewed(sequence_id)
    return {"hand_tasks": len(tasks), "submissions": dict(profiles), "accepted_by_qc": by_qc,
            "approved_by_admin": by_admin, "without_labels": len(_unaccepted(tasks)),
            "accepted_profiles": dict(Counter(w.split("-")[0] for w in _accepted_workers()))}


def _approve_reviewed(sequence_id: int) -> int:
    """The admin's approvals of direct-link work (no marketplace submission to pay): for each
    hand task still without accepted work, the assignment QC left for review (not
    provisional) with the smallest median error, as backend.demo.approve_reviewed picks it;
    the number approved."""
    from _qc_pipeline import _admin_decides
    from sqlalchemy import select

    from backend.annotation.models import Assignment
    from backend.db import session_scope
    from backend.quality.models import QCReport

    open_ids = {t["id"] for t in _unaccepted(_hand_tasks(sequence_id))}
    with session_scope() as session:
        rows = session.execute(
            select(QCReport.task_id, QCReport.assignment_id, QCReport.metrics)
            .join(Assignment, Assignment.id == QCReport.assignment_id)
            .where(QCReport.sequence_id == sequence_id, QCReport.outcome == "review",
                   QCReport.provisional.is_(False), Assignment.status == "submitted")).all()
    best: dict[int, tuple[float, int]] = {}
    for task_id, assignment_id, metrics in rows:
        error = (metrics or {}).get("median_error_px")
        key = (float("inf") if error is None else float(error), assignment_id)
        if task_id in open_ids and (task_id not in best or key < best[task_id]):
            best[task_id] = key
    for _error, assignment_id in best.values():
        _admin_decides(assignment_id, approve=True)
    return len(best)


def _accepted_workers() -> list[str]:
    from sqlalchemy import select

    from backend.annotation.models import Assignment
    from backend.db import session_scope
    from backend.labels import ACCEPTED

    with session_scope() as session:
        return list(session.scalars(select(Assignment.worker_id).where(
            Assignment.status == ACCEPTED)))


def ground_truth(export: dict[str, Any], capture: Path, out: Path) -> None:
    """The capture's joint_2d and visibility, written by the COCO writer for the export's
    images in the export's order (so image ids agree), without seg as the export has none."""
    from worker.formats import dexycb
    from worker.formats.coco import CocoWriter, HandKeypoints
    from worker.synth.annotators import hand_visibility

    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    views: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    with out.open("wb") as fh, CocoWriter(fh, label_source="annotated_2d") as writer:
        for image in export["images"]:
            serial = image["serial"]
            if serial not in views:
                labels = [np.load(seq_dir / serial / dexycb.labels_file(f))
                          for f in range(_frames(seq_dir))]
                joint_2d = np.stack([lab["joint_2d"][0] for lab in labels]).astype(np.float64)
                seg = np.stack([lab["seg"] for lab in labels])
                views[serial] = (joint_2d, hand_visibility(joint_2d, seg))
            joint_2d, visible = views[serial]
            f = image["frame"]
            xy = np.where((joint_2d[f] == dexycb.NO_LABEL).all(axis=1, keepdims=True), np.nan,
                          joint_2d[f])
            writer.add_image(image["file_name"], image["width"], image["height"],
                             hand=HandKeypoints(xy, visible[f]),
                             extra={"serial": serial, "frame": f})


def _frames(seq_dir: Path) -> int:
    import yaml

    from worker.formats import dexycb

    return int(yaml.safe_load((seq_dir / dexycb.META_FILE).read_text())["num_frames"])


def evaluate(export_path: Path, gt_path: Path) -> dict[str, Any]:
    """COCOeval of the export's hands (detections, score 1) against the ground truth."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    from worker.formats.coco import HAND_CATEGORY_ID

    exported, gt = COCO(str(export_path)), COCO(str(gt_path))
    sigmas = np.asarray(exported.dataset["info"]["oks_sigmas"])
    hands = [dict(a, score=1.0) for a in exported.loadAnns(exported.getAnnIds(
        catIds=[HAND_CATEGORY_ID])) if a["num_keypoints"] > 0]
    if not hands:
        raise SystemExit("no hand task has accepted work, so the export has no hand to score: "
                         "give the crowd more --rounds or --views")
    evaluation = COCOeval(gt, gt.loadRes(hands), iouType="keypoints")
    evaluation.params.kpt_oks_sigmas = sigmas
    evaluation.params.catIds = [HAND_CATEGORY_ID]
    evaluation.evaluate()
    evaluation.accumulate()
    evaluation.summarize()
    errors = []
    for hand in hands:
        truths = gt.loadAnns(gt.getAnnIds(imgIds=[hand["image_id"]]))
        if not truths:  # a hand labelled where the truth has none: no distance to measure
            continue
        a = np.asarray(hand["keypoints"], dtype=np.float64).reshape(-1, 3)
        b = np.asarray(truths[0]["keypoints"], dtype=np.float64).reshape(-1, 3)
        both = (a[:, 2] > 0) & (b[:, 2] > 0)
        if both.any():
            errors.append(float(np.linalg.norm(a[both, :2] - b[both, :2], axis=1).mean()))
    gt_hands = sum(a["num_keypoints"] > 0 for a in gt.loadAnns(gt.getAnnIds()))
    stats = [round(float(v), 4) for v in evaluation.stats[:3]]
    return {"AP": stats[0], "AP50": stats[1], "AP75": stats[2],
            "mean_px_error": round(float(np.mean(errors)), 3),
            "median_px_error": round(float(np.median(errors)), 3),
            "p95_px_error": round(float(np.percentile(errors, 95)), 3),
            "images": len(gt.dataset["images"]), "images_with_exported_hand": len(hands),
            "images_with_true_hand": int(gt_hands), "oks_sigmas": "export info.oks_sigmas"}


EPILOG = ("Default run here (2 shared cores): about 20 s (4 x 36) quiet, 1 minute at 8 views;"
          " more under load. Short: --views 4 --frames 6 --rounds 2 (at 2 views QC may accept"
          " nothing).")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=EPILOG)
    parser.add_argument("--seed", type=int, default=101)
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--frames", type=int, default=36)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    work = isolated_workdir("coco-eval")
    started = time.perf_counter()
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.config import get_settings
    from backend.db import session_scope
    from backend.exports.service import run_export
    from backend.migrate import upgrade
    from backend.storage import get_storage
    from worker.synth import generate_capture

    upgrade(get_settings().database_url)
    capture = work / "capture"
    generate_capture(capture, seed=args.seed, frames=args.frames, views=args.views)
    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        create_tasks(session, get_storage(), sequence_id)
    accepted = crowd(sequence_id, capture, args.rounds, args.seed)
    export_zip = work / "coco.zip"
    run_export("coco", [sequence_id], "accepted", {"labels": "2d"}, export_zip)
    import zipfile

    export_path, gt_path = work / "export.json", work / "truth.json"
    with zipfile.ZipFile(export_zip) as archive:
        export_path.write_bytes(archive.read("annotations.json"))
    ground_truth(json.loads(export_path.read_text()), capture, gt_path)
    figures = evaluate(export_path, gt_path)
    print(json.dumps({"seed": args.seed, "views": args.views, "frames": args.frames,
                      **figures, "crowd": accepted,
                      "seconds": round(time.perf_counter() - started, 1),
                      "load": [round(x, 2) for x in os.getloadavg()]}))


if __name__ == "__main__":
    main()
