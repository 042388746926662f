"""CLI of rig health, registered on the main app by backend/cli/__init__.py:

    dexlabel rig health SEQUENCE [--json]    estimate here, store a new calibration version
    dexlabel rig adopt SEQUENCE VERSION [--no-solve]   put a version in use (0: imported)

SEQUENCE is a sequence id or SUBJECT/NAME.
"""

from __future__ import annotations

import json
from typing import Annotated

import typer

from backend.cli.console import SequenceArg, progress, refusing_bad_input, resolve_sequence
from backend.db import session_scope

rig_app = typer.Typer(help="Rig health: cameras off in calibration, sync or depth.",
                      no_args_is_help=True, rich_markup_mode=None)


def _line(row: dict) -> str:
    depth = "-" if row["depth_scale_percent"] is None else (
        f"{row['depth_scale_percent']:+.2f} % ({row['depth_shift_px'][0]}, "
        f"{row['depth_shift_px'][1]}) px")
    verdict = "; ".join(row["faults"]) or "ok"
    return (f"{row['serial']:>14s}  {row['time_offset_frames']:+d} fr  "
            f"{row['rotation_deg']:5.2f} deg {row['translation_mm']:5.1f} mm "
            f"{row['image_shift_px']:5.1f} px  {row['residual_px_before'] or 0:5.2f} -> "
            f"{row['residual_px_after'] or 0:5.2f} px  depth {depth}  {verdict}")


@rig_app.command("health")
def health_command(
    sequence: SequenceArg,
    as_json: Annotated[bool, typer.Option("--json", help="print the report as JSON")] = False,
) -> None:
    """Estimate each camera's time offset, pose and depth errors.

    Every camera's time offset, pose correction and depth scale and shift, from the accepted
    labels; the result is stored as a new calibration version (not in use)."""
    from backend.rig.service import estimate, read_inputs, store_version

    with refusing_bad_input(), session_scope() as session:
        sequence_id = resolve_sequence(session, sequence)
        inputs = read_inputs(session, sequence_id)
    with progress(f"rig health of sequence {sequence_id}") as step:
        cameras, report = estimate(inputs)
        step("estimated")
    with refusing_bad_input(), session_scope() as session:
        number = store_version(session, sequence_id, cameras, report).number
    if as_json:
        typer.echo(json.dumps({"sequence_id": sequence_id, "version": number, **report}))
        return
    typer.echo(f"sequence {sequence_id}: calibration version {number} (not in use; "
               f"dexlabel rig adopt {sequence_id} {number})")
    typer.echo("        camera  time   pose correction   image  residual before -> after")
    for row in report["cameras"]:
        typer.echo(_line(row))
    typer.echo("cameras off: " + (", ".join(report["faulty"]) or "none"))
    for hand in report["hands"]:
        typer.echo(f"hand {hand['index']} ({hand['side']}) shape: bones "
                   f"{hand['bone_diff_median_mm']:.2f} mm off (median), "
                   f"{hand['bone_diff_max_mm']:.2f} mm at most, over {hand['frames']} frames: "
                   + ("; ".join(hand["faults"]) or "ok"))


@rig_app.command("adopt")
def adopt_command(
    sequence: SequenceArg,
    version: Annotated[int, typer.Argument(min=0, help="calibration version; 0 = imported")],
    solve: Annotated[bool, typer.Option("--solve/--no-solve",
                                        help="queue a solve under it")] = True,
) -> None:
    """Put a calibration version in use, and solve again.

    The version is used by the solve, QC and export from then on."""
    from backend.pipeline import adopt_calibration

    with refusing_bad_input(), session_scope() as session:
        sequence_id = resolve_sequence(session, sequence)
        outcome = adopt_calibration(session, sequence_id, version, solve)
    typer.echo(f"sequence {sequence_id}: calibration version {version} in use; solve: "
               f"{outcome}")
