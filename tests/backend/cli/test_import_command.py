"""`dexlabel import` refuses a capture whose image data is broken past a valid header: one
`error:` line naming the file, exit 2, nothing imported."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from backend.cli import app
from tests.backend.captures import capture_edits as edit


def test_import_of_a_truncated_jpeg_is_one_error_line_naming_the_file(
    instance: Path, cli: CliRunner, small_capture: Path, tmp_path: Path
) -> None:
    cap = edit.copy_capture(small_capture, tmp_path / "cap")
    serial = str(edit.meta(cap)["serials"][2])
    frame = edit.sequence_dir(cap) / serial / "color_000003.jpg"
    frame.write_bytes(frame.read_bytes()[:-4000])

    done = cli.invoke(app, ["import", str(cap)])
    assert done.exit_code == 2, done.output
    errors = [line for line in done.output.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1
    assert f"{serial}/color_000003.jpg: JPEG image does not decode" in errors[0]
    assert not any(p.is_file() for p in (instance / "storage").rglob("*"))


def test_import_of_a_path_too_long_is_one_error_line(instance: Path, cli: CliRunner) -> None:
    done = cli.invoke(app, ["import", "/tmp/" + "z" * 5000])
    assert done.exit_code == 2, done.output
    errors = [line for line in done.output.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "at most 4096 characters" in errors[0]
