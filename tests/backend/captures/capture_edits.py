"""Helpers that copy a capture and break it in one specific way."""

from __future__ import annotations

import shutil
from pathlib import Path

import yaml


def copy_capture(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def sequence_dir(root: Path) -> Path:
    return next(root.glob("*/*/meta.yml")).parent


def meta(root: Path) -> dict:
    return yaml.safe_load((sequence_dir(root) / "meta.yml").read_text())


def extrinsics_file(root: Path) -> Path:
    return next((root / "calibration").glob("extrinsics_*/extrinsics.yml"))


def set_extrinsics(root: Path, serial: str, values: list) -> None:
    path = extrinsics_file(root)
    doc = yaml.safe_load(path.read_text())
    doc["extrinsics"][serial] = values
    path.write_text(yaml.safe_dump(doc))
