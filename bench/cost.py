"""Benchmark: the cost of a labelled 3D frame, DexYCB's labelling protocol against ours, on the
same capture through the whole product path.

A synthetic capture no test uses (``--seed`` 7717, ``--views`` x ``--frames``, one object) is
labelled once per protocol, each in a fresh embedded instance of its own (a child process):
import, tasks, HITs on the built-in marketplace, a simulated crowd (backend.crowd.simulate,
``--profile`` careful by default) working through the portal and the annotation API, the
marketplace's confirmation, QC (approve, reject and re-open, or leave for the admin, who
approves the best as the demo's admin does), the solve of the accepted labels, payment. Then
the product's own figures: backend.progress.frame_costs (actions, working seconds, money per
labelled 3D frame, from the ledger), and against the capture's truth the hand's MPJPE (mm,
frames the solve labelled and trusts) and each object's ADD (mm, mean vertex distance over the
frames it trusts).

Protocols (backend.crowd.simulate.PROTOCOLS and ASSISTED):
    dexycb    every joint and landmark clicked on every frame in every view ("every-frame");
    ours      the product's keyframe worker: a keyframe every 4 frames, where the path bends and
              where visibility changes, interpolated in between ("keyframes");
    assisted  ours with the page's assistance ("assisted", worker.synth.assisted through the
              routes the page asks): a keyframe on the first frame and at visibility changes,
              each point followed forward and tracked between keyframes (POST
              /api/annotate/proposals), suggestions from the views already accepted (GET
              /api/annotate/suggestions) where there are any, every shown position further than
              worker.synth.assisted.TOLERANCE_PX from the point corrected, then accepted.

Effort is what the simulated worker earns on the page's counters: an action per keyframe (a
click, a key for an occluded one), with assistance what the page's edit counter records
(the worker's clicks, drags, occlusion keys and accepts; not the re-tracks the page writes by
itself after a correction), working time modelled as a minute of reading plus 3 s per action
(backend.crowd.simulate; no person is timed). "first_view_actions": per target, the edit
actions of its first accepted view (the accepted assignment submitted first), the view worked
with the least help; "view_actions": per target, each submitted assignment's view, actions, kept
suggestions, status, profile, QC outcome and whether an admin decided it; "qc_by_profile": per
simulated profile, units submitted and flagged by QC (left for review, or rejected). Money is
real ledger money for rewards priced per task at ``--hourly`` dollars an hour of that
protocol's expected working time (the mean over the tasks of a kind, from the same simulated
workers on the truth), plus the marketplace's fee; rejected work is done but not paid.

Prints a line per protocol (each instance's own progress on stderr), then one JSON line:
{"capture", "seed", "views", "frames", "profile", "crowd_seed", "hourly_usd", "protocols":
{name: {"hand", "objects", "total", "mpjpe_mm", "add_mm", "rewards_usd",
"first_view_actions", "view_actions", "failed_jobs" (key and last error line of each job
that failed), "seconds"}}, "ratios": {ours over dexycb per labelled hand frame: "actions",
"seconds", "money"}, "assisted_ratios": {assisted over dexycb, the same}} (each ratio block
only when both its protocols ran).

``--publish adaptive`` publishes each target's widest-baseline views first and more only
while the solve is unsure (backend.crowd.adaptive); the crowd comes back for each view the
solve asks for, until none is left ("views_published" per target, "publish_rounds"). The
DexYCB protocol is every view, whatever the setting (its own definition).

Usage: python bench/cost.py [--seed 7717] [--views 8] [--frames 72] [--profile careful]
           [--protocols dexycb,ours,assisted] [--publish every-view|adaptive]
           [--initial-views N] [--crowd-seed N]

``--crowd-seed`` draws another simulated crowd (which workers are blind acceptors, everyone's
noise); 0 is the demo's own, the same for every capture.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from _server import free_port, isolated_workdir

ROOT = Path(__file__).resolve().parents[1]
PROTOCOLS = {"dexycb": "every-frame", "ours": "keyframes", "assisted": "assisted"}


def _truth(capture: Path) -> tuple[np.ndarray, np.ndarray]:
    """(F, 21, 3) true hand joints and (O, F, 3, 4) object-to-world poses, world metres."""
    from backend.captures.layout import read_sequence
    from backend.captures.truth import CaptureTruth
    from worker.formats import dexycb

    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    plan = read_sequence(seq_dir)
    master = plan.cameras[0]
    joints = []
    for f in range(plan.num_frames):
        with np.load(seq_dir / master.serial / dexycb.labels_file(f)) as labels:
            joints.append(labels[dexycb.JOINT_3D][0].astype(np.float64))
    to_world = np.asarray(master.extrinsics, dtype=np.float64)
    world = np.stack(joints) @ to_world[:, :3].T + to_world[:, 3]
    return world, CaptureTruth(capture).object_poses()


def _rewards(capture: Path, tasks: list[dict], protocol: str, hourly: float) -> dict[str, int]:
    """Reward cents per task kind: ``hourly`` dollars an hour of the protocol's mean modelled
    working time over the kind's tasks (careful workers on the truth; with assistance, on the
    view's frames in process, without suggestions)."""
    from backend.captures.truth import CaptureTruth
    from backend.crowd.simulate import ASSISTED, working_seconds
    from backend.crowd.simulate import PROTOCOLS as STEPS
    from worker.synth.annotators import annotate, keyframe_actions

    truth, rng = CaptureTruth(capture), np.random.default_rng(0)
    seconds: dict[str, list[float]] = {}
    for task in tasks:
        xy, visible = truth.points(task, rng)
        if protocol == ASSISTED:
            actions = _assisted_edits(capture, task, xy, visible, rng)
        else:
            key_step, follow = STEPS[protocol]
            work = annotate(xy, visible, (task["width"], task["height"]), "careful", rng,
                            key_step, follow)
            effort = keyframe_actions(work.tracks)
            actions = effort["clicks"] + effort["drags"] + effort["keys"]
        seconds.setdefault(task["kind"], []).append(working_seconds(actions))
    return {kind: max(1, round(float(np.mean(s)) / 3600.0 * hourly * 100))
            for kind, s in seconds.items()}


def _assisted_edits(capture: Path, task: dict, xy: np.ndarray, visible: np.ndarray,
                    rng: np.random.Generator) -> int:
    """The page's edit count of a careful assisted worker on the task's view, the proposals
    computed in process (as the route computes them), no suggestions."""
    from _crowd_labels import grey_view

    from worker.assist.checks import check_key
    from worker.formats import dexycb
    from worker.synth.assisted import AssistSetting, assisted_annotate

    view = next(capture.glob(dexycb.META_GLOB)).parent / task["serial"]
    grey = grey_view(view, task["num_frames"])
    setting = AssistSetting(grey, check_key("rewards"), task["id"], follows=True,
                            retracks=True)
    return int(assisted_annotate(xy, visible, setting, "careful", rng).actions["edits"])


def _views(sequence_id: int, profiles: dict[str, str]) -> dict[str, list[dict[str, Any]]]:
    """Per target, each submitted assignment in submission order: its view (camera serial),
    edit actions, how many of its keyframes are suggestions kept unchanged (source
    "prefilled"), its status, the simulated worker's profile, what QC said when it last scored
    the target (approve, review or reject) and whether an admin decided it (QC had left it for
    review; a later scoring may read approve)."""
    from sqlalchemy import select
    from sqlalchemy.orm import selectinload

    from backend.annotation.models import Assignment, Task
    from backend.captures.models import Camera
    from backend.db import session_scope
    from backend.quality.models import ADMIN_DECIDED, QCReport

    out: dict[str, list[dict[str, Any]]] = {}
    with session_scope() as session:
        rows = session.execute(
            select(Task.target_key, Camera.serial, Assignment, QCReport.outcome,
                   QCReport.reasons, QCReport.action_detail)
            .join(Task, Task.id == Assignment.task_id)
            .join(Camera, Camera.id == Task.camera_id)
            .outerjoin(QCReport, QCReport.assignment_id == Assignment.id)
            .where(Task.sequence_id == sequence_id, Assignment.submitted_at.is_not(None))
            .options(selectinload(Assignment.tracks))
            .order_by(Assignment.submitted_at, Assignment.id)).all()
        for target, serial, work, qc, reasons, detail in rows:
            suggested = sum(len(r) > 4 and r[4] == "prefilled"
                            for t in work.tracks for r in t.keyframes)
            out.setdefault(target, []).append({"view": serial, "actions": int(work.edit_count),
                                               "suggested": suggested,
                                               "status": work.status, "qc": qc,
                                               "qc_reasons": reasons or [],
                                               "admin_decided": detail == ADMIN_DECIDED,
                                               "profile": profiles.get(work.external_id)})
    return out


def _qc_by_profile(views: dict[str, list[dict[str, Any]]]) -> dict[str, dict[str, Any]]:
    """Per simulated profile: submitted units, how many QC flagged (review or reject when it
    last scored them, or left for the admin who decided them), and that rate."""
    out: dict[str, dict[str, Any]] = {}
    for rows in views.values():
        for row in rows:
            line = out.setdefault(row["profile"] or "unknown", {"units": 0, "flagged": 0})
            line["units"] += 1
            line["flagged"] += int(row["qc"] in ("review", "reject") or row["admin_decided"])
    for line in out.values():
        line["flagged_rate"] = round(line["flagged"] / line["units"], 4)
    return out


def _first_views(views: dict[str, list[dict[str, Any]]]) -> dict[str, int]:
    """Per target, the edit actions of its first accepted view (the accepted assignment
    submitted first)."""
    from backend.labels import ACCEPTED

    return {target: next(v["actions"] for v in rows if v["status"] == ACCEPTED)
            for target, rows in views.items() if any(v["status"] == ACCEPTED for v in rows)}


def _setup(capture: Path) -> tuple[int, list[dict]]:
    """Migrate, import, create the tasks; (sequence id, tasks as the API reads them)."""
    from backend.annotation.service import create_tasks
    from backend.captures.flows import import_path
    from backend.config import get_settings
    from backend.db import session_scope
    from backend.migrate import upgrade
    from backend.storage import get_storage

    upgrade(get_settings().database_url)
    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        tasks = [{"id": t.id, "kind": t.kind, "serial": t.camera.serial,
                  "target_key": t.target_key, "object_id": t.object_id,
                  "width": t.camera.width, "height": t.camera.height,
                  "num_frames": t.sequence.num_frames}
                 for t in create_tasks(session, get_storage(), sequence_id)]
    return sequence_id, tasks


def _publish(sequence_id: int, rewards: dict[str, int], policy: str,
             initial_views: int | None = None) -> None:
    from backend.crowd import flows, pricing
    from backend.crowd.providers import get_provider
    from backend.crowd.schemas import PublishOptions

    marketplace = get_provider("mturk")
    for kind in ("hand", "object"):
        options = PublishOptions(max_assignments=1, provider="mturk", min_approval_rate=None,
                                 reward=pricing.cents_to_dollars(rewards[kind]),
                                 policy=policy, initial_views=initial_views)
        flows.publish_each(marketplace, options, sequence_id, kind)


def _accuracy(sequence_id: int, capture: Path) -> tuple[float | None, list[float]]:
    """Hand MPJPE (mm) over the frames the solve labelled and trusts; object ADD (mm)."""
    from _qc_pipeline import object_add_mm

    from backend.db import session_scope
    from backend.progress.frame_costs import labelled_masks
    from backend.solve.results import decode_result
    from backend.solve.service import current_run
    from backend.storage import get_storage

    joints, poses = _truth(capture)
    with session_scope() as session:
        run = current_run(session, sequence_id)
        key = None if run is None else run.result_key
    if key is None:
        return None, []
    arrays = decode_result(get_storage().get_bytes(key))
    trusted = labelled_masks(arrays, ["hand:0"])["hand:0"]
    err = np.linalg.norm(arrays["hand_joints"][trusted] - joints[trusted], axis=-1) * 1000.0
    add, _ = object_add_mm(sequence_id, poses)
    return (round(float(err.mean()), 3) if err.size else None), add


def _published_views(sequence_id: int) -> dict[str, int]:
    """Per target, the views published to the crowd."""
    from sqlalchemy import func, select

    from backend.annotation.models import Task
    from backend.crowd.models import CrowdHit
    from backend.db import session_scope

    with session_scope() as session:
        return {key: int(n) for key, n in session.execute(
            select(Task.target_key, func.count(func.distinct(Task.id)))
            .join(CrowdHit, CrowdHit.task_id == Task.id)
            .where(Task.sequence_id == sequence_id, CrowdHit.hit_id.is_not(None))
            .group_by(Task.target_key))}


def one(capture: Path, name: str, profile: str, hourly: float,
        policy: str = "every-view", initial_views: int | None = None,
        crowd_seed: int = 0) -> dict[str, Any]:
    """One protocol through the product in a fresh instance (this process); its figures."""
    port = free_port()
    isolated_workdir(f"cost-{name}", DEXLABEL_PUBLIC_URL=f"http://127.0.0.1:{port}",
                     DEXLABEL_INPROCESS_WORKER="true")
    from backend import demo
    from backend.db import session_scope
    from backend.progress.frame_costs import frame_costs

    started = time.perf_counter()
    protocol = PROTOCOLS[name]
    sequence_id, tasks = _setup(capture)
    rewards = _rewards(capture, tasks, protocol, hourly)
    admin = demo.demo_logins()["admin"]
    server = demo.DemoServer("127.0.0.1", port)
    server.start()
    try:
        _publish(sequence_id, rewards, "every-view" if name == "dexycb" else policy,
                 initial_views)
        # Each solve may publish another view (adaptive): the crowd comes back for it.
        outcomes, rounds = demo.demo_until_solved(sequence_id, capture, admin, None, profile,
                                                  protocol, crowd_seed)
    finally:
        server.stop()
    with session_scope() as session:
        found = frame_costs(session, [sequence_id])[0]
    mpjpe, add = _accuracy(sequence_id, capture)
    views = _views(sequence_id, {o.assignment_id: o.profile for o in outcomes
                                 if o.assignment_id is not None})
    lines = {t.target_key: t.model_dump() for t in found.targets}
    return {"hand": lines.get("hand:0"),
            "objects": [v for k, v in lines.items() if k.startswith("object:")],
            "total": found.total.model_dump(), "mpjpe_mm": mpjpe, "add_mm": add,
            "rewards_usd": {k: v / 100 for k, v in rewards.items()},
            "first_view_actions": _first_views(views), "view_actions": views,
            "qc_by_profile": _qc_by_profile(views),
            "unaccepted_tasks": demo.unaccepted(sequence_id)[0],
            "views_published": _published_views(sequence_id), "publish_rounds": rounds,
            "failed_jobs": _failed_jobs(), "seconds": round(time.perf_counter() - started, 1)}


def _failed_jobs() -> list[dict[str, str]]:
    """The instance's jobs that failed (their key and error's last line): a run whose work
    was never checked or solved says why."""
    from sqlalchemy import select

    from backend.db import session_scope
    from backend.jobs.models import Job

    with session_scope() as session:
        rows = session.execute(select(Job.key, Job.error).where(Job.status == "failed")
                               .order_by(Job.id)).all()
    out = []
    for key, error in rows:
        lines = (error or "").strip().splitlines()
        out.append({"key": key, "error": lines[-1] if lines else ""})
    return out


def _child(capture: Path, name: str, args: argparse.Namespace) -> dict[str, Any]:
    """``one`` in a process of its own (each protocol gets a fresh instance and settings)."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("DEXLABEL_") or k == "DEXLABEL_BENCH_KEEP"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    done = subprocess.run(
        [sys.executable, __file__, "--one", name, "--capture", str(capture), "--profile",
         args.profile, "--hourly", str(args.hourly), "--publish", args.publish,
         "--crowd-seed", str(args.crowd_seed),
         *(["--initial-views", str(args.initial_views)] if args.initial_views else [])],
        cwd=ROOT, env=env, capture_output=True, text=True)
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    # The instance's own progress (rounds, the admin's decisions, warnings), for the record.
    sys.stderr.write("".join(f"  {name}: {ln}\n" for ln in done.stdout.splitlines()
                             if not ln.startswith("{")) + done.stderr)
    if done.returncode != 0 or not lines:
        sys.exit(f"{name}: exit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}")
    result: dict[str, Any] = json.loads(lines[-1])
    return result


def _ratio(ours: float | None, theirs: float | None) -> float | None:
    return round(ours / theirs, 4) if ours is not None and theirs else None


def _ratios(ours: dict[str, Any], theirs: dict[str, Any]) -> dict[str, float | None]:
    """Per labelled hand frame, ``ours`` over ``theirs``: actions, seconds, money."""
    return {"actions": _ratio(ours["actions_per_frame"], theirs["actions_per_frame"]),
            "seconds": _ratio(ours["seconds_per_frame"], theirs["seconds_per_frame"]),
            "money": _ratio(_money(ours), _money(theirs))}


def _money(line: dict[str, Any]) -> float | None:
    value = line.get("money_per_frame")
    return None if value is None else float(value)


EPILOG = ("Smallest (smoke): --views 4 --frames 12, about 3-4 minutes here (2 shared cores);"
          " 8 views x 72 frames: the every-frame crowd and two solves, tens of minutes.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=EPILOG)
    parser.add_argument("--seed", type=int, default=7717, help="the capture's seed")
    parser.add_argument("--views", type=int, default=8)
    parser.add_argument("--frames", type=int, default=72)
    parser.add_argument("--capture", type=Path, help="a synthetic capture (default: generate)")
    parser.add_argument("--profile", default="careful",
                        help="the simulated crowd's profile (careful, mixed, ...)")
    parser.add_argument("--hourly", type=float, default=12.0,
                        help="dollars an hour of modelled working time the rewards pay")
    parser.add_argument("--protocols", default="dexycb,ours",
                        help="comma-separated, of dexycb, ours and assisted (ratios need"
                             " dexycb)")
    parser.add_argument("--publish", choices=["every-view", "adaptive"], default="every-view",
                        help="how views are published for ours and assisted (DexYCB's: every"
                             " view)")
    parser.add_argument("--initial-views", type=int, default=None,
                        help="adaptive: the views published first per target (default: the"
                             " setting's, 3)")
    parser.add_argument("--crowd-seed", type=int, default=0,
                        help="the simulated crowd's draw (profiles and noise; 0: the demo's)")
    parser.add_argument("--one", choices=sorted(PROTOCOLS), help=argparse.SUPPRESS)
    args = parser.parse_args()
    chosen = [p.strip() for p in args.protocols.split(",") if p.strip()]
    if not chosen or set(chosen) - set(PROTOCOLS):
        parser.error(f"--protocols {args.protocols!r}: name some of {', '.join(PROTOCOLS)}")
    if args.initial_views is not None and not 2 <= args.initial_views <= args.views:
        parser.error(f"--initial-views {args.initial_views}: between 2 and --views"
                     f" ({args.views})")
    if args.one:
        print(json.dumps(one(args.capture.resolve(), args.one, args.profile, args.hourly,
                             args.publish, args.initial_views, args.crowd_seed)))
        return
    capture = args.capture
    if capture is None:
        from worker.synth import generate_capture

        capture = isolated_workdir("cost") / f"capture-s{args.seed}"
        generate_capture(capture, seed=args.seed, frames=args.frames, views=args.views,
                         objects=1, workers=1)
    result: dict[str, Any] = {"capture": str(capture), "seed": args.seed, "views": args.views,
                              "frames": args.frames, "profile": args.profile,
                              "crowd_seed": args.crowd_seed,
                              "publish": args.publish, "initial_views": args.initial_views,
                              "hourly_usd": args.hourly, "protocols": {}}
    for name in chosen:
        result["protocols"][name] = got = _child(capture.resolve(), name, args)
        hand = got["hand"]
        first = got["first_view_actions"].get("hand:0")
        print(f"{name}: hand {hand['frames_labelled']} 3D frames, {hand['actions_per_frame']}"
              f" actions, {hand['seconds_per_frame']} s, ${hand['money_per_frame']} per frame;"
              f" first view {first} actions; MPJPE {got['mpjpe_mm']} mm, ADD"
              f" {got['add_mm']} mm", flush=True)
    ran = result["protocols"]
    for field, name in (("ratios", "ours"), ("assisted_ratios", "assisted")):
        if "dexycb" in ran and name in ran:
            result[field] = _ratios(ran[name]["hand"], ran["dexycb"]["hand"])
    print(json.dumps(result))


if __name__ == "__main__":
    main()
