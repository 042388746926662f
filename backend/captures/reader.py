"""Reading a capture's files under one root: YAML documents and their fields checked, every
problem an InvalidCapture naming the file relative to the root; a digest of what was read."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from backend.errors import InvalidCapture


class CaptureReader:
    """Reads files under one root, naming them relative to it in every error."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.digest = hashlib.sha256()

    def rel(self, path: Path) -> str:
        try:
            return path.relative_to(self.root).as_posix()
        except ValueError:
            return str(path)

    def fail(self, path: Path, problem: str) -> InvalidCapture:
        return InvalidCapture(self.rel(path), problem)

    def yaml(self, path: Path) -> dict[str, Any]:
        if not path.is_file():
            raise self.fail(path, "file is missing")
        data = path.read_bytes()
        self.digest.update(self.rel(path).encode() + b"\0" + data)
        try:
            doc = yaml.safe_load(data)
        except yaml.YAMLError as exc:
            where = getattr(exc, "problem_mark", None)
            line = f" at line {where.line + 1}" if where is not None else ""
            raise self.fail(path, f"not valid YAML{line}: {getattr(exc, 'problem', exc)}") from None
        if not isinstance(doc, dict):
            raise self.fail(path, "expected a mapping at the top level")
        return doc

    def field(
        self, doc: dict[str, Any], path: Path, name: str, kind: type | tuple[type, ...]
    ) -> Any:
        if name not in doc:
            raise self.fail(path, f"field '{name}' is missing")
        value = doc[name]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            raise self.fail(path, f"field '{name}' must be {_kind_name(kind)}, got {value!r:.60}")
        return value

    def numbers(self, value: Any, path: Path, name: str, count: int) -> list[float]:
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise self.fail(path, f"field '{name}' must be a list of {count} numbers") from None
        if arr.size != count or arr.ndim > 2:
            raise self.fail(
                path, f"field '{name}' must hold {count} numbers, got shape {list(arr.shape)}"
            )
        if not np.all(np.isfinite(arr)):
            raise self.fail(path, f"field '{name}' holds a non-finite number")
        return [float(v) for v in arr.ravel()]


def _kind_name(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {list: "a list", dict: "a mapping", str: "a string", int: "an integer",
             float: "a number"}
    return " or ".join(names.get(k, k.__name__) for k in kinds)
