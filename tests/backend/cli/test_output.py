"""The command line as a newcomer meets it: every command's --help readable at 80 columns
(whole option names, no markup, no type on a flag, command lists not cut short), a solve's
result in a few readable lines, and a refusal before any work is announced."""

from __future__ import annotations

import os
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from typer.main import get_command
from typer.testing import CliRunner

from backend.cli import app
from tests.backend.cli.conftest import DEXLABEL, clean_env

# Sphinx/RST roles and literals that a terminal shows as they are.
MARKUP = re.compile(r"``|:(func|class|meth|mod|attr):`|\*\*")


def _commands(command: Any, path: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], Any]]:
    yield path, command
    for name, sub in getattr(command, "commands", {}).items():
        yield from _commands(sub, (*path, name))


COMMANDS = list(_commands(get_command(app)))


def _help(path: tuple[str, ...]) -> str:
    result = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "80"},
                                prog_name="dexlabel")
    assert result.exit_code == 0, result.output
    return result.output


def _section(text: str, title: str) -> list[str]:
    lines = text.splitlines()
    if f"{title}:" not in lines:
        return []
    start = lines.index(f"{title}:") + 1
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith(" ")), len(lines))
    return lines[start:end]


@pytest.mark.parametrize("path", [p for p, _ in COMMANDS], ids=lambda p: " ".join(p) or "root")
def test_every_help_page_reads_at_80_columns(path: tuple[str, ...]) -> None:
    command = dict(COMMANDS)[path]
    text = _help(path)
    assert all(len(line) <= 80 for line in text.splitlines()), text
    assert not MARKUP.search(text), text
    assert "<bool>" not in text and "…" not in text, text
    # Every option's every name in full.
    for param in command.params:
        for name in (*param.opts, *param.secondary_opts):
            if name.startswith("-"):
                found = re.search(rf"(^|[\s,/;]){re.escape(name)}(\s|,|$)", text,
                                  re.MULTILINE)
                assert found, (name, text)
    # A command list gives each command's whole first sentence, never a cut one.
    for line in _section(text, "Commands"):
        assert not line.rstrip().endswith("..."), line


def test_the_installed_command_help_fits_80_columns() -> None:
    """The real entry point in a fresh process, with the terminal width a newcomer has."""
    done = subprocess.run([*DEXLABEL, "publish", "--help"], capture_output=True, text=True,
                          env=clean_env(COLUMNS="80"), timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert all(len(line) <= 80 for line in done.stdout.splitlines()), done.stdout
    for option in ("--allow-large-hits", "--min-approval-rate", "--require-training",
                   "--no-require-training"):
        assert option in done.stdout
    assert "<bool>" not in done.stdout and "╭" not in done.stdout


def test_synth_into_a_folder_in_use_fails_before_it_announces_work(tmp_path: Path) -> None:
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "file").touch()
    result = CliRunner().invoke(app, ["synth", str(taken), "--frames", "2", "--views", "1",
                                      "--objects", "1"])
    assert result.exit_code == 2
    assert result.output.splitlines() == [
        f"error: {taken} exists and is not an empty folder; give a new one"]
    assert os.listdir(taken) == ["file"]
    assert not (tmp_path / "taken.partial").exists()


def test_a_solve_summary_reads_as_a_few_lines_with_its_gaps_named() -> None:
    from backend.cli.solve import summary_lines

    summary = {"frames": 72, "labelled_frames": 70, "kpt_px_median": 1.234,
               "kpt_px_mean": None, "depth_rms_mm": 4.2,
               "fingertip_px": {"thumb": 1.0, "index": None},
               "solver": {"unlabelled": {"5": "fewer than 2 views", "9": "no labels"}},
               "object_flags": ["frame 3: object 0 seen by one view"]}
    assert summary_lines(7, "paper", summary, 12.34) == [
        "solve run 7 done in 12.3 s (paper optimiser)",
        "  frames labelled: 70 of 72",
        "  left unlabelled: 2 frames (frame 5: fewer than 2 views; ...)",
        "  keypoint error: median 1.23 px, mean -",
        "  fingertips: thumb 1.0, index - px",
        "  depth error: 4.20 mm RMS",
        ("  object poses not pinned down: 1 (exported as unlabelled; first: frame 3: "
         "object 0 seen by one view)"),
        "  everything: --json, or GET /api/solve-runs/7",
    ]
