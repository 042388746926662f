"""Lint: no module of backend/ outside the crowd providers names an MTurk operation.

The crowd domain reaches a crowd only through ``backend.crowd.provider.CrowdProvider``; only
``backend/crowd/providers/`` speaks MTurk (and ``backend/market/``, which *is* an MTurk-compatible
marketplace). An operation is named when its name (``create_hit`` or ``CreateHIT``) is a string
(``call(client, "create_hit")``, ``get_paginator("list_hits")``), a CamelCase identifier, or an
attribute of anything but one of our own modules (``client.send_bonus(...)``; our own
``decisions.send_bonus`` is a module's function). The operation names come from botocore's own
service model, so every MTurk operation counts. (Importing boto3 or botocore is ruff's
banned-api rule, TID251, in pyproject.toml.)

Usage: python tests/lint_crowd_seam.py [FILE_OR_DIR ...]   (default: backend); exits 1 on a
finding, naming file, line and operation.
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from pathlib import Path

import botocore.session
from botocore import xform_name

ROOT = Path(__file__).resolve().parents[1]
# Where MTurk may be spoken.
ALLOWED = ("backend/crowd/providers/", "backend/market/")


def operations() -> tuple[frozenset[str], frozenset[str]]:
    """(CamelCase, snake_case) names of every operation of botocore's mturk model."""
    model = botocore.session.get_session().get_service_model("mturk")
    camel = frozenset(model.operation_names)
    return camel, frozenset(xform_name(name) for name in camel)


def _our_modules(tree: ast.Module) -> set[str]:
    """Names this module binds to modules of ours (``from backend.crowd import decisions``)."""
    bound = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("backend"):
            bound.update(alias.asname or alias.name for alias in node.names)
        elif isinstance(node, ast.Import):
            bound.update((alias.asname or alias.name).split(".")[0] for alias in node.names
                         if alias.name.startswith("backend"))
    return bound


def findings(path: Path, camel: frozenset[str], snake: frozenset[str]) -> Iterator[str]:
    tree = ast.parse(path.read_text(), str(path))
    ours = _our_modules(tree)
    names = camel | snake
    for node in ast.walk(tree):
        named = None
        if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and node.value in names:
            named = node.value
        elif isinstance(node, ast.Name) and node.id in camel:
            named = node.id
        elif isinstance(node, ast.Attribute) and node.attr in names and not (
                isinstance(node.value, ast.Name) and node.value.id in ours):
            named = node.attr
        if named is not None:
            shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
            yield (f"{shown}:{getattr(node, 'lineno', 0)}: names the MTurk "
                   f"operation {named!r}; only backend/crowd/providers/ speaks to a crowd")


def sources(args: list[str]) -> Iterator[Path]:
    for arg in args or ["backend"]:
        target = (ROOT / arg).resolve()
        for path in sorted([target] if target.is_file() else target.rglob("*.py")):
            relative = path.relative_to(ROOT).as_posix()
            if not relative.startswith(ALLOWED):
                yield path


def main(args: list[str]) -> int:
    camel, snake = operations()
    found = [line for path in sources(args) for line in findings(path, camel, snake)]
    for line in found:
        sys.stderr.write(line + "\n")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
