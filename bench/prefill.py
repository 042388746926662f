"""Benchmark: pre-fill suggestions (GET /api/annotate/suggestions) against ground truth, timed.

On a synthetic capture (``--capture DIR``, or one generated with ``--capture-seed``: 8 views
x 72 frames at 640x480, a few minutes), every view's hand gets one accepted assignment from
the simulated careful worker (worker.synth.annotators: a keyframe every ``--every`` frames
plus visibility changes, 2 px noise). Then, for each view in turn, the endpoint answers an
assignment of that view from the other views' work, and its answer is compared with the
view's true joints:

    error           px from the suggested position to the true joint, where a position is
                    suggested and the joint is visible (the assignment's check cells, shown
                    15 px off on purpose, left out);
    suggested       share of the truly visible joints with a suggested position;
    visibility      share of all (frame, joint) cells whose suggested visibility equals the
                    truth (unknown counts as wrong), and share of the truly occluded caught.

Timing (median of ``--runs``): the endpoint in process for one view's 21 joints over the
clip with every other view's accepted work: "first", a view's first request (token, queries,
densifying the tracks, the triangulation, reading and decoding the view's depth maps, the
answer), and "again", a request whose result the server kept (a reload, another worker of the
task); and the pure worker.assist.prefill.prefill on arrays with the depth maps already
decoded. The machine's 1-minute load average is printed beside them.

By accepted views ("by_accepted_views", bench/_suggest_eval.py): with one careful crowd
worker's image-checked labels per view (bench/_crowd_labels.py) as the accepted work, each
target view (the first ``--targets``; default all) is suggested from 1, 2 and 3+ (all) other
views: from 1-2 by the hand model fitted to their labels and depth (worker.solver.suggest),
from 3 or more by triangulation, as the endpoint does. Per count: median and 90th percentile
px error of the suggested visible joints against the truth, the share of truly occluded
joints proposed occluded, and the median seconds one view's suggestions took.

Prints one JSON line: {"capture", "frames", "views", "every", "error", "suggested",
"visibility", "timing_ms", "by_accepted_views"}.
Usage: python bench/prefill.py [--capture DIR] [--capture-seed 7] [--views 8] [--frames 72]
                               [--every 4] [--runs 5] [--worker-seed 3] [--targets N]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from _suggest_eval import by_accepted_views

from _server import isolated_workdir, median_ms


def _summary(err: np.ndarray) -> dict[str, float | int]:
    return {"n": int(err.size), "median_px": round(float(np.median(err)), 3),
            "p90_px": round(float(np.percentile(err, 90)), 3),
            "max_px": round(float(err.max()), 3)}


def _setup(capture: Path, every: int, seed: int) -> dict[str, Any]:
    """Import, create the tasks, accept one careful worker's tracks of every hand task; the
    hand tasks (id, serial, size) in view order and their truth."""
    from backend.accounts.service import create_admin
    from backend.annotation.models import Assignment, Track
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.captures.truth import CaptureTruth
    from backend.config import get_settings
    from backend.db import session_scope
    from backend.labels import ACCEPTED
    from backend.migrate import upgrade
    from backend.storage import get_storage
    from worker.synth.annotators import annotate, hand_visibility

    upgrade(get_settings().database_url)
    sequence_id = import_path(capture)[0].sequence_id
    truth_of, rng = CaptureTruth(capture), np.random.default_rng(seed)
    tasks = []
    with session_scope() as session:
        create_admin(session, "bench@example.org", "bench password 1234")
        for task in create_tasks(session, get_storage(), sequence_id):
            if task.kind != "hand":
                continue
            frames, size = task.sequence.num_frames, (task.camera.width, task.camera.height)
            joint_2d, seg = truth_of.view(task.camera.serial, frames)
            visible = hand_visibility(joint_2d, seg)
            work = annotate(joint_2d, visible, size, "careful", rng, key_step=every)
            assignment = Assignment(task_id=task.id, worker_id=f"careful-{task.id}",
                                    external_id=f"bench-{task.id}", status=ACCEPTED, version=1)
            assignment.tracks = [Track(point_index=p, keyframes=rows)
                                 for p, rows in enumerate(work.tracks)]
            session.add(assignment)
            tasks.append({"id": task.id, "serial": task.camera.serial, "frames": frames,
                          "truth": joint_2d, "visible": visible})
    return {"sequence_id": sequence_id, "tasks": tasks}


def _link(task_id: int, worker: str) -> tuple[int, str]:
    """A direct assignment of the task: its id and token."""
    from backend.annotation.models import Task
    from backend.annotation.service import create_assignment
    from backend.annotation.tokens import assignment_token
    from backend.db import session_scope

    with session_scope() as session:
        task = session.get_one(Task, task_id)
        assignment = create_assignment(session, task, worker)
        return assignment.id, assignment_token(task, assignment)


def _compare(answer: dict, task: dict, cells: list[tuple[int, int]]) -> dict[str, np.ndarray]:
    xy = np.swapaxes(np.array([[[np.nan, np.nan] if v is None else v for v in p["xy"]]
                               for p in answer["points"]], dtype=float), 0, 1)
    suggested = np.array([[-1 if v is None else int(v) for v in p["visible"]]
                          for p in answer["points"]]).T
    truth, visible = task["truth"], task["visible"]
    plain = np.ones(visible.shape, bool)
    for point, frame in cells:
        plain[frame, point] = False
    has = np.isfinite(xy).all(axis=-1)
    return {"errors": np.linalg.norm(xy - truth, axis=-1)[has & visible & plain],
            "suggested": has[visible], "agree": (suggested == visible).ravel(),
            "caught": (suggested == 0)[~visible]}


def _accuracy(client: Any, tasks: list[dict]) -> dict[str, Any]:
    from backend.config import get_settings
    from worker.assist.checks import check_cells, check_key

    key = check_key(get_settings().signing_key)
    parts: dict[str, list[np.ndarray]] = {"errors": [], "suggested": [], "agree": [],
                                          "caught": []}
    for task in tasks:
        assignment_id, token = _link(task["id"], f"target-{task['id']}")
        resp = client.get("/api/annotate/suggestions",
                          headers={"Authorization": f"Bearer {token}"})
        if resp.status_code != 200 or not resp.json()["available"]:
            raise RuntimeError(f"suggestions failed: {resp.status_code} {resp.text[:300]}")
        cells = check_cells(key, assignment_id, 21, task["frames"])
        for name, values in _compare(resp.json(), task, cells).items():
            parts[name].append(values)
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    return {"error": _summary(cat["errors"]),
            "suggested": round(float(cat["suggested"].mean()), 4),
            "visibility": {"agree": round(float(cat["agree"].mean()), 4),
                           "occluded_caught": round(float(cat["caught"].mean()), 4)
                           if cat["caught"].size else None,
                           "occluded": int(cat["caught"].size)}}


def _pure_ms(capture: Path, sequence_id: int, runs: int) -> float:
    """The pure function for view 0 from the other views' stored work, depth decoded."""
    from backend.captures.service import camera_model, sequence_cameras
    from backend.db import session_scope
    from backend.labels import labelled_work, sequence_tasks
    from worker.assist.prefill import prefill, view_work
    from worker.formats import dexycb

    with session_scope() as session:
        rows = sequence_cameras(session, sequence_id)
        cameras = [camera_model(c) for c in rows]
        view_of = {c.id: i for i, c in enumerate(rows)}
        tasks = {t.id: t for t in sequence_tasks(session, sequence_id, "hand:0")}
        work = [view_work(view_of[tasks[a.task_id].camera_id],
                          ((t.point_index, t.keyframes) for t in a.tracks),
                          tasks[a.task_id].sequence.num_frames, 21)
                for a in labelled_work(session, tasks)]
        work = [w for w in work if w.view != 0]
        serial, frames = rows[0].serial, work[0].xy.shape[0]
    view_dir = next(capture.glob(dexycb.META_GLOB)).parent / serial
    depth = np.stack([cv2.imread(str(view_dir / dexycb.depth_file(f)), cv2.IMREAD_UNCHANGED)
                      for f in range(frames)])
    return median_ms(lambda: prefill(cameras, work, 0, depth), runs)


def _timing(client: Any, task: dict, runs: int) -> dict[str, float]:
    """Median ms of the endpoint: "first", the view's first request (nothing kept), and
    "again", a request after it (the result kept: another worker's, a reload)."""
    from backend.labels.suggestions import clear_cache

    _, token = _link(task["id"], "timed")
    headers = {"Authorization": f"Bearer {token}"}

    def endpoint() -> None:
        resp = client.get("/api/annotate/suggestions", headers=headers)
        if resp.status_code != 200:
            raise RuntimeError(f"suggestions failed: {resp.status_code} {resp.text[:300]}")

    endpoint()  # warm: imports, the first connection

    def first() -> None:
        clear_cache()
        endpoint()

    return {"first": median_ms(first, runs), "again": median_ms(endpoint, runs)}


EPILOG = ("Default run here (2 shared cores): 3-5 minutes (an 8 x 72 capture made: 2.3-2.9"
          " minutes). Short: --capture DIR (reuse one; 4 views at least), --views 4 --frames 12"
          " --runs 1.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=EPILOG)
    parser.add_argument("--capture", type=Path, help="a synthetic capture (default: generate)")
    parser.add_argument("--capture-seed", type=int, default=7)
    parser.add_argument("--views", type=int, default=8,
                        help="views of a generated capture (4 at least: 3 others suggest)")
    parser.add_argument("--frames", type=int, default=72, help="frames of a generated capture")
    parser.add_argument("--every", type=int, default=4, help="the worker keys every K frames")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--worker-seed", type=int, default=3)
    parser.add_argument("--targets", type=int, default=None,
                        help="target views of the by-accepted-views figures (default all; 0: none)")
    args = parser.parse_args()
    work = isolated_workdir("prefill")
    capture = args.capture
    if capture is None:
        from worker.synth import generate_capture

        capture = work / f"capture-s{args.capture_seed}"
        generate_capture(capture, seed=args.capture_seed, frames=args.frames, views=args.views,
                         workers=1)
    capture = capture.resolve()
    from fastapi.testclient import TestClient

    from backend.app import create_app

    setup = _setup(capture, args.every, args.worker_seed)
    tasks = setup["tasks"]
    client = TestClient(create_app())
    result = {"capture": str(capture), "frames": tasks[0]["frames"], "views": len(tasks),
              "every": args.every, **_accuracy(client, tasks),
              "timing_ms": {"points": 21, "other_views": len(tasks) - 1, "runs": args.runs,
                            "endpoint": _timing(client, tasks[0], args.runs),
                            "load_average": round(os.getloadavg()[0], 1),
                            "pure": _pure_ms(capture, setup["sequence_id"], args.runs)}}
    if args.targets != 0:
        result["by_accepted_views"] = by_accepted_views(capture, work, args.worker_seed,
                                                        args.targets)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
