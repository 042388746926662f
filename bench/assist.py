"""Benchmark: the effort and accuracy of assisted annotation against today's keyframe worker.

Two synthetic captures of one scene (``--capture``/``--fast-capture``, or generated from
``--capture-seed`` with ``--views`` views at ``--frames`` and ``--fast-frames`` frames; 24 frames
is the same motion three times faster per frame). On each, every view's hand is labelled, in
the order of the views' serials, by one simulated crowd of each variant (``--crowd-seed``):

    today     worker.synth.annotators' careful worker: a keyframe every 4 frames plus the
              visibility changes, 2 px noise;
    assisted  worker.synth.assisted's careful worker: tracking proposals (worker.assist.lk,
              what POST /api/annotate/proposals computes) with the check cells planted, and
              from the fourth view on (worker.assist.prefill.MIN_ACCEPTED_VIEWS, as the
              suggestions route) the pre-fill of the views before it, corrected where off
              by more than ``--tolerance`` px;
    blind     the blind acceptor on the same pre-fill: accepts everything.

Per variant: actions per task (mean over the views of clicks + drags + keys, the rule in
worker.synth.assisted; the kinds apart in "per_task"), the label error against the true
joints (px at visible joints, mean and p95; a joint left without a position counts as
infinite), and for today and assisted the hand's MPJPE (mm) of the default optimiser
(worker.solver) on the labels and depth of all views, the hand alone (``--solve``).

QC (``--draws`` crowds on the 72-frame capture, imported into a fresh embedded setup): in each
crowd ``--blind-views`` views (drawn) get a blind acceptor and the others a careful assisted
worker, all with the careful crowd's pre-fill; each assignment created first so that its
database id draws its check cells with the instance's key, its tracks saved with their
sources, then the product's QC job (backend.quality.flows.run_qc) scores the target:
flagged = review or reject, per profile (as bench/qc.py counts them; a provisional report
counts by its outcome, "provisional" says how many were); "checks_kept_unshown": check cells
kept unchanged where the pre-fill was shown without an offset (occluded or of unknown
visibility), which worker.assist.checks.accepted_checks counts as accepted all the same.

Also on the 72-frame capture: "proposals", the LK proposals accepted where they hold against
linear interpolation between the keyframe worker's keyframes (``--every``, ``--worker-seed``;
label error over all frames and between keyframes, "proposed" the share of those with a
proposal), and "timing_ms", the proposals for 21 points over the clip (median of ``--runs``),
of the pure function and of the endpoint in process (token, keyframe checks, reading and
decoding the frames from storage, tracking, the answer).

Prints one JSON line (after an "effort:" line with the crowds' part): {"capture",
"fast_capture", "crowd_seed", "tolerance_px", "judge_sigma_px", "default", "fast",
"proposals", "timing_ms", "qc", "targets"}.
Usage: python bench/assist.py [--capture DIR] [--fast-capture DIR] [--capture-seed 7]
           [--views 4] [--crowd-seed 9] [--draws 5] [--blind-views 1] [--solve both|fast|none]
           [--runs 5] [--skip-qc]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from _crowd_labels import grey_view

from _server import isolated_workdir, median_ms


def _errors(dense_xy: np.ndarray, truth: np.ndarray, visible: np.ndarray,
            mask: np.ndarray) -> np.ndarray:
    """Errors (px) at visible joints within ``mask`` (F, P); a missing position counts as
    missing (not as zero)."""
    keep = visible & mask & np.isfinite(truth).all(axis=2)
    return np.linalg.norm(dense_xy - truth, axis=2)[keep]


def _summary(err: np.ndarray) -> dict[str, float | int]:
    finite = err[np.isfinite(err)]
    if finite.size == 0:
        return {"n": 0}
    return {"n": int(finite.size), "mean_px": round(float(finite.mean()), 3),
            "median_px": round(float(np.median(finite)), 3),
            "p90_px": round(float(np.percentile(finite, 90)), 3),
            "max_px": round(float(finite.max()), 3)}


def _dense(tracks: list[list[list[Any]]], frames: int) -> np.ndarray:
    from worker.tracks.interpolate import dense_track

    return np.stack([dense_track(rows, frames).xy for rows in tracks], axis=1)


def _accepted(tracks: list[list[list[Any]]], xy: np.ndarray, ok: np.ndarray
              ) -> list[list[list[Any]]]:
    """The worker's keyframes with every proposal that holds added as a visible keyframe."""
    out = []
    for p, rows in enumerate(tracks):
        keyed = {int(r[0]): r for r in rows}
        for f in np.flatnonzero(ok[:, p]):
            keyed.setdefault(int(f), [int(f), float(xy[f, p, 0]), float(xy[f, p, 1]), 1])
        out.append([keyed[f] for f in sorted(keyed)])
    return out


def _accuracy(capture: Path, frames: int, every: int, seed: int) -> dict[str, Any]:
    from backend.captures.truth import CaptureTruth
    from worker.assist.lk import propose
    from worker.formats import dexycb
    from worker.synth.annotators import annotate, hand_visibility

    truth_of = CaptureTruth(capture)
    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    serials = sorted(p.name for p in seq_dir.iterdir() if p.is_dir())
    rng = np.random.default_rng(seed)
    parts: dict[str, list[np.ndarray]] = {k: [] for k in (
        "interp_all", "interp_between", "assist_all", "assist_between", "interp_on", "lk_on")}
    between_total = proposed = 0
    for serial in serials:
        joint_2d, seg = truth_of.view(serial, frames)
        truth = np.where((joint_2d == dexycb.NO_LABEL).all(axis=2, keepdims=True), np.nan,
                         joint_2d)
        visible = hand_visibility(joint_2d, seg)
        grey = grey_view(seq_dir / serial, frames)
        size = (grey.shape[2], grey.shape[1])
        work = annotate(truth, visible, size, "careful", rng, key_step=every,
                        follow_motion=False)
        found = propose(grey, work.tracks)
        keyed = np.zeros(visible.shape, bool)
        for p, rows in enumerate(work.tracks):
            keyed[[int(r[0]) for r in rows], p] = True
        interp = _dense(work.tracks, frames)
        assisted = _dense(_accepted(work.tracks, found.xy, found.ok), frames)
        everywhere = np.ones(visible.shape, bool)
        parts["interp_all"].append(_errors(interp, truth, visible, everywhere))
        parts["interp_between"].append(_errors(interp, truth, visible, ~keyed))
        parts["assist_all"].append(_errors(assisted, truth, visible, everywhere))
        parts["assist_between"].append(_errors(assisted, truth, visible, ~keyed))
        parts["interp_on"].append(_errors(interp, truth, visible, found.ok))
        parts["lk_on"].append(_errors(found.xy, truth, visible, found.ok))
        between_total += int((visible & ~keyed).sum())
        proposed += int((visible & found.ok).sum())
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    return {
        "views": len(serials),
        "interpolation": {"all": _summary(cat["interp_all"]),
                          "between": _summary(cat["interp_between"])},
        "assisted": {"all": _summary(cat["assist_all"]),
                     "between": _summary(cat["assist_between"]),
                     "proposed": round(proposed / max(between_total, 1), 3),
                     "on_proposed": {"interpolation": _summary(cat["interp_on"]),
                                     "lk": _summary(cat["lk_on"])}},
    }


def _timing(capture: Path, frames: int, every: int, runs: int) -> dict[str, Any]:
    """Median ms of 21-point proposals over the clip: pure function and endpoint."""
    from fastapi.testclient import TestClient

    from backend.accounts.service import create_admin
    from backend.annotation.models import Task
    from backend.annotation.service import create_assignment, create_tasks
    from backend.annotation.tokens import assignment_token
    from backend.app import create_app
    from backend.captures.flows import import_path
    from backend.captures.truth import CaptureTruth
    from backend.config import get_settings
    from backend.db import session_scope
    from backend.migrate import upgrade
    from backend.storage import get_storage
    from worker.assist.lk import propose
    from worker.formats import dexycb
    from worker.synth.annotators import annotate, hand_visibility

    upgrade(get_settings().database_url)
    sequence_id = import_path(capture)[0].sequence_id
    with session_scope() as session:
        create_admin(session, "bench@example.org", "bench password 1234")
        task = next(t for t in create_tasks(session, get_storage(), sequence_id)
                    if t.kind == "hand")
        task = session.get_one(Task, task.id)
        token = assignment_token(task, create_assignment(session, task, "bench"))
        serial = task.camera.serial
    joint_2d, seg = CaptureTruth(capture).view(serial, frames)
    grey = grey_view(next(capture.glob(dexycb.META_GLOB)).parent / serial, frames)
    work = annotate(joint_2d, hand_visibility(joint_2d, seg), (grey.shape[2], grey.shape[1]),
                    "careful", np.random.default_rng(0), key_step=every, follow_motion=False)
    body = {"tracks": [{"point": p, "keyframes": rows} for p, rows in enumerate(work.tracks)]}
    client = TestClient(create_app())
    headers = {"Authorization": f"Bearer {token}"}

    def endpoint() -> None:
        resp = client.post("/api/annotate/proposals", json=body, headers=headers)
        if resp.status_code != 200:
            raise RuntimeError(f"proposals failed: {resp.status_code} {resp.text}")

    endpoint()  # warm: imports, the first connection
    return {"points": 21, "frames": frames, "size": [grey.shape[2], grey.shape[1]],
            "runs": runs, "pure": median_ms(lambda: propose(grey, work.tracks), runs),
            "endpoint": median_ms(endpoint, runs)}


@dataclass
class _View:
    """One view of a capture as the simulated crowd and the solver need it (hand only).

    truth: (F, 21, 2) px, NaN where there is no label; visible: (F, 21) bool; grey: (F, H, W)
    uint8; depth: (F, H, W) uint16 mm; camera: the view's CameraModel (world = master frame).
    """

    serial: str
    truth: np.ndarray
    visible: np.ndarray
    grey: np.ndarray
    depth: np.ndarray
    camera: Any


@dataclass
class _Capture:
    views: list[_View]
    frames: int
    side: str
    betas: np.ndarray
    joints_world: np.ndarray  # (F, 21, 3) metres


def _load(capture: Path) -> _Capture:
    """Every view of the capture's first sequence, in the order the views are labelled."""
    from backend.captures.layout import read_sequence
    from backend.captures.truth import CaptureTruth
    from worker.formats import dexycb
    from worker.geometry.cameras import CameraModel, intrinsics_matrix
    from worker.synth.annotators import hand_visibility

    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    plan = read_sequence(seq_dir)
    frames = plan.num_frames
    truth_of = CaptureTruth(capture)
    views = []
    for cam in sorted(plan.cameras, key=lambda c: c.serial):
        joint_2d, seg = truth_of.view(cam.serial, frames)
        depth = np.stack([cv2.imread(str(seq_dir / cam.serial / dexycb.depth_file(f)),
                                     cv2.IMREAD_ANYDEPTH) for f in range(frames)])
        views.append(_View(
            serial=cam.serial, visible=hand_visibility(joint_2d, seg),
            truth=np.where((joint_2d == dexycb.NO_LABEL).all(axis=2, keepdims=True), np.nan,
                           joint_2d),
            grey=grey_view(seq_dir / cam.serial, frames), depth=depth,
            camera=CameraModel(intrinsics_matrix(cam.fx, cam.fy, cam.ppx, cam.ppy),
                               np.asarray(cam.distortion), np.asarray(cam.extrinsics),
                               cam.width, cam.height)))
    master = plan.cameras[0]
    joints = []
    for f in range(frames):
        with np.load(seq_dir / master.serial / dexycb.labels_file(f)) as labels:
            joints.append(labels[dexycb.JOINT_3D][0].astype(np.float64))
    to_world = np.asarray(master.extrinsics, dtype=np.float64)
    joints_world = np.stack(joints) @ to_world[:, :3].T + to_world[:, 3]
    hand = plan.hands[0]
    return _Capture(views, frames, hand.side,
                    np.asarray(hand.betas if hand.betas is not None else [], np.float64),
                    joints_world)


def _prefill_for(cap: _Capture, done: list[list[list[list[Any]]]]) -> Any:
    """The pre-fill of the next view from the labels of the views before it (None before
    MIN_ACCEPTED_VIEWS are done, as the route), as the simulated worker takes it: unknown
    visibility suggested visible (as the page takes it), no check cell there (as the route)."""
    from worker.assist.prefill import MIN_ACCEPTED_VIEWS, prefill, view_work
    from worker.synth.assisted import Prefill

    target = len(done)
    if target < MIN_ACCEPTED_VIEWS:
        return None
    work = [view_work(v, enumerate(tracks), cap.frames, 21) for v, tracks in enumerate(done)]
    found = prefill([v.camera for v in cap.views[:target + 1]], work, target,
                    cap.views[target].depth)
    return Prefill(xy=found.xy, visible=np.where(found.known, found.visible, True),
                   known=found.known)


def _work_one(view: _View, variant: str, key: bytes, assignment_id: int, prefill: Any,
              rng: np.random.Generator, judging: tuple[float, float]
              ) -> tuple[list[Any], dict[str, int]]:
    """(tracks, actions) of one simulated worker on one view: today's keyframe worker, or an
    assisted one (careful or blind) with the given pre-fill; judging: the careful assisted
    worker's (tolerance, judge sigma), px."""
    from worker.synth.annotators import annotate, keyframe_actions
    from worker.synth.assisted import AssistSetting, assisted_annotate

    size = (view.grey.shape[2], view.grey.shape[1])
    if variant == "today":
        work = annotate(view.truth, view.visible, size, "careful", rng, follow_motion=False)
        return work.tracks, keyframe_actions(work.tracks)
    setting = AssistSetting(view.grey, key, assignment_id, prefill)
    done = assisted_annotate(view.truth, view.visible, setting, variant, rng, *judging)
    return done.tracks, done.actions


def _dense_labels(tracks: list[Any], frames: int) -> tuple[np.ndarray, np.ndarray]:
    """(F, 21, 2) px and (F, 21) visibility of one view's tracks (sources dropped)."""
    from worker.synth.assisted import plain_rows
    from worker.tracks.interpolate import dense_points

    return dense_points(((p, plain_rows(rows)) for p, rows in enumerate(tracks)), frames, 21)


def _mpjpe_mm(cap: _Capture, labels: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """The hand's MPJPE (mm, over the frames the solve labels) of the default optimiser on
    these labels and the views' depth, the hand alone (no objects)."""
    import torch

    from worker.solver import HandTarget, SolveInputs, SolveSettings, solve

    torch.set_num_threads(1)  # a small shared machine: as bench/solve.py
    hand = HandTarget(cap.side, cap.betas, np.stack([xy for xy, _ in labels]),
                      np.stack([vis for _, vis in labels]))
    inputs = SolveInputs([v.camera for v in cap.views], cap.frames, hand, [],
                         [v.depth for v in cap.views])
    result = solve(inputs, SolveSettings(optimiser="default"))
    lab = result.labelled
    err = np.linalg.norm(result.hand_joints[lab] - cap.joints_world[lab], axis=-1) * 1000.0
    return round(float(err.mean()), 3)


def _variant(cap: _Capture, variant: str, key: bytes, rng: np.random.Generator,
             judging: tuple[float, float], prefills: list[Any] | None, solve: bool
             ) -> tuple[dict[str, Any], list[Any]]:
    """One crowd (one worker per view, in label order) of a variant: its summary and the
    pre-fill each view was given (the careful crowd's own, computed as it goes)."""
    done: list[Any] = []
    given: list[Any] = []
    actions: list[dict[str, int]] = []
    errors, labels = [], []
    for i, view in enumerate(cap.views):
        prefill = None
        if variant != "today":
            prefill = prefills[i] if prefills is not None else _prefill_for(cap, done)
        given.append(prefill)
        tracks, acts = _work_one(view, variant, key, 1000 + i, prefill, rng, judging)
        done.append(tracks)
        actions.append(acts)
        xy, vis = _dense_labels(tracks, cap.frames)
        labels.append((xy, vis))
        keep = view.visible & np.isfinite(view.truth).all(axis=2)
        err = np.linalg.norm(xy - view.truth, axis=2)[keep]
        errors.append(np.where(np.isfinite(err), err, np.inf))
    totals = [a["clicks"] + a["drags"] + a["keys"] for a in actions]
    err = np.concatenate(errors)
    out: dict[str, Any] = {
        "actions_per_task": round(float(np.mean(totals)), 1),
        "actions_per_view": totals,
        "per_task": {k: round(float(np.mean([a[k] for a in actions])), 1) for k in actions[0]},
        "label_error_px": {"mean": round(float(np.mean(err)), 3),
                           "p95": round(float(np.percentile(err, 95)), 3),
                           "n": int(err.size)},
        "prefilled_views": sum(p is not None for p in given)}
    if solve:
        out["mpjpe_mm"] = _mpjpe_mm(cap, labels)
    return out, given


def _effort(capture: Path, seed: int, judging: tuple[float, float], solve: bool
            ) -> tuple[dict, _Capture, list[Any]]:
    """Today's keyframe worker, the careful assisted worker and the blind acceptor on every
    view's hand of one capture (each crowd from the same seed); the careful crowd's pre-fills
    are what the blind one gets. The solve runs on today's and the careful crowd's labels."""
    from worker.assist.checks import check_key

    cap = _load(capture)
    key = check_key("bench assist")
    out: dict[str, Any] = {"frames": cap.frames, "views": len(cap.views)}
    started = time.perf_counter()
    out["today"], _ = _variant(cap, "today", key, np.random.default_rng(seed), judging, None,
                               solve)
    out["assisted"], prefills = _variant(cap, "careful", key, np.random.default_rng(seed),
                                         judging, None, solve)
    out["blind"], _ = _variant(cap, "blind", key, np.random.default_rng(seed), judging,
                               prefills, False)
    out["actions_ratio"] = round(out["assisted"]["actions_per_task"]
                                 / out["today"]["actions_per_task"], 3)
    out["seconds"] = round(time.perf_counter() - started, 1)
    return out, cap, prefills


def _qc(capture: Path, cap: _Capture, prefills: list[Any], draws: int, blind_views: int,
        seed: int, judging: tuple[float, float]) -> dict[str, Any]:
    """``draws`` crowds through the product's QC job (backend.quality.flows.run_qc) in a fresh
    embedded setup: in each, ``blind_views`` views (drawn) get a blind acceptor, the others a
    careful assisted worker, each given the careful crowd's pre-fill once 3 views before it are
    careful (a blind acceptor's view is rejected, so it does not count); each assignment is
    created first so that its id draws its check cells (with the instance's key), then its
    tracks are saved with their sources."""
    from qc import _clear, _fresh_setup, _of_kind, _run_qc, _setup

    from backend.annotation.models import Assignment, Track
    from backend.config import get_settings
    from backend.db import session_scope, utcnow
    from backend.quality.models import QCReport
    from worker.assist.checks import check_key
    from worker.assist.prefill import MIN_ACCEPTED_VIEWS

    _fresh_setup("assist-qc")
    sequence_id, every_task = _setup(capture)
    tasks = _of_kind(every_task, "hand")
    task_of = {t["serial"]: t for t in tasks}
    key = check_key(get_settings().signing_key)
    rng = np.random.default_rng(seed)
    table = {p: {"approve": 0, "review": 0, "reject": 0} for p in ("careful", "blind")}
    provisional = {"careful": 0, "blind": 0}
    unshown = {"careful": 0, "blind": 0}
    reasons: list[str] = []
    for draw in range(draws):
        _clear(sequence_id)
        blind = set(rng.permutation(len(cap.views))[:blind_views].tolist())
        profile_of: dict[int, str] = {}
        view_of: dict[int, int] = {}
        for i, view in enumerate(cap.views):
            profile = "blind" if i in blind else "careful"
            with session_scope() as session:
                # Ids never reused across draws (SQLite hands a deleted row's id out again),
                # so that each crowd gets its own check cells.
                assignment = Assignment(
                    id=1 + draw * len(cap.views) + i,
                    task_id=task_of[view.serial]["id"], worker_id=f"{profile}-{draw}-{i}",
                    external_id=f"assist-{draw}-{i}", status="submitted", version=1,
                    working_time_s=150.0, submitted_at=utcnow())
                session.add(assignment)
                session.flush()
                # As the product offers it: once 3 views before this one were accepted (QC
                # rejects a blind acceptor), made of the careful crowd's earlier views.
                accepted = sum(1 for j in range(i) if j not in blind)
                prefill = prefills[i] if accepted >= MIN_ACCEPTED_VIEWS else None
                tracks, _ = _work_one(view, profile, key, assignment.id, prefill, rng, judging)
                assignment.tracks = [Track(point_index=p, keyframes=rows)
                                     for p, rows in enumerate(tracks)]
                unshown[profile] += _kept_unshown(key, assignment.id, tracks, prefill)
                profile_of[assignment.id], view_of[assignment.id] = profile, i
        _run_qc(sequence_id, tasks[0]["target_key"])
        with session_scope() as session:
            for report in session.query(QCReport).filter(
                    QCReport.assignment_id.in_(profile_of)):
                profile = profile_of[report.assignment_id]
                table[profile][report.outcome] += 1
                provisional[profile] += int(report.provisional)
                if (profile == "careful") != (report.outcome == "approve") and len(reasons) < 8:
                    view = view_of[report.assignment_id]
                    given = "pre-filled " if prefills[view] is not None else ""
                    reasons.append(f"{profile} on {given}view {view} {report.outcome}: "
                                   + "; ".join(report.reasons[:2]))

    def flagged(row: dict[str, int]) -> float:
        return round((row["review"] + row["reject"]) / max(sum(row.values()), 1), 4)

    return {"draws": draws, "confusion": table, "blind_flagged_rate": flagged(table["blind"]),
            "careful_flagged_rate": flagged(table["careful"]), "provisional": provisional,
            "checks_kept_unshown": unshown, "misses": reasons}


def _kept_unshown(key: bytes, assignment_id: int, tracks: list[Any], prefill: Any) -> int:
    """Check cells of an assignment kept visible as "prefilled" where the route planted no
    offset: QC would count them as accepted checks, so this stays 0 while the route and QC
    agree on where cells are planted. Tracking proposals are planted wherever they are given,
    so only pre-fill counts."""
    from worker.assist.checks import check_cells
    from worker.synth.assisted import row_source

    if prefill is None:
        return 0
    shown = prefill.shown()
    kept = 0
    for point, frame in check_cells(key, assignment_id, len(tracks), shown.shape[0]):
        row = next((r for r in tracks[point] if r[0] == frame), None)
        kept += int(row is not None and row_source(row) == "prefilled" and bool(row[3])
                    and not shown[frame, point])
    return kept


def _targets(default: dict, fast: dict, qc: dict | None) -> dict[str, bool]:
    """The issue's acceptance checks."""
    out = {}
    for name, run in (("default", default), ("fast", fast)):
        out[f"{name}_actions_le_third"] = run["actions_ratio"] <= 1 / 3
        out[f"{name}_error_le_today"] = (run["assisted"]["label_error_px"]["mean"]
                                         <= run["today"]["label_error_px"]["mean"])
    if "mpjpe_mm" in fast["assisted"]:
        out["fast_mpjpe_le_2mm"] = fast["assisted"]["mpjpe_mm"] <= 2.0
    out["fast_actions_le_today"] = (fast["assisted"]["actions_per_task"]
                                    <= fast["today"]["actions_per_task"])
    if qc is not None:
        out["blind_flagged_ge_95pct"] = qc["blind_flagged_rate"] >= 0.95
        out["careful_flagged_le_3pct"] = qc["careful_flagged_rate"] <= 0.03
    return out


def _capture_for(given: Path | None, work: Path, seed: int, frames: int, views: int) -> Path:
    if given is not None:
        return given.resolve()
    from worker.synth import generate_capture

    out = work / f"capture-s{seed}-f{frames}"
    generate_capture(out, seed=seed, frames=frames, views=views, workers=1)
    return out.resolve()


EPILOG = ("Default run here (2 shared cores): 6-12 minutes (two 4-view captures made, 72 and"
          " 24 frames; two solves; 5 QC crowds); --views 8 about 10-15 minutes. Short:"
          " --capture DIR --fast-capture DIR (reuse captures), --solve none, --draws 1, --runs"
          " 1, --skip-qc; smallest: --frames 12 --fast-frames 6 --draws 1 --runs 1 --solve none"
          " (about 30 s quiet).")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=EPILOG)
    parser.add_argument("--capture", type=Path, help="a synthetic capture (default: generate)")
    parser.add_argument("--fast-capture", type=Path,
                        help="the same scene at --fast-frames (default: generate)")
    parser.add_argument("--capture-seed", type=int, default=7)
    parser.add_argument("--frames", type=int, default=72, help="frames of a generated capture")
    parser.add_argument("--fast-frames", type=int, default=24,
                        help="frames of the generated fast capture (the same motion, faster)")
    parser.add_argument("--views", type=int, default=4, help="views of a generated capture")
    parser.add_argument("--every", type=int, default=4, help="the worker keys every K frames")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--worker-seed", type=int, default=3)
    parser.add_argument("--crowd-seed", type=int, default=9)
    parser.add_argument("--tolerance", type=float, default=None,
                        help="px the careful assisted worker lets a suggestion be off "
                             "(default worker.synth.assisted.TOLERANCE_PX)")
    parser.add_argument("--judge-sigma", type=float, default=None,
                        help="px noise of the careful assisted worker's judgement "
                             "(default worker.synth.assisted.JUDGE_SIGMA_PX)")
    parser.add_argument("--draws", type=int, default=5, help="crowds through QC")
    parser.add_argument("--blind-views", type=int, default=1,
                        help="views of each QC crowd given a blind acceptor")
    parser.add_argument("--solve", choices=("both", "fast", "none"), default="both",
                        help="captures whose labels are solved (the 72-frame solves take "
                             "about a minute each on a loaded 2-core machine)")
    parser.add_argument("--skip-qc", action="store_true")
    args = parser.parse_args()
    from worker.synth.assisted import JUDGE_SIGMA_PX, TOLERANCE_PX

    judging = (TOLERANCE_PX if args.tolerance is None else args.tolerance,
               JUDGE_SIGMA_PX if args.judge_sigma is None else args.judge_sigma)
    work = isolated_workdir("assist")
    capture = _capture_for(args.capture, work, args.capture_seed, args.frames, args.views)
    fast_capture = _capture_for(args.fast_capture, work, args.capture_seed, args.fast_frames,
                                args.views)
    frames = _frames(capture)
    result: dict[str, Any] = {"capture": str(capture), "fast_capture": str(fast_capture),
                              "crowd_seed": args.crowd_seed, "tolerance_px": judging[0],
                              "judge_sigma_px": judging[1]}
    result["default"], cap, prefills = _effort(capture, args.crowd_seed, judging,
                                               args.solve == "both")
    result["fast"], _, _ = _effort(fast_capture, args.crowd_seed, judging,
                                   args.solve != "none")
    print(f"effort: {json.dumps(result)}", flush=True)
    result["proposals"] = {"frames": frames, "every": args.every,
                           **_accuracy(capture, frames, args.every, args.worker_seed)}
    result["timing_ms"] = _timing(capture, frames, args.every, args.runs)
    result["qc"] = None if args.skip_qc else _qc(capture, cap, prefills, args.draws,
                                                  args.blind_views, args.crowd_seed, judging)
    result["targets"] = _targets(result["default"], result["fast"], result["qc"])
    print(json.dumps(result))


def _frames(capture: Path) -> int:
    import yaml

    from worker.formats import dexycb

    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    return int(yaml.safe_load((seq_dir / dexycb.META_FILE).read_text())["num_frames"])


if __name__ == "__main__":
    main()
