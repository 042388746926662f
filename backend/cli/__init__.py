"""The `dexlabel` command line.

Every command but ``migrate``, ``synth``, ``demo`` and ``prelabel`` works on an instance:
before it runs, a migrated database must be where the settings point (``DEXLABEL_VAR_DIR``),
or the command stops with one line saying so, creating nothing. Bad input is refused the same
way everywhere (backend.cli.console: ``error: ...``, exit 2), and sequences are named by id or
SUBJECT/NAME.
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import typer
from typer.core import TyperGroup

from backend.cli.console import fail, progress, refusing_bad_input
from backend.config import get_settings, keep_instance_private
from backend.instance import (
    adopt_recorded_server,
    client_url,
    forget_server,
    record_server,
    refuse_second_server,
    require_database,
    serve_at,
)

if TYPE_CHECKING:
    from backend.crowd.simulate import Protocol

# Commands that make their own instance (or none) instead of needing one.
NO_INSTANCE = frozenset({"migrate", "synth", "demo", "prelabel"})
# Commands that run for long and find the server's address each time they need it.
LONG_RUNNING = frozenset({"serve", "worker"})
_ARGS = "dexlabel.args"


class _Commands(TyperGroup):
    """The root group; it keeps the arguments after the command name, so the instance check
    can let ``--help`` through."""

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        ctx.meta[_ARGS] = tuple(args)
        return super().resolve_command(ctx, args)


# Plain help (rich_markup_mode=None on every group): it wraps to the terminal, never cuts an
# option's name, and shows no type on a flag.
app = typer.Typer(cls=_Commands,
                  help="dexlabel: crowd-labelled multi-view video to 3D hand and object poses.",
                  no_args_is_help=True, rich_markup_mode=None, add_completion=False,
                  pretty_exceptions_enable=False)


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
    keep_instance_private(get_settings().var_dir)
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
    keep_instance_private(get_settings().var_dir)
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
        metavar="FAULT",
        help="rig fault the product reads, truth unchanged (repeatable or a comma list): "
             "extrinsics:DEG,MM, late:N, depth-scale:S, depth-shift:LO-HI, betas[:SIGMA]; "
             "see worker/synth/faults.py")] = None,
    fault_seed: Annotated[int, typer.Option(min=0, help="seed of the faults' choices")] = 0,
    forearm: Annotated[bool, typer.Option(
        "--forearm", help="draw a forearm and sleeve from the wrist (closer to real footage, "
                          "for hand detectors); the truth is unchanged")] = False,
    varied_light: Annotated[bool, typer.Option(
        "--varied-light", help="a room's light drawn from the seed (more ambient light, the "
                               "lamp anywhere above) instead of the fixed one")] = False,
) -> None:
    """Write a synthetic capture and its ground-truth labels.

    The capture has DexYCB's raw layout; its folder must be new or empty."""
    from worker.synth import generate_capture
    from worker.synth.faults import parse_faults

    try:
        faults = parse_faults(fault or [])
        # Refused before any work is announced (generate_capture checks it again).
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise FileExistsError(f"{out} exists and is not an empty folder; give a new one")
        clean = out.with_name(out.name + ".clean") if faults else out
        with progress(f"synthesising {views} views x {frames} frames") as step:
            summary = generate_capture(clean, seed=seed, frames=frames, views=views,
                                       objects=objects, forearm=forearm,
                                       varied_light=varied_light)
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
    """Import a capture (DexYCB layout, or a video per camera)."""
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
# With --workers N, uvicorn's supervisor pings every server process each half second and kills
# one that does not answer within this many seconds, also while it starts. uvicorn's 5 s is
# less than a process's start (interpreter, uvicorn, then the app in a thread beside the one
# that answers) takes on a loaded machine: starting children were killed 8-17 times in a row.
WORKER_HEALTH_TIMEOUT_S = 30


@app.command()
def serve(
    host: Annotated[str, typer.Option()] = "127.0.0.1",
    port: Annotated[int, typer.Option()] = 8000,
    workers: Annotated[int, typer.Option(
        min=1, max=64, help="server processes sharing the port (PostgreSQL only)")] = 1,
) -> None:
    """Run the API and pages.

    On the embedded default it runs a queue consumer too. The address is recorded in the
    instance for the other commands. --workers N serves from N processes, which needs
    PostgreSQL: SQLite takes one writer at a time, and only the writers of one process wait
    their turn (the others would fail on a locked file)."""
    import uvicorn

    from backend.jobs.consumer import start_inprocess_consumer
    from backend.server_process import KEEP_ALIVE_S
    from worker.tasks import register_handlers

    settings = serve_at(host, port)
    if workers > 1 and settings.is_sqlite:
        fail(f"--workers {workers} needs PostgreSQL (DEXLABEL_DATABASE_URL): the embedded SQLite "
             "database takes one writer at a time, so it is served by one process; run "
             "without --workers, or point DEXLABEL_DATABASE_URL at PostgreSQL")
    with refusing_bad_input():  # one server per instance: refused before anything starts
        record_server(settings, client_url(host, port))
    consumer = None
    if settings.inprocess_worker and not settings.redis_url:
        register_handlers()
        consumer = start_inprocess_consumer(settings.worker_threads)
    # uvicorn stops on SIGINT/SIGTERM, then raises the signal again for the handler it found:
    # this one ends the process through the ``finally`` below, so the record is removed. With
    # several processes, uvicorn's supervisor stops them and returns instead.
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _exit_cleanly)
    try:
        uvicorn.run("backend.app:create_served_app", factory=True, host=host, port=port,
                    workers=workers, timeout_graceful_shutdown=SHUTDOWN_GRACE_S,
                    timeout_worker_healthcheck=WORKER_HEALTH_TIMEOUT_S,
                    timeout_keep_alive=KEEP_ALIVE_S,
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
    from backend.jobs.consumer import make_consumer
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
    protocol: Annotated[Literal["keyframes", "assisted", "every-frame"], typer.Option(
        help="how the simulated crowd labels: keyframes (a keyframe every few frames), "
             "assisted (with the page's tracking and suggestions) or every-frame "
             "(DexYCB's: every point on every frame)")] = "keyframes",
    crowd_seed: Annotated[int, typer.Option(
        min=0, max=1_000_000, help="the simulated crowd's draw (its profiles and noise); "
                                   "0 is the demo's own")] = 0,
) -> None:
    """A demo instance: a capture, a simulated crowd, a solve.

    Migrate, synthesise a capture if none, import it, publish its tasks on the built-in
    marketplace, start the server, let a simulated crowd (mixed profiles) work until every
    task has accepted work, wait for the quality checks and the solve, print the links with
    ready logins, and keep serving. Re-running adds nothing that is already there."""
    import time

    from backend import demo as d
    from backend.demo import report

    started = time.perf_counter()
    settings = serve_at(host, port)
    with refusing_bad_input():  # one server per instance, checked before the slow work
        refuse_second_server(settings)
    keep_instance_private(settings.var_dir)
    seq, capture = _demo_capture(settings.var_dir / "demo-capture", settings.database_url,
                                 frames, views, objects)
    with refusing_bad_input():
        logins = d.demo_logins()
        annotate = d.demo_annotation_link(seq.sequence_id, settings.public_url)
    server = d.DemoServer(host, port)
    try:
        with refusing_bad_input():
            _demo_work(server, seq.sequence_id, capture, logins["admin"], assignments,
                       workers, simulate_, protocol, crowd_seed)
            report.demo_print(seq, settings.public_url, logins, annotate)
            typer.echo(f"{report.demo_summary(seq.sequence_id)} (demo ready in "
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


def _demo_capture(capture: Path, database_url: str, frames: int, views: int,
                  objects: int) -> tuple[Any, Path]:
    """The demo's migrated database and imported capture (synthesised first if there is
    none): (the import's result, the capture's folder)."""
    from backend import migrate as m

    m.upgrade(database_url)
    if not any(capture.glob("*/*/meta.yml")):
        synth(capture, seed=7, frames=frames, views=views, objects=objects)
    return _import(capture)[0], capture


def _demo_work(server: Any, sequence_id: int, capture: Path, admin_login: Any,
               assignments: int, workers: int | None, simulate: bool,
               protocol: Protocol = "keyframes", crowd_seed: int = 0) -> None:
    """Start the demo's server, publish, let the simulated crowd work (and come back for the
    views a solve publishes under the adaptive policy), leave a hand HIT open in the worker
    portal for the demo worker, wait for the quality checks and the solve (when this process
    runs a queue consumer)."""
    from backend import demo as d
    from backend.demo.portal_hit import leave_hand_hit

    server.start()
    d.demo_publish(sequence_id, assignments)
    if simulate and server.has_consumer:
        d.demo_until_solved(sequence_id, capture, admin_login, workers, protocol=protocol,
                            crowd_seed=crowd_seed)
    elif simulate:
        d.demo_crowd(sequence_id, capture, admin_login, workers, False, protocol=protocol,
                     crowd_seed=crowd_seed)
    leave_hand_hit(sequence_id)
    if server.has_consumer:
        d.wait_for_jobs()
        d.wait_for_solve(sequence_id)
    else:
        typer.echo("no queue consumer here: quality checks wait for `dexlabel worker`")


def _register_crowd_commands() -> None:
    from backend.cli.crowd import crowd_app, publish_command, tasks_app

    app.add_typer(tasks_app, name="tasks")
    app.command("publish")(publish_command)
    app.add_typer(crowd_app, name="crowd")


_register_crowd_commands()


def _register_domain_commands() -> None:
    from backend.cli.captures import sequences_app
    from backend.cli.exports import export_command
    from backend.cli.jobs import jobs_app
    from backend.cli.prelabel import prelabel_command
    from backend.cli.quality import qc_app, training_app
    from backend.cli.rig import rig_app
    from backend.cli.solve import calibrate_hand_command, solve_command
    from backend.cli.status import status_command

    app.command("status")(status_command)
    app.command("solve")(solve_command)
    app.command("calibrate-hand")(calibrate_hand_command)
    app.command("export")(export_command)
    app.command("prelabel")(prelabel_command)
    app.add_typer(qc_app, name="qc")
    app.add_typer(jobs_app, name="jobs")
    app.add_typer(training_app, name="training")
    app.add_typer(sequences_app, name="sequences")
    app.add_typer(rig_app, name="rig")


_register_domain_commands()
