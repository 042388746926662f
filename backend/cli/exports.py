"""The export command, registered on the main app by backend/cli/__init__.py:

    dexlabel export SEQUENCE... | --all --format F --out PATH [--include accepted|submitted]
                    [--frames] [--link-frames] [--split s0|s1|s2|s3] [--labels 2d|3d]

PATH ending in .zip or .tar is an archive, anything else a folder; it must not exist. The export
is written under a temporary name next to PATH and moved there only when complete.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

import typer

from backend.cli.console import fail, progress, refusing_bad_input, resolve_sequence
from backend.db import session_scope
from backend.errors import DexlabelError
from worker.formats import FORMATS

# Suffixes that name a file, not a folder: refused rather than made into a folder so named.
_FILE_SUFFIXES = {".gz", ".tgz", ".bz2", ".xz", ".zst", ".7z", ".rar", ".json", ".xml", ".npz"}
EXIT_CANCELLED = 130  # as a shell reports a command ended by Ctrl-C


def export_command(
    sequences: Annotated[list[str] | None, typer.Argument(
        help="sequence ids or SUBJECT/NAME (or --all)", show_default=False)] = None,
    all_sequences: Annotated[bool, typer.Option("--all", help="every sequence")] = False,
    fmt: Annotated[str, typer.Option("--format", help="dexycb, coco, bop, cvat or json")] = "",
    out: Annotated[Path | None, typer.Option(
        "--out", help="the archive (.zip, .tar) or folder to write; must not exist")] = None,
    include: Annotated[str, typer.Option(
        "--include", help="accepted labels, or all submitted work with its QC outcome")
    ] = "accepted",
    frames: Annotated[bool, typer.Option(
        "--frames", help="copy the colour and depth frames too (dexycb, bop)")] = False,
    link_frames: Annotated[bool, typer.Option(
        "--link-frames", help="link the frames instead of copying them (tar or folder)")
    ] = False,
    split: Annotated[Literal["s0", "s1", "s2", "s3"] | None, typer.Option(
        "--split", help="dexycb: write DexYCB's split lists of this setup")] = None,
    labels: Annotated[Literal["2d", "3d"] | None, typer.Option(
        "--labels", help="coco: hand keypoints from the 2D labels or the solve")] = None,
) -> None:
    """Export labels of sequences in a dataset's format.

    One or more sequences (or --all), with a progress bar."""
    # The arguments are checked before the export's modules load: a typo answers at once.
    out = _checked_out(fmt, out, bool(sequences), all_sequences)
    from backend.exports.archive import kind_of
    from backend.exports.service import check_request, run_export

    options: dict[str, Any] = {"frames": "link" if link_frames else ("copy" if frames else None),
                               "split": split, "labels": labels}
    options = {k: v for k, v in options.items() if v is not None}
    with refusing_bad_input(), session_scope() as session:
        ids = None if all_sequences else [resolve_sequence(session, s) for s in sequences or []]
        ids, skipped = check_request(session, fmt, ids, include, options, kind_of(out))
    for reason in skipped:
        typer.secho(f"skipped: {reason}", err=True)
    try:
        with progress(f"{fmt} export", total=None) as step:
            result = run_export(fmt, ids, include, options, out,
                                lambda done, total: step(f"view {done} of {total}"))
    except KeyboardInterrupt:
        typer.secho(f"export cancelled; nothing was written at {out}", err=True)
        raise typer.Exit(EXIT_CANCELLED) from None
    except (DexlabelError, OSError, ValueError) as exc:
        # The temporary output is already removed; say what went wrong, not a traceback.
        detail = exc.detail if isinstance(exc, DexlabelError) else str(exc)
        typer.secho(f"error: the export failed: {detail}; nothing was written at {out}",
                    fg=typer.colors.RED, err=True)
        raise typer.Exit(1) from None
    typer.echo(f"{out}: {result['sequences']} sequence(s), {result['frames']} frames, "
               f"{result['files']} files, {result['bytes'] / 1e6:.1f} MB")


def _checked_out(fmt: str, out: Path | None, named: bool, all_sequences: bool) -> Path:
    """The export's output path, once the command's arguments are whole and the path is free
    (else the command stops naming what to give)."""
    if not fmt:
        fail("give --format (dexycb, coco, bop, cvat or json)")
    if fmt not in FORMATS:
        fail(f"--format must be one of {', '.join(FORMATS)}; {fmt!r} is none of them")
    if out is None:
        fail("give --out PATH (an archive .zip or .tar, or a folder)")
    if named == all_sequences:
        fail("give one or more sequences, or --all")
    if out.exists() or out.is_symlink():
        fail(f"{out} exists; give a path that does not")
    if not out.parent.is_dir():
        fail(f"the folder {out.parent} does not exist; create it or give a path in an existing "
             "folder")
    if out.suffix.lower() in _FILE_SUFFIXES:
        fail(f"{out.name}: an export is written as .zip, .tar or a folder (a path without one "
             f"of those suffixes); {out.suffix} is none of them")
    return out
