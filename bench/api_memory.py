"""Benchmark: what an API process costs before it serves anything.

Each round starts a fresh Python process (embedded settings in a temp folder) that imports
backend.app and calls create_app(), then reads its own memory from /proc/self/status. An API
process should not load PyTorch or the solver: `serve --workers N` pays this N times.

Prints a JSON summary on its last line:
    rss_mb           resident memory after create_app(), MB (VmRSS; median over rounds)
    peak_rss_mb      the process's peak resident memory, MB (VmHWM; median)
    create_app_s     seconds from before `import backend.app` to create_app() returned (median)
    create_app_s_all every round's seconds
    modules          modules loaded after create_app() (median)
    torch_loaded     whether any round found `torch` in sys.modules
    solver_loaded    whether any round found the solver's numerics (worker.solver.entry)
    target_rss_mb    200; within_target: rss_mb <= target_rss_mb
    load             1-minute load average at the start and the end (timings depend on it)
Usage: python bench/api_memory.py [--rounds 5]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from _server import isolated_workdir

ROOT = Path(__file__).resolve().parent.parent
TARGET_RSS_MB = 200

# Run in the fresh process: time the import and create_app(), then report memory and modules.
_PROBE = """
import json, sys, time
started = time.perf_counter()
from backend.app import create_app
create_app()
seconds = time.perf_counter() - started
status = dict(line.split(":", 1) for line in open("/proc/self/status") if ":" in line)
kb = lambda key: int(status[key].split()[0])
print(json.dumps({"seconds": seconds, "rss_kb": kb("VmRSS"), "hwm_kb": kb("VmHWM"),
                  "modules": len(sys.modules), "torch": "torch" in sys.modules,
                  "solver": "worker.solver.entry" in sys.modules}))
"""

EPILOG = "About 2 s a round on a quiet machine; the smoke run uses --rounds 1."


def probe() -> dict[str, float]:
    """One fresh process's figures (see _PROBE)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    out = subprocess.run([sys.executable, "-c", _PROBE], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=300, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"create_app() failed in a fresh process: {out.stderr[-2000:]}")
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=EPILOG)
    parser.add_argument("--rounds", type=int, default=5, help="fresh processes to measure")
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error(f"--rounds must be at least 1, got {args.rounds}")
    isolated_workdir("api-memory")
    load_start = round(os.getloadavg()[0], 2)
    rounds = [probe() for _ in range(args.rounds)]
    rss_mb = round(statistics.median(r["rss_kb"] for r in rounds) / 1024, 1)
    print(json.dumps({
        "rss_mb": rss_mb,
        "peak_rss_mb": round(statistics.median(r["hwm_kb"] for r in rounds) / 1024, 1),
        "create_app_s": round(statistics.median(r["seconds"] for r in rounds), 3),
        "create_app_s_all": [round(r["seconds"], 3) for r in rounds],
        "modules": int(statistics.median(r["modules"] for r in rounds)),
        "torch_loaded": any(r["torch"] for r in rounds),
        "solver_loaded": any(r["solver"] for r in rounds),
        "target_rss_mb": TARGET_RSS_MB,
        "within_target": rss_mb <= TARGET_RSS_MB,
        "rounds": args.rounds,
        "load": {"start": load_start, "end": round(os.getloadavg()[0], 2)},
    }))


if __name__ == "__main__":
    main()
