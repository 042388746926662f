"""The instance folder is its owner's alone (mode 0700): the database, queue, signing key and
export archives inside it are out of other users' reach, whatever their own modes."""

from __future__ import annotations

import stat
import subprocess
from pathlib import Path

from tests.backend.cli.conftest import DEXLABEL, clean_env


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_migrate_makes_the_instance_folder_private(tmp_path: Path) -> None:
    var_dir = tmp_path / "var"
    done = subprocess.run([*DEXLABEL, "migrate"], cwd=tmp_path, capture_output=True, text=True,
                          env=clean_env(DEXLABEL_VAR_DIR=str(var_dir)), timeout=120)
    assert done.returncode == 0, done.stderr
    assert (var_dir / "dexlabel.db").is_file()
    assert _mode(var_dir) == 0o700


def test_a_command_on_an_open_instance_folder_makes_it_private(
    tmp_path: Path, instance: Path,
) -> None:
    instance.chmod(0o755)
    done = subprocess.run([*DEXLABEL, "jobs", "list"], cwd=tmp_path, capture_output=True,
                          text=True, env=clean_env(DEXLABEL_VAR_DIR=str(instance)), timeout=120)
    assert done.returncode == 0, done.stderr
    assert _mode(instance) == 0o700
