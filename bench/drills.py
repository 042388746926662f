"""Fault drills: real workers, real servers, real faults, with the product's real timings.

Each drill runs in a fresh instance of its own (a temp folder; the Redis and PostgreSQL ones on
throwaway servers from tests/servers.py, never the machine's) and in a process of its own, and
prints one JSON line; ``all`` runs every drill and ends with one JSON object of them all.

    kill-qc     a worker is killed (kill -9) after the first action of a QC job over 6
                submissions (a 3 s pause at each checkpoint); another worker starts at once, as
                a supervisor would restart it. The job must finish once: 6 decisions, one
                payment each. Measures the seconds from the kill to the job done (its lease,
                5 s here, then at most a reaper pass, 60 s).
    kill-solve  a worker is killed mid-solve (a 4-view x 12-frame capture with labels from its
                ground truth) and another starts at once; the run must end done once, in the
                job's second attempt. Measures the seconds from the kill to the run done.
    redis       PostgreSQL and Redis (throwaway), two workers of 4 threads each, and 20 jobs a
                second queued for 60 s, each working 0.2 s. Redis is killed at 15 s and
                started again empty at 35 s. Every job must run exactly once; measures how
                long a queueing unit of work took while Redis was down, and the seconds from
                Redis's return to the first job done and to every job done.
    lease       a QC job that works about 90 s (a 15 s pause after each of its 6 actions) on a
                2 s lease, beside a second worker, with the reapers at their real minute: the
                heartbeat keeps the lease, so one attempt acts once on every report.

Usage: python bench/drills.py [kill-qc|kill-solve|redis|lease|all]   (default: all)
Default run here (2 shared cores): all four, about 10 minutes. Short: one drill; kill-qc is the
quickest (1-3 minutes: a 6 x 16 capture at 320x240, a server, 6 submissions, a kill).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.servers import wait_for  # noqa: E402

from _server import isolated_workdir, start_server  # noqa: E402

DRILLS = ("kill-qc", "kill-solve", "redis", "lease")
CLI = [sys.executable, "-m", "backend.cli"]
# The drill job of the redis drill: where each run is written down, one line per run.
RUNS_LOG = "DEXLABEL_DRILL_RUNS"


def _worker(log: Path, threads: int = 1, **settings: str) -> subprocess.Popen[bytes]:
    """A `dexlabel worker` (with the drill's job registered) in a process of its own."""
    env = {**os.environ, **settings}
    return subprocess.Popen([sys.executable, __file__, "worker", str(threads)], env=env,
                            cwd=ROOT, stdout=log.open("ab"), stderr=subprocess.STDOUT)


def _stop(*procs: subprocess.Popen[bytes]) -> None:
    for proc in procs:
        if proc.poll() is None:
            proc.terminate()
    for proc in procs:
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _kill(proc: subprocess.Popen[bytes]) -> None:
    proc.send_signal(signal.SIGKILL)  # no clean-up runs: the job's row still says running
    proc.wait(timeout=10)


def _migrate() -> None:
    subprocess.run(CLI + ["migrate"], check=True, capture_output=True, timeout=300)


def _job(key: str) -> Any:
    from sqlalchemy import select

    from backend.db import session_scope
    from backend.jobs.models import Job

    with session_scope() as session:
        job = session.scalars(select(Job).where(Job.key == key)).one()
        session.expunge(job)
        return job


# --- QC drills: a crowd on the built-in marketplace ------------------------------------------


def _crowd_qc(name: str) -> tuple[str, list[subprocess.Popen[bytes]], Path]:
    """An instance serving its marketplace, 6 submissions (5 careful, 1 spammer) of one hand
    target, confirmed: its QC job queued. (the job's key, the server, the log file)"""
    work = isolated_workdir(name)  # before anything reads the settings
    from worker.synth import generate_capture

    _migrate()
    capture = work / "capture"
    generate_capture(capture, seed=5, frames=16, views=6, objects=1, width=320, height=240)
    server, base = start_server(dict(os.environ))
    os.environ["DEXLABEL_PUBLIC_URL"] = base
    from backend.quality.service import qc_key
    from tests.backend.quality.helpers import crowd_submits, publish_hand_tasks, sync_submissions

    sequence_id, _ = publish_hand_tasks(capture, max_assignments=1)
    crowd_submits(base, capture, ["careful"] * 5 + ["spammer"])
    sync_submissions()
    return qc_key(sequence_id, "hand:0"), [server], work / "workers.log"


def _qc_outcome() -> dict[str, Any]:
    from sqlalchemy import select

    from backend.crowd.models import CrowdPayment
    from backend.db import session_scope
    from backend.quality.models import QCReport

    with session_scope() as session:
        reports = list(session.scalars(select(QCReport)))
        payments = list(session.scalars(select(CrowdPayment)))
    decided = [p.assignment_id for p in payments if p.kind != "bonus"]
    return {"actions": sorted(str(r.action) for r in reports),
            "decided_by_an_admin": sum(r.action_detail == "decided by an admin"
                                       for r in reports),
            "payments": len(decided), "assignments_paid_twice": len(decided) - len(set(decided))}


def drill_kill_qc() -> dict[str, Any]:
    from backend.db import session_scope

    key, procs, log = _crowd_qc("drill-kill-qc")
    settings = {"DEXLABEL_JOB_PAUSE_S": "3", "DEXLABEL_JOB_LEASE_S": "5"}
    first = _worker(log, **settings)
    try:
        def paid() -> bool:
            from sqlalchemy import func, select

            from backend.crowd.models import CrowdPayment

            with session_scope() as session:
                return bool(session.scalar(select(func.count()).select_from(CrowdPayment)))

        wait_for(paid, "the first worker's first action", 300)
    finally:
        _kill(first)
        killed = time.monotonic()
    attempts_at_kill = _job(key).attempts
    second = _worker(log, **settings)
    procs.append(second)
    try:
        job = wait_for(lambda: (j := _job(key)).status in ("done", "failed") and j,
                       "the job to finish after the kill", 600)
        recovered_s = time.monotonic() - killed
    finally:
        _stop(*procs)
    outcome = _qc_outcome()
    ok = (job.status == "done" and outcome["assignments_paid_twice"] == 0
          and outcome["payments"] == 6 and outcome["decided_by_an_admin"] == 0)
    return {"drill": "kill-qc", "ok": ok, "status": job.status, "attempts": job.attempts,
            "attempts_at_kill": attempts_at_kill, "kill_to_done_s": round(recovered_s, 1),
            "lease_s": 5, **outcome}


def drill_lease() -> dict[str, Any]:
    key, procs, log = _crowd_qc("drill-lease")
    settings = {"DEXLABEL_JOB_PAUSE_S": "15", "DEXLABEL_JOB_LEASE_S": "2"}
    started = time.monotonic()
    procs += [_worker(log, **settings), _worker(log, **settings)]
    try:
        job = wait_for(lambda: (j := _job(key)).status in ("done", "failed") and j,
                        "the QC job to finish", 900)
    finally:
        _stop(*procs)
    outcome = _qc_outcome()
    ok = (job.status == "done" and job.attempts == 1 and outcome["payments"] == 6
          and outcome["assignments_paid_twice"] == 0 and outcome["decided_by_an_admin"] == 0)
    return {"drill": "lease", "ok": ok, "status": job.status, "attempts": job.attempts,
            "job_s": round(time.monotonic() - started, 1), "lease_s": 2, **outcome}


# --- kill -9 mid-solve -------------------------------------------------------------------


def drill_kill_solve() -> dict[str, Any]:
    work = isolated_workdir("drill-kill-solve")  # before anything reads the settings
    from sqlalchemy import select

    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.db import session_scope
    from backend.solve.models import SolveRun
    from backend.solve.service import job_key, request_solve
    from backend.storage import get_storage
    from tests.backend.solve import test_solve_api
    from worker.synth import generate_capture

    _migrate()
    frames = 12
    capture = work / "capture"
    generate_capture(capture, seed=3, frames=frames, views=4, objects=1)
    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        create_tasks(session, get_storage(), sequence_id)
    test_solve_api.FRAMES = frames  # labels from the capture's truth, every frame
    test_solve_api._approve_from_truth(capture, sequence_id)
    with session_scope() as session:
        run_id = request_solve(session, sequence_id, optimiser="default").id
    key = job_key(run_id)

    def run_status() -> str:
        with session_scope() as session:
            return session.get_one(SolveRun, run_id).status

    log = work / "workers.log"
    settings = {"DEXLABEL_JOB_LEASE_S": "10"}
    first = _worker(log, **settings)
    try:
        wait_for(lambda: run_status() == "running", "the first worker to start solving", 600)
        time.sleep(2)  # inside the solver
    finally:
        _kill(first)
        killed = time.monotonic()
    status_at_kill = run_status()
    second = _worker(log, **settings)
    try:
        job = wait_for(lambda: (j := _job(key)).status in ("done", "failed") and j,
                        "the solve to finish after the kill", 1800)
        recovered_s = time.monotonic() - killed
    finally:
        _stop(second)
    with session_scope() as session:
        runs = [(r.id, r.status) for r in session.scalars(
            select(SolveRun).where(SolveRun.sequence_id == sequence_id))]
    ok = job.status == "done" and job.attempts == 2 and runs == [(run_id, "done")]
    return {"drill": "kill-solve", "ok": ok, "run_status_at_kill": status_at_kill,
            "status": job.status, "attempts": job.attempts, "runs": runs,
            "kill_to_done_s": round(recovered_s, 1), "lease_s": 10}


# --- Redis stopped under load --------------------------------------------------------------


def drill_redis() -> dict[str, Any]:
    from tests.servers import ThrowawayPostgres, ThrowawayRedis

    postgres, redis = ThrowawayPostgres().start(), ThrowawayRedis().start()
    try:
        return _redis_under_load(postgres.url, redis)
    finally:
        redis.remove()
        postgres.remove()


def _redis_under_load(database_url: str, redis: Any) -> dict[str, Any]:
    work = isolated_workdir("drill-redis")  # (it drops any database or Redis URL set before)
    os.environ.update({"DEXLABEL_DATABASE_URL": database_url, "DEXLABEL_REDIS_URL": redis.url,
                       RUNS_LOG: str(work / "runs.log")})
    _migrate()
    from sqlalchemy import func, select

    from backend.db import session_scope
    from backend.jobs.models import Job
    from backend.jobs.service import enqueue_job

    log = work / "workers.log"
    workers = [_worker(log, threads=4), _worker(log, threads=4)]
    rate, seconds, down_at, up_at = 20, 60, 15.0, 35.0
    latencies: list[tuple[float, float]] = []  # (when, seconds the queueing unit took)
    returned: list[float] = []

    def outage(t0: float) -> None:
        time.sleep(max(t0 + down_at - time.monotonic(), 0))
        redis.stop()
        time.sleep(max(t0 + up_at - time.monotonic(), 0))
        redis.start()  # empty: what it held is gone
        returned.append(time.monotonic())

    try:
        time.sleep(3)  # the workers are up
        t0 = time.monotonic()
        fault = threading.Thread(target=outage, args=(t0,))
        fault.start()
        for n in range(rate * seconds):
            time.sleep(max(t0 + n / rate - time.monotonic(), 0))
            began = time.monotonic()
            with session_scope() as session:
                enqueue_job(session, "drill", f"drill:{n}", {"n": n})
            latencies.append((began - t0, time.monotonic() - began))
        fault.join()
        back = returned[0]
        total = rate * seconds

        def done() -> int:
            with session_scope() as session:
                return int(session.scalar(select(func.count()).select_from(Job).where(
                    Job.kind == "drill", Job.status == "done")) or 0)

        def done_after_return() -> bool:
            with session_scope() as session:
                return bool(session.scalar(select(func.count()).select_from(Job).where(
                    Job.kind == "drill", Job.status == "done",
                    Job.key.in_([f"drill:{n}" for n in range(int(down_at * rate),
                                                               int(up_at * rate))]))))

        wait_for(done_after_return, "a job queued during the outage to run", 600)
        first_s = time.monotonic() - back
        wait_for(lambda: done() == total, "every job to run", 900)
        all_s = time.monotonic() - back
    finally:
        _stop(*workers)
        if not redis.running():
            redis.start()
    runs = (work / "runs.log").read_text().split()
    during = [took for at, took in latencies if down_at <= at < up_at]
    with session_scope() as session:
        attempts = session.scalar(select(func.max(Job.attempts)).where(Job.kind == "drill"))
    ok = len(runs) == len(set(runs)) == total and attempts == 1
    return {"drill": "redis", "ok": ok, "jobs": total, "runs": len(runs),
            "ran_twice": len(runs) - len(set(runs)), "max_attempts": attempts,
            "outage_s": up_at - down_at,
            "queueing_while_down_s": {"median": round(sorted(during)[len(during) // 2], 3),
                                      "max": round(max(during), 3)},
            "return_to_first_outage_job_done_s": round(first_s, 1),
            "return_to_all_done_s": round(all_s, 1)}


def worker_main(threads: int) -> None:
    """A `dexlabel worker` that also runs the redis drill's job."""
    from backend.cli import app
    from backend.jobs.runner import job_handler

    @job_handler("drill")
    def _drill(args: dict[str, Any]) -> dict[str, Any]:
        time.sleep(0.2)
        with open(os.environ[RUNS_LOG], "a") as runs:
            runs.write(f"drill:{args['n']}\n")
        return {"message": f"drill job {args['n']}"}

    app(["worker", "--workers", str(threads)])


def main(argv: list[str]) -> None:
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__)
        return
    if argv[:1] == ["worker"]:
        worker_main(int(argv[1]))
        return
    chosen = argv[0] if argv else "all"
    if chosen == "all":  # each drill in a process of its own: its own settings and queue
        results = []
        for name in DRILLS:
            out = subprocess.run([sys.executable, __file__, name], cwd=ROOT,
                                 capture_output=True, text=True)
            line = (out.stdout.strip().splitlines() or ["{}"])[-1]
            try:
                results.append(json.loads(line))
            except json.JSONDecodeError:
                results.append({"drill": name, "ok": False, "error": out.stderr[-2000:]})
            print(json.dumps(results[-1]), flush=True)
        print(json.dumps({"ok": all(r.get("ok") for r in results),
                          "drills": {r.get("drill", "?"): r for r in results}}))
        return
    drills = {"kill-qc": drill_kill_qc, "kill-solve": drill_kill_solve, "redis": drill_redis,
              "lease": drill_lease}
    if chosen not in drills:
        raise SystemExit(f"unknown drill {chosen!r}; one of {', '.join(DRILLS)} or all")
    print(json.dumps(drills[chosen]()), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
