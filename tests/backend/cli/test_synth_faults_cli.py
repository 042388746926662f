"""`dexlabel synth --fault`: a capture whose product inputs carry the fault, truth unchanged, and
bad fault names refused before anything is written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from typer.testing import CliRunner

from backend.captures.layout import find_sequence_dirs, read_sequence
from backend.cli import app

TINY = ["--frames", "2", "--views", "2", "--objects", "1", "--seed", "13"]


def test_synth_with_a_fault_writes_the_faulty_copy_only(tmp_path: Path, cli: CliRunner) -> None:
    done = cli.invoke(app, ["synth", str(tmp_path / "clean"), *TINY])
    assert done.exit_code == 0, done.output
    done = cli.invoke(app, ["synth", str(tmp_path / "bad"), *TINY, "--fault",
                            "extrinsics:1,10", "--fault-seed", "2"])
    assert done.exit_code == 0, done.output
    assert "injecting extrinsics:1,10" in done.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad", "clean"]
    record = yaml.safe_load((tmp_path / "bad" / "fault.yml").read_text())
    assert record["faults"] == ["extrinsics:1,10"] and record["seed"] == 2
    clean, bad = (read_sequence(find_sequence_dirs(tmp_path / n)[0]) for n in ("clean", "bad"))
    moved = [np.linalg.norm(np.array(b.extrinsics)[:, 3] - np.array(c.extrinsics)[:, 3])
             for c, b in zip(clean.cameras, bad.cameras, strict=True)]
    np.testing.assert_allclose(moved, [0.0, 0.01], atol=1e-9)


def test_synth_refuses_an_unknown_fault_before_writing(tmp_path: Path, cli: CliRunner) -> None:
    done = cli.invoke(app, ["synth", str(tmp_path / "x"), *TINY, "--fault", "wobble:1"])
    assert done.exit_code == 2
    assert done.output.splitlines()[-1].startswith("error: unknown fault 'wobble'")
    assert not list(tmp_path.iterdir())
