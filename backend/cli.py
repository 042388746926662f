"""The `dexlabel` command line."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from backend.config import get_settings
from backend.errors import DexlabelError

app = typer.Typer(help="dexlabel: crowd-labelled multi-view video to 3D hand and object poses.",
                  no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False)


def _fail(exc: DexlabelError) -> None:
    typer.secho(f"error: {exc.detail}", fg=typer.colors.RED, err=True)
    raise typer.Exit(2)


@app.command()
def migrate(
    to: Annotated[str, typer.Option(help="target revision ('head', or an id)")] = "head",
    down: Annotated[bool, typer.Option("--down", help="downgrade to --to (e.g. base)")] = False,
) -> None:
    """Create or update the database schema (Alembic migrations)."""
    from backend import migrate as m

    url = get_settings().database_url
    (m.downgrade if down else m.upgrade)(url, to)
    typer.echo(f"database at {to} ({_safe_url(url)})")


def _safe_url(url: str) -> str:
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)


@app.command()
def synth(
    out: Annotated[Path, typer.Argument(help="folder to write the capture to")],
    seed: Annotated[int, typer.Option(help="random seed; same seed, same bytes")] = 0,
    frames: Annotated[int, typer.Option(min=2, max=10000)] = 72,
    views: Annotated[int, typer.Option(min=1, max=64)] = 8,
    objects: Annotated[int, typer.Option(min=1, max=10)] = 3,
) -> None:
    """Write a synthetic capture (DexYCB layout) with its ground-truth labels."""
    from worker.synth import generate_capture

    summary = generate_capture(out, seed=seed, frames=frames, views=views, objects=objects)
    typer.echo(f"wrote {summary.subject}/{summary.sequence}: {len(summary.serials)} views x "
               f"{summary.num_frames} frames, objects {summary.ycb_ids} -> {out}")


@app.command("import")
def import_(path: Annotated[Path, typer.Argument(help="capture root or one sequence folder")]) -> None:
    """Import a capture (DexYCB raw layout, or one video per camera)."""
    from backend.captures.flows import import_path

    try:
        results = import_path(path)
    except DexlabelError as exc:
        _fail(exc)
        return
    for r in results:
        state = "imported" if r.created else "already imported, unchanged:"
        typer.echo(f"{state} {r.subject}/{r.name} (id {r.sequence_id}): "
                   f"{r.num_cameras} cameras x {r.num_frames} frames")


@app.command("create-admin")
def create_admin(
    email: Annotated[str, typer.Argument()],
    password: Annotated[str | None, typer.Option(help="read from a prompt when not given")] = None,
    reset: Annotated[bool, typer.Option(help="set a new password for an existing admin")] = False,
) -> None:
    """Create an admin account (or reset its password)."""
    from backend.accounts.service import create_admin as create
    from backend.db import session_scope

    if password is None:
        password = typer.prompt("password", hide_input=True, confirmation_prompt=True)
    try:
        with session_scope() as session:
            admin = create(session, email, password, reset=reset)
            typer.echo(f"admin {admin.email} ready (id {admin.id})")
    except DexlabelError as exc:
        _fail(exc)


@app.command()
def serve(
    host: Annotated[str, typer.Option()] = "127.0.0.1",
    port: Annotated[int, typer.Option()] = 8000,
) -> None:
    """Run the API and pages (plus an in-process queue consumer on the embedded default)."""
    _serve(host, port)


def _serve(host: str, port: int) -> None:
    import uvicorn

    from backend.queue import start_inprocess_consumer

    settings = get_settings()
    consumer = None
    if settings.inprocess_worker and not settings.redis_url:
        consumer = start_inprocess_consumer(settings.worker_threads)
    try:
        uvicorn.run("backend.app:create_app", factory=True, host=host, port=port)
    finally:
        if consumer is not None:
            consumer.stop(graceful=True)


@app.command()
def worker(
    workers: Annotated[int, typer.Option(min=1, max=64, help="worker threads")] = 2,
) -> None:
    """Run a queue consumer (one per machine when scaling out)."""
    from backend.queue import make_consumer

    settings = get_settings()
    typer.echo(f"queue consumer on {'redis' if settings.redis_url else settings.queue_path}")
    make_consumer(workers).run()


@app.command()
def demo(
    host: Annotated[str, typer.Option()] = "127.0.0.1",
    port: Annotated[int, typer.Option()] = 8000,
    serve_: Annotated[bool, typer.Option(
        "--serve/--no-serve", help="keep serving when done (--no-serve: exit)")] = True,
    frames: Annotated[int, typer.Option(min=2, max=10000, help="frames of a new capture")] = 72,
    views: Annotated[int, typer.Option(min=1, max=64, help="views of a new capture")] = 8,
    objects: Annotated[int, typer.Option(min=1, max=10, help="objects of a new capture")] = 3,
    assignments: Annotated[int, typer.Option(min=1, max=9, help="assignments per HIT")] = 2,
    workers: Annotated[int | None, typer.Option(
        min=1, max=1000, help="simulated workers (default: assignments x hand tasks)")] = None,
    simulate_: Annotated[bool, typer.Option(
        "--simulate/--no-simulate", help="fill the demo with simulated submissions")] = True,
) -> None:
    """Migrate, synthesise a capture if none, import it, create and publish its tasks on the
    built-in marketplace, start the server, let a simulated crowd (mixed profiles) submit work,
    print it all, and keep serving. Re-running adds nothing that is already there."""
    from backend import migrate as m
    from backend.captures.flows import import_path
    from backend.demo import (
        DemoServer, demo_admin, demo_annotation_links, demo_crowd, demo_print, demo_settings,
    )

    settings = demo_settings(host, port)
    m.upgrade(settings.database_url)
    capture = settings.var_dir / "demo-capture"
    if not any(capture.glob("*/*/meta.yml")):
        typer.echo(f"synthesising a demo capture in {capture} ...")
        synth(capture, seed=7, frames=frames, views=views, objects=objects)
    try:
        seq = import_path(capture)[0]
        password = demo_admin()
        annotate, preview = demo_annotation_links(seq.sequence_id, settings.public_url)
    except DexlabelError as exc:
        _fail(exc)
        return
    server = DemoServer(host, port)
    try:
        server.start(consumer=serve_)
        demo_crowd(seq.sequence_id, capture, password, assignments, workers, simulate_)
        demo_print(seq, settings.public_url, password, annotate, preview)
        if serve_:
            typer.echo("serving; Ctrl+C stops")
            sys.stdout.flush()
            server.wait()
    except DexlabelError as exc:
        _fail(exc)
    finally:
        server.stop()


tasks_app = typer.Typer(help="Annotation tasks (sequence x view x target).", no_args_is_help=True)
app.add_typer(tasks_app, name="tasks")


def _resolve_sequence(session, ref: str) -> int:  # type: ignore[no-untyped-def]
    from backend.captures.service import find_sequence, get_sequence_or_raise

    if ref.isdigit():
        return get_sequence_or_raise(session, int(ref)).id
    subject, _, name = ref.partition("/")
    seq = find_sequence(session, subject, name) if name else None
    if seq is None:
        raise DexlabelError(f"no sequence {ref!r} (give an id or SUBJECT/SEQUENCE)")
    return seq.id


@tasks_app.command("create")
def tasks_create(
    sequence: Annotated[str, typer.Argument(help="sequence id or SUBJECT/SEQUENCE")],
) -> None:
    """Create one task per view and target of a sequence (idempotent)."""
    from backend.annotation.service import create_tasks
    from backend.db import session_scope
    from backend.storage import get_storage

    try:
        with session_scope() as session:
            tasks = create_tasks(session, get_storage(), _resolve_sequence(session, sequence))
            hands = sum(t.kind == "hand" for t in tasks)
            typer.echo(f"{len(tasks)} tasks: {hands} hand, {len(tasks) - hands} object "
                       f"(ids {tasks[0].id}-{tasks[-1].id})")
    except DexlabelError as exc:
        _fail(exc)


def _publish_options(  # type: ignore[no-untyped-def]
    reward: str, assignments: int, allow_large_hits: bool, round_: int,
    min_approval_rate: int | None, require_training: bool,
):
    from pydantic import ValidationError

    from backend.crowd.schemas import PublishOptions

    try:
        return PublishOptions(reward=reward, max_assignments=assignments,
                              allow_large_hits=allow_large_hits, round=round_,
                              min_approval_rate=min_approval_rate,
                              require_training=require_training)
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        _fail(DexlabelError(problems))


@app.command()
def publish(
    sequence: Annotated[str | None, typer.Option(help="sequence id or SUBJECT/SEQUENCE")] = None,
    dry_run: Annotated[bool, typer.Option(
        "--dry-run", help="print the cost, publish nothing")] = False,
    reward: Annotated[str, typer.Option(help="reward per assignment in US dollars")] = "0.50",
    assignments: Annotated[int, typer.Option(min=1, help="assignments per HIT")] = 1,
    allow_large_hits: Annotated[bool, typer.Option(
        "--allow-large-hits",
        help="allow 10+ assignments per HIT (MTurk fee 40%, not 20%)")] = False,
    round_: Annotated[int, typer.Option("--round", min=1, help="publishing round")] = 1,
    min_approval_rate: Annotated[int | None, typer.Option(min=0, max=100)] = 95,
    require_training: Annotated[bool, typer.Option(
        help="require our training qualification")] = False,
) -> None:
    """Publish one HIT per task not yet published in this round (safe to re-run)."""
    from backend.config import get_settings
    from backend.crowd import flows
    from backend.crowd.client import make_client
    from backend.db import session_scope

    options = _publish_options(reward, assignments, allow_large_hits, round_, min_approval_rate,
                               require_training)
    try:
        with session_scope() as session:
            sequence_id = _resolve_sequence(session, sequence) if sequence else None
            plan = flows.plan(session, options, sequence_id)
        c = plan.cost
        typer.echo(f"{c.hits} HITs x {c.assignments_per_hit} assignment(s) at ${c.reward} "
                   f"(+ ${c.fee_per_assignment} fee each): rewards ${c.rewards} + fees ${c.fees}"
                   f" = ${c.total}")
        if dry_run:
            typer.echo("dry run: nothing published")
            return
        result = flows.publish_each(make_client(get_settings()), options, sequence_id)
        typer.echo(f"published: {result.created} created, {result.recovered} recovered, "
                   f"{result.already_published} already published")
    except DexlabelError as exc:
        _fail(exc)


crowd_app = typer.Typer(help="The crowd: HITs on the MTurk endpoint.", no_args_is_help=True)
app.add_typer(crowd_app, name="crowd")


@crowd_app.command("sync")
def crowd_sync() -> None:
    """Collect submitted assignments and check them against the requester API's records."""
    from backend.config import get_settings
    from backend.crowd.client import make_client
    from backend.crowd.sync import sync
    from backend.db import session_scope

    try:
        with session_scope() as session:
            result = sync(session, make_client(get_settings()))
        typer.echo(f"{result.hits} HITs: {result.accepted} new submissions accepted, "
                   f"{result.already_accepted} known, {len(result.mismatched)} refused "
                   f"(HIT or worker mismatch), {len(result.unknown)} unknown")
        for assignment_id in result.mismatched:
            typer.echo(f"refused {assignment_id}: HIT or worker differs from our record")
    except DexlabelError as exc:
        _fail(exc)



_COST_COLUMNS = ("spent_rewards", "spent_bonuses", "spent_fees", "spent",
                 "committed_rewards", "committed_bonuses", "committed_fees", "committed")


def _cost_row(label: str, line) -> str:  # type: ignore[no-untyped-def]
    return f"{label:<32}" + "".join(f"{getattr(line, c):>10}" for c in _COST_COLUMNS)


@crowd_app.command("costs")
def crowd_costs() -> None:
    """Spend so far and money committed (US dollars): rewards, bonuses and fees apart, for the
    project, per sequence and per worker."""
    from backend.crowd.costs import costs
    from backend.db import session_scope

    with session_scope() as session:
        report = costs(session)
    typer.echo(f"{'':<32}{'--- spent ---':>40}{'--- committed ---':>40}")
    typer.echo(f"{'':<32}" + "".join(f"{h:>10}" for h in ("rewards", "bonuses", "fees",
                                                           "total") * 2))
    typer.echo(_cost_row("project", report.total))
    for line in report.by_sequence:
        typer.echo(_cost_row(f"sequence {line.key}", line))
    for line in report.by_worker:
        typer.echo(_cost_row(f"worker {line.key}", line))


@crowd_app.command("bonus")
def crowd_bonus(
    assignment: Annotated[int, typer.Argument(help="our assignment id")],
    amount: Annotated[str, typer.Argument(help="US dollars, e.g. 1.00")],
    reason: Annotated[str, typer.Option(help="what the worker reads")],
    key: Annotated[str, typer.Option(help="names this bonus: one key pays once")] = "1",
) -> None:
    """Pay a bonus once (ledger row committed before the payment; safe to re-run)."""
    from backend.crowd import flows, pricing
    from backend.crowd.client import make_client

    try:
        cents = pricing.dollars_to_cents(amount)
        paid = flows.pay_bonus(make_client(get_settings()), assignment, cents, reason, key)
    except ValueError as exc:
        _fail(DexlabelError(str(exc)))
        return
    except DexlabelError as exc:
        _fail(exc)
        return
    state = "already paid" if paid.already_done else "paid"
    typer.echo(f"bonus {key!r} of assignment {assignment} {state}: ${paid.amount} "
               f"(+ ${paid.fee} fee) to {paid.worker_id}")


@crowd_app.command("simulate")
def crowd_simulate(
    capture: Annotated[Path, typer.Option(help="synthetic capture with the ground truth")],
    workers: Annotated[int, typer.Option(min=1, max=1000)] = 5,
    profile: Annotated[str, typer.Option(
        help="mixed, careful, sloppy, swapper, lazy, spammer or occluder")] = "mixed",
    base: Annotated[str | None, typer.Option(help="the app's URL (default: PUBLIC_URL)")] = None,
    admin_email: Annotated[str | None, typer.Option(envvar="DEXLABEL_ADMIN_EMAIL")] = None,
    admin_password: Annotated[str | None, typer.Option(envvar="DEXLABEL_ADMIN_PASSWORD")] = None,
    seed: Annotated[int, typer.Option(help="random seed of profiles and labels")] = 0,
) -> None:
    """Simulated workers accept, label and submit HITs through the portal, over HTTP."""
    from backend.crowd.simulate import simulate

    try:
        if not admin_email or not admin_password:
            raise DexlabelError("give --admin-email and --admin-password (an admin of the app)")
        outcomes = simulate(base or get_settings().public_url, capture, workers, profile,
                            admin_email, admin_password, seed)
    except ValueError as exc:
        _fail(DexlabelError(str(exc)))
    except DexlabelError as exc:
        _fail(exc)
    for o in outcomes:
        typer.echo(f"{o.worker_id} {o.profile:9s} {o.status:17s} HIT {o.hit_id or '-'} "
                   f"assignment {o.assignment_id or '-'} task {o.task_id or '-'}")
    done = sum(o.status == "submitted" for o in outcomes)
    typer.echo(f"{done} of {len(outcomes)} simulated workers submitted")

def _register_domain_commands() -> None:
    from backend.jobs.cli import jobs_app
    from backend.quality.cli import qc_app, training_app
    from backend.solve.cli import calibrate_hand_command, solve_command

    app.command("solve")(solve_command)
    app.command("calibrate-hand")(calibrate_hand_command)
    app.add_typer(qc_app, name="qc")
    app.add_typer(jobs_app, name="jobs")
    app.add_typer(training_app, name="training")


_register_domain_commands()

if __name__ == "__main__":
    app()
