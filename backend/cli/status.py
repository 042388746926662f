"""`dexlabel status [SEQUENCE]`: where the work stands, as the progress API shows it."""

from __future__ import annotations

from json import dumps
from typing import Annotated

import typer

from backend.annotation.schemas import TASK_STATES
from backend.cli.console import refusing_bad_input, resolve_sequence
from backend.progress.schemas import (
    SequenceFrameCost,
    SequenceProgress,
    TargetFrameCost,
    TaskProgress,
)


def _solve_line(p: SequenceProgress) -> str:
    if p.solve is None:
        return "solve: none yet"
    s = p.solve
    line = f"solve: run {s.run_id} {s.status}"
    if s.finished_at is not None:
        line += f" at {s.finished_at:%Y-%m-%d %H:%M:%S}"
    line += {"current": " (the current accepted labels)",
             "outdated": " (the accepted labels have changed since)",
             "by hand": " (asked for by hand)"}[s.labels]
    if s.error:
        line += f": {s.error.strip().splitlines()[-1]}"
    return line


def summary_line(p: SequenceProgress) -> str:
    """One line: the sequence, its state, its tasks per state and its solve."""
    total = sum(p.counts.values())
    # Views the adaptive publishing policy holds back are open tasks, named apart.
    counts = {**p.counts, "open": p.counts["open"] - p.held}
    states = ", ".join([f"{counts[state]} {state}" for state in TASK_STATES if counts[state]]
                       + ([f"{p.held} held back"] if p.held else []))
    return (f"{p.sequence_id}  {p.subject}/{p.name}  {p.state}: {total} tasks"
            f"{' (' + states + ')' if states else ''}; {_solve_line(p)}")


def _cell(task: TaskProgress) -> str:
    return "held back" if task.held else task.state


def _grid(p: SequenceProgress) -> list[str]:
    cells = {(t.serial, t.target_key): t for t in p.tasks}
    width = max([len("view"), *map(len, p.views)])
    cols = [max(len(target), *(len(_cell(t)) for t in p.tasks)) for target in p.targets]
    lines = ["  ".join([f"{'view':<{width}}", *(f"{t:<{w}}" for t, w in zip(p.targets, cols,
                                                                             strict=True))])]
    for serial in p.views:
        row = [_cell(cells[(serial, t)]) if (serial, t) in cells else "-" for t in p.targets]
        lines.append("  ".join([f"{serial:<{width}}", *(f"{s:<{w}}" for s, w in zip(
            row, cols, strict=True))]).rstrip())
    return lines


COST_HEADER = ("target", "3D frames", "actions", "seconds", "money", "actions/frame",
               "seconds/frame", "money/frame", "currency")


def _cost_cells(line: TargetFrameCost) -> list[str]:
    def shown(value: object) -> str:
        return "-" if value is None else str(value)

    return [line.target_key, str(line.frames_labelled), str(line.actions), f"{line.seconds:.1f}",
            line.money, shown(line.actions_per_frame), shown(line.seconds_per_frame),
            shown(line.money_per_frame), line.currency]


def cost_table(costs: SequenceFrameCost) -> list[str]:
    """The cost per labelled 3D frame, a row per target and the total (whose 3D frames are
    those labelled for every target), in aligned columns."""
    rows = [list(COST_HEADER), *(_cost_cells(t) for t in [*costs.targets, costs.total])]
    widths = [max(len(row[i]) for row in rows) for i in range(len(COST_HEADER))]
    return ["  ".join(cell.ljust(w) if i == 0 else cell.rjust(w)
                      for i, (cell, w) in enumerate(zip(row, widths, strict=True))).rstrip()
            for row in rows]


# Sequences read and printed at a time by `dexlabel status` without a sequence.
STATUS_PAGE = 200


def _every_sequence(json: bool) -> None:
    """One line (or one JSON object) per sequence, printed a page at a time as it is read."""
    from sqlalchemy import select

    from backend.captures.models import Sequence
    from backend.db import session_scope
    from backend.progress.service import sequences_progress

    offset, printed = 0, 0
    if json:
        typer.echo("[", nl=False)
    while True:
        with session_scope() as session:
            ids = list(session.scalars(select(Sequence.id).order_by(Sequence.id)
                                       .offset(offset).limit(STATUS_PAGE)))
            page = sequences_progress(session, ids)
        for p in page:
            if json:
                typer.echo(("," if printed else "") + "\n" + p.model_dump_json(indent=2),
                           nl=False)
            else:
                typer.echo(summary_line(p))
            printed += 1
        if len(ids) < STATUS_PAGE:
            break
        offset += STATUS_PAGE
    if json:
        typer.echo("\n]")
    elif not printed:
        typer.echo("no sequences yet: `dexlabel import PATH` or `dexlabel synth` adds one")


def status_command(
    sequence: Annotated[str | None, typer.Argument(
        help="sequence id or SUBJECT/NAME (default: one line per sequence)",
        show_default=False)] = None,
    json: Annotated[bool, typer.Option(
        "--json", help="print the progress API's JSON (one sequence's with its frame_costs)",
    )] = False,
) -> None:
    """Where the work stands, and its cost per labelled 3D frame.

    Each view x target task's state (open, published, submitted, in review, accepted), HIT
    and assignment counts, the current solve, and per target the actions, seconds and money
    spent per frame that solve labelled and did not flag."""
    from backend.db import session_scope
    from backend.progress.frame_costs import frame_costs
    from backend.progress.service import sequences_progress

    if sequence is None:
        with refusing_bad_input():
            _every_sequence(json)
        return
    with refusing_bad_input(), session_scope() as session:
        sequence_id = resolve_sequence(session, sequence)
        found = sequences_progress(session, [sequence_id])
        costs = frame_costs(session, [sequence_id])[0]
    if json:
        # The progress API's JSON, with the cost per labelled 3D frame the table shows.
        body = found[0].model_dump(mode="json") | {"frame_costs": costs.model_dump(mode="json")}
        typer.echo(dumps(body, indent=2))
        return
    p = found[0]
    typer.echo(summary_line(p))
    a = p.assignments
    typer.echo(f"HITs: {p.hits} published, {p.hits_live} open; assignments: {a.approved} "
               f"approved, {a.rejected} rejected, {a.submitted} submitted, {a.working} working")
    if p.tasks:
        typer.echo("")
        for line in _grid(p):
            typer.echo(line)
    typer.echo("")
    run = f"solve run {costs.solve_run_id}" if costs.solve_run_id else "no solve yet"
    typer.echo(f"cost per labelled 3D frame ({run}; money spent, from the crowd ledger):")
    for line in cost_table(costs):
        typer.echo(line)
