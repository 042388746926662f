"""CLI tests: the `dexlabel` commands in this process (typer's runner) on a migrated SQLite
instance, or as subprocesses where the point is a fresh process (no instance, a server in
another terminal)."""

from __future__ import annotations

import os
import socket
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import reset_caches


@pytest.fixture
def instance(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[Path]:
    """A migrated instance folder (its SQLite database and storage inside); its path."""
    from backend.migrate import upgrade

    var_dir = tmp_path / "var"
    for name in [k for k in os.environ if k.startswith("DEXLABEL_")]:
        monkeypatch.delenv(name)
    monkeypatch.setenv("DEXLABEL_VAR_DIR", str(var_dir))
    monkeypatch.setenv("DEXLABEL_ENV", "test")
    reset_caches()
    upgrade(f"sqlite:///{var_dir / 'dexlabel.db'}")
    yield var_dir
    reset_caches()


@pytest.fixture
def cli() -> CliRunner:
    return CliRunner()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def clean_env(**settings: str) -> dict[str, str]:
    """This process's environment without any DEXLABEL_ setting, plus ``settings``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEXLABEL_")}
    env.update(settings)
    return env


DEXLABEL = [sys.executable, "-m", "backend.cli"]
