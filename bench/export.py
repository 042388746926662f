"""Benchmark of the label export: a project of many synthetic sequences in every format.

Builds a project in a fresh instance folder: one small synthetic capture (default 4 views x 24
frames at 160x120, 2 objects) imported under N different sequence names, each with its hand
tasks accepted (labels = the capture's ground-truth joint_2d) and a finished solve run whose
stored result is the ground truth. Then exports the first 10 and all N sequences in each format
(dexycb with frames copied; bop with frames copied; coco, cvat, json), each export in a process
of its own so its peak memory (ru_maxrss) is its own; that peak is mostly the modules the
export loads, so each run also reports ``export_growth_mb``, how far its resident memory rose
above where it stood once a one-sequence warm-up export had loaded everything (sampled every
10 ms). Prints one JSON object on its last line.

    python bench/export.py [--sequences 50] [--frames 24] [--views 4] [--size 160x120]
                           [--archive zip|tar]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import resource
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FORMATS = {"dexycb": {"frames": "copy"}, "bop": {"frames": "copy"}, "coco": {}, "cvat": {},
           "json": {}}


def _env(var: Path) -> None:
    os.environ["DEXLABEL_VAR_DIR"] = str(var)
    os.environ["DEXLABEL_ENV"] = "test"


def _stored_truth_solve(seq_dir: Path, serials: list[str]) -> bytes:
    """A solve result (backend.solve.results) holding the capture's ground truth."""
    import numpy as np
    import yaml

    from backend.solve.results import encode_result
    from worker.formats import dexycb
    from worker.geometry.transforms import quaternion_to_matrix

    pose = np.load(seq_dir / dexycb.POSE_FILE)
    frames = pose["pose_y"].shape[0]
    rot = quaternion_to_matrix(pose["pose_y"][..., :4].astype(np.float64))
    object_poses = np.concatenate([rot, pose["pose_y"][..., 4:, None]], axis=-1)
    # The master camera's frame is the world: its joint_3d are world joints.
    joints = np.stack([np.load(seq_dir / serials[0] / dexycb.labels_file(f))["joint_3d"][0]
                       for f in range(frames)]).astype(np.float64)
    meta = yaml.safe_load((seq_dir / dexycb.META_FILE).read_text())
    root = seq_dir.parent.parent
    betas = yaml.safe_load((root / dexycb.mano_file(meta["mano_calib"][0])).read_text())["betas"]
    result = SimpleNamespace(
        hand_pose_m=pose["pose_m"][:, 0].astype(np.float64), hand_joints=joints,
        object_poses=np.transpose(object_poses, (1, 0, 2, 3)), labelled=np.ones(frames, bool),
        reasons=[""] * frames, kpt_error_px=np.zeros((frames, len(serials), 21)),
        depth_rms_mm=np.zeros(frames), landmark_vertices=[[] for _ in meta["ycb_ids"]],
        betas=np.asarray(betas),
        object_confidence=np.ones((len(meta["ycb_ids"]), frames)),
        object_flags=[[""] * frames for _ in meta["ycb_ids"]])
    return encode_result(result, serials, [dexycb.YCB_CLASSES[i] for i in meta["ycb_ids"]],
                         "right")


def build_project(var: Path, work: Path, count: int, frames: int, views: int, width: int,
                  height: int) -> int:
    """Import ``count`` copies of one capture with accepted hand labels and a done solve."""
    _env(var)
    from backend.annotation.models import Track
    from backend.annotation.service import create_assignment, create_tasks
    from backend.captures.flows import import_path
    from backend.captures.models import Camera, Sequence
    from backend.config import get_settings
    from backend.db import session_scope, utcnow
    from backend.migrate import upgrade
    from backend.solve.models import SolveRun
    from backend.solve.results import result_key
    from backend.storage import get_storage
    from worker.formats import dexycb
    from worker.synth import generate_capture
    from worker.synth.annotators import hand_visibility

    upgrade(get_settings().database_url or "")
    capture = work / "capture"
    generate_capture(capture, seed=11, frames=frames, views=views, objects=2, width=width,
                     height=height, workers=1)
    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    serials = [p.name for p in sorted(seq_dir.iterdir()) if p.is_dir()]
    import numpy as np

    truth = {s: [np.load(seq_dir / s / dexycb.labels_file(f)) for f in range(frames)]
             for s in serials}
    solve_bytes = _stored_truth_solve(seq_dir, sorted(serials))
    for i in range(count):
        copy = work / f"copy_{i:03d}"
        shutil.copytree(capture, copy, copy_function=os.link)
        (copy / seq_dir.parent.name / seq_dir.name).rename(
            copy / seq_dir.parent.name / f"bench_{i:03d}")
        seq_id = import_path(copy)[0].sequence_id
        with session_scope() as session:
            seq = session.get_one(Sequence, seq_id)
            for task in create_tasks(session, get_storage(), seq_id):
                if task.kind != "hand":
                    continue
                cam = session.get_one(Camera, task.camera_id)
                joint_2d = np.stack([lab["joint_2d"][0] for lab in truth[cam.serial]])
                seg = np.stack([lab["seg"] for lab in truth[cam.serial]])
                visible = hand_visibility(joint_2d.astype(np.float64), seg)
                assignment = create_assignment(session, task, f"W{i % 7}")
                assignment.status, assignment.version = "approved", 1
                for j in range(21):
                    rows = [[f, float(x), float(y), int(v)] if 0 <= x < cam.width
                            and 0 <= y < cam.height else [f, None, None, 0]
                            for f, ((x, y), v) in enumerate(zip(joint_2d[:, j],
                                                                visible[:, j], strict=True))]
                    session.add(Track(assignment_id=assignment.id, point_index=j,
                                      keyframes=rows))
            run = SolveRun(sequence_id=seq_id, optimiser="default", params={}, status="done",
                           timings={}, num_frames=frames, num_views=views,
                           finished_at=utcnow())
            session.add(run)
            session.flush()
            run.result_key = result_key(seq.storage_uid, run.id)
            get_storage().put_bytes(run.result_key, solve_bytes)
        shutil.rmtree(copy)
    return count


def _rss_mb() -> float:
    """This process's resident memory now, MB."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def _one_export(var: str, fmt: str, ids: list[int], out: str, queue: Any) -> None:
    _env(Path(var))
    from backend.exports.service import run_export

    # A one-sequence export first, to a throwaway path: every module and cache the format
    # uses is loaded before the measured export starts.
    warm = Path(out).with_name(f"warm-{Path(out).name}")
    run_export(fmt, ids[:1], "accepted", FORMATS[fmt], warm)
    warm.unlink(missing_ok=True)
    before = _rss_mb()
    peak = [before]
    done = threading.Event()

    def watch() -> None:  # resident memory every 10 ms while the export runs
        while not done.wait(0.01):
            peak[0] = max(peak[0], _rss_mb())

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    started = time.perf_counter()
    result = run_export(fmt, ids, "accepted", FORMATS[fmt], Path(out))
    seconds = time.perf_counter() - started
    done.set()
    watcher.join()
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    queue.put({"seconds": seconds, "bytes": result["bytes"], "frames": result["frames"],
               "peak_mb": peak_mb, "growth_mb": max(peak[0], _rss_mb()) - before})


def run_one(var: Path, fmt: str, ids: list[int], out: Path) -> dict[str, Any]:
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_one_export, args=(str(var), fmt, ids, str(out), queue))
    proc.start()
    figures: dict[str, Any] = queue.get()
    proc.join()
    out.unlink(missing_ok=True)
    return {"frames": figures["frames"], "seconds": round(figures["seconds"], 2),
            "frames_per_s": round(figures["frames"] / figures["seconds"], 1),
            "mb": round(figures["bytes"] / 1e6, 2),
            "mb_per_s": round(figures["bytes"] / 1e6 / figures["seconds"], 2),
            "peak_mb": round(figures["peak_mb"], 1),
            "export_growth_mb": round(figures["growth_mb"], 1)}


EPILOG = ("Default run here (2 shared cores): about 5 minutes (50 sequences, every format"
          " twice, each export in a process of its own). Short: --sequences 2 --frames 4"
          " --views 2 (every format once, about 1 minute).")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=EPILOG)
    parser.add_argument("--sequences", type=int, default=50)
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--size", default="160x120")
    parser.add_argument("--archive", choices=("zip", "tar"), default="zip",
                        help="a zip keeps one central-directory entry per file in memory "
                             "until it is closed; a tar keeps none")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    work = Path(tempfile.mkdtemp(prefix="dexlabel-bench-export-"))
    try:
        var = work / "var"
        started = time.perf_counter()
        build_project(var, work, args.sequences, args.frames, args.views, width, height)
        build_s = time.perf_counter() - started
        _env(var)
        from backend.captures.models import Sequence
        from backend.db import session_scope

        with session_scope() as session:
            ids = list(session.scalars(__import__("sqlalchemy").select(Sequence.id)
                                       .order_by(Sequence.id)))
        runs: dict[str, dict[str, Any]] = {}
        # The first 10 sequences and all of them (one run when there are 10 or fewer).
        sizes = sorted({min(10, len(ids)), len(ids)})
        for fmt in FORMATS:
            for n in sizes:
                runs[f"{fmt}_{n}"] = run_one(var, fmt, ids[:n],
                                             work / f"{fmt}_{n}.{args.archive}")
                print(fmt, n, runs[f"{fmt}_{n}"], flush=True)
        growth = {fmt: round(runs[f"{fmt}_{sizes[-1]}"]["peak_mb"]
                             / runs[f"{fmt}_{sizes[0]}"]["peak_mb"], 3) for fmt in FORMATS}
        export_growth = {fmt: [runs[f"{fmt}_{n}"]["export_growth_mb"] for n in sizes]
                         for fmt in FORMATS}
        summary = {
            "sequences": len(ids), "views": args.views, "frames": args.frames,
            "size": args.size, "archive": args.archive, "build_s": round(build_s, 1),
            "runs": runs,
            "peak_memory_ratio_all_over_10": growth,
            "export_growth_mb_10_and_all": export_growth,
            "targets": {"peak_memory_flat": all(r <= 1.15 for r in growth.values())},
            "load": os.getloadavg(),
        }
        print(json.dumps(summary))
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
