"""Running a benchmark as a reader does and checking its JSON line (bench/smoke.py and
bench/headline.py).

A ``Run`` names a bench script, its arguments (``{capture}``-style placeholders filled from
the run's ``Context``: small synthetic captures made on first use, a PostgreSQL URL of the
run's own), the keys its last JSON line must hold (dotted paths into nested objects) and the
values some of them must equal. ``run_bench`` runs it in a process of its own from the
repository root and returns what a summary reports.
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
# Where CI (or a person) says that a missing tool is a failure rather than a skip.
STRICT = os.environ.get("CI") == "true" or os.environ.get("DEXLABEL_TEST_REQUIRE_SERVICES") == "1"
CHROMIUM = os.environ.get("DEXLABEL_CHROMIUM", "/usr/bin/chromium")
PG_SERVER = os.environ.get("DEXLABEL_TEST_POSTGRES_URL",
                           "postgresql+psycopg://postgres@127.0.0.1:5432/postgres")


@dataclass(frozen=True)
class Run:
    """One bench command and what its last line must say."""

    bench: str                                  # script name under bench/, without .py
    args: tuple[str, ...]  # may hold {capture}, {fast_capture}, {pg_url}, {work}
    keys: tuple[str, ...]                       # dotted paths that must be present, not null
    equal: dict[str, Any] = field(default_factory=dict)  # dotted path -> required value
    needs: tuple[str, ...] = ()                 # "chromium", "postgres"
    timeout_s: float = 600.0


class Context:
    """What runs share: small captures (made once, on first use) and a scratch folder
    (removed at exit unless DEXLABEL_BENCH_KEEP is set)."""

    def __init__(self, work: Path | None = None) -> None:
        self.work = work or Path(tempfile.mkdtemp(prefix="dexlabel-bench-runs-"))
        if work is None and not os.environ.get("DEXLABEL_BENCH_KEEP"):
            atexit.register(shutil.rmtree, self.work, ignore_errors=True)
        self._made: dict[str, Path] = {}

    def capture(self, name: str, frames: int, views: int = 4) -> Path:
        """A synthetic capture (seed 7, 1 object, 640x480) of ``frames`` x ``views``."""
        if name not in self._made:
            sys.path.insert(0, str(ROOT))
            from worker.synth import generate_capture

            out = self.work / name
            generate_capture(out, seed=7, frames=frames, views=views, objects=1, workers=1)
            self._made[name] = out
        return self._made[name]

    def fill(self, arg: str) -> str:
        """``arg`` with its placeholders replaced ({work}: the scratch folder)."""
        arg = arg.replace("{work}", str(self.work))
        if "{capture}" in arg:
            arg = arg.replace("{capture}", str(self.capture("capture", 12)))
        if "{fast_capture}" in arg:
            arg = arg.replace("{fast_capture}", str(self.capture("fast_capture", 6)))
        if "{pg_url}" in arg:
            base = PG_SERVER.rsplit("/", 1)[0]
            arg = arg.replace("{pg_url}", f"{base}/dexlabel_bench_runs_{os.getpid()}")
        return arg


def missing_tool(run: Run) -> str | None:
    """Why ``run`` cannot run on this machine, or None."""
    if "chromium" in run.needs and not Path(CHROMIUM).exists():
        return f"Chromium is not installed at {CHROMIUM}"
    if "postgres" in run.needs and (shutil.which("pg_isready") is None or subprocess.run(
            ["pg_isready", "-q", "-h", "127.0.0.1", "-p", "5432"]).returncode != 0):
        return "PostgreSQL is not answering on 127.0.0.1:5432"
    return None


def lookup(obj: Any, path: str) -> Any:
    """The value at dotted ``path`` in nested dicts; KeyError naming the path if absent."""
    for part in path.split("."):
        if not isinstance(obj, dict) or part not in obj:
            raise KeyError(path)
        obj = obj[part]
    return obj


def check(line: dict[str, Any], run: Run) -> list[str]:
    """Problems with a bench's JSON line: keys missing or null, values not as required."""
    problems = []
    for path in run.keys:
        try:
            if lookup(line, path) is None:
                problems.append(f"{path} is null")
        except KeyError:
            problems.append(f"{path} missing")
    for path, want in run.equal.items():
        try:
            got = lookup(line, path)
        except KeyError:
            problems.append(f"{path} missing")
            continue
        if got != want:
            problems.append(f"{path} is {got!r}, not {want!r}")
    return problems


def last_json(stdout: str) -> dict[str, Any] | None:
    """The last non-empty stdout line as a JSON object, or None."""
    lines = [ln for ln in stdout.splitlines() if ln.strip()]
    try:
        value = json.loads(lines[-1]) if lines else None
    except json.JSONDecodeError:
        return None
    return value if isinstance(value, dict) else None


def run_bench(run: Run, ctx: Context) -> dict[str, Any]:
    """Run one bench; {"ok", "seconds", "command", "problems"} and "line" (its JSON), or
    "skipped" (a tool this machine lacks, outside CI)."""
    why = missing_tool(run)
    if why is not None:
        return {"ok": not STRICT, "skipped": why, "seconds": 0.0, "problems": [] if not STRICT
                else [f"{why} (a failure in CI)"]}
    argv = [ctx.fill(a) for a in run.args]
    command = f"python bench/{run.bench}.py {' '.join(argv)}".strip()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    started = time.perf_counter()
    try:
        out = subprocess.run([sys.executable, str(BENCH / f"{run.bench}.py"), *argv],
                             cwd=ROOT, env=env, capture_output=True, text=True,
                             timeout=run.timeout_s)
    except subprocess.TimeoutExpired:
        return {"ok": False, "command": command, "seconds": round(time.perf_counter() - started, 1),
                "problems": [f"no answer in {run.timeout_s:.0f} s"]}
    seconds = round(time.perf_counter() - started, 1)
    line = last_json(out.stdout)
    problems = [] if out.returncode == 0 else [f"exit {out.returncode}: {out.stderr[-1500:]}"]
    if line is None:
        problems.append("its last line is not a JSON object")
    else:
        problems += check(line, run)
    return {"ok": not problems, "command": command, "seconds": seconds, "problems": problems,
            "line": line}
