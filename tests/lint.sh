#!/usr/bin/env bash
# Lint and type checks: ruff over the Python sources, mypy over the product packages, the
# import contracts (domains import downwards only; worker/ reaches backend/ only through
# worker/tasks.py), with the rules in pyproject.toml, and the crowd seam (no MTurk operation
# named outside backend/crowd/providers/: tests/lint_crowd_seam.py). Exits non-zero on any
# finding.
# Needs the test extras installed in the virtualenv (tests/run.sh installs them).
# Usage: bash tests/lint.sh
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=${DEXLABEL_VENV:-.venv}
status=0
echo "ruff check backend worker bench migrations tests"
"$VENV/bin/ruff" check --no-cache backend worker bench migrations tests || status=1
echo "mypy backend worker"
"$VENV/bin/mypy" backend worker || status=1
echo "lint-imports (the layer contracts in pyproject.toml)"
"$VENV/bin/lint-imports" --no-cache || status=1
echo "crowd seam (MTurk operations only in backend/crowd/providers/)"
"$VENV/bin/python" tests/lint_crowd_seam.py || status=1
exit "$status"
