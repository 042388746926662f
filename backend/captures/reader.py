"""Reading a capture's files under one root: YAML documents and their fields checked, every
problem an InvalidCapture naming the file relative to the root; a digest of what was read.

An HTTP import reads only inside the folders captures are imported from (CaptureRoots): every
file and folder is resolved, symbolic links followed, before it is opened, and one that leads
outside is refused (403) by its name in the capture."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from backend.errors import Forbidden, InvalidCapture


class CaptureRoots:
    """The folders an import may read from (resolved), and the instance folder they are shown
    relative to: an error names no absolute path of the server."""

    def __init__(self, folders: Sequence[Path], var_dir: Path) -> None:
        self.folders = [Path(f).resolve() for f in folders]
        self.var_dir = var_dir.resolve()

    def holds(self, path: Path) -> bool:
        """Whether ``path``, symbolic links followed, lies inside one of the folders."""
        try:
            resolved = path.resolve()
        except (OSError, RuntimeError):  # RuntimeError: a symbolic link loop
            return False
        return any(resolved.is_relative_to(folder) for folder in self.folders)

    def shown(self) -> str:
        """The folders as an error shows them: relative to the instance folder, or by their
        place in DEXLABEL_CAPTURE_ROOTS."""
        names = []
        for number, folder in enumerate(self.folders, 1):
            if folder == self.var_dir:
                names.append("the instance folder")
            elif folder.is_relative_to(self.var_dir):
                names.append(f"{folder.relative_to(self.var_dir).as_posix()}/ in the instance "
                             "folder")
            else:
                names.append(f"folder {number} of DEXLABEL_CAPTURE_ROOTS")
        return ", ".join(names)

    def refuse(self, what: str) -> Forbidden:
        return Forbidden(
            f"{what} is outside the folders captures are imported from ({self.shown()}); put "
            "the capture in one of them or list its folder in DEXLABEL_CAPTURE_ROOTS")


class CaptureReader:
    """Reads files under one root, naming them relative to it in every error; with ``roots``
    (an HTTP import), only files and folders that lie inside them."""

    def __init__(self, root: Path, roots: CaptureRoots | None = None) -> None:
        self.root = root
        self.roots = roots
        self.digest = hashlib.sha256()

    def inside(self, path: Path) -> Path:
        """``path`` itself, once it is known to lie inside the roots, symbolic links followed.

        Raises:
            Forbidden: naming the file or folder relative to the capture root.
        """
        if self.roots is not None and not self.roots.holds(path):
            raise self.roots.refuse(f"{self.rel(path)} (a symbolic link in the capture?)")
        return path

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
        self.inside(path)
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
