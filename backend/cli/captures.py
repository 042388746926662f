"""CLI of imported sequences: `dexlabel sequences delete`."""

from __future__ import annotations

from typing import Annotated

import typer

from backend.cli.console import SequenceArg, refusing_bad_input, resolve_sequence
from backend.db import session_scope

sequences_app = typer.Typer(help="Imported sequences.", no_args_is_help=True,
                            rich_markup_mode=None)


@sequences_app.command("delete")
def sequences_delete(
    sequence: SequenceArg,
    force: Annotated[bool, typer.Option(
        "--force", help="delete it even with submitted or approved work (deleted too)")] = False,
) -> None:
    """Delete a sequence with its tasks, work and stored files.

    Refused while it has submitted or approved work, unless --force."""
    from backend.pipeline.deletion import delete_sequence

    with refusing_bad_input():
        with session_scope() as session:
            sequence_id = resolve_sequence(session, sequence)
        done = delete_sequence(sequence_id, force)
    d = done.sequence
    typer.echo(f"deleted sequence {d.sequence_id} {d.subject}/{d.name}: {d.tasks} tasks, "
               f"{d.assignments} assignments ({d.finished_assignments} submitted or approved), "
               f"{done.files} stored files")
