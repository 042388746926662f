"""Benchmark: quality-control decisions on simulated crowds, as confusion tables per scenario.

Each scenario imports a synthetic capture into a fresh embedded setup, has simulated workers
(worker.synth.annotators) submit to its tasks, and lets the product's own QC job
(backend.quality.flows.run_qc, the code a queue worker runs) score and decide them.
good = careful; bad = every other profile; "flagged" = review or reject.

Scenarios (``--scenario``, comma-separated; default all but the slow pool and timing):
    hands-8, hands-4     the mixed crowd, one worker per view (DexYCB labels every view once):
                         ``--draws`` crowds, each view's worker drawn from the mixed profile
                         weights (half careful), on the capture with 8 / 4 views
    objects-8, objects-4 the same for object landmarks (one worker per object task, drawn
                         from the object mix: same_spot, both landmarks on one spot, too), each
                         landmark track also checked against the solved object
                         (worker.quality.anchored). ``--object-poses solved`` (the default):
                         each crowd goes the product's way (bench/_qc_pipeline.py): QC before
                         the solve, rejected tasks re-opened to another crowd worker, work left
                         for review decided by an admin who judges right, the solve (default
                         optimiser) of the accepted labels once every task has them, then the
                         landmark QC the solve queues; ~30-60 s a crowd at 8 views.
                         ``truth``: the solve is stood in for by the capture's true object
                         poses (the check judges the workers, not the solver). Both take the
                         same first workers. A frozen ("lazy") track on an object that never
                         moves is right, and counted apart (lazy-still), as is a bad profile's
                         label that marks hidden all through an object its view never shows
                         (unseen: a careful worker's label there is the same),
                         and a swapper's exchange of two landmarks its view hides (or
                         shows within 3 px of each other) all through the swap
                         (swap-unseen: it asserts nothing a careful label does not)
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
asserted), and swap_coverage, the mean share of the true window reported. Object scenarios after the
product's solve count each crowd's first workers (the labels the truth run judges) and add:
pipeline (rounds, re-opened tasks, admin decisions, crowds solved), reopened (the re-opened
tasks' workers' confusion), the solve's object ADD (mm, per object: median and maximum over
the crowds, frames the solve trusts), its flagged poses, and its seconds.

Prints one JSON line: {"captures", "crowd_seed", "draws", "object_draws", "object_poses",
"scenarios": {name: summary}} (an object scenario run with both poses is named
"objects-8 (truth)" and "objects-8 (solved)").
``--fault NAME`` (repeatable or a comma list; see worker/synth/faults.py) runs every scenario
on a copy of each capture with that rig fault injected (made once under the run's folder, the
truth unchanged; ``none`` is the capture as it is) and prints "faults": {fault: {scenario:
careful_flagged, bad_flagged}} with the full tables under "scenarios_by_fault".
Usage: python bench/qc.py [--capture DIR ...] [--capture-seed 7] [--crowd-seed 11]
                          [--scenario hands-8,hands-4,objects-8,objects-4] [--draws 10]
                          [--object-draws N] [--object-poses solved|truth|truth,solved]
                          [--fault none,extrinsics:0.5,5 ...] [--fault-seed 0]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from _faults import CLEAN, HELP, fault_names, faulty_capture
from _server import isolated_workdir

# same_spot (both landmarks on one spot) is drawn for object tasks only.
BAD_PROFILES = ("sloppy", "swapper", "lazy", "spammer", "occluder", "same_spot")
DEFAULT_SCENARIOS = "hands-8,hands-4,objects-8,objects-4"
ALL_SCENARIOS = ("hands-8", "hands-4", "objects-8", "objects-4", "pool", "timing")
OBJECT_POSES = ("truth", "solved")
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


def _setup(capture: Path) -> tuple[int, list[dict]]:
    """Import, create the tasks; (sequence id, every task as a dict, with "moving": whether
    the task's object is the grasped one)."""
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
                 for t in session.query(Task).filter_by(sequence_id=sequence_id)
                 .order_by(Task.id)]
    return sequence_id, tasks


def _of_kind(tasks: list[dict], kind: str) -> list[dict]:
    return [t for t in tasks if t["kind"] == kind]


# A swap of two landmarks whose true positions stay this close (px) changes no position by more
# than a careful click's noise.
SWAP_SAME_PX = 3.0


def _swap_unseen(xy: np.ndarray, visible: np.ndarray) -> bool:
    """Whether a swapper's exchange of the two landmarks (worker.synth.annotators) changes
    nothing its label asserts in this view: inside the swap window both are hidden, or both
    show within SWAP_SAME_PX of each other, in every frame. xy (F, 2, 2) px, visible (F, 2)
    the view's truth."""
    from worker.synth.annotators import swap_window

    lo, hi = swap_window(len(visible))
    vis, pos = visible[lo:hi + 1], xy[lo:hi + 1]
    both = vis.all(axis=1)
    close = np.linalg.norm(pos[:, 0] - pos[:, 1], axis=-1) <= SWAP_SAME_PX
    return bool(((~vis.any(axis=1)) | (both & close)).all())


def _submit(task: dict, profile: str, worker: str, truth: Any, rng: np.random.Generator,
            unseen: dict[int, str] | None = None) -> int:
    """One simulated worker's submitted assignment, written as the page's submit writes it.
    Its id joins ``unseen`` (if given) as "unseen" when the view never shows the task's points
    and the label marks them all hidden, and as "swap-unseen" when a swapper's exchange of an
    object's landmarks changes nothing the label asserts there (_swap_unseen): right work,
    whatever the profile."""
    from backend.annotation.models import Assignment, Track
    from backend.db import session_scope, utcnow
    from worker.synth.annotators import annotate
    from worker.tracks.interpolate import dense_points

    xy, visible = truth.points(task, rng)
    work = annotate(xy, visible, (task["width"], task["height"]), profile, rng)
    hidden = not visible.any() and not dense_points(
        enumerate(work.tracks), task["num_frames"], xy.shape[1])[1].any()
    with session_scope() as session:
        assignment = Assignment(task_id=task["id"], worker_id=worker,
                                external_id=f"bench-{worker}-{task['id']}", status="submitted",
                                version=1, working_time_s=150.0, submitted_at=utcnow())
        assignment.tracks = [Track(point_index=p, keyframes=rows)
                             for p, rows in enumerate(work.tracks)]
        session.add(assignment)
        session.flush()
        if unseen is not None and hidden:
            unseen[assignment.id] = "unseen"
        elif unseen is not None and profile == "swapper" and task["kind"] == "object" \
                and _swap_unseen(xy, visible):
            unseen[assignment.id] = "swap-unseen"
        return assignment.id


def _clear(sequence_id: int, kind: str | None = None) -> None:
    """Remove every assignment of the sequence (of ``kind``'s tasks, if given) and its report
    (the next crowd starts afresh, as in a new project: thresholds are learned from its own
    reports)."""
    from sqlalchemy import delete, select

    from backend.annotation.models import Assignment, Task
    from backend.db import session_scope
    from backend.quality.models import QCReport

    with session_scope() as session:
        task_ids = select(Task.id).where(Task.sequence_id == sequence_id)
        if kind is not None:
            task_ids = task_ids.where(Task.kind == kind)
        session.execute(delete(QCReport).where(QCReport.sequence_id == sequence_id,
                                               QCReport.task_id.in_(task_ids)))
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
    from backend.captures.truth import CaptureTruth
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

    def add(self, profile_of: dict[int, str], frames: int, tag: str = "") -> None:
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
                    self.misses.append(f"{tag}{profile} {report.target_key} {report.outcome}: "
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


def _label_profile(task: dict, profile: str, apart: str | None = None) -> str:
    """The profile a label is counted under: a frozen track on an object that never moves is
    right (lazy-still), and so is a bad profile's label marking hidden all through an object
    the view never shows (apart "unseen": a careful worker's label there is the same) and a
    swap of two landmarks the view hides through the swap (apart "swap-unseen")."""
    if task["kind"] == "object" and profile != "careful" and apart:
        return apart
    still = task["kind"] == "object" and profile == "lazy" and not task["moving"]
    return "lazy-still" if still else profile


def mixed(capture: Path, kind: str, draws: int, crowd_seed: int,
          object_poses: str = "truth") -> dict:
    """``draws`` crowds on one imported capture, one worker per task of ``kind`` drawn from the
    mixed profile weights, every target's QC job run; the summed confusion table. Object
    landmarks are judged against the capture's true object poses (``object_poses`` "truth")
    or after the product's own solve of each crowd's accepted work ("solved")."""
    from backend.captures.truth import CaptureTruth
    from worker.synth.annotators import draw_profiles

    _fresh_setup(f"qc-{kind}")
    sequence_id, every = _setup(capture)
    tasks = _of_kind(every, kind)
    if kind == "object" and object_poses == "truth":
        _store_true_solve(capture, sequence_id)
    truth = CaptureTruth(capture)
    tally = _Tally(extra=("lazy-still", "unseen", "swap-unseen") if kind == "object" else ())
    rng = np.random.default_rng(crowd_seed)
    solved = _SolvedCrowd(sequence_id, every, truth, crowd_seed) \
        if kind == "object" and object_poses == "solved" else None
    seconds = []
    path = _HandPath(sequence_id, tasks, truth, crowd_seed) if kind == "hand" else None
    for draw in range(draws):
        _clear(sequence_id, kind)
        profile_of = {}
        # Per crowd: the database may give a removed assignment's id to the next crowd's.
        unseen: dict[int, str] = {}
        for task, profile in zip(tasks, draw_profiles(len(tasks), "mixed", rng, kind),
                                 strict=True):
            key = _submit(task, profile, f"{profile}-d{draw}-{task['id']}", truth, rng, unseen)
            profile_of[key] = _label_profile(task, profile, unseen.get(key))
        if solved is not None:
            solved.run(draw, profile_of)
        else:
            seconds += [_run_qc(sequence_id, target)[0]
                        for target in sorted({t["target_key"] for t in tasks})]
        tally.add(profile_of, tasks[0]["num_frames"], f"d{draw} ")
        if path is not None:
            path.run(draw, profile_of)
    out = {"views": _views_of(capture), "draws": draws, **tally.summary(kind == "hand")}
    if kind == "object":
        out["object_poses"] = object_poses
    if solved is not None:
        return {**out, **solved.summary()}
    if path is not None:
        out["settled"] = path.summary()
    return {**out, "qc_job_s_median": round(statistics.median(seconds), 3)}


class _HandPath:
    """The hand scenarios carried on from the first QC pass (bench/_hand_path.py): reviews
    decided by an admin, rejected tasks re-opened to another worker of the same crowd."""

    def __init__(self, sequence_id: int, tasks: list[dict], truth: Any, crowd_seed: int) -> None:
        self.sequence_id, self.truth = sequence_id, truth
        self.tasks = {t["id"]: t for t in tasks}
        # Their own stream: each crowd's first workers stay those of the first pass.
        self.rng = np.random.default_rng([crowd_seed, 2])
        self.verdicts: list[tuple[str, str]] = []
        self.careful_flags: list[str] = []
        self.counts: dict[str, int] = {}
        self.draw = self.made = 0

    def _resubmit(self, task_id: int) -> tuple[int, str]:
        from worker.synth.annotators import draw_profiles

        profile = draw_profiles(1, "mixed", self.rng, "hand")[0]
        self.made += 1
        key = _submit(self.tasks[task_id], profile,
                      f"{profile}-d{self.draw}-r{self.made}-{task_id}", self.truth, self.rng)
        return key, profile

    def run(self, draw: int, first: dict[int, str]) -> None:
        import _hand_path

        self.draw = draw
        verdict, counts = _hand_path.settle(self.sequence_id, dict(first), self._resubmit,
                                            self.careful_flags)
        self.verdicts += [(first[key], v) for key, v in verdict.items()]
        for name, value in counts.items():
            self.counts[name] = self.counts.get(name, 0) + value

    def summary(self) -> dict:
        import _hand_path

        return {**_hand_path.rates(self.verdicts), **self.counts,
                "careful_flags": self.careful_flags}


class _SolvedCrowd:
    """The object scenarios after the product's own solve (bench/_qc_pipeline.py): the hand's
    careful labels submitted once, each crowd carried through QC, re-opened tasks, an admin's
    decisions, the solve and the landmark QC after it."""

    def __init__(self, sequence_id: int, tasks: list[dict], truth: Any, crowd_seed: int) -> None:
        self.sequence_id, self.truth = sequence_id, truth
        self.tasks = {t["id"]: t for t in tasks}
        # Re-opened tasks' workers and the hand's come from their own stream, so each crowd's
        # first workers are the same as with the true poses.
        self.rng = np.random.default_rng([crowd_seed, 1])
        self.hand: dict[int, str] = {}
        self.reopened = _Tally(extra=("lazy-still", "unseen", "swap-unseen"))
        self.counts: dict[str, int] = {}
        # {profile: {assignment status: count}} of the first workers once all is done: what
        # the product accepted (approved labels are the ones the solve used).
        self.status: dict[str, dict[str, int]] = {}
        self.solve_s: list[float] = []
        self.draw_s: list[float] = []
        self.unsolved: list[dict] = []
        self.add_mm: list[list[float]] = []
        self.flagged: list[int] = []
        self.true_poses = truth.object_poses()
        self.draw, self.made = 0, 0

    def _resubmit(self, task_id: int) -> tuple[int, str]:
        """Another worker on a task whose label was rejected: careful for the hand, drawn
        from the mixed crowd for an object."""
        from worker.synth.annotators import draw_profiles

        task = self.tasks[task_id]
        profile = "careful" if task["kind"] == "hand" else \
            draw_profiles(1, "mixed", self.rng, "object")[0]
        self.made += 1
        unseen: dict[int, str] = {}
        key = _submit(task, profile, f"{profile}-d{self.draw}-r{self.made}-{task_id}",
                      self.truth, self.rng, unseen)
        return key, _label_profile(task, profile, unseen.get(key))

    def run(self, draw: int, first: dict[int, str]) -> None:
        """One crowd (``first``: {assignment id: profile} of its object labels) from its
        submission to the landmark QC after the solve."""
        import _qc_pipeline as pipe

        started = time.perf_counter()
        self.draw = draw
        pipe.clear_solves(self.sequence_id)
        submitted = [t["id"] for t in self.tasks.values() if t["kind"] == "object"]
        if not self.hand:
            for task in self.tasks.values():
                if task["kind"] == "hand":
                    key = _submit(task, "careful", f"careful-hand-{task['id']}", self.truth,
                                  self.rng)
                    self.hand[key] = "careful"
                    submitted.append(task["id"])
        profile_of = {**self.hand, **first}
        counts, why = pipe.to_solve(self.sequence_id, submitted, profile_of, self._resubmit)
        for name, value in counts.items():
            self.counts[name] = self.counts.get(name, 0) + value
        for profile, status in pipe.statuses(first).items():
            row = self.status.setdefault(profile, {})
            for name, n in status.items():
                row[name] = row.get(name, 0) + n
        later = {k: v for k, v in profile_of.items() if k not in first and k not in self.hand}
        self.reopened.add(later, next(iter(self.tasks.values()))["num_frames"])
        if why is not None:
            self.unsolved.append({"draw": draw, "why": why})
        run = pipe.solved_run(self.sequence_id)
        if run is not None:
            self.solve_s.append(run[1])
            add, flagged = pipe.object_add_mm(self.sequence_id, self.true_poses)
            self.add_mm.append(add)
            self.flagged.append(flagged)
        self.draw_s.append(time.perf_counter() - started)

    def summary(self) -> dict:
        add = np.array(self.add_mm, float).reshape(len(self.add_mm), -1)
        return {"pipeline": self.counts, "unsolved": self.unsolved, "first_status": self.status,
                "reopened": {p: row for p, row in self.reopened.table.items() if any(row.values())},
                "solve_add_mm_median": np.round(np.median(add, axis=0), 2).tolist()
                if len(add) else None,
                "solve_add_mm_max": np.round(add.max(axis=0), 2).tolist() if len(add) else None,
                "solve_flagged_poses": self.flagged,
                "solve_s_median": round(statistics.median(self.solve_s), 1)
                if self.solve_s else None,
                "draw_s_median": round(statistics.median(self.draw_s), 1)}


def pool(capture: Path, rounds: int, crowd_seed: int) -> dict:
    """Each round, every view gets one careful worker and one of a bad profile (taken in
    turn); one QC job scores them all."""
    from backend.captures.truth import CaptureTruth

    _fresh_setup("qc-pool")
    sequence_id, every = _setup(capture)
    tasks = _of_kind(every, "hand")
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
    from backend.captures.truth import CaptureTruth

    _fresh_setup("qc-timing")
    sequence_id, every = _setup(capture)
    tasks = _of_kind(every, "hand")
    truth, rng = CaptureTruth(capture), np.random.default_rng(crowd_seed)
    for task in tasks:
        _submit(task, "careful", f"timed-{task['id']}", truth, rng)
    runs = [_run_qc(sequence_id, "hand:0") for _ in range(repeats)]
    return {"qc_job_s": round(statistics.median(s for s, _ in runs), 3),
            "qc_job_size": f"{len(tasks)} views x {tasks[0]['num_frames']} frames x 21 joints",
            "qc_job_parts_s": {name: round(statistics.median(t[name] for _, t in runs), 3)
                               for name in runs[0][1]}}


EPILOG = ("Default run here (2 shared cores): well over half an hour (every default scenario"
          " at 10 crowds; each object crowd goes through a solve, 1.5-3 minutes); captures made"
          " 2-4 minutes each. Short: --capture DIR (4 or 8 views) --scenario hands-4 --draws 1;"
          " --object-poses truth skips the solves.")


def main() -> None:
    parser = argparse.ArgumentParser(epilog=EPILOG)
    parser.add_argument("--capture", type=Path, action="append", default=[],
                        help="a synthetic capture (repeatable; one per view count)")
    parser.add_argument("--capture-seed", type=int, default=7,
                        help="seed of the captures generated for view counts not given")
    parser.add_argument("--crowd-seed", type=int, default=11)
    parser.add_argument("--scenario", default=DEFAULT_SCENARIOS,
                        help=f"comma-separated, of {', '.join(ALL_SCENARIOS)}")
    parser.add_argument("--draws", type=int, default=10, help="crowds per mixed scenario")
    parser.add_argument("--object-draws", type=int, default=None,
                        help="crowds per object scenario (default: --draws)")
    parser.add_argument("--object-poses", default="solved",
                        help="comma-separated, of truth, solved: the object poses the landmark "
                             "check after the solve is judged against")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--fault", action="append", help=HELP)
    parser.add_argument("--fault-seed", type=int, default=0, help="seed of the faults' choices")
    args = parser.parse_args()
    try:
        faults = fault_names(args.fault)
    except ValueError as exc:
        parser.error(str(exc))
    scenarios = [s.strip() for s in args.scenario.split(",") if s.strip()]
    unknown = sorted(set(scenarios) - set(ALL_SCENARIOS))
    if unknown:
        parser.error(f"unknown scenario(s) {unknown}; known: {', '.join(ALL_SCENARIOS)}")
    poses = [s.strip() for s in args.object_poses.split(",") if s.strip()]
    if not poses or set(poses) - set(OBJECT_POSES):
        parser.error(f"--object-poses must name some of {', '.join(OBJECT_POSES)}, got "
                     f"{args.object_poses!r}")
    object_draws = args.draws if args.object_draws is None else args.object_draws

    work = isolated_workdir("qc", DEXLABEL_QC_BLOCK_AFTER_FAILURES="0")
    wanted = {int(s.split("-")[1]) for s in scenarios if "-" in s} | \
        ({8} if {"pool", "timing"} & set(scenarios) else set())
    captures = _captures(args.capture, wanted, args.capture_seed, work)
    out: dict[str, dict] = {}
    runs = [(name, None) for name in scenarios if not name.startswith("objects")]
    runs += [(name, pose) for name in scenarios if name.startswith("objects") for pose in poses]
    by_fault: dict[str, dict] = {}
    for fault in faults:
        rig = {v: faulty_capture(p, fault, work, args.fault_seed) for v, p in captures.items()}
        out = by_fault.setdefault(fault, {})
        for name, pose in runs:
            started = time.perf_counter()
            label = name if pose is None or len(poses) == 1 else f"{name} ({pose})"
            if name in ("pool", "timing"):
                run = pool(rig[8], args.rounds, args.crowd_seed) if name == "pool" \
                    else timing(rig[8], args.repeats, args.crowd_seed)
            else:
                kind, views = name.split("-")
                run = mixed(rig[int(views)], kind.rstrip("s"),
                            object_draws if pose else args.draws, args.crowd_seed,
                            pose or "truth")
            out[label] = {**run, "seconds": round(time.perf_counter() - started, 1)}
            tag = label if fault == CLEAN else f"{fault} {label}"
            print(f"{tag}: {json.dumps(out[label])}", flush=True)
    summary = {"captures": {v: str(p) for v, p in sorted(captures.items())},
               "crowd_seed": args.crowd_seed, "draws": args.draws,
               "object_draws": object_draws, "object_poses": poses}
    if faults == [CLEAN]:
        summary["scenarios"] = by_fault[CLEAN]
    else:
        summary["faults"] = {fault: _fault_rates(runs) for fault, runs in by_fault.items()}
        summary["fault_seed"], summary["scenarios_by_fault"] = args.fault_seed, by_fault
    print(json.dumps(summary))


def _fault_rates(runs: dict[str, dict]) -> dict[str, dict]:
    """Per scenario the careful and bad work flagged under one fault (and the solve's object
    ADD, mm, where the scenario solved)."""
    out = {}
    for label, run in runs.items():
        if "good_flagged_rate" not in run:
            continue
        out[label] = {"careful_flagged": run["good_flagged_rate"],
                      "bad_flagged": run["bad_flagged_rate"]}
        if "settled" in run:
            out[label].update({f"{name}_settled": run["settled"][name]
                               for name in ("careful_flagged", "bad_flagged")})
        if run.get("solve_add_mm_median") is not None:
            out[label]["solve_add_mm_median"] = run["solve_add_mm_median"]
    return out


if __name__ == "__main__":
    main()
