"""Benchmark: quality-control decisions on a simulated crowd, as a confusion table.

A default synthetic capture (8 views x 72 frames) is imported into a fresh embedded setup and
its hand tasks get submissions from simulated workers (worker.synth.annotators): in each of
``--rounds`` rounds every view gets one careful worker and one worker of a bad profile
(sloppy, swapper, lazy, spammer, occluder, taken in turn). The product's own QC job
(backend.quality.flows.run_qc, the code a queue worker runs) scores and decides them all.
good = careful; bad = every other profile; "flagged" = review or reject.

Then the job size the issue names is timed alone: one hand target with one assignment per
view (8 views x 72 frames x 21 joints).

Prints the table, then a JSON summary on its last line:
    confusion                   {profile: {approve, review, reject}}
    bad_flagged_rate            share of bad assignments sent to review or rejected (target >= 0.95)
    good_flagged_rate           share of careful ones sent to review or rejected (target <= 0.03)
    swaps_found / swaps_total   swappers whose report names ring and little over about the true span
    qc_job_s                    seconds of one QC job, 8 views x 72 frames x 21 joints (median)
    qc_job_parts_s              its parts: reading tracks and depth maps, scoring, acting
    objects                     the confusion table and rates of object-landmark QC (two careful
                                workers and one of each bad profile per object task)
    mixed                       the same measures over --mixed-seeds fresh projects where each
                                view is labelled by one worker drawn from the mixed profile
                                (half careful): the harder case, fewer good views to agree
Usage: python bench/qc.py [--capture DIR] [--rounds 3] [--repeats 3] [--mixed-seeds 10]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from _server import isolated_workdir

BAD_PROFILES = ("sloppy", "swapper", "lazy", "spammer", "occluder")


def _capture(path: Path | None, work: Path) -> Path:
    from worker.synth import generate_capture

    if path is not None and any(path.glob("*/*/meta.yml")):
        return path
    out = path or work / "capture"
    generate_capture(out, seed=7)
    return out


def _setup(capture: Path, kind: str = "hand") -> tuple[int, list[dict]]:
    """Import (unless imported), create the tasks; (sequence id, tasks of ``kind`` as dicts,
    with "moving": whether the task's object is the grasped one)."""
    from backend.annotation.models import Task
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.captures.models import SceneObject
    from backend.config import get_settings
    from backend.db import session_scope
    from backend.migrate import upgrade
    from backend.storage import get_storage

    upgrade(get_settings().database_url)
    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        create_tasks(session, get_storage(), sequence_id)
        tasks = [{"id": t.id, "serial": t.camera.serial, "kind": t.kind,
                  "num_frames": t.sequence.num_frames, "target_key": t.target_key,
                  "width": t.camera.width, "height": t.camera.height,
                  "moving": t.object_id is not None
                  and session.get_one(SceneObject, t.object_id).grasped}
                 for t in session.query(Task).filter_by(sequence_id=sequence_id, kind=kind)]
    return sequence_id, tasks


def _submit(task: dict, profile: str, worker: str, truth, rng: np.random.Generator) -> int:
    """One simulated worker's submitted assignment, written as the page's submit writes it."""
    from backend.annotation.models import Assignment, Track
    from backend.db import session_scope, utcnow
    from worker.synth.annotators import annotate

    xy, visible = truth.points(task, rng)
    work = annotate(xy, visible, (task["width"], task["height"]), profile, rng)
    with session_scope() as session:
        assignment = Assignment(task_id=task["id"], worker_id=worker,
                                external_id=f"bench-{worker}-{task['id']}", status="submitted",
                                version=1, working_time_s=150.0, submitted_at=utcnow())
        assignment.tracks = [Track(point_index=p, keyframes=rows)
                             for p, rows in enumerate(work.tracks)]
        session.add(assignment)
        session.flush()
        return assignment.id


def _run_qc(sequence_id: int, target_key: str = "hand:0") -> tuple[float, dict[str, float]]:
    """Seconds of one whole QC job of a target, and its own breakdown."""
    from backend.quality.flows import run_qc

    t0 = time.perf_counter()
    result = run_qc(sequence_id, target_key)
    return time.perf_counter() - t0, result["timings"]


def _objects(capture: Path, truth, rng: np.random.Generator) -> dict:
    """Object landmarks in the same project: every object task gets two careful workers and one
    of each bad profile; each object target's QC job decides. A frozen ("lazy") track is wrong
    only on the object that moves (the grasped one): on a still object it is counted apart."""
    sequence_id, tasks = _setup(capture, kind="object")
    profile_of: dict[int, str] = {}
    for task in tasks:
        for i, profile in enumerate(("careful", "careful", *BAD_PROFILES)):
            key = _submit(task, profile, f"{profile}-o{i}-{task['id']}", truth, rng)
            profile_of[key] = profile if profile != "lazy" or task["moving"] else "lazy-still"
    for target in sorted({t["target_key"] for t in tasks}):
        _run_qc(sequence_id, target)
    tally = _Tally(extra=("lazy-still",))
    tally.add(sequence_id, profile_of, tasks[0]["num_frames"])
    summary = tally.summary()
    del summary["swaps_found"], summary["swaps_total"]
    return summary


def _swap_found(swaps: list[dict], frames: int) -> bool:
    from worker.synth.annotators import swap_window

    first, last = swap_window(frames)
    for swap in swaps:
        if sorted(swap.get("fingers", [])) != ["little", "ring"]:
            continue
        lo, hi = swap["frames"]
        # The reported span must overlap the true one by most of its length.
        overlap = min(hi, last) - max(lo, first) + 1
        if overlap >= 0.7 * (last - first + 1):
            return True
    return False


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--capture", type=Path, default=None,
                        help="reuse (or write) the synthetic capture here")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--mixed-seeds", type=int, default=10,
                        help="projects of the mixed-crowd scenario (one worker per view)")
    args = parser.parse_args()

    work = isolated_workdir("qc", DEXLABEL_QC_BLOCK_AFTER_FAILURES="0")
    capture = _capture(args.capture, work)

    from backend.crowd.simulate import CaptureTruth

    sequence_id, tasks = _setup(capture)
    truth = CaptureTruth(capture)
    rng = np.random.default_rng(args.seed)
    profile_of: dict[int, str] = {}
    turn = 0
    for r in range(args.rounds):
        for task in tasks:
            good = _submit(task, "careful", f"careful-{r}-{task['id']}", truth, rng)
            profile_of[good] = "careful"
            bad_profile = BAD_PROFILES[turn % len(BAD_PROFILES)]
            turn += 1
            bad = _submit(task, bad_profile, f"{bad_profile}-{r}-{task['id']}", truth, rng)
            profile_of[bad] = bad_profile
    pool_s, _ = _run_qc(sequence_id)

    frames = tasks[0]["num_frames"]
    tally = _Tally()
    tally.add(sequence_id, profile_of, frames)
    confusion = tally.table

    print(f"{'profile':10s} {'approve':>8s} {'review':>8s} {'reject':>8s}")
    for profile, row in confusion.items():
        print(f"{profile:10s} {row['approve']:8d} {row['review']:8d} {row['reject']:8d}")

    objects = _objects(capture, truth, rng)
    mixed = _mixed_crowds(capture, truth, args.mixed_seeds, args.seed)

    # The job size of the issue: one hand target, one assignment per view, in a fresh setup.
    _fresh_setup()
    sequence_id, tasks = _setup(capture)
    for task in tasks:
        _submit(task, "careful", f"timed-{task['id']}", truth, rng)
    runs = [_run_qc(sequence_id) for _ in range(args.repeats)]
    job_s = [seconds for seconds, _ in runs]
    parts = {name: round(statistics.median(t[name] for _, t in runs), 3)
             for name in runs[0][1]}

    summary = {
        **tally.summary(),
        "assignments": len(profile_of),
        "pool_qc_job_s": round(pool_s, 3),
        "pool_views": len(tasks),
        "qc_job_s": round(statistics.median(job_s), 3),
        "qc_job_size": f"{len(tasks)} views x {frames} frames x 21 joints",
        "qc_job_parts_s": parts,
        "mixed": mixed,
        "objects": objects,
    }
    print(json.dumps(summary))


def _mixed_crowds(capture: Path, truth, seeds: int, base_seed: int) -> dict:
    """Each of ``seeds`` fresh projects: every view labelled by one worker drawn from the mixed
    profile weights (half careful), scored alone by the QC job; the summed confusion table."""
    from worker.synth.annotators import draw_profiles

    tally = _Tally()
    for seed in range(seeds):
        _fresh_setup()
        sequence_id, tasks = _setup(capture)
        rng = np.random.default_rng(base_seed + 1000 + seed)
        profile_of = {}
        for task, profile in zip(tasks, draw_profiles(len(tasks), "mixed", rng), strict=True):
            profile_of[_submit(task, profile, f"{profile}-m{seed}-{task['id']}", truth, rng)] = \
                profile
        _run_qc(sequence_id)
        tally.add(sequence_id, profile_of, tasks[0]["num_frames"])
    return {"projects": seeds, **tally.summary()}


class _Tally:
    """QC outcomes of simulated work by profile, and the swaps reported right."""

    def __init__(self, extra: tuple[str, ...] = ()) -> None:
        self.table = {p: {"approve": 0, "review": 0, "reject": 0}
                      for p in ("careful", *BAD_PROFILES, *extra)}
        self.swaps_found = self.swaps_total = 0

    def add(self, sequence_id: int, profile_of: dict[int, str], frames: int) -> None:
        from backend.db import session_scope
        from backend.quality.models import QCReport

        with session_scope() as session:
            for report in session.query(QCReport).filter(
                    QCReport.assignment_id.in_(profile_of)):
                profile = profile_of[report.assignment_id]
                self.table[profile][report.outcome] += 1
                if profile == "swapper":
                    self.swaps_total += 1
                    self.swaps_found += _swap_found(report.swaps, frames)

    def summary(self) -> dict:
        bad = [self.table[p] for p in BAD_PROFILES]
        good = self.table["careful"]
        return {"confusion": self.table,
                "bad_flagged_rate": _flagged_rate(bad),
                "good_flagged_rate": _flagged_rate([good]),
                "swaps_found": self.swaps_found, "swaps_total": self.swaps_total}


def _flagged_rate(rows: list[dict[str, int]]) -> float:
    """Share of the counted assignments sent to review or rejected."""
    total = sum(sum(r.values()) for r in rows)
    return round(sum(r["review"] + r["reject"] for r in rows) / max(total, 1), 4)


def _fresh_setup() -> None:
    """Point this process at a new empty embedded setup (settings, engine, storage)."""
    from backend.config import get_settings
    from backend.db import get_engine, get_sessionmaker
    from backend.storage import get_storage

    isolated_workdir("qc-one", DEXLABEL_QC_BLOCK_AFTER_FAILURES="0")
    get_engine().dispose()
    for cached in (get_settings, get_engine, get_sessionmaker, get_storage):
        cached.cache_clear()


if __name__ == "__main__":
    main()
