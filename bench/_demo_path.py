"""The README's demo path for the export benches (bench/export_truth.py,
bench/toolkit_readers.py): ``dexlabel`` commands in an instance folder of their own, a
synthetic capture of a given seed run through ``dexlabel demo``, and exports unpacked."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def dexlabel(var: Path, *args: str) -> None:
    """One ``dexlabel`` command in the instance folder ``var`` (no other DEXLABEL_ setting of
    this shell leaks in); its output goes to stderr; exits naming the command if it fails."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("DEXLABEL_")}
    env.update(DEXLABEL_VAR_DIR=str(var), PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-m", "backend.cli", *args], cwd=ROOT, env=env,
                          stdout=sys.stderr, stderr=sys.stderr)
    if done.returncode != 0:
        sys.exit(f"dexlabel {' '.join(args)} failed (exit {done.returncode})")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port


def run_demo(spec: str, seed: int, fault: str | None, var: Path) -> Path:
    """Synthesise a capture of ``seed`` (with ``fault`` for ``dexlabel synth --fault``) of
    FRAMES,VIEWS,OBJECTS ``spec`` and run ``dexlabel demo --no-serve`` on it in ``var``;
    returns the capture (the truth)."""
    try:
        frames, views, objects = (int(part) for part in spec.split(","))
    except ValueError:
        sys.exit(f"--demo {spec!r}: expected FRAMES,VIEWS,OBJECTS, e.g. 24,4,2")
    truth = var / "demo-capture"
    size = ("--frames", str(frames), "--views", str(views), "--objects", str(objects))
    dexlabel(var, "synth", str(truth), "--seed", str(seed), *size,
             *(["--fault", fault] if fault else []))
    dexlabel(var, "demo", "--no-serve", "--port", str(free_port()), *size)
    return truth


def unpacked(path: Path, scratch: Path) -> Path:
    """An export folder as is, or a .zip / .tar archive unpacked into ``scratch``."""
    if path.is_dir():
        return path
    scratch.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".zip":
        with zipfile.ZipFile(path) as archive:
            archive.extractall(scratch)
    else:
        with tarfile.open(path) as archive:
            archive.extractall(scratch, filter="data")
    return scratch
