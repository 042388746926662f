"""What every `dexlabel` command shares: one way to refuse bad input, sequences named by id or
SUBJECT/NAME, and progress that suits where the output goes.

Bad input (a sequence that does not exist, an amount that is not positive, no instance here)
prints one line ``error: ...`` on stderr and exits with status 2, never a traceback. Work that
ran and failed (a job that ended ``failed``) exits with status 1.

Long work shows a progress bar with the elapsed time on a terminal, and a plain line per step
otherwise (a log file, CI), and always ends with one line giving its timing.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Annotated, NoReturn

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)
from sqlalchemy.orm import Session

from backend.errors import DexlabelError, NotFound

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1

SequenceArg = Annotated[str, typer.Argument(
    help="sequence id, or SUBJECT/NAME", show_default=False)]


def fail(problem: DexlabelError | str) -> NoReturn:
    """Refuse bad input: ``error: <detail>`` on stderr, exit status 2."""
    detail = problem.detail if isinstance(problem, DexlabelError) else str(problem)
    typer.secho(f"error: {detail}", fg=typer.colors.RED, err=True)
    raise typer.Exit(EXIT_BAD_INPUT)


@contextmanager
def refusing_bad_input() -> Iterator[None]:
    """Run a command's body; any of our errors it raises becomes :func:`fail`."""
    try:
        yield
    except DexlabelError as exc:
        fail(exc)


def resolve_sequence(session: Session, ref: str) -> int:
    """The id of the sequence named by ``ref``: its id ("12") or SUBJECT/NAME.

    Raises:
        NotFound: no such sequence (an unknown sequence is an error, never an empty listing).
    """
    from backend.captures.models import Sequence
    from backend.captures.service import find_sequence

    ref = ref.strip()
    if ref.isdigit():
        if session.get(Sequence, int(ref)) is None:
            raise NotFound(f"no sequence {ref} (give an id or SUBJECT/NAME)")
        return int(ref)
    subject, _, name = ref.partition("/")
    found = find_sequence(session, subject, name) if subject and name else None
    if found is None:
        raise NotFound(f"no sequence {ref!r} (give an id or SUBJECT/NAME)")
    return found.id


def _console() -> Console:
    return Console(highlight=False)


def on_terminal() -> bool:
    """Whether standard output is an interactive terminal (bars) or not (plain lines)."""
    return _console().is_terminal


Step = Callable[[str], None]


@contextmanager
def progress(label: str, total: int | None = None, err: bool = False) -> Iterator[Step]:
    """Progress of one piece of long work; yields ``step(what)``, called as each step ends.

    ``total`` is the number of steps (None: unknown, a spinner). On a terminal a bar with
    the step count and the elapsed time; otherwise ``label: what (i/total)`` per step. Either
    way the work ends with ``label: done in 12.3 s`` (or ``label: failed after ...``). With
    ``err`` every line goes to stderr (stdout carries only a command's --json document).
    """
    started = time.perf_counter()
    done = 0
    if on_terminal():
        columns = [SpinnerColumn(), TextColumn("{task.description}"), BarColumn()]
        if total is not None:
            columns.append(MofNCompleteColumn())
        bar = Progress(*columns, TimeElapsedColumn(),
                       console=Console(highlight=False, stderr=err), transient=True)
        task = bar.add_task(label, total=total)

        def step(what: str) -> None:
            nonlocal done
            done += 1
            bar.update(task, advance=1, description=f"{label}: {what}")
    else:
        typer.echo(f"{label} ...", err=err)
        bar = None

        def step(what: str) -> None:
            nonlocal done
            done += 1
            typer.echo(f"{label}: {what}" + (f" ({done}/{total})" if total else ""), err=err)
    ok = False
    try:
        if bar is not None:
            with bar:
                yield step
        else:
            yield step
        ok = True
    finally:
        elapsed = time.perf_counter() - started
        typer.echo(f"{label}: {'done in' if ok else 'failed after'} {elapsed:.1f} s", err=err)
