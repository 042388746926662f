"""The `dexlabel` command line.

Every command but ``migrate``, ``synth`` and ``demo`` works on an instance: before it runs, a
migrated database must be where the settings point (``DEXLABEL_VAR_DIR``), or the command
stops with one line saying so, creating nothing. Bad input is refused the same way everywhere
(backend.cli.console: ``error: ...``, exit 2), and sequences are named by id or SUBJECT/NAME.
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from backend.cli.console import SequenceArg, fail, progress, refusing_bad_input, resolve_sequence
from backend.config import get_settings
from backend.instance import (
    adopt_recorded_server,
    client_url,
    forget_server,
    record_server,
    require_database,
    serve_at,
)

# Commands that make their own instance (or none) instead of needing one.
NO_INSTANCE = frozenset({"migrate", "synth", "demo"})
# Commands that run for long and find the server's address each time they need it.
LONG_RUNNING = frozenset({"serve", "worker"})
_ARGS = "dexlabel.args"


class _Commands(TyperGroup):
    """The root group; it keeps the arguments after the command name, so the instance check
    can let ``--help`` through."""

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        ctx.meta[_ARGS] = tuple(args)
        return super().resolve_command(ctx, args)


app = typer.Typer(cls=_Commands,
                  help="dexlabel: crowd-labelled multi-view video to 3D hand and object poses.",
                  no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False)


def _asks_for_help(ctx: typer.Context) -> bool:
    args = ctx.meta.get(_ARGS, ())
    command = ctx.command.get_command(ctx, ctx.invoked_subcommand or "")  # type: ignore[attr-defined]
    return "--help" in args or (isinstance(command, TyperGroup) and len(args) <= 1)


@app.callback()
def _instance(ctx: typer.Context) -> None:
    if ctx.resilient_parsing or ctx.invoked_subcommand in NO_INSTANCE or _asks_for_help(ctx):
        return
    with refusing_bad_input():
        require_database(get_settings())
    if ctx.invoked_subcommand not in LONG_RUNNING:
        adopt_recorded_server()


@app.command()
def migrate(
    to: Annotated[str, typer.Option(help="target revision ('head', or an id)")] = "head",
    down: Annotated[bool, typer.Option("--down", help="downgrade to --to (e.g. base)")] = False,
) -> None:
    """Create or update the database schema (Alembic migrations)."""
    from sqlalchemy.engine import make_url

    from backend import migrate as m

    url = get_settings().database_url
    (m.downgrade if down else m.upgrade)(url, to)
    typer.echo(f"database at {to} ({make_url(url).render_as_string(hide_password=True)})")


@app.command()
def synth(
    out: Annotated[Path, typer.Argument(help="folder to write the capture to")],
    seed: Annotated[int, typer.Option(help="random seed; same seed, same bytes")] = 0,
    frames: Annotated[int, typer.Option(min=2, max=10000)] = 72,
    views: Annotated[int, typer.Option(min=1, max=64)] = 8,
    objects: Annotated[int, typer.Option(min=1, max=10)] = 3,
    fault: Annotated[list[str] | None, typer.Option(
        help="rig fault the product reads, truth unchanged (repeatable or a comma list): "
             "extrinsics:DEG,MM, late:N, depth-scale:S, depth-shift:LO-HI, betas[:SIGMA]; "
             "see worker/synth/faults.py")] = None,
    fault_seed: Annotated[int, typer.Option(min=0, help="seed of the faults' choices")] = 0,
) -> None:
    """Write a synthetic capture (DexYCB layout) with its ground-truth labels."""
    from worker.synth import generate_capture
    from worker.synth.faults import parse_faults

    try:
        faults = parse_faults(fault or [])
        if faults and out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise FileExistsError(f"{out} exists and is not an empty folder")
        clean = out.with_name(out.name + ".clean") if faults else out
        with progress(f"synthesising {views} views x {frames} frames") as step:
            summary = generate_capture(clean, seed=seed, frames=frames, views=views,
                                       objects=objects)
            step(f"{summary.subject}/{summary.sequence}")
        if faults:
            _with_faults(clean, out, faults, fault_seed)
    except (FileExistsError, ValueError) as exc:
        fail(str(exc))
    typer.echo(f"wrote {summary.subject}/{summary.sequence}: {len(summary.serials)} views x "
               f"{summary.num_frames} frames, objects {summary.ycb_ids} -> {out}")


def _with_faults(clean: Path, out: Path, faults: list[Any], seed: int) -> None:
    """The faulty copy of the capture at ``clean`` written to ``out``; ``clean`` removed."""
    import shutil

    from worker.synth.faults import inject_faults

    try:
        with progress(f"injecting {', '.join(f.name for f in faults)}") as step:
            record = inject_faults(clean, out, faults, seed=seed)
            step(", ".join(sorted(record.get("cameras", {}))) or "calibration")
    finally:
        shutil.rmtree(clean, ignore_errors=True)


def _import(path: Path) -> list[Any]:
    from backend.captures.flows import import_path

    with refusing_bad_input(), progress(f"importing {path}") as step:
        results = import_path(path)
        for r in results:
            step(f"{r.subject}/{r.name}")
    for r in results:
        if r.created:
            state = "imported"
        elif r.repaired:
            state = f"already imported, {r.repaired} missing stored files written again:"
        else:
            state = "already imported, unchanged:"
        typer.echo(f"{state} {r.subject}/{r.name} (id {r.sequence_id}): "
                   f"{r.num_cameras} cameras x {r.num_frames} frames")
    return results


@app.command("import")
def import_(
    path: Annotated[Path, typer.Argument(help="capture root or one sequence folder")],
) -> None:
    """Import a capture (DexYCB raw layout, or one video per camera)."""
    _import(path)


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
    with refusing_bad_input(), session_scope() as session:
        admin = create(session, email, password, reset=reset)
        typer.echo(f"admin {admin.email} ready (id {admin.id})")


# A stopping server finishes the requests it has for at most this long (every database wait
# of a request is bounded by DEXLABEL_DB_WAIT_S), then closes what is left.
SHUTDOWN_GRACE_S = 15


@app.command()
def serve(
    host: Annotated[str, typer.Option()] = "127.0.0.1",
    port: Annotated[int, typer.Option()] = 8000,
    workers: Annotated[int, typer.Option(
        min=1, max=64, help="server processes sharing the port (PostgreSQL only)")] = 1,
) -> None:
    """Run the API and pages (plus an in-process queue consumer on the embedded default);
    the address is recorded in the instance for the other commands. ``--workers N`` serves
    from N processes, which needs PostgreSQL: SQLite takes one writer at a time, and only
    the writers of one process wait their turn (the others would fail on a locked file)."""
    import uvicorn

    from backend.jobs.runner import start_inprocess_consumer
    from worker.tasks import register_handlers

    settings = serve_at(host, port)
    if workers > 1 and settings.is_sqlite:
        fail(f"--workers {workers} needs PostgreSQL (DEXLABEL_DATABASE_URL): the embedded SQLite "
             "database takes one writer at a time, so it is served by one process; run "
             "without --workers, or point DEXLABEL_DATABASE_URL at PostgreSQL")
    consumer = None
    if settings.inprocess_worker and not settings.redis_url:
        register_handlers()
        consumer = start_inprocess_consumer(settings.worker_threads)
    record_server(settings, client_url(host, port))
    # uvicorn stops on SIGINT/SIGTERM, then raises the signal again for the handler it found:
    # this one ends the process through the ``finally`` below, so the record is removed. With
    # several processes, uvicorn's supervisor stops them and returns instead.
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _exit_cleanly)
    try:
        uvicorn.run("backend.app:create_served_app", factory=True, host=host, port=port,
                    workers=workers, timeout_graceful_shutdown=SHUTDOWN_GRACE_S,
                    # The client address behind a proxy is DEXLABEL_TRUSTED_PROXIES' business
                    # (backend.accounts.limits.client_address), not uvicorn's loopback default.
                    proxy_headers=False)
    finally:
        forget_server(settings)
        if consumer is not None:
            consumer.stop(graceful=True)


def _exit_cleanly(_signum: int, _frame: object) -> None:
    raise SystemExit(0)


@app.command()
def worker(
    workers: Annotated[int, typer.Option(min=1, max=64, help="worker threads")] = 2,
) -> None:
    """Run a queue consumer (one per machine when scaling out)."""
    from backend.jobs.runner import make_consumer
    from worker.tasks import register_handlers

    settings = get_settings()
    register_handlers()
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
        min=1, max=1000, help="simulated workers per round (default: one per open "
                              "assignment)")] = None,
    simulate_: Annotated[bool, typer.Option(
        "--simulate/--no-simulate", help="fill the demo with simulated submissions")] = True,
) -> None:
    """Migrate, synthesise a capture if none, import it, publish its tasks on the built-in
    marketplace, start the server, let a simulated crowd (mixed profiles) work until every
    task has accepted work, wait for the quality checks and the solve, print the links with
    ready logins, and keep serving. Re-running adds nothing that is already there."""
    import time

    from backend import demo as d
    from backend import migrate as m

    started = time.perf_counter()
    settings = serve_at(host, port)
    m.upgrade(settings.database_url)
    capture = settings.var_dir / "demo-capture"
    if not any(capture.glob("*/*/meta.yml")):
        synth(capture, seed=7, frames=frames, views=views, objects=objects)
    seq = _import(capture)[0]
    with refusing_bad_input():
        logins = d.demo_logins()
        annotate = d.demo_annotation_link(seq.sequence_id, settings.public_url)
    server = d.DemoServer(host, port)
    try:
        with refusing_bad_input():
            server.start()
            d.demo_publish(seq.sequence_id, assignments)
            if simulate_:
                d.demo_crowd(seq.sequence_id, capture, logins["admin"], workers,
                             server.has_consumer)
            if server.has_consumer:
                d.wait_for_jobs()
                d.wait_for_solve(seq.sequence_id)
            else:
                typer.echo("no queue consumer here: quality checks wait for `dexlabel worker`")
            d.demo_print(seq, settings.public_url, logins, annotate)
            typer.echo(f"{d.demo_summary(seq.sequence_id)} (demo ready in "
                       f"{time.perf_counter() - started:.0f} s)")
        if serve_:
            typer.echo(f"serving at {settings.public_url}; Ctrl+C stops")
            sys.stdout.flush()
            server.wait()
        else:
            typer.echo(f"--no-serve: nothing is being served now; `dexlabel serve --port {port}` "
                       "serves these links")
    finally:
        server.stop()


tasks_app = typer.Typer(help="Annotation tasks (sequence x view x target).", no_args_is_help=True)
app.add_typer(tasks_app, name="tasks")


@tasks_app.command("create")
def tasks_create(sequence: SequenceArg) -> None:
    """Create one task per view and target of a sequence (idempotent)."""
    from backend.annotation.service import create_tasks
    from backend.db import session_scope
    from backend.storage import get_storage

    with refusing_bad_input(), session_scope() as session:
        tasks = create_tasks(session, get_storage(), resolve_sequence(session, sequence))
        hands = sum(t.kind == "hand" for t in tasks)
        typer.echo(f"{len(tasks)} tasks: {hands} hand, {len(tasks) - hands} object "
                   f"(ids {tasks[0].id}-{tasks[-1].id})")


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
        fail("; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors()))


@app.command()
def publish(
    sequence: Annotated[str | None, typer.Option(help="sequence id or SUBJECT/NAME")] = None,
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
    from backend.crowd import flows
    from backend.crowd.client import make_client
    from backend.db import session_scope

    options = _publish_options(reward, assignments, allow_large_hits, round_, min_approval_rate,
                               require_training)
    with refusing_bad_input():
        with session_scope() as session:
            sequence_id = resolve_sequence(session, sequence) if sequence else None
            plan = flows.plan(session, options, sequence_id)
        c = plan.cost
        typer.echo(f"{c.hits} HITs x {c.assignments_per_hit} assignment(s) at ${c.reward} "
                   f"(+ ${c.fee_per_assignment} fee each): rewards ${c.rewards} + fees ${c.fees}"
                   f" = ${c.total}")
        if dry_run:
            typer.echo("dry run: nothing published")
            return
        with progress(f"publishing {c.hits} HITs") as step:
            result = flows.publish_each(make_client(get_settings()), options, sequence_id)
            step(f"{result.created} created")
        typer.echo(f"published: {result.created} created, {result.recovered} recovered, "
                   f"{result.already_published} already published")


crowd_app = typer.Typer(help="The crowd: HITs on the MTurk endpoint.", no_args_is_help=True)
app.add_typer(crowd_app, name="crowd")


@crowd_app.command("sync")
def crowd_sync() -> None:
    """Collect submitted assignments, check them against the requester API's records, and
    queue the quality check of each new one."""
    from backend.crowd.client import make_client
    from backend.db import session_scope
    from backend.pipeline import sync

    with refusing_bad_input(), session_scope() as session:
        result = sync(session, make_client(get_settings()))
    typer.echo(f"{result.hits} HITs: {result.accepted} new submissions accepted, "
               f"{result.already_accepted} known, {len(result.mismatched)} refused "
               f"(HIT or worker mismatch), {len(result.unknown)} unknown")
    for assignment_id in result.mismatched:
        typer.echo(f"refused {assignment_id}: HIT or worker differs from our record")


_COST_COLUMNS = ("spent_rewards", "spent_bonuses", "spent_fees", "spent",
                 "committed_rewards", "committed_bonuses", "committed_fees", "committed")


def _cost_row(label: str, line: Any) -> str:
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
        named = f" {line.name}" if line.name and line.name != f"sequence {line.key}" else ""
        typer.echo(_cost_row(f"sequence {line.key}{named}", line))
    for line in report.by_worker:
        typer.echo(_cost_row(f"worker {line.key}", line))


@crowd_app.command("bonus")
def crowd_bonus(
    assignment: Annotated[int, typer.Argument(help="our assignment id")],
    amount: Annotated[str, typer.Argument(help="US dollars, more than 0, e.g. 1.00")],
    reason: Annotated[str, typer.Option(help="what the worker reads")],
    key: Annotated[str, typer.Option(help="names this bonus: one key pays once")] = "1",
) -> None:
    """Pay a bonus once (ledger row committed before the payment; safe to re-run)."""
    from backend.crowd import flows, pricing
    from backend.crowd.client import make_client

    try:
        cents = pricing.dollars_to_cents(amount)
    except (ValueError, ArithmeticError):  # decimal's InvalidOperation for "abc"
        cents = -1
    if cents <= 0:
        fail(f"a bonus is a dollar amount in whole cents above 0, like 1.00 (got {amount!r})")
    with refusing_bad_input():
        paid = flows.pay_bonus(make_client(get_settings()), assignment, cents, reason, key)
    state = "already paid" if paid.already_done else "paid"
    typer.echo(f"bonus {key!r} of assignment {assignment} {state}: ${paid.amount} "
               f"(+ ${paid.fee} fee) to {paid.worker_id}")


@crowd_app.command("simulate")
def crowd_simulate(
    capture: Annotated[Path, typer.Option(help="synthetic capture with the ground truth")],
    workers: Annotated[int, typer.Option(min=1, max=1000)] = 5,
    profile: Annotated[str, typer.Option(
        help="mixed, careful, sloppy, swapper, lazy, spammer or occluder")] = "mixed",
    base: Annotated[str | None, typer.Option(
        help="the app's URL (default: PUBLIC_URL, or this instance's running server)")] = None,
    admin_email: Annotated[str | None, typer.Option(envvar="DEXLABEL_ADMIN_EMAIL")] = None,
    admin_password: Annotated[str | None, typer.Option(envvar="DEXLABEL_ADMIN_PASSWORD")] = None,
    seed: Annotated[int, typer.Option(help="random seed of profiles and labels")] = 0,
    first: Annotated[int, typer.Option(min=1, help="number of the first simulated worker")] = 1,
) -> None:
    """Simulated workers accept, label and submit HITs through the portal, over HTTP."""
    from backend.crowd.simulate import simulate

    if not admin_email or not admin_password:
        fail("give --admin-email and --admin-password (an admin of the app)")
    try:
        with refusing_bad_input():
            outcomes = simulate(base or get_settings().public_url, capture, workers, profile,
                                admin_email, admin_password, seed, first_index=first)
    except ValueError as exc:
        fail(str(exc))
    for o in outcomes:
        typer.echo(f"{o.worker_id} {o.profile:9s} {o.status:17s} HIT {o.hit_id or '-'} "
                   f"assignment {o.assignment_id or '-'} task {o.task_id or '-'}")
    done = sum(o.status == "submitted" for o in outcomes)
    typer.echo(f"{done} of {len(outcomes)} simulated workers submitted")


def _register_domain_commands() -> None:
    from backend.cli.captures import sequences_app
    from backend.cli.exports import export_command
    from backend.cli.jobs import jobs_app
    from backend.cli.progress import status_command
    from backend.cli.quality import qc_app, training_app
    from backend.cli.rig import rig_app
    from backend.cli.solve import calibrate_hand_command, solve_command

    app.command("status")(status_command)
    app.command("solve")(solve_command)
    app.command("calibrate-hand")(calibrate_hand_command)
    app.command("export")(export_command)
    app.add_typer(qc_app, name="qc")
    app.add_typer(jobs_app, name="jobs")
    app.add_typer(training_app, name="training")
    app.add_typer(sequences_app, name="sequences")
    app.add_typer(rig_app, name="rig")


_register_domain_commands()
