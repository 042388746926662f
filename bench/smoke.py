"""Smoke run: every benchmark under bench/ at its smallest meaningful size, checked.

Every script bench/*.py but the private helpers (_*.py) and the two runners (smoke.py,
headline.py) must have an entry in QUICK below; a script without one fails the run, so a new
bench is smoke-run from the day it lands. Each bench runs in a process of its own, from the
repository root, on small synthetic captures made once for the run (4 views x 12 frames and
4 x 6, 1 object, 640x480), a few seconds of load, one crowd, one draw; its last stdout line must
be a JSON object holding the keys listed here (dotted paths into nested objects, present and
not null; a few values must equal what is given, e.g. a drill's "ok").

A bench that needs a tool the machine lacks (annotate: Chromium; scale_db: PostgreSQL) is
skipped, except in CI (CI=true or DEXLABEL_TEST_REQUIRE_SERVICES=1), where that
is a failure. scale_db fills a database of its own on the machine's PostgreSQL
(dexlabel_bench_runs_PID, dropped at the end).

Prints one line per bench as it ends, then one JSON object on its last line: {"ok", "seconds",
"cpu_s" (CPU seconds of the run and the benches it waited for), "load" (1/5/15-minute load
average at the start and the end), "commit", "benches": {name:
{"ok", "seconds", "command", "problems"} or {"skipped"}}}. Exits 1 if any bench failed.

Length here (2 cores): 15.6 minutes at a load average of about 20 (other people's work on the
cores), of which 296 CPU seconds were the run's own; on a quiet machine about 5-6 minutes (an
estimate: that CPU time plus the kill-qc drill's waits, not a measurement).

    python bench/smoke.py [--only assist,qc] [--list]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _runs import BENCH, ROOT, Context, Run, run_bench

RUNNERS = {"smoke", "headline"}

QUICK: dict[str, Run] = {
    "api_memory": Run("api_memory", ("--rounds", "1"),
                      ("rss_mb", "peak_rss_mb", "create_app_s", "modules"),
                      equal={"torch_loaded": False, "solver_loaded": False}),
    "annotate": Run("annotate", ("--frames", "6", "--views", "2", "--steps", "10"),
                    ("first_frame_ms_median", "all_frames_ms_median", "step_ms_median",
                     "step_ms_p99", "autosave_bytes"), needs=("chromium",)),
    "assist": Run("assist", ("--capture", "{capture}", "--fast-capture", "{fast_capture}",
                             "--runs", "1", "--draws", "1", "--solve", "fast"),
                  ("default.actions_ratio", "default.today.actions_per_task",
                   "default.assisted.actions_per_task", "default.assisted.label_error_px.mean",
                   "default.blind.label_error_px.mean", "fast.actions_ratio",
                   "fast.today.mpjpe_mm", "fast.assisted.mpjpe_mm",
                   "proposals.interpolation.between.mean_px",
                   "proposals.assisted.between.mean_px", "proposals.assisted.proposed",
                   "timing_ms.pure", "timing_ms.endpoint", "qc.blind_flagged_rate",
                   "qc.careful_flagged_rate", "targets")),
    "coco_eval": Run("coco_eval", ("--views", "4", "--frames", "12", "--rounds", "3"),
                     ("AP", "AP50", "AP75", "mean_px_error", "crowd", "seconds")),
    "cost": Run("cost", ("--views", "4", "--frames", "12", "--protocols",
                         "dexycb,ours,assisted", "--publish", "adaptive"),
                ("protocols.dexycb.hand.actions_per_frame", "protocols.ours.hand.actions_per_frame",
                 "protocols.ours.hand.money_per_frame", "protocols.ours.mpjpe_mm",
                 "protocols.ours.add_mm", "ratios.actions", "ratios.money",
                 "protocols.assisted.hand.actions_per_frame", "assisted_ratios.actions",
                 "protocols.assisted.views_published.hand:0"),
                equal={"protocols.ours.unaccepted_tasks": 0,
                       "protocols.dexycb.unaccepted_tasks": 0,
                       "protocols.assisted.unaccepted_tasks": 0}, timeout_s=900.0),
    "drills": Run("drills", ("kill-qc",), ("kill_to_done_s", "attempts", "payments"),
                  equal={"drill": "kill-qc", "ok": True, "assignments_paid_twice": 0}),
    "export": Run("export", ("--sequences", "2", "--frames", "4", "--views", "2"),
                  ("runs.dexycb_2.seconds", "runs.bop_2.seconds", "runs.coco_2.frames_per_s",
                   "runs.cvat_2.seconds",
                   "runs.json_2.seconds", "runs.json_2.peak_mb", "runs.json_2.export_growth_mb",
                   "peak_memory_ratio_all_over_10", "build_s")),
    "export_truth": Run("export_truth", ("--demo", "12,3,1", "--seed", "7"),
                        ("summary.hand_mm_mean", "summary.labelled_share_min",
                         "summary.labelled_frames_over_max", "summary.cross_camera_spread_mm")),
    "follow": Run("follow", ("--capture", "{capture}", "--max-views", "1"),
                  ("mean.lk_edits", "mean.model_edits", "mean.follow_proposed", "seconds")),
    "import": Run("import", ("--frames", "6", "--views", "2", "--rounds", "1"),
                  ("synth_s", "import_s", "bundle_cold_fps", "bundle_warm_fps",
                   "single_frame_fps")),
    "load": Run("load", ("--capture", "{capture}", "--annotators", "4", "--seconds", "3",
                         "--bursts", "1", "--burst", "2", "--alone", "20"),
                ("saves", "saves_per_s", "save_ms.p50", "save_ms.p99", "save_errors",
                 "page_loads", "page_load_ms.p99", "committed_unacknowledged"),
                equal={"lost": 0}),
    "market": Run("market", ("--hits", "10", "--calls", "5"),
                  ("create_hit_per_s", "publish_1000_s", "list_assignments_per_s",
                   "get_account_balance_per_s", "publish_flow_1000_s",
                   "publish_flow_hits_per_s")),
    "prefill": Run("prefill", ("--capture", "{capture}", "--runs", "1", "--targets", "1"),
                   ("error", "suggested", "visibility", "timing_ms.endpoint.first",
                    "timing_ms.endpoint.again", "timing_ms.pure",
                    "by_accepted_views.hand.1.median_px", "by_accepted_views.hand.2.median_px",
                    "by_accepted_views.hand.3+.median_px")),
    # Without the optional extra (MediaPipe) it only says so: {"available": false}.
    "prelabel": Run("prelabel", ("--frames", "6", "--views", "2"),
                    ("available", "seed", "frames", "views")),
    "qc": Run("qc", ("--capture", "{capture}", "--scenario", "hands-4,objects-4", "--draws", "1",
                     "--object-poses", "truth"),
              ("scenarios.hands-4.bad_flagged_rate", "scenarios.hands-4.good_flagged_rate",
               "scenarios.hands-4.swaps_found", "scenarios.hands-4.settled.careful_flagged",
               "scenarios.objects-4.bad_flagged_rate",
               "scenarios.objects-4.good_flagged_rate")),
    "rig_faults": Run("rig_faults", ("--capture", "{capture}", "--cache", "{work}/rig_cache",
                                     "--fault", "late1"),
                      ("mpjpe_faulty_mm", "mpjpe_refined_mm", "named", "seconds")),
    "scale_db": Run("scale_db", ("--sequences", "2", "--repeat", "1", "--url", "{pg_url}"),
                    ("sequences", "tasks", "observations", "fill_s", "db_bytes", "queries"),
                    needs=("postgres",)),
    "solve": Run("solve", ("--capture", "{capture}", "--work", "{work}/solve", "--frames", "4",
                           "--paper-frames", "2"),
                 ("runs.run.mpjpe_mm", "runs.run.seconds", "speed.speed_ratio_same_frames",
                  "default_total_seconds")),
    # Skips (ok) unless DEXYCB_TOOLKIT / BOP_TOOLKIT (and TOOLKIT_PYTHON) name the checkouts.
    "toolkit_readers": Run("toolkit_readers", ("--demo", "12,3,1", "--seed", "7"),
                           ("dexycb", "bop"), equal={"ok": True}),
}


def benches() -> list[str]:
    """The bench scripts: bench/*.py but the private helpers and the runners."""
    return sorted(p.stem for p in BENCH.glob("*.py")
                  if not p.name.startswith("_") and p.stem not in RUNNERS)


def commit() -> str:
    out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                         capture_output=True, text=True)
    return out.stdout.strip() or "unknown"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="About 5-6 minutes here on a quiet machine (15.6 at a load average of 20); "
               "--only runs a few benches.")
    parser.add_argument("--only", default="", help="comma-separated bench names")
    parser.add_argument("--list", action="store_true", help="print the commands, run nothing")
    args = parser.parse_args()
    names = benches()
    chosen = [n.strip() for n in args.only.split(",") if n.strip()] or names
    unknown = sorted(set(chosen) - set(names))
    if unknown:
        parser.error(f"no bench script named {unknown}; benches: {', '.join(names)}")
    ctx = Context()
    if args.list:
        for name in chosen:
            run = QUICK.get(name)
            print(f"{name}: " + (f"python bench/{name}.py {' '.join(run.args)}" if run
                                 else "no smoke entry"))
        return
    load_start = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    results: dict[str, dict] = {}
    for name in chosen:
        run = QUICK.get(name)
        if run is None:
            results[name] = {"ok": False, "problems": [
                f"bench/{name}.py has no entry in bench/smoke.py's QUICK"]}
        else:
            results[name] = run_bench(run, ctx)
            results[name].pop("line", None)
        print(f"smoke {name}: {json.dumps(results[name])}", flush=True)
    ok = all(r["ok"] for r in results.values())
    print(json.dumps({"ok": ok, "seconds": round(time.perf_counter() - started, 1),
                      "cpu_s": _cpu_s(),
                      "load": {"start": load_start,
                               "end": [round(x, 2) for x in os.getloadavg()]},
                      "commit": commit(), "benches": results}))
    sys.exit(0 if ok else 1)


def _cpu_s() -> float:
    """CPU seconds (user + system) of this run and every bench process it waited for: what
    the run costs whatever else the machine is doing."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return round(own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime, 1)


if __name__ == "__main__":
    main()
