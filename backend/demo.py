"""The demo's moving parts: a server in a thread, the published tasks, a simulated crowd, and
the links printed for a first look (`dexlabel demo` in backend/cli.py drives them)."""

from __future__ import annotations

import secrets
from pathlib import Path

import typer

from backend.config import get_settings
from backend.errors import DexlabelError

DEMO_ADMIN_EMAIL = "demo@dexlabel.local"


def demo_settings(host: str, port: int):  # type: ignore[no-untyped-def]
    """The settings, with PUBLIC_URL at the server started here unless one was configured:
    the HITs' page links and the requester client must reach it."""
    import os

    from backend.config import Settings

    if get_settings().public_url == Settings.model_fields["public_url"].default:
        os.environ["DEXLABEL_PUBLIC_URL"] = f"http://{host}:{port}"
        get_settings.cache_clear()
    return get_settings()


class DemoServer:
    """The app served by uvicorn in a thread of this process (the demo's crowd runs meanwhile)."""

    def __init__(self, host: str, port: int) -> None:
        self.host, self.port = host, port
        self.server = None  # type: ignore[var-annotated]
        self.thread = None  # type: ignore[var-annotated]
        self.consumer = None  # type: ignore[var-annotated]

    def start(self, consumer: bool) -> None:
        import threading
        import time

        import uvicorn

        from backend.app import create_app
        from backend.queue import start_inprocess_consumer

        settings = get_settings()
        if consumer and settings.inprocess_worker and not settings.redis_url:
            self.consumer = start_inprocess_consumer(settings.worker_threads)
        config = uvicorn.Config(create_app(), host=self.host, port=self.port,
                                log_level="warning")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise DexlabelError(f"the server did not start on {self.host}:{self.port}")
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
        if self.server is not None:
            self.server.should_exit = True
        if self.thread is not None:
            self.thread.join(timeout=30)
        if self.consumer is not None:
            self.consumer.stop(graceful=True)


def demo_crowd(sequence_id: int, capture: Path, password: str, assignments: int,
                workers: int | None, simulate_: bool) -> None:
    """Publish the sequence's tasks (hand tasks first, so they are offered first), let the
    simulated crowd work unless the demo already has submissions, and sync them."""
    from backend.crowd import flows
    from backend.crowd.client import make_client
    from backend.crowd.schemas import PublishOptions
    from backend.crowd.simulate import simulate
    from backend.crowd.sync import sync
    from backend.db import session_scope

    client = make_client(get_settings())
    options = PublishOptions(max_assignments=assignments)
    for kind in ("hand", "object"):
        result = flows.publish_each(client, options, sequence_id, kind)
        typer.echo(f"{kind} tasks: {result.created} HITs created, {result.recovered} "
                   f"recovered, {_demo_hits(sequence_id, kind)} published in all")
    done, hand_tasks = _demo_counts(sequence_id)
    if not simulate_ or done:
        typer.echo(f"simulated crowd skipped: {done} submissions already in the demo"
                   if simulate_ else "simulated crowd skipped (--no-simulate)")
        return
    count = workers or assignments * hand_tasks
    typer.echo(f"{count} simulated workers (mixed profiles) at work ...")
    outcomes = simulate(get_settings().public_url, capture, count, "mixed",
                        DEMO_ADMIN_EMAIL, password, seed=7)
    for o in outcomes:
        typer.echo(f"  {o.worker_id} {o.profile:9s} {o.status:17s} HIT {o.hit_id or '-'} "
                   f"task {o.task_id or '-'}")
    with session_scope() as session:
        synced = sync(session, client)
    done, _ = _demo_counts(sequence_id)
    typer.echo(f"{sum(o.status == 'submitted' for o in outcomes)} of {len(outcomes)} "
               f"simulated workers submitted; {synced.accepted} submissions synced; "
               f"{done} submissions in the demo")
    typer.echo("quality checks are queued for every target with submissions: see "
               f"`dexlabel qc reports {sequence_id}`, `dexlabel jobs list` or /api/qc/reports")


def _demo_hits(sequence_id: int, kind: str) -> int:
    from sqlalchemy import func, select

    from backend.annotation.models import Task
    from backend.crowd.models import CrowdHit
    from backend.db import session_scope

    with session_scope() as session:
        return int(session.scalar(
            select(func.count()).select_from(CrowdHit).join(Task, Task.id == CrowdHit.task_id)
            .where(Task.sequence_id == sequence_id, Task.kind == kind,
                   CrowdHit.hit_id.is_not(None))) or 0)


def _demo_counts(sequence_id: int) -> tuple[int, int]:
    """(submitted assignments, hand tasks) of the demo sequence."""
    from sqlalchemy import func, select

    from backend.annotation.models import Assignment, Task
    from backend.db import session_scope

    with session_scope() as session:
        done = session.scalar(select(func.count()).select_from(Assignment)
                              .join(Task, Task.id == Assignment.task_id)
                              .where(Task.sequence_id == sequence_id,
                                     Assignment.status != "working"))
        hands = session.scalar(select(func.count()).select_from(Task).where(
            Task.sequence_id == sequence_id, Task.kind == "hand"))
    return int(done or 0), int(hands or 0)


def demo_print(seq, base: str, password: str, annotate: str,  # type: ignore[no-untyped-def]
                preview: str) -> None:
    base = base.rstrip("/")
    typer.echo(f"\nsequence {seq.subject}/{seq.name} (id {seq.sequence_id}): "
               f"{seq.num_cameras} cameras x {seq.num_frames} frames")
    typer.echo(f"API docs:        {base}/docs")
    typer.echo(f"health:          {base}/healthz")
    typer.echo(f"sequences:       {base}/api/sequences  (admin bearer token)")
    typer.echo(f"admin login:     POST {base}/api/auth/token  email={DEMO_ADMIN_EMAIL} "
               f"password={password}")
    typer.echo(f"costs:           {base}/api/crowd/costs  (or: dexlabel crowd costs)")
    typer.echo(f"first view:      {base}{_demo_view_url(seq.sequence_id)}")
    typer.echo(f"annotate (hand): {annotate}")
    typer.echo(f"HIT preview:     {preview}")


def demo_admin() -> str:
    """(Re)set the demo admin's password and return it."""
    from backend.accounts.service import create_admin as create
    from backend.db import session_scope

    password = secrets.token_urlsafe(12)
    with session_scope() as session:
        create(session, DEMO_ADMIN_EMAIL, password, reset=True)
    return password


def demo_annotation_links(sequence_id: int, base: str) -> tuple[str, str]:
    """Tasks for the demo sequence, and page links for the first hand task: a demo worker's
    assignment, and the read-only preview a worker sees before accepting a HIT."""
    from urllib.parse import urlencode

    from backend.annotation import service
    from backend.annotation.router import PREVIEW_ASSIGNMENT_ID, assignment_token, task_token
    from backend.db import session_scope
    from backend.storage import get_storage

    with session_scope() as session:
        tasks = service.create_tasks(session, get_storage(), sequence_id)
        task = service.get_task_or_raise(session, next(t.id for t in tasks if t.kind == "hand"))
        assignment = next((a for a in task.assignments if a.worker_id == "demo-worker"), None)
        if assignment is None:
            assignment = service.create_assignment(session, task, "demo-worker")
        work = {"token": assignment_token(task, assignment),
                "assignmentId": assignment.external_id, "workerId": assignment.worker_id}
        look = {"token": task_token(task), "assignmentId": PREVIEW_ASSIGNMENT_ID}
    return f"{base}/annotate/?{urlencode(work)}", f"{base}/annotate/?{urlencode(look)}"


def _demo_view_url(sequence_id: int) -> str:
    from backend.accounts.deps import VIEW_SCOPE
    from backend.captures.service import get_sequence_or_raise
    from backend.db import session_scope
    from backend.security import sign_token

    with session_scope() as session:
        serial = get_sequence_or_raise(session, sequence_id).cameras[0].serial
    token = sign_token({"scope": VIEW_SCOPE, "sequence_id": sequence_id, "serial": serial},
                       get_settings().secret_key, 7 * 24 * 3600)
    return f"/api/sequences/{sequence_id}/views/{serial}/frames?token={token}"
