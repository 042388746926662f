"""Benchmark: a DexYCB-sized database, and the admin listings and heavy reads against it.

DexYCB is 1,000 sequences x 8 views (582K frames); one accepted label set for every view of
the hand and 4 objects is 40,000 tasks and about 17 million labelled keypoint observations.
This fills a new PostgreSQL database (made by the project's migrations) with that much work as
the product stores it: subjects, sequences, cameras, objects, hands, frame rows (storage keys
only, no image files), a task per view x target, HITs, assignments with tracks (keyframes
every few frames, rows [frame, x, y, visible]), verified submissions, payments, QC reports,
worker blocks, jobs and a solve run per finished sequence. Rows go in with COPY, in batches of
sequences, one transaction per batch; ids are given here so children can name their parents.

About 90% of the sequences are finished (every task accepted, solved from the accepted labels
as they are now); the rest are in progress: tasks accepted, in review, waiting for QC, being
worked on, or not published yet. Some work is rejected and its HIT re-opened with one more
assignment, as the QC job does.

Then each admin listing and heavy read is timed as the product runs it: the endpoints through
the app (FastAPI's TestClient, an admin's bearer token) and the service functions the QC and
solve jobs call, on a finished sequence in the middle of the set.

Prints a JSON summary on its last line:
    sequences, views, tasks, assignments, tracks, frames   what was filled
    observations              keypoint observations (points x frames) of accepted work;
                              observations_stored: of every assignment's tracks
    fill_s                    seconds to fill (migrations apart), VACUUM and ANALYZE
    migrate_s                 seconds of the migrations on the new database
    db_bytes, db_size         pg_database_size after the fill
    tables                    rows and total bytes (with indexes and TOAST) of the big tables
    queries                   per query: median ms over --repeat runs (after one warm-up),
                              min_ms (the fastest run), sql_ms (median time spent executing
                              SQL), cpu_ms (median CPU time of this process: the app's own
                              work), db_cpu_ms (median CPU time of the database server's
                              processes, when it runs on this machine), SQL statements per
                              run, rows (or items) returned
Usage: python bench/scale_db.py [--sequences 1000] [--url URL] [--keep] [--repeat 5]
       [--no-queries] [--time-only]
The database (default dexlabel_scale on the local server) is dropped and made again; it is
dropped at the end unless --keep. --time-only migrates a kept database to the newest schema
and times the queries again without filling.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

DEFAULT_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/dexlabel_scale"
# DexYCB's eight RealSense D415 serials.
SERIALS = ("836212060125", "839512060362", "840412060917", "841412060263",
           "932122060857", "932122060861", "932122061900", "932122062010")
YCB = ("002_master_chef_can", "003_cracker_box", "004_sugar_box", "005_tomato_soup_can",
       "006_mustard_bottle", "007_tuna_fish_can", "008_pudding_box", "009_gelatin_box",
       "010_potted_meat_can", "011_banana", "019_pitcher_base", "021_bleach_cleanser",
       "024_bowl", "025_mug", "035_power_drill", "036_wood_block", "037_scissors",
       "040_large_marker", "051_large_clamp", "052_extra_large_clamp", "061_foam_brick")
SUBJECTS = 10
OBJECTS = 4
HAND_POINTS = 21
OBJECT_POINTS = 2
WORKERS = 600
FINISHED_SHARE = 0.9
REJECT_P = 0.12
BATCH_SEQUENCES = 20
START = datetime(2026, 3, 2, 8, 0, tzinfo=UTC)
BIG_TABLES = ("frames", "tasks", "assignments", "tracks", "crowd_hits", "crowd_submissions",
              "crowd_payments", "qc_reports", "jobs", "solve_runs")

COLUMNS: dict[str, tuple[str, ...]] = {
    "subjects": ("id", "name", "created_at"),
    "sequences": ("id", "subject_id", "name", "storage_uid", "num_frames", "fps",
                  "master_serial", "source_kind", "fingerprint", "created_at"),
    "cameras": ("id", "sequence_id", "serial", "view_index", "width", "height", "fx", "fy",
                "ppx", "ppy", "distortion", "extrinsics", "has_depth"),
    "scene_objects": ("id", "sequence_id", "index", "ycb_id", "name", "mesh_key",
                      "num_vertices", "num_faces", "grasped", "initial_pose"),
    "hands": ("id", "sequence_id", "index", "side", "calib_name", "betas"),
    "frames": ("id", "camera_id", "index", "color_key", "color_bytes", "depth_key", "thumb_key",
               "stats"),
    "tasks": ("id", "sequence_id", "camera_id", "kind", "target_key", "hand_id", "object_id",
              "num_points", "highlight", "created_at"),
    "crowd_hits": ("id", "task_id", "round", "request_token", "hit_id", "max_assignments",
                   "reward_cents", "expired_at", "created_at"),
    "assignments": ("id", "task_id", "worker_id", "external_id", "hit_id", "status", "version",
                    "edit_count", "working_time_s", "saved_at", "submitted_at", "created_at"),
    "tracks": ("id", "assignment_id", "point_index", "keyframes"),
    "crowd_submissions": ("id", "assignment_id", "hit_id", "worker_id", "market_status",
                          "created_at"),
    "crowd_payments": ("id", "kind", "assignment_id", "worker_id", "request_token",
                       "amount_cents", "fee_cents", "feedback", "created_at", "state"),
    "qc_reports": ("id", "assignment_id", "task_id", "sequence_id", "target_key", "worker_id",
                   "method", "metrics", "per_joint", "per_frame", "swaps", "thresholds",
                   "outcome", "reasons", "feedback", "provisional", "views", "action",
                   "action_detail", "updated_at", "created_at"),
    "solve_runs": ("id", "sequence_id", "optimiser", "params", "status", "timings", "summary",
                   "error", "result_key", "labels_digest", "num_frames", "num_views",
                   "started_at", "finished_at", "created_at"),
    "jobs": ("id", "kind", "key", "args", "status", "attempts", "max_attempts", "error",
             "result", "lease_until", "updated_at", "started_at", "finished_at", "created_at",
             "requests", "requests_claimed"),
    "crowd_worker_actions": ("id", "worker_id", "kind", "target", "value", "reason",
                             "created_at"),
}
# Parents before children (foreign keys are checked row by row).
TABLE_ORDER = tuple(COLUMNS)

THRESHOLDS = {
    "median_error_px.review_above": 3.5, "median_error_px.reject_above": 12.0,
    "p90_error_px.review_above": 7.0, "p90_error_px.reject_above": 30.0,
    "outlier_fraction.review_above": 0.05, "outlier_fraction.reject_above": 0.5,
    "jitter_px.review_above": 3.0, "motion_ratio.review_below": 0.6,
    "motion_ratio.reject_below": 0.2, "occluded_on_surface.review_above": 0.1,
    "occluded_on_surface.reject_above": 0.3, "completeness.review_below": 0.95,
    "completeness.reject_below": 0.5, "working_time_s.review_below": 30.0,
    "jump_fraction.review_above": 0.02, "moved_with_object.review_below": 0.35,
    "moved_with_object.reject_below": 0.12, "motion_ratio.review_above": 3.0,
}
REJECT_FEEDBACK = ("Your ring tip and little tip labels were swapped in frames {a}-{b}; please "
                   "check which finger is which before moving on.")


def _dumps(value: Any) -> str:
    return json.dumps(value, separators=(",", ":"))


def psycopg_url(url: str) -> str:
    """A libpq URL from a SQLAlchemy one (postgresql+psycopg://... -> postgresql://...)."""
    scheme, rest = url.split("://", 1)
    return f"{scheme.split('+', 1)[0]}://{rest}"


def _database_name(url: str) -> tuple[str, str]:
    """(the server's maintenance database URL, the database name) of a libpq URL."""
    base, _, tail = psycopg_url(url).rpartition("/")
    name = tail.split("?", 1)[0]
    if not name:
        raise SystemExit(f"error: {url} names no database")
    return f"{base}/postgres", name


def create_database(url: str) -> None:
    """Drop the URL's database if it exists and create it empty."""
    import psycopg

    admin, name = _database_name(url)
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
        conn.execute(f'CREATE DATABASE "{name}"')


def drop_database(url: str) -> None:
    import psycopg

    admin, name = _database_name(url)
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


# --- what one sequence holds ---------------------------------------------------------------


@dataclass
class _Ids:
    """The next id of each table (the database is empty when the fill starts)."""

    next: dict[str, int] = field(default_factory=lambda: dict.fromkeys(COLUMNS, 1))

    def take(self, table: str) -> int:
        value = self.next[table]
        self.next[table] = value + 1
        return value


@dataclass
class FillStats:
    sequences: int = 0
    finished: int = 0
    views: int = 0
    tasks: int = 0
    assignments: int = 0
    tracks: int = 0
    frames: int = 0
    hits: int = 0
    qc_reports: int = 0
    jobs: int = 0
    observations: int = 0
    observations_stored: int = 0
    rows: dict[str, int] = field(default_factory=lambda: dict.fromkeys(COLUMNS, 0))


class _Filler:
    """Makes the rows of sequences one at a time into per-table lists."""

    def __init__(self, seed: int, total: int) -> None:
        self.rng = random.Random(seed)
        self.ids = _Ids()
        self.total = total
        self.rows: dict[str, list[tuple[Any, ...]]] = {t: [] for t in COLUMNS}
        self.stats = FillStats()
        self.workers = [self._worker_id(i) for i in range(WORKERS)]
        # Each worker's chance of a rejection: most are careful, a few are not.
        self.worker_reject = [min(0.6, self.rng.lognormvariate(-2.4, 0.9))
                              for _ in self.workers]
        self.worker_weight = [1.0 / (1 + i) ** 0.6 for i in range(WORKERS)]
        self.rejections: dict[str, int] = {}
        self.serial = 0
        self.subject_names: list[str] = []

    # names -------------------------------------------------------------------------------

    def _worker_id(self, i: int) -> str:
        return "A" + format((i * 0x9E3779B97F4A7C15 + 0x1234567) % 36**13, "X").rjust(13, "0")

    def _market_id(self, kind: int) -> str:
        """A 30-character marketplace id (HIT or assignment), unique by construction."""
        self.serial += 1
        mixed = (self.serial * 0x9E3779B97F4A7C15F39CC0605CEDC835 + kind) % (1 << 120)
        return format(mixed, "030X")

    def _at(self, base: datetime, max_hours: float) -> datetime:
        return base + timedelta(hours=self.rng.uniform(0.05, max_hours))

    # the capture --------------------------------------------------------------------------

    def subjects(self) -> None:
        for i in range(SUBJECTS):
            name = f"2020{7 + i // 5:02d}{9 + i:02d}-subject-{i + 1:02d}"
            self.subject_names.append(name)
            self.rows["subjects"].append((self.ids.take("subjects"), name, START))

    def sequence(self, index: int) -> None:
        rng = self.rng
        seq_id = self.ids.take("sequences")
        subject_id = 1 + index % SUBJECTS
        subject = self.subject_names[subject_id - 1]
        name = f"{subject[:8]}_{index // SUBJECTS:06d}"
        # The storage prefix an import gives a sequence: a hash of its name, then its own part.
        uid = (hashlib.sha256(f"{subject}/{name}".encode()).hexdigest()[:24]
               + f"-{index:012x}")
        num_frames = rng.randint(64, 81)
        created = START + timedelta(days=90 * index / max(self.total, 1))
        self.rows["sequences"].append(
            (seq_id, subject_id, name, uid, num_frames, 30.0, SERIALS[0], "images",
             hashlib.sha256(uid.encode()).hexdigest(), created))
        cameras = []
        for view, serial in enumerate(SERIALS):
            cam_id = self.ids.take("cameras")
            cameras.append(cam_id)
            extrinsics = [[round(rng.uniform(-1, 1), 6) for _ in range(4)] for _ in range(3)]
            self.rows["cameras"].append(
                (cam_id, seq_id, serial, view, 640, 480, 615.0 + view, 615.5 + view, 320.5,
                 240.2, "[0.0,0.0,0.0,0.0,0.0]", _dumps(extrinsics), True))
            base = f"captures/{uid}/{serial}"
            for f in range(num_frames):
                stats = {"brightness": round(rng.uniform(60, 140), 2),
                         "sharpness": round(rng.uniform(20, 400), 1),
                         "depth_coverage": round(rng.uniform(0.6, 0.99), 3)}
                self.rows["frames"].append(
                    (self.ids.take("frames"), cam_id, f, f"{base}/color_{f:06d}.jpg",
                     rng.randint(38_000, 64_000), f"{base}/aligned_depth_to_color_{f:06d}.png",
                     f"{base}/thumb_{f:06d}.jpg", _dumps(stats)))
        objects = []
        ycb = rng.sample(range(len(YCB)), OBJECTS)
        for k, y in enumerate(ycb):
            obj_id = self.ids.take("scene_objects")
            objects.append(obj_id)
            pose = [[1.0, 0.0, 0.0, round(rng.uniform(-0.2, 0.2), 4)],
                    [0.0, 1.0, 0.0, round(rng.uniform(-0.2, 0.2), 4)],
                    [0.0, 0.0, 1.0, round(rng.uniform(0.6, 0.9), 4)]]
            mesh_key = f"captures/{uid}/models/{YCB[y]}/textured_simple.obj"
            self.rows["scene_objects"].append(
                (obj_id, seq_id, k, y + 1, YCB[y], mesh_key, rng.randint(2_000, 40_000),
                 rng.randint(4_000, 80_000), k == 0, _dumps(pose)))
        hand_id = self.ids.take("hands")
        side = "right" if rng.random() < 0.8 else "left"
        self.rows["hands"].append(
            (hand_id, seq_id, 0, side, f"mano_20200709_140042_{subject}_{side}",
             _dumps([round(rng.gauss(0, 0.8), 4) for _ in range(10)])))
        self.stats.sequences += 1
        self.stats.views += len(cameras)
        self.stats.frames += len(cameras) * num_frames
        finished = rng.random() < FINISHED_SHARE
        self._work(seq_id, uid, num_frames, cameras, hand_id, objects, created, finished)

    # the work -----------------------------------------------------------------------------

    def _work(self, seq_id: int, uid: str, num_frames: int, cameras: list[int], hand_id: int,
              objects: list[int], created: datetime, finished: bool) -> None:
        rng = self.rng
        approved: list[int] = []
        job_time = created + timedelta(hours=1)
        self._job("frame_stats", f"frame_stats:{seq_id}", {"sequence_id": seq_id}, "done",
                  job_time, {"message": f"frame statistics of {len(cameras) * num_frames} "
                             "frames"})
        targets = [("hand", "hand:0", hand_id, None, HAND_POINTS)] + [
            ("object", f"object:{k}", None, obj, OBJECT_POINTS) for k, obj in enumerate(objects)]
        for cam_id in cameras:
            for kind, key, h_id, o_id, points in targets:
                task_id = self.ids.take("tasks")
                highlight = None
                if kind == "object":
                    cx, cy = rng.uniform(150, 490), rng.uniform(120, 360)
                    highlight = {"polygon": [[round(cx + 40 * dx, 1), round(cy + 30 * dy, 1)]
                                             for dx, dy in ((-1, -1), (1, -1), (1.2, 0), (1, 1),
                                                            (-1, 1), (-1.2, 0))]}
                self.rows["tasks"].append(
                    (task_id, seq_id, cam_id, kind, key, h_id, o_id, points,
                     None if highlight is None else _dumps(highlight), created))
                self.stats.tasks += 1
                if finished:
                    state = "approved"
                else:
                    state = rng.choices(("approved", "review", "submitted", "working", "open"),
                                        (50, 15, 10, 10, 15))[0]
                approved += self._task_work(seq_id, uid, task_id, key, num_frames, points,
                                            created, state)
        for _kind, key, *_ in targets:
            status = "done" if finished or rng.random() < 0.7 else rng.choice(
                ("queued", "running", "retrying", "failed"))
            error = ("Traceback (most recent call last):\n  ...\nValueError: labels '12': xy "
                     "must have shape (F, P, 2)") if status in ("failed", "retrying") else None
            self._job("qc", f"qc:{seq_id}:{key}", {"sequence_id": seq_id, "target_key": key},
                      status, job_time + timedelta(hours=30),
                      {"message": f"qc: {key} scored 8: 7 approve, 0 review, 1 reject; "
                       "acted: 7 approved, 1 rejected"} if status == "done" else None, error)
        if finished:
            self._solve(seq_id, uid, num_frames, len(cameras), sorted(approved),
                        job_time + timedelta(hours=40))
            self.stats.finished += 1

    def _task_work(self, seq_id: int, uid: str, task_id: int, key: str, num_frames: int,
                   points: int, created: datetime, state: str) -> list[int]:
        """The HIT(s), assignments, tracks, submissions, payments and QC reports of a task;
        the ids of its approved assignments."""
        rng = self.rng
        if state == "open":
            return []
        hit_at = self._at(created, 24)
        reward = 50 if key.startswith("hand") else 20
        hit_round = 1
        if rng.random() < 0.02:  # a first round that expired with nobody taking it
            self._hit(task_id, 1, None, 1, reward, hit_at, expired=hit_at + timedelta(days=3))
            hit_round, hit_at = 2, hit_at + timedelta(days=3, hours=1)
        hit_id = self._market_id(1)
        # Rejected attempts before the outcome; each re-opens the HIT with one more slot.
        outcomes: list[str] = []
        while len(outcomes) < 3 and rng.random() < REJECT_P:
            outcomes.append("rejected")
        outcomes.append(state)
        self._hit(task_id, hit_round, hit_id, len(outcomes), reward, hit_at, expired=None)
        at = hit_at
        approved = []
        for status in outcomes:
            at = self._at(at, 30)
            assignment_id = self._assignment(seq_id, uid, task_id, key, hit_id, num_frames,
                                             points, at, status, reward)
            if status == "approved":
                approved.append(assignment_id)
        return approved

    def _hit(self, task_id: int, hit_round: int, hit_id: str | None, slots: int, reward: int,
             at: datetime, expired: datetime | None) -> None:
        token = hashlib.sha256(f"hit:{task_id}:{hit_round}".encode()).hexdigest()[:64]
        self.rows["crowd_hits"].append(
            (self.ids.take("crowd_hits"), task_id, hit_round, token,
             hit_id or self._market_id(1), slots, reward, expired, at))
        self.stats.hits += 1

    def _pick_worker(self, status: str) -> str:
        rng = self.rng
        i = 0
        for _ in range(8):
            i = rng.choices(range(WORKERS), self.worker_weight)[0]
            if (status == "rejected") == (rng.random() < self.worker_reject[i]):
                break
        return self.workers[i]

    def _assignment(self, seq_id: int, uid: str, task_id: int, key: str, hit_id: str,
                    num_frames: int, points: int, at: datetime, status: str,
                    reward: int) -> int:
        rng = self.rng
        a_id = self.ids.take("assignments")
        worker = self._pick_worker(status)
        working = round(rng.uniform(60, 240) if points == OBJECT_POINTS
                        else rng.uniform(400, 1800), 1)
        stored = "submitted" if status in ("review", "submitted") else status
        saved = at + timedelta(seconds=working)
        self.rows["assignments"].append(
            (a_id, task_id, worker, self._market_id(2), hit_id, stored, rng.randint(3, 60),
             rng.randint(points * 4, points * 30), working, saved,
             None if stored == "working" else saved, at))
        self.stats.assignments += 1
        self._tracks(a_id, num_frames, points)
        self.stats.observations_stored += num_frames * points
        if stored == "approved":
            self.stats.observations += num_frames * points
        if stored == "working":
            return a_id
        submitted = saved
        decided = submitted + timedelta(minutes=rng.uniform(5, 600))
        self.rows["crowd_submissions"].append(
            (self.ids.take("crowd_submissions"), a_id, hit_id, worker, "Submitted", submitted))
        self._job("confirm", f"confirm:{a_id}", {"assignment_id": a_id}, "done", submitted,
                  {"state": "accepted", "message": f"assignment {a_id}: accepted"})
        if status == "submitted":  # waiting for its quality check
            return a_id
        self._report(a_id, task_id, seq_id, key, worker, num_frames, points, status, decided)
        if stored == "approved":
            fee = max(1, round(reward * 0.2))
            self._payment("approval", a_id, worker, f"approval-{a_id}", reward, fee, None,
                          decided)
            if rng.random() < 0.03:
                self._payment("bonus", a_id, worker, f"bonus-{a_id}-careful", 25, 5,
                              "careful work on occluded joints", decided,
                              "pending" if rng.random() < 0.1 else "done")
        elif stored == "rejected":
            self._payment("rejection", a_id, worker, f"rejection-{a_id}", 0, 0,
                          REJECT_FEEDBACK.format(a=10, b=30), decided)
            self.rejections[worker] = self.rejections.get(worker, 0) + 1
        return a_id

    def _tracks(self, assignment_id: int, num_frames: int, points: int) -> None:
        rng = self.rng
        step = rng.randint(3, 6)
        frames = list(range(0, num_frames, step))
        if frames[-1] != num_frames - 1:
            frames.append(num_frames - 1)
        for p in range(points):
            x, y = rng.uniform(120, 520), rng.uniform(90, 390)
            rows: list[list[Any]] = []
            for f in frames:
                x = min(639.0, max(0.0, x + rng.gauss(0, 4)))
                y = min(479.0, max(0.0, y + rng.gauss(0, 4)))
                if rng.random() < 0.12:
                    rows.append([f, None, None, 0] if rng.random() < 0.5
                                else [f, round(x, 1), round(y, 1), 0])
                else:
                    rows.append([f, round(x, 1), round(y, 1), 1])
            self.rows["tracks"].append((self.ids.take("tracks"), assignment_id, p, _dumps(rows)))
            self.stats.tracks += 1

    def _report(self, a_id: int, task_id: int, seq_id: int, key: str, worker: str,
                num_frames: int, points: int, status: str, at: datetime) -> None:
        rng = self.rng
        bad = status == "rejected"
        median = rng.uniform(6, 25) if bad else rng.uniform(0.8, 3.0)
        metrics = {
            "median_error_px": round(median, 3), "mean_error_px": round(median * 1.3, 3),
            "p90_error_px": round(median * 2.4, 3),
            "outlier_fraction": round(rng.uniform(0.1, 0.6) if bad else rng.uniform(0, 0.04), 4),
            "visibility_disagreement": round(rng.uniform(0, 0.2), 4),
            "occluded_on_surface": round(rng.uniform(0, 0.08), 4),
            "visible_behind_surface": round(rng.uniform(0, 0.08), 4),
            "jitter_px": round(rng.uniform(0.2, 2.5), 3),
            "motion_ratio": round(rng.uniform(0.7, 1.4), 3),
            "completeness": round(rng.uniform(0.97, 1.0), 4),
            "visible_fraction": round(rng.uniform(0.6, 0.95), 4),
            "working_time_s": round(rng.uniform(60, 1800), 1),
            "scored_fraction": round(rng.uniform(0.8, 1.0), 4)}
        per_joint = [round(median * rng.uniform(0.5, 1.6), 3) for _ in range(points)]
        per_frame = [round(median * rng.uniform(0.5, 1.6), 3) for _ in range(num_frames)]
        swaps = ([{"points": [16, 20], "names": ["ring tip", "little tip"], "frames": [10, 30],
                   "gain_px": 7.5}] if bad and key.startswith("hand") else [])
        if status == "approved":
            outcome, reasons, feedback = "approve", [], ""
            action, detail = "approved", "approved automatically"
            if rng.random() < 0.05:
                outcome, reasons, detail = "review", ["median_error_px"], "decided by an admin"
        elif status == "rejected":
            outcome, reasons = "reject", ["median_error_px", "swap"]
            feedback = REJECT_FEEDBACK.format(a=10, b=30)
            action, detail = "rejected", "re-opened with one more assignment"
        else:  # in review
            outcome, reasons, feedback = "review", ["p90_error_px"], ""
            action, detail = "review", "left for an admin's review"
        self.rows["qc_reports"].append(
            (self.ids.take("qc_reports"), a_id, task_id, seq_id, key, worker, "consensus",
             _dumps(metrics), _dumps(per_joint), _dumps(per_frame), _dumps(swaps),
             _dumps(THRESHOLDS), outcome, _dumps(reasons), feedback, False, 8, action, detail,
             at, at))
        self.stats.qc_reports += 1

    def _payment(self, kind: str, a_id: int, worker: str, token: str, amount: int, fee: int,
                 feedback: str | None, at: datetime, state: str = "done") -> None:
        self.rows["crowd_payments"].append(
            (self.ids.take("crowd_payments"), kind, a_id, worker, token, amount, fee, feedback,
             at, state))

    def _job(self, kind: str, key: str, args: dict[str, Any], status: str, at: datetime,
             result: dict[str, Any] | None, error: str | None = None) -> None:
        finished = at + timedelta(seconds=self.rng.uniform(0.2, 90)) \
            if status in ("done", "failed") else None
        started = None if status == "queued" else at
        lease = at + timedelta(minutes=15) if status == "running" else None
        attempts = 0 if status == "queued" else (5 if status == "failed" else 1)
        self.rows["jobs"].append(
            (self.ids.take("jobs"), kind, key, _dumps(args), status, attempts, 5, error,
             None if result is None else _dumps(result), lease, finished or at, started,
             finished, at, 1, 0 if status == "queued" else 1))
        self.stats.jobs += 1

    def _solve(self, seq_id: int, uid: str, num_frames: int, views: int, approved: list[int],
               at: datetime) -> None:
        """A done solve run from the sequence's accepted labels (the digest the pipeline
        gives them: sha256 of the approved assignment ids in id order), now and then after a
        failed one."""
        rng = self.rng
        digest = hashlib.sha256(",".join(str(a) for a in approved).encode()).hexdigest()
        params = {"optimiser": "default", "device": "cpu", "w_depth": 1.0, "w_kpt": 1.0,
                  "w_reg": 0.001, "iterations": 30}
        if rng.random() < 0.05:
            run_id = self.ids.take("solve_runs")
            self.rows["solve_runs"].append(
                (run_id, seq_id, "default", _dumps(params), "failed", "{}", None,
                 "ValueError: object 2 has no initial pose", None, digest, num_frames, views,
                 at, at + timedelta(seconds=3), at))
            at += timedelta(hours=2)
        run_id = self.ids.take("solve_runs")
        total = rng.uniform(60, 400)
        timings = {"gather_s": round(total * 0.1, 2), "solve_s": round(total * 0.85, 2),
                   "store_s": round(total * 0.05, 2), "total_s": round(total, 2)}
        summary = {"fingertip_px": {f: round(rng.uniform(2, 6), 2) for f in
                                    ("thumb", "index", "middle", "ring", "little")},
                   "depth_rms_mm": round(rng.uniform(4, 9), 2), "labelled_frames": num_frames,
                   "frames": num_frames}
        finished = at + timedelta(seconds=total)
        self.rows["solve_runs"].append(
            (run_id, seq_id, "default", _dumps(params), "done", _dumps(timings),
             _dumps(summary), None, f"solves/{uid}/run_{run_id:06d}/result.npz", digest,
             num_frames, views, at, finished, at))
        self._job("solve", f"solve-run:{run_id}", {"run_id": run_id}, "done", at,
                  {"message": f"solve run {run_id} done in {total:.0f} s"})

    def blocks(self) -> None:
        """Workers the QC job blocked after repeated rejections."""
        for worker, count in sorted(self.rejections.items()):
            if count >= 8:
                self.rows["crowd_worker_actions"].append(
                    (self.ids.take("crowd_worker_actions"), worker, "block", "", None,
                     f"{count} rejected assignments", START + timedelta(days=60)))

    def take_rows(self) -> dict[str, list[tuple[Any, ...]]]:
        rows, self.rows = self.rows, {t: [] for t in COLUMNS}
        for table, batch in rows.items():
            self.stats.rows[table] += len(batch)
        return rows


def _copy(conn: Any, rows: dict[str, list[tuple[Any, ...]]]) -> None:
    with conn.cursor() as cur:
        for table in TABLE_ORDER:
            batch = rows[table]
            if not batch:
                continue
            cols = ", ".join(f'"{c}"' for c in COLUMNS[table])
            with cur.copy(f"COPY {table} ({cols}) FROM STDIN") as copy:
                for row in batch:
                    copy.write_row(row)


def fill(url: str, sequences: int = 1000, seed: int = 0,
         progress: Callable[[int], None] | None = None) -> FillStats:
    """Fill the migrated, empty database at ``url`` with ``sequences`` DexYCB-sized sequences
    and their work, then VACUUM and ANALYZE it. Returns what was written."""
    import psycopg

    from backend.crowd.totals import REBUILD_SQL

    filler = _Filler(seed, sequences)
    with psycopg.connect(psycopg_url(url)) as conn:
        filler.subjects()
        for start in range(0, sequences, BATCH_SEQUENCES):
            for index in range(start, min(start + BATCH_SEQUENCES, sequences)):
                filler.sequence(index)
            _copy(conn, filler.take_rows())
            conn.commit()
            if progress is not None:
                progress(filler.stats.sequences)
        filler.blocks()
        _copy(conn, filler.take_rows())
        with conn.cursor() as cur:
            # The serial counters continue after the ids given here.
            for table in COLUMNS:
                cur.execute(f"SELECT setval(pg_get_serial_sequence('{table}', 'id'), "
                            f"GREATEST((SELECT max(id) FROM {table}), 1))")
            # The cost report's running totals, as the product keeps them with each payment.
            for statement in REBUILD_SQL:
                cur.execute(statement)
        conn.commit()
        conn.autocommit = True
        # The steady state of a live database: statistics and visibility maps as autovacuum
        # leaves them (index-only scans need the latter).
        conn.execute("VACUUM (ANALYZE)")
    return filler.stats


def table_sizes(url: str) -> tuple[int, dict[str, dict[str, int]]]:
    """(pg_database_size, {table: {rows, bytes}}) of the big tables."""
    import psycopg

    with psycopg.connect(psycopg_url(url)) as conn:
        size = conn.execute("SELECT pg_database_size(current_database())").fetchall()[0][0]
        tables = {}
        for table in BIG_TABLES:
            rows, total = conn.execute(
                f"SELECT count(*), pg_total_relation_size('{table}') FROM {table}").fetchall()[0]
            tables[table] = {"rows": int(rows), "bytes": int(total)}
    return int(size), tables


# --- timing the reads --------------------------------------------------------------------


def _point_at(url: str) -> None:
    """This process's settings, engine and storage: the filled database."""
    os.environ.update({"DEXLABEL_DATABASE_URL": url, "DEXLABEL_ENV": "test",
                       "DEXLABEL_VAR_DIR": tempfile.mkdtemp(prefix="dexlabel-scale-")})
    os.environ.pop("DEXLABEL_REDIS_URL", None)
    from backend.config import get_settings
    from backend.db import get_engine, get_sessionmaker
    from backend.storage import get_storage

    for fn in (get_settings, get_engine, get_sessionmaker, get_storage):
        fn.cache_clear()


def sample_sequence(url: str) -> int:
    """A finished sequence in the middle of the set (its latest solve run is done)."""
    from sqlalchemy import func, select

    from backend.db import session_scope
    from backend.solve.models import SolveRun

    with session_scope() as session:
        middle = (session.scalar(select(func.max(SolveRun.sequence_id))) or 1) // 2
        found = session.scalar(select(SolveRun.sequence_id).where(
            SolveRun.status == "done", SolveRun.sequence_id >= middle)
            .order_by(SolveRun.sequence_id).limit(1))
    return int(found or 1)


@dataclass
class Timed:
    ms: float  # median wall time of a run
    min_ms: float  # fastest run (the least disturbed by other load on the machine)
    sql_ms: float  # median time inside the database driver's execute (the SQL itself)
    cpu_ms: float  # median CPU time of this process (the app's own work, whatever the load)
    # Median CPU time of the database's server processes (a local server only, else None):
    # with cpu_ms, what a read costs whatever else the machine runs.
    db_cpu_ms: float | None
    statements: int
    items: int


def _server_pids() -> list[int]:
    """The server processes of this database's connections (this process's pool)."""
    from sqlalchemy import text

    from backend.db import get_engine

    with get_engine().connect() as conn:
        return [int(pid) for pid in conn.scalars(text(
            "SELECT pid FROM pg_stat_activity WHERE datname = current_database()"))]


def _server_cpu_s(pids: list[int]) -> float | None:
    """Seconds on a CPU so far of these server processes (/proc/PID/schedstat), or None when
    the server is not on this machine."""
    total = 0.0
    for pid in pids:
        try:
            total += int(Path(f"/proc/{pid}/schedstat").read_text().split()[0]) / 1e9
        except (OSError, ValueError, IndexError):
            return None
    return total


def _measure(fn: Callable[[], int], repeat: int) -> Timed:
    from sqlalchemy import event

    from backend.db import get_engine

    engine = get_engine()
    count = [0]
    in_sql = [0.0]
    started_at: list[float] = []

    def _before(*_: Any) -> None:
        count[0] += 1
        started_at.append(time.perf_counter())

    def _after(*_: Any) -> None:
        in_sql[0] += time.perf_counter() - started_at.pop()

    event.listen(engine, "before_cursor_execute", _before)
    event.listen(engine, "after_cursor_execute", _after)
    try:
        items = fn()  # warm-up: connections, plan caches, the OS page cache
        pids = _server_pids()
        count[0] = 0
        times, sql, cpu, db_cpu = [], [], [], []
        for _ in range(repeat):
            in_sql[0] = 0.0
            db_started = _server_cpu_s(pids)
            started, cpu_started = time.perf_counter(), time.process_time()
            fn()
            times.append((time.perf_counter() - started) * 1000)
            cpu.append((time.process_time() - cpu_started) * 1000)
            sql.append(in_sql[0] * 1000)
            db_now = _server_cpu_s(pids)
            if db_started is not None and db_now is not None:
                db_cpu.append((db_now - db_started) * 1000)
        statements = count[0] // repeat
    finally:
        event.remove(engine, "before_cursor_execute", _before)
        event.remove(engine, "after_cursor_execute", _after)
    return Timed(round(statistics.median(times), 2), round(min(times), 2),
                 round(statistics.median(sql), 2), round(statistics.median(cpu), 2),
                 round(statistics.median(db_cpu), 2) if db_cpu else None, statements, items)


def read_queries(sequence_id: int) -> dict[str, Callable[[], int]]:
    """Each heavy read the QC and solve jobs and the progress page run, as a function of no
    arguments that opens its own session and returns how many things it read."""
    from backend.db import session_scope
    from backend.exports.content import load_sequence
    from backend.exports.service import check_request
    from backend.labels import accepted_digest, approved_labels, count_accepted
    from backend.progress.service import sequence_progress
    from backend.quality.inputs import target_inputs
    from backend.quality.service import _population, worker_quality

    def run(fn: Callable[[Any], int]) -> Callable[[], int]:
        def call() -> int:
            with session_scope() as session:
                return fn(session)
        return call

    seq = sequence_id
    frames = 0

    def _frames(session: Any) -> int:
        nonlocal frames
        from backend.captures.models import Sequence

        frames = session.get(Sequence, seq).num_frames
        return frames

    run(_frames)()
    return {
        "progress_service": run(lambda s: len(sequence_progress(s, seq).tasks)),
        "accepted_digest": run(lambda s: int(accepted_digest(s, seq)[0] is not None)),
        "qc_target_inputs_hand": run(lambda s: len(target_inputs(s, seq, "hand:0").labels)),
        "qc_target_inputs_object": run(
            lambda s: len(target_inputs(s, seq, "object:1").labels)),
        "qc_population_hand": run(lambda s: len(_population(s, "hand", {}))),
        "qc_worker_quality": run(lambda s: len(worker_quality(s))),
        "solve_approved_labels": run(lambda s: len(approved_labels(s, seq, frames))),
        "solve_count_accepted": run(lambda s: count_accepted(s, seq)),
        "export_load_sequence": run(lambda s: len(load_sequence(s, seq).work)),
        "export_check_project": run(
            lambda s: len(check_request(s, "json", None, "accepted", {}).ids)),
    }


def api_queries(sequence_id: int) -> dict[str, Callable[[], int]]:
    """The admin endpoints, through the app with an admin's token; each returns its items."""
    from fastapi.testclient import TestClient
    from sqlalchemy import select

    from backend.accounts.service import create_admin
    from backend.annotation.models import Assignment
    from backend.app import create_app
    from backend.captures.models import Camera
    from backend.db import session_scope

    email, password = "scale-bench@dexlabel.local", "scale-bench-password"
    with session_scope() as session:
        create_admin(session, email, password, reset=True)
    client = TestClient(create_app())
    token = client.post("/api/auth/token", json={"email": email, "password": password})
    headers = {"Authorization": f"Bearer {token.json()['access_token']}"}

    def get(path: str) -> Callable[[], int]:
        def call() -> int:
            resp = client.get(path, headers=headers)
            if resp.status_code != 200:
                raise RuntimeError(f"GET {path}: {resp.status_code} {resp.text[:300]}")
            body = resp.json()
            if isinstance(body, list):
                return len(body)
            if "tasks" in body:
                return len(body["tasks"])
            if "frames" in body:
                return len(body["frames"])
            if "items" in body or "assignments" in body:
                return len(body.get("items", body.get("assignments", [])))
            return len(body.get("by_sequence", [])) + len(body.get("by_worker", []))
        return call

    seq = sequence_id
    with session_scope() as session:
        serial = session.scalar(select(Camera.serial).where(Camera.sequence_id == seq)
                                .order_by(Camera.view_index).limit(1))
        worker = session.scalar(select(Assignment.worker_id).where(
            Assignment.worker_id.is_not(None)).order_by(Assignment.id).limit(1))
    return {
        "GET /api/auth/me (floor)": get("/api/auth/me"),
        "GET /api/sequences": get("/api/sequences"),
        "GET /api/sequences/{id}/progress": get(f"/api/sequences/{seq}/progress"),
        "GET /api/qc/reports?sequence_id=": get(f"/api/qc/reports?sequence_id={seq}"),
        "GET /api/qc/workers": get("/api/qc/workers"),
        "GET /api/crowd/costs": get("/api/crowd/costs"),
        "GET /api/jobs": get("/api/jobs"),
        "GET /api/jobs?status=failed": get("/api/jobs?status=failed"),
        "GET /api/jobs?kind=solve": get("/api/jobs?kind=solve"),
        "GET /api/tasks?sequence_id=": get(f"/api/tasks?sequence_id={seq}"),
        "GET /api/sequences/{id}/views/{serial}/frames": get(
            f"/api/sequences/{seq}/views/{serial}/frames"),
        "GET /api/qc/queue": get("/api/qc/queue"),
        "GET /api/crowd/workers": get("/api/crowd/workers"),
        "GET /api/crowd/workers/{id}": get(f"/api/crowd/workers/{worker}"),
    }


def time_queries(url: str, repeat: int = 5) -> dict[str, dict[str, float | int | None]]:
    """Median milliseconds, statements per run and items of each listing and heavy read."""
    _point_at(url)
    seq = sample_sequence(url)
    out: dict[str, dict[str, float | int | None]] = {}
    for name, fn in {**api_queries(seq), **read_queries(seq)}.items():
        timed = _measure(fn, repeat)
        out[name] = {"ms": timed.ms, "min_ms": timed.min_ms, "sql_ms": timed.sql_ms,
                     "cpu_ms": timed.cpu_ms, "db_cpu_ms": timed.db_cpu_ms,
                     "statements": timed.statements, "items": timed.items}
        db_cpu = "-" if timed.db_cpu_ms is None else f"{timed.db_cpu_ms:6.1f}"
        print(f"{name:34s} {timed.ms:7.1f} ms (min {timed.min_ms:6.1f}, SQL {timed.sql_ms:6.1f},"
              f" CPU {timed.cpu_ms:6.1f} + DB {db_cpu}) {timed.statements:3d} statements"
              f" {timed.items:5d} items", flush=True)
    return out


def _human(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GB"


def time_only(url: str, repeat: int) -> dict[str, Any]:
    """The timings on a database filled before (``--keep``), after migrating it to head."""
    from backend.migrate import upgrade

    upgrade(url)
    size, tables = table_sizes(url)
    _point_at(url)
    seq = sample_sequence(url)
    return {"db_bytes": size, "db_size": _human(size), "tables": tables,
            "sample_sequence_id": seq, "queries": time_queries(url, repeat)}


def run(url: str, sequences: int, keep: bool, repeat: int, queries: bool,
        seed: int = 0) -> dict[str, Any]:
    from backend.migrate import upgrade

    create_database(url)
    try:
        started = time.perf_counter()
        upgrade(url)
        migrate_s = time.perf_counter() - started
        started = time.perf_counter()
        last = [started]

        def progress(done: int) -> None:
            now = time.perf_counter()
            if now - last[0] > 15 or done == sequences:
                last[0] = now
                print(f"filled {done}/{sequences} sequences in {now - started:.0f} s",
                      flush=True)

        stats = fill(url, sequences, seed, progress)
        fill_s = time.perf_counter() - started
        size, tables = table_sizes(url)
        summary: dict[str, Any] = {
            "sequences": stats.sequences, "finished": stats.finished, "views": stats.views,
            "tasks": stats.tasks, "hits": stats.hits, "assignments": stats.assignments,
            "tracks": stats.tracks, "frames": stats.frames, "qc_reports": stats.qc_reports,
            "jobs": stats.jobs, "observations": stats.observations,
            "observations_stored": stats.observations_stored,
            "fill_s": round(fill_s, 1), "migrate_s": round(migrate_s, 1), "db_bytes": size,
            "db_size": _human(size), "tables": tables}
        print(f"filled in {fill_s:.0f} s: {_human(size)}", flush=True)
        if queries:
            _point_at(url)
            summary["sample_sequence_id"] = sample_sequence(url)
            summary["queries"] = time_queries(url, repeat)
        return summary
    finally:
        if not keep:
            from backend.db import get_engine

            if get_engine.cache_info().currsize:
                get_engine().dispose()
            drop_database(url)


EPILOG = ("Default run here (2 shared cores): about 4-8 minutes (the 1,000-sequence fill takes"
          " 2-4, then the timings); needs PostgreSQL. Short: --sequences 2 --repeat 1"
          " (under a minute), --no-queries.")


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=EPILOG)
    parser.add_argument("--sequences", type=int, default=1000)
    parser.add_argument("--url", default=os.environ.get("DEXLABEL_SCALE_URL", DEFAULT_URL),
                        help="SQLAlchemy URL of the database to (re)create")
    parser.add_argument("--keep", action="store_true", help="keep the database afterwards")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per query")
    parser.add_argument("--no-queries", dest="queries", action="store_false")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--time-only", action="store_true",
                        help="only time the queries on a database kept by an earlier run")
    args = parser.parse_args(argv)
    if args.time_only:
        summary = time_only(args.url, args.repeat)
    else:
        summary = run(args.url, args.sequences, args.keep, args.repeat, args.queries,
                      args.seed)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
