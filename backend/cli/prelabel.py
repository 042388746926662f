"""`dexlabel prelabel CAPTURE`: the optional hand prelabeler (extra ``prelabel``) run on a
synthetic capture's views and scored against its truth."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from backend.cli.console import fail, refusing_bad_input


def prelabel_command(
    capture: Annotated[Path, typer.Argument(help="a synthetic capture (dexlabel synth)")],
    view: Annotated[list[str] | None, typer.Option(
        metavar="SERIAL", help="only this view (repeatable); default every view")] = None,
    still: Annotated[bool, typer.Option(
        "--still", help="each frame on its own (no following of the hand between frames)")]
        = False,
    as_json: Annotated[bool, typer.Option("--json", help="one JSON object")] = False,
) -> None:
    """Hand proposals on a capture, scored against its truth.

    MediaPipe's hand landmarker (optional extra: pip install 'dexlabel[prelabel]') proposes
    the hand's 21 joints in every frame of each view; per view, the command reports the share
    of frames with the hand visible where it was found (and of those with most of its joints
    in view) and the median pixel error of the proposed joints. Needs no instance."""
    from backend.captures.prelabel import overall, prelabel_capture
    from worker.assist.prelabel import CLEAR_MIN_JOINTS, MediaPipeHands, PrelabelUnavailable

    if not capture.is_dir():
        fail(f"{capture} is not a folder")
    try:
        model = MediaPipeHands(video=not still)
    except PrelabelUnavailable as exc:
        fail(str(exc))
    with refusing_bad_input():
        views = prelabel_capture(capture, model, views=view)
    rows = [v.summary() for v in views]
    if as_json:
        typer.echo(json.dumps({"model": model.name, "video": not still, "views": rows,
                               "overall": overall(views)}))
        return
    for r in [*rows, {"serial": "all views", **overall(views)}]:
        typer.echo(f"{r['serial']}: found in {_share(r['found'], r['visible'])} frames with the "
                   f"hand visible, {_share(r['found_clear'], r['clear'])} with {CLEAR_MIN_JOINTS}+ "
                   f"joints in view; median error "
                   + ("-" if r["median_px"] is None else f"{r['median_px']:.1f} px")
                   + f"; {r['proposed_unseen']} proposals where it is not visible")


def _share(found: int, of: int) -> str:
    return f"{found} of {of}" + (f" ({100 * found / of:.0f}%)" if of else "")
