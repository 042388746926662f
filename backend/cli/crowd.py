"""Command-line functions of the crowd, registered on the main app by backend/cli/__init__.py:

    dexlabel tasks create SEQUENCE          one task per view and target
    dexlabel publish [--sequence S] [...]   publish tasks as HITs (--dry-run: the cost only)
    dexlabel crowd publish|sync|costs|bonus|simulate
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from backend.cli.console import SequenceArg, fail, progress, refusing_bad_input, resolve_sequence
from backend.config import get_settings

tasks_app = typer.Typer(help="Annotation tasks (sequence x view x target).",
                        no_args_is_help=True, rich_markup_mode=None)


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
    min_approval_rate: int | None, require_training: bool, provider: str | None = None,
    assignee: str | None = None, views: dict[str, Any] | None = None,
):
    from pydantic import ValidationError

    from backend.crowd.schemas import PublishOptions

    try:
        return PublishOptions(reward=reward, max_assignments=assignments,
                              allow_large_hits=allow_large_hits, round=round_,
                              min_approval_rate=min_approval_rate,
                              require_training=require_training, provider=provider,
                              assignee=assignee, **(views or {}))
    except ValidationError as exc:
        fail("; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors()))


def publish_command(
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
    provider: Annotated[str | None, typer.Option(
        help="mturk, prolific or team (default: DEXLABEL_CROWD_PROVIDER)")] = None,
    assignee: Annotated[str | None, typer.Option(
        help="team only: the portal worker id the tasks are assigned to")] = None,
    policy: Annotated[str | None, typer.Option(
        help="every-view (all views at once) or adaptive (the widest-baseline views first, "
             "more after each solve while it is unsure; default: DEXLABEL_PUBLISH_POLICY)")
    ] = None,
    initial_views: Annotated[int | None, typer.Option(
        help="adaptive: views published first per target (default: "
             "DEXLABEL_PUBLISH_INITIAL_VIEWS)")] = None,
    confidence: Annotated[float | None, typer.Option(
        help="adaptive: the solve confidence (0-1] a frame must reach (default: "
             "DEXLABEL_PUBLISH_CONFIDENCE)")] = None,
    confident_share: Annotated[float | None, typer.Option(
        help="adaptive: the share (0-1] of a target's frames that must reach it (default: "
             "DEXLABEL_PUBLISH_CONFIDENT_SHARE)")] = None,
) -> None:
    """Publish a HIT per task not yet published (safe to re-run).

    One HIT (unit of work of the provider) per task not yet published in this round (under
    --policy adaptive: per target, the initial views only; the solve publishes more);
    --dry-run prints the cost only, in the provider's fees and currency."""
    from backend.crowd import flows
    from backend.db import session_scope

    views = {"policy": policy, "initial_views": initial_views, "confidence": confidence,
             "confident_share": confident_share}
    options = _publish_options(reward, assignments, allow_large_hits, round_, min_approval_rate,
                               require_training, provider, assignee, views)
    with refusing_bad_input():
        with session_scope() as session:
            sequence_id = resolve_sequence(session, sequence) if sequence else None
            plan = flows.plan(session, options, sequence_id)
        c = plan.cost
        money = "$" if c.currency == "USD" else f"{c.currency} "
        typer.echo(f"{c.hits} HITs x {c.assignments_per_hit} assignment(s) at {money}{c.reward} "
                   f"(+ {money}{c.fee_per_assignment} fee each): rewards {money}{c.rewards} + "
                   f"fees {money}{c.fees} = {money}{c.total} ({c.provider})")
        if dry_run:
            typer.echo("dry run: nothing published")
            return
        with progress(f"publishing {c.hits} HITs") as step:
            result = flows.publish_each(None, options, sequence_id)
            step(f"{result.created} created")
        typer.echo(f"published: {result.created} created, {result.recovered} recovered, "
                   f"{result.already_published} already published")


crowd_app = typer.Typer(help="The crowd: units of work (HITs) on the crowd providers.",
                        no_args_is_help=True, rich_markup_mode=None)
crowd_app.command("publish")(publish_command)


@crowd_app.command("sync")
def crowd_sync() -> None:
    """Collect submitted assignments and queue their quality checks.

    Each one is checked against its provider's records first."""
    from backend.db import session_scope
    from backend.pipeline import sync

    with refusing_bad_input(), session_scope() as session:
        result = sync(session)
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
    """Spend so far and money committed, in each provider's currency.

    Rewards, bonuses and fees apart, for the project, per sequence, worker and provider."""
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
    for line in report.by_provider:
        typer.echo(_cost_row(f"provider {line.key} ({line.currency})", line))


@crowd_app.command("bonus")
def crowd_bonus(
    assignment: Annotated[int, typer.Argument(help="our assignment id")],
    amount: Annotated[str, typer.Argument(help="US dollars, more than 0, e.g. 1.00")],
    reason: Annotated[str, typer.Option(help="what the worker reads")],
    key: Annotated[str, typer.Option(help="names this bonus: one key pays once")] = "1",
) -> None:
    """Pay a worker a bonus, once (safe to re-run).

    Its ledger row is committed before the payment, and one --key pays once."""
    from backend.crowd import flows, pricing

    try:
        cents = pricing.dollars_to_cents(amount)
    except (ValueError, ArithmeticError):  # decimal's InvalidOperation for "abc"
        cents = -1
    if cents <= 0:
        fail(f"a bonus is a dollar amount in whole cents above 0, like 1.00 (got {amount!r})")
    with refusing_bad_input():
        paid = flows.pay_bonus(None, assignment, cents, reason, key)
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
    """Let simulated workers accept, label and submit HITs.

    They work through the portal, over HTTP, like real workers."""
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


