"""Re-run the headline figures of every section of BENCHMARKS.md (and the README's page, import
and marketplace benchmarks), each with the command its section names.

For each section, its benches run one after another in processes of their own, at the
section's size (the commands below), and the figures a reader takes from the section are read
from each bench's JSON line. With ``--quick`` every bench runs at the smoke size of
bench/smoke.py instead (a check that the commands still work, not figures to quote).

Prints a line per bench as it ends, then one JSON object on its last line: {"ok", "quick",
"commit", "load" (1/5/15-minute load average at the start and the end), "seconds",
"sections": {title: {bench: {"command", "seconds", "ok", "problems", "figures": {key:
value}}}}}. Exits 1 if any bench failed.

Default run here (2 shared cores): several hours (bench/qc.py's scenarios alone take well
over half an hour, the solve scenarios 10-20 minutes, the drills 10); one section with
``--section``; ``--quick``: about 5-6 minutes on a quiet machine.

    python bench/headline.py [--quick] [--section QC --section Solve] [--list]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _runs import Context, Run, lookup, run_bench
from smoke import QUICK, commit

HOURS = 4 * 3600.0
PG = ("postgres",)

SECTIONS: dict[str, list[Run]] = {
    "Drills": [Run("drills", ("all",), ("drills",), equal={"ok": True}, needs=PG,
                   timeout_s=HOURS)],
    "DexYCB-sized database": [Run("scale_db", ("--url", "{pg_url}", "--repeat", "7"),
                                  ("fill_s", "db_size", "observations", "queries"), needs=PG,
                                  timeout_s=HOURS)],
    "Load": [Run("load", ("--db", "postgres", "--workers", "2", "--annotators", "200",
                          "--seconds", "60", "--bursts", "2", "--alone", "0"),
                 ("saves_per_s", "save_ms.p50", "save_ms.p99", "save_ms.max", "save_errors",
                  "page_loads", "page_load_ms.p99", "lost", "committed_unacknowledged"),
                 needs=PG, timeout_s=HOURS)],
    "Solve": [Run("solve", ("--work", "{work}/solve", "--capture-seed", "23", "--crowd-seed",
                            "1", "--scenario", "all", "--paper-frames", "16"),
                  ("runs.8views.mpjpe_mm", "runs.4views.mpjpe_mm", "runs.gross15.mpjpe_mm",
                   "speed.speed_ratio_same_frames", "default_total_seconds"),
                  timeout_s=HOURS)],
    "Export": [Run("export", (), ("runs", "peak_memory_ratio_all_over_10",
                                  "export_growth_mb_10_and_all"), timeout_s=HOURS),
               Run("coco_eval", ("--seed", "101", "--views", "4", "--frames", "36"),
                   ("AP", "AP50", "AP75", "mean_px_error", "crowd"), timeout_s=HOURS)],
    "QC": [Run("qc", ("--capture-seed", "71", "--crowd-seed", "505", "--draws", "10",
                      "--object-draws", "3", "--object-poses", "truth,solved"),
               ("scenarios",), timeout_s=HOURS)],
    "Tracking proposals (assisted annotation)": [
        Run("assist", ("--views", "8", "--crowd-seed", "9", "--draws", "4", "--solve", "fast",
                       "--runs", "3"),
            ("default.actions_ratio", "default.today.actions_per_task",
             "default.assisted.actions_per_task", "default.today.label_error_px.mean",
             "default.assisted.label_error_px.mean", "default.blind.label_error_px.mean",
             "fast.actions_ratio", "fast.today.mpjpe_mm", "fast.assisted.mpjpe_mm",
             "proposals", "timing_ms", "qc.confusion", "targets"), timeout_s=HOURS),
        Run("prefill", ("--runs", "3"), ("error", "suggested", "visibility", "timing_ms"),
            timeout_s=HOURS)],
    "README: page, import, marketplace, API process": [
        Run("annotate", (), QUICK["annotate"].keys, needs=("chromium",), timeout_s=HOURS),
        Run("import", (), QUICK["import"].keys, timeout_s=HOURS),
        Run("market", (), QUICK["market"].keys, timeout_s=HOURS),
        Run("api_memory", (), QUICK["api_memory"].keys, equal=QUICK["api_memory"].equal,
            timeout_s=HOURS)],
}


def _figures(line: dict[str, Any] | None, run: Run) -> dict[str, Any]:
    figures: dict[str, Any] = {}
    for path in (*run.keys, *run.equal) if line else ():
        try:
            figures[path] = lookup(line, path)
        except KeyError:
            figures[path] = None
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     epilog="Default run here: several hours; --quick about "
                                            "5-6 minutes quiet; --section runs one section.")
    parser.add_argument("--quick", action="store_true", help="every bench at its smoke size")
    parser.add_argument("--section", action="append", default=[],
                        help=f"a section to run (repeatable): {'; '.join(SECTIONS)}")
    parser.add_argument("--list", action="store_true", help="print the commands, run nothing")
    args = parser.parse_args()
    unknown = sorted(set(args.section) - set(SECTIONS))
    if unknown:
        parser.error(f"unknown section(s) {unknown}; known: {'; '.join(SECTIONS)}")
    chosen = {t: [QUICK[r.bench] if args.quick else r for r in runs]
              for t, runs in SECTIONS.items() if not args.section or t in args.section}
    if args.list:
        for title, runs in chosen.items():
            for run in runs:
                print(f"{title}: python bench/{run.bench}.py {' '.join(run.args)}")
        return
    ctx = Context()
    load_start = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    out: dict[str, dict[str, Any]] = {}
    for title, runs in chosen.items():
        out[title] = {}
        for run in runs:
            result = run_bench(run, ctx)
            result["figures"] = _figures(result.pop("line", None), run)
            out[title][run.bench] = result
            print(f"{title}, {run.bench}: {json.dumps(result)}", flush=True)
    ok = all(r["ok"] for section in out.values() for r in section.values())
    print(json.dumps({"ok": ok, "quick": args.quick, "commit": commit(),
                      "load": {"start": load_start,
                               "end": [round(x, 2) for x in os.getloadavg()]},
                      "seconds": round(time.perf_counter() - started, 1), "sections": out}))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
