"""Benchmark: quality-control decisions on simulated crowds, as confusion tables per scenario.

Each scenario imports a synthetic capture into a fresh embedded setup, has simulated workers
(worker.synth.annotators) submit to its tasks, and lets the product's own QC job
(backend.quality.flows.run_qc, the code a queue worker runs) score and decide them.
good = careful; bad = every other profile; "flagged" = review or reject.

Scenarios (``--scenario``, comma-separated; default all but the slow pool and timing):
    hands-8, hands-4     the mixed crowd, one worker per view (DexYCB labels every view once):
                         ``--draws`` crowds, each view's worker drawn from the mixed profile
                         weights (half careful), on the capture with 8 / 4 views
    objects-8, objects-4 the same for object landmarks (one worker per object task); the
                         sequence has a finished solve whose object poses are the capture's
                         ground truth, so each landmark track is also checked against the
                         solved object (worker.quality.anchored). A frozen ("lazy") track on an
                         object that never moves is right, and counted apart (lazy-still)
    pool                 every view gets one careful worker and one bad one per round
                         (``--rounds``), all scored together (several workers per view)
    timing               one QC job of one hand target, one careful worker per view, timed

Captures: ``--capture DIR`` (repeatable: any synthetic capture; each scenario takes the one
with its number of views); a view count none of them has is generated with
``--capture-seed`` into the run's folder (2-4 minutes each).

Per scenario: confusion {profile: {approve, review, reject, provisional}} (provisional also
counted in its outcome), bad_flagged_rate, good_flagged_rate, and for hands swaps_found /
swaps_total: swappers whose report names ring and little over a span inside the true window
(+-2 frames; the tail of the window where no two other views see both fingers cannot be
asserted), and swap_coverage, the mean share of the true window reported.

Prints one JSON line: {"captures", "crowd_seed", "draws", "scenarios": {name: summary}}.
Usage: python bench/qc.py [--capture DIR ...] [--capture-seed 7] [--crowd-seed 11]
                          [--scenario hands-8,hands-4,objects-8,objects-4] [--draws 10]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from _server import isolated_workdir

BAD_PROFILES = ("sloppy", "swapper", "lazy", "spammer", "occluder")
DEFAULT_SCENARIOS = "hands-8,hands-4,objects-8,objects-4"
ALL_SCENARIOS = ("hands-8", "hands-4", "objects-8", "objects-4", "pool", "timing")
# A reported swap span may start or end this many frames outside the true window.
SPAN_SLACK = 2


def _views_of(capture: Path) -> int:
    from backend.captures.layout import find_sequence_dirs, read_sequence

    return len(read_sequence(find_sequence_dirs(capture)[0]).cameras)


def _captures(given: list[Path], wanted: set[int], seed: int, work: Path) -> dict[int, Path]:
    """{views: capture folder} for every wanted view count: the given ones, else generated."""
    from worker.synth import generate_capture

    out = {}
    for path in given:
        out.setdefault(_views_of(path), path)
    for views in sorted(wanted - set(out)):
        out[views] = work / f"capture-s{seed}-v{views}"
        generate_capture(out[views], seed=seed, views=views, workers=1)
    return out


def _setup(capture: Path, kind: str = "hand") -> tuple[int, list[dict]]:
    """Import, create the tasks; (sequence id, tasks of ``kind`` as dicts, with "moving":
    whether the task's object is the grasped one)."""
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
                 for t in session.query(Task).filter_by(sequence_id=sequence_id)]
    return sequence_id, [t for t in tasks if t["kind"] == kind]


def _submit(task: dict, profile: str, worker: str, truth: Any, rng: np.random.Generator) -> int:
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


def _clear(sequence_id: int) -> None:
    """Remove every assignment of the sequence and its report (the next crowd starts afresh,
    as in a new project: thresholds are learned from its own reports)."""
    from sqlalchemy import delete, select

    from backend.annotation.models import Assignment, Task
    from backend.db import session_scope
    from backend.quality.models import QCReport

    with session_scope() as session:
        session.execute(delete(QCReport).where(QCReport.sequence_id == sequence_id))
        task_ids = select(Task.id).where(Task.sequence_id == sequence_id)
        for assignment in session.scalars(select(Assignment).where(
                Assignment.task_id.in_(task_ids))):
            session.delete(assignment)


def _run_qc(sequence_id: int, target_key: str) -> tuple[float, dict[str, float]]:
    """Seconds of one whole QC job of a target, and its own breakdown."""
    from backend.quality.flows import run_qc

    t0 = time.perf_counter()
    result = run_qc(sequence_id, target_key)
    return time.perf_counter() - t0, result["timings"]


def _store_true_solve(capture: Path, sequence_id: int) -> None:
    """A finished solve run of the sequence whose object poses are the capture's ground truth
    (the landmark check after the solve then judges the workers, not the solver)."""
    from backend.crowd.simulate import CaptureTruth
    from backend.db import session_scope
    from backend.solve.service import store_object_poses

    with session_scope() as session:
        store_object_poses(session, sequence_id, CaptureTruth(capture).object_poses())


def _swap_check(swaps: list[dict], frames: int) -> tuple[bool, float]:
    """(a ring/little swap reported inside the true window, share of the window covered)."""
    from worker.synth.annotators import swap_window

    first, last = swap_window(frames)
    found, covered = False, 0.0
    for swap in swaps:
        if sorted(swap.get("fingers", [])) != ["little", "ring"]:
            continue
        lo, hi = swap["frames"]
        overlap = min(hi, last) - max(lo, first) + 1
        if overlap > 0 and lo >= first - SPAN_SLACK and hi <= last + SPAN_SLACK:
            found = True
            covered = max(covered, overlap / (last - first + 1))
    return found, covered


class _Tally:
    """QC outcomes of simulated work by profile, and the swaps reported right."""

    def __init__(self, extra: tuple[str, ...] = ()) -> None:
        self.table = {p: {"approve": 0, "review": 0, "reject": 0, "provisional": 0}
                      for p in ("careful", *BAD_PROFILES, *extra)}
        self.swaps_found = self.swaps_total = 0
        self.coverage: list[float] = []
        # Why careful work was flagged and which bad work passed (a few of each, to look at).
        self.misses: list[str] = []

    def add(self, profile_of: dict[int, str], frames: int) -> None:
        from backend.db import session_scope
        from backend.quality.models import QCReport

        with session_scope() as session:
            for report in session.query(QCReport).filter(
                    QCReport.assignment_id.in_(profile_of)):
                profile = profile_of[report.assignment_id]
                self.table[profile][report.outcome] += 1
                self.table[profile]["provisional"] += int(report.provisional)
                good, passed = profile == "careful", report.outcome == "approve"
                if profile in ("careful", *BAD_PROFILES) and good != passed \
                        and len(self.misses) < 12:
                    self.misses.append(f"{profile} {report.target_key} {report.outcome}: "
                                       + "; ".join(report.reasons[:3]))
                if profile == "swapper" and report.target_key.startswith("hand"):
                    found, covered = _swap_check(report.swaps, frames)
                    self.swaps_total += 1
                    self.swaps_found += found
                    self.coverage.append(covered)

    def summary(self, hands: bool = True) -> dict:
        bad = [self.table[p] for p in BAD_PROFILES]
        out: dict[str, Any] = {"confusion": self.table,
                               "bad": sum(_decided(r) for r in bad),
                               "bad_flagged_rate": _flagged_rate(bad),
                               "good": _decided(self.table["careful"]),
                               "good_flagged_rate": _flagged_rate([self.table["careful"]]),
                               "misses": self.misses}
        if hands:
            out.update(swaps_found=self.swaps_found, swaps_total=self.swaps_total,
                       swap_coverage=round(statistics.mean(self.coverage), 3)
                       if self.coverage else None)
        return out


def _decided(row: dict[str, int]) -> int:
    return row["approve"] + row["review"] + row["reject"]


def _flagged_rate(rows: list[dict[str, int]]) -> float:
    """Share of the counted assignments sent to review or rejected."""
    total = sum(_decided(r) for r in rows)
    return round(sum(r["review"] + r["reject"] for r in rows) / max(total, 1), 4)


def _fresh_setup(name: str) -> None:
    """Point this process at a new empty embedded setup (settings, engine, storage)."""
    from backend.config import get_settings
    from backend.db import get_engine, get_sessionmaker
    from backend.storage import get_storage

    get_engine().dispose()
    isolated_workdir(name, DEXLABEL_QC_BLOCK_AFTER_FAILURES="0")
    for cached in (get_settings, get_engine, get_sessionmaker, get_storage):
        cached.cache_clear()


def mixed(capture: Path, kind: str, draws: int, crowd_seed: int) -> dict:
    """``draws`` crowds on one imported capture, one worker per task of ``kind`` drawn from the
    mixed profile weights, every target's QC job run; the summed confusion table."""
    from backend.crowd.simulate import CaptureTruth
    from worker.synth.annotators import draw_profiles

    _fresh_setup(f"qc-{kind}")
    sequence_id, tasks = _setup(capture, kind)
    if kind == "object":
        _store_true_solve(capture, sequence_id)
    truth = CaptureTruth(capture)
    tally = _Tally(extra=("lazy-still",) if kind == "object" else ())
    rng = np.random.default_rng(crowd_seed)
    seconds = []
    for draw in range(draws):
        _clear(sequence_id)
        profile_of = {}
        for task, profile in zip(tasks, draw_profiles(len(tasks), "mixed", rng), strict=True):
            key = _submit(task, profile, f"{profile}-d{draw}-{task['id']}", truth, rng)
            still = kind == "object" and profile == "lazy" and not task["moving"]
            profile_of[key] = "lazy-still" if still else profile
        seconds += [_run_qc(sequence_id, target)[0]
                    for target in sorted({t["target_key"] for t in tasks})]
        tally.add(profile_of, tasks[0]["num_frames"])
    return {"views": _views_of(capture), "draws": draws, **tally.summary(kind == "hand"),
            "qc_job_s_median": round(statistics.median(seconds), 3)}


def pool(capture: Path, rounds: int, crowd_seed: int) -> dict:
    """Each round, every view gets one careful worker and one of a bad profile (taken in
    turn); one QC job scores them all."""
    from backend.crowd.simulate import CaptureTruth

    _fresh_setup("qc-pool")
    sequence_id, tasks = _setup(capture)
    truth, rng = CaptureTruth(capture), np.random.default_rng(crowd_seed)
    profile_of: dict[int, str] = {}
    for r in range(rounds):
        for turn, task in enumerate(tasks):
            profile_of[_submit(task, "careful", f"careful-{r}-{task['id']}", truth, rng)] = \
                "careful"
            bad = BAD_PROFILES[(r * len(tasks) + turn) % len(BAD_PROFILES)]
            profile_of[_submit(task, bad, f"{bad}-{r}-{task['id']}", truth, rng)] = bad
    seconds, _ = _run_qc(sequence_id, "hand:0")
    tally = _Tally()
    tally.add(profile_of, tasks[0]["num_frames"])
    return {"views": len(tasks), "assignments": len(profile_of), **tally.summary(),
            "qc_job_s": round(seconds, 3)}


def timing(capture: Path, repeats: int, crowd_seed: int) -> dict:
    """One hand target, one careful worker per view: the QC job's seconds and its parts."""
    from backend.crowd.simulate import CaptureTruth

    _fresh_setup("qc-timing")
    sequence_id, tasks = _setup(capture)
    truth, rng = CaptureTruth(capture), np.random.default_rng(crowd_seed)
    for task in tasks:
        _submit(task, "careful", f"timed-{task['id']}", truth, rng)
    runs = [_run_qc(sequence_id, "hand:0") for _ in range(repeats)]
    return {"qc_job_s": round(statistics.median(s for s, _ in runs), 3),
            "qc_job_size": f"{len(tasks)} views x {tasks[0]['num_frames']} frames x 21 joints",
            "qc_job_parts_s": {name: round(statistics.median(t[name] for _, t in runs), 3)
                               for name in runs[0][1]}}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--capture", type=Path, action="append", default=[],
                        help="a synthetic capture (repeatable; one per view count)")
    parser.add_argument("--capture-seed", type=int, default=7,
                        help="seed of the captures generated for view counts not given")
    parser.add_argument("--crowd-seed", type=int, default=11)
    parser.add_argument("--scenario", default=DEFAULT_SCENARIOS,
                        help=f"comma-separated, of {', '.join(ALL_SCENARIOS)}")
    parser.add_argument("--draws", type=int, default=10, help="crowds per mixed scenario")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    scenarios = [s.strip() for s in args.scenario.split(",") if s.strip()]
    unknown = sorted(set(scenarios) - set(ALL_SCENARIOS))
    if unknown:
        parser.error(f"unknown scenario(s) {unknown}; known: {', '.join(ALL_SCENARIOS)}")

    work = isolated_workdir("qc", DEXLABEL_QC_BLOCK_AFTER_FAILURES="0")
    wanted = {int(s.split("-")[1]) for s in scenarios if "-" in s} | \
        ({8} if {"pool", "timing"} & set(scenarios) else set())
    captures = _captures(args.capture, wanted, args.capture_seed, work)
    out: dict[str, dict] = {}
    for name in scenarios:
        started = time.perf_counter()
        if name in ("pool", "timing"):
            run = pool(captures[8], args.rounds, args.crowd_seed) if name == "pool" \
                else timing(captures[8], args.repeats, args.crowd_seed)
        else:
            kind, views = name.split("-")
            run = mixed(captures[int(views)], kind.rstrip("s"), args.draws, args.crowd_seed)
        out[name] = {**run, "seconds": round(time.perf_counter() - started, 1)}
        print(f"{name}: {json.dumps(out[name])}", flush=True)
    print(json.dumps({"captures": {v: str(p) for v, p in sorted(captures.items())},
                      "crowd_seed": args.crowd_seed, "draws": args.draws, "scenarios": out}))


if __name__ == "__main__":
    main()
