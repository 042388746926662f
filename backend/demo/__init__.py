"""The demo's moving parts (`dexlabel demo` in backend/cli/__init__.py drives them): a server
and a queue consumer in this process, ready logins kept in the instance, the published tasks, a
simulated crowd that works until every task has accepted work, and the links printed for a
first look.
"""

from __future__ import annotations

import json
import os
import secrets
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import typer
from sqlalchemy import func, select

from backend.config import get_settings
from backend.db import session_scope
from backend.errors import DexlabelError
from backend.instance import client_url, forget_server, record_server

if TYPE_CHECKING:
    import uvicorn
    from huey.consumer import Consumer

    from backend.crowd.simulate import Protocol, WorkerOutcome

DEMO_ADMIN_EMAIL = "demo@dexlabel.local"
DEMO_WORKER_EMAIL = "demo-worker@dexlabel.local"
LOGINS_FILE = "demo-logins.json"
# The simulated crowd works in rounds: rejected work re-opens its HIT with one more
# assignment, which the next round's new workers take. Mixed profiles reject about a third
# of the work, so six rounds leave a task without accepted work only rarely.
MAX_ROUNDS = 6
ACTIVE_JOBS = ("queued", "running", "retrying")
# How long the demo waits for the queue to go idle (QC and the solve), and how often it looks.
JOBS_TIMEOUT_S = 1800.0
POLL_S = 0.5
# Crowd-and-solve passes at most: under the adaptive publishing policy each solve may publish
# another view per target (backend.crowd.adaptive), and the crowd comes back for it.
MAX_SOLVE_PASSES = 8
# Apart far enough that two crowd seeds never share a round's seed (rounds x passes < 1009).
CROWD_SEED_STRIDE = 1009


@dataclass(frozen=True)
class Login:
    email: str
    password: str


class DemoServer:
    """The app served by uvicorn in a thread of this process, with a queue consumer (QC and
    the solve run while the crowd works); its address is recorded in the instance."""

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port
        self.server: uvicorn.Server | None = None
        self.thread: threading.Thread | None = None
        self.consumer: Consumer | None = None

    @property
    def has_consumer(self) -> bool:
        return self.consumer is not None

    def start(self) -> None:
        import uvicorn

        from backend.app import create_app
        from backend.jobs.consumer import start_inprocess_consumer
        from backend.server_process import KEEP_ALIVE_S
        from worker.tasks import register_handlers

        settings = get_settings()
        # Claimed first: a second server of this instance is refused before it starts.
        record_server(settings, client_url(self.host, self.port))
        if settings.inprocess_worker and not settings.redis_url:
            register_handlers()
            self.consumer = start_inprocess_consumer(settings.worker_threads)
        config = uvicorn.Config(create_app(), host=self.host, port=self.port,
                                log_level="warning", proxy_headers=False,
                                timeout_keep_alive=KEEP_ALIVE_S)
        self.server = server = uvicorn.Server(config)
        self.thread = thread = threading.Thread(target=server.run, daemon=True)
        thread.start()
        deadline = time.monotonic() + 30
        while not server.started:
            if not thread.is_alive() or time.monotonic() > deadline:
                raise DexlabelError(f"the server did not start on {self.host}:{self.port} "
                                    "(is the port taken? try --port)")
            time.sleep(0.05)

    def wait(self) -> None:
        """Serve until Ctrl+C or SIGTERM: uvicorn installs its own signal handlers only in
        the main thread, so this (main) thread asks the server to exit."""
        import signal

        def _exit(_signum: int, _frame: object) -> None:
            if self.server is not None:
                self.server.should_exit = True

        signal.signal(signal.SIGINT, _exit)
        signal.signal(signal.SIGTERM, _exit)
        while self.thread is not None and self.thread.is_alive():
            self.thread.join(0.5)

    def stop(self) -> None:
        forget_server(get_settings())
        if self.server is not None:
            self.server.should_exit = True
        if self.thread is not None:
            self.thread.join(timeout=30)
        if self.consumer is not None:
            self.consumer.stop(graceful=True)


# --- logins ------------------------------------------------------------------------------


def _saved_logins(path: Path) -> dict[str, Login]:
    try:
        data = json.loads(path.read_text())
        return {role: Login(str(v["email"]), str(v["password"])) for role, v in data.items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def _save_logins(path: Path, logins: dict[str, Login]) -> None:
    """Written readable by the owner only (0600): the file holds passwords."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as out:
        json.dump({role: vars(login) for role, login in logins.items()}, out, indent=2)
    os.chmod(path, 0o600)


def demo_logins() -> dict[str, Login]:
    """The demo's admin and portal worker, ready to sign in; their passwords are made once
    and kept in ``{var_dir}/demo-logins.json``, so a re-run prints the same ones."""
    from backend.accounts.models import PortalAccount
    from backend.accounts.service import change_password, create_admin
    from backend.market.clock import now
    from backend.portal.accounts import create_account
    from backend.security import verify_password

    path = get_settings().var_dir / LOGINS_FILE
    saved = _saved_logins(path)
    logins = {role: saved.get(role) or Login(email, secrets.token_urlsafe(12))
              for role, email in (("admin", DEMO_ADMIN_EMAIL), ("worker", DEMO_WORKER_EMAIL))}
    _save_logins(path, logins)
    admin, worker = logins["admin"], logins["worker"]
    with session_scope() as session:
        create_admin(session, admin.email, admin.password, reset=True)
        account = session.scalar(select(PortalAccount).where(PortalAccount.email == worker.email))
        if account is None:
            create_account(session, worker.email, worker.password, now())
        else:
            if not verify_password(worker.password, account.password_hash):
                # The logins file was lost: the kept password wins, and tokens issued under
                # the old one end.
                change_password(session, account, worker.password)
            account.active = True
    return logins


def demo_annotation_link(sequence_id: int, base: str) -> str:
    """Creates the sequence's tasks; the page link of a demo worker's own assignment on the
    first hand task (a direct link: its submission goes to QC without a marketplace)."""
    from backend.annotation import service
    from backend.annotation.tokens import assignment_token, page_url
    from backend.storage import get_storage

    with session_scope() as session:
        tasks = service.create_tasks(session, get_storage(), sequence_id)
        task = service.get_task_or_raise(session, next(t.id for t in tasks if t.kind == "hand"))
        assignment = next((a for a in task.assignments if a.worker_id == "demo-worker"), None)
        if assignment is None:
            assignment = service.create_assignment(session, task, "demo-worker")
        return page_url(base, assignment_token(task, assignment),
                        assignmentId=assignment.external_id, workerId=assignment.worker_id)


# --- the crowd ---------------------------------------------------------------------------


def demo_publish(sequence_id: int, assignments: int) -> None:
    """Publish the sequence's tasks on the built-in marketplace, hand tasks first (so they
    are offered first), then the object tasks."""
    from backend.crowd import flows
    from backend.crowd.providers import get_provider
    from backend.crowd.schemas import PublishOptions

    marketplace = get_provider("mturk")
    options = PublishOptions(max_assignments=assignments, provider="mturk")
    for kind in ("hand", "object"):
        result = flows.publish_each(marketplace, options, sequence_id, kind)
        typer.echo(f"{kind} tasks: {result.created} HITs created, {result.recovered} "
                   f"recovered, {_hits(sequence_id, kind)} published in all")


def round_seed(crowd_seed: int, round_: int, pass_: int = 1) -> int:
    """The simulated crowd's seed for one round of one crowd-and-solve pass: crowd 0's first
    pass is the demo's own (7 + round); a later pass, or another crowd seed, draws other
    profiles and other noise in every round."""
    return 7 + round_ + MAX_ROUNDS * (pass_ - 1) + CROWD_SEED_STRIDE * crowd_seed


def demo_crowd(sequence_id: int, capture: Path, admin: Login, workers: int | None,
               can_wait: bool, profile: str = "mixed",
               protocol: Protocol = "keyframes", crowd_seed: int = 0, pass_: int = 1
               ) -> list[WorkerOutcome]:
    """Rounds of simulated workers (``profile``: mixed by default; labelling as ``protocol``
    asks, backend.crowd.simulate; round r draws with round_seed(crowd_seed, r, pass_)), one
    per open assignment, until every
    task has accepted work or MAX_ROUNDS passed. After each round the submissions are synced
    and the quality checks waited for: they approve, or reject and re-open the HIT with one
    more assignment; the demo's admin approves the best work left for review.
    Returns what each simulated worker did (its profile, its assignment), every round's."""
    from backend.crowd.simulate import simulate

    done: list[WorkerOutcome] = []
    for round_ in range(1, MAX_ROUNDS + 1):
        missing, _ = unaccepted(sequence_id)
        slots = _open_slots(sequence_id, extend=round_ > 1)
        if not missing or not slots:
            return done
        count = min(workers or slots, slots)
        typer.echo(f"round {round_}: {count} simulated workers for {missing} tasks without "
                   "accepted work ...")
        started = time.perf_counter()
        outcomes = simulate(get_settings().public_url, capture, count, profile, admin.email,
                            admin.password, seed=round_seed(crowd_seed, round_, pass_),
                            first_index=_simulated_accounts() + 1, protocol=protocol)
        done.extend(outcomes)
        submitted = sum(o.status == "submitted" for o in outcomes)
        _sync()
        typer.echo(f"round {round_}: {submitted} submitted in "
                   f"{time.perf_counter() - started:.0f} s; quality checks running ...")
        if not can_wait or not wait_for_jobs():
            return done
        if approve_reviewed(sequence_id):
            wait_for_jobs()
        if not submitted:
            return done
    return done


def demo_until_solved(sequence_id: int, capture: Path, admin: Login, workers: int | None,
                      profile: str = "mixed", protocol: Protocol = "keyframes",
                      crowd_seed: int = 0) -> tuple[list[WorkerOutcome], int]:
    """The crowd (demo_crowd), then the quality checks and the solve waited for, again while
    a solve published more views (the adaptive policy) that have no accepted work, at most
    MAX_SOLVE_PASSES times; (every simulated worker's outcome, passes). Needs a queue
    consumer (the checks and the solve run on it)."""
    done: list[WorkerOutcome] = []
    passes = 0
    while passes < MAX_SOLVE_PASSES:
        passes += 1
        done += demo_crowd(sequence_id, capture, admin, workers, True, profile, protocol,
                           crowd_seed, passes)
        wait_for_jobs()
        wait_for_solve(sequence_id)
        wait_for_jobs()
        if not unaccepted(sequence_id)[0]:
            break
        typer.echo(f"pass {passes}: the solve asked for more views; the crowd comes back")
    return done, passes


def approve_reviewed(sequence_id: int) -> int:
    """The demo's admin at work: for each task still without accepted work, approve the
    assignment QC left for review with the smallest error (as the admin page's Approve does),
    saying which; the number approved."""
    from backend.annotation.models import Assignment
    from backend.labels import ACCEPTED
    from backend.pipeline import approve
    from backend.quality.models import QCReport

    with session_scope() as session:
        accepted = set(session.scalars(select(Assignment.task_id).where(
            Assignment.status == ACCEPTED)))
        rows = session.execute(
            select(QCReport.task_id, QCReport.assignment_id, QCReport.target_key,
                   QCReport.metrics, QCReport.feedback)
            .join(Assignment, Assignment.id == QCReport.assignment_id)
            .where(QCReport.sequence_id == sequence_id, QCReport.outcome == "review",
                   QCReport.provisional.is_(False), Assignment.status == "submitted")).all()
    best: dict[int, tuple[float, int, str, str]] = {}
    for task_id, assignment_id, target, metrics, feedback in rows:
        error = (metrics or {}).get("median_error_px")
        key = (float("inf") if error is None else float(error), assignment_id, target,
               (feedback or "").split(". ")[0])
        if task_id not in accepted and (task_id not in best or key < best[task_id]):
            best[task_id] = key
    for task_id, (_error, assignment_id, target, why) in sorted(best.items()):
        with session_scope() as session:
            approve(session, None, assignment_id, None)
        typer.echo(f"  demo admin approved assignment {assignment_id} (task {task_id}, "
                   f"{target}), left for review: {why}")
    return len(best)


def _sync() -> int:
    from backend.pipeline import sync

    with session_scope() as session:
        return sync(session).accepted


def wait_for_jobs(timeout_s: float = JOBS_TIMEOUT_S) -> bool:
    """Wait until no job is queued, running or retrying; False when the time ran out."""
    from backend.jobs.models import Job

    deadline = time.monotonic() + timeout_s
    while True:
        with session_scope() as session:
            active = session.scalar(select(func.count()).select_from(Job)
                                    .where(Job.status.in_(ACTIVE_JOBS))) or 0
        if not active:
            return True
        if time.monotonic() > deadline:
            typer.echo(f"{active} jobs still queued or running after {timeout_s:.0f} s")
            return False
        time.sleep(POLL_S)


def wait_for_solve(sequence_id: int, timeout_s: float = JOBS_TIMEOUT_S) -> None:
    """Wait until the sequence's newest solve run is done or failed (none: nothing to wait
    for); a run still queued while no job is active has nobody to run it and is not waited
    for."""
    from backend.jobs.models import Job
    from backend.solve.models import SolveRun

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with session_scope() as session:
            status = session.scalar(select(SolveRun.status).where(
                SolveRun.sequence_id == sequence_id).order_by(SolveRun.id.desc()).limit(1))
            active = session.scalar(select(func.count()).select_from(Job)
                                    .where(Job.status.in_(ACTIVE_JOBS))) or 0
        if status in (None, "done", "failed") or (status == "queued" and not active):
            return
        time.sleep(POLL_S)


def _hits(sequence_id: int, kind: str) -> int:
    from backend.annotation.models import Task
    from backend.crowd.models import CrowdHit

    with session_scope() as session:
        return int(session.scalar(
            select(func.count()).select_from(CrowdHit).join(Task, Task.id == CrowdHit.task_id)
            .where(Task.sequence_id == sequence_id, Task.kind == kind,
                   CrowdHit.hit_id.is_not(None))) or 0)


def unaccepted(sequence_id: int) -> tuple[int, int]:
    """(tasks without approved work, tasks) of the sequence, leaving out the views the
    adaptive publishing policy holds back."""
    from backend.annotation.models import Assignment, Task
    from backend.crowd.adaptive import held_task_ids
    from backend.labels import ACCEPTED

    with session_scope() as session:
        tasks = set(session.scalars(select(Task.id).where(Task.sequence_id == sequence_id)))
        # Views the adaptive policy holds back wait for a solve that needs them.
        tasks -= held_task_ids(session, [sequence_id])
        accepted = set(session.scalars(select(Assignment.task_id).where(
            Assignment.task_id.in_(tasks), Assignment.status == ACCEPTED)))
    return len(tasks - accepted), len(tasks)


def _open_slots(sequence_id: int, extend: bool) -> int:
    """Assignments the marketplace still offers on the sequence's HITs; with ``extend``,
    first one more on each HIT whose task has neither accepted nor submitted work and nothing
    left on offer."""
    from backend.annotation.models import Assignment, Task
    from backend.crowd.actions import add_assignments
    from backend.crowd.models import CrowdHit
    from backend.crowd.providers import get_provider
    from backend.labels import SCORED_STATUSES

    marketplace = get_provider("mturk")
    with session_scope() as session:
        hits = dict(session.execute(
            select(CrowdHit.hit_id, CrowdHit.task_id).join(Task, Task.id == CrowdHit.task_id)
            .where(Task.sequence_id == sequence_id, CrowdHit.hit_id.is_not(None))).all())
        # Tasks with accepted work, or with submitted work QC has not decided yet (it waits
        # for more views to compare with): another assignment would not help them.
        scored = set(session.scalars(select(Assignment.task_id).where(
            Assignment.task_id.in_(hits.values()), Assignment.status.in_(SCORED_STATUSES))))
    offered: dict[str, int] = {}
    for hit_id in hits:
        unit = marketplace.unit(hit_id) if hit_id is not None else None
        if unit is not None:  # the places no worker holds or has submitted
            offered[unit.unit_id] = max(unit.places - unit.held - unit.submitted, 0)
    for hit_id, available in offered.items():
        if extend and not available and hits[hit_id] not in scored:
            with session_scope() as session, session.no_autoflush:
                row = session.scalar(select(CrowdHit).where(CrowdHit.hit_id == hit_id))
                if row is not None and \
                        row.max_assignments + 1 < marketplace.fees().large_unit_places:
                    add_assignments(session, marketplace, hit_id, 1)
                    offered[hit_id] = 1
    return sum(offered.values())


def _simulated_accounts() -> int:
    from backend.accounts.models import PortalAccount
    from backend.crowd.simulate import WORKER_EMAIL

    pattern = WORKER_EMAIL.split("{", 1)[0] + "%"
    with session_scope() as session:
        return int(session.scalar(select(func.count()).select_from(PortalAccount)
                                  .where(PortalAccount.email.like(pattern))) or 0)
