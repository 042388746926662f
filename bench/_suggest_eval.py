"""Suggestion error by number of accepted views, for bench/prefill.py.

Each view of a synthetic capture is labelled by one simulated careful worker through the
crowd's keyframe path (bench/_crowd_labels.py, image-checked), and that is the view's accepted
work. For every target view and each count k of accepted views (1, 2, and 3 or more: all
other views, at least 3), the k views after the target (in serial order, wrapping) suggest
the target's points: 1-2 views by the hand model fitted to their labels and depth
(worker.solver.suggest), 3 or more by triangulation (worker.assist.prefill), as the product
does. Objects (1 and 2 views): each view's careful worker picks its own 2 landmarks; the
first accepted view's are carried into the target by the object's poses fitted to the
accepted views' landmarks and depth.

Hand error: px from a suggested position to the true joint where the joint is truly visible and
the suggestion says visible (or cannot tell); occlusion: share of the truly occluded joints
(inside the image) proposed occluded.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from _crowd_labels import crowd_hand, write_grey

COUNTS = ("1", "2", "3+")


def _capture(capture: Path) -> dict[str, Any]:
    from backend.captures.layout import read_sequence
    from backend.captures.truth import CaptureTruth
    from worker.formats import dexycb
    from worker.geometry.cameras import CameraModel, intrinsics_matrix
    from worker.synth.annotators import hand_visibility

    seq_dir = next(capture.glob(dexycb.META_GLOB)).parent
    plan = read_sequence(seq_dir)
    frames, truth = plan.num_frames, CaptureTruth(capture)
    cameras, depth, joints, visible = [], [], [], []
    for cam in plan.cameras:
        cameras.append(CameraModel(intrinsics_matrix(cam.fx, cam.fy, cam.ppx, cam.ppy),
                                   np.asarray(cam.distortion), np.asarray(cam.extrinsics),
                                   cam.width, cam.height))
        depth.append(np.stack([cv2.imread(str(seq_dir / cam.serial / dexycb.depth_file(f)),
                                          cv2.IMREAD_UNCHANGED) for f in range(frames)]))
        joint_2d, seg = truth.view(cam.serial, frames)
        joints.append(joint_2d)
        visible.append(hand_visibility(joint_2d, seg))
    hand = plan.hands[0]
    return {"cameras": cameras, "depth": depth, "joints": np.stack(joints),
            "visible": np.stack(visible), "side": hand.side,
            "betas": np.asarray(hand.betas or np.zeros(10), float),
            "serials": [c.serial for c in plan.cameras], "frames": frames}


def _crowd_work(capture: Path, scene: dict[str, Any], cache: Path, seed: int) -> list[Any]:
    """One careful crowd worker's image-checked labels per view, as ViewWork."""
    from worker.assist.prefill import ViewWork

    write_grey(capture, cache, scene["serials"])
    grey = np.load(cache / "grey.npy")
    cam = scene["cameras"][0]
    xy, seen, _ = crowd_hand(scene["joints"], scene["visible"], grey, "crowd",
                             (cam.width, cam.height), np.random.default_rng(seed))
    return [ViewWork(view=v, xy=xy[v], visible=seen[v], decided=np.isfinite(xy[v]).all(-1))
            for v in range(len(xy))]


def _suggest(scene: dict[str, Any], work: list[Any], target: int, accepted: list[int]
             ) -> tuple[Any, tuple[float, float]]:
    """The target's suggestions from the accepted views' work, and the seconds they took
    (wall, and CPU of the process: all its threads)."""
    from worker.assist.prefill import prefill
    from worker.solver.suggest import MAX_FIT_VIEWS, fit_hand_joints, fitted_prefill

    mine = [work[v] for v in accepted]
    tick, cpu = time.perf_counter(), time.process_time()
    if len(accepted) > MAX_FIT_VIEWS:
        found = prefill(scene["cameras"], mine, target, scene["depth"][target])
    else:
        joints = fit_hand_joints(scene["cameras"], mine,
                                 {v: scene["depth"][v] for v in accepted},
                                 scene["side"], scene["betas"])
        found = fitted_prefill(scene["cameras"], mine, target, joints, scene["depth"][target])
    return found, (time.perf_counter() - tick, time.process_time() - cpu)


def _errors(scene: dict[str, Any], found: Any, target: int) -> tuple[np.ndarray, np.ndarray]:
    """(px errors of shown suggestions at visible joints, caught flags of occluded joints)."""
    truth, visible = scene["joints"][target], scene["visible"][target]
    cam = scene["cameras"][target]
    inside = ((truth[..., 0] >= 0) & (truth[..., 0] < cam.width) & (truth[..., 1] >= 0)
              & (truth[..., 1] < cam.height))
    has = np.isfinite(found.xy).all(axis=-1)
    shown = has & ~(found.known & ~found.visible)
    err = np.linalg.norm(found.xy - truth, axis=-1)[shown & visible]
    caught = (found.known & ~found.visible)[~visible & inside]
    return err, caught


def _stat(values: np.ndarray) -> dict[str, float | int | None]:
    if not values.size:
        return {"n": 0, "median_px": None, "p90_px": None}
    return {"n": int(values.size), "median_px": round(float(np.median(values)), 2),
            "p90_px": round(float(np.percentile(values, 90)), 2)}


def _object_work(capture: Path, scene: dict[str, Any], index: int, seed: int) -> list[Any]:
    """One careful worker's 2 landmarks of object ``index`` per view (each view its own), as
    ViewWork."""
    from backend.captures.truth import CaptureTruth
    from worker.assist.prefill import view_work
    from worker.synth.annotators import annotate

    truth, rng, frames = CaptureTruth(capture), np.random.default_rng(seed), scene["frames"]
    out = []
    for v, serial in enumerate(scene["serials"]):
        xy, visible = truth.object_points(serial, index, frames, rng)
        cam = scene["cameras"][v]
        tracks = annotate(xy, visible, (cam.width, cam.height), "careful", rng).tracks
        out.append(view_work(v, enumerate(tracks), frames, 2))
    return out


def _object_errors(capture: Path, scene: dict[str, Any], seed: int, targets: int
                   ) -> dict[str, Any]:
    """Object landmark suggestions from 1 and 2 accepted views: px from each suggested
    position to where the same surface point (the first accepted worker's landmark as the
    solver maps it) lies under the object's true pose, where it is suggested visible."""
    from backend.captures.layout import read_sequence
    from backend.captures.truth import CaptureTruth
    from worker.formats import dexycb
    from worker.geometry.mesh_io import read_mesh
    from worker.solver.suggest import fit_object_points, fitted_prefill

    plan = read_sequence(next(capture.glob(dexycb.META_GLOB)).parent)
    true_poses = CaptureTruth(capture).object_poses()  # (O, F, 3, 4)
    views, out = len(scene["cameras"]), {}
    parts: dict[str, tuple[list[np.ndarray], list[np.ndarray], list[float]]] = {
        "1": ([], [], []), "2": ([], [], [])}
    for index, obj in enumerate(plan.objects):
        mesh = read_mesh(obj.mesh_path)
        work = _object_work(capture, scene, index, seed + index)
        pose = None if obj.initial_pose is None else np.asarray(obj.initial_pose, float)
        for name, (errors, moving, seconds) in parts.items():
            for target in range(min(targets, views)):
                accepted = [(target + 1 + i) % views for i in range(int(name))]
                mine = [work[v] for v in accepted]
                tick = time.perf_counter()
                try:
                    world, local = fit_object_points(
                        scene["cameras"], mine, {v: scene["depth"][v] for v in accepted},
                        np.asarray(mesh.vertices, float), np.asarray(mesh.faces), pose)
                except ValueError:
                    continue
                seconds.append(time.perf_counter() - tick)
                found = fitted_prefill(scene["cameras"], mine, target, world,
                                       scene["depth"][target])
                truth = (np.einsum("fij,pj->fpi", true_poses[index][:, :, :3], local)
                         + true_poses[index][:, None, :, 3])
                xy = scene["cameras"][target].project(truth)
                shown = np.isfinite(found.xy).all(axis=-1) & found.known & found.visible
                # Moved: more than 5 mm from where frame 0 has it (at rest the given initial
                # pose, exact on a synthetic capture, answers alone).
                moved = np.linalg.norm(truth - truth[:1], axis=-1) > 0.005
                errors.append(np.linalg.norm(found.xy - xy, axis=-1)[shown])
                moving.append(np.linalg.norm(found.xy - xy, axis=-1)[shown & moved])
    for name, (errors, moving, seconds) in parts.items():
        out[name] = {**_stat(np.concatenate(errors) if errors else np.zeros(0)),
                     "moving": _stat(np.concatenate(moving) if moving else np.zeros(0)),
                     "seconds_per_view": round(float(np.median(seconds)), 2)
                     if seconds else None}
    return out


def by_accepted_views(capture: Path, cache: Path, seed: int, targets: int | None = None
                      ) -> dict[str, Any]:
    """Hand suggestion error per count of accepted views (1, 2, 3+); ``targets``: how many
    target views to evaluate (default all)."""
    scene = _capture(capture)
    work = _crowd_work(capture, scene, cache, seed)
    views = len(scene["cameras"])
    out: dict[str, Any] = {}
    for name in COUNTS:
        count = views - 1 if name == "3+" else int(name)
        errors, caught, seconds, cpu = [], [], [], []
        for target in range(views if targets is None else min(targets, views)):
            accepted = [(target + 1 + i) % views for i in range(count)]
            found, took = _suggest(scene, work, target, accepted)
            err, hit = _errors(scene, found, target)
            errors.append(err)
            caught.append(hit)
            seconds.append(took[0])
            cpu.append(took[1])
        cat_caught = np.concatenate(caught)
        out[name] = {**_stat(np.concatenate(errors)),
                     "occluded_caught": round(float(cat_caught.mean()), 3)
                     if cat_caught.size else None, "occluded": int(cat_caught.size),
                     "seconds_per_view": round(float(np.median(seconds)), 2),
                     "cpu_seconds_per_view": round(float(np.median(cpu)), 2)}
    objects = _object_errors(capture, scene, seed, views if targets is None else targets)
    return {"hand": out, "objects": objects, "frames": scene["frames"], "views": views}
